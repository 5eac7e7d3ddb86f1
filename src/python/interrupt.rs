//! Long calls that stop on Ctrl-C and report progress.
//!
//! The core's work runs as a task of rayon's pool under a [`Token`]; the calling thread releases the
//! GIL and wakes every [`POLL`] to look at Python's signals (Ctrl-C, Jupyter's interrupt) and to
//! report progress. On a signal it tells the work to stop, waits for it (the core checks its
//! token between batches), and raises the signal's exception. A Python callable used as a field
//! is called from the calling thread, as documented, so that work stays there (see [`run`]).
//!
//! A panic in the core's work (on the task's thread or in any rayon worker it fans out to, whose
//! panics rayon carries back to the task) is caught where the work ends and raised at once as a
//! `RuntimeError` naming the call ([`call`]) with the panic's message; the pool and the process
//! stay usable. [`detach`] does the same for short work run without polling.

use crate::cancel::{self, Token};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::any::Any;
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Duration;

/// How often the calling thread looks at Python's signals and reports progress.
const POLL: Duration = Duration::from_millis(50);

/// Runs `work` so that Ctrl-C stops it; `progress`, when given, is called with the count of
/// work done so far ([`Token::done`]) at every poll. With `on_caller` (a Python callable as the
/// field, which users may expect on their own thread), the work runs on the calling thread
/// instead: Python raises KeyboardInterrupt inside the callable, which stops the work as any
/// exception of the callable does, and `progress` is called once, at the end.
pub fn run<T: Send>(
    py: Python<'_>,
    progress: Option<&Bound<'_, PyAny>>,
    on_caller: bool,
    work: impl FnOnce() -> crate::Result<T> + Send,
) -> PyResult<T> {
    let token = Token::new();
    if on_caller {
        let result = catch_unwind(AssertUnwindSafe(|| {
            cancel::run_under(token.clone(), || py.detach(work))
        }))
        .map_err(panic_error)?;
        if let (Some(p), Ok(_)) = (progress, &result) {
            p.call1((token.done(),))?;
        }
        return result.map_err(PyErr::from);
    }
    let caller = std::thread::current();
    // The task's outcome: its result, or the payload of a panic it (or a worker it waited for)
    // raised, so that the polling below ends in either case.
    type Outcome<T> = std::thread::Result<crate::Result<T>>;
    let finished: std::sync::Mutex<Option<Outcome<T>>> = std::sync::Mutex::new(None);
    let mut raised: Option<PyErr> = None;
    // The work runs as a task of rayon's pool (long-lived threads, whose allocator caches stay
    // warm from call to call), while this thread polls.
    rayon::in_place_scope(|s| {
        let t = token.clone();
        let (finished, caller) = (&finished, caller.clone());
        s.spawn(move |_| {
            let r = catch_unwind(AssertUnwindSafe(|| cancel::run_under(t, work)));
            *finished.lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
            caller.unpark();
        });
        let mut reported = 0;
        let done = || finished.lock().unwrap_or_else(|e| e.into_inner()).is_some();
        while !done() {
            py.detach(|| std::thread::park_timeout(POLL));
            if done() {
                break;
            }
            if raised.is_none() {
                if let Err(e) = py.check_signals() {
                    token.stop();
                    raised = Some(e);
                }
            }
            if let (Some(p), None) = (progress, &raised) {
                let done = token.done();
                if done != reported {
                    reported = done;
                    if let Err(e) = p.call1((done,)) {
                        token.stop();
                        raised = Some(e);
                    }
                }
            }
        }
    });
    let result = match finished.into_inner().unwrap_or_else(|e| e.into_inner()) {
        Some(Ok(r)) => r,
        Some(Err(payload)) => return Err(panic_error(payload)),
        None => {
            return Err(PyRuntimeError::new_err(format!(
                "{}: the work ended without a result",
                name()
            )))
        }
    };
    if let (Some(p), None, Ok(_)) = (progress, &raised, &result) {
        p.call1((token.done(),))?;
    }
    match raised {
        Some(e) => Err(e),
        None => result.map_err(PyErr::from),
    }
}

thread_local! {
    /// The Python name of the call this thread is in ([`call`]), for panic reports.
    static CALL: Cell<&'static str> = const { Cell::new("implicitmesh") };
}

/// Names the Python call this thread is in, until the returned guard drops: a panic in its work
/// is reported as a `RuntimeError` starting with `name`.
pub fn call(name: &'static str) -> Call {
    Call(CALL.with(|c| c.replace(name)))
}

/// Restores the previous call's name when dropped ([`call`]).
pub struct Call(&'static str);

impl Drop for Call {
    fn drop(&mut self) {
        CALL.with(|c| c.set(self.0));
    }
}

fn name() -> &'static str {
    CALL.with(|c| c.get())
}

/// The `RuntimeError` for a panic with `payload` in the current call's work.
fn panic_error(payload: Box<dyn Any + Send>) -> PyErr {
    let message = if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".to_string()
    };
    PyRuntimeError::new_err(format!(
        "{}: internal error, a panic in the core: {message} (please report it; the process is unaffected)",
        name()
    ))
}

/// Runs short `work` without the GIL and without polling for Ctrl-C; a panic in it becomes a
/// `RuntimeError` as in [`run`].
pub fn detach<T: Send, E: Into<PyErr> + Send>(
    py: Python<'_>,
    work: impl FnOnce() -> Result<T, E> + Send,
) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(|| py.detach(work))) {
        Ok(r) => r.map_err(Into::into),
        Err(payload) => Err(panic_error(payload)),
    }
}

/// Panics inside a rayon worker of a [`run`], or on the calling thread with `on_caller`: for
/// tests of the panic reports only (`_core._panic_in_worker`).
#[pyfunction]
#[pyo3(signature = (on_caller=false))]
pub fn _panic_in_worker(py: Python<'_>, on_caller: bool) -> PyResult<()> {
    use rayon::prelude::*;
    let _call = call("_panic_in_worker");
    run(py, None, on_caller, || {
        (0..64u32).into_par_iter().for_each(|i| {
            if i == 63 {
                panic!("a panic forced for testing");
            }
        });
        Ok(())
    })
}

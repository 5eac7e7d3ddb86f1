//! Long calls that stop on Ctrl-C and report progress.
//!
//! The core's work runs as a task of rayon's pool under a [`Token`]; the calling thread releases the
//! GIL and wakes every [`POLL`] to look at Python's signals (Ctrl-C, Jupyter's interrupt) and to
//! report progress. On a signal it tells the work to stop, waits for it (the core checks its
//! token between batches), and raises the signal's exception. A Python callable used as a field
//! is called from the calling thread, as documented, so that work stays there (see [`run`]).

use crate::cancel::{self, Token};
use pyo3::prelude::*;
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
        let result = cancel::run_under(token.clone(), || py.detach(work));
        if let (Some(p), Ok(_)) = (progress, &result) {
            p.call1((token.done(),))?;
        }
        return result.map_err(PyErr::from);
    }
    let caller = std::thread::current();
    let finished: std::sync::Mutex<Option<crate::Result<T>>> = std::sync::Mutex::new(None);
    let mut raised: Option<PyErr> = None;
    // The work runs as a task of rayon's pool (long-lived threads, whose allocator caches stay
    // warm from call to call), while this thread polls.
    rayon::in_place_scope(|s| {
        let t = token.clone();
        let (finished, caller) = (&finished, caller.clone());
        s.spawn(move |_| {
            let r = cancel::run_under(t, work);
            *finished.lock().unwrap() = Some(r);
            caller.unpark();
        });
        let mut reported = 0;
        while finished.lock().unwrap().is_none() {
            py.detach(|| std::thread::park_timeout(POLL));
            if finished.lock().unwrap().is_some() {
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
    let result = finished
        .into_inner()
        .unwrap()
        .expect("the scope ends after its task");
    if let (Some(p), None, Ok(_)) = (progress, &raised, &result) {
        p.call1((token.done(),))?;
    }
    match raised {
        Some(e) => Err(e),
        None => result.map_err(PyErr::from),
    }
}

//! Cooperative interruption of long calls.
//!
//! A caller that wants to stop a call runs it under a [`Token`] ([`run_under`]); the call's own
//! thread checks the token between units of work ([`check`]: every batch of field values or
//! gradients, every wave of a walk, every level of a subdivision, every phase of a polygonizer)
//! and returns [`Error::Interrupted`] once it is set. The token lives in a thread-local of the
//! call's thread, so nothing in between takes it as an argument; work inside rayon's pool is not
//! interrupted mid-phase (its results would be discarded anyway), only between phases. The token
//! also counts work done, for progress reports.

use crate::error::{Error, Result};
use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::Arc;

/// A stop flag and a count of work done, shared between a call and whoever watches it.
#[derive(Clone, Debug, Default)]
pub struct Token(Arc<State>);

#[derive(Debug, Default)]
struct State {
    stop: AtomicBool,
    done: AtomicU64,
}

impl Token {
    /// A new token, not set.
    pub fn new() -> Self {
        Self::default()
    }
    /// Asks the call to stop at its next check.
    pub fn stop(&self) {
        self.0.stop.store(true, Relaxed);
    }
    /// Whether [`Token::stop`] was called.
    pub fn stopped(&self) -> bool {
        self.0.stop.load(Relaxed)
    }
    /// Units of work the call reported done (field values and gradients computed, constraints
    /// fitted, or vertices a subdivision placed).
    pub fn done(&self) -> u64 {
        self.0.done.load(Relaxed)
    }
    /// Reports `n` units done, from any thread; `Err(Error::Interrupted)` when told to stop.
    pub fn advance(&self, n: u64) -> Result<()> {
        self.0.done.fetch_add(n, Relaxed);
        self.check()
    }
    /// `Err(Error::Interrupted)` when told to stop.
    pub fn check(&self) -> Result<()> {
        if self.stopped() {
            Err(Error::Interrupted)
        } else {
            Ok(())
        }
    }
}

/// This thread's token, for work that fans out over rayon's threads (which do not see it).
pub fn current() -> Option<Token> {
    CURRENT.with(|c| c.borrow().clone())
}

thread_local! {
    static CURRENT: RefCell<Option<Token>> = const { RefCell::new(None) };
}

/// Runs `work` on this thread with `token` as its token (the previous one is restored after).
pub fn run_under<R>(token: Token, work: impl FnOnce() -> R) -> R {
    struct Restore(Option<Token>);
    impl Drop for Restore {
        fn drop(&mut self) {
            CURRENT.with(|c| *c.borrow_mut() = self.0.take());
        }
    }
    let _restore = Restore(CURRENT.with(|c| c.borrow_mut().replace(token)));
    work()
}

/// `Err(Error::Interrupted)` when this thread's token was told to stop.
#[inline]
pub fn check() -> Result<()> {
    CURRENT.with(|c| match &*c.borrow() {
        Some(t) if t.stopped() => Err(Error::Interrupted),
        _ => Ok(()),
    })
}

/// Reports `n` units of work done on this thread's token (if any), then [`check`]s it.
#[inline]
pub fn advance(n: u64) -> Result<()> {
    CURRENT.with(|c| match &*c.borrow() {
        Some(t) => {
            t.0.done.fetch_add(n, Relaxed);
            if t.stopped() {
                Err(Error::Interrupted)
            } else {
                Ok(())
            }
        }
        None => Ok(()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_see_only_their_threads_token() {
        assert_eq!(check(), Ok(()));
        let t = Token::new();
        let r = run_under(t.clone(), || {
            advance(5).unwrap();
            t.stop();
            // Another thread has no token.
            std::thread::scope(|s| s.spawn(check).join().unwrap()).unwrap();
            (check(), advance(1))
        });
        assert_eq!(r, (Err(Error::Interrupted), Err(Error::Interrupted)));
        assert_eq!(t.done(), 6);
        // Restored after the call.
        assert_eq!(check(), Ok(()));
    }
}

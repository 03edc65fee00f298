//! A fit from Python with the GIL released and Ctrl-C honoured.
//!
//! Python runs its signal handlers on the main thread, between bytecodes; a fit that holds
//! that thread in Rust would leave Ctrl-C pending until it ends. So the fit runs on a
//! worker thread while the calling thread waits with the GIL released and, every
//! [`POLL`], runs the pending handlers (`PyErr_CheckSignals`). When one raises (Ctrl-C's
//! `KeyboardInterrupt`), the fit's interrupt flag is set: it finishes its iteration, saves
//! a checkpoint, releases the run folder's lock and returns, and the exception is raised.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

use pyo3::prelude::*;

/// How often the waiting thread looks for a signal.
const POLL: Duration = Duration::from_millis(50);

/// Runs `work(interrupt)` on a worker thread with the GIL released. Returns its result,
/// and the exception of a signal handler that raised meanwhile (after which the flag
/// was set and `work` was waited for).
pub fn run_interruptible<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(&AtomicBool) -> T + Send,
) -> (T, Option<PyErr>) {
    let interrupt = AtomicBool::new(false);
    let finished = (Mutex::new(false), Condvar::new());
    let mut raised = None;
    let value = std::thread::scope(|scope| {
        let worker = scope.spawn(|| {
            // Told on every exit, a panic included, so that the wait below ends.
            struct Done<'a>(&'a (Mutex<bool>, Condvar));
            impl Drop for Done<'_> {
                fn drop(&mut self) {
                    *self.0.0.lock().unwrap_or_else(|e| e.into_inner()) = true;
                    self.0.1.notify_all();
                }
            }
            let _done = Done(&finished);
            work(&interrupt)
        });
        loop {
            let done = py.detach(|| {
                let (lock, wake) = &finished;
                let guard = lock.lock().unwrap_or_else(|e| e.into_inner());
                let (guard, _) = wake
                    .wait_timeout_while(guard, POLL, |done| !*done)
                    .unwrap_or_else(|e| e.into_inner());
                *guard
            });
            if done {
                break;
            }
            // A second Ctrl-C while the iteration finishes changes nothing: the first
            // exception is the one raised.
            if let Err(e) = py.check_signals()
                && raised.is_none()
            {
                raised = Some(e);
                interrupt.store(true, Ordering::SeqCst);
            }
        }
        worker.join()
    });
    match value {
        Ok(v) => (v, raised),
        // The library does not panic on bad input; a panic here is a bug, re-raised as is.
        Err(panic) => std::panic::resume_unwind(panic),
    }
}

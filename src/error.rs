//! The crate's error type.
//!
//! User data never causes a panic: readers, the fit loop and the CLI return
//! [`DomaError`], which names the file or the iteration and the problem.

use std::path::PathBuf;

/// Everything that can go wrong in doma's library code.
#[derive(Debug, thiserror::Error)]
pub enum DomaError {
    /// A file could not be read or written.
    // Not `source`: thiserror would chain it, and `{:#}` would print the reason twice.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        error: std::io::Error,
    },
    /// A file was read but its contents are not valid.
    #[error("{path}: {reason}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// Data handed to the library is not usable (empty, NaN, mismatched shapes).
    #[error("invalid data: {0}")]
    InvalidData(String),
    /// A configuration value is out of range.
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// The loss stopped being finite during a fit.
    #[error(
        "the loss became {value} at iteration {iteration} (frame {frame}); the fit was stopped"
    )]
    NonFiniteLoss {
        /// The 0-based iteration (one pass over all frames).
        iteration: usize,
        /// The frame whose step produced the value.
        frame: usize,
        /// The offending value (NaN or ±inf).
        value: f64,
    },
    /// The requested compute backend cannot run on this machine.
    #[error("backend {backend} is not available: {reason}")]
    BackendUnavailable {
        /// The backend's name.
        backend: String,
        /// Why.
        reason: String,
    },
    /// A command-line flag or its combination with others cannot run; the message names
    /// the flag.
    #[error("{0}")]
    Usage(String),
    /// A run folder is held by another process's fit (its `.lock`, [`crate::run::RunLock`]).
    #[error(
        "{path}: the run is being fitted by {holder} (it holds {path}/.lock); wait for it, or stop it"
    )]
    Busy {
        /// The run folder.
        path: PathBuf,
        /// Who holds it: "process 1234", or "another process".
        holder: String,
    },
    /// An output would replace something a run reads ([`crate::io::check_output`]).
    #[error("{out}: refusing to write there: {why}")]
    WouldReplaceInput {
        /// The output asked for.
        out: PathBuf,
        /// Which input it would reach: inside the run folder, or an input file.
        why: String,
    },
    /// A new fit was asked into a folder that already holds a run.
    #[error("{0} already holds a run; resume it with --resume or choose another folder")]
    RunExists(PathBuf),
    /// A tensor could not be read back from the device.
    #[error("device error: {0}")]
    Device(String),
}

impl DomaError {
    /// An [`DomaError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        DomaError::Io {
            path: path.into(),
            error,
        }
    }
}

/// The crate's result type.
pub type Result<T, E = DomaError> = std::result::Result<T, E>;

/// How many [`catch_internal_errors`] calls are running: while any is, a panic is
/// recorded for its thread rather than printed.
static CATCHING: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
static HOOK: std::sync::Once = std::sync::Once::new();

std::thread_local! {
    static CAUGHT: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

/// The text of a panic's payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic".into())
}

/// Runs `f`, turning a panic into `Err(its message and place)`: a bug left in the code
/// must reach a user as one error naming what they ran, not a backtrace or a dead Python
/// interpreter; unwinding drops a run lock on the way out. While any call is catching, a
/// panic is not printed (with `RUST_BACKTRACE` set, it is, with its backtrace); other
/// panics go to the hook that was there before. Safe to call from several threads at once.
pub fn catch_internal_errors<R>(f: impl FnOnce() -> R) -> std::result::Result<R, String> {
    use std::sync::atomic::Ordering;
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        let verbose = std::env::var_os("RUST_BACKTRACE").is_some_and(|v| v != "0");
        std::panic::set_hook(Box::new(move |info| {
            if CATCHING.load(Ordering::SeqCst) == 0 {
                return previous(info);
            }
            let at = info
                .location()
                .map(|l| format!(" at {}:{}", l.file(), l.line()))
                .unwrap_or_default();
            let message = format!("{}{at}", panic_message(info.payload()));
            CAUGHT.with(|c| {
                c.borrow_mut().get_or_insert(message);
            });
            if verbose {
                eprintln!("{info}\n{}", std::backtrace::Backtrace::force_capture());
            }
        }));
    });
    CAUGHT.with(|c| c.borrow_mut().take());
    CATCHING.fetch_add(1, Ordering::SeqCst);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    CATCHING.fetch_sub(1, Ordering::SeqCst);
    // A panic on a worker thread reaches here as its payload, without its place.
    let caught = CAUGHT.with(|c| c.borrow_mut().take());
    result.map_err(|payload| caught.unwrap_or_else(|| panic_message(&*payload)))
}

#[cfg(test)]
mod internal_error_tests {
    use super::catch_internal_errors;

    #[test]
    fn a_panic_is_caught_as_its_message_and_place_on_each_thread() {
        let threads: Vec<_> = (0..4)
            .map(|i| {
                std::thread::spawn(move || {
                    let caught =
                        catch_internal_errors(|| -> u8 { panic!("index {i} past the end") });
                    (caught.unwrap_err(), catch_internal_errors(|| i))
                })
            })
            .collect();
        for (i, t) in threads.into_iter().enumerate() {
            let (what, fine) = t.join().unwrap();
            assert!(
                what.contains(&format!("index {i} past the end")) && what.contains("src/error.rs"),
                "{what}"
            );
            assert_eq!(fine, Ok(i));
        }
        // A panic on a thread the call spawned arrives as its payload.
        let what = catch_internal_errors(|| {
            std::thread::scope(|s| s.spawn(|| -> u8 { panic!("on a worker") }).join())
                .unwrap_or_else(|p| std::panic::resume_unwind(p))
        })
        .unwrap_err();
        assert!(what.contains("on a worker"), "{what}");
    }
}

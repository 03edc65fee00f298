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

//! The library's errors as Python exceptions, with the library's message: a file that
//! cannot be read or written is an `OSError` (`FileNotFoundError`, `FileExistsError`,
//! `PermissionError` where the cause says so), bad shapes, values and options a
//! `ValueError`, a missing backend or a failed fit a `RuntimeError`.

use std::io::ErrorKind;

use doma::DomaError;
use pyo3::PyErr;
use pyo3::exceptions::{
    PyFileExistsError, PyFileNotFoundError, PyOSError, PyPermissionError, PyRuntimeError,
    PyValueError,
};

/// `message` with the command line's flags named as this package's arguments:
/// `--test-fraction` as `test_fraction=`, `--resume` as `doma.resume()`.
pub fn pythonic(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(at) = rest.find("--") {
        let before = rest[..at].chars().next_back();
        let name_len = rest[at + 2..]
            .find(|c: char| !(c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-'))
            .unwrap_or(rest.len() - at - 2);
        let name = &rest[at + 2..at + 2 + name_len];
        let a_flag = before.is_none_or(|c| c == ' ' || c == '(' || c == '`' || c == '"')
            && name.starts_with(|c: char| c.is_ascii_lowercase());
        out.push_str(&rest[..at]);
        if a_flag {
            match name {
                "resume" => out.push_str("doma.resume()"),
                _ => {
                    out.push_str(&name.replace('-', "_"));
                    out.push('=');
                }
            }
        } else {
            out.push_str(&rest[at..at + 2 + name_len]);
        }
        rest = &rest[at + 2 + name_len..];
        // A value after the flag joins its argument: `test_fraction=2`.
        let value = rest.strip_prefix(' ').filter(|v| {
            v.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '.' || c == '"')
        });
        if a_flag
            && name != "resume"
            && let Some(v) = value
        {
            rest = v;
        }
    }
    out.push_str(rest);
    out
}

/// The exception for `error`.
pub fn to_py(error: DomaError) -> PyErr {
    let message = pythonic(&error.to_string());
    match &error {
        DomaError::Io { error, .. } => match error.kind() {
            ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
            ErrorKind::AlreadyExists => PyFileExistsError::new_err(message),
            ErrorKind::PermissionDenied => PyPermissionError::new_err(message),
            _ => PyOSError::new_err(message),
        },
        DomaError::RunExists(_) => PyFileExistsError::new_err(message),
        DomaError::Busy { .. } => PyOSError::new_err(message),
        DomaError::Malformed { .. }
        | DomaError::WouldReplaceInput { .. }
        | DomaError::InvalidData(_)
        | DomaError::InvalidConfig(_)
        | DomaError::Usage(_) => PyValueError::new_err(message),
        _ => PyRuntimeError::new_err(message),
    }
}

/// `Result<T, DomaError>` into `PyResult<T>`.
pub trait IntoPy<T> {
    /// The result with its error as a Python exception.
    fn py(self) -> pyo3::PyResult<T>;
}

impl<T> IntoPy<T> for doma::Result<T> {
    fn py(self) -> pyo3::PyResult<T> {
        self.map_err(to_py)
    }
}

/// Runs `body`, turning a panic left in the library into a `RuntimeError` naming `call`
/// and the file or folder it was given, rather than PyO3's `PanicException` (a
/// `BaseException`, which `except Exception` does not catch). Unwinding drops a run's
/// lock on the way.
pub fn guarded<T>(
    call: &str,
    about: Option<&std::path::Path>,
    body: impl FnOnce() -> pyo3::PyResult<T>,
) -> pyo3::PyResult<T> {
    doma::error::catch_internal_errors(body).unwrap_or_else(|what| {
        let about = about.map_or(String::new(), |p| format!(" on {}", p.display()));
        Err(PyRuntimeError::new_err(format!(
            "doma.{call}{about} stopped on an internal error ({what}); this is a bug, please \
             report it with the call"
        )))
    })
}

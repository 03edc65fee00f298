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

/// The exception for `error`.
pub fn to_py(error: DomaError) -> PyErr {
    let message = error.to_string();
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

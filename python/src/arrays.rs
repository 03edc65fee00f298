//! NumPy arrays through Python's buffer protocol: the Python layer (`doma/__init__.py`)
//! hands over C-contiguous `float32` / `bool` arrays, read here in place; outputs are
//! arrays it allocated, written here in place. Shapes are checked again here, so that
//! `doma._native` called directly refuses what it cannot read.

use pyo3::buffer::{Element, PyBuffer};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A C-contiguous buffer's address and length, to be read or written with the GIL
/// released. The buffer object that it came from must outlive it (the caller holds it).
#[derive(Clone, Copy)]
pub struct Raw<T> {
    ptr: *mut T,
    len: usize,
}

// SAFETY: the address stays valid while the exporting `PyBuffer` is held (the caller
// holds it for the whole call), and a buffer export pins the array's memory.
unsafe impl<T: Send> Send for Raw<T> {}
unsafe impl<T: Sync> Sync for Raw<T> {}

impl<T> Raw<T> {
    /// The elements, read-only.
    ///
    /// # Safety
    /// The buffer must still be exported, and nothing may write it meanwhile.
    pub unsafe fn slice<'a>(self) -> &'a [T] {
        // SAFETY: by the caller's contract and the check of `contiguous`.
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }

    /// The elements, writable.
    ///
    /// # Safety
    /// The buffer must still be exported, writable, and not read or written elsewhere.
    pub unsafe fn slice_mut<'a>(self) -> &'a mut [T] {
        // SAFETY: by the caller's contract and the checks of `contiguous` (writability).
        unsafe { std::slice::from_raw_parts_mut(self.ptr, self.len) }
    }
}

/// Checks that `buffer` (called `name` in errors) is C-contiguous with `shape` (a `None`
/// dimension takes any length), writable when `writable`, and returns its dimensions.
pub fn contiguous<T: Element>(
    buffer: &PyBuffer<T>,
    name: &str,
    shape: &[Option<usize>],
    writable: bool,
) -> PyResult<(Vec<usize>, Raw<T>)> {
    let dims = buffer.shape().to_vec();
    let fits = dims.len() == shape.len()
        && dims
            .iter()
            .zip(shape)
            .all(|(d, s)| s.is_none_or(|s| s == *d));
    if !fits {
        let want: Vec<String> = shape
            .iter()
            .map(|s| s.map_or("any".to_string(), |s| s.to_string()))
            .collect();
        return Err(PyValueError::new_err(format!(
            "{name} has shape {dims:?}, not [{}]",
            want.join(", ")
        )));
    }
    if !buffer.is_c_contiguous() {
        return Err(PyValueError::new_err(format!(
            "{name} is not C-contiguous (numpy.ascontiguousarray makes it so)"
        )));
    }
    if writable && buffer.readonly() {
        return Err(PyValueError::new_err(format!("{name} is read-only")));
    }
    let raw = Raw {
        ptr: buffer.buf_ptr() as *mut T,
        len: buffer.item_count(),
    };
    Ok((dims, raw))
}

/// A new `bytearray` holding `values`' bytes, which the Python layer views as an array
/// (`numpy.frombuffer`, no further copy).
pub fn to_bytearray<'py, T: bytemuck::Pod>(
    py: Python<'py>,
    values: &[T],
) -> Bound<'py, pyo3::types::PyByteArray> {
    pyo3::types::PyByteArray::new(py, bytemuck::cast_slice(values))
}

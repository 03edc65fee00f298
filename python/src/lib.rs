//! `doma._native`: the compiled part of the `doma` Python package. Each function is the
//! library's own ([`doma::run`]), called in process; `doma/__init__.py` is the API over
//! it, which turns any array into the C-contiguous `float32` / `bool` buffers read here.
//!
//! | module | what |
//! |---|---|
//! | `fit.rs` | `fit`, `resume`, `load`: fits into run folders, runs opened |
//! | `field.rs` | `Field`: a fitted run's warp, Jacobian, evaluation and files |
//! | `tracks.rs` | `read_tracks`: a sequence file as arrays |
//! | `command.rs` | `main`: the `doma` command line, for the console script |
//! | `convert.rs` | Python values into the library's types (enums, the fit options) |
//! | `arrays.rs`, `errors.rs`, `interrupt.rs` | buffers, exceptions, Ctrl-C |

mod arrays;
mod command;
mod convert;
mod errors;
mod field;
mod fill;
mod fit;
mod interrupt;
mod tracks;

use pyo3::prelude::*;

/// The version of the library this module was built from.
const VERSION: &str = env!("CARGO_PKG_VERSION");

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fit::fit, m)?)?;
    m.add_function(wrap_pyfunction!(fit::resume, m)?)?;
    m.add_function(wrap_pyfunction!(fit::load, m)?)?;
    m.add_function(wrap_pyfunction!(tracks::read_tracks, m)?)?;
    m.add_function(wrap_pyfunction!(fill::fill_into, m)?)?;
    m.add_function(wrap_pyfunction!(fill::fill_file, m)?)?;
    m.add_function(wrap_pyfunction!(tracks::sequence_reads, m)?)?;
    m.add_function(wrap_pyfunction!(command::main, m)?)?;
    m.add_class::<field::Field>()?;
    m.add("CHOICES", convert::choices(m.py())?)?;
    m.add("__version__", VERSION)?;
    Ok(())
}

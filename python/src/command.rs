//! `doma._native.main`: the `doma` command line, run in process by the package's console
//! script (`doma/__main__.py`), so that `pip install` gives the same CLI as `cargo build`:
//! one implementation, [`doma::cli::run_args`].

use pyo3::prelude::*;

/// Runs `doma` with the arguments `argv` (the program name first) and returns its exit
/// status ([`doma::cli::run_args`]). Meant for the console script, whose process runs
/// nothing else.
#[pyfunction]
pub fn main(py: Python<'_>, argv: Vec<String>) -> i32 {
    doma::backend::tune_allocator();
    // Without the GIL: a fit runs for minutes, and Ctrl-C is the CLI's own handler's.
    py.detach(|| doma::cli::run_args(argv))
}

//! The `doma` command line: parsing and the exit status; each subcommand lives in
//! [`doma::cli`].

use std::process::ExitCode;

fn main() -> ExitCode {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    ExitCode::from(doma::cli::run_args(std::env::args_os()).clamp(0, 255) as u8)
}

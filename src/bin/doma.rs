//! The `doma` command line: parsing and the exit status; each subcommand lives in
//! [`doma::cli`].

use std::process::ExitCode;

use clap::Parser;
use doma::cli::Cli;

fn main() -> ExitCode {
    // SAFETY: first thing in main; no other thread exists yet.
    unsafe { doma::cli::init_process() };
    let cli = Cli::parse();
    match cli.command.run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

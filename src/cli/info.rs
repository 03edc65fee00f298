//! `doma info`: what a run folder holds.

use std::path::PathBuf;

use crate::run::{RunDir, info};
use crate::{DomaError, Result};

/// The flags of `doma info`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Print a run's model, parameter count, checkpoint size and data shape")]
pub struct InfoArgs {
    /// The run folder.
    pub run: PathBuf,
}

/// Prints the run's description as JSON.
pub fn run(args: &InfoArgs) -> Result<()> {
    let info = info(&RunDir::new(&args.run))?;
    let text =
        serde_json::to_string_pretty(&info).map_err(|e| DomaError::InvalidData(e.to_string()))?;
    println!("{text}");
    Ok(())
}

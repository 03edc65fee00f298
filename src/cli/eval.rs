//! `doma eval`: the metrics of a fitted run.

use std::path::PathBuf;

use crate::cli::DeviceArgs;
use crate::run::{RunDir, eval_run};
use crate::{DomaError, Result};

/// The flags of `doma eval`.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Print the metrics of a fitted run, on its held-out points or on new data")]
pub struct EvalArgs {
    /// The run folder.
    pub run: PathBuf,
    /// Evaluate on every point of this data instead of the run's held-out points.
    pub data: Option<PathBuf>,
    /// The device.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// Prints the report as JSON.
pub fn run(args: &EvalArgs) -> Result<()> {
    let device = args.device.backend.device()?;
    let report = eval_run(&RunDir::new(&args.run), args.data.as_deref(), &device)?;
    let text =
        serde_json::to_string_pretty(&report).map_err(|e| DomaError::InvalidData(e.to_string()))?;
    println!("{text}");
    Ok(())
}

//! `doma fit`: fit a motion field to a user's data into a resumable run folder.

use std::path::PathBuf;

use crate::Result;
use crate::backend::BackendKind;
use crate::cli::WeightSearchArgs;
use crate::run::{FitOutcome, NewFit, RunDir, RunSpec, fit_run};

/// The flags of `doma fit`: the fit's options ([`RunSpec`], shared with batch manifests
/// and Python), the run folder, and how to resume one.
#[derive(clap::Parser, Debug, Clone)]
#[command(about = "Fit a motion field to your own data into a run folder (resumable)")]
pub struct FitArgs {
    /// The fit's options.
    #[command(flatten)]
    pub spec: RunSpec,
    /// The compute backend (default flex; a resumed fit keeps its own).
    #[arg(long)]
    pub backend: Option<BackendKind>,
    /// How an `auto` weight is searched.
    #[command(flatten)]
    pub search: WeightSearchArgs,
    /// The run folder to create (it must not hold a run yet).
    #[arg(long, required_unless_present = "resume", conflicts_with = "resume")]
    pub out: Option<PathBuf>,
    /// Continue the interrupted run in this folder from its last checkpoint (its options
    /// are the run's own).
    #[arg(long, conflicts_with = "RunSpec")]
    pub resume: Option<PathBuf>,
    /// Print errors only (no progress bar, no notes, no summary).
    #[arg(long)]
    pub quiet: bool,
    /// Also write the fit's report (the run's report.json) here as JSON; `-` prints it.
    #[arg(long, value_name = "PATH")]
    pub json: Option<PathBuf>,
}

impl FitArgs {
    /// What the flags ask for (the same that a batch manifest's entry deserialises into).
    pub fn spec(&self) -> RunSpec {
        RunSpec {
            backend: self.backend,
            ..self.spec.clone()
        }
    }

    /// The new fit, its data read once (after the weight search, with `--h-weight auto`).
    fn prepare(&self) -> Result<NewFit> {
        let search = self.search.search()?;
        let quiet = self.quiet;
        let fit = self.spec().prepare(&search, |p| {
            if !quiet {
                eprintln!(
                    "weight {:e}: validation EPE {:.2}e-4",
                    p.weight, p.validation_epe_x1e4
                )
            }
        })?;
        if quiet {
            return Ok(fit);
        }
        for note in &fit.sequence.notes {
            eprintln!("{}: {note}", fit.config.data.display());
        }
        let left_out = fit.sequence.model_outputs_left_out;
        if left_out > 0 {
            eprintln!(
                "left out the file's {left_out} model outputs (the points that POINT:ANGLES, \
                 FORCES, MOMENTS, POWERS, ... list): --model-outputs fits them"
            );
        }
        if let Some(choice) = &fit.config.weight_search {
            eprintln!("chose the L_H weight {:e}", choice.weight);
        }
        Ok(fit)
    }
}

/// Fits (or resumes) the run; Ctrl-C saves a checkpoint and exits with status 130.
pub fn run(args: &FitArgs) -> Result<()> {
    let interrupt = crate::cli::interrupt::install();
    let (run, new) = match (&args.resume, &args.out) {
        (Some(dir), _) => (RunDir::new(dir), None),
        (None, Some(out)) => (RunDir::new(out), Some(args.prepare()?)),
        (None, None) => {
            return Err(crate::DomaError::Usage(
                "give DATA and --out, or --resume RUN".into(),
            ));
        }
    };
    // A folder that is not a run fails here, before anything else. A resumed fit runs on
    // the backend it was started on (its Adam state and random stream are that device's).
    let backend = match &new {
        Some(n) => n.config.backend,
        None => {
            let saved = run.load_config()?.backend;
            if let Some(asked) = args.backend.filter(|&b| b != saved) {
                return Err(crate::DomaError::Usage(format!(
                    "--backend {asked}: {} was fitted on {saved}, and resumes there",
                    run.dir.display()
                )));
            }
            saved
        }
    };
    let device = backend.device()?;
    match fit_run(&run, new, &device, interrupt, None, !args.quiet)? {
        FitOutcome::Finished(report) => {
            if let Some(path) = &args.json {
                let text = serde_json::to_string_pretty(&report)
                    .map_err(|e| crate::DomaError::InvalidData(e.to_string()))?;
                if path.as_os_str() == "-" {
                    println!("{text}");
                } else {
                    crate::io::write_atomic(path, format!("{text}\n").as_bytes())?;
                }
            }
            if !args.quiet {
                eprintln!(
                    "wrote {} (its report: {})",
                    run.dir.display(),
                    run.dir.join("report.json").display()
                );
            }
            Ok(())
        }
        FitOutcome::Interrupted { iterations_done } => {
            eprintln!(
                "interrupted after {iterations_done} iterations; the checkpoint is saved. Continue with: doma fit --resume {}",
                run.dir.display()
            );
            crate::cli::interrupt::exit();
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;
    use crate::loss::DataPenalty;
    use crate::run::ModelChoice;
    use crate::train::select::Weight;

    fn parse(args: &[&str]) -> std::result::Result<FitArgs, clap::Error> {
        FitArgs::try_parse_from([&["fit"], args].concat())
    }

    /// A flag and a JSON field of the same name mean the same thing: the flags parse to the
    /// spec that the JSON deserialises to.
    #[test]
    fn flags_and_json_are_one_options_type() {
        let flags = "a.traj --out r --variant scaled-se3 --iters 20 --h-weight auto \
                     --frames 3..=9 --robust huber:0.02 --count-hidden --test-fraction 0.5 \
                     --recipe fast --learning-rate 3e-4 --fits 3";
        let flags = parse(&flags.split_whitespace().collect::<Vec<_>>()).unwrap();
        let json: RunSpec = serde_json::from_str(
            r#"{"data": "a.traj", "model": "scaled-se3", "iterations": 20, "h_weight": "auto",
                "frames": [3, 10], "robust": "huber:0.02", "count_hidden": true,
                "test_fraction": 0.5, "recipe": "fast", "learning_rate": 3e-4, "fits": 3}"#,
        )
        .unwrap();
        assert_eq!(flags.spec(), json);
        assert_eq!(json.model, Some(ModelChoice::ScaledSe3));
        assert_eq!(json.h_weight, Some(Weight::Auto));
        assert_eq!(json.robust, Some(DataPenalty::Huber { delta: 0.02 }));
        // A given learning rate wins over the recipe's.
        let fit = json.fit_config(|| Ok(1)).unwrap();
        assert_eq!(fit.schedule.learning_rate, 3e-4);
        // Written back, the spec reads the same.
        let text = serde_json::to_string(&json).unwrap();
        assert!(text.contains(r#""robust":"huber:0.02""#), "{text}");
        assert_eq!(serde_json::from_str::<RunSpec>(&text).unwrap(), json);
    }

    #[test]
    fn resume_conflicts_with_every_option_but_the_backend() {
        for extra in [
            &["--iters", "5"][..],
            &["--variant", "trans"],
            &["--count-hidden"],
        ] {
            let err = parse(&[&["--resume", "r"][..], extra].concat()).unwrap_err();
            assert_eq!(
                err.kind(),
                clap::error::ErrorKind::ArgumentConflict,
                "{extra:?}"
            );
        }
        assert!(parse(&["--resume", "r", "--backend", "flex"]).is_ok());
        assert!(parse(&["--resume", "r", "--quiet"]).is_ok());
    }

    #[test]
    fn a_bad_value_is_refused_naming_the_choices() {
        let err = parse(&["a.traj", "--out", "r", "--robust", "l2"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("huber[:DELTA]"), "{err}");
        let err = parse(&["a.traj", "--out", "r", "--variant", "affine"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("affinity") && err.contains("dpf"), "{err}");
        let err = parse(&["a.traj", "--out", "r", "--iters", "0"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("at least 1"), "{err}");
        let err = parse(&["a.traj", "--out", "r", "--fits", "10"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("from 1 to 9"), "{err}");
    }
}

//! `doma plot`: plots of a run, each as PNG and SVG ([`crate::plot`]).

use std::path::{Path, PathBuf};

use burn::tensor::Device;

use super::RunDir;
use crate::data::mesh::as_points;
use crate::io::load_json;
use crate::metrics::{EPE_SCALE, epe_per_frame, predict};
use crate::plot::{Series, line_plot, three_views};
use crate::train::IterationRecord;
use crate::train::select::WeightChoice;
use crate::{DomaError, Result};

/// Writes the run's plots into `RUN_DIR/plots/`, each as `.png` and `.svg`: `loss`
/// (trajectory and total loss per iteration, log scale), `epe_per_frame` (held-out EPE per
/// frame) and, for each of `frames` (default: the middle and the last frame),
/// `points_frame_KKKK` (three views of the held-out points observed in frame KKKK, coloured
/// by error; a frame where none is observed is skipped). Returns the PNG paths written.
pub fn plot_run(run: &RunDir, frames: Option<&[usize]>, device: &Device) -> Result<Vec<PathBuf>> {
    let config = run.load_config()?;
    let field = run.load_field(&config, device)?;
    let data = run.load_data(&config)?;
    let (test, _) = config.measured(&data.trajectories)?;
    let t = test.frames();
    let default = [t / 2, t - 1];
    let chosen = frames.unwrap_or(&default);
    if let Some(&bad) = chosen.iter().find(|&&k| k >= t) {
        return Err(DomaError::InvalidConfig(format!(
            "frame {bad} is not within the run's {t} frames"
        )));
    }
    let history: Vec<IterationRecord> = load_json(&run.history())?;
    let dir = run.dir.join("plots");
    // The plots belong in the run folder; only the data must not be among them.
    crate::io::check_output(&dir, None, &[&config.data])?;
    std::fs::create_dir_all(&dir).map_err(|e| DomaError::io(&dir, e))?;
    let predicted = predict(&field, &test, device)?;
    let per_frame = epe_per_frame(&predicted, &test)?;
    let mut written = vec![loss_plot(&history, &dir)?, epe_plot(&per_frame, &dir)?];
    if let Some(choice) = &config.weight_search {
        written.push(weight_plot(choice, &dir)?);
    }
    let canonical = as_points(test.canonical());
    for &k in chosen {
        // Only the points observed in frame k have a truth to show an error against.
        let seen: Vec<usize> = (0..test.points())
            .filter(|&i| test.is_observed(k, i))
            .collect();
        if seen.is_empty() {
            continue;
        }
        let pick = |p: Vec<[f32; 3]>| -> Vec<[f32; 3]> { seen.iter().map(|&i| p[i]).collect() };
        let (truth, pred) = (
            pick(as_points(test.frame(k))),
            pick(as_points(predicted.frame(k))),
        );
        let canonical = pick(canonical.clone());
        let mut errors: Vec<f64> = truth
            .iter()
            .zip(&pred)
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).abs() as f64).sum())
            .collect();
        errors.sort_by(f64::total_cmp);
        // The colour scale ends at the 99th percentile, so that one outlier does not wash
        // out the rest.
        let max = errors[(errors.len() - 1) * 99 / 100];
        let title = format!("Frame {k}: EPE {:.1} ×1e-4", per_frame[k] * EPE_SCALE);
        let path = dir.join(format!("points_frame_{k:04}.png"));
        three_views(&title, &canonical, &truth, &pred, max).save_png_and_svg(&path)?;
        written.push(path);
    }
    Ok(written)
}

/// `loss.png`: the trajectory and total loss per iteration, log scale.
fn loss_plot(history: &[IterationRecord], dir: &Path) -> Result<PathBuf> {
    let curve = |f: fn(&IterationRecord) -> f64| {
        history.iter().map(|r| (r.iteration as f64, f(r))).collect()
    };
    let series = [
        Series {
            name: "trajectory L1",
            color: [40, 60, 200],
            points: curve(|r| r.trajectory_loss),
        },
        Series {
            name: "total",
            color: [210, 30, 30],
            points: curve(|r| r.total_loss),
        },
    ];
    let path = dir.join("loss.png");
    line_plot("Loss", "iteration", "loss", &series, true).save_png_and_svg(&path)?;
    Ok(path)
}

/// `weight_search.png`: the validation EPE of each weight tried (`--h-weight auto`), the
/// weight on a log axis (0 drawn a decade below the smallest other weight).
fn weight_plot(choice: &WeightChoice, dir: &Path) -> Result<PathBuf> {
    let smallest = choice
        .grid
        .iter()
        .map(|p| p.weight)
        .filter(|&w| w > 0.0)
        .fold(1.0, f64::min);
    let series = [Series {
        name: "validation EPE (0 drawn a decade left of the smallest)",
        color: [120, 40, 170],
        points: choice
            .grid
            .iter()
            .map(|p| {
                let w = if p.weight > 0.0 {
                    p.weight
                } else {
                    smallest / 10.0
                };
                (w, p.validation_epe_x1e4)
            })
            .collect(),
    }];
    let path = dir.join("weight_search.png");
    let chosen = match choice.weight {
        0.0 => "0 (no L_H)".to_string(),
        w => format!("{w:e}"),
    };
    let title = format!("L_H weight by validation: chose {chosen}");
    line_plot(&title, "weight", "EPE ×1e-4", &series, false)
        .log_x()
        .save_png_and_svg(&path)?;
    Ok(path)
}

/// `epe_per_frame.png`: the held-out EPE of each frame.
fn epe_plot(per_frame: &[f64], dir: &Path) -> Result<PathBuf> {
    let series = [Series {
        name: "EPE",
        color: [30, 170, 90],
        // A frame with no observed held-out point (NaN) has no value to draw.
        points: per_frame
            .iter()
            .enumerate()
            .filter(|(_, e)| !e.is_nan())
            .map(|(k, e)| (k as f64, e * EPE_SCALE))
            .collect(),
    }];
    let path = dir.join("epe_per_frame.png");
    line_plot(
        "Held-out EPE per frame",
        "frame",
        "EPE ×1e-4",
        &series,
        false,
    )
    .save_png_and_svg(&path)?;
    Ok(path)
}

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
/// (trajectory and total loss per iteration, log scale), `epe_per_frame` (the EPE per frame
/// on what the run measures, its title says which), for tracks with gaps `gap_KK` (the
/// longest gaps as `doma complete` fills them, [`GAP_FIGURES`]) and, for each of `frames` (default: the middle and the last frame),
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
    let (_, what) = config.measured(&data.trajectories)?;
    let mut written = vec![
        loss_plot(&history, &dir)?,
        epe_plot(&per_frame, what, &dir)?,
    ];
    // Tracks with gaps: the longest gaps as `doma complete` fills them, in the data's units.
    if data
        .trajectories
        .observed()
        .is_some_and(|o| o.iter().any(|&seen| !seen))
    {
        written.extend(gap_plots(run, &config, &dir, device)?);
    }
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

/// The gaps `doma plot` draws for a run of tracks with gaps, the longest first.
pub const GAP_FIGURES: usize = 4;

/// `gap_KK.png` for the [`GAP_FIGURES`] longest gaps that `doma complete` fills (by
/// default): the track's coordinate that moves most around the gap, observed before and
/// after it and filled inside it, in the data's units.
fn gap_plots(
    run: &RunDir,
    config: &super::RunConfig,
    dir: &Path,
    device: &Device,
) -> Result<Vec<PathBuf>> {
    let done = super::complete_tracks(run, super::FillPolicy::default(), device)?;
    let (t, n) = (done.frames, done.points);
    let (labels, _) = super::names_and_rate(&config.data).unwrap_or_default();
    let mut gaps: Vec<(usize, usize, usize)> = Vec::new();
    for i in 0..n {
        let mut k = 0;
        while k < t {
            if !done.filled[k * n + i] {
                k += 1;
                continue;
            }
            let start = k;
            while k < t && done.filled[k * n + i] {
                k += 1;
            }
            gaps.push((i, start, k));
        }
    }
    gaps.sort_by_key(|&(i, a, b)| (std::cmp::Reverse(b - a), i, a));
    let mut written = Vec::new();
    for (g, &(i, a, b)) in gaps.iter().take(GAP_FIGURES).enumerate() {
        let from = a.saturating_sub(b - a);
        let to = (b + (b - a)).min(t);
        let at = |k: usize, d: usize| done.tracks[3 * (k * n + i) + d] as f64;
        let range = |d: usize| {
            let v: Vec<f64> = (from..to)
                .map(|k| at(k, d))
                .filter(|v| v.is_finite())
                .collect();
            v.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                - v.iter().cloned().fold(f64::INFINITY, f64::min)
        };
        let d = (0..3)
            .max_by(|&x, &y| range(x).total_cmp(&range(y)))
            .unwrap_or(0);
        let seen = |ks: std::ops::Range<usize>| -> Vec<(f64, f64)> {
            ks.filter(|&k| done.observed[k * n + i])
                .map(|k| (done.source_frames[k] as f64, at(k, d)))
                .collect()
        };
        let series = [
            Series {
                name: "observed, before",
                color: [40, 60, 200],
                points: seen(from..a),
            },
            Series {
                name: "filled",
                color: [210, 30, 30],
                points: (a.saturating_sub(1)..(b + 1).min(t))
                    .map(|k| (done.source_frames[k] as f64, at(k, d)))
                    .collect(),
            },
            Series {
                name: "observed, after",
                color: [40, 160, 90],
                points: seen(b..to),
            },
        ];
        let input = |k: usize| done.kept.as_ref().map_or(k, |kept| kept[k]);
        let marker = labels
            .get(input(i))
            .filter(|l| !l.is_empty())
            .cloned()
            .unwrap_or_else(|| format!("track {}", input(i)));
        let title = format!(
            "{marker}: {} frames filled ({}–{}), {}",
            b - a,
            done.source_frames[a],
            done.source_frames[b - 1],
            ["x", "y", "z"][d]
        );
        let path = dir.join(format!("gap_{g:02}.png"));
        line_plot(&title, "frame", ["x", "y", "z"][d], &series, false).save_png_and_svg(&path)?;
        written.push(path);
    }
    Ok(written)
}

/// `epe_per_frame.png`: the EPE of each frame on `what` the run measures.
fn epe_plot(per_frame: &[f64], what: &str, dir: &Path) -> Result<PathBuf> {
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
        &format!("EPE per frame on {what}"),
        "frame",
        "EPE ×1e-4",
        &series,
        false,
    )
    .save_png_and_svg(&path)?;
    Ok(path)
}

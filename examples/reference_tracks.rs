//! Tracks that are not seen in the reference frame: placing them by their neighbours'
//! motion (what doma does, docs/design.md §7) against dropping them, on tracker-like data
//! from the shipped meshes (`examples/tracker_data.rs`).
//!
//! ```sh
//! cargo run --release --example tracker_data -- /tmp/tracks
//! cargo run --release --example reference_tracks -- /tmp/tracks/md2_faerie_tapvid3d.npz 1000
//! ```
//! hides 20 % of the observations in spans (seed 0), fits DOMA-Affinity to every track
//! ("placed": placed by their neighbours, then learned with the field) and to the tracks
//! seen in the reference frame alone ("dropped"), and prints
//! the EPE ×1e-4 on the hidden observations of the tracks both fits have, and the placed
//! fit's on the tracks that the dropped fit cannot predict at all.

use std::path::PathBuf;

use anyhow::Context;
use burn::tensor::Device;
use doma::data::Trajectories;
use doma::data::mesh::as_points;
use doma::data::sequence::{LoadOptions, load_sequence_with};
use doma::field::{DomaFieldConfig, MotionField, Variant};
use doma::jacobian::JacobianKind;
use doma::train::{FitConfig, Trainer, WithSchedule};

/// The EPE ×1e-4 of `field` (fitted to `data`) on the entries `(frame, row)` with `truth`.
fn epe(
    field: &dyn MotionField,
    data: &Trajectories,
    entries: &[(usize, usize)],
    truth: &[[f32; 3]],
    device: &Device,
) -> anyhow::Result<f64> {
    let x = as_points(data.canonical());
    let mut total = 0.0;
    for (&(k, r), y) in entries.iter().zip(truth) {
        doma::warp::warp_frames(field, &[x[r]], k..k + 1, data.frames(), device, |_, p| {
            total += (0..3).map(|c| (p[0][c] - y[c]).abs() as f64).sum::<f64>();
            Ok(())
        })?;
    }
    Ok(1e4 * total / entries.len() as f64)
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path: PathBuf = args
        .next()
        .context("usage: reference_tracks FILE.npz [ITERS]")?
        .into();
    let iterations: usize = args.next().map_or(Ok(1000), |s| s.parse())?;
    let options = LoadOptions {
        drop_unobserved: true,
        hold_out: Some(doma::data::sequence::HoldOut {
            fraction: 0.2,
            spans: doma::gaps::spans::DEFAULT_SPANS,
            seed: 0,
        }),
        ..LoadOptions::default()
    };
    let seq = load_sequence_with(&path, &options)?;
    let held = seq.held_out.clone().context("nothing held out")?;
    let all = &seq.trajectories;
    let r = all.reference();
    let seen: Vec<usize> = (0..all.points())
        .filter(|&i| all.is_observed(r, i))
        .collect();
    let dropped = all.select_points(&seen)?;
    let mut row = vec![usize::MAX; all.points()];
    for (j, &i) in seen.iter().enumerate() {
        row[i] = j;
    }
    let device = Device::flex();
    let config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
        .with_jacobian(JacobianKind::Analytic)
        .with_iterations(iterations);
    let placed_fit = Trainer::from_config(&config, all, &device)?.run()?;
    // The fit learned the canonical positions of the tracks unseen in the reference frame.
    let learned = match &placed_fit.canonical {
        Some(x) => all.clone().with_canonical(x.clone())?,
        None => all.clone(),
    };
    let all = &learned;
    let dropped_fit = Trainer::from_config(&config, &dropped, &device)?.run()?;
    // The hidden entries of tracks seen in the reference frame, and of the others.
    let (mut both, mut both_truth, mut others, mut others_truth) = (vec![], vec![], vec![], vec![]);
    for (&(k, i), &y) in held.entries.iter().zip(&held.truth) {
        if row[i] == usize::MAX {
            others.push((k, i));
            others_truth.push(y);
        } else {
            both.push((k, i));
            both_truth.push(y);
        }
    }
    let both_rows: Vec<(usize, usize)> = both.iter().map(|&(k, i)| (k, row[i])).collect();
    println!(
        "{}: {} tracks, {} seen in reference frame {r}; {iterations} iterations",
        path.display(),
        all.points(),
        seen.len()
    );
    println!(
        "  hidden observations of tracks seen in frame {r} ({}): placed {:.2}, dropped {:.2}",
        both.len(),
        epe(&placed_fit.field, all, &both, &both_truth, &device)?,
        epe(
            &dropped_fit.field,
            &dropped,
            &both_rows,
            &both_truth,
            &device
        )?
    );
    if !others.is_empty() {
        println!(
            "  hidden observations of the other tracks ({}): placed {:.2}, dropped {:.2} \
             (the dropped fit's field at their placed positions)",
            others.len(),
            epe(&placed_fit.field, all, &others, &others_truth, &device)?,
            epe(&dropped_fit.field, all, &others, &others_truth, &device)?
        );
    }
    Ok(())
}

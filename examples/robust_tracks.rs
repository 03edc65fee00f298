//! Outliers in tracks: the trajectory loss's L1 against Huber and Charbonnier penalties and
//! against L1 with a tracker's confidence weights, on the faerie's "taunt" clip seen by the
//! simulated tracker (`doma::data::tracker`) with a fraction of its observations displaced.
//!
//! ```sh
//! cargo run --release --example robust_tracks -- 0.05 1000
//! ```
//! displaces 5 % of the observed entries by 0.3 box diagonals in a random direction (as a
//! tracker that jumps to another surface), gives them confidence 0.1 (1 elsewhere), hides
//! 20 % of the observations in spans (seed 0), fits DOMA-Affinity with each penalty, and
//! prints the EPE ×1e-4 of the hidden observations against the *true* positions.

use anyhow::Context;
use burn::tensor::Device;
use doma::data::layout::TrackFile;
use doma::data::mesh::{as_points, read_obj};
use doma::data::sequence::{LoadOptions, load_sequence_with};
use doma::data::tracker::{TrackerConfig, simulate};
use doma::data::traj::read_traj;
use doma::field::{DomaFieldConfig, Variant};
use doma::jacobian::JacobianKind;
use doma::loss::DataPenalty;
use doma::train::{FitConfig, Trainer, WithSchedule};
use doma_formats::npy::NpyValues;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let fraction: f64 = args.next().map_or(Ok(0.05), |s| s.parse())?;
    let iterations: usize = args.next().map_or(Ok(1000), |s| s.parse())?;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let truth = read_traj(root.join("md2_faerie.traj"))?.select_frames(95..112, 1)?;
    let faces = read_obj(root.join("md2_faerie.obj"))?.faces;
    let view = simulate(&truth, &faces, &TrackerConfig::default())?;
    let (t, n) = (truth.frames(), truth.points());
    let clean = view.camera_positions();
    let observed = view.observed();
    // Outliers: observed entries moved by 0.3 diagonals of the frame-0 box.
    let first = as_points(&clean[..3 * n]);
    let diagonal = (0..3)
        .map(|c| {
            let (lo, hi) = first
                .iter()
                .fold((f32::MAX, f32::MIN), |(l, h), p| (l.min(p[c]), h.max(p[c])));
            (hi - lo).powi(2)
        })
        .sum::<f32>()
        .sqrt();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut noisy = clean.clone();
    let mut confidence = vec![1.0f32; t * n];
    for e in (0..t * n).filter(|&e| observed[e]) {
        if rng.random_bool(fraction) {
            let d: [f32; 3] = std::array::from_fn(|_| rng.random_range(-1.0f32..1.0));
            let len = d.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-6);
            for c in 0..3 {
                noisy[3 * e + c] += 0.3 * diagonal * d[c] / len;
            }
            confidence[e] = 0.1;
        }
    }
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("noisy.npz");
    std::fs::write(
        &path,
        doma_formats::npz::encode_npz_values(&[
            ("tracks_XYZ", &[t, n, 3], NpyValues::F32(&noisy)),
            ("visibility", &[t, n], NpyValues::Bool(&observed)),
            ("confidence", &[t, n], NpyValues::F32(&confidence)),
        ]),
    )?;
    let device = Device::flex();
    println!(
        "faerie frames 95..112, {:.0} % of the observations displaced, {iterations} iterations",
        100.0 * fraction
    );
    for (name, penalty, weighted) in [
        ("L1", DataPenalty::L1, false),
        ("Huber 0.01", DataPenalty::Huber { delta: 0.01 }, false),
        (
            "Charbonnier 0.01",
            DataPenalty::Charbonnier { epsilon: 0.01 },
            false,
        ),
        ("L1, confidence", DataPenalty::L1, true),
    ] {
        let options = LoadOptions {
            file: TrackFile {
                confidence: weighted.then(|| "confidence".to_string()),
                ..TrackFile::default()
            },
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
        let kept = seq.kept.clone().unwrap_or_else(|| (0..n).collect());
        let mut config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity))
            .with_jacobian(JacobianKind::Analytic)
            .with_iterations(iterations);
        config.loss.data_penalty = Some(penalty);
        let fitted = Trainer::from_config(&config, &seq.trajectories, &device)?.run()?;
        let data = match &fitted.canonical {
            Some(x) => seq.trajectories.clone().with_canonical(x.clone())?,
            None => seq.trajectories.clone(),
        };
        let x = as_points(data.canonical());
        let mut total = 0.0;
        for &(k, r) in &held.entries {
            let e = 3 * (k * n + kept[r]);
            let y: [f32; 3] = std::array::from_fn(|c| (clean[e + c] - seq.center[c]) / seq.scale);
            doma::warp::warp_frames(&fitted.field, &[x[r]], k..k + 1, t, &device, |_, p| {
                total += (0..3).map(|c| (p[0][c] - y[c]).abs() as f64).sum::<f64>();
                Ok(())
            })?;
        }
        println!(
            "  {name:<18} EPE on {} hidden observations (true positions): {:.2}",
            held.entries.len(),
            1e4 * total / held.entries.len() as f64
        );
    }
    Ok(())
}

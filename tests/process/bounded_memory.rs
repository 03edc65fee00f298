//! Evaluation and warping in bounded memory: 10⁶ points warped over 100 frames, and the
//! EPE of 10⁶ tracks, measured by a counting global allocator (every heap byte of the
//! process, Burn's and rayon's threads included). Holding every frame's prediction would
//! take 10⁶ × 100 × 12 B = 1.2 GB; the stated bound is one frame's output plus one chunk's
//! activations (`doma::warp::WARP_CHUNK` rows).

use burn::tensor::{Device, Tensor, TensorData};
use doma::data::Trajectories;
use doma::field::{DomaFieldConfig, MotionField, Variant};
use doma::metrics::field_epe_per_frame;
use doma::siren::WithSirenShape;
use doma::warp::{WARP_CHUNK, warp_frames};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[path = "counting.rs"]
mod counting;

use counting::{MB, extra_peak};

#[test]
fn warping_and_evaluating_a_million_points_stays_within_a_chunk() {
    let device = Device::flex();
    // A 32-wide SIREN keeps the test fast; the chunk's activations scale with the width
    // (the bound for the paper's 128 is in `WARP_CHUNK`'s docs).
    let hidden = 32;
    let field = DomaFieldConfig::new(Variant::Affinity)
        .with_hidden(hidden)
        .init(0, &device);
    let n = 1_000_000;
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let points: Vec<[f32; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0f32..1.0)))
        .collect();
    // One frame's output, plus one chunk through the network (`WARP_CHUNK`'s docs): the
    // pre-activation and output of each of the 3 sine layers, and the input and head.
    let frame = n * 12;
    let chunk = WARP_CHUNK * 4 * (2 * 3 * hidden + 64);
    let bound = frame + chunk + 4 * MB;

    let frames = 100;
    let mut seen = 0;
    let mut first = Vec::new();
    let warp_peak = extra_peak(|| {
        warp_frames(&field, &points, 0..frames, frames, &device, |k, y| {
            assert_eq!(y.len(), n);
            assert!(y.iter().flatten().all(|c| c.is_finite()), "frame {k}");
            if k == 0 {
                first = y[..4].to_vec();
            }
            seen += 1;
            Ok(())
        })
        .unwrap();
    });
    assert_eq!(seen, frames);
    // The streamed warp is the field's warp.
    let x = Tensor::<2>::from_data(
        TensorData::new(points[..4].as_flattened().to_vec(), [4, 3]),
        &device,
    );
    let direct: Vec<f32> = doma::readback::to_vec(field.warp(x, -1.0)).unwrap();
    for (a, b) in first.as_flattened().iter().zip(&direct) {
        assert!((a - b).abs() < 1e-5, "{a} vs {b}");
    }
    eprintln!(
        "warp of {n} points over {frames} frames: peak {:.1} MB above the input (bound {:.1} MB; all frames at once: {:.0} MB)",
        warp_peak as f64 / MB as f64,
        bound as f64 / MB as f64,
        (n * frames * 12) as f64 / MB as f64
    );
    assert!(
        warp_peak < bound,
        "warp peak {warp_peak} B over the bound {bound} B"
    );

    // The EPE of a million tracks over 10 frames: the tracks themselves are the input.
    let t = 10;
    let positions: Vec<f32> = (0..t * n * 3).map(|i| (i % 1999) as f32 / 1999.0).collect();
    let truth = Trajectories::new(t, n, positions).unwrap();
    let mut per_frame = Vec::new();
    let eval_peak = extra_peak(|| {
        per_frame = field_epe_per_frame(&field, &truth, &device).unwrap();
    });
    assert_eq!(per_frame.len(), t);
    assert!(per_frame.iter().all(|e| e.is_finite() && *e > 0.0));
    eprintln!(
        "EPE of {n} tracks over {t} frames: peak {:.1} MB above the data (bound {:.1} MB; all predictions at once: {:.0} MB)",
        eval_peak as f64 / MB as f64,
        (bound + frame) as f64 / MB as f64,
        (n * t * 12) as f64 / MB as f64
    );
    // The canonical points are copied out of the tracks once: one frame more.
    assert!(
        eval_peak < bound + frame,
        "EPE peak {eval_peak} B over the bound"
    );
}

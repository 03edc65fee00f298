//! Tracker output in bounded memory: reading and fitting 10⁵ tracks over 100 frames with a
//! third of the entries unobserved takes no more than the same tracks complete, plus the
//! mask and the observed rows' indices. Measured by a counting global allocator.

#[path = "counting.rs"]
mod counting;

use burn::tensor::Device;
use counting::{MB, extra_peak};
use doma::data::layout::TrackFile;
use doma::data::npy::write_npy;
use doma::data::sequence::{LoadOptions, load_sequence_with};
use doma::field::{DomaFieldConfig, Variant};
use doma::jacobian::JacobianKind;
use doma::siren::WithSirenShape;
use doma::train::{FitConfig, Trainer, WithSchedule};
use doma_formats::npy::NpyValues;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn masked_tracks_read_and_fit_within_the_dense_memory_plus_the_mask() {
    let (t, n) = (100, 100_000);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let start: Vec<[f32; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0f32..1.0)))
        .collect();
    let mut positions = Vec::with_capacity(t * n * 3);
    for k in 0..t {
        let a = 0.01 * k as f32;
        for p in &start {
            positions.extend_from_slice(&[p[0] + a, p[1] * (1.0 + a), p[2] - a * p[0]]);
        }
    }
    // A third of the entries hidden, in runs along each track.
    let observed: Vec<bool> = (0..t * n)
        .map(|e| (e / n + 7 * (e % n)) % 30 >= 10)
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let (dense, masked) = (dir.path().join("dense.npy"), dir.path().join("masked.npz"));
    write_npy(&dense, &[t, n, 3], &positions).unwrap();
    std::fs::write(
        &masked,
        doma_formats::npz::encode_npz_values(&[
            ("tracks_XYZ", &[t, n, 3], NpyValues::F32(&positions)),
            ("visibility", &[t, n], NpyValues::Bool(&observed)),
        ]),
    )
    .unwrap();
    drop(positions);
    let device = Device::flex();
    let config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(32))
        .with_iterations(1)
        .with_jacobian(JacobianKind::Analytic)
        .with_points_per_step(Some(2048));
    let fit = |path: &std::path::Path| {
        let options = LoadOptions {
            file: TrackFile::default(),
            ..LoadOptions::default()
        };
        let seq = load_sequence_with(path, &options).unwrap();
        let fitted = Trainer::from_config(&config, &seq.trajectories, &device)
            .unwrap()
            .run()
            .unwrap();
        assert_eq!(fitted.history.len(), 1);
        seq.trajectories.observed_count()
    };
    let mut counts = (0, 0);
    let dense_peak = extra_peak(|| counts.0 = fit(&dense));
    let masked_peak = extra_peak(|| counts.1 = fit(&masked));
    let seen = observed.iter().filter(|&&o| o).count();
    assert_eq!(counts, (t * n, seen));
    // The mask (a bool per entry) and the observed rows' indices on the device (an i64
    // each); the mask is also decoded once through f32, as every array is.
    let allowance = t * n * (1 + 4) + seen * 8;
    eprintln!(
        "{n} tracks × {t} frames, {:.0} % observed: peak {:.0} MB complete, {:.0} MB masked \
         (allowance for the mask and rows {:.0} MB)",
        100.0 * seen as f64 / (t * n) as f64,
        dense_peak as f64 / MB as f64,
        masked_peak as f64 / MB as f64,
        allowance as f64 / MB as f64
    );
    assert!(
        masked_peak <= dense_peak + allowance,
        "masked peak {masked_peak} B over {dense_peak} + {allowance}"
    );
}

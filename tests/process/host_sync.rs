//! The fit loop makes no host sync inside a step: `Trainer::step` reads nothing
//! back, and `Trainer::iteration` reads once, its losses, after its last step. Counted by
//! `doma::readback::reads`, through which the crate makes every device → host read
//! (clippy refuses Burn's read methods elsewhere in `src/`). On flex and on wgpu (lavapipe
//! under CI), for both Jacobian methods, with `L_H` (its own jittered points), the
//! elasticity loss and a per-step subset of the training points.
//!
//! One test function: the counter is per process, and tests of one binary run in parallel.

#[path = "../common/mod.rs"]
mod common;

use burn::tensor::Device;
use doma::data::Trajectories;
use doma::field::{DomaFieldConfig, Variant};
use doma::jacobian::JacobianKind;
use doma::prelude::WithSirenShape;
use doma::readback::reads;
use doma::train::{FitConfig, Trainer};

/// 120 points on their own paths over 4 frames.
fn data() -> Trajectories {
    let (t, n) = (4, 120);
    let pos = (0..t * n * 3)
        .map(|i| ((i * 7919 % 113) as f32 / 113.0) - 0.5)
        .collect();
    Trajectories::new(t, n, pos).unwrap()
}

/// `subsets`: the `points_per_step` settings to check (all of them on flex; on wgpu, whose
/// kernels compile on first use, one).
fn check(device: &Device, label: &str, subsets: &[Option<usize>]) {
    let data = data();
    for method in [JacobianKind::Autodiff, JacobianKind::Analytic] {
        for &subset in subsets {
            let config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(16))
                .with_smoothness_weight(0.1)
                .with_elasticity_weight(0.01)
                .with_points_per_step(subset)
                .with_jacobian(method);
            let mut trainer = Trainer::from_config(&config, &data, device).unwrap();
            let case = format!("{label}, {method}, points per step {subset:?}");

            let before = reads();
            let record = trainer.iteration().unwrap().clone();
            assert_eq!(
                reads() - before,
                1,
                "{case}: an iteration of {} steps reads once",
                data.frames()
            );
            assert!(record.total_loss.is_finite());

            let before = reads();
            let losses: Vec<_> = (0..5).map(|k| trainer.step(k % 4, 1e-4).unwrap()).collect();
            assert_eq!(reads(), before, "{case}: five steps read nothing back");
            // The losses are there when asked for: one read for all five.
            let values: Vec<f64> =
                doma::readback::to_vec(burn::tensor::Tensor::stack::<2>(losses, 0)).unwrap();
            assert_eq!(values.len(), 10);
            assert!(values.iter().all(|v| v.is_finite()), "{case}: {values:?}");
            assert_eq!(reads(), before + 1);
        }
    }
}

#[test]
fn a_step_reads_nothing_back_and_an_iteration_reads_once() {
    check(&Device::flex(), "flex", &[None, Some(50)]);
    if let Some(device) =
        common::wgpu_device_or_skip("a_step_reads_nothing_back_and_an_iteration_reads_once")
    {
        check(&device, "wgpu", &[Some(50)]);
    }
}

//! The trajectory objective's steps against losses computed on the host.

use burn::module::Module;
use rand::SeedableRng;

use super::*;
use crate::field::{DomaFieldConfig, Variant};
use crate::jacobian::JacobianKind;
use crate::siren::WithSirenShape;
use crate::train::rows::step_rows;

/// 40 points moving on their own paths over 3 frames.
fn data() -> Trajectories {
    let (t, n) = (3, 40);
    let pos = (0..t * n * 3)
        .map(|i| ((i * 7919 % 113) as f32 / 113.0) - 0.5)
        .collect();
    Trajectories::new(t, n, pos).unwrap()
}

#[test]
fn points_per_step_takes_distinct_rows_and_the_l1_over_them_alone() {
    let data = data();
    let device = Device::flex();
    let config = FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(16))
        .with_jacobian(JacobianKind::Autodiff)
        .with_points_per_step(Some(7));
    let field = config
        .model
        .init(0, data.frame(0), &device.clone().autodiff());
    let mut objective = TrajectoryObjective::new(&field, &config, &data, &device).unwrap();
    let order = [2, 0, 1];
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    Objective::<crate::field::model::Model>::prepare_iteration(&mut objective, &order, &mut rng);
    // The rows a step would draw for itself from the same stream: the same rows.
    let mut replay = ChaCha8Rng::seed_from_u64(5);
    let drawn: Vec<Vec<i64>> = order
        .iter()
        .map(|_| step_rows(40, 7, &mut replay))
        .collect();
    let rows = objective.rows.prepared_rows().unwrap();
    let rows: Vec<i64> = crate::readback::to_vec(rows).unwrap();
    assert_eq!(rows, drawn.concat());
    for step in &drawn {
        let distinct: std::collections::BTreeSet<_> = step.iter().collect();
        assert_eq!(distinct.len(), 7);
        assert!(step.iter().all(|&r| (0..40).contains(&r)));
    }
    // Each step's L1 is the mean |y − ŷ| over its 7 rows' 21 coordinates, computed here
    // on the host from the field's prediction of every point.
    let inference = field.clone().valid();
    for (s, &k) in order.iter().enumerate() {
        let (l1, _) = objective.step_loss(&field, k, 0, &mut rng).unwrap();
        let l1 = crate::readback::to_vec::<f64, 1, _>(l1).unwrap()[0];
        let all: Vec<f32> =
            crate::readback::to_vec(inference.warp(data.frame_tensor(0, &device), data.time(k)))
                .unwrap();
        let target = data.frame(k);
        let expected = drawn[s]
            .iter()
            .flat_map(|&r| (0..3).map(move |c| 3 * r as usize + c))
            .map(|i| (all[i] - target[i]).abs() as f64)
            .sum::<f64>()
            / 21.0;
        assert!(
            (l1 - expected).abs() < 1e-6 * expected.max(1.0),
            "{l1} vs {expected}"
        );
    }
}

#[test]
fn a_masked_frame_s_l1_is_over_its_observed_rows_and_an_empty_frame_s_is_zero() {
    let full = data();
    let mut observed = vec![true; 3 * 40];
    // Frame 1 observes the even rows only; frame 2 observes none.
    for i in 0..40 {
        observed[40 + i] = i % 2 == 0;
        observed[80 + i] = false;
    }
    let masked = crate::data::tracks::Tracks::new(3, 40, full.positions().to_vec(), observed)
        .unwrap()
        .into_trajectories(Some(0))
        .unwrap();
    let device = Device::flex();
    let config = FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(16))
        .with_jacobian(JacobianKind::Autodiff);
    let field = config
        .model
        .init(0, masked.canonical(), &device.clone().autodiff());
    let mut objective = TrajectoryObjective::new(&field, &config, &masked, &device).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let inference = field.clone().valid();
    let all: Vec<f32> =
        crate::readback::to_vec(inference.warp(masked.canonical_tensor(&device), masked.time(1)))
            .unwrap();
    let target = full.frame(1);
    let expected = (0..40)
        .step_by(2)
        .flat_map(|r| (0..3).map(move |c| 3 * r + c))
        .map(|i| (all[i] - target[i]).abs() as f64)
        .sum::<f64>()
        / 60.0;
    let (l1, _) = objective.step_loss(&field, 1, 0, &mut rng).unwrap();
    let l1 = crate::readback::to_vec::<f64, 1, _>(l1).unwrap()[0];
    assert!(
        (l1 - expected).abs() < 1e-6 * expected.max(1.0),
        "{l1} vs {expected}"
    );
    let (l1, total) = objective.step_loss(&field, 2, 0, &mut rng).unwrap();
    let read = |t| crate::readback::to_vec::<f64, 1, _>(t).unwrap()[0];
    assert_eq!((read(l1), read(total)), (0.0, 0.0));
}

/// What `Trainer::step_frames` minimises: the sum of the frames' losses, whose
/// gradient is the sum of theirs.
#[test]
fn the_gradient_of_a_batch_of_frames_is_the_sum_of_theirs() {
    let data = data();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(16))
        .with_jacobian(JacobianKind::Analytic);
    let field = DomaFieldConfig::new(Variant::Affinity)
        .with_hidden(16)
        .init(1, &ad);
    let mut objective = TrajectoryObjective::new(&field, &config, &data, &device).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut loss = |k: usize| objective.step_loss(&field, k, 0, &mut rng).unwrap().1;
    let grad = |total: Tensor<1>| -> Vec<f64> {
        let grads = total.backward();
        let layer = &field.siren.sine[0];
        crate::readback::to_vec(layer.weight.val().grad(&grads).expect("a gradient")).unwrap()
    };
    let (g0, g2) = (grad(loss(0)), grad(loss(2)));
    let batch = grad(loss(0) + loss(2));
    for ((a, b), s) in g0.iter().zip(&g2).zip(&batch) {
        assert!(
            (a + b - s).abs() <= 1e-6 * (1.0 + s.abs()),
            "{a} + {b} vs {s}"
        );
    }
}

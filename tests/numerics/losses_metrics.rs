//! Losses and metrics on hand-computed values.

use crate::common;

use burn::tensor::{Device, Tensor, TensorData};
use common::{tensor2, to_vec};
use doma::data::Trajectories;
use doma::loss::{self, SmoothnessNorm};
use doma::metrics;
use doma::prelude::*;

fn scalar(t: Tensor<1>) -> f64 {
    to_vec(t)[0]
}

/// A `[3, N, 3]` warp tangent with the same matrix `M` at every point
/// (`tangent[k, n, i] = M[i][k]`).
fn warp_tangent(m: [[f64; 3]; 3], n: usize, device: &Device) -> Tensor<3> {
    let mut v = Vec::new();
    for k in 0..3 {
        for _ in 0..n {
            for row in &m {
                v.push(row[k]);
            }
        }
    }
    Tensor::from_data(TensorData::new(v, [3, n, 3]), device)
}

/// The robustifier by hand: ρ(q) = 2(q/c)²/((q/c)² + 4), c = 0.03.
fn rho(q: f64) -> f64 {
    let z = (q / 0.03).powi(2);
    2.0 * z / (z + 4.0)
}

#[test]
fn trajectory_l1_is_the_mean_over_coordinates() {
    let d = Device::flex();
    let pred = tensor2(vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [2, 3], &d);
    let target = tensor2(vec![1.0, 0.0, 0.0, 1.0, 3.0, 1.0], [2, 3], &d);
    // |diffs| = 1, 0, 0, 0, 2, 0 → 3 / 6.
    assert!((scalar(loss::trajectory_l1(pred, target)) - 0.5).abs() < 1e-7);
}

#[test]
fn the_temporal_loss_is_the_mean_squared_second_difference_over_delta_squared() {
    let d = Device::flex();
    // Point i follows y = (a_i t², b_i t, 0) with a = (1, 2), b = (5, −3), sampled at
    // t = 0.3 ∓ 0.1: the second difference is (2 a_i Δ², 0, 0) (the linear part cancels),
    // so ‖·/Δ²‖² = 4 a_i², and the mean over the two points is (4 + 16) / 2 = 10.
    let (a, b, delta) = ([1.0, 2.0], [5.0, -3.0], 0.1);
    let at = |t: f64| {
        let v = (0..2).flat_map(|i| [a[i] * t * t, b[i] * t, 0.0]).collect();
        tensor2(v, [2, 3], &d)
    };
    let got = scalar(loss::acceleration(
        at(0.3 - delta),
        at(0.3),
        at(0.3 + delta),
        delta,
    ));
    assert!((got - 10.0).abs() < 1e-3, "{got}");
    // A motion linear in time has none.
    let linear = |t: f64| tensor2(vec![t, 2.0 * t, -t], [1, 3], &d);
    let none = scalar(loss::acceleration(
        linear(0.0),
        linear(0.5),
        linear(1.0),
        0.5,
    ));
    assert!(none.abs() < 1e-6, "{none}");
}

#[test]
fn smoothness_in_both_forms() {
    let d = Device::flex();
    // [3, P = 2, O = 2]: entries 0.1, 0.2, ..., 1.2.
    let v: Vec<f64> = (1..=12).map(|i| i as f64 / 10.0).collect();
    let tangent = Tensor::<3>::from_data(TensorData::new(v.clone(), [3, 2, 2]), &d);
    let squared: f64 = v.iter().map(|x| x * x).sum::<f64>() / 2.0; // 6.5 / 2
    assert!((squared - 3.25).abs() < 1e-12);
    let got = scalar(loss::smoothness(tangent.clone(), SmoothnessNorm::Squared));
    assert!((got - 3.25).abs() < 1e-5, "{got}");
    let charb: f64 = v.iter().map(|x| (x * x + 1.0).sqrt() - 1.0).sum::<f64>() / 2.0;
    let got = scalar(loss::smoothness(tangent, SmoothnessNorm::Charbonnier));
    assert!((got - charb).abs() < 1e-5, "{got} vs {charb}");
}

#[test]
fn elasticity_of_known_singular_values() {
    let d = Device::flex();
    // diag(2, 1, 1): σ = (2, 1, 1), q = ln² 2.
    let q = 2f64.ln().powi(2);
    let got = scalar(loss::elasticity(warp_tangent(
        [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        4,
        &d,
    )));
    assert!((got - rho(q)).abs() < 1e-4, "{got} vs {}", rho(q));

    // [[1, 2, 0], [0, 1, 0], [0, 0, 0.9]]: the 2×2 block has σ = √2 ± 1 (det 1, σ₁² + σ₂² = 6).
    let s = 2f64.sqrt();
    let q = (s + 1.0).ln().powi(2) + (s - 1.0).ln().powi(2) + 0.9f64.ln().powi(2);
    let got = scalar(loss::elasticity(warp_tangent(
        [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.9]],
        3,
        &d,
    )));
    assert!((got - rho(q)).abs() < 1e-4, "{got} vs {}", rho(q));

    // A rotation has σ = 1: no elastic energy.
    let (sn, cs) = 0.8f64.sin_cos();
    let got = scalar(loss::elasticity(warp_tangent(
        [[cs, -sn, 0.0], [sn, cs, 0.0], [0.0, 0.0, 1.0]],
        5,
        &d,
    )));
    assert!(got.abs() < 1e-6, "{got}");
}

#[test]
fn eigenvalues_of_symmetric_matrices() {
    let d = Device::flex();
    let col = |v: f64| tensor2(vec![v], [1, 1], &d);
    let eig = |s: [f64; 6]| -> Vec<f64> {
        loss::symmetric_eigenvalues(s.map(col))
            .into_iter()
            .map(|t| to_vec(t)[0])
            .collect()
    };
    // diag(1, 3, 2) → 3, 2, 1.
    let e = eig([1.0, 3.0, 2.0, 0.0, 0.0, 0.0]);
    for (a, b) in e.iter().zip([3.0, 2.0, 1.0]) {
        assert!((a - b).abs() < 1e-4, "{e:?}");
    }
    // [[2, 1, 0], [1, 2, 0], [0, 0, 5]] → 5, 3, 1.
    let e = eig([2.0, 2.0, 5.0, 1.0, 0.0, 0.0]);
    for (a, b) in e.iter().zip([5.0, 3.0, 1.0]) {
        assert!((a - b).abs() < 1e-4, "{e:?}");
    }
    // An isotropic matrix (a pure scaling) stays finite.
    let e = eig([2.0, 2.0, 2.0, 0.0, 0.0, 0.0]);
    for a in &e {
        assert!((a - 2.0).abs() < 1e-4, "{e:?}");
    }
}

#[test]
fn epe_sums_coordinates_and_averages_points_and_frames() {
    // 2 frames, 2 points.
    let truth = Trajectories::new(2, 2, vec![0.0; 12]).unwrap();
    let predicted = Trajectories::new(
        2,
        2,
        vec![
            0.0, 0.0, 0.0, /**/ 1.0, 0.0, 0.0, // frame 0: errors 0 and 1
            1.0, -1.0, 0.5, /**/ 0.0, 0.0, -0.5, // frame 1: errors 2.5 and 0.5
        ],
    )
    .unwrap();
    let per_frame = metrics::epe_per_frame(&predicted, &truth).unwrap();
    assert_eq!(per_frame, vec![0.5, 1.5]);
    assert_eq!(metrics::epe(&predicted, &truth).unwrap(), 1.0);
    let other = Trajectories::new(3, 2, vec![0.0; 18]).unwrap();
    assert!(metrics::epe(&predicted, &other).is_err());
}

#[test]
fn a_perfect_field_has_zero_epe() {
    // A zero-output Trans field is the identity; on a static sequence its EPE is 0.
    let d = Device::flex();
    let field = doma::field::DomaFieldConfig::new(doma::field::Variant::Trans)
        .with_hidden(8)
        .init(0, &d);
    let zero_out = doma::siren::Siren::from_weights(
        &field
            .siren
            .to_weights()
            .into_iter()
            .enumerate()
            .map(|(i, mut l)| {
                if i == field.siren.sine.len() {
                    l.weight.iter_mut().for_each(|w| *w = 0.0);
                    l.bias.iter_mut().for_each(|b| *b = 0.0);
                }
                l
            })
            .collect::<Vec<_>>(),
        30.0,
        &d,
    );
    let field = doma::field::DomaField {
        siren: zero_out,
        variant: field.variant,
        time_scale: field.time_scale,
    };
    let p: Vec<f32> = common::random_points(10, 1)
        .iter()
        .map(|v| *v as f32)
        .collect();
    let still = Trajectories::new(3, 10, [p.clone(), p.clone(), p].concat()).unwrap();
    assert_eq!(metrics::evaluate_epe(&field, &still, &d).unwrap(), 0.0);
}

#[test]
fn robust_penalties_and_confidence_weights_match_hand_computed_values() {
    use doma::loss::DataPenalty;
    let d = Device::flex();
    // Residuals 0.005, −0.02, 0 for point 0 and 0.1, 0, 0 for point 1.
    let pred = tensor2(vec![0.005, -0.02, 0.0, 0.1, 0.0, 0.0], [2, 3], &d);
    let target = tensor2(vec![0.0; 6], [2, 3], &d);
    let loss = |p, w: Option<Vec<f64>>| {
        let w = w.map(|w| tensor2(w, [2, 1], &d));
        scalar(loss::trajectory_loss(pred.clone(), target.clone(), p, w))
    };
    // L1: (0.005 + 0.02 + 0.1) / 6.
    assert!((loss(DataPenalty::L1, None) - 0.125 / 6.0).abs() < 1e-7);
    // Huber, δ = 0.01: 0.005²/0.02 = 0.00125; 0.02 − 0.005 = 0.015; 0.1 − 0.005 = 0.095.
    let huber = loss(DataPenalty::Huber { delta: 0.01 }, None);
    assert!(
        (huber - (0.00125 + 0.015 + 0.095) / 6.0).abs() < 1e-7,
        "{huber}"
    );
    // Charbonnier, ε = 0.01: √(r² + 10⁻⁴) − 0.01 per coordinate (0 for r = 0).
    let c = |r: f64| (r * r + 1e-4).sqrt() - 0.01;
    let charb = loss(DataPenalty::Charbonnier { epsilon: 0.01 }, None);
    let expected = (c(0.005) + c(0.02) + c(0.1)) / 6.0;
    assert!((charb - expected).abs() < 1e-7, "{charb} vs {expected}");
    // Weights 3 and 1: (3 · 0.025 + 1 · 0.1) / (3 · 4).
    let weighted = loss(DataPenalty::L1, Some(vec![3.0, 1.0]));
    assert!((weighted - 0.175 / 12.0).abs() < 1e-7, "{weighted}");
    // A zero weight removes a point; all-zero weights give 0, not NaN.
    let only_second = loss(DataPenalty::L1, Some(vec![0.0, 2.0]));
    assert!((only_second - 0.1 / 3.0).abs() < 1e-7);
    assert_eq!(loss(DataPenalty::L1, Some(vec![0.0, 0.0])), 0.0);
    // The unweighted L1 penalty is trajectory_l1, bit for bit.
    assert_eq!(
        loss(DataPenalty::L1, None).to_bits(),
        scalar(loss::trajectory_l1(pred.clone(), target.clone())).to_bits()
    );
    assert!(DataPenalty::Huber { delta: 0.0 }.validate().is_err());
    assert!(
        DataPenalty::Charbonnier { epsilon: f64::NAN }
            .validate()
            .is_err()
    );
}

#[test]
fn the_epe_of_masked_trajectories_averages_observed_entries_only() {
    use doma::data::tracks::Tracks;
    // 2 frames × 2 points; point 1 is unobserved in frame 1, where the prediction is far off.
    let truth = Tracks::new(
        2,
        2,
        vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        vec![true, true, true, false],
    )
    .unwrap()
    .into_trajectories(Some(0))
    .unwrap();
    let predicted = Trajectories::new(
        2,
        2,
        vec![0.5, 0.0, 0.0, 1.0, 0.25, 0.0, 0.0, 0.0, 0.0, 9.0, 9.0, 9.0],
    )
    .unwrap();
    // Frame 0: (0.5 + 0.25) / 2; frame 1: point 0 alone, 0.
    let per_frame = metrics::epe_per_frame(&predicted, &truth).unwrap();
    assert_eq!(per_frame, vec![0.375, 0.0]);
    assert_eq!(metrics::epe(&predicted, &truth).unwrap(), 0.1875);
}

//! The baselines (MLP-ReLU, PE.6, DCT-NeRF, BoneCloud): shapes, parameter counts, the
//! identity at their initial state, closed-form motions, and `L_H` in the common fit loop
//! (the Jacobians against finite differences are in `baselines_f64.rs`).

use crate::common;

use burn::module::Param;
use burn::tensor::{Device, Tensor, TensorData};
use common::{backward_lock, rel_err, tensor2, to_vec};
use doma::data::Trajectories;
use doma::field::MotionField;
use doma::field::baselines::bone_cloud::BoneCloudConfig;
use doma::field::baselines::dct::{DctConfig, dct_basis};
use doma::field::baselines::mlp::MlpConfig;
use doma::field::model::ModelConfig;
use doma::prelude::*;
use doma::train::{FitConfig, fit_model};

fn x(n: usize, seed: u64, device: &Device) -> Tensor<2> {
    tensor2(common::random_points(n, seed), [n, 3], device)
}

#[test]
fn parameter_counts_follow_the_layer_shapes() {
    // 6 × 128 ReLU on [x, t]: (4·128 + 128) + 5 (128² + 128) + (128·3 + 3).
    assert_eq!(MlpConfig::new().num_params(), 640 + 5 * 16_512 + 387);
    // PE.6 widens the input to 4 (1 + 2·6) = 52.
    assert_eq!(MlpConfig::new().with_pe_octaves(6).encoded_width(), 52);
    assert_eq!(
        MlpConfig::new().with_pe_octaves(6).num_params(),
        52 * 128 + 128 + 5 * 16_512 + 387
    );
    // DCT-NeRF: x only, K = min(T, 10) coefficients per coordinate.
    let dct = DctConfig::new(20);
    assert_eq!(dct.k(), 10);
    assert_eq!(dct.num_params(), 3 * 128 + 128 + 5 * 16_512 + 128 * 30 + 30);
    // BoneCloud: 3K positions + 9TK transforms.
    assert_eq!(
        BoneCloudConfig::new(20).num_params(),
        3 * 1024 + 9 * 20 * 1024
    );
    let device = Device::flex();
    let pts = common::random_points(50, 1)
        .iter()
        .map(|&v| v as f32)
        .collect::<Vec<_>>();
    let models: Vec<(usize, usize)> = vec![
        (
            MlpConfig::new().init(0, &device).param_count(),
            MlpConfig::new().num_params(),
        ),
        (
            DctConfig::new(20).init(0, &device).param_count(),
            dct.num_params(),
        ),
        (
            BoneCloudConfig::new(20)
                .init(&pts, 0, &device)
                .param_count(),
            BoneCloudConfig::new(20).num_params(),
        ),
    ];
    for (got, want) in models {
        assert_eq!(got, want);
    }
}

#[test]
fn every_baseline_is_the_identity_at_its_initial_state() {
    let device = Device::flex();
    let p = x(40, 2, &device);
    let host: Vec<f32> = to_vec(p.clone()).iter().map(|&v| v as f32).collect();
    let fields: Vec<(&str, Box<dyn MotionField>)> = vec![
        ("mlp", Box::new(MlpConfig::new().init(1, &device))),
        (
            "pe6",
            Box::new(MlpConfig::new().with_pe_octaves(6).init(1, &device)),
        ),
        ("dct", Box::new(DctConfig::new(8).init(1, &device))),
        (
            "bones",
            Box::new(
                BoneCloudConfig::new(8)
                    .with_bones(64)
                    .init(&host, 1, &device),
            ),
        ),
    ];
    for (name, f) in fields {
        for t in [-1.0, 0.0, 1.0] {
            let y = f.warp(p.clone(), t);
            assert_eq!(y.dims(), [40, 3], "{name}");
            assert!(
                rel_err(&to_vec(y), &to_vec(p.clone())) < 1e-5,
                "{name} at t = {t}"
            );
        }
    }
}

#[test]
fn the_dct_basis_is_orthonormal() {
    let t = 13;
    for i in 0..t {
        for j in 0..t {
            let dot: f64 = (0..t)
                .map(|k| dct_basis(i, k, t) * dct_basis(j, k, t))
                .sum();
            let want = if i == j { 1.0 } else { 0.0 };
            assert!((dot - want).abs() < 1e-12, "φ{i}·φ{j} = {dot}");
        }
    }
}

#[test]
fn bone_cloud_applies_a_bone_transform_in_closed_form() {
    let device = Device::flex();
    // One bone: every point's weight is 1, so frame 1 must be exactly R x + t with R a
    // quarter turn about z (6-D: a1 = (0, 1, 0), a2 = (−1, 0, 0)) and t = (1, 2, 3).
    let mut bc =
        BoneCloudConfig::new(2)
            .with_bones(1)
            .init(&[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], 0, &device);
    let pose = [
        1.0f32, 0., 0., 1., 0., 0., 0., 0., 0., 0., -1., 1., 0., 0., 0., 1., 2., 3.,
    ];
    bc.pose = Param::from_data(TensorData::new(pose.to_vec(), [2, 1, 9]), &device);
    let p = x(10, 4, &device);
    let y = to_vec(bc.warp(p.clone(), 1.0));
    let xs = to_vec(p);
    for i in 0..10 {
        let (a, b, c) = (xs[3 * i], xs[3 * i + 1], xs[3 * i + 2]);
        let want = [-b + 1.0, a + 2.0, c + 3.0];
        for k in 0..3 {
            assert!((y[3 * i + k] - want[k]).abs() < 1e-5, "point {i}");
        }
    }
    // The skinning weights of many bones sum to 1.
    let host: Vec<f32> = xs.iter().map(|&v| v as f32).collect();
    let many = BoneCloudConfig::new(2)
        .with_bones(32)
        .init(&host, 3, &device);
    let w = many.skinning_weights(doma::jacobian::Dual::constant(x(10, 5, &device)));
    for s in to_vec(w.value.sum_dim(1)) {
        assert!((s - 1.0).abs() < 1e-5);
    }
}

#[test]
fn the_smoothness_loss_trains_a_baseline_through_the_common_fit_loop() {
    let _g = backward_lock();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    // 4 frames of 30 points translating along x.
    let base = common::random_points(30, 6);
    let positions: Vec<f32> = (0..4)
        .flat_map(|k| {
            base.chunks(3)
                .flat_map(move |p| [p[0] + 0.1 * k as f64, p[1], p[2]])
        })
        .map(|v| v as f32)
        .collect();
    let data = Trajectories::new(4, 30, positions).unwrap();
    let mlp = MlpConfig::new()
        .with_hidden(32)
        .with_layers(3)
        .with_pe_octaves(6);
    let config = FitConfig::new(ModelConfig::Mlp(mlp.clone()))
        .with_iterations(20)
        .with_learning_rate(1e-3)
        .with_smoothness_weight(0.1);
    let model = mlp.init(0, &ad);
    let fitted = fit_model(model, &config, &data, &device).unwrap();
    let (first, last) = (&fitted.history[0], fitted.history.last().unwrap());
    assert!(
        last.trajectory_loss < first.trajectory_loss,
        "{first:?} → {last:?}"
    );
    // L_H is in the total once the output layer has moved off zero.
    assert!(last.total_loss > last.trajectory_loss, "{last:?}");
}

#[test]
fn the_analytic_jacobian_is_refused_for_models_without_siren_layers() {
    let device = Device::flex();
    let data = Trajectories::new(3, 8, (0..72).map(|i| i as f32 * 0.01).collect()).unwrap();
    for model in [
        ModelConfig::Mlp(MlpConfig::new().with_hidden(8)),
        ModelConfig::DctNerf(DctConfig::new(3).with_hidden(8)),
        ModelConfig::BoneCloud(BoneCloudConfig::new(3).with_bones(4)),
    ] {
        let name = model.paper_name();
        let analytic = FitConfig::new(model.clone())
            .with_iterations(1)
            .with_jacobian(doma::jacobian::JacobianKind::Analytic);
        match doma::train::fit(&analytic, &data, &device) {
            Err(doma::DomaError::InvalidConfig(m)) => {
                assert!(m.contains("analytic") && m.contains(name), "{m}")
            }
            other => panic!("{name}: analytic was not refused: {other:?}"),
        }
        // The model's own check says the same before anything is built.
        assert!(analytic.model.check_jacobian(analytic.jacobian).is_err());
        // Autodiff, the general method, applies.
        let _g = backward_lock();
        let fitted = doma::train::fit(&FitConfig::new(model).with_iterations(1), &data, &device);
        assert!(fitted.is_ok(), "{name}: {fitted:?}");
    }
}

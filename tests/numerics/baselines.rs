//! The baselines (MLP-ReLU, PE.6, DCT-NeRF, BANMO, BoneCloud): shapes, parameter counts, the
//! identity at their initial state, closed-form motions, and `L_H` in the common fit loop
//! (the Jacobians against finite differences are in `baselines_f64.rs`).

use crate::common;

use burn::module::Param;
use burn::tensor::{Device, Tensor, TensorData};
use common::{backward_lock, rel_err, tensor2, to_vec};
use doma::data::Trajectories;
use doma::field::MotionField;
use doma::field::baselines::banmo::{self, BanmoConfig, BoneTransforms};
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
        ModelConfig::Banmo(small_banmo(3)),
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

/// A BANMO of the authors' structure at a test's size.
fn small_banmo(frames: usize) -> BanmoConfig {
    BanmoConfig::new(frames)
        .with_code_size(16)
        .with_transform_width(32)
        .with_skin_width(16)
}

/// Row-major 3×3 product and transpose, on the host.
fn mat_mul(a: &[f64], b: &[f64]) -> [f64; 9] {
    let mut m = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            m[3 * i + j] = (0..3).map(|k| a[3 * i + k] * b[3 * k + j]).sum();
        }
    }
    m
}

fn transpose(a: &[f64]) -> [f64; 9] {
    let mut m = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            m[3 * i + j] = a[3 * j + i];
        }
    }
    m
}

#[test]
fn banmo_has_the_authors_parameter_count() {
    // The authors' module, built at their sizes: 696,111 registered parameters, of which
    // 324 (a density layer 256 → 1 and 64 → 1, and two scalars) never reach the warp;
    // 695,787 are trained: the transform network 644,374, the skinning MLP 48,217, the
    // pose code's linear map 2,816, the rest code 128, the bones 250, skin_aux 2.
    let config = BanmoConfig::new(20);
    assert_eq!(config.num_params(), 695_787);
    assert_eq!(
        config.num_params() + config.unused_authors_params(),
        696_111
    );
    assert_eq!(config.encoded_width(3), 63);
    assert_eq!(config.encoded_width(1), 21);
    let device = Device::flex();
    assert_eq!(config.init(0, &device).param_count(), 695_787);
    assert_eq!(ModelConfig::Banmo(config).num_params(), 695_787);
}

#[test]
fn banmo_rotation_maps_match_closed_forms() {
    let device = Device::flex();
    // A quarter turn about z, as an axis-angle and as a quaternion (real part first, not
    // normalised: the map normalises).
    let quarter = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let h = std::f64::consts::FRAC_PI_2;
    let r = to_vec(banmo::so3_exp(tensor2(vec![0.0, 0.0, h], [1, 3], &device)));
    let s2 = std::f64::consts::SQRT_2;
    let q = to_vec(banmo::quaternion_matrix(tensor2(
        vec![s2, 0.0, 0.0, s2],
        [1, 4],
        &device,
    )));
    for k in 0..9 {
        assert!((r[k] - quarter[k]).abs() < 1e-6, "exp: {r:?}");
        assert!((q[k] - quarter[k]).abs() < 1e-6, "quaternion: {q:?}");
    }
    // exp(0) is the identity exactly (the clamped angle multiplies a zero skew matrix).
    let zero = to_vec(banmo::so3_exp(tensor2(vec![0.0; 3], [1, 3], &device)));
    assert_eq!(zero, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    // A bone's motion relative to its rest pose composes back: rest ∘ Δ = pose.
    let rots = |seed: u64| banmo::so3_exp(x(4, seed, &device));
    let rest = BoneTransforms {
        rotations: rots(1),
        translations: x(4, 2, &device),
    };
    let pose = BoneTransforms {
        rotations: rots(3),
        translations: x(4, 4, &device),
    };
    let delta = pose.relative_to(&rest);
    let (rr, rt) = (to_vec(rest.rotations), to_vec(rest.translations));
    let (pr, pt) = (to_vec(pose.rotations), to_vec(pose.translations));
    let (dr, dt) = (to_vec(delta.rotations), to_vec(delta.translations));
    for b in 0..4 {
        let m = |v: &[f64]| v[9 * b..9 * b + 9].to_vec();
        let composed = mat_mul(&m(&rr), &m(&dr));
        for k in 0..9 {
            assert!((composed[k] - pr[9 * b + k]).abs() < 1e-5, "bone {b}");
        }
        for i in 0..3 {
            let moved: f64 = (0..3).map(|j| rr[9 * b + 3 * i + j] * dt[3 * b + j]).sum();
            assert!(
                (moved + rt[3 * b + i] - pt[3 * b + i]).abs() < 1e-5,
                "bone {b}"
            );
        }
    }
}

#[test]
fn banmo_with_an_identity_pose_reproduces_its_input() {
    let device = Device::flex();
    let p = x(30, 7, &device);
    for bones in [1, 25] {
        let mut m = small_banmo(5).with_bones(bones).init(3, &device);
        // A zero output layer: every code gives every bone exp(0) = I and τ = 0, so each
        // bone's motion relative to its rest pose is the identity, whatever the weights.
        let out = &mut m.transform.output;
        out.weight = out.weight.clone().map(|w| w.zeros_like());
        out.bias = out.bias.take().map(|b| b.map(|b| b.zeros_like()));
        for t in [-1.0, 0.0, 1.0] {
            let y = m.warp(p.clone(), t);
            assert!(
                rel_err(&to_vec(y), &to_vec(p.clone())) < 1e-6,
                "{bones} bones at t = {t}"
            );
        }
    }
}

#[test]
fn banmo_moves_every_point_rigidly_when_every_bone_moves_alike() {
    let device = Device::flex();
    let mut m = small_banmo(6).with_bones(8).init(5, &device);
    // Give every bone the first bone's rows of the transform network's output layer, scaled
    // up so that the motion is far from the identity: all bones then get the same rest
    // transform and the same transform at every frame, so the blend is that one rigid map.
    let out = &mut m.transform.output;
    out.weight = out
        .weight
        .clone()
        .map(|w| w.narrow(1, 0, 6).repeat_dim(1, 8).mul_scalar(40.0));
    out.bias = out
        .bias
        .take()
        .map(|b| b.map(|b| b.narrow(0, 0, 6).repeat_dim(0, 8)));
    let n = 20;
    let p = x(n, 8, &device);
    let frame = 4;
    let t = -1.0 + 2.0 * frame as f64 / 5.0;
    let (rest, pose) = m.rest_and_pose(frame);
    let delta = pose.relative_to(&rest);
    let (r, tau) = (to_vec(delta.rotations), to_vec(delta.translations));
    // A proper rotation, and not the identity.
    let rtr = mat_mul(&transpose(&r[..9]), &r[..9]);
    let eye = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    assert!(rel_err(&rtr, &eye) < 1e-5, "RᵀR = {rtr:?}");
    let off: f64 = (0..9).map(|k| (r[k] - eye[k]).abs()).fold(0.0, f64::max);
    assert!(off > 0.1, "the motion is near the identity: {r:?}");
    // The skinning weights themselves are far from uniform.
    let w = to_vec(
        m.skinning_weights(doma::jacobian::Dual::constant(p.clone()), &rest)
            .value,
    );
    let spread = w.iter().fold(0.0f64, |a, &v| a.max(v)) - w.iter().fold(1.0f64, |a, &v| a.min(v));
    assert!(spread > 0.05, "weights spread {spread}");
    let y = to_vec(m.warp(p.clone(), t));
    let xs = to_vec(p);
    for i in 0..n {
        for a in 0..3 {
            let want: f64 = (0..3).map(|b| r[3 * a + b] * xs[3 * i + b]).sum::<f64>() + tau[a];
            assert!(
                (y[3 * i + a] - want).abs() < 1e-4,
                "point {i}: {} vs {want}",
                y[3 * i + a]
            );
        }
    }
}

#[test]
fn banmo_skinning_weights_sum_to_one() {
    let device = Device::flex();
    let mut m = small_banmo(3).init(9, &device);
    // Spread the bones (centres, orientations, precisions) so the Gaussian terms differ.
    let noise = tensor2(
        common::random_points(84, 11)[..250]
            .iter()
            .map(|v| 0.5 * v)
            .collect(),
        [25, 10],
        &device,
    );
    m.bones = m.bones.clone().map(|b| b + noise);
    let p = x(50, 10, &device);
    let (rest, _) = m.rest_and_pose(1);
    let w = m
        .skinning_weights(doma::jacobian::Dual::constant(p), &rest)
        .value;
    assert_eq!(w.dims(), [50, 25]);
    for s in to_vec(w.clone().sum_dim(1)) {
        assert!((s - 1.0).abs() < 1e-5, "{s}");
    }
    assert!(to_vec(w).iter().all(|&v| (0.0..=1.0).contains(&v)));
}

//! Guided alignment: the AIAP and Chamfer losses on hand-computed values, the Chamfer
//! schedule, the DPF baseline (stacked weights, batched evaluation, parameter count,
//! Jacobian vs finite differences), checkpoints (bit-exact round trip, f16, bad files), and
//! a short Eq. 12 registration.

use crate::common;

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use common::{backward_lock, rel_err, tensor2, to_vec};
use doma::DomaError;
use doma::checkpoint::{Precision, encode_checkpoint, load_checkpoint, save_checkpoint};
use doma::data::Trajectories;
use doma::data::mesh::TriMesh;
use doma::field::dpf::DpfConfig;
use doma::field::{DomaFieldConfig, MotionField, Variant};
use doma::jacobian::{Autodiff, JacobianKind};
use doma::loss::{AiapNeighbourhoods, CHAMFER_BLOCK, aiap, chamfer};
use doma::prelude::*;
use doma::register::{RegistrationConfig, RegistrationTask, register};

fn points(v: &[[f32; 3]], device: &Device) -> Tensor<2> {
    Tensor::from_data(
        TensorData::new(v.as_flattened().to_vec(), [v.len(), 3]),
        device,
    )
}

fn scalar(t: Tensor<1>) -> f64 {
    to_vec(t)[0]
}

#[test]
fn aiap_is_zero_under_a_rigid_motion_and_hand_computed_under_a_stretch() {
    let device = Device::flex();
    let canonical: Vec<[f32; 3]> = (0..50)
        .map(|i| {
            let t = i as f32;
            [(t * 0.7).sin(), (t * 0.3).cos(), (t * 0.13).sin()]
        })
        .collect();
    let nb = AiapNeighbourhoods::new(&canonical, 5).unwrap();
    let (s, c) = 0.7f32.sin_cos();
    let moved: Vec<[f32; 3]> = canonical
        .iter()
        .map(|p| [c * p[0] - s * p[2] + 3.0, p[1] - 1.0, s * p[0] + c * p[2]])
        .collect();
    assert!(scalar(aiap(points(&moved, &device), &nb)) < 1e-5);

    // Points at x = 0, 1, 3 with K = 2: neighbour pairs (0,1), (1,0), (2,1) of lengths
    // 1, 1, 2. Scaling by 2 changes them by 1, 1, 2; each pair appears twice in its 2×2
    // matrix: (2 + 2 + 4) / (3 · 2 · 2) = 2/3.
    let line = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [3.0, 0.0, 0.0]];
    let nb = AiapNeighbourhoods::new(&line, 2).unwrap();
    let stretched: Vec<[f32; 3]> = line.iter().map(|p| [2.0 * p[0], 0.0, 0.0]).collect();
    assert!((scalar(aiap(points(&stretched, &device), &nb)) - 2.0 / 3.0).abs() < 1e-6);
    assert!(AiapNeighbourhoods::new(&line, 4).is_err());
    assert!(AiapNeighbourhoods::new(&line, 1).is_err());
}

#[test]
fn the_device_chamfer_loss_matches_the_kd_tree_and_has_the_right_gradient() {
    let _lock = backward_lock();
    let device = Device::flex();
    // More rows than one block, so that the blocking is exercised.
    let n = CHAMFER_BLOCK + 300;
    let a: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            let t = i as f32;
            [(t * 0.37).sin(), (t * 0.11).cos(), (t * 0.07).sin()]
        })
        .collect();
    let b: Vec<[f32; 3]> = (0..400)
        .map(|i| {
            let t = i as f32;
            [(t * 0.23).cos(), (t * 0.41).sin(), (t * 0.05).cos()]
        })
        .collect();
    let on_device = scalar(chamfer(points(&a, &device), points(&b, &device)));
    let tree = doma::metrics::chamfer(&a, &b).unwrap();
    assert!(
        (on_device - tree).abs() < 1e-4 * tree,
        "{on_device} vs {tree}"
    );

    // One point against one point: CD = 2|a − b|², ∂CD/∂a = 4 (a − b).
    let ad = device.clone().autodiff();
    let pa = tensor2(vec![0.5, -1.0, 2.0], [1, 3], &ad).require_grad();
    let pb = tensor2(vec![1.0, 1.0, 1.0], [1, 3], &ad);
    let loss = chamfer(pa.clone(), pb);
    assert!((scalar(loss.clone()) - 2.0 * (0.25 + 4.0 + 1.0)).abs() < 1e-5);
    let grads = loss.backward();
    let g = to_vec(pa.grad(&grads).unwrap());
    assert!(rel_err(&g, &[-2.0, -8.0, 4.0]) < 1e-5, "{g:?}");
}

#[test]
fn the_chamfer_weight_follows_the_authors_schedule() {
    let c = RegistrationConfig::new().with_iterations(100);
    // Off up to and including iteration 25 (= 0.25 n), then 1e3 · 0.95^(n − it − 1).
    assert_eq!(c.chamfer_weight_at(0), 0.0);
    assert_eq!(c.chamfer_weight_at(25), 0.0);
    assert!((c.chamfer_weight_at(26) - 1e3 * 0.95f64.powi(73)).abs() < 1e-9);
    assert_eq!(c.chamfer_weight_at(99), 1e3);
    assert!((c.schedule.lr_factor(0) - 1.0).abs() < 1e-12);
    assert!((c.schedule.lr_factor(99) - 2.0 / 101.0).abs() < 1e-12);
}

#[test]
fn dpf_stacks_one_net_per_frame() {
    let device = Device::flex();
    let config = DpfConfig::new(30).with_n_hidden(3);
    // Per frame: 3·128+128 + 3·(128·128+128) + 128·3+3 = 50,435 (docs/reference.md §2: T nets).
    assert_eq!(config.siren().num_params(), 50_435);
    let dpf = config.init(0, &device);
    assert_eq!(dpf.param_count(), 30 * 50_435);
    assert_eq!(dpf.num_params(), 30 * 50_435);
    assert_eq!((dpf.frame_of(-1.0), dpf.frame_of(1.0)), (0, 29));
    assert_eq!(dpf.frame_of(doma::data::normalized_time(17, 30)), 17);

    // The batched evaluation of every frame equals the per-frame warp.
    let x = tensor2(common::random_points(64, 3), [64, 3], &device);
    let all = dpf.warp_all(x.clone());
    for k in [0, 11, 29] {
        let one = dpf.warp(x.clone(), doma::data::normalized_time(k, 30));
        let from_all = all.clone().narrow(0, k, 1).reshape([64, 3]);
        assert!(rel_err(&to_vec(one), &to_vec(from_all)) < 1e-5, "frame {k}");
    }
    // Frames share nothing: two seeds differ per frame, but frame k's output depends only
    // on frame k's slice.
    let other = DpfConfig::new(30).with_n_hidden(3).init(1, &device);
    let y0 = to_vec(dpf.warp(x.clone(), -1.0));
    let y1 = to_vec(other.warp(x.clone(), -1.0));
    assert!(rel_err(&y0, &y1) > 1e-3);
}

#[test]
fn dpf_jacobian_matches_finite_differences() {
    let device = Device::flex();
    let dpf = DpfConfig::new(4)
        .with_hidden(32)
        .with_n_hidden(1)
        .init(5, &device);
    let x = common::random_points(6, 9);
    let t = doma::data::normalized_time(2, 4);
    let out = dpf.warp_dual(tensor2(x.clone(), [6, 3], &device), t, &Autodiff);
    // Tangent c is ∂y/∂x_c, [3, N, 3].
    let tangent = to_vec(out.warped.tangent.unwrap());
    let h = 1e-2;
    for c in 0..3 {
        let shifted = |s: f64| {
            let mut xs = x.clone();
            for p in 0..6 {
                xs[3 * p + c] += s;
            }
            to_vec(dpf.warp(tensor2(xs, [6, 3], &device), t))
        };
        let (plus, minus) = (shifted(h), shifted(-h));
        let fd: Vec<f64> = plus
            .iter()
            .zip(&minus)
            .map(|(p, m)| (p - m) / (2.0 * h))
            .collect();
        let ad = &tangent[c * 18..(c + 1) * 18];
        assert!(rel_err(ad, &fd) < 2e-2, "column {c}: {ad:?} vs {fd:?}");
    }
}

#[test]
fn dpf_value_path_through_the_fused_sine_layers_matches_the_plain_one_with_its_gradients() {
    let _g = backward_lock();
    let device = Device::flex().autodiff();
    let dpf = DpfConfig::new(3).with_hidden(32).init(2, &device);
    let x = tensor2(common::random_points(50, 4), [50, 3], &device);
    let t = doma::data::normalized_time(1, 3);
    // Values and weight gradients of `sum(y²)`, frame 1's nets only.
    let run = |y: Tensor<2>| -> (Vec<f64>, Vec<f64>, bool) {
        let grads = y.clone().mul(y.clone()).sum().backward();
        let mut g = Vec::new();
        let net = &dpf.nets[1];
        for layer in net.sine.iter().chain([&net.output]) {
            let b = layer.bias.as_ref().expect("SIREN layers have a bias");
            for p in [
                to_vec(
                    layer
                        .weight
                        .val()
                        .grad(&grads)
                        .expect("frame 1 has gradients"),
                ),
                to_vec(b.val().grad(&grads).expect("frame 1 has gradients")),
            ] {
                g.extend(p);
            }
        }
        let others = dpf.nets[0].sine[0].weight.val().grad(&grads).is_some();
        (to_vec(y), g, others)
    };
    let (plain_y, plain_g, _) = run(dpf.warp(x.clone(), t));
    for method in [JacobianKind::Analytic, JacobianKind::Autodiff] {
        let y = dpf
            .warp_values(x.clone(), t, method.method().as_ref())
            .warped
            .value;
        let (y, g, others) = run(y);
        assert!(rel_err(&y, &plain_y) < 1e-5, "{method:?} values");
        assert!(rel_err(&g, &plain_g) < 1e-4, "{method:?} gradients");
        assert!(!others, "{method:?}: frame 0 got a gradient");
    }
}

#[test]
fn checkpoints_round_trip_bit_exactly_and_in_f16() {
    let device = Device::flex();
    let dir = common::scratch("doma-ckpt");
    let config = DomaFieldConfig::new(Variant::Affinity).with_n_hidden(3);
    let field = config.init(3, &device);
    let path = dir.join("model.bpk");
    let bytes = save_checkpoint(field.clone(), &path, Precision::F32).unwrap();
    assert_eq!(bytes, std::fs::metadata(&path).unwrap().len());
    // The authors' registration Affinity: 51,724 parameters (BURN.md: 207,920 B).
    assert_eq!(field.param_count(), 51_724);
    assert_eq!(bytes, 207_920);
    let loaded = load_checkpoint(config.init(99, &device), &path).unwrap();
    let x = tensor2(common::random_points(32, 1), [32, 3], &device);
    assert_eq!(
        to_vec(field.warp(x.clone(), 0.3)),
        to_vec(loaded.warp(x.clone(), 0.3))
    );
    for (a, b) in field
        .siren
        .to_weights()
        .iter()
        .zip(loaded.siren.to_weights())
    {
        assert_eq!(a, &b);
    }
    // f16: about half the bytes; values rounded to f16 (relative error < 1e-3).
    let half = dir.join("half.bpk");
    let half_bytes = save_checkpoint(field.clone(), &half, Precision::F16).unwrap();
    assert!(half_bytes < bytes * 6 / 10, "{half_bytes} vs {bytes}");
    let loaded = load_checkpoint(config.init(99, &device), &half).unwrap();
    for (a, b) in field
        .siren
        .to_weights()
        .iter()
        .zip(loaded.siren.to_weights())
    {
        assert!(rel_err(&b.weight, &a.weight) < 1e-3);
    }
    // DPF for 30 frames is more than 10× bigger than Affinity.
    let dpf = DpfConfig::new(30).with_n_hidden(3).init(0, &device);
    let dpf_bytes = encode_checkpoint(dpf, Precision::F32).unwrap().len() as u64;
    assert!(dpf_bytes > 10 * bytes, "{dpf_bytes}");
    // No temporary files are left.
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| n.ends_with(".bpk")), "{names:?}");
}

#[test]
fn bad_checkpoints_are_refused_naming_the_file() {
    let device = Device::flex();
    let dir = common::scratch("doma-badckpt");
    let garbage = dir.join("garbage.bpk");
    std::fs::write(&garbage, b"not a burnpack at all").unwrap();
    let config = DomaFieldConfig::new(Variant::Trans);
    match load_checkpoint(config.init(0, &device), &garbage) {
        Err(DomaError::Malformed { path, .. }) => assert_eq!(path, garbage),
        other => panic!("{other:?}"),
    }
    // A checkpoint of another shape does not fit.
    let other = dir.join("affinity.bpk");
    save_checkpoint(
        DomaFieldConfig::new(Variant::Affinity).init(0, &device),
        &other,
        Precision::F32,
    )
    .unwrap();
    match load_checkpoint(config.init(0, &device), &other) {
        Err(DomaError::Malformed { path, reason }) => {
            assert_eq!(path, other);
            assert!(reason.contains("does not fit"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    let truncated = dir.join("truncated.bpk");
    let bytes = std::fs::read(&other).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert!(
        load_checkpoint(
            DomaFieldConfig::new(Variant::Affinity).init(0, &device),
            &truncated
        )
        .is_err()
    );
}

/// A unit square moving by a known translation over 4 frames; keypoints are its corners.
fn moving_square() -> RegistrationTask {
    let template = TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [0.5, 0.0, 0.0],
            [0.5, 0.5, 0.0],
            [0.0, 0.5, 0.0],
            [0.25, 0.25, 0.1],
        ],
        vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]],
    )
    .unwrap();
    let mut positions = Vec::new();
    for k in 0..4 {
        for v in &template.vertices {
            positions.extend([v[0] + 0.1 * k as f32, v[1] - 0.05 * k as f32, v[2]]);
        }
    }
    let targets = Trajectories::new(4, 5, positions).unwrap();
    RegistrationTask {
        keypoints: targets.select_points(&[0, 2, 4]).unwrap(),
        template: template.clone(),
        target_faces: template.faces.clone(),
        targets,
    }
}

#[test]
fn a_short_registration_reduces_the_guidance_loss_with_every_term() {
    let _lock = backward_lock();
    let device = Device::flex();
    let task = moving_square();
    let config = RegistrationConfig::new()
        .with_iterations(40)
        .with_learning_rate(1e-3)
        .with_canonical_samples(64)
        .with_target_samples(64)
        .with_aiap_weight(1.0)
        .with_smoothness_weight(0.001);
    let ad = device.clone().autodiff();
    let field = DomaFieldConfig::new(Variant::Affinity)
        .with_hidden(32)
        .init(0, &ad);
    let fitted = register(field, &task, &config, &device, false).unwrap();
    let first = fitted.history[0].trajectory_loss;
    let last = fitted.history.last().unwrap().trajectory_loss;
    assert!(last < 0.5 * first, "guidance L1 {first} → {last}");
    assert_eq!(fitted.steps, 40 * 4);
    // The Chamfer term is on in the last iterations, so the total exceeds the guidance.
    let r = fitted.history.last().unwrap();
    assert!(r.total_loss > r.trajectory_loss);

    // DPF runs through the same loop.
    let dpf = DpfConfig::new(4).with_hidden(32).init(0, &ad);
    let fitted = register(
        dpf,
        &task,
        &config.clone().with_iterations(5),
        &device,
        false,
    )
    .unwrap();
    assert_eq!(fitted.history.len(), 5);

    // Keypoints and targets must have the same frames.
    let mut bad = moving_square();
    bad.keypoints = bad.keypoints.select_frames(0..3, 1).unwrap();
    let field = DomaFieldConfig::new(Variant::Trans)
        .with_hidden(8)
        .init(0, &ad);
    assert!(matches!(
        register(field, &bad, &config, &device, false),
        Err(DomaError::InvalidData(_))
    ));
}

#[test]
fn a_warped_mesh_sequence_is_the_field_at_each_frames_time() {
    let device = Device::flex();
    let field = DomaFieldConfig::new(Variant::Affinity)
        .with_hidden(16)
        .init(4, &device);
    let mesh = TriMesh::new(
        vec![[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.5, 0.2]],
        vec![[0, 1, 2]],
    )
    .unwrap();
    let seq = doma::warp::warp_mesh_sequence(&field, &mesh, 5, &device).unwrap();
    assert_eq!((seq.frames(), seq.points()), (5, 3));
    for k in 0..5 {
        let x = points(&mesh.vertices, &device);
        let y = to_vec(field.warp(x, doma::data::normalized_time(k, 5)));
        let got: Vec<f64> = seq.frame(k).iter().map(|&v| v as f64).collect();
        assert!(rel_err(&got, &y) < 1e-6, "frame {k}");
    }
}

#[test]
fn a_dpf_step_on_one_frame_leaves_the_other_frames_untouched() {
    let _lock = backward_lock();
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let data = Trajectories::new(3, 5, (0..45).map(|i| i as f32 * 0.01).collect()).unwrap();
    let dpf = DpfConfig::new(3)
        .with_hidden(8)
        .with_n_hidden(1)
        .init(0, &ad);
    let config =
        doma::train::FitConfig::new(doma::field::model::ModelConfig::Dpf(DpfConfig::new(3)));
    let mut trainer = doma::train::Trainer::new(dpf, &config, &data, &device).unwrap();
    let weights = |t: &doma::train::Trainer<doma::field::dpf::Dpf, _>| -> Vec<Vec<f64>> {
        t.field()
            .nets
            .iter()
            .map(|n| to_vec(n.sine[0].weight.val()))
            .collect()
    };
    // A step on frame 0 gives frame 0 Adam moments; a step on frame 1 must then leave
    // frame 0 alone (with one stacked parameter, its momentum would move it again).
    trainer.step(0, 1e-2).unwrap();
    let before = weights(&trainer);
    trainer.step(1, 1e-2).unwrap();
    let after = weights(&trainer);
    assert_eq!(after[0], before[0], "frame 0 moved during frame 1's step");
    assert_eq!(after[2], before[2]);
    assert_ne!(after[1], before[1]);
}

#[test]
fn dpf_runs_its_frame_sirens_through_the_analytic_jacobian_too() {
    let _g = backward_lock();
    let device = Device::flex().autodiff();
    let dpf = DpfConfig::new(3).with_hidden(16).init(5, &device);
    let x = tensor2(common::random_points(20, 9), [20, 3], &device);
    let t = doma::data::normalized_time(2, 3);
    // Values, tangents and the θ-gradient of L_H, by each method.
    let run = |method: &dyn JacobianMethod| {
        let raw = dpf.raw_dual(x.clone(), t, method);
        let tangent = raw.tangent.clone().expect("tangents");
        let l = doma::loss::smoothness(tangent.clone(), doma::loss::SmoothnessNorm::Squared);
        let grads = l.backward();
        let g = to_vec(
            dpf.nets[2].sine[0]
                .weight
                .val()
                .grad(&grads)
                .expect("a gradient"),
        );
        (to_vec(raw.value), to_vec(tangent), g)
    };
    let (v_ad, j_ad, g_ad) = run(&Autodiff);
    let (v_an, j_an, g_an) = run(&doma::jacobian::Analytic);
    assert!(rel_err(&v_an, &v_ad) < 1e-5, "values");
    assert!(rel_err(&j_an, &j_ad) < 1e-4, "tangents");
    assert!(rel_err(&g_an, &g_ad) < 1e-3, "θ-gradient of L_H");
}

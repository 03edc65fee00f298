//! The baselines' spatial Jacobians (forward mode on duals, through ReLU, Fourier features,
//! the DCT basis and RBF skinning) against f64 central differences. Its own process: the
//! f64 device is configured once.

use crate::common;

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};
use common::{f64_flex, rel_err, tensor2, to_vec};
use doma::field::MotionField;
use doma::field::baselines::banmo::BanmoConfig;
use doma::field::baselines::bone_cloud::BoneCloudConfig;
use doma::field::baselines::dct::DctConfig;
use doma::field::baselines::mlp::MlpConfig;
use doma::jacobian::Autodiff;

/// `∂y/∂x` by forward mode vs central differences, for a field at time `t`.
fn check_jacobian(name: &str, f: &dyn MotionField, t: f64, tol: f64) {
    let device = f64_flex();
    let n = 8;
    let xs = common::random_points(n, 11);
    let out = f.warp_dual(tensor2(xs.clone(), [n, 3], &device), t, &Autodiff);
    let tangent = to_vec(out.warped.tangent.expect("tangents"));
    // Small enough for BANMO's highest Fourier frequency (2⁹): the central difference's
    // error grows with the cube of the frequency.
    let h = 1e-7;
    for c in 0..3 {
        let shifted = |s: f64| {
            let mut v = xs.clone();
            for p in 0..n {
                v[3 * p + c] += s;
            }
            to_vec(f.warp(tensor2(v, [n, 3], &device), t))
        };
        let (plus, minus) = (shifted(h), shifted(-h));
        let fd: Vec<f64> = plus
            .iter()
            .zip(&minus)
            .map(|(a, b)| (a - b) / (2.0 * h))
            .collect();
        let ad = &tangent[c * 3 * n..(c + 1) * 3 * n];
        assert!(
            rel_err(ad, &fd) < tol,
            "{name}, column {c}: {}",
            rel_err(ad, &fd)
        );
    }
}

/// A model whose output layer is no longer zero, so that its Jacobian is not trivial.
fn perturbed_output<M: Module>(m: M, device: &Device) -> M {
    struct Jitter(u64, Device);
    impl burn::module::ModuleMapper for Jitter {
        fn map_float<const D: usize>(&mut self, p: Param<Tensor<D>>) -> Param<Tensor<D>> {
            self.0 += 1;
            let seed = self.0;
            let device = self.1.clone();
            p.map(move |t| {
                let n = t.shape().num_elements();
                let noise: Vec<f64> = (0..n)
                    .map(|i| {
                        (((i as u64 * 2_654_435_761 + seed * 97) % 1000) as f64 / 1000.0 - 0.5)
                            * 0.1
                    })
                    .collect();
                t.clone()
                    + Tensor::<1>::from_data(TensorData::new(noise, [n]), &device)
                        .reshape(t.shape())
            })
        }
    }
    m.map(&mut Jitter(0, device.clone()))
}

#[test]
fn jacobians_through_relu_fourier_features_and_skinning_match_finite_differences() {
    let device = f64_flex();
    let mlp = perturbed_output(
        MlpConfig::new()
            .with_hidden(32)
            .with_layers(3)
            .init(2, &device),
        &device,
    );
    check_jacobian("MLP-ReLU", &mlp, 0.3, 1e-6);
    let pe = perturbed_output(
        MlpConfig::new()
            .with_hidden(32)
            .with_layers(3)
            .with_pe_octaves(6)
            .init(2, &device),
        &device,
    );
    check_jacobian("MLP-ReLU PE.6", &pe, -0.4, 1e-6);
    let dct = perturbed_output(
        DctConfig::new(6)
            .with_hidden(32)
            .with_layers(3)
            .init(2, &device),
        &device,
    );
    check_jacobian("DCT-NeRF", &dct, 0.2, 1e-6);
    let host: Vec<f32> = common::random_points(40, 3)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let bc = perturbed_output(
        BoneCloudConfig::new(3)
            .with_bones(16)
            .with_sigma(3.0)
            .init(&host, 2, &device),
        &device,
    );
    check_jacobian("BoneCloud", &bc, 1.0, 1e-6);
    // BANMO, small, with every parameter moved off its initial value (the bones off the
    // origin) and an inverse temperature of 1000·e^{−4.6} ≈ 10, so that the skinning
    // weights vary smoothly with x and their derivative is part of the Jacobian.
    let mut banmo = perturbed_output(
        BanmoConfig::new(4)
            .with_bones(5)
            .with_code_size(8)
            .with_transform_width(16)
            .with_skin_width(12)
            .init(2, &device),
        &device,
    );
    banmo.skin_aux = Param::from_data(TensorData::new(vec![-4.6f64, 1.0], [2]), &device);
    check_jacobian("BANMO", &banmo, 1.0 / 3.0, 1e-6);
}

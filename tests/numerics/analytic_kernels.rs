//! The CubeCL kernels of the analytic op on wgpu against their reference, the Burn-primitive
//! composition run on flex, on random inputs in f32 (1e-4 relative): the dual, the first
//! (input) dual and the value-only sine activation, each forward and backward. Skipped
//! without a wgpu adapter,
//! except under CI (`CI` set), where that fails.

use crate::common;

use burn::tensor::{Device, Tensor, TensorData};
use common::{random_points, rel_err, to_vec};
use doma::jacobian::analytic::{SineKernel, activation, kernel_launches};

fn tensor(values: &[f64], shape: Vec<usize>, device: &Device) -> Tensor<2> {
    let data = TensorData::new(values.iter().map(|&v| v as f32).collect::<Vec<_>>(), shape);
    Tensor::<2>::from_data(data, device)
}

/// Rows of `zs` (`z_v` for the input layer's passes) and of `g` for `n` points.
fn rows(which: SineKernel, n: usize) -> (usize, usize) {
    match which {
        SineKernel::DualForward | SineKernel::DualBackward => (4 * n, 4 * n),
        SineKernel::Forward | SineKernel::Backward => (n, n),
        SineKernel::DualInputForward | SineKernel::DualInputBackward => (n, 4 * n),
    }
}

/// The pass `which` on `device` for `n` points: `zs` and `g` (see [`rows`]), the bias `b`
/// (`[d]`) and `W` (`[4, d]`).
fn run(which: SineKernel, device: &Device, inputs: [&[f64]; 4], n: usize, d: usize) -> Vec<f64> {
    let [zs, b, g, w] = inputs;
    let (zs_rows, g_rows) = rows(which, n);
    let bias = tensor(b, vec![1, d], device).reshape([d]);
    let out = activation(
        which,
        tensor(zs, vec![zs_rows, d], device),
        bias,
        tensor(g, vec![g_rows, d], device),
        tensor(w, vec![4, d], device),
        30.0,
    );
    to_vec(out)
}

#[test]
fn every_sine_kernel_matches_the_primitive_reference() {
    let Some(wgpu) =
        common::wgpu_device_or_skip("every_sine_kernel_matches_the_primitive_reference")
    else {
        return;
    };
    let flex = Device::flex();
    // 4N = 4 · 37 rows, not a multiple of the cube size; d = 19, which the kernels read
    // element by element, and d = 20, which they read in vectors of 4.
    for (n, d) in [(37, 19), (37, 20)] {
        check_every_kernel(&flex, &wgpu, n, d);
    }
}

fn check_every_kernel(flex: &Device, wgpu: &Device, n: usize, d: usize) {
    for which in [
        SineKernel::DualForward,
        SineKernel::DualBackward,
        SineKernel::Forward,
        SineKernel::Backward,
        SineKernel::DualInputForward,
        SineKernel::DualInputBackward,
    ] {
        let (zs_rows, g_rows) = rows(which, n);
        // random_points gives 3 values per point in [-1, 1]; scale zs like a layer's S W.
        let zs: Vec<f64> = random_points(zs_rows * d, 1)
            .iter()
            .take(zs_rows * d)
            .map(|v| 0.1 * v)
            .collect();
        let b: Vec<f64> = random_points(d, 2)
            .iter()
            .take(d)
            .map(|v| 0.05 * v)
            .collect();
        let g: Vec<f64> = random_points(g_rows * d, 3)
            .into_iter()
            .take(g_rows * d)
            .collect();
        // A first layer's weights: SIREN's init scale, U(-1/c, 1/c) for c = 4 inputs.
        let w: Vec<f64> = random_points(4 * d, 4)
            .iter()
            .take(4 * d)
            .map(|v| 0.25 * v)
            .collect();
        let before = kernel_launches();
        let reference = run(which, flex, [&zs, &b, &g, &w], n, d);
        assert_eq!(
            kernel_launches(),
            before,
            "flex runs the reference, not a kernel"
        );
        let kernel = run(which, wgpu, [&zs, &b, &g, &w], n, d);
        assert_eq!(
            kernel_launches(),
            before + 1,
            "{which:?}: wgpu launched its CubeCL kernel once"
        );
        assert_eq!(kernel.len(), reference.len());
        assert_eq!(
            kernel.len(),
            g_rows * d,
            "{which:?}: the output has g's shape"
        );
        let e = rel_err(&kernel, &reference);
        assert!(e < 1e-4, "{which:?}, d = {d}: kernel vs reference {e:e}");
    }
}

//! The heads against closed-form motions, and Gram–Schmidt's properties.

use crate::common;

use burn::tensor::{Device, Tensor};
use common::{random_points, tensor2, to_vec};
use doma::field::{MotionField, Variant, rotation};
use doma::jacobian::Dual;
use doma::prelude::*;

/// A rotation matrix (row-major) from an axis and an angle (Rodrigues).
fn rotation_matrix(axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let [x, y, z] = axis.map(|a| a / n);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

fn apply(a: &[[f64; 3]; 3], u: [f64; 3], p: &[f64]) -> Vec<f64> {
    p.chunks(3)
        .flat_map(|x| (0..3).map(move |i| a[i][0] * x[0] + a[i][1] * x[1] + a[i][2] * x[2] + u[i]))
        .collect()
}

/// Runs `variant`'s head on the same raw output row for every point.
fn head_warp(
    variant: Variant,
    raw_row: &[f64],
    points: &[f64],
    device: &Device,
) -> (Vec<f64>, Vec<f64>) {
    let n = points.len() / 3;
    let raw: Vec<f64> = (0..n).flat_map(|_| raw_row.iter().copied()).collect();
    let raw = Dual::constant(tensor2(raw, [n, raw_row.len()], device));
    let local = variant.local_affine(raw);
    let (a, _) = local.matrices();
    let y = local.apply(Dual::constant(tensor2(points.to_vec(), [n, 3], device)));
    (to_vec(y.value), to_vec(a))
}

fn assert_close(a: &[f64], b: &[f64], tol: f64, what: &str) {
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tol, "{what}[{i}]: {x} vs {y}");
    }
}

/// The 6-D representation of a rotation: the first two columns of R, as a 3×2
/// matrix read row-major (docs/reference.md §2.1).
fn six_d(r: &[[f64; 3]; 3]) -> [f64; 6] {
    [r[0][0], r[0][1], r[1][0], r[1][1], r[2][0], r[2][1]]
}

#[test]
fn trans_head_translates() {
    let device = Device::flex();
    let p = random_points(16, 1);
    let u = [0.3, -0.2, 0.7];
    let (y, a) = head_warp(Variant::Trans, &u, &p, &device);
    let eye = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    assert_close(&y, &apply(&eye, u, &p), 1e-6, "y");
    assert_close(
        &a[..9],
        &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        0.0,
        "A",
    );
}

#[test]
fn se3_head_reproduces_a_rigid_motion() {
    let device = Device::flex();
    let p = random_points(16, 2);
    let r = rotation_matrix([0.2, -0.5, 0.8], 1.1);
    let u = [0.1, 0.4, -0.3];
    let mut raw = six_d(&r).to_vec();
    // Gram–Schmidt ignores the lengths of the columns and the a2 component along a1.
    for v in raw.iter_mut().step_by(2) {
        *v *= 2.5;
    }
    raw.extend(u);
    let (y, a) = head_warp(Variant::Se3, &raw, &p, &device);
    assert_close(&y, &apply(&r, u, &p), 1e-5, "y");
    let r_flat: Vec<f64> = r.iter().flatten().copied().collect();
    assert_close(&a[..9], &r_flat, 1e-6, "R");
}

#[test]
fn scaled_se3_head_reproduces_a_scaled_rigid_motion() {
    let device = Device::flex();
    let p = random_points(16, 3);
    let r = rotation_matrix([1.0, 1.0, 0.0], -0.7);
    let s: f64 = 1.7;
    let u = [-0.5, 0.0, 0.25];
    let mut raw = vec![(s.exp() - 1.0).ln()]; // softplus⁻¹(s)
    raw.extend(six_d(&r));
    raw.extend(u);
    let (y, _) = head_warp(Variant::ScaledSe3, &raw, &p, &device);
    let sr = r.map(|row| row.map(|v| s * v));
    assert_close(&y, &apply(&sr, u, &p), 1e-5, "y");
}

#[test]
fn affinity_head_reproduces_an_affine_motion() {
    let device = Device::flex();
    let p = random_points(16, 4);
    let a = [[1.2, 0.3, -0.4], [0.0, 0.8, 0.5], [-0.1, 0.2, 1.5]];
    let u = [0.3, 0.1, -0.2];
    let mut raw: Vec<f64> = a.iter().flatten().copied().collect(); // row-major
    raw.extend(u);
    let (y, a_out) = head_warp(Variant::Affinity, &raw, &p, &device);
    assert_close(&y, &apply(&a, u, &p), 1e-5, "y");
    let a_flat: Vec<f64> = a.iter().flatten().copied().collect();
    assert_close(&a_out[..9], &a_flat, 1e-7, "A");
}

#[test]
fn gram_schmidt_gives_rotations_and_the_identity() {
    let device = Device::flex();
    let n = 64;
    let six = random_points(2 * n, 5); // 6 values per row
    let cols = rotation::gram_schmidt(Dual::constant(tensor2(six, [n, 6], &device)));
    let cols: Vec<Vec<f64>> = cols.into_iter().map(|c| to_vec(c.value)).collect();
    for i in 0..n {
        let col = |j: usize| [cols[j][3 * i], cols[j][3 * i + 1], cols[j][3 * i + 2]];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        for j in 0..3 {
            for k in 0..3 {
                let expected = if j == k { 1.0 } else { 0.0 };
                assert!(
                    (dot(col(j), col(k)) - expected).abs() < 1e-5,
                    "RᵀR ≠ I at row {i}"
                );
            }
        }
        let (a, b, c) = (col(0), col(1), col(2));
        let det = a[0] * (b[1] * c[2] - b[2] * c[1]) - b[0] * (a[1] * c[2] - a[2] * c[1])
            + c[0] * (a[1] * b[2] - a[2] * b[1]);
        assert!((det - 1.0).abs() < 1e-5, "det R = {det} at row {i}");
    }
    let identity = rotation::gram_schmidt(Dual::constant(tensor2(
        vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        [1, 6],
        &device,
    )));
    let flat: Vec<f64> = identity.into_iter().flat_map(|c| to_vec(c.value)).collect();
    assert_eq!(flat, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
}

#[test]
fn a_field_warps_with_its_local_transform() {
    // y = A x + u must hold between `warp` and `local_transform` for every variant.
    let device = Device::flex();
    let p = random_points(32, 6);
    for variant in Variant::ALL {
        let field = doma::field::DomaFieldConfig::new(variant)
            .with_hidden(32)
            .init(1, &device);
        let x = tensor2(p.clone(), [32, 3], &device);
        let y = to_vec(field.warp(x.clone(), 0.3));
        let (a, u) = field.local_transform(x.clone(), 0.3);
        let ax: Tensor<2> = a.matmul(x.unsqueeze_dim(2)).squeeze_dim(2);
        let expected = to_vec(ax + u);
        assert_close(&y, &expected, 1e-5, &variant.to_string());
    }
}

//! The losses of a DOMA fit (DESIGN §3, REFERENCE §4). Each returns a one-element
//! tensor, so that it can be summed and differentiated.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

/// The trajectory (reconstruction) loss, REFERENCE §4.1: the mean absolute error over
/// all `N × 3` coordinates of `predicted` and `target` (`[N, 3]`). It divides by `3N`,
/// whereas the EPE metric sums over the three coordinates.
pub fn trajectory_l1(predicted: Tensor<2>, target: Tensor<2>) -> Tensor<1> {
    (predicted - target).abs().mean()
}

/// How the smoothness loss `L_H` treats each Jacobian entry (REFERENCE §4.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum SmoothnessNorm {
    /// The "-H" rows: the sum of the squared entries, `Σ J_rc²`
    /// (`= ‖∇A‖_F² + ‖∇u‖_F²` for Affinity).
    Squared,
    /// Charbonnier per entry, `Σ (√(J_rc² + 1) − 1)`, as the authors' registration code.
    /// (The paper's Eq. 13 applies `Ψ` to the total instead; the code does not.)
    Charbonnier,
}

/// The smoothness loss `L_H` (Eq. 13, in the authors' form; REFERENCE §4.2): the
/// per-point penalty of the raw-output Jacobian, averaged over the `P` points.
/// `tangent` is `[3, P, O]` (`∂o/∂x` as the tangents of a [`crate::jacobian::Dual`]).
pub fn smoothness(tangent: Tensor<3>, norm: SmoothnessNorm) -> Tensor<1> {
    let points = tangent.dims()[1] as f64;
    let squared = tangent.square();
    let per_entry = match norm {
        SmoothnessNorm::Squared => squared,
        SmoothnessNorm::Charbonnier => squared.add_scalar(1.0).sqrt().sub_scalar(1.0),
    };
    per_entry.sum().div_scalar(points)
}

/// The scale `c` of the elasticity robustifier (REFERENCE §4.3).
pub const ELASTIC_SCALE: f64 = 0.03;

/// Keeps `p` of the eigenvalue formula away from zero, so that an isotropic
/// `JᵀJ` (a pure scaling, the identity) has finite gradients. It shifts the
/// eigenvalues by about `√3·1e-6` at most.
const EIGEN_EPS: f64 = 1e-12;
/// Keeps `acos` off ±1, where its derivative is infinite (repeated eigenvalues).
const ACOS_MARGIN: f64 = 1e-6;
/// Eigenvalues below this are clamped before the logarithm (a singular warp).
const EIGEN_FLOOR: f64 = 1e-30;

/// The three eigenvalues of the symmetric 3×3 matrices `S` given by their six
/// distinct entries (each `[N, 1]`), by the closed-form trigonometric solution
/// (Smith 1961). Returned largest first, each `[N, 1]`. Plain tensor ops, so it runs
/// on every backend and Burn's reverse mode differentiates it.
pub fn symmetric_eigenvalues(s: [Tensor<2>; 6]) -> [Tensor<2>; 3] {
    let [a, b, c, d, e, f] = s; // S00, S11, S22, S01, S12, S02
    let q = (a.clone() + b.clone() + c.clone()).div_scalar(3.0);
    let (ba, bb, bc) = (a - q.clone(), b - q.clone(), c - q.clone());
    let p1 = d.clone().square() + e.clone().square() + f.clone().square();
    let p2 = ba.clone().square() + bb.clone().square() + bc.clone().square() + p1.mul_scalar(2.0);
    let p = p2.div_scalar(6.0).add_scalar(EIGEN_EPS).sqrt();
    let inv = p.clone().recip();
    let (b00, b11, b22) = (ba * inv.clone(), bb * inv.clone(), bc * inv.clone());
    let (b01, b12, b02) = (d * inv.clone(), e * inv.clone(), f * inv);
    let det = b00 * (b11.clone() * b22.clone() - b12.clone().square())
        - b01.clone() * (b01.clone() * b22 - b12.clone() * b02.clone())
        + b02.clone() * (b01 * b12 - b11 * b02);
    let r = det
        .div_scalar(2.0)
        .clamp(-1.0 + ACOS_MARGIN, 1.0 - ACOS_MARGIN);
    let phi = r.acos().div_scalar(3.0);
    let two_p = p.mul_scalar(2.0);
    let l1 = q.clone() + two_p.clone() * phi.clone().cos();
    let l3 = q.clone() + two_p * phi.add_scalar(2.0 * std::f64::consts::PI / 3.0).cos();
    let l2 = q.mul_scalar(3.0) - l1.clone() - l3.clone();
    [l1, l2, l3]
}

/// The singular values of the 3×3 matrices `M` (`[N, 3]` each) given by their columns
/// `c_k = M[:, k]`: the square roots of the eigenvalues of `MᵀM`, largest first.
pub fn singular_values_3x3(columns: [Tensor<2>; 3]) -> [Tensor<2>; 3] {
    let g = |i: usize, j: usize| (columns[i].clone() * columns[j].clone()).sum_dim(1);
    let lambda = symmetric_eigenvalues([g(0, 0), g(1, 1), g(2, 2), g(0, 1), g(1, 2), g(0, 2)]);
    lambda.map(|l| l.clamp_min(EIGEN_FLOOR).sqrt())
}

/// The elasticity loss "-E" (Nerfies; REFERENCE §4.3) on the Jacobian of the whole
/// warp, `tangent: [3, N, 3]` (`tangent[k, n, i] = ∂y_i/∂x_k`):
/// `q = Σ_j log² σ_j(∂y/∂x)` per point, then the authors' robustifier
/// `ρ(q) = 2 (q/c)² / ((q/c)² + 4)` with `c = 0.03` (applied to `q` itself, which is
/// already squared: a quirk of the reference that we keep), averaged over points.
pub fn elasticity(tangent: Tensor<3>) -> Tensor<1> {
    let [_, n, _] = tangent.dims();
    let columns = [0, 1, 2].map(|k| tangent.clone().narrow(0, k, 1).reshape([n, 3]));
    let [s1, s2, s3] = singular_values_3x3(columns);
    let q = s1.log().square() + s2.log().square() + s3.log().square();
    elastic_robustifier(q).mean()
}

/// `ρ(q) = 2 (q/c)² / ((q/c)² + 4)`, `c` = [`ELASTIC_SCALE`].
pub fn elastic_robustifier(q: Tensor<2>) -> Tensor<2> {
    let z = q.div_scalar(ELASTIC_SCALE).square();
    z.clone().mul_scalar(2.0) / z.add_scalar(4.0)
}

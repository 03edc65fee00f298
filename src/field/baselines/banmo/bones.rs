//! BANMO's bone transforms: rotations from axis-angle or quaternions, a bone's motion
//! relative to its rest pose, and the linear blend of the bones' transforms.

use burn::tensor::Tensor;

use crate::dual::Dual;

/// Per-bone rigid transforms: rotations `[B, 3, 3]` and translations `[B, 3]`.
#[derive(Clone, Debug)]
pub struct BoneTransforms {
    /// `R_b`, `[B, 3, 3]`.
    pub rotations: Tensor<3>,
    /// `τ_b`, `[B, 3]`.
    pub translations: Tensor<2>,
}

impl BoneTransforms {
    /// A bone's motion relative to its rest pose, `rest_b⁻¹ ∘ self_b`:
    /// `R^Δ = Rʳᵀ R`, `τ^Δ = Rʳᵀ (τ − τʳ)` (docs/reference.md §2.3).
    pub fn relative_to(&self, rest: &BoneTransforms) -> BoneTransforms {
        let b = self.translations.dims()[0];
        let rt = rest.rotations.clone().swap_dims(1, 2);
        let dt = (self.translations.clone() - rest.translations.clone()).unsqueeze_dim::<3>(2);
        BoneTransforms {
            rotations: rt.clone().matmul(self.rotations.clone()),
            translations: rt.matmul(dt).reshape([b, 3]),
        }
    }

    /// Linear blend skinning with weights `w` (`[N, B]`): the raw outputs `[N, 12]`,
    /// `A = Σ_b w_b R_b` row-major then `u = Σ_b w_b τ_b`.
    pub fn blend(&self, w: Dual) -> Dual {
        let b = self.translations.dims()[0];
        let rows = self.rotations.clone().reshape([b, 9]);
        Dual::cat(vec![
            w.clone().linear(rows, None),
            w.linear(self.translations.clone(), None),
        ])
    }
}

/// `exp(ω)` for axis-angles `[B, 3]` (Rodrigues), with the angle `√max(‖ω‖², 1e−4)` as
/// in the authors' rotation map.
pub fn so3_exp(omega: Tensor<2>) -> Tensor<3> {
    let b = omega.dims()[0];
    let device = omega.device();
    let theta = omega.clone().square().sum_dim(1).clamp_min(1e-4).sqrt(); // [B, 1]
    let fac1 = theta.clone().sin() / theta.clone();
    let fac2 = (theta.clone().cos().neg().add_scalar(1.0)) / theta.square();
    let k = hat(omega);
    let k2 = k.clone().matmul(k.clone());
    let eye = Tensor::<2>::eye(3, &device).unsqueeze_dim::<3>(0);
    let f1 = fac1.reshape([b, 1, 1]);
    let f2 = fac2.reshape([b, 1, 1]);
    eye + k.mul(f1) + k2.mul(f2)
}

/// The cross-product matrices `[ω]×`, `[B, 3, 3]`.
fn hat(omega: Tensor<2>) -> Tensor<3> {
    let b = omega.dims()[0];
    let c = |i: usize| omega.clone().narrow(1, i, 1);
    let zero = c(0).zeros_like();
    Tensor::cat(
        vec![
            zero.clone(),
            c(2).neg(),
            c(1),
            c(2),
            zero.clone(),
            c(0).neg(),
            c(1).neg(),
            c(0),
            zero,
        ],
        1,
    )
    .reshape([b, 3, 3])
}

/// The rotations of quaternions `[B, 4]` (real part first), normalised first.
pub fn quaternion_matrix(q: Tensor<2>) -> Tensor<3> {
    let b = q.dims()[0];
    let two_s = q.clone().square().sum_dim(1).recip().mul_scalar(2.0); // [B, 1]
    let c = |i: usize| q.clone().narrow(1, i, 1);
    let (r, i, j, k) = (c(0), c(1), c(2), c(3));
    let p = |a: &Tensor<2>, b: &Tensor<2>| a.clone().mul(b.clone()).mul(two_s.clone());
    let one = |t: Tensor<2>| t.neg().add_scalar(1.0);
    Tensor::cat(
        vec![
            one(p(&j, &j) + p(&k, &k)),
            p(&i, &j) - p(&k, &r),
            p(&i, &k) + p(&j, &r),
            p(&i, &j) + p(&k, &r),
            one(p(&i, &i) + p(&k, &k)),
            p(&j, &k) - p(&i, &r),
            p(&i, &k) - p(&j, &r),
            p(&j, &k) + p(&i, &r),
            one(p(&i, &i) + p(&j, &j)),
        ],
        1,
    )
    .reshape([b, 3, 3])
}

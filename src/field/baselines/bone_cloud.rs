//! The BoneCloud baseline of Tab. 1 (docs/reference.md §2.2): `K = 1024` bones with learnable
//! canonical positions `v_k`, and per frame a rigid transform per bone (6-D rotation,
//! initialised to the identity, and a translation, initialised to 0), blended by RBF
//! skinning weights `w_k(x) ∝ exp(−σ‖x − v_k‖)` (σ = 10, plain distance, normalised to 1):
//!
//! `y = Σ_k w_k(x) (R_k^t x + t_k^t) = (Σ_k w_k R_k^t) x + Σ_k w_k t_k^t`.
//!
//! So linear blend skinning *is* a local affine map: the blended `A = Σ w_k R_k` and
//! `u = Σ w_k t_k` are two `[N, K] × [K, ·]` matmuls, and the Affinity head applies them.
//! The raw outputs are those 12 numbers (`A` row-major, then `u`). On [`Dual`]s, so `L_H`
//! and the elasticity loss work through the skinning weights. The authors fit it with
//! Adam at lr 1e-3.

use burn::config::Config;
use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::ops::Mul;

use crate::dual::Dual;
use crate::field::rotation::gram_schmidt;
use crate::field::{MotionField, Variant};
use crate::jacobian::JacobianMethod;

/// The shape of a BoneCloud model.
#[derive(Config, Debug)]
pub struct BoneCloudConfig {
    /// The number of frames `T`.
    pub frames: usize,
    /// The number of bones `K`.
    #[config(default = 1024)]
    pub bones: usize,
    /// The RBF sharpness `σ` of the skinning weights.
    #[config(default = 10.0)]
    pub sigma: f64,
}

impl BoneCloudConfig {
    /// [`BoneCloudConfig::num_params`] in checked arithmetic: `None` past `usize`.
    pub fn checked_params(&self) -> Option<usize> {
        let poses = self.frames.checked_mul(self.bones)?.checked_mul(9)?;
        self.bones.checked_mul(3)?.checked_add(poses)
    }

    /// Trainable parameters: `3K` bone positions and `9TK` per-frame bone transforms.
    pub fn num_params(&self) -> usize {
        3 * self.bones + 9 * self.frames * self.bones
    }

    /// Bones uniform in the bounding box of `canonical` (`[N·3]`, the canonical training
    /// points), seeded; every frame's transforms the identity.
    ///
    /// # Panics
    /// If `canonical` is empty or `frames`/`bones` is 0 (programming errors).
    pub fn init(&self, canonical: &[f32], seed: u64, device: &Device) -> BoneCloud {
        assert!(!canonical.is_empty() && self.frames > 0 && self.bones > 0);
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in canonical.chunks_exact(3) {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let bones: Vec<f32> = (0..self.bones)
            .flat_map(|_| [0, 1, 2].map(|c| lo[c] + (hi[c] - lo[c]) * rng.random::<f32>()))
            .collect();
        let identity = [1.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let pose: Vec<f32> = identity.repeat(self.frames * self.bones);
        BoneCloud {
            bones: Param::from_data(TensorData::new(bones, [self.bones, 3]), device),
            pose: Param::from_data(TensorData::new(pose, [self.frames, self.bones, 9]), device),
            sigma: self.sigma,
            frames: self.frames,
        }
    }
}

/// Bones with per-frame rigid transforms, blended by RBF skinning.
#[derive(Module, Debug)]
pub struct BoneCloud {
    /// Canonical bone positions, `[K, 3]`.
    pub bones: Param<Tensor<2>>,
    /// Per frame and bone: 6-D rotation then translation, `[T, K, 9]`.
    pub pose: Param<Tensor<3>>,
    /// `σ`.
    pub sigma: f64,
    /// `T`.
    pub frames: usize,
}

impl BoneCloud {
    /// The frame nearest normalised time `t` ([`crate::field::frame_of`]).
    pub fn frame_of(&self, t: f64) -> usize {
        crate::field::frame_of(t, self.frames)
    }

    /// The normalised skinning weights `[N, K]` of `x`.
    pub fn skinning_weights(&self, x: Dual) -> Dual {
        let v = self.bones.val(); // [K, 3]
        let k = v.dims()[0];
        let v_sq = v.clone().square().sum_dim(1).transpose(); // [1, K]
        let x_sq = x.clone().mul(x.clone()).sum_channels(); // [N, 1]
        let cross = x.linear(v.transpose().mul_scalar(-2.0), None); // [N, K]
        let ones = Tensor::<2>::ones([1, k], &cross.value.device());
        // |x|² broadcast to [N, K] through a rank-1 matmul, so that its tangents are
        // [3, N, K] like the rest.
        let d2 = cross + x_sq.linear(ones, None) + Dual::constant(v_sq);
        let d = d2.clamp_min(1e-12).sqrt();
        d.mul_scalar(-self.sigma).softmax()
    }

    /// The per-bone transforms of frame `k`: rotations row-major `[K, 9]` and
    /// translations `[K, 3]`.
    fn bone_transforms(&self, frame: usize) -> (Tensor<2>, Tensor<2>) {
        let [_, k, _] = self.pose.dims();
        let p = self.pose.val().narrow(0, frame, 1).reshape([k, 9]);
        let [c0, c1, c2] = gram_schmidt(Dual::constant(p.clone().narrow(1, 0, 6)));
        // Row-major R: row i = (c0[i], c1[i], c2[i]).
        let cols = [c0.value, c1.value, c2.value];
        let rows: Vec<Tensor<2>> = (0..3)
            .flat_map(|i| cols.iter().map(move |c| c.clone().narrow(1, i, 1)))
            .collect();
        (Tensor::cat(rows, 1), p.narrow(1, 6, 3))
    }
}

impl BoneCloud {
    /// The raw outputs are the blended `A` (row-major) and `u` at the frame nearest `t`.
    fn raw_on_duals(&self, x: Dual, t: f64) -> Dual {
        let w = self.skinning_weights(x);
        let (rot, trans) = self.bone_transforms(self.frame_of(t));
        Dual::cat(vec![w.clone().linear(rot, None), w.linear(trans, None)])
    }
}

impl MotionField for BoneCloud {
    /// Forward mode on duals (the method is a general one: [`MotionField::accepts`]).
    fn raw(&self, x: Dual, t: f64, _general: &dyn JacobianMethod) -> Dual {
        self.raw_on_duals(x, t)
    }

    /// No SIREN layers: forward mode on duals, so general methods only.
    fn has_siren_layers(&self) -> bool {
        false
    }

    /// Linear blend skinning is a blended local affine map.
    fn head(&self) -> Variant {
        Variant::Affinity
    }

    fn param_count(&self) -> usize {
        self.num_params()
    }
}

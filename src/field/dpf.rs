//! The frame-wise DPF baseline (docs/design.md §1, docs/reference.md §2): one 3-D-input SIREN per frame,
//! `g_k(x) = x + u_k(x)`, with no time input and nothing shared between frames.
//!
//! The `T` networks live in one module, one [`Siren`] per frame. A fit step on
//! frame `k` uses frame `k`'s parameters alone (one matmul per layer), so only they get a
//! gradient and Adam leaves the other frames' weights and moments untouched, exactly as
//! PyTorch's Adam skips the authors' separate nets. [`Dpf::warp_all`] evaluates every frame
//! at once: it stacks each layer's weights into `[T, fan_in, fan_out]` and runs one batched
//! matmul per layer. The parameter count grows as `O(T)`, which is what Tab. 3 compares.
//! Like the authors' code, it has `T` nets (frame 0 too; the paper says `T − 1`).
//!
//! Why not one stacked `[T, fan_in, fan_out]` parameter per layer (docs/design.md §1): then every
//! step's gradient covers all frames, zero outside frame `k`, and Adam's momentum keeps
//! moving the other frames' weights after each of their steps, `T − 1` extra updates per
//! real one. That is a different (and, measured, a much faster-converging) baseline than
//! the authors'.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::{MotionField, Variant};
use crate::dual::Dual;
use crate::jacobian::JacobianMethod;
use crate::siren::{Siren, SirenConfig, SirenInitializer, SirenShape, WithSirenShape};

/// The shape of a DPF model.
#[derive(Config, Debug)]
pub struct DpfConfig {
    /// The number of frames `T` (one SIREN each).
    pub frames: usize,
    /// Each frame SIREN's width, depth and frequency.
    #[config(default = "SirenShape::new()")]
    pub shape: SirenShape,
}

impl WithSirenShape for DpfConfig {
    fn shape_mut(&mut self) -> &mut SirenShape {
        &mut self.shape
    }
}

impl DpfConfig {
    /// One frame's SIREN: input `x` (3), output the displacement `u_k` (3).
    pub fn siren(&self) -> SirenConfig {
        SirenConfig::new(3)
            .with_d_in(3)
            .with_shape(self.shape.clone())
    }

    /// `T ×` the per-frame SIREN's parameters.
    pub fn num_params(&self) -> usize {
        self.frames * self.siren().num_params()
    }

    /// A model whose frame nets are drawn, one after another, by the authors' SIREN
    /// initialiser (docs/reference.md §1) from one stream seeded by `seed`.
    ///
    /// # Panics
    /// If `frames` is 0 (a programming error; the callers check their data).
    pub fn init(&self, seed: u64, device: &Device) -> Dpf {
        assert!(self.frames > 0, "DPF needs at least one frame");
        let siren = self.siren();
        let omega = self.shape.omega;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let nets = (0..self.frames)
            .map(|_| {
                let layers = SirenInitializer::new(omega)
                    .with_scale(self.shape.scale())
                    .init(&siren, &mut rng);
                Siren::from_weights(&layers, omega, device)
            })
            .collect();
        Dpf {
            nets,
            frames: self.frames,
        }
    }
}

/// `T` SIRENs `x ↦ u_k(x)`; the warp to frame `k` is `x + u_k(x)`.
#[derive(Module, Debug)]
pub struct Dpf {
    /// One SIREN per frame, input `x` (no time), output the displacement.
    pub nets: Vec<Siren>,
    /// `T`.
    pub frames: usize,
}

impl Dpf {
    /// The frame nearest normalised time `t` ([`crate::field::frame_of`]).
    pub fn frame_of(&self, t: f64) -> usize {
        crate::field::frame_of(t, self.frames)
    }

    /// Every frame's warp of the same points at once, `x: [N, 3]` → `[T, N, 3]`: the
    /// layers' weights stacked to `[T, d_in, d_out]`, one batched matmul per layer.
    pub fn warp_all(&self, x: Tensor<2>) -> Tensor<3> {
        let [n, _] = x.dims();
        let x3 = x.unsqueeze_dim::<3>(0).repeat_dim(0, self.frames); // [T, N, 3]
        let layers = |net: &Siren| -> Vec<burn::nn::Linear> {
            net.sine.iter().chain([&net.output]).cloned().collect()
        };
        let per_frame: Vec<Vec<burn::nn::Linear>> = self.nets.iter().map(layers).collect();
        let depth = per_frame[0].len();
        let omega = self.nets[0].omega;
        let mut h = x3.clone();
        for l in 0..depth {
            let w = Tensor::stack(per_frame.iter().map(|f| f[l].weight.val()).collect(), 0);
            let b: Tensor<2> = Tensor::stack(
                per_frame
                    .iter()
                    .map(|f| f[l].bias.as_ref().expect("SIREN layers have a bias").val())
                    .collect(),
                0,
            );
            h = h.matmul(w) + b.unsqueeze_dim::<3>(1);
            if l + 1 < depth {
                h = h.mul_scalar(omega).sin();
            }
        }
        debug_assert_eq!(h.dims(), [self.frames, n, 3]);
        x3 + h
    }
}

impl MotionField for Dpf {
    /// The raw output is the displacement `u_k(x)` of the frame nearest `t`: frame `k`'s
    /// SIREN run through `method`, so Analytic's fused kernels serve DPF too (with Burn's
    /// `sin` this baseline's steps were about 5× slower than a DOMA step of the same
    /// width, all of it in `sinf`/`cosf`).
    fn raw(&self, x: Dual, t: f64, method: &dyn JacobianMethod) -> Dual {
        super::siren_raw(&self.nets[self.frame_of(t)], x, method, |x| x)
    }

    /// A displacement model: `A = I`, `u = raw`.
    fn head(&self) -> Variant {
        Variant::Trans
    }

    fn param_count(&self) -> usize {
        self.num_params()
    }
}

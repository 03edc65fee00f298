//! The frame-wise DPF baseline (DESIGN §1, REFERENCE §2): one 3-D-input SIREN per frame,
//! `g_k(x) = x + u_k(x)`, with no time input and nothing shared between frames.
//!
//! The `T` networks live in one module, one parameter per frame and layer. A fit step on
//! frame `k` uses frame `k`'s parameters alone (one matmul per layer), so only they get a
//! gradient and Adam leaves the other frames' weights and moments untouched, exactly as
//! PyTorch's Adam skips the authors' separate nets. [`Dpf::warp_all`] evaluates every frame
//! at once: it stacks each layer's weights into `[T, fan_in, fan_out]` and runs one batched
//! matmul per layer. The parameter count grows as `O(T)`, which is what Tab. 3 compares.
//! Like the authors' code, it has `T` nets (frame 0 too; the paper says `T − 1`).
//!
//! Why not one stacked `[T, fan_in, fan_out]` parameter per layer (DESIGN §1): then every
//! step's gradient covers all frames, zero outside frame `k`, and Adam's momentum keeps
//! moving the other frames' weights after each of their steps, `T − 1` extra updates per
//! real one. That is a different (and, measured, a much faster-converging) baseline than
//! the authors'.

use burn::config::Config;
use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::{MotionField, Variant, WarpOutput};
use crate::jacobian::{Dual, JacobianMethod};
use crate::siren::{SirenConfig, SirenInitializer};

/// The shape of a DPF model.
#[derive(Config, Debug)]
pub struct DpfConfig {
    /// The number of frames `T` (one SIREN each).
    pub frames: usize,
    /// Hidden width `d`.
    #[config(default = 128)]
    pub hidden: usize,
    /// Hidden sine layers `n` after the first.
    #[config(default = 2)]
    pub n_hidden: usize,
    /// Sine frequency `ω₀`.
    #[config(default = 30.0)]
    pub omega: f64,
}

impl DpfConfig {
    /// One frame's SIREN: input `x` (3), output the displacement `u_k` (3).
    pub fn siren(&self) -> SirenConfig {
        SirenConfig::new(3)
            .with_d_in(3)
            .with_hidden(self.hidden)
            .with_n_hidden(self.n_hidden)
            .with_omega(self.omega)
    }

    /// `T ×` the per-frame SIREN's parameters.
    pub fn num_params(&self) -> usize {
        self.frames * self.siren().num_params()
    }

    /// A model whose frame nets are drawn, one after another, by the authors' SIREN
    /// initialiser (REFERENCE §1) from one stream seeded by `seed`.
    ///
    /// # Panics
    /// If `frames` is 0 (a programming error; the callers check their data).
    pub fn init(&self, seed: u64, device: &Device) -> Dpf {
        assert!(self.frames > 0, "DPF needs at least one frame");
        let siren = self.siren();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let nets = (0..self.frames)
            .map(|_| {
                let layers = SirenInitializer::new(self.omega).init(&siren, &mut rng);
                FrameNet {
                    weights: layers
                        .iter()
                        .map(|l| {
                            Param::from_data(
                                TensorData::new(l.weight.clone(), [l.fan_in, l.fan_out]),
                                device,
                            )
                        })
                        .collect(),
                    biases: layers
                        .iter()
                        .map(|l| {
                            Param::from_data(TensorData::new(l.bias.clone(), [l.fan_out]), device)
                        })
                        .collect(),
                }
            })
            .collect();
        Dpf {
            nets,
            omega: self.omega,
            frames: self.frames,
        }
    }
}

/// One frame's SIREN `x ↦ u_k(x)`: per layer (sine layers first, output last) a
/// `[fan_in, fan_out]` weight and a `[fan_out]` bias.
#[derive(Module, Debug)]
pub struct FrameNet {
    /// The weights.
    pub weights: Vec<Param<Tensor<2>>>,
    /// The biases.
    pub biases: Vec<Param<Tensor<1>>>,
}

/// `T` SIRENs `x ↦ u_k(x)`; the warp to frame `k` is `x + u_k(x)`.
#[derive(Module, Debug)]
pub struct Dpf {
    /// One net per frame.
    pub nets: Vec<FrameNet>,
    /// The sine frequency `ω₀`.
    pub omega: f64,
    /// `T`.
    pub frames: usize,
}

impl Dpf {
    /// The frame nearest normalised time `t` ([`crate::field::frame_of`]).
    pub fn frame_of(&self, t: f64) -> usize {
        crate::field::frame_of(t, self.frames)
    }

    /// Frame `k`'s displacement `u_k(x)` on duals, `x: [N, 3]`.
    pub fn displacement_dual(&self, x: Dual, k: usize) -> Dual {
        let net = &self.nets[k];
        let last = net.weights.len() - 1;
        let mut h = x;
        for (l, (w, b)) in net.weights.iter().zip(&net.biases).enumerate() {
            h = h.linear(w.val(), Some(b.val()));
            if l < last {
                h = h.mul_scalar(self.omega).sin();
            }
        }
        h
    }

    /// Every frame's warp of the same points at once, `x: [N, 3]` → `[T, N, 3]`: the
    /// layers' weights stacked to `[T, d_in, d_out]`, one batched matmul per layer.
    pub fn warp_all(&self, x: Tensor<2>) -> Tensor<3> {
        let [n, _] = x.dims();
        let x3 = x.unsqueeze_dim::<3>(0).repeat_dim(0, self.frames); // [T, N, 3]
        let layers = self.nets[0].weights.len();
        let mut h = x3.clone();
        for l in 0..layers {
            let w = Tensor::stack(
                self.nets.iter().map(|net| net.weights[l].val()).collect(),
                0,
            );
            let b: Tensor<2> =
                Tensor::stack(self.nets.iter().map(|net| net.biases[l].val()).collect(), 0);
            h = h.matmul(w) + b.unsqueeze_dim::<3>(1);
            if l + 1 < layers {
                h = h.mul_scalar(self.omega).sin();
            }
        }
        debug_assert_eq!(h.dims(), [self.frames, n, 3]);
        x3 + h
    }
}

impl MotionField for Dpf {
    /// The raw output is the displacement `u_k(x)` of the frame nearest `t`. Any
    /// `jacobian` method gets the forward mode on duals (the Analytic kernels are
    /// SIREN-with-time specific).
    fn raw_dual(&self, x: Tensor<2>, t: f64, jacobian: Option<&dyn JacobianMethod>) -> Dual {
        let x = crate::field::spatial_input(x, jacobian);
        self.displacement_dual(x, self.frame_of(t))
    }

    /// A displacement model: `A = I`, `u = raw`.
    fn head(&self) -> Variant {
        Variant::Trans
    }

    /// The value path of the fit loop: frame `k`'s sine layers through `method`'s
    /// [`JacobianMethod::sine_layer`] (fused for [`crate::jacobian::Analytic`]; with
    /// Burn's `sin` this baseline's steps were about 5× slower than a DOMA step of the
    /// same width, all of it in `sinf`/`cosf`).
    fn warp_values(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> WarpOutput {
        let net = &self.nets[self.frame_of(t)];
        let last = net.weights.len() - 1;
        let mut h = x.clone();
        for (w, b) in net.weights.iter().zip(&net.biases).take(last) {
            h = method.sine_layer(h, w.val(), b.val(), self.omega);
        }
        let u = h.matmul(net.weights[last].val()) + net.biases[last].val().unsqueeze_dim::<2>(0);
        crate::field::head_warp(Variant::Trans, x, Dual::constant(u), None)
    }

    fn param_count(&self) -> usize {
        self.num_params()
    }
}

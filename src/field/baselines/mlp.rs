//! The MLP-ReLU baselines of Tab. 1 (docs/reference.md §2: not in the authors' release): 6 hidden
//! layers × 128, ReLU, input `[x, t]`, output a displacement, `y = x + o`. With
//! `pe_octaves = 6` the input first goes through NeRF's Fourier features ("PE.6"):
//! `γ(p) = [p, sin(2⁰πp), cos(2⁰πp), …, sin(2⁵πp), cos(2⁵πp)]` on each of the four inputs.
//!
//! The weights are drawn like PyTorch's `nn.Linear` (`U(±1/√fan_in)` for weights and
//! biases) from a seeded stream; the output layer starts at zero, so an unfitted model is
//! the identity warp. Everything runs on [`Dual`]s, so the smoothness and elasticity losses
//! work through ReLU and the Fourier features with the `Autodiff` Jacobian.

use burn::config::Config;
use burn::module::Module;
use burn::nn::Linear;
use burn::tensor::Device;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::dual::Dual;
use crate::field::{MotionField, time_input};
use crate::jacobian::JacobianMethod;
use crate::siren::{LayerWeights, linear_from};

/// The shape of an MLP-ReLU baseline.
#[derive(Config, Debug)]
pub struct MlpConfig {
    /// Hidden width (the paper's 128).
    #[config(default = 128)]
    pub hidden: usize,
    /// Hidden ReLU layers (the paper's 6).
    #[config(default = 6)]
    pub layers: usize,
    /// Fourier-feature octaves of the input (0: plain MLP-ReLU; 6: "PE.6").
    #[config(default = 0)]
    pub pe_octaves: usize,
    /// Input width before encoding: 4 for `[x, t]`, 3 for `x` alone.
    #[config(default = 4)]
    pub d_in: usize,
    /// Output width (3: a displacement).
    #[config(default = 3)]
    pub d_out: usize,
}

/// Draws `U(±1/√fan_in)` weights and biases (PyTorch's `nn.Linear` default).
pub(crate) fn pytorch_linear(
    fan_in: usize,
    fan_out: usize,
    zero: bool,
    rng: &mut impl Rng,
) -> LayerWeights {
    let bound = 1.0 / (fan_in as f64).sqrt();
    let mut draw = |n: usize| -> Vec<f64> {
        (0..n)
            .map(|_| {
                if zero {
                    0.0
                } else {
                    rng.random_range(-bound..bound)
                }
            })
            .collect()
    };
    LayerWeights {
        fan_in,
        fan_out,
        weight: draw(fan_in * fan_out),
        bias: draw(fan_out),
    }
}

impl MlpConfig {
    /// The width of the encoded input.
    pub fn encoded_width(&self) -> usize {
        self.d_in * (1 + 2 * self.pe_octaves)
    }

    /// [`MlpConfig::num_params`] in checked arithmetic, without its loop: `None` past
    /// `usize`.
    pub fn checked_params(&self) -> Option<usize> {
        let encoded = self
            .d_in
            .checked_mul(self.pe_octaves.checked_mul(2)?.checked_add(1)?)?;
        let h = self.hidden;
        match self.layers {
            0 => crate::siren::stacked_params(&[(1, encoded, self.d_out)]),
            l => {
                crate::siren::stacked_params(&[(1, encoded, h), (l - 1, h, h), (1, h, self.d_out)])
            }
        }
    }

    /// Trainable parameters.
    pub fn num_params(&self) -> usize {
        let mut fan_in = self.encoded_width();
        let mut total = 0;
        for _ in 0..self.layers {
            total += fan_in * self.hidden + self.hidden;
            fan_in = self.hidden;
        }
        total + fan_in * self.d_out + self.d_out
    }

    /// A model drawn from `seed` on `device` (output layer zero: the identity warp).
    pub fn init(&self, seed: u64, device: &Device) -> Mlp {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut fan_in = self.encoded_width();
        let mut hidden = Vec::with_capacity(self.layers);
        for _ in 0..self.layers {
            hidden.push(linear_from(
                &pytorch_linear(fan_in, self.hidden, false, &mut rng),
                device,
            ));
            fan_in = self.hidden;
        }
        let output = linear_from(&pytorch_linear(fan_in, self.d_out, true, &mut rng), device);
        Mlp {
            hidden,
            output,
            pe_octaves: self.pe_octaves,
        }
    }
}

/// An MLP-ReLU (optionally with Fourier features) predicting a displacement.
#[derive(Module, Debug)]
pub struct Mlp {
    /// The hidden ReLU layers.
    pub hidden: Vec<Linear>,
    /// The linear output layer.
    pub output: Linear,
    /// Fourier-feature octaves (0 = none).
    pub pe_octaves: usize,
}

impl Mlp {
    /// NeRF's positional encoding of `p` (`[N, C]` → `[N, C(1 + 2L)]`).
    pub fn encode(&self, p: Dual) -> Dual {
        if self.pe_octaves == 0 {
            return p;
        }
        let mut parts = vec![p.clone()];
        for k in 0..self.pe_octaves {
            let scaled = p
                .clone()
                .mul_scalar(std::f64::consts::PI * (1u64 << k) as f64);
            parts.push(scaled.clone().sin());
            parts.push(scaled.cos());
        }
        Dual::cat(parts)
    }

    /// The network on duals: encoding, ReLU layers, linear output.
    pub fn forward_dual(&self, input: Dual) -> Dual {
        let mut h = self.encode(input);
        for layer in &self.hidden {
            h = h
                .linear(layer.weight.val(), layer.bias.as_ref().map(|b| b.val()))
                .relu();
        }
        h.linear(
            self.output.weight.val(),
            self.output.bias.as_ref().map(|b| b.val()),
        )
    }
}

impl MotionField for Mlp {
    /// The raw output is the displacement `o = MLP(γ([x, t]))`, in forward mode on duals
    /// (the method is a general one: [`MotionField::accepts`]).
    fn raw(&self, x: Dual, t: f64, _general: &dyn JacobianMethod) -> Dual {
        let xt = time_input(x.value.clone(), t);
        let input = if x.has_tangent() {
            Dual::seed_spatial(xt)
        } else {
            Dual::constant(xt)
        };
        self.forward_dual(input)
    }

    /// No SIREN layers: forward mode on duals, so general methods only.
    fn has_siren_layers(&self) -> bool {
        false
    }

    /// A displacement model: `A = I`, `u = raw`.
    fn head(&self) -> crate::field::Variant {
        crate::field::Variant::Trans
    }

    fn param_count(&self) -> usize {
        self.num_params()
    }
}

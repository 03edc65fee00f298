//! The DCT-NeRF baseline of Tab. 1 (Wang et al. 2021, "Neural trajectory fields";
//! docs/reference.md §2.2: not in the authors' release). An MLP-ReLU of the canonical position alone (no time
//! input, no positional encoding, 6 × 128) outputs `K` coefficients per coordinate of a
//! trajectory in the orthonormal DCT-II basis over the `T` frames:
//!
//! `u(x, k) = Σ_{j<K} c_j(x) φ_j(k)`, `φ_0(k) = 1/√T`, `φ_j(k) = √(2/T) cos(π j (2k+1) / 2T)`,
//!
//! and `y = x + u`. doma's `K` is `min(T, 10)` by default (a smooth trajectory; the paper
//! does not give its value). The basis is a fixed `[3K, 3]` matrix per frame, so the whole
//! model stays one MLP and one matmul, on [`Dual`]s.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};

use super::mlp::{Mlp, MlpConfig};
use crate::dual::Dual;
use crate::field::MotionField;
use crate::jacobian::JacobianMethod;

/// The shape of a DCT-NeRF model.
#[derive(Config, Debug)]
pub struct DctConfig {
    /// The number of frames `T` of the basis.
    pub frames: usize,
    /// DCT coefficients per coordinate; `None`: `min(T, 10)`.
    pub coefficients: Option<usize>,
    /// Hidden width.
    #[config(default = 128)]
    pub hidden: usize,
    /// Hidden ReLU layers.
    #[config(default = 6)]
    pub layers: usize,
}

impl DctConfig {
    /// `K`.
    pub fn k(&self) -> usize {
        self.coefficients.unwrap_or(self.frames.min(10)).max(1)
    }

    fn mlp(&self) -> MlpConfig {
        MlpConfig::new()
            .with_d_in(3)
            .with_d_out(3 * self.k())
            .with_hidden(self.hidden)
            .with_layers(self.layers)
    }

    /// [`DctConfig::num_params`] in checked arithmetic: `None` past `usize`.
    pub fn checked_params(&self) -> Option<usize> {
        MlpConfig::new()
            .with_d_in(3)
            .with_d_out(self.k().checked_mul(3)?)
            .with_hidden(self.hidden)
            .with_layers(self.layers)
            .checked_params()
    }

    /// Trainable parameters.
    pub fn num_params(&self) -> usize {
        self.mlp().num_params()
    }

    /// A model drawn from `seed` (zero output layer: the identity warp).
    ///
    /// # Panics
    /// If `frames` is 0 (a programming error).
    pub fn init(&self, seed: u64, device: &Device) -> DctNerf {
        assert!(self.frames > 0, "DCT-NeRF needs at least one frame");
        DctNerf {
            mlp: self.mlp().init(seed, device),
            frames: self.frames,
            k: self.k(),
        }
    }
}

/// DCT-NeRF: per-point DCT trajectory coefficients from an MLP of `x`.
#[derive(Module, Debug)]
pub struct DctNerf {
    /// `x ↦` coefficients `[3K]`, coordinate-major (`c[coord·K + j]`).
    pub mlp: Mlp,
    /// `T`.
    pub frames: usize,
    /// `K`.
    pub k: usize,
}

/// The orthonormal DCT-II basis function `φ_j` at frame `k` of `t` frames.
pub fn dct_basis(j: usize, k: usize, t: usize) -> f64 {
    let t_f = t as f64;
    if j == 0 {
        1.0 / t_f.sqrt()
    } else {
        (2.0 / t_f).sqrt()
            * (std::f64::consts::PI * j as f64 * (2 * k + 1) as f64 / (2.0 * t_f)).cos()
    }
}

impl DctNerf {
    /// The frame nearest normalised time `t` ([`crate::field::frame_of`]).
    pub fn frame_of(&self, t: f64) -> usize {
        crate::field::frame_of(t, self.frames)
    }

    /// The `[3K, 3]` matrix that maps coefficients to the displacement at frame `k`.
    fn basis_matrix(&self, k: usize, device: &Device) -> Tensor<2> {
        let mut m = vec![0f32; 3 * self.k * 3];
        for c in 0..3 {
            for j in 0..self.k {
                m[(c * self.k + j) * 3 + c] = dct_basis(j, k, self.frames) as f32;
            }
        }
        Tensor::from_data(TensorData::new(m, [3 * self.k, 3]), device)
    }
}

impl DctNerf {
    /// The raw output is the displacement `u(x, k)` at the frame nearest `t`.
    fn raw_on_duals(&self, x: Dual, t: f64) -> Dual {
        let device = x.value.device();
        let coefficients = self.mlp.forward_dual(x);
        coefficients.linear(self.basis_matrix(self.frame_of(t), &device), None)
    }
}

impl MotionField for DctNerf {
    /// Forward mode on duals (the method is a general one: [`MotionField::accepts`]).
    fn raw(&self, x: Dual, t: f64, _general: &dyn JacobianMethod) -> Dual {
        self.raw_on_duals(x, t)
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

//! The SIREN backbone (Eq. 1; Sitzmann et al. 2020) with the authors' initialisation.
//!
//! Layers `i = 0..=n` are sine layers `h_{i+1} = sin(ω (h_i W_i + b_i))`, and the
//! output layer is linear, `o = h_{n+1} W_o + b_o` (the "outermost linear" form).
//! `ω` multiplies the bias too (docs/reference.md §1).

use burn::config::Config;
use burn::module::{Module, Param};
use burn::nn::Linear;
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::dual::Dual;

/// The body of a SIREN that the experiments vary: width, depth and frequency. Every
/// SIREN-based model (DOMA, DPF, the fluid widths) nests one, so the three numbers are
/// declared once.
#[derive(Config, Debug, PartialEq)]
pub struct SirenShape {
    /// Hidden width `d` (the paper's 128).
    #[config(default = 128)]
    pub hidden: usize,
    /// Number of hidden sine layers `n` after the first sine layer (the paper's 2).
    #[config(default = 2)]
    pub n_hidden: usize,
    /// The frequency `ω₀` of every sine layer (Eq. 1; the authors' 30).
    #[config(default = 30.0)]
    pub omega: f64,
    /// The weight-scaling factor `α` of the initialisation (Yeom, Lee and Lee, *Fast
    /// Training of Sinusoidal Neural Fields via Scaling Initialization*, ICLR 2025): every
    /// weight but the output layer's is drawn `α` times wider, which raises the field's
    /// initial frequency content. On the paper's held-out error it moved the final error,
    /// not the time to it (docs/speed.md, "Time to accuracy"). `None` (a config without the
    /// field) is 1, the authors' initialisation, bit for bit.
    pub init_scale: Option<f64>,
}

impl SirenShape {
    /// The initialisation's weight scale `α` (1 unless one is set).
    pub fn scale(&self) -> f64 {
        self.init_scale.unwrap_or(1.0)
    }

    /// Refuses shapes that cannot be built or would not fit in memory (an `hidden²`
    /// weight matrix per layer).
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |m: String| Err(crate::DomaError::InvalidConfig(m));
        if self.hidden == 0 {
            return bad("hidden width must be at least 1".into());
        }
        if !(self.omega.is_finite() && self.omega > 0.0) {
            return bad(format!("sine frequency {} must be positive", self.omega));
        }
        let a = self.scale();
        if !(a.is_finite() && a > 0.0) {
            return bad(format!("initialisation scale {a} must be positive"));
        }
        Ok(())
    }
}

/// The builders of a config that nests a [`SirenShape`], written once for every
/// SIREN-based model: `DomaFieldConfig::new(v).with_hidden(64)`.
pub trait WithSirenShape: Sized {
    /// The nested shape.
    fn shape_mut(&mut self) -> &mut SirenShape;

    /// Sets the hidden width `d`.
    fn with_hidden(mut self, hidden: usize) -> Self {
        self.shape_mut().hidden = hidden;
        self
    }

    /// Sets the number of hidden sine layers `n` after the first.
    fn with_n_hidden(mut self, n_hidden: usize) -> Self {
        self.shape_mut().n_hidden = n_hidden;
        self
    }

    /// Sets the sine frequency `ω₀`.
    fn with_omega(mut self, omega: f64) -> Self {
        self.shape_mut().omega = omega;
        self
    }

    /// Sets the initialisation's weight scale `α` ([`SirenShape::init_scale`]).
    fn with_init_scale(mut self, scale: f64) -> Self {
        self.shape_mut().init_scale = Some(scale);
        self
    }
}

/// The shape of a SIREN (Eq. 1): input and output widths around a [`SirenShape`].
#[derive(Config, Debug)]
pub struct SirenConfig {
    /// Input width (4 for `[x, y, z, t]`).
    #[config(default = 4)]
    pub d_in: usize,
    /// Output width (3 for Trans, 9 for SE(3), 10 for Scaled SE(3), 12 for Affinity).
    pub d_out: usize,
    /// Width, depth and frequency.
    #[config(default = "SirenShape::new()")]
    pub shape: SirenShape,
}

impl WithSirenShape for SirenConfig {
    fn shape_mut(&mut self) -> &mut SirenShape {
        &mut self.shape
    }
}

impl SirenConfig {
    /// The widths `(fan_in, fan_out)` of every layer, sine layers first, output last.
    pub fn layer_shapes(&self) -> Vec<(usize, usize)> {
        let d = self.shape.hidden;
        let mut shapes = vec![(self.d_in, d)];
        shapes.extend((0..self.shape.n_hidden).map(|_| (d, d)));
        shapes.push((d, self.d_out));
        shapes
    }

    /// [`SirenConfig::num_params`] without allocating or overflowing: `None` past
    /// `usize` (a config's sizes are checked with it before anything is built).
    pub fn checked_params(&self) -> Option<usize> {
        let d = self.shape.hidden;
        stacked_params(&[
            (1, self.d_in, d),
            (self.shape.n_hidden, d, d),
            (1, d, self.d_out),
        ])
    }

    /// The number of trainable parameters (weights and biases).
    pub fn num_params(&self) -> usize {
        self.layer_shapes().iter().map(|(i, o)| i * o + o).sum()
    }

    /// A SIREN initialised by [`SirenInitializer`] from `seed`, on `device`.
    pub fn init(&self, seed: u64, device: &Device) -> Siren {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let omega = self.shape.omega;
        let layers = SirenInitializer::new(omega)
            .with_scale(self.shape.scale())
            .init(self, &mut rng);
        Siren::from_weights(&layers, omega, device)
    }
}

/// The weights and biases of stacks of dense layers, `(count, fan_in, fan_out)` each, in
/// checked arithmetic: `None` where the count passes `usize`.
pub fn stacked_params(stacks: &[(usize, usize, usize)]) -> Option<usize> {
    stacks
        .iter()
        .try_fold(0usize, |total, &(count, fan_in, fan_out)| {
            let layer = fan_in.checked_mul(fan_out)?.checked_add(fan_out)?;
            total.checked_add(count.checked_mul(layer)?)
        })
}

/// Host-side weights of one layer: `weight` is `[fan_in, fan_out]` row-major
/// (Burn's `y = x W + b` layout), `bias` is `[fan_out]`.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerWeights {
    /// Input width.
    pub fan_in: usize,
    /// Output width.
    pub fan_out: usize,
    /// `[fan_in, fan_out]`, row-major.
    pub weight: Vec<f64>,
    /// `[fan_out]`.
    pub bias: Vec<f64>,
}

/// Which kind of layer a weight bound is for (docs/reference.md §1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerRole {
    /// The first sine layer, fed `[x, t]`.
    First,
    /// A hidden sine layer.
    Hidden,
    /// The linear output layer.
    Output,
}

/// The SIREN initialisation of the authors' code (docs/reference.md §1):
/// - first layer `W ~ U(±1/fan_in)`;
/// - hidden and output layers `W ~ U(±√(6/fan_in)/ω₀)`;
/// - every bias `U(±1/√fan_in)` (PyTorch's `nn.Linear` default, never re-initialised);
///
/// and, with a weight scale `α ≠ 1` ([`SirenShape::init_scale`]), the first and hidden
/// layers' weight bounds multiplied by `α`.
#[derive(Clone, Copy, Debug)]
pub struct SirenInitializer {
    /// The sine frequency `ω₀`.
    pub omega: f64,
    /// The weight scale `α` of the sine layers (1: the authors').
    pub scale: f64,
}

impl SirenInitializer {
    /// The authors' initialiser for sine frequency `omega`.
    pub fn new(omega: f64) -> Self {
        SirenInitializer { omega, scale: 1.0 }
    }

    /// The same with the sine layers' weights drawn `scale` times wider.
    pub fn with_scale(self, scale: f64) -> Self {
        SirenInitializer { scale, ..self }
    }

    /// The half-width of the uniform weight distribution of a layer.
    pub fn weight_bound(&self, role: LayerRole, fan_in: usize) -> f64 {
        // `x * 1.0` is `x` exactly, so the default scale draws the authors' weights bit
        // for bit.
        match role {
            LayerRole::First => self.scale / fan_in as f64,
            LayerRole::Hidden => self.scale * (6.0 / fan_in as f64).sqrt() / self.omega,
            LayerRole::Output => (6.0 / fan_in as f64).sqrt() / self.omega,
        }
    }

    /// The half-width of the uniform bias distribution of a layer.
    pub fn bias_bound(&self, fan_in: usize) -> f64 {
        1.0 / (fan_in as f64).sqrt()
    }

    /// Draws every layer of `config`, sine layers first, output last.
    pub fn init(&self, config: &SirenConfig, rng: &mut impl Rng) -> Vec<LayerWeights> {
        let shapes = config.layer_shapes();
        let last = shapes.len() - 1;
        shapes
            .iter()
            .enumerate()
            .map(|(i, &(fan_in, fan_out))| {
                let role = match i {
                    0 => LayerRole::First,
                    i if i == last => LayerRole::Output,
                    _ => LayerRole::Hidden,
                };
                let wb = self.weight_bound(role, fan_in);
                let bb = self.bias_bound(fan_in);
                LayerWeights {
                    fan_in,
                    fan_out,
                    weight: (0..fan_in * fan_out)
                        .map(|_| rng.random_range(-wb..wb))
                        .collect(),
                    bias: (0..fan_out).map(|_| rng.random_range(-bb..bb)).collect(),
                }
            })
            .collect()
    }
}

/// A SIREN with sine layers `sine[0..=n]` and a linear `output` layer (Eq. 1).
#[derive(Module, Debug)]
pub struct Siren {
    /// The sine layers: the first (fed `[x, t]`) and the `n` hidden ones.
    pub sine: Vec<Linear>,
    /// The linear output layer.
    pub output: Linear,
    /// The sine frequency `ω₀`, which multiplies `h W + b`.
    pub omega: f64,
}

/// A Burn `Linear` holding `layer`'s weights.
pub(crate) fn linear_from(layer: &LayerWeights, device: &Device) -> Linear {
    let w = TensorData::new(layer.weight.clone(), [layer.fan_in, layer.fan_out]);
    let b = TensorData::new(layer.bias.clone(), [layer.fan_out]);
    Linear {
        weight: Param::from_data(w, device),
        bias: Some(Param::from_data(b, device)),
    }
}

fn read_back(t: Tensor<2>) -> Vec<f64> {
    crate::readback::to_vec(t).expect("a float tensor converts to f64")
}

impl Siren {
    /// Builds a SIREN from host weights (sine layers first, output last).
    pub fn from_weights(layers: &[LayerWeights], omega: f64, device: &Device) -> Self {
        assert!(
            layers.len() >= 2,
            "a SIREN needs a sine layer and an output layer"
        );
        let (out, sine) = layers.split_last().expect("checked above");
        Siren {
            sine: sine.iter().map(|l| linear_from(l, device)).collect(),
            output: linear_from(out, device),
            omega,
        }
    }

    /// Reads the weights back to the host (sine layers first, output last).
    pub fn to_weights(&self) -> Vec<LayerWeights> {
        self.sine
            .iter()
            .chain(std::iter::once(&self.output))
            .map(|l| {
                let [fan_in, fan_out] = l.weight.val().dims();
                let bias = l.bias.as_ref().expect("SIREN layers have a bias").val();
                LayerWeights {
                    fan_in,
                    fan_out,
                    weight: read_back(l.weight.val()),
                    bias: read_back(bias.unsqueeze_dim(0)),
                }
            })
            .collect()
    }

    /// Output width.
    pub fn d_out(&self) -> usize {
        self.output.weight.val().dims()[1]
    }

    /// The network on a batch `[N, d_in]` → `[N, d_out]`.
    pub fn forward(&self, input: Tensor<2>) -> Tensor<2> {
        self.forward_dual(Dual::constant(input)).value
    }

    /// The network on duals: the tangents of the input are pushed through every
    /// layer (`ż_i = ω ḣ_i W_i`, `ḣ_{i+1} = cos z_i ⊙ ż_i`, `J = ḣ_{n+1} W_o`; docs/design.md §2).
    pub fn forward_dual(&self, input: Dual) -> Dual {
        let mut h = input;
        for layer in &self.sine {
            h = h
                .linear(layer.weight.val(), layer.bias.as_ref().map(|b| b.val()))
                .mul_scalar(self.omega)
                .sin();
        }
        h.linear(
            self.output.weight.val(),
            self.output.bias.as_ref().map(|b| b.val()),
        )
    }
}

//! The BANMO baseline of Tab. 1 (Yang et al. 2022), as the authors adapted its deformation
//! module to point trajectories (docs/reference.md §2.3): Gaussian bones, skinning weights
//! from the bones' Gaussian terms plus a neural residual, and per-frame bone transforms
//! from a pose code, blended linearly.
//!
//! - **Codes.** A free rest code `z_r` (128-d) and, per frame `k`, a pose code
//!   `z_k = L(γ(k))`: a linear map of the Fourier encoding of the *raw* frame index
//!   (`γ(v) = [v, sin 2⁰v, cos 2⁰v, …, sin 2⁹v, cos 2⁹v]`, no π).
//! - **Transforms.** One network `G` (8 × 256 ReLU layers, the 5th fed `[z, h]`, every bias
//!   zeroed at the start) maps a code to each bone's rotation `exp(ω)` (axis-angle) and
//!   translation `0.1 τ`. `G(z_r)` places the bones at rest; a bone's motion at frame `k`
//!   is `Δ_b = G_b(z_r)⁻¹ ∘ G_b(z_k)`, i.e. `R^Δ = Rʳᵀ R(k)`, `τ^Δ = Rʳᵀ (τ(k) − τʳ)`.
//! - **Skinning.** Bone `b` is a Gaussian with centre `c_b`, orientation `O_b` and
//!   precisions `s_b`, moved to rest by `G(z_r)`; its logit at `x` is
//!   `−1000 e^{a} Σ_i s_b,i [O_bᵀ (c_b − x)]_i²` plus a skinning MLP's residual on
//!   `[γ(x), z_r]` (5 × 64 ReLU, the 5th fed the input again); `w = softmax_b`.
//! - **Warp.** `y = (Σ_b w_b R^Δ_b) x + Σ_b w_b τ^Δ_b` (forward linear blend skinning).
//!
//! Like BoneCloud, the blend is a local affine map, so the raw outputs are the blended `A`
//! (row-major) and `u`, read by the Affinity head. Everything runs on [`Dual`]s, so `L_H`
//! reaches the skinning weights by forward mode (autodiff alone: no SIREN layers). The
//! authors fit it with Adam at 1e-3 and no regulariser. Their module also registers a
//! density layer and a scalar in each network that never reach the warp; doma does not
//! build them ([`BanmoConfig::unused_authors_params`]).

use burn::config::Config;
use burn::module::{Module, Param};
use burn::nn::Linear;
use burn::tensor::{Device, Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::ops::Mul;

use super::mlp::pytorch_linear;
use crate::dual::Dual;
use crate::field::{MotionField, Variant};
use crate::jacobian::JacobianMethod;
use crate::siren::linear_from;

/// The layer that is fed the network's input again (NeRF's `skips = [4]`).
const SKIP: usize = 4;

/// The shape of a BANMO model; the defaults are the authors' (docs/reference.md §2.3).
#[derive(Config, Debug)]
pub struct BanmoConfig {
    /// The number of frames `T` (the pose code reads the frame index).
    pub frames: usize,
    /// Gaussian bones `B`.
    #[config(default = 25)]
    pub bones: usize,
    /// Fourier frequencies `L` of the point and frame encodings.
    #[config(default = 10)]
    pub frequencies: usize,
    /// The size of the rest and pose codes.
    #[config(default = 128)]
    pub code_size: usize,
    /// ReLU layers of the transform network `G`.
    #[config(default = 8)]
    pub transform_layers: usize,
    /// Width of `G`.
    #[config(default = 256)]
    pub transform_width: usize,
    /// ReLU layers of the skinning MLP.
    #[config(default = 5)]
    pub skin_layers: usize,
    /// Width of the skinning MLP.
    #[config(default = 64)]
    pub skin_width: usize,
}

/// The layer widths `(fan_in, fan_out)` of a NeRF-style MLP with `layers` ReLU layers of
/// `width` on an `input`-wide input: the trunk (the layer [`SKIP`] also fed the input),
/// then a linear feature layer, a ReLU layer of half the width and the output layer.
fn nerf_shapes(input: usize, layers: usize, width: usize, output: usize) -> Vec<(usize, usize)> {
    let mut shapes: Vec<(usize, usize)> = (0..layers)
        .map(|i| match i {
            0 => (input, width),
            SKIP => (input + width, width),
            _ => (width, width),
        })
        .collect();
    shapes.extend([(width, width), (width, width / 2), (width / 2, output)]);
    shapes
}

impl BanmoConfig {
    /// The width of the encoding of `d` numbers: `d (1 + 2L)` (63 for a point, 21 for a
    /// frame index).
    pub fn encoded_width(&self, d: usize) -> usize {
        d * (1 + 2 * self.frequencies)
    }

    fn transform_shapes(&self) -> Vec<(usize, usize)> {
        nerf_shapes(
            self.code_size,
            self.transform_layers,
            self.transform_width,
            6 * self.bones,
        )
    }

    fn skin_shapes(&self) -> Vec<(usize, usize)> {
        nerf_shapes(
            self.encoded_width(3) + self.code_size,
            self.skin_layers,
            self.skin_width,
            self.bones,
        )
    }

    /// [`BanmoConfig::num_params`] in checked arithmetic, without building the layer
    /// lists: `None` past `usize`.
    pub fn checked_params(&self) -> Option<usize> {
        let nerf = |input: usize, layers: usize, width: usize, output: usize| {
            let trunk = match layers {
                0 => vec![],
                l if l > SKIP => vec![
                    (1, input, width),
                    (1, input.checked_add(width)?, width),
                    (l - 2, width, width),
                ],
                l => vec![(1, input, width), (l - 1, width, width)],
            };
            let head = [
                (1, width, width),
                (1, width, width / 2),
                (1, width / 2, output),
            ];
            crate::siren::stacked_params(&[trunk.as_slice(), &head].concat())
        };
        let encode = |d: usize| d.checked_mul(self.frequencies.checked_mul(2)?.checked_add(1)?);
        let transform = nerf(
            self.code_size,
            self.transform_layers,
            self.transform_width,
            self.bones.checked_mul(6)?,
        )?;
        let skin = nerf(
            encode(3)?.checked_add(self.code_size)?,
            self.skin_layers,
            self.skin_width,
            self.bones,
        )?;
        let code = encode(1)?.checked_add(1)?.checked_mul(self.code_size)?;
        [skin, code, self.code_size, self.bones.checked_mul(10)?, 2]
            .iter()
            .try_fold(transform, |a, &b| a.checked_add(b))
    }

    /// Trainable parameters: the transform network, the skinning MLP, the pose code's
    /// linear map, the rest code, the bones (`10 B`) and the two skinning scalars (the
    /// authors' `skin_aux`, of which only the first is read). 695,787 at the authors' sizes.
    pub fn num_params(&self) -> usize {
        let layers =
            |shapes: Vec<(usize, usize)>| -> usize { shapes.iter().map(|(i, o)| i * o + o).sum() };
        layers(self.transform_shapes())
            + layers(self.skin_shapes())
            + (self.encoded_width(1) + 1) * self.code_size
            + self.code_size
            + 10 * self.bones
            + 2
    }

    /// What the authors' module registers besides [`BanmoConfig::num_params`] and never
    /// uses: a density layer (`W → 1`) and a scalar in each of the two networks.
    pub fn unused_authors_params(&self) -> usize {
        (self.transform_width + 1) + (self.skin_width + 1) + 2
    }

    /// A model drawn from `seed` on `device`, initialised as the authors do: every bone at
    /// the origin with the identity orientation and unit precisions, the rest code
    /// `N(0, 1)`, PyTorch's default `U(±1/√fan_in)` layers, with the transform network's
    /// biases zeroed, and the skinning temperature `a = 0`.
    ///
    /// # Panics
    /// If a size is 0, or a width is below 2 (programming errors;
    /// [`ModelConfig::validate`](crate::field::model::ModelConfig::validate) refuses them
    /// first).
    pub fn init(&self, seed: u64, device: &Device) -> Banmo {
        assert!(self.frames > 0 && self.bones > 0 && self.code_size > 0);
        assert!(self.transform_width >= 2 && self.skin_width >= 2);
        assert!(self.transform_layers > 0 && self.skin_layers > 0);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let nerf = |shapes: Vec<(usize, usize)>, zero_bias: bool, rng: &mut ChaCha8Rng| {
            let mut layers: Vec<Linear> = shapes
                .iter()
                .map(|&(i, o)| {
                    let mut w = pytorch_linear(i, o, false, rng);
                    if zero_bias {
                        w.bias.iter_mut().for_each(|b| *b = 0.0);
                    }
                    linear_from(&w, device)
                })
                .collect();
            let output = layers.pop().expect("three layers follow the trunk");
            let narrow = layers.pop().expect("two layers follow the trunk");
            let feature = layers.pop().expect("a layer follows the trunk");
            NerfMlp {
                trunk: layers,
                feature,
                narrow,
                output,
            }
        };
        let pose_code = linear_from(
            &pytorch_linear(self.encoded_width(1), self.code_size, false, &mut rng),
            device,
        );
        let rest: Vec<f64> = (0..self.code_size)
            .map(|_| standard_normal(&mut rng))
            .collect();
        let transform = nerf(self.transform_shapes(), true, &mut rng);
        let skin = nerf(self.skin_shapes(), false, &mut rng);
        let bone = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        Banmo {
            bones: Param::from_data(
                TensorData::new(bone.repeat(self.bones), [self.bones, 10]),
                device,
            ),
            rest_code: Param::from_data(TensorData::new(rest, [1, self.code_size]), device),
            pose_code,
            transform,
            skin,
            skin_aux: Param::from_data(TensorData::new(vec![0.0f32, 1.0], [2]), device),
            frequencies: self.frequencies,
            frames: self.frames,
        }
    }
}

/// One `N(0, 1)` draw (Box–Muller).
fn standard_normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A NeRF-style MLP: ReLU trunk layers (the 5th fed `[input, h]`), a linear feature
/// layer, a ReLU layer of half the width and a linear output.
#[derive(Module, Debug)]
pub struct NerfMlp {
    /// The ReLU trunk.
    pub trunk: Vec<Linear>,
    /// The linear feature layer after the trunk.
    pub feature: Linear,
    /// The ReLU layer of half the width.
    pub narrow: Linear,
    /// The output layer.
    pub output: Linear,
}

/// `[p, s] W + b` for a layer whose input is the point-dependent `p` followed by `shared`
/// (`[1, C]`, the same for every point): `shared`'s share of the product is a row, folded
/// into the bias, so that it is not repeated per point. `extra` (the skip layer's `h`)
/// follows both.
fn split_linear(layer: &Linear, p: Dual, shared: Option<&Tensor<2>>, extra: Option<Dual>) -> Dual {
    let w = layer.weight.val();
    let [_, out] = w.dims();
    let a = p.channels();
    let c = shared.map_or(0, |s| s.dims()[1]);
    let mut bias = layer.bias.as_ref().map(|b| b.val());
    if let Some(s) = shared {
        let row = s.clone().matmul(w.clone().narrow(0, a, c)).reshape([out]);
        bias = Some(match bias {
            Some(b) => b + row,
            None => row,
        });
    }
    let mut y = p.linear(w.clone().narrow(0, 0, a), bias);
    if let Some(h) = extra {
        let k = h.channels();
        y = y + h.linear(w.narrow(0, a + c, k), None);
    }
    y
}

fn apply(layer: &Linear, h: Dual) -> Dual {
    h.linear(layer.weight.val(), layer.bias.as_ref().map(|b| b.val()))
}

impl NerfMlp {
    /// The network on `[p, shared]` (`shared`: `[1, C]`, the same for every row).
    pub fn forward(&self, p: Dual, shared: Option<&Tensor<2>>) -> Dual {
        let mut h: Option<Dual> = None;
        for (i, layer) in self.trunk.iter().enumerate() {
            let z = match (i, h.take()) {
                (0, _) => split_linear(layer, p.clone(), shared, None),
                (SKIP, extra) => split_linear(layer, p.clone(), shared, extra),
                (_, Some(prev)) => apply(layer, prev),
                (_, None) => unreachable!("only the first layer has no input yet"),
            };
            h = Some(z.relu());
        }
        let h = h.expect("the trunk has a layer");
        let f = apply(&self.feature, h);
        apply(&self.output, apply(&self.narrow, f).relu())
    }
}

/// NeRF's Fourier encoding without π: `[v, sin 2⁰v, cos 2⁰v, …, sin 2^{L−1}v,
/// cos 2^{L−1}v]`, each frequency's block the sines of every column, then the cosines.
pub fn fourier_encode(v: Dual, frequencies: usize) -> Dual {
    let mut parts = vec![v.clone()];
    for k in 0..frequencies {
        let scaled = v.clone().mul_scalar((1u64 << k) as f64);
        parts.push(scaled.clone().sin());
        parts.push(scaled.cos());
    }
    Dual::cat(parts)
}

mod bones;

pub use bones::{BoneTransforms, quaternion_matrix, so3_exp};

/// BANMO's deformation module (docs/reference.md §2.3).
#[derive(Module, Debug)]
pub struct Banmo {
    /// Per bone: centre (3), orientation quaternion, real part first (4), log-precisions
    /// (3); `[B, 10]`, before the rest transform.
    pub bones: Param<Tensor<2>>,
    /// The rest code `z_r`, `[1, C]`.
    pub rest_code: Param<Tensor<2>>,
    /// The pose code's linear map, `γ(k)` → `z_k`.
    pub pose_code: Linear,
    /// The transform network `G`: a code → per bone `(τ/0.1, ω)`.
    pub transform: NerfMlp,
    /// The skinning MLP: `[γ(x), z_r]` → per-bone logit residuals.
    pub skin: NerfMlp,
    /// The skinning scalars: `a` (inverse temperature `1000 eᵃ`), and one the authors
    /// register but never read, kept so that the parameter layout is theirs.
    pub skin_aux: Param<Tensor<1>>,
    /// `L`.
    pub frequencies: usize,
    /// `T`.
    pub frames: usize,
}

impl Banmo {
    /// The frame nearest normalised time `t` ([`crate::field::frame_of`]).
    pub fn frame_of(&self, t: f64) -> usize {
        crate::field::frame_of(t, self.frames)
    }

    /// The number of bones `B`.
    pub fn bones(&self) -> usize {
        self.bones.dims()[0]
    }

    /// `G(z)` for codes `z: [M, C]`: per code and bone, `R = exp(ω)` and `0.1 τ`.
    fn transforms_of(&self, codes: Tensor<2>) -> Vec<BoneTransforms> {
        let m = codes.dims()[0];
        let b = self.bones();
        let out = self.transform.forward(Dual::constant(codes), None).value; // [M, 6B]
        (0..m)
            .map(|row| {
                let o = out.clone().narrow(0, row, 1).reshape([b, 6]);
                BoneTransforms {
                    rotations: so3_exp(o.clone().narrow(1, 3, 3)),
                    translations: o.narrow(1, 0, 3).mul_scalar(0.1),
                }
            })
            .collect()
    }

    /// The pose code `z_k = L(γ(k))` of frame `k` (the raw index), `[1, C]`.
    pub fn pose_code(&self, frame: usize) -> Tensor<2> {
        let device = self.rest_code.device();
        let k = Tensor::<2>::from_data(TensorData::new(vec![frame as f32], [1, 1]), &device);
        let gamma = fourier_encode(Dual::constant(k), self.frequencies);
        apply(&self.pose_code, gamma).value
    }

    /// The bones' rest transforms `G(z_r)` and their transforms at frame `k`, `G(z_k)`,
    /// from one pass of `G`.
    pub fn rest_and_pose(&self, frame: usize) -> (BoneTransforms, BoneTransforms) {
        let codes = Tensor::cat(vec![self.rest_code.val(), self.pose_code(frame)], 0);
        let mut both = self.transforms_of(codes);
        let pose = both.pop().expect("two codes");
        let rest = both.pop().expect("two codes");
        (rest, pose)
    }

    /// The normalised skinning weights `[N, B]` of `x` with the bones at `rest`: the
    /// softmax of the Gaussian terms plus the skinning MLP's residual.
    pub fn skinning_weights(&self, x: Dual, rest: &BoneTransforms) -> Dual {
        let b = self.bones();
        let bones = self.bones.val();
        let centre0 = bones.clone().narrow(1, 0, 3).unsqueeze_dim::<3>(2); // [B, 3, 1]
        let orient = quaternion_matrix(bones.clone().narrow(1, 3, 4));
        let precision = bones.narrow(1, 7, 3).exp(); // [B, 3]
        // The bones at rest: c = Rʳ c⁰ + τʳ, O = Rʳ M(q).
        let centre =
            rest.rotations.clone().matmul(centre0).reshape([b, 3]) + rest.translations.clone();
        let o = rest.rotations.clone().matmul(orient);
        // P = O diag(s) Oᵀ, so that Σ_i s_i [Oᵀ(c − x)]_i² = (x − c)ᵀ P (x − c), expanded
        // into xᵀPx − 2 (Pc)·x + cᵀPc: every term a matmul of [N, ·] by [·, B].
        let p = o
            .clone()
            .mul(precision.unsqueeze_dim::<3>(1))
            .matmul(o.swap_dims(1, 2)); // [B, 3, 3]
        let pc = p
            .clone()
            .matmul(centre.clone().unsqueeze_dim::<3>(2))
            .reshape([b, 3]);
        let cpc = pc.clone().mul(centre).sum_dim(1); // [B, 1]
        let pf = p.reshape([b, 9]);
        let entry = |i: usize, j: usize| pf.clone().narrow(1, 3 * i + j, 1);
        // xᵀPx over the six distinct products of P's symmetric entries.
        let quad_w = Tensor::cat(
            vec![
                entry(0, 0),
                entry(1, 1),
                entry(2, 2),
                entry(0, 1).mul_scalar(2.0),
                entry(0, 2).mul_scalar(2.0),
                entry(1, 2).mul_scalar(2.0),
            ],
            1,
        ); // [B, 6]
        let col = |i: usize| x.clone().narrow(i, 1);
        let quad = Dual::cat(vec![
            col(0).mul(col(0)),
            col(1).mul(col(1)),
            col(2).mul(col(2)),
            col(0).mul(col(1)),
            col(0).mul(col(2)),
            col(1).mul(col(2)),
        ]);
        // −1000 eᵃ, folded into the weights so that `a` is learnt.
        let scale = self
            .skin_aux
            .val()
            .narrow(0, 0, 1)
            .exp()
            .mul_scalar(-1000.0)
            .reshape([1, 1]);
        let quad_w = quad_w.transpose().mul(scale.clone());
        let lin_w = pc.transpose().mul_scalar(-2.0).mul(scale.clone());
        let gauss_bias = cpc.transpose().mul(scale).reshape([b]);
        let gauss = quad.linear(quad_w, Some(gauss_bias)) + x.clone().linear(lin_w, None);
        let residual = self.skin.forward(
            fourier_encode(x, self.frequencies),
            Some(&self.rest_code.val()),
        );
        (gauss + residual).softmax()
    }

    /// The raw outputs at frame `k`: the blended `A` (row-major) and `u`.
    fn raw_at(&self, x: Dual, frame: usize) -> Dual {
        let (rest, pose) = self.rest_and_pose(frame);
        let w = self.skinning_weights(x, &rest);
        pose.relative_to(&rest).blend(w)
    }
}

impl MotionField for Banmo {
    /// Forward mode on duals (the method is a general one: [`MotionField::accepts`]).
    fn raw(&self, x: Dual, t: f64, _general: &dyn JacobianMethod) -> Dual {
        self.raw_at(x, self.frame_of(t))
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

//! Motion fields: a SIREN `f(x, t)` plus a head that turns its raw outputs into a local
//! transformation `(A, u)`, so that `y = A x + u` (Eq. 4).
//!
//! The heads ([`trans`], [`se3`], [`scaled_se3`], [`affinity`]) are written once, on
//! [`Dual`]s: with tangents from a [`JacobianMethod`] the warp's Jacobian `∂y/∂x` comes out
//! for every variant; on plain values the same code is a plain forward pass.
//! [`model::ModelConfig`] names every model, the DOMA variants and the baselines.

pub mod affinity;
pub mod baselines;
pub mod dpf;
pub mod model;
pub mod rotation;
pub mod scaled_se3;
pub mod se3;
pub mod trans;

use burn::config::Config;
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};
use std::ops::{Add, Mul};

use crate::dual::Dual;
use crate::jacobian::{Autodiff, JacobianMethod};
use crate::siren::{Siren, SirenConfig, SirenShape, WithSirenShape};

/// The DOMA variants, which differ in the degrees of freedom of `A` (Sec. 3.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Variant {
    /// `A = I` (Eq. 10).
    Trans,
    /// `A ∈ SO(3)` (Eq. 11).
    Se3,
    /// `A = s Q`, `s > 0`, `Q ∈ SO(3)` (Eq. 12).
    ScaledSe3,
    /// A free 3×3 `A` (Eq. 4).
    Affinity,
}

impl Variant {
    /// All variants, in the paper's table order.
    pub const ALL: [Variant; 4] = [
        Variant::Trans,
        Variant::Se3,
        Variant::ScaledSe3,
        Variant::Affinity,
    ];

    /// The number of raw SIREN outputs of this head.
    pub fn outputs(self) -> usize {
        match self {
            Variant::Trans => trans::OUTPUTS,
            Variant::Se3 => se3::OUTPUTS,
            Variant::ScaledSe3 => scaled_se3::OUTPUTS,
            Variant::Affinity => affinity::OUTPUTS,
        }
    }

    /// The paper's name.
    pub fn paper_name(self) -> &'static str {
        match self {
            Variant::Trans => "Trans",
            Variant::Se3 => "SE(3)",
            Variant::ScaledSe3 => "Scaled SE(3)",
            Variant::Affinity => "Affinity",
        }
    }

    /// The head: raw outputs `[N, O]` → local transformation.
    pub fn local_affine(self, raw: Dual) -> LocalAffine {
        match self {
            Variant::Trans => trans::local_affine(raw),
            Variant::Se3 => se3::local_affine(raw),
            Variant::ScaledSe3 => scaled_se3::local_affine(raw),
            Variant::Affinity => affinity::local_affine(raw),
        }
    }
}

crate::names::value_names!(Variant);

/// A per-point affine map `y = A x + u`, with `A` given by its columns (`None` = `I`).
#[derive(Clone, Debug)]
pub struct LocalAffine {
    /// The three columns of `A`, each `[N, 3]`; `None` for the identity.
    pub columns: Option<[Dual; 3]>,
    /// `u`, `[N, 3]`.
    pub translation: Dual,
}

impl LocalAffine {
    /// `y = A x + u` for `x: [N, 3]`; the tangents of `x` (if any) flow into `y`.
    pub fn apply(self, x: Dual) -> Dual {
        match self.columns {
            None => x.add(self.translation),
            Some([c0, c1, c2]) => c0
                .mul(x.clone().narrow(0, 1))
                .add(c1.mul(x.clone().narrow(1, 1)))
                .add(c2.mul(x.narrow(2, 1)))
                .add(self.translation),
        }
    }

    /// `A` as `[N, 3, 3]` (`A[n, i, j]`), and `u` as `[N, 3]`.
    pub fn matrices(&self) -> (Tensor<3>, Tensor<2>) {
        let u = self.translation.value.clone();
        let a = match &self.columns {
            Some(cols) => Tensor::stack(cols.iter().map(|c| c.value.clone()).collect(), 2),
            None => {
                let n = u.dims()[0];
                Tensor::<2>::eye(3, &u.device())
                    .unsqueeze_dim::<3>(0)
                    .repeat_dim(0, n)
            }
        };
        (a, u)
    }
}

/// What a field evaluation returns: the raw network outputs and the warped points,
/// each with spatial tangents when they come from [`MotionField::warp_dual`].
#[derive(Clone, Debug)]
pub struct WarpOutput {
    /// The raw outputs `o = f(x, t)`, `[N, O]` (tangents: `∂o/∂x`, used by `L_H`).
    pub raw: Dual,
    /// The warped points `y`, `[N, 3]` (tangents: `∂y/∂x`, used by the elasticity loss).
    pub warped: Dual,
}

/// A motion field: canonical points `x` at normalised time `t ∈ [-1, 1]` → positions.
///
/// Every model whose network is made of SIREN layers runs them through the
/// [`JacobianMethod`] it is given, for values and for tangents alike. A model without
/// SIREN layers (the MLP baselines, BoneCloud) can only be differentiated on duals: it
/// accepts [general](JacobianMethod::is_general) methods alone
/// ([`MotionField::accepts`]), and the fit refuses the others instead of substituting one.
pub trait MotionField {
    /// The raw network outputs `o = f(x, t)`, `[N, O]`, at `x: [N, 3]` through `method`.
    /// When `x` carries its spatial seed ([`Dual::seed_spatial`]), `o` carries `∂o/∂x`
    /// (what `L_H` penalises, Eq. 13); on a constant `x` it is the value path, which a
    /// method may fuse ([`crate::jacobian::Analytic`] does).
    fn raw(&self, x: Dual, t: f64, method: &dyn JacobianMethod) -> Dual;

    /// The raw outputs with their spatial tangents `∂o/∂x`.
    fn raw_dual(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> Dual {
        self.raw(Dual::seed_spatial(x), t, method)
    }

    /// The raw outputs alone, `[N, O]`.
    fn raw_values(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> Tensor<2> {
        self.raw(Dual::constant(x), t, method).value
    }

    /// How the raw outputs become a local transformation `(A, u)` (Eq. 4): the DOMA
    /// field's variant; [`Variant::Trans`] (`A = I`, `u = raw`) for the displacement
    /// models (DPF, MLP, DCT-NeRF); [`Variant::Affinity`] for BoneCloud's blended map.
    fn head(&self) -> Variant;

    /// The model's one SIREN, when the model is a SIREN and a head (a DOMA field): what
    /// the fused step ([`crate::train::StepKind::Fused`]) trains. `None` (the default) for
    /// every other model.
    fn siren(&self) -> Option<&Siren> {
        None
    }

    /// The factor `s` on the time that the model's SIREN reads, `[x, s·t]`
    /// ([`DomaFieldConfig::time_scale`]): what the fused step feeds the same SIREN. 1 (the
    /// default) for every model but a DOMA field fitted to a long recording.
    fn time_scale(&self) -> f64 {
        1.0
    }

    /// Whether the model's network is made of SIREN layers (the default), which every
    /// Jacobian method can differentiate.
    fn has_siren_layers(&self) -> bool {
        true
    }

    /// Whether `method` applies to this model: every method for a SIREN-based model,
    /// only the general ones for the others.
    fn accepts(&self, method: &dyn JacobianMethod) -> bool {
        self.has_siren_layers() || method.is_general()
    }

    /// The number of trainable parameters.
    fn param_count(&self) -> usize;

    /// The warp `y = A x + u` at `x: [N, 3]`, time `t` (Eq. 4), with the tangents of the
    /// raw outputs and of `y` (`∂y/∂x`, the elasticity loss's input) computed by `method`.
    fn warp_dual(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> WarpOutput {
        let raw = self.raw_dual(x.clone(), t, method);
        head_warp(self.head(), x, raw)
    }

    /// The warp without tangents, through `method`'s value path. The fit loop uses it for
    /// the trajectory loss.
    fn warp_values(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> WarpOutput {
        let raw = Dual::constant(self.raw_values(x.clone(), t, method));
        head_warp(self.head(), x, raw)
    }

    /// The local transformation `(A [N, 3, 3], u [N, 3])` at `x`, `t` (Eq. 4).
    fn local_transform(&self, x: Tensor<2>, t: f64) -> (Tensor<3>, Tensor<2>) {
        let raw = Dual::constant(self.raw_values(x, t, &Autodiff));
        self.head().local_affine(raw).matrices()
    }

    /// The warped positions `y(x, t)`, `[N, 3]` (evaluation): through the fused SIREN op
    /// of [`crate::jacobian::Analytic`] where the model accepts it (on the CPU backends 4×
    /// faster than Burn's ops, whose `sin` is scalar libm), else by Burn's plain ops.
    fn warp(&self, x: Tensor<2>, t: f64) -> Tensor<2> {
        let fused = crate::jacobian::Analytic;
        if self.accepts(&fused) {
            self.warp_values(x, t, &fused).warped.value
        } else {
            self.warp_values(x, t, &Autodiff).warped.value
        }
    }
}

/// Refuses a Jacobian method that `field` does not accept ([`MotionField::accepts`]):
/// the one check behind every fit, so that no method is silently substituted.
pub fn check_method(
    field: &dyn MotionField,
    kind: crate::jacobian::JacobianKind,
) -> crate::Result<()> {
    if field.accepts(kind.method().as_ref()) {
        return Ok(());
    }
    Err(crate::DomaError::InvalidConfig(format!(
        "the {kind} Jacobian applies to SIREN layers only, and this model has none: use autodiff"
    )))
}

/// The frame of `frames` nearest normalised time `t` (`t_k = −1 + 2k/(T−1)`), clamped:
/// how the frame-indexed models (DPF, DCT-NeRF, BoneCloud) read the fit loop's time.
pub fn frame_of(t: f64, frames: usize) -> usize {
    if frames < 2 {
        return 0;
    }
    let k = ((t + 1.0) * 0.5 * (frames - 1) as f64).round();
    k.clamp(0.0, (frames - 1) as f64) as usize
}

/// The warp `y = A x + u` of raw outputs `raw` at `x` through `head` (Eq. 4). When `raw`
/// carries tangents, `x` is seeded with its own (`∂x/∂x = I`) so that `y` gets `∂y/∂x`.
pub fn head_warp(head: Variant, x: Tensor<2>, raw: Dual) -> WarpOutput {
    let x = if raw.has_tangent() {
        Dual::seed_spatial(x)
    } else {
        Dual::constant(x)
    };
    let warped = head.local_affine(raw.clone()).apply(x);
    WarpOutput { raw, warped }
}

/// A SIREN's raw outputs at `x` through `method`: its forward mode when `x` carries
/// tangents, its value path otherwise. `input` builds the network's input from `x`'s
/// values (`[x, t]` for DOMA, `x` for DPF).
pub fn siren_raw(
    siren: &Siren,
    x: Dual,
    method: &dyn JacobianMethod,
    input: impl FnOnce(Tensor<2>) -> Tensor<2>,
) -> Dual {
    if x.has_tangent() {
        method.forward_dual(siren, input(x.value))
    } else {
        Dual::constant(method.forward(siren, input(x.value)))
    }
}

/// `[x, t]`: appends a constant time column to `x: [N, 3]`.
pub fn time_input(x: Tensor<2>, t: f64) -> Tensor<2> {
    let n = x.dims()[0];
    let time = Tensor::<2>::full([n, 1], t, &x.device());
    Tensor::cat(vec![x, time], 1)
}

/// The frames whose normalised times `[−1, 1]` a DOMA field's SIREN reads as they are;
/// a fit to a longer recording stretches them to `[−s, s]`, `s = T / 1000`
/// ([`DomaFieldConfig::time_scale`], [`time_scale_for`]).
pub const TIME_SPAN_FRAMES: usize = 1000;

/// The largest time scale a DOMA field takes ([`DomaFieldConfig::time_scale`]).
pub const MAX_TIME_SCALE: f64 = 1e6;

/// The time scale `s` a fit gives a DOMA field for a recording of `frames` frames:
/// `None` (1) up to [`TIME_SPAN_FRAMES`], else `T / TIME_SPAN_FRAMES`.
///
/// A SIREN's first layer starts with a fixed band of frequencies over its input's range
/// (Eq. 1, `ω₀ = 30`), so on normalised times a recording twelve times as long is asked
/// for motion twelve times as fast: on a minute at 200 Hz (12,000 frames) the field
/// fitted the training tracks eleven times worse than on its first 5 s (EPE 385 against
/// 34 ×10⁻⁴), and filled gaps twice as badly (7.07 against 3.86 mm). Stretching time keeps the frequencies per frame of a 1,000-frame clip
/// (docs/design.md §7).
pub fn time_scale_for(frames: usize) -> Option<f64> {
    (frames > TIME_SPAN_FRAMES).then(|| frames as f64 / TIME_SPAN_FRAMES as f64)
}

/// The shape of a DOMA field: its variant (the head, Eq. 4, 10–12) and its SIREN body.
#[derive(Config, Debug)]
pub struct DomaFieldConfig {
    /// The head.
    pub variant: Variant,
    /// The SIREN's width, depth and frequency.
    #[config(default = "SirenShape::new()")]
    pub shape: SirenShape,
    /// The factor `s` on the normalised time `t` that the SIREN reads: `f(x, s·t)`, so
    /// that the times of a long recording span `[−s, s]` ([`time_scale_for`]). `None` (a
    /// config without the field) is 1: the paper's field, bit for bit.
    pub time_scale: Option<f64>,
}

impl WithSirenShape for DomaFieldConfig {
    fn shape_mut(&mut self) -> &mut SirenShape {
        &mut self.shape
    }
}

impl DomaFieldConfig {
    /// The SIREN of this field (input `[x, y, z, t]`, output the head's raw parameters).
    pub fn siren(&self) -> SirenConfig {
        SirenConfig::new(self.variant.outputs()).with_shape(self.shape.clone())
    }

    /// A field initialised from `seed` on `device`.
    pub fn init(&self, seed: u64, device: &Device) -> DomaField {
        DomaField {
            siren: self.siren().init(seed, device),
            variant: self.variant,
            time_scale: self.time_scale.unwrap_or(1.0),
        }
    }

    /// Refuses a time scale that is not a positive number up to [`MAX_TIME_SCALE`].
    pub fn validate(&self) -> crate::Result<()> {
        match self.time_scale {
            Some(s) if !(s > 0.0 && s <= MAX_TIME_SCALE) => {
                Err(crate::DomaError::InvalidConfig(format!(
                    "time scale {s} must be positive and at most {MAX_TIME_SCALE:e} \
                     (the SIREN reads s·t as f32, and sin of a larger time is noise)"
                )))
            }
            _ => self.shape.validate(),
        }
    }
}

/// One SIREN `f(x, t)` and a head: the DOMA motion field.
#[derive(Module, Debug)]
pub struct DomaField {
    /// The SIREN, input `[x, y, z, t]`, output the head's raw parameters.
    pub siren: Siren,
    /// The head.
    #[module(skip)]
    pub variant: Variant,
    /// The factor on the time the SIREN reads ([`DomaFieldConfig::time_scale`]).
    #[module(skip)]
    pub time_scale: f64,
}

impl MotionField for DomaField {
    fn raw(&self, x: Dual, t: f64, method: &dyn JacobianMethod) -> Dual {
        siren_raw(&self.siren, x, method, |x| {
            time_input(x, self.time_scale * t)
        })
    }

    /// The method seeds its own tangents, so `x`'s seed (an upload and a `repeat` per
    /// call, two kernel dispatches on a GPU) is not built.
    fn raw_dual(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> Dual {
        method.forward_dual(&self.siren, time_input(x, self.time_scale * t))
    }

    fn head(&self) -> Variant {
        self.variant
    }

    fn siren(&self) -> Option<&Siren> {
        Some(&self.siren)
    }

    fn time_scale(&self) -> f64 {
        self.time_scale
    }

    fn param_count(&self) -> usize {
        self.num_params()
    }
}

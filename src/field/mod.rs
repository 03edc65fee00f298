//! Motion fields: a SIREN `f(x, t)` plus a head that turns its raw outputs into a local
//! transformation `(A, u)`, so that `y = A x + u` (Eq. 4).
//!
//! The heads ([`trans`], [`se3`], [`scaled_se3`], [`affinity`]) are written once, on
//! [`Dual`]s: with a [`JacobianMethod`] the warp's Jacobian `∂y/∂x` comes out for every
//! variant; without one the same code is a plain forward pass.

pub mod affinity;
pub mod baselines;
pub mod dpf;
pub mod rotation;
pub mod scaled_se3;
pub mod se3;
pub mod trans;

use burn::config::Config;
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};
use std::ops::{Add, Mul};

use crate::jacobian::{Dual, JacobianMethod};
use crate::siren::{Siren, SirenConfig};

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

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Trans => "trans",
            Variant::Se3 => "se3",
            Variant::ScaledSe3 => "scaled-se3",
            Variant::Affinity => "affinity",
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

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

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
/// each with spatial tangents when a Jacobian was requested.
#[derive(Clone, Debug)]
pub struct WarpOutput {
    /// The raw outputs `o = f(x, t)`, `[N, O]` (tangents: `∂o/∂x`, used by `L_H`).
    pub raw: Dual,
    /// The warped points `y`, `[N, 3]` (tangents: `∂y/∂x`, used by the elasticity loss).
    pub warped: Dual,
}

/// A motion field: canonical points `x` at normalised time `t ∈ [-1, 1]` → positions.
pub trait MotionField {
    /// The raw network outputs `o = f(x, t)`, `[N, O]`, at `x: [N, 3]`; with `jacobian`
    /// they carry their spatial tangents `∂o/∂x` (what `L_H` penalises).
    fn raw_dual(&self, x: Tensor<2>, t: f64, jacobian: Option<&dyn JacobianMethod>) -> Dual;

    /// How the raw outputs become a local transformation `(A, u)` (Eq. 4): the DOMA
    /// field's variant; [`Variant::Trans`] (`A = I`, `u = raw`) for the displacement
    /// models (DPF, MLP, DCT-NeRF); [`Variant::Affinity`] for BoneCloud's blended map.
    fn head(&self) -> Variant;

    /// Evaluates the field at `x: [N, 3]`, time `t`: the raw outputs through
    /// [`MotionField::head`]. With `jacobian`, the outputs carry their spatial tangents.
    fn warp_dual(&self, x: Tensor<2>, t: f64, jacobian: Option<&dyn JacobianMethod>) -> WarpOutput {
        let raw = self.raw_dual(x.clone(), t, jacobian);
        head_warp(self.head(), x, raw, jacobian)
    }

    /// Like `warp_dual(x, t, None)` (no tangents), but through `method`'s value path,
    /// which a method may fuse ([`crate::jacobian::Analytic`] does). The fit loop uses it
    /// for the trajectory loss.
    fn warp_values(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> WarpOutput {
        let _ = method;
        self.warp_dual(x, t, None)
    }

    /// The local transformation `(A [N, 3, 3], u [N, 3])` at `x`, `t` (Eq. 4).
    fn local_transform(&self, x: Tensor<2>, t: f64) -> (Tensor<3>, Tensor<2>) {
        self.head()
            .local_affine(self.raw_dual(x, t, None))
            .matrices()
    }

    /// The number of trainable parameters.
    fn param_count(&self) -> usize;

    /// The warped positions `y(x, t)`, `[N, 3]`.
    fn warp(&self, x: Tensor<2>, t: f64) -> Tensor<2> {
        self.warp_dual(x, t, None).warped.value
    }
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

/// `x` as a dual: seeded for spatial tangents when a Jacobian is requested.
pub fn spatial_input(x: Tensor<2>, jacobian: Option<&dyn JacobianMethod>) -> Dual {
    match jacobian {
        Some(_) => Dual::seed_spatial(x),
        None => Dual::constant(x),
    }
}

/// The warp `y = A x + u` of raw outputs `raw` at `x` through `head` (Eq. 4), with the
/// tangents of `x` when a Jacobian is requested.
pub fn head_warp(
    head: Variant,
    x: Tensor<2>,
    raw: Dual,
    jacobian: Option<&dyn JacobianMethod>,
) -> WarpOutput {
    let warped = head
        .local_affine(raw.clone())
        .apply(spatial_input(x, jacobian));
    WarpOutput { raw, warped }
}

/// `[x, t]`: appends a constant time column to `x: [N, 3]`.
pub fn time_input(x: Tensor<2>, t: f64) -> Tensor<2> {
    let n = x.dims()[0];
    let time = Tensor::<2>::full([n, 1], t, &x.device());
    Tensor::cat(vec![x, time], 1)
}

/// The shape of a DOMA field: its variant and its SIREN.
#[derive(Config, Debug)]
pub struct DomaFieldConfig {
    /// The head.
    pub variant: Variant,
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

impl DomaFieldConfig {
    /// The SIREN of this field (input `[x, y, z, t]`).
    pub fn siren(&self) -> SirenConfig {
        SirenConfig::new(self.variant.outputs())
            .with_hidden(self.hidden)
            .with_n_hidden(self.n_hidden)
            .with_omega(self.omega)
    }

    /// A field initialised from `seed` on `device`.
    pub fn init(&self, seed: u64, device: &Device) -> DomaField {
        DomaField {
            siren: self.siren().init(seed, device),
            variant: self.variant,
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
}

impl MotionField for DomaField {
    fn raw_dual(&self, x: Tensor<2>, t: f64, jacobian: Option<&dyn JacobianMethod>) -> Dual {
        let xt = time_input(x, t);
        match jacobian {
            Some(method) => method.forward_dual(&self.siren, xt),
            None => Dual::constant(self.siren.forward(xt)),
        }
    }

    fn head(&self) -> Variant {
        self.variant
    }

    fn warp_values(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> WarpOutput {
        let raw = Dual::constant(method.forward(&self.siren, time_input(x.clone(), t)));
        head_warp(self.variant, x, raw, None)
    }

    fn param_count(&self) -> usize {
        self.num_params()
    }
}

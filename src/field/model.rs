//! Every model a fit can train, named by one config: the DOMA variants (Eq. 4, 10–12) and
//! the baselines of Tab. 1 and Tab. 3 (DPF, MLP-ReLU, MLP-ReLU PE.6, DCT-NeRF, BANMO,
//! BoneCloud).
//!
//! [`ModelConfig`] is what a run's `config.json` stores under `model`, e.g.
//! `{"doma": {"variant": "affinity", "shape": {…}}}` or `{"dpf": {"frames": 10, …}}`;
//! [`Model`] is the initialised module, itself a [`MotionField`], so that one fit loop,
//! one checkpoint format and one evaluation serve them all.

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::baselines::banmo::{Banmo, BanmoConfig};
use super::baselines::bone_cloud::{BoneCloud, BoneCloudConfig};
use super::baselines::dct::{DctConfig, DctNerf};
use super::baselines::mlp::{Mlp, MlpConfig};
use super::dpf::{Dpf, DpfConfig};
use super::{DomaField, DomaFieldConfig, MotionField, Variant};
use crate::checkpoint::{Precision, decode_checkpoint, encode_stable};
use crate::dual::Dual;
use crate::jacobian::{JacobianKind, JacobianMethod};
use crate::{DomaError, Result};

/// A model's name in tables and JSON records, spelled as the paper's rows (Tab. 1 names
/// the DOMA variants alone, Tab. 3 and A8 prefix them with "DOMA-").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ModelName {
    /// DOMA-Trans in Tab. 1 and 2.
    #[serde(rename = "Trans")]
    Trans,
    /// DOMA-SE(3).
    #[serde(rename = "SE(3)")]
    Se3,
    /// DOMA-Scaled SE(3).
    #[serde(rename = "Scaled SE(3)")]
    ScaledSe3,
    /// DOMA-Affinity in Tab. 1 and 2.
    #[serde(rename = "Affinity")]
    Affinity,
    /// DOMA-Trans in Tab. 3 and A8.
    #[serde(rename = "DOMA-Trans")]
    DomaTrans,
    /// DOMA-Affinity in Tab. 3 and A8.
    #[serde(rename = "DOMA-Affinity")]
    DomaAffinity,
    /// The frame-wise DPF baseline.
    #[serde(rename = "DPF")]
    Dpf,
    /// MLP-ReLU.
    #[serde(rename = "MLP-ReLU")]
    Mlp,
    /// MLP-ReLU PE.6.
    #[serde(rename = "MLP-ReLU PE.6")]
    MlpPe6,
    /// DCT-NeRF.
    #[serde(rename = "DCT-NeRF")]
    DctNerf,
    /// BANMO.
    #[serde(rename = "BANMO")]
    Banmo,
    /// BoneCloud.
    #[serde(rename = "BoneCloud")]
    BoneCloud,
}

impl ModelName {
    /// The name as printed and stored.
    pub fn as_str(self) -> &'static str {
        match self {
            ModelName::Trans => "Trans",
            ModelName::Se3 => "SE(3)",
            ModelName::ScaledSe3 => "Scaled SE(3)",
            ModelName::Affinity => "Affinity",
            ModelName::DomaTrans => "DOMA-Trans",
            ModelName::DomaAffinity => "DOMA-Affinity",
            ModelName::Dpf => "DPF",
            ModelName::Mlp => "MLP-ReLU",
            ModelName::MlpPe6 => "MLP-ReLU PE.6",
            ModelName::DctNerf => "DCT-NeRF",
            ModelName::Banmo => "BANMO",
            ModelName::BoneCloud => "BoneCloud",
        }
    }

    /// The Tab. 1/2 name of a DOMA variant.
    pub fn of_variant(variant: Variant) -> Self {
        match variant {
            Variant::Trans => ModelName::Trans,
            Variant::Se3 => ModelName::Se3,
            Variant::ScaledSe3 => ModelName::ScaledSe3,
            Variant::Affinity => ModelName::Affinity,
        }
    }
}

impl std::fmt::Display for ModelName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // `pad` so that width specifiers in tables apply.
        f.pad(self.as_str())
    }
}

/// The model of a fit.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelConfig {
    /// A DOMA field: one SIREN `f(x, t)` and a variant's head.
    Doma(DomaFieldConfig),
    /// The frame-wise DPF baseline: one SIREN per frame.
    Dpf(DpfConfig),
    /// MLP-ReLU, with Fourier features when `pe_octaves > 0` (MLP-ReLU PE.6).
    Mlp(MlpConfig),
    /// DCT-NeRF.
    DctNerf(DctConfig),
    /// BANMO (Gaussian bones, neural skinning, pose codes).
    Banmo(BanmoConfig),
    /// BoneCloud (linear blend skinning).
    BoneCloud(BoneCloudConfig),
}

impl ModelConfig {
    /// A DOMA field of `variant` with the paper's SIREN (128 wide, 2 hidden layers).
    pub fn doma(variant: Variant) -> Self {
        ModelConfig::Doma(DomaFieldConfig::new(variant))
    }

    /// The model's Tab. 1 name ("Affinity", "DPF", "MLP-ReLU PE.6", …).
    pub fn name(&self) -> ModelName {
        match self {
            ModelConfig::Doma(c) => ModelName::of_variant(c.variant),
            ModelConfig::Dpf(_) => ModelName::Dpf,
            ModelConfig::Mlp(c) if c.pe_octaves > 0 => ModelName::MlpPe6,
            ModelConfig::Mlp(_) => ModelName::Mlp,
            ModelConfig::DctNerf(_) => ModelName::DctNerf,
            ModelConfig::Banmo(_) => ModelName::Banmo,
            ModelConfig::BoneCloud(_) => ModelName::BoneCloud,
        }
    }

    /// The model's Tab. 1 name as text.
    pub fn paper_name(&self) -> &'static str {
        self.name().as_str()
    }

    /// Whether the model is built of SIREN layers, so that every Jacobian method applies
    /// (the others accept [`JacobianKind::Autodiff`] alone).
    pub fn is_siren(&self) -> bool {
        matches!(self, ModelConfig::Doma(_) | ModelConfig::Dpf(_))
    }

    /// Refuses a Jacobian method that cannot apply to this model, naming both.
    pub fn check_jacobian(&self, kind: JacobianKind) -> Result<()> {
        if self.is_siren() || kind.method().is_general() {
            return Ok(());
        }
        Err(DomaError::InvalidConfig(format!(
            "the {kind} Jacobian applies to SIREN layers only, and {} has none: use autodiff",
            self.paper_name()
        )))
    }

    /// The frames a frame-indexed model (DPF, DCT-NeRF, BANMO, BoneCloud) was built for; `None`
    /// for the DOMA fields and the MLP, which take any time.
    pub fn frames(&self) -> Option<usize> {
        match self {
            ModelConfig::Dpf(c) => Some(c.frames),
            ModelConfig::DctNerf(c) => Some(c.frames),
            ModelConfig::Banmo(c) => Some(c.frames),
            ModelConfig::BoneCloud(c) => Some(c.frames),
            ModelConfig::Doma(_) | ModelConfig::Mlp(_) => None,
        }
    }

    /// Refuses a frame-indexed model built for another number of frames than `data_frames`.
    pub fn check_frames(&self, data_frames: usize) -> Result<()> {
        match self.frames() {
            Some(t) if t != data_frames => Err(DomaError::InvalidConfig(format!(
                "{} is built for {t} frames, but the data has {data_frames}",
                self.paper_name()
            ))),
            _ => Ok(()),
        }
    }

    /// [`ModelConfig::num_params`] in checked arithmetic, without allocating: `None` past
    /// `usize`.
    pub fn checked_params(&self) -> Option<usize> {
        match self {
            ModelConfig::Doma(c) => c.siren().checked_params(),
            ModelConfig::Dpf(c) => c.siren().checked_params()?.checked_mul(c.frames),
            ModelConfig::Mlp(c) => c.checked_params(),
            ModelConfig::DctNerf(c) => c.checked_params(),
            ModelConfig::Banmo(c) => c.checked_params(),
            ModelConfig::BoneCloud(c) => c.checked_params(),
        }
    }

    /// The number of trainable parameters.
    pub fn num_params(&self) -> usize {
        match self {
            ModelConfig::Doma(c) => c.siren().num_params(),
            ModelConfig::Dpf(c) => c.num_params(),
            ModelConfig::Mlp(c) => c.num_params(),
            ModelConfig::DctNerf(c) => c.num_params(),
            ModelConfig::Banmo(c) => c.num_params(),
            ModelConfig::BoneCloud(c) => c.num_params(),
        }
    }

    /// Refuses shapes that cannot be built, and models of more than `MAX_PARAMS`
    /// parameters (an allocation that size would abort the process, not fail).
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(DomaError::InvalidConfig(m));
        match self {
            ModelConfig::Doma(c) => c.validate()?,
            ModelConfig::Dpf(c) => {
                c.shape.validate()?;
                if c.frames == 0 {
                    return bad("DPF needs at least one frame".into());
                }
            }
            ModelConfig::Mlp(c) if c.hidden == 0 => {
                return bad("hidden width must be at least 1".into());
            }
            ModelConfig::Mlp(c) if c.d_in != 4 || c.d_out != 3 => {
                return bad(format!(
                    "the MLP baseline maps [x, y, z, t] to a displacement: d_in 4 and d_out 3, \
                     not {} and {}",
                    c.d_in, c.d_out
                ));
            }
            ModelConfig::DctNerf(c) if c.hidden == 0 || c.frames == 0 => {
                return bad("DCT-NeRF needs a hidden width and frames".into());
            }
            ModelConfig::Banmo(c)
                if c.bones == 0
                    || c.frames == 0
                    || c.code_size == 0
                    || c.transform_layers == 0
                    || c.skin_layers == 0
                    || c.transform_width < 2
                    || c.skin_width < 2 =>
            {
                return bad("BANMO needs bones, frames, a code, and layers at least 2 wide".into());
            }
            ModelConfig::Banmo(c) if c.frequencies > MAX_FREQUENCIES => {
                return bad(format!(
                    "BANMO's {} frequencies are more than the {MAX_FREQUENCIES} its encoding \
                     computes (2^k for k < L, in 64 bits)",
                    c.frequencies
                ));
            }
            ModelConfig::BoneCloud(c) if c.bones == 0 || c.frames == 0 => {
                return bad("BoneCloud needs bones and frames".into());
            }
            ModelConfig::BoneCloud(c) if !(c.sigma.is_finite() && c.sigma > 0.0) => {
                return bad(format!(
                    "BoneCloud's sharpness sigma must be positive, not {}",
                    c.sigma
                ));
            }
            _ => {}
        }
        // Counted in closed form and checked arithmetic: a config of 10⁹ layers is refused
        // here, not after a 16 GB list of their shapes.
        match self.checked_params() {
            Some(params) if params <= MAX_PARAMS => Ok(()),
            Some(params) => bad(format!(
                "{} with {params} parameters is over the limit of {MAX_PARAMS}",
                self.paper_name()
            )),
            None => bad(format!(
                "{}'s parameter count overflows (the limit is {MAX_PARAMS})",
                self.paper_name()
            )),
        }
    }

    /// The model initialised from `seed` on `device`. `canonical` (`[N·3]`, the canonical
    /// training points) places BoneCloud's bones; the other models ignore it.
    pub fn init(&self, seed: u64, canonical: &[f32], device: &Device) -> Model {
        match self {
            ModelConfig::Doma(c) => Model::Doma(c.init(seed, device)),
            ModelConfig::Dpf(c) => Model::Dpf(c.init(seed, device)),
            ModelConfig::Mlp(c) => Model::Mlp(c.init(seed, device)),
            ModelConfig::DctNerf(c) => Model::DctNerf(c.init(seed, device)),
            ModelConfig::Banmo(c) => Model::Banmo(c.init(seed, device)),
            ModelConfig::BoneCloud(c) => Model::BoneCloud(c.init(canonical, seed, device)),
        }
    }
}

/// The most frequencies of BANMO's positional encoding: its `2^k` (`k < L`) is computed in
/// 64 bits (an `f32` argument has lost every bit of a unit-scale input long before).
pub const MAX_FREQUENCIES: usize = 63;

/// The largest model a config may ask for: 10⁸ parameters (400 MB of f32 weights, and as
/// much again for each of Adam's moments).
pub const MAX_PARAMS: usize = 100_000_000;

/// An initialised model of any [`ModelConfig`].
// One model per fit, so the size of the largest variant (BANMO's two networks) costs
// nothing worth a box.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Model {
    /// See [`ModelConfig::Doma`].
    Doma(DomaField),
    /// See [`ModelConfig::Dpf`].
    Dpf(Dpf),
    /// See [`ModelConfig::Mlp`].
    Mlp(Mlp),
    /// See [`ModelConfig::DctNerf`].
    DctNerf(DctNerf),
    /// See [`ModelConfig::Banmo`].
    Banmo(Banmo),
    /// See [`ModelConfig::BoneCloud`].
    BoneCloud(BoneCloud),
}

impl Model {
    /// The burnpack bytes of the model's parameters, as the bare module writes them (so a
    /// DOMA field's `model.bpk` is the same file whether or not it came through `Model`),
    /// with stable parameter ids: the same weights give the same bytes.
    pub fn encode(&self, precision: Precision) -> Result<Vec<u8>> {
        match self {
            Model::Doma(m) => encode_stable(m.clone(), precision),
            Model::Dpf(m) => encode_stable(m.clone(), precision),
            Model::Mlp(m) => encode_stable(m.clone(), precision),
            Model::DctNerf(m) => encode_stable(m.clone(), precision),
            Model::Banmo(m) => encode_stable(m.clone(), precision),
            Model::BoneCloud(m) => encode_stable(m.clone(), precision),
        }
    }

    /// Loads [`Model::encode`]'s bytes into this (freshly initialised) model of the same
    /// config.
    pub fn decode(self, bytes: &[u8]) -> Result<Self> {
        Ok(match self {
            Model::Doma(m) => Model::Doma(decode_checkpoint(m, bytes)?),
            Model::Dpf(m) => Model::Dpf(decode_checkpoint(m, bytes)?),
            Model::Mlp(m) => Model::Mlp(decode_checkpoint(m, bytes)?),
            Model::DctNerf(m) => Model::DctNerf(decode_checkpoint(m, bytes)?),
            Model::Banmo(m) => Model::Banmo(decode_checkpoint(m, bytes)?),
            Model::BoneCloud(m) => Model::BoneCloud(decode_checkpoint(m, bytes)?),
        })
    }

    /// The model as a motion field.
    pub fn as_field(&self) -> &dyn MotionField {
        match self {
            Model::Doma(m) => m,
            Model::Dpf(m) => m,
            Model::Mlp(m) => m,
            Model::DctNerf(m) => m,
            Model::Banmo(m) => m,
            Model::BoneCloud(m) => m,
        }
    }
}

impl MotionField for Model {
    fn raw(&self, x: Dual, t: f64, method: &dyn JacobianMethod) -> Dual {
        self.as_field().raw(x, t, method)
    }

    fn raw_dual(&self, x: Tensor<2>, t: f64, method: &dyn JacobianMethod) -> Dual {
        self.as_field().raw_dual(x, t, method)
    }

    fn head(&self) -> Variant {
        self.as_field().head()
    }

    fn has_siren_layers(&self) -> bool {
        self.as_field().has_siren_layers()
    }

    fn siren(&self) -> Option<&crate::siren::Siren> {
        self.as_field().siren()
    }

    fn time_scale(&self) -> f64 {
        self.as_field().time_scale()
    }

    fn param_count(&self) -> usize {
        self.as_field().param_count()
    }
}

#[cfg(test)]
mod tests;

//! The paper's baselines (Tab. 1), behind the same [`crate::field::MotionField`] trait and
//! the same fit loop as the DOMA variants: MLP-ReLU and MLP-ReLU PE.6 ([`mlp`]), DCT-NeRF
//! ([`dct`]), BANMO ([`banmo`]) and BoneCloud ([`bone_cloud`]). The frame-wise DPF
//! baseline is [`crate::field::dpf`].

pub mod banmo;
pub mod bone_cloud;
pub mod dct;
pub mod mlp;

use serde::{Deserialize, Serialize};

/// The baselines that the experiments can run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Baseline {
    /// MLP-ReLU, 6 × 128, input `[x, t]`.
    Mlp,
    /// MLP-ReLU with 6 octaves of Fourier features.
    MlpPe6,
    /// DCT-NeRF: an MLP of `x` gives DCT trajectory coefficients.
    DctNerf,
    /// BANMO: 25 Gaussian bones, a skinning MLP and pose codes.
    Banmo,
    /// BoneCloud: 1024 bones, RBF skinning.
    BoneCloud,
}

impl Baseline {
    /// All of them, in the paper's table order.
    pub const ALL: [Baseline; 5] = [
        Baseline::Mlp,
        Baseline::MlpPe6,
        Baseline::DctNerf,
        Baseline::Banmo,
        Baseline::BoneCloud,
    ];

    /// The paper's row name.
    pub fn paper_name(self) -> &'static str {
        match self {
            Baseline::Mlp => "MLP-ReLU",
            Baseline::MlpPe6 => "MLP-ReLU PE.6",
            Baseline::DctNerf => "DCT-NeRF",
            Baseline::Banmo => "BANMO",
            Baseline::BoneCloud => "BoneCloud",
        }
    }

    /// The model of this baseline for a `frames`-frame sequence, with the paper's sizes.
    pub fn config(self, frames: usize) -> super::model::ModelConfig {
        use super::model::ModelConfig;
        match self {
            Baseline::Mlp => ModelConfig::Mlp(mlp::MlpConfig::new()),
            Baseline::MlpPe6 => ModelConfig::Mlp(mlp::MlpConfig::new().with_pe_octaves(6)),
            Baseline::DctNerf => ModelConfig::DctNerf(dct::DctConfig::new(frames)),
            Baseline::Banmo => ModelConfig::Banmo(banmo::BanmoConfig::new(frames)),
            Baseline::BoneCloud => ModelConfig::BoneCloud(bone_cloud::BoneCloudConfig::new(frames)),
        }
    }

    /// Adam's learning rate (docs/reference.md §5: 1e-3 for BoneCloud and BANMO, 1e-4
    /// otherwise).
    pub fn learning_rate(self) -> f64 {
        match self {
            Baseline::BoneCloud | Baseline::Banmo => 1e-3,
            _ => 1e-4,
        }
    }
}

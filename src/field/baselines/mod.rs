//! The paper's baselines (Tab. 1), behind the same [`crate::field::MotionField`] trait and
//! the same fit loop as the DOMA variants: MLP-ReLU and MLP-ReLU PE.6 ([`mlp`]), DCT-NeRF
//! ([`dct`]) and BoneCloud ([`bone_cloud`]). The frame-wise DPF baseline is
//! [`crate::field::dpf`]. BANMO is not implemented.

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
    /// BoneCloud: 1024 bones, RBF skinning.
    BoneCloud,
}

impl Baseline {
    /// All of them, in the paper's table order.
    pub const ALL: [Baseline; 4] = [
        Baseline::Mlp,
        Baseline::MlpPe6,
        Baseline::DctNerf,
        Baseline::BoneCloud,
    ];

    /// The paper's row name.
    pub fn paper_name(self) -> &'static str {
        match self {
            Baseline::Mlp => "MLP-ReLU",
            Baseline::MlpPe6 => "MLP-ReLU PE.6",
            Baseline::DctNerf => "DCT-NeRF",
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
            Baseline::BoneCloud => ModelConfig::BoneCloud(bone_cloud::BoneCloudConfig::new(frames)),
        }
    }

    /// Adam's learning rate (docs/reference.md §5: 1e-3 for BoneCloud, 1e-4 otherwise).
    pub fn learning_rate(self) -> f64 {
        match self {
            Baseline::BoneCloud => 1e-3,
            _ => 1e-4,
        }
    }
}

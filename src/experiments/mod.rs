//! The paper's experiments as library functions, shared by the CLI and the examples.

pub mod fluid;
pub mod image2d;
pub mod meshes;
pub mod scaling;
pub mod speed;
pub mod synthetic;
pub mod time_to_accuracy;

use serde::{Deserialize, Serialize};

/// Which experiment wrote a JSON record (its `experiment` field).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Experiment {
    /// Tab. 1: fit 25 % of a mesh's vertices, predict the rest.
    NovelPoints,
    /// Tab. 3: guided alignment of a template.
    MeshAlignment,
    /// Supplement Tab. A8: clips of a fluid simulation.
    Fluid,
    /// Supplement Tab. A7: a deforming 2-D pixel grid.
    Image2d,
}

/// The regulariser of a record's row, spelled as the rows of the paper's tables: `none`,
/// `h` (`L_H`, Eq. 13), `e` (elasticity), `a` (AIAP), `ah` (both of Tab. 3's).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RowReg {
    /// None.
    None,
    /// The smoothness loss ("-H").
    H,
    /// The elasticity loss ("-E").
    E,
    /// AIAP ("-A").
    A,
    /// AIAP and the smoothness loss ("-AH").
    Ah,
}

impl RowReg {
    /// The suffix of the paper's row names ("", "-H", "-E", "-A", "-AH").
    pub fn suffix(self) -> &'static str {
        match self {
            RowReg::None => "",
            RowReg::H => "-H",
            RowReg::E => "-E",
            RowReg::A => "-A",
            RowReg::Ah => "-AH",
        }
    }
}

impl From<synthetic::Regularizer> for RowReg {
    fn from(r: synthetic::Regularizer) -> Self {
        match r {
            synthetic::Regularizer::None => RowReg::None,
            synthetic::Regularizer::H => RowReg::H,
            synthetic::Regularizer::E => RowReg::E,
        }
    }
}

impl From<meshes::AlignReg> for RowReg {
    fn from(r: meshes::AlignReg) -> Self {
        match r {
            meshes::AlignReg::None => RowReg::None,
            meshes::AlignReg::A => RowReg::A,
            meshes::AlignReg::H => RowReg::H,
            meshes::AlignReg::Ah => RowReg::Ah,
        }
    }
}

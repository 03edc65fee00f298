//! The paper's experiments as library functions, shared by the CLI and the examples.

pub mod fluid;
pub mod image2d;
pub mod meshes;
pub mod speed;
pub mod synthetic;

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

//! The paper's experiments as library functions, shared by the CLI and the examples.

pub mod fluid;
pub mod image2d;
pub mod meshes;
pub mod speed;
pub mod synthetic;

//! DeformingThings4D's `.anime` animated meshes, the layout of the dataset's own published
//! loader, little-endian:
//!
//! | field | type |
//! |---|---|
//! | `nf`, `nv`, `nt` | `i32` frames, vertices, triangles |
//! | base vertices | `nv × 3` `f32` |
//! | faces | `nt × 3` `i32` (0-based vertex indices) |
//! | offsets | `(nf − 1) × nv × 3` `f32`, frame `k` = base + offset `k − 1` |
//!
//! Frame 0 is the base mesh. The reader refuses a truncated, oversized or inconsistent file
//! (negative or zero counts, a face index out of range, non-finite coordinates) with
//! [`DomaError::Malformed`] naming the file; it never panics.

use std::path::Path;

use super::Trajectories;
use crate::{DomaError, Result};

/// An animated triangle mesh: per-vertex trajectories (frame 0 = the base mesh) and the
/// triangles, which every frame shares.
#[derive(Clone, Debug, PartialEq)]
pub struct AnimatedMesh {
    /// The vertices' positions in every frame, `[T, V, 3]`.
    pub trajectories: Trajectories,
    /// Triangles as 0-based vertex indices.
    pub faces: Vec<[u32; 3]>,
}

/// Reads a `.anime` file.
pub fn read_anime(path: impl AsRef<Path>) -> Result<AnimatedMesh> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| DomaError::io(path, e))?;
    parse_anime(&bytes).map_err(|reason| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    })
}

/// Parses the bytes of a `.anime` file ([`doma_formats::anime::parse`]); the error says
/// what is wrong.
pub fn parse_anime(bytes: &[u8]) -> std::result::Result<AnimatedMesh, String> {
    let a = doma_formats::anime::parse(bytes)?;
    Ok(AnimatedMesh {
        trajectories: Trajectories::from(a.frames),
        faces: a.faces,
    })
}

/// The bytes of `mesh` as a `.anime` file (offsets from frame 0).
pub fn encode_anime(mesh: &AnimatedMesh) -> Result<Vec<u8>> {
    doma_formats::anime::encode(&doma_formats::anime::Anime {
        frames: mesh.trajectories.to_frames(),
        faces: mesh.faces.clone(),
    })
    .map_err(DomaError::InvalidData)
}

/// Writes `mesh` to `path` as a `.anime` file, atomically.
pub fn write_anime(path: impl AsRef<Path>, mesh: &AnimatedMesh) -> Result<()> {
    crate::io::write_atomic(path.as_ref(), &encode_anime(mesh)?)
}

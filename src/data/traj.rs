//! The `.traj` point-trajectory format (`data/README.md`), little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 0..4 | magic `b"TRAJ"` |
//! | 4..8 | `u32` version = 1 |
//! | 8..12 | `u32` T, the number of frames |
//! | 12..16 | `u32` N, the number of points |
//! | 16.. | `T·N·3` `f32` positions, frame-major |
//!
//! A file whose length is not `16 + 12·T·N` is malformed. The reader refuses it, and
//! any other defect, with [`DomaError::Malformed`] naming the file; it never panics and
//! never allocates more than the file's own size.

use std::path::Path;

use super::Trajectories;
use crate::{DomaError, Result};

pub use doma_formats::traj::{MAGIC, VERSION};

/// Reads a `.traj` file.
pub fn read_traj(path: impl AsRef<Path>) -> Result<Trajectories> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| DomaError::io(path, e))?;
    parse_traj(&bytes).map_err(|reason| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    })
}

/// Parses the bytes of a `.traj` file ([`doma_formats::traj::parse`]); the error says
/// what is wrong (the caller adds the file name).
pub fn parse_traj(bytes: &[u8]) -> std::result::Result<Trajectories, String> {
    doma_formats::traj::parse(bytes).map(Trajectories::from)
}

/// The bytes of `data` as a `.traj` file.
pub fn encode_traj(data: &Trajectories) -> Result<Vec<u8>> {
    doma_formats::traj::encode(&data.to_frames()).map_err(DomaError::InvalidData)
}

/// Writes `data` to `path` as a `.traj` file, atomically (temporary file, then rename).
pub fn write_traj(path: impl AsRef<Path>, data: &Trajectories) -> Result<()> {
    crate::io::write_atomic(path.as_ref(), &encode_traj(data)?)
}

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

/// The four magic bytes.
pub const MAGIC: &[u8; 4] = b"TRAJ";
/// The only version there is.
pub const VERSION: u32 = 1;
const HEADER: usize = 16;

/// Reads a `.traj` file.
pub fn read_traj(path: impl AsRef<Path>) -> Result<Trajectories> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| DomaError::io(path, e))?;
    parse_traj(&bytes).map_err(|reason| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    })
}

/// Parses the bytes of a `.traj` file; the error says what is wrong (the caller adds
/// the file name).
pub fn parse_traj(bytes: &[u8]) -> std::result::Result<Trajectories, String> {
    if bytes.len() < HEADER {
        return Err(format!(
            "truncated: {} bytes, shorter than the 16-byte header",
            bytes.len()
        ));
    }
    if &bytes[0..4] != MAGIC {
        return Err(format!(
            "not a .traj file: the magic is {:?}, not \"TRAJ\"",
            String::from_utf8_lossy(&bytes[0..4])
        ));
    }
    let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    let (version, frames, points) = (word(4), word(8) as usize, word(12) as usize);
    if version != VERSION {
        return Err(format!(
            "unsupported version {version} (this reader knows 1)"
        ));
    }
    if frames == 0 || points == 0 {
        return Err(format!(
            "an empty sequence ({frames} frames, {points} points)"
        ));
    }
    let expected = frames
        .checked_mul(points)
        .and_then(|v| v.checked_mul(12))
        .and_then(|v| v.checked_add(HEADER))
        .ok_or_else(|| format!("{frames} frames × {points} points overflows"))?;
    if bytes.len() != expected {
        return Err(super::size_mismatch(
            bytes.len(),
            expected,
            &format!("{frames} frames × {points} points need 16 + 12·T·N ="),
        ));
    }
    let positions: Vec<f32> = bytes[HEADER..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Trajectories::new(frames, points, positions).map_err(|e| match e {
        DomaError::InvalidData(reason) => reason,
        other => other.to_string(),
    })
}

/// The bytes of `data` as a `.traj` file.
pub fn encode_traj(data: &Trajectories) -> Result<Vec<u8>> {
    let too_big = |what: &str, v: usize| {
        DomaError::InvalidData(format!("{what} = {v} does not fit the format's u32"))
    };
    let frames = u32::try_from(data.frames()).map_err(|_| too_big("T", data.frames()))?;
    let points = u32::try_from(data.points()).map_err(|_| too_big("N", data.points()))?;
    let mut out = Vec::with_capacity(HEADER + 4 * data.positions().len());
    out.extend_from_slice(MAGIC);
    for v in [VERSION, frames, points] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in data.positions() {
        out.extend_from_slice(&v.to_le_bytes());
    }
    Ok(out)
}

/// Writes `data` to `path` as a `.traj` file, atomically (temporary file, then rename).
pub fn write_traj(path: impl AsRef<Path>, data: &Trajectories) -> Result<()> {
    crate::io::write_atomic(path.as_ref(), &encode_traj(data)?)
}

//! The `.traj` format (little-endian): the magic `b"TRAJ"`, `u32` version 1, `u32` T,
//! `u32` N, then `T·N·3` `f32` positions, frame-major. A file whose length is not
//! `16 + 12·T·N` is malformed.

use crate::{Frames, size_mismatch};

/// The four magic bytes.
pub const MAGIC: &[u8; 4] = b"TRAJ";
/// The only version there is.
pub const VERSION: u32 = 1;
const HEADER: usize = 16;

/// Parses the bytes of a `.traj` file; the error says what is wrong (the caller adds
/// the file name).
pub fn parse(bytes: &[u8]) -> Result<Frames, String> {
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
        return Err(size_mismatch(
            bytes.len(),
            expected,
            &format!("{frames} frames × {points} points need 16 + 12·T·N ="),
        ));
    }
    let positions: Vec<f32> = bytes[HEADER..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Frames::new(frames, points, positions)
}

/// The bytes of `data` as a `.traj` file; refuses counts that do not fit a `u32`.
pub fn encode(data: &Frames) -> Result<Vec<u8>, String> {
    let too_big = |what: &str, v: usize| format!("{what} = {v} does not fit the format's u32");
    let frames = u32::try_from(data.frames).map_err(|_| too_big("T", data.frames))?;
    let points = u32::try_from(data.points).map_err(|_| too_big("N", data.points))?;
    let mut out = Vec::with_capacity(HEADER + 4 * data.positions.len());
    out.extend_from_slice(MAGIC);
    for v in [VERSION, frames, points] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in &data.positions {
        out.extend_from_slice(&v.to_le_bytes());
    }
    Ok(out)
}

//! The file formats of doma as pure functions over bytes and text: `.traj` ([`traj`]),
//! DeformingThings4D `.anime` ([`anime`]), NumPy `.npy` ([`npy`]) and `.npz` ([`npz`]),
//! OBJ meshes ([`obj`]), any OBJ with its materials for display ([`textured`]), and C3D
//! ([`c3d`]) and OpenSim's TRC ([`trc`]) motion-capture files. The `.npz` and C3D readers take their bytes from memory
//! or from the file a piece at a time ([`source`]).
//!
//! This crate has no Burn dependency, so that the readers can be fuzzed (`fuzz/` in the
//! doma repository) without building a deep-learning framework under coverage
//! instrumentation. Every parser returns `Err(reason)` for a bad input, never panics; the
//! `doma` crate adds the file name and turns the result into its own types.

#![forbid(unsafe_code)]

pub mod anime;
pub mod c3d;
pub mod npy;
pub mod npz;
pub mod obj;
pub mod source;
pub mod textured;
pub mod traj;
pub mod trc;

/// Checked point positions: `frames × points` points, `[T, N, 3]` frame-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Frames {
    /// `T`.
    pub frames: usize,
    /// `N`.
    pub points: usize,
    /// `T·N·3` finite coordinates.
    pub positions: Vec<f32>,
}

impl Frames {
    /// Checks `positions` ([`check_positions`]) and wraps them.
    pub fn new(frames: usize, points: usize, positions: Vec<f32>) -> Result<Self, String> {
        check_positions(frames, points, &positions)?;
        Ok(Frames {
            frames,
            points,
            positions,
        })
    }
}

/// Refuses an empty sequence, a length that is not `T·N·3`, and non-finite coordinates
/// (naming the frame, point and coordinate).
pub fn check_positions(frames: usize, points: usize, positions: &[f32]) -> Result<(), String> {
    if frames == 0 || points == 0 {
        return Err(format!(
            "an empty sequence ({frames} frames, {points} points)"
        ));
    }
    let expected = frames
        .checked_mul(points)
        .and_then(|v| v.checked_mul(3))
        .ok_or_else(|| "frame × point count overflows".to_string())?;
    if positions.len() != expected {
        return Err(format!(
            "{} coordinates for {frames} frames × {points} points × 3 = {expected}",
            positions.len()
        ));
    }
    if let Some(i) = positions.iter().position(|v| !v.is_finite()) {
        let (f, p) = (i / (3 * points), (i / 3) % points);
        return Err(format!(
            "coordinate {} of point {p} in frame {f} is {}",
            i % 3,
            positions[i]
        ));
    }
    Ok(())
}

/// The message for a file of `actual` bytes whose header says `expected`: "truncated" or
/// "oversized", then `need` and the expected size.
pub fn size_mismatch(actual: usize, expected: usize, need: &str) -> String {
    let what = if actual < expected {
        "truncated"
    } else {
        "oversized"
    };
    format!("{what}: {actual} bytes, but {need} {expected}")
}

/// The CRC-32 lookup table (IEEE 802.3, reflected polynomial `0xEDB88320`).
const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = (c >> 1) ^ (0xEDB8_8320 & (c & 1).wrapping_neg());
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// An incremental CRC-32 (IEEE 802.3, as zip and PNG use), so that a member can be checked
/// while it is inflated, in pieces.
#[derive(Clone, Copy, Debug)]
pub struct Crc32(u32);

impl Default for Crc32 {
    fn default() -> Self {
        Crc32(!0)
    }
}

impl Crc32 {
    /// Adds `bytes`.
    pub fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 >> 8) ^ CRC_TABLE[((self.0 ^ b as u32) & 0xFF) as usize];
        }
    }

    /// The CRC of everything added.
    pub fn finish(self) -> u32 {
        !self.0
    }
}

/// CRC-32 of `bytes`.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = Crc32::default();
    crc.update(bytes);
    crc.finish()
}

#[cfg(test)]
mod tests {
    #[test]
    fn crc32_matches_the_standard_check_value() {
        assert_eq!(super::crc32(b"123456789"), 0xCBF4_3926);
    }
}

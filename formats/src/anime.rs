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
//! an error saying what is wrong; it never panics.

use crate::{Frames, size_mismatch};

/// An animated triangle mesh: per-vertex positions (frame 0 = the base mesh) and the
/// triangles, which every frame shares.
#[derive(Clone, Debug, PartialEq)]
pub struct Anime {
    /// The vertices' positions in every frame, `[T, V, 3]`.
    pub frames: Frames,
    /// Triangles as 0-based vertex indices.
    pub faces: Vec<[u32; 3]>,
}

fn read_i32(bytes: &[u8], at: usize) -> i32 {
    i32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn read_f32(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

/// Parses the bytes of a `.anime` file; the error says what is wrong.
pub fn parse(bytes: &[u8]) -> Result<Anime, String> {
    if bytes.len() < 12 {
        return Err(format!(
            "truncated: {} bytes, shorter than the 12-byte header",
            bytes.len()
        ));
    }
    let count = |at: usize, what: &str| -> Result<usize, String> {
        let v = read_i32(bytes, at);
        if v <= 0 {
            Err(format!("the {what} count is {v}; it must be positive"))
        } else {
            Ok(v as usize)
        }
    };
    let (nf, nv, nt) = (
        count(0, "frame")?,
        count(4, "vertex")?,
        count(8, "triangle")?,
    );
    let overflow = || format!("{nf} frames × {nv} vertices × {nt} triangles overflows");
    let base_len = nv.checked_mul(12).ok_or_else(overflow)?;
    let face_len = nt.checked_mul(12).ok_or_else(overflow)?;
    let offs_len = (nf - 1).checked_mul(base_len).ok_or_else(overflow)?;
    let expected = [base_len, face_len, offs_len]
        .iter()
        .try_fold(12usize, |acc, &v| acc.checked_add(v))
        .ok_or_else(overflow)?;
    if bytes.len() != expected {
        return Err(size_mismatch(
            bytes.len(),
            expected,
            &format!("{nf} frames, {nv} vertices and {nt} triangles need"),
        ));
    }
    let base_at = 12;
    let faces_at = base_at + base_len;
    let offs_at = faces_at + face_len;
    let faces = (0..nt)
        .map(|f| {
            let mut tri = [0u32; 3];
            for (c, slot) in tri.iter_mut().enumerate() {
                let v = read_i32(bytes, faces_at + 4 * (3 * f + c));
                if v < 0 || v as usize >= nv {
                    return Err(format!("face {f} refers to vertex {v}, outside 0..{nv}"));
                }
                *slot = v as u32;
            }
            Ok(tri)
        })
        .collect::<Result<Vec<_>, String>>()?;
    let base: Vec<f32> = (0..3 * nv)
        .map(|i| read_f32(bytes, base_at + 4 * i))
        .collect();
    let mut positions = Vec::with_capacity(nf * 3 * nv);
    positions.extend_from_slice(&base);
    for k in 1..nf {
        let at = offs_at + (k - 1) * base_len;
        positions.extend((0..3 * nv).map(|i| base[i] + read_f32(bytes, at + 4 * i)));
    }
    let frames = Frames::new(nf, nv, positions)?;
    Ok(Anime { frames, faces })
}

/// The bytes of `mesh` as a `.anime` file (offsets from frame 0).
pub fn encode(mesh: &Anime) -> Result<Vec<u8>, String> {
    let t = &mesh.frames;
    let fit = |what: &str, v: usize| {
        i32::try_from(v).map_err(|_| format!("{what} = {v} does not fit an i32"))
    };
    let (nf, nv, nt) = (
        fit("frames", t.frames)?,
        fit("vertices", t.points)?,
        fit("triangles", mesh.faces.len())?,
    );
    if nt == 0 {
        return Err("a .anime mesh needs triangles".into());
    }
    if let Some((f, tri)) = mesh
        .faces
        .iter()
        .enumerate()
        .find(|(_, tri)| tri.iter().any(|&v| v as usize >= t.points))
    {
        return Err(format!(
            "face {f} {tri:?} refers to a vertex outside 0..{}",
            t.points
        ));
    }
    let mut out = Vec::with_capacity(12 + 4 * (t.positions.len() + 3 * mesh.faces.len()));
    for v in [nf, nv, nt] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let len = 3 * t.points;
    let base = &t.positions[..len];
    for v in base {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for tri in &mesh.faces {
        for &v in tri {
            out.extend_from_slice(&(v as i32).to_le_bytes());
        }
    }
    for k in 1..t.frames {
        for (p, b) in t.positions[k * len..(k + 1) * len].iter().zip(base) {
            out.extend_from_slice(&(p - b).to_le_bytes());
        }
    }
    Ok(out)
}

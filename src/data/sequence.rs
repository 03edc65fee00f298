//! Loading a user's sequence: any supported file (`.traj`, `.anime`, `.npy`, `.npz`, a
//! folder of OBJ frames) with its faces, a clip and a stride, normalised; and the seeded
//! split of its points into training and held-out sets (the paper's Tab. 1 protocol).

use std::ops::Range;
use std::path::Path;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::mesh::read_obj;
use super::{Trajectories, anime, npy, traj};
use crate::{DomaError, Result};

/// An animated mesh: vertex trajectories `[T, V, 3]` and, when known, the triangles.
#[derive(Clone, Debug)]
pub struct Sequence {
    /// A short name for the records (the file stem).
    pub name: String,
    /// The vertices' positions in every frame.
    pub trajectories: Trajectories,
    /// The triangles (vertex order = trajectory point order).
    pub faces: Option<Vec<[u32; 3]>>,
    /// The normalisation applied: `x' = (x − center) / scale`.
    pub center: [f32; 3],
    /// See `center`.
    pub scale: f32,
}

/// Loads `data` (`.traj`, `.anime`, `.npy`, `.npz`, or a folder of OBJ frames with equal
/// vertex counts); the faces come from `mesh` (an OBJ
/// whose vertices are the points in order), else from the `.anime`, else from a sibling
/// `NAME.obj` next to a `.traj`. Then keeps `frames` every `stride`-th frame, and
/// normalises the coordinates ([`Trajectories::normalized`]: frame 0's bounding box centred,
/// its longest side spanning `[−1, 1]`); every metric is in these units. An OBJ whose
/// vertex count differs from the point count is refused, naming the file.
pub fn load_sequence(
    data: &Path,
    mesh: Option<&Path>,
    frames: Option<Range<usize>>,
    stride: usize,
) -> Result<Sequence> {
    let (trajectories, mut faces) = read_any(data)?;
    let ext = extension(data);
    let sibling = data.with_extension("obj");
    let obj = mesh
        .map(Path::to_path_buf)
        .or_else(|| (faces.is_none() && ext == "traj" && sibling.is_file()).then_some(sibling));
    if let Some(obj) = obj {
        let m = read_obj(&obj)?;
        if m.vertices.len() != trajectories.points() {
            return Err(DomaError::Malformed {
                path: obj,
                reason: format!(
                    "{} vertices, but {} has {} points",
                    m.vertices.len(),
                    data.display(),
                    trajectories.points()
                ),
            });
        }
        faces = Some(m.faces);
    }
    let trajectories = match frames {
        Some(r) => trajectories.select_frames(r, stride)?,
        None if stride > 1 => trajectories.select_frames(0..trajectories.frames(), stride)?,
        None => trajectories,
    };
    // Fit and measure in normalised coordinates, so that one ω₀ suits every user's units.
    let (trajectories, center, scale) =
        trajectories
            .normalized()
            .map_err(|e| DomaError::Malformed {
                path: data.to_path_buf(),
                reason: e.to_string(),
            })?;
    let name = data
        .file_stem()
        .map_or("data".into(), |s| s.to_string_lossy().into_owned());
    Ok(Sequence {
        name,
        trajectories,
        faces,
        center,
        scale,
    })
}

/// The file's extension, lower-case ("" if none).
fn extension(data: &Path) -> String {
    data.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

/// Reads any supported sequence file (or OBJ folder) by its extension: the trajectories,
/// and the faces where the format has them.
pub fn read_any(data: &Path) -> Result<(Trajectories, Option<Vec<[u32; 3]>>)> {
    let meta = std::fs::metadata(data).map_err(|e| DomaError::io(data, e))?;
    if !(meta.is_file() || meta.is_dir()) {
        // A FIFO or a device would block a read forever, or never end.
        return Err(DomaError::Malformed {
            path: data.to_path_buf(),
            reason: "not a regular file or folder (a FIFO, a socket or a device)".into(),
        });
    }
    Ok(match extension(data).as_str() {
        _ if data.is_dir() => {
            let (t, f) = super::mesh::read_obj_sequence(data)?;
            (t, Some(f))
        }
        "traj" => (traj::read_traj(data)?, None),
        "anime" => {
            let a = anime::read_anime(data)?;
            (a.trajectories, Some(a.faces))
        }
        "npy" => (npy::read_npy_trajectories(data)?, None),
        "npz" => (npy::read_npz_trajectories(data, None)?, None),
        _ => {
            return Err(DomaError::Malformed {
                path: data.to_path_buf(),
                reason:
                    "unknown format: expected .traj, .anime, .npy, .npz or a folder of .obj frames"
                        .into(),
            });
        }
    })
}

/// A seeded split of `n` indices into `round(fraction · n)` and the rest.
pub fn split_indices(n: usize, fraction: f64, seed: u64) -> Result<(Vec<usize>, Vec<usize>)> {
    let n_train = (fraction * n as f64).round() as usize;
    if !(fraction > 0.0 && fraction < 1.0) || n_train == 0 || n_train >= n {
        return Err(DomaError::InvalidConfig(format!(
            "a training fraction of {fraction} does not split {n} points into two non-empty sets"
        )));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    let test = order.split_off(n_train);
    Ok((order, test))
}

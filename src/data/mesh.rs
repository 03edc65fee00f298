//! Triangle meshes: OBJ files and sequences, vertex normals, unique edges, area-weighted
//! surface sampling (Sec. 4.2, Tab. 1 and Tab. 3 evaluate on meshes). Warping a mesh through
//! a fitted field is [`crate::warp`], above both `data` and `field`.
//!
//! OBJ is read by a small parser of our own rather than `tobj`: a mesh's vertex order *is*
//! its point identity here (vertex `i` of the OBJ is point `i` of the `.traj`), and `tobj`
//! renumbers vertices in the order the faces first use them and drops unused ones. Only
//! `v` and `f` records matter; polygons are fan-triangulated; every other record is skipped.

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub use doma_formats::obj::{TriMesh, check_faces, encode_obj, parse_obj, write_obj_to};

use super::Trajectories;
use crate::io::write_atomic;
use crate::{DomaError, Result};

/// Reads an OBJ mesh (vertex order preserved).
pub fn read_obj(path: impl AsRef<Path>) -> Result<TriMesh> {
    let path = path.as_ref();
    let bytes = crate::io::read_input(path, crate::io::InputKind::Mesh)?;
    let malformed = |reason| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    };
    let text = std::str::from_utf8(&bytes).map_err(|_| malformed("not UTF-8 text".into()))?;
    parse_obj(text).map_err(malformed)
}

/// Writes an OBJ file atomically (`encode_obj`).
pub fn write_obj(
    path: impl AsRef<Path>,
    mesh: &TriMesh,
    normals: Option<&[[f32; 3]]>,
) -> Result<()> {
    write_atomic(
        path.as_ref(),
        encode_obj(&mesh.vertices, &mesh.faces, normals).as_bytes(),
    )
}

/// Writes every frame of `frames` (`[T, V, 3]`) as `dir/frame_0000.obj`, … with `faces`
/// and recomputed vertex normals, so that any viewer can play the sequence. Each file is
/// written atomically. Returns the paths.
pub fn write_obj_sequence(
    dir: impl AsRef<Path>,
    frames: &Trajectories,
    faces: &[[u32; 3]],
) -> Result<Vec<PathBuf>> {
    let dir = dir.as_ref();
    check_faces(faces, frames.points()).map_err(DomaError::InvalidData)?;
    std::fs::create_dir_all(dir).map_err(|e| DomaError::io(dir, e))?;
    (0..frames.frames())
        .map(|k| {
            let vertices = as_points(frames.frame(k));
            let normals = vertex_normals(&vertices, faces);
            let path = dir.join(format!("frame_{k:04}.obj"));
            write_atomic(
                &path,
                encode_obj(&vertices, faces, Some(&normals)).as_bytes(),
            )?;
            Ok(path)
        })
        .collect()
}

/// Reads a folder of OBJ frames (sorted by file name) with equal vertex counts as
/// trajectories plus the first frame's faces. Refuses an empty folder and frames whose
/// vertex counts differ (naming the file).
pub fn read_obj_sequence(dir: impl AsRef<Path>) -> Result<(Trajectories, Vec<[u32; 3]>)> {
    let dir = dir.as_ref();
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| DomaError::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("obj")))
        .collect();
    // Natural order: `frame_2` before `frame_10`.
    files
        .sort_by(|a, b| doma_formats::obj::natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    if files.is_empty() {
        return Err(DomaError::Malformed {
            path: dir.to_path_buf(),
            reason: "the folder holds no .obj frames".into(),
        });
    }
    let meshes = files.iter().map(read_obj).collect::<Result<Vec<_>>>()?;
    let frames = doma_formats::obj::stack_frames(&meshes).map_err(|e| DomaError::Malformed {
        path: files[e.frame].clone(),
        reason: if e.frame > 0 {
            format!("{} (the first frame is {})", e.reason, files[0].display())
        } else {
            e.reason
        },
    })?;
    let faces = meshes
        .into_iter()
        .next()
        .map(|m| m.faces)
        .unwrap_or_default();
    Ok((Trajectories::from(frames), faces))
}

/// `[V·3]` → `[V][3]`.
pub fn as_points(flat: &[f32]) -> Vec<[f32; 3]> {
    flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f32; 3]) -> f32 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// `v / |v|`, or zero for a zero vector.
pub fn normalize(a: [f32; 3]) -> [f32; 3] {
    let n = norm(a);
    if n > 0.0 { a.map(|c| c / n) } else { [0.0; 3] }
}

/// `(b − a) × (c − a)` of face `f`: twice its area times its unit normal.
fn face_cross(vertices: &[[f32; 3]], f: [u32; 3]) -> [f32; 3] {
    let [a, b, c] = f.map(|i| vertices[i as usize]);
    cross(sub(b, a), sub(c, a))
}

/// Face areas.
pub fn face_areas(vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> Vec<f32> {
    faces
        .iter()
        .map(|&f| 0.5 * norm(face_cross(vertices, f)))
        .collect()
}

/// Area-weighted unit vertex normals: the sum of the adjacent faces' `(b−a)×(c−a)`,
/// normalised; zero for a vertex in no (non-degenerate) face.
pub fn vertex_normals(vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut acc = vec![[0f32; 3]; vertices.len()];
    for &f in faces {
        let n = face_cross(vertices, f);
        for i in f {
            for c in 0..3 {
                acc[i as usize][c] += n[c];
            }
        }
    }
    acc.into_iter().map(normalize).collect()
}

/// The unique undirected edges `[a, b]`, `a < b`, sorted.
pub fn unique_edges(faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|&[a, b, c]| [[a, b], [b, c], [c, a]])
        .map(|[a, b]| if a < b { [a, b] } else { [b, a] })
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// Points on a mesh surface: for each, its face and barycentric coordinates, so that the
/// same material points can be placed on any pose of the mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceSamples {
    /// The face of each sample.
    pub face: Vec<u32>,
    /// The barycentric weights `(w_a, w_b, w_c)` of each sample.
    pub bary: Vec<[f32; 3]>,
}

impl SurfaceSamples {
    /// Draws `n` points uniformly by area on the mesh `(vertices, faces)` (the face by
    /// inverse-CDF of the areas, the point by the square-root barycentric rule), seeded.
    /// Refuses a mesh of zero area.
    pub fn draw(
        vertices: &[[f32; 3]],
        faces: &[[u32; 3]],
        n: usize,
        rng: &mut impl Rng,
    ) -> Result<Self> {
        let mut cdf = Vec::with_capacity(faces.len());
        let mut total = 0f64;
        for a in face_areas(vertices, faces) {
            total += a as f64;
            cdf.push(total);
        }
        if !(total > 0.0 && total.is_finite()) {
            return Err(DomaError::InvalidData(format!(
                "cannot sample a surface of area {total} ({} faces)",
                faces.len()
            )));
        }
        let mut face = Vec::with_capacity(n);
        let mut bary = Vec::with_capacity(n);
        for _ in 0..n {
            let u = rng.random::<f64>() * total;
            let f = cdf.partition_point(|&c| c <= u).min(faces.len() - 1);
            let (r1, r2) = (rng.random::<f32>().sqrt(), rng.random::<f32>());
            face.push(f as u32);
            bary.push([1.0 - r1, r1 * (1.0 - r2), r1 * r2]);
        }
        Ok(SurfaceSamples { face, bary })
    }

    /// Like [`SurfaceSamples::draw`] from a seed.
    pub fn seeded(vertices: &[[f32; 3]], faces: &[[u32; 3]], n: usize, seed: u64) -> Result<Self> {
        Self::draw(vertices, faces, n, &mut ChaCha8Rng::seed_from_u64(seed))
    }

    /// The number of samples.
    pub fn len(&self) -> usize {
        self.face.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.face.is_empty()
    }

    /// The samples' positions on the pose `vertices` of the mesh.
    pub fn points(&self, vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> Vec<[f32; 3]> {
        self.face
            .iter()
            .zip(&self.bary)
            .map(|(&f, w)| {
                let [a, b, c] = faces[f as usize].map(|i| vertices[i as usize]);
                std::array::from_fn(|k| w[0] * a[k] + w[1] * b[k] + w[2] * c[k])
            })
            .collect()
    }

    /// The samples' unit normals (their faces' normals) on the pose `vertices`.
    pub fn normals(&self, vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> Vec<[f32; 3]> {
        self.face
            .iter()
            .map(|&f| normalize(face_cross(vertices, faces[f as usize])))
            .collect()
    }
}

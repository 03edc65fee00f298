//! `doma warp`: a canonical mesh through a fitted run, as an OBJ sequence.

use std::path::{Path, PathBuf};

use burn::tensor::Device;

use super::{OpenRun, RunDir};
use crate::data::mesh::{TriMesh, as_points, read_obj, vertex_normals, write_obj_to};
use crate::data::sequence::Sequence;
use crate::data::textured::TexturedMesh;
use crate::io::write_atomic_with;
use crate::{DomaError, Result};

/// Warps the canonical mesh `mesh` (an OBJ in the data's own units: a plain triangle mesh
/// keeps its vertex order; one with UVs or materials, or polygons, is read by
/// [`TexturedMesh`] and written back with them; default: the run data's own canonical
/// frame with its faces) through the run's field to frames `frames` (default:
/// all of the run's frames) and writes `out/frame_0000.obj`, … with recomputed normals, each
/// atomically. Returns the paths written.
pub fn warp_run(
    run: &RunDir,
    mesh: Option<&Path>,
    out: &Path,
    frames: Option<std::ops::Range<usize>>,
    device: &Device,
) -> Result<Vec<PathBuf>> {
    let OpenRun {
        config,
        field,
        data: own,
        frames: range,
    } = run.open(frames, device)?;
    let total = own.trajectories.frames();
    let inputs: Vec<&Path> = std::iter::once(config.data.as_path()).chain(mesh).collect();
    crate::io::check_output(out, Some(&run.dir), &inputs)?;
    // The mesh and every file it names are checked before the output folder is made, so
    // that a refusal leaves nothing behind.
    let canonical = canonical_mesh(mesh)?;
    if let Canonical::Textured(textured) = &canonical {
        textured.material_files()?;
    }
    let frame_path = |k: usize| out.join(format!("frame_{k:04}.obj"));
    // Nor may a frame replace the mesh or the data (a mesh warped into its own folder).
    for k in range.clone() {
        crate::io::check_output(&frame_path(k), None, &inputs)?;
    }
    std::fs::create_dir_all(out).map_err(|e| DomaError::io(out, e))?;
    let to_norm =
        |v: &[f32; 3]| -> [f32; 3] { std::array::from_fn(|c| (v[c] - own.center[c]) / own.scale) };
    let to_data = |y: &mut Vec<[f32; 3]>, k: usize| -> Result<()> {
        for p in y.iter_mut() {
            *p = std::array::from_fn(|c| p[c] * own.scale + own.center[c]);
        }
        match y.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
            // A field that moves a vertex past f32's range in the data's units: say so
            // rather than write `inf` into a mesh.
            Some(v) => Err(DomaError::InvalidData(format!(
                "frame {k}: vertex {v} warps to {:?}, outside f32's range in the data's units",
                y[v]
            ))),
            None => Ok(()),
        }
    };
    let mut paths = Vec::new();
    // One frame at a time, each streamed to its file: memory holds the mesh, one warped
    // frame and its normals, whatever the number of frames.
    match canonical {
        // A user's textured mesh: any OBJ, its UVs and materials kept (`data::textured`).
        Canonical::Textured(textured) => {
            let norm: Vec<[f32; 3]> = textured.positions().iter().map(to_norm).collect();
            textured.copy_materials(out)?;
            crate::warp::warp_frames(&field, &norm, range, total, device, |k, mut y| {
                to_data(&mut y, k)?;
                let path = frame_path(k);
                write_atomic_with(&path, |w| textured.write_obj(w, &y))?;
                paths.push(path);
                Ok(())
            })?;
        }
        plain => {
            let canonical = match plain {
                Canonical::Plain(m) => m,
                _ => own_canonical_mesh(&own, &config.data)?,
            };
            let norm: Vec<[f32; 3]> = canonical.vertices.iter().map(to_norm).collect();
            crate::warp::warp_frames(&field, &norm, range, total, device, |k, mut y| {
                to_data(&mut y, k)?;
                let normals = vertex_normals(&y, &canonical.faces);
                let path = frame_path(k);
                write_atomic_with(&path, |w| {
                    write_obj_to(w, &y, &canonical.faces, Some(&normals))
                })?;
                paths.push(path);
                Ok(())
            })?;
        }
    }
    Ok(paths)
}

/// The mesh to warp, by how it is read.
enum Canonical {
    /// No mesh given: the run's own.
    Own,
    /// A triangle OBJ without UVs or materials, read strictly: its vertex order is kept,
    /// so frame `k`'s vertex `i` is the input's vertex `i`.
    Plain(TriMesh),
    /// Any other OBJ, through `tobj` (`data::textured`).
    Textured(TexturedMesh),
}

/// Reads `mesh`: strictly when it has no `vt` or `mtllib` line and the strict reader takes
/// it; else as a textured mesh. When both readers refuse it, the strict reader's reason is
/// reported.
fn canonical_mesh(mesh: Option<&Path>) -> Result<Canonical> {
    let Some(path) = mesh else {
        return Ok(Canonical::Own);
    };
    let text = crate::io::read_input(path, crate::io::InputKind::Mesh)?;
    let textured = text.split(|&b| b == b'\n').any(|line| {
        let line = line.trim_ascii_start();
        line.starts_with(b"vt ") || line.starts_with(b"vt\t") || line.starts_with(b"mtllib")
    });
    if textured {
        return TexturedMesh::read(path).map(Canonical::Textured);
    }
    match read_obj(path) {
        Ok(m) => Ok(Canonical::Plain(m)),
        Err(strict) => TexturedMesh::read(path)
            .map(Canonical::Textured)
            .map_err(|_| strict),
    }
}

/// The run data's own canonical mesh, in the data's units: the canonical positions (frame 0 for complete data) with the sequence's faces.
fn own_canonical_mesh(own: &Sequence, data: &Path) -> Result<TriMesh> {
    let faces = own.faces.clone().ok_or_else(|| {
        DomaError::InvalidData(format!(
            "{} has no faces: give the canonical mesh with --mesh",
            data.display()
        ))
    })?;
    let vertices = as_points(own.trajectories.canonical())
        .iter()
        .map(|p| std::array::from_fn(|c| p[c] * own.scale + own.center[c]))
        .collect();
    Ok(TriMesh { vertices, faces })
}

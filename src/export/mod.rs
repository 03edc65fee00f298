//! `doma export`: the fitted motion as one binary glTF 2.0 file (`.glb`), built with
//! `gltf-json`.
//!
//! The motion is stored as **morph targets**, one per frame, played by one animation on
//! the mesh's morph weights with linear interpolation between one-hot weight vectors (so
//! the shape between two keyframes is the linear blend of the two warped frames). glTF has
//! no other way to move vertices independently: skinning needs a skeleton, and a DOMA field
//! has none (every point has its own `(A, u)`). Morph targets play in Blender (imported as
//! shape keys with their animation) and in three.js-based viewers (`AnimationMixer`;
//! three.js binds morph targets as textures under WebGL 2, so their number is not capped).
//! Each target carries position and normal displacements; the base shape is the first
//! exported frame.
//!
//! The canonical shape is a user's mesh (`--mesh`, read with its UVs and materials, a
//! diffuse PNG/JPEG texture embedded), else the run's own first frame with its faces, else
//! the run's points (a `POINTS` primitive). `color_by_error` adds vertex colours: each
//! vertex's mean end-point error over the frames where it is observed, on a blue-to-red
//! ramp (the vertices must then be the run's points, in order). The run's own points of
//! tracks with gaps are coloured per frame: grey (or their error colour) where observed,
//! magenta (RGB 0.85, 0.3, 0.85, the viewer's colour too) where the field fills them,
//! through `COLOR_0` morph targets. `up` turns the data's up axis onto glTF's +y.

use std::path::Path;

use burn::tensor::Device;

use crate::data::mesh::{as_points, read_obj};
use crate::data::sequence::Sequence;
use crate::data::textured::{Part, TexturedMesh};
use crate::run::{OpenRun, RunDir};
use crate::{DomaError, Result};

mod glb;

use glb::build_glb;

/// What to export.
#[derive(Clone, Debug, Default)]
pub struct ExportOptions {
    /// The frames (default: all of the run's).
    pub frames: Option<std::ops::Range<usize>>,
    /// Colour the vertices by their mean EPE over the frames.
    pub color_by_error: bool,
    /// Keyframes per second of the animation (default 24).
    pub fps: Option<f32>,
    /// The data's up axis, turned onto glTF's +y (default: the data's y stays up).
    pub up: Option<crate::view::Axis>,
}

/// What was written.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportSummary {
    /// Vertices of the exported shape.
    pub vertices: usize,
    /// Triangles (0 for a point cloud).
    pub triangles: usize,
    /// Frames, one morph target each.
    pub frames: usize,
    /// Bytes of the `.glb`.
    pub bytes: usize,
}

/// Exports the fitted motion of the run in `run` to `out` (a `.glb`, written atomically).
pub fn export_gltf(
    run: &RunDir,
    mesh: Option<&Path>,
    out: &Path,
    options: &ExportOptions,
    device: &Device,
) -> Result<ExportSummary> {
    crate::io::check_writable(out)?;
    let OpenRun {
        config,
        field,
        data: own,
        frames: range,
    } = run.open(options.frames.clone(), device)?;
    let inputs: Vec<&Path> = std::iter::once(config.data.as_path()).chain(mesh).collect();
    crate::io::check_output(out, Some(&run.dir), &inputs)?;
    let total = own.trajectories.frames();
    let to_data =
        |p: [f32; 3]| -> [f32; 3] { std::array::from_fn(|c| p[c] * own.scale + own.center[c]) };
    let to_norm =
        |p: [f32; 3]| -> [f32; 3] { std::array::from_fn(|c| (p[c] - own.center[c]) / own.scale) };
    let (shape, are_points) = export_shape(mesh, options, &own, &config.data, to_data)?;
    let canonical: Vec<[f32; 3]> = shape.positions().into_iter().map(to_norm).collect();
    let mut frames: Vec<Vec<[f32; 3]>> = Vec::with_capacity(range.len());
    let mut error_sum = vec![0f64; canonical.len()];
    let mut error_count = vec![0usize; canonical.len()];
    crate::warp::warp_frames(&field, &canonical, range.clone(), total, device, |k, y| {
        if let Some(v) = y.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(DomaError::InvalidData(format!(
                "frame {k}: vertex {v} warps to a non-finite position"
            )));
        }
        if options.color_by_error && are_points {
            let truth = own.trajectories.frame(k);
            for (i, p) in y.iter().enumerate() {
                if own.trajectories.is_observed(k, i) {
                    error_sum[i] += (0..3)
                        .map(|c| (p[c] as f64 - truth[3 * i + c] as f64).abs())
                        .sum::<f64>();
                    error_count[i] += 1;
                }
            }
        }
        frames.push(y.into_iter().map(to_data).collect());
        Ok(())
    })?;
    let colors =
        (options.color_by_error && are_points).then(|| error_colors(&error_sum, &error_count));
    let fps = options.fps.unwrap_or(24.0);
    // The last key time, (T − 1) / fps, must be a finite f32: `--fps 1e-45` is not.
    let last = (frames.len().saturating_sub(1)) as f32 / fps;
    if !(fps.is_finite() && fps > 0.0 && last.is_finite()) {
        return Err(DomaError::InvalidConfig(format!(
            "--fps {fps}: the frames per second must be positive and large enough that \
             every key time is a finite number"
        )));
    }
    if let Some(up) = options.up {
        // A cyclic relabelling of the axes (a rotation) that puts `up` on glTF's +y.
        let perm = [[2, 0, 1], [0, 1, 2], [1, 2, 0]][up.index()];
        for frame in &mut frames {
            for p in frame.iter_mut() {
                *p = perm.map(|c| p[c]);
            }
        }
    }
    // The run's own points of masked data: which are observed in each exported frame.
    let observed: Option<Vec<Vec<bool>>> =
        (mesh.is_none() && own.trajectories.observed().is_some()).then(|| {
            range
                .clone()
                .map(|k| {
                    (0..own.trajectories.points())
                        .map(|i| own.trajectories.is_observed(k, i))
                        .collect()
                })
                .collect()
        });
    let glb = build_glb(&shape, &frames, colors.as_deref(), observed.as_deref(), fps)?;
    crate::io::write_atomic(out, &glb)?;
    Ok(ExportSummary {
        vertices: canonical.len(),
        triangles: shape.parts.iter().map(|p| p.triangles.len()).sum(),
        frames: frames.len(),
        bytes: glb.len(),
    })
}

/// Each vertex's colour on the error ramp: its mean L1 error over the frames where it is
/// observed, relative to the largest.
fn error_colors(error_sum: &[f64], error_count: &[usize]) -> Vec<[f32; 3]> {
    let mean: Vec<f64> = error_sum
        .iter()
        .zip(error_count)
        .map(|(e, &n)| if n > 0 { e / n as f64 } else { 0.0 })
        .collect();
    let max = mean.iter().copied().fold(0.0, f64::max).max(1e-12);
    mean.iter()
        .map(|&e| {
            let [r, g, b] = crate::plot::ramp(e / max);
            [r as f32 / 255.0, g as f32 / 255.0, b as f32 / 255.0]
        })
        .collect()
}

/// The shape to export, in the data's units, and whether its vertices are the run's points:
/// `mesh` (one vertex per point when colouring by error), or the run's own points and faces.
fn export_shape(
    mesh: Option<&Path>,
    options: &ExportOptions,
    own: &Sequence,
    data: &Path,
    to_data: impl Fn([f32; 3]) -> [f32; 3],
) -> Result<(TexturedMesh, bool)> {
    Ok(match mesh {
        Some(path) if options.color_by_error => {
            let strict = read_obj(path)?;
            if strict.vertices.len() != own.trajectories.points() {
                return Err(DomaError::Malformed {
                    path: path.to_path_buf(),
                    reason: format!(
                        "{} vertices, but the run's data has {} points: colouring by error needs one vertex per point, in order",
                        strict.vertices.len(),
                        own.trajectories.points()
                    ),
                });
            }
            (single_part(strict.vertices, strict.faces, path), true)
        }
        Some(path) => (TexturedMesh::read(path)?, false),
        None => {
            let vertices: Vec<[f32; 3]> = as_points(own.trajectories.canonical())
                .into_iter()
                .map(to_data)
                .collect();
            let faces = own.faces.clone().unwrap_or_default();
            (single_part(vertices, faces, data), true)
        }
    })
}

pub(crate) fn single_part(
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    path: &Path,
) -> TexturedMesh {
    TexturedMesh {
        path: path.to_path_buf(),
        parts: vec![Part {
            name: "mesh".into(),
            positions,
            texcoords: None,
            triangles,
            material: None,
        }],
        materials: Vec::new(),
        mtllibs: Vec::new(),
    }
}

//! A tracker's view of an animated mesh, for testing and measuring what doma does with real
//! tracker output when the truth is known: a fixed camera sees the mesh, a vertex facing
//! away from it is hidden, a tracker loses points for spans of frames, and some tracks only
//! start late. The result is written in PointOdyssey's or TAPVid-3D's layout
//! ([`super::layout`]), with the true positions kept under the hidden entries (as
//! PointOdyssey keeps them).

use std::path::Path;

use doma_formats::npy::NpyValues;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::Trajectories;
use super::layout::Layout;
use super::mesh::{as_points, vertex_normals};
use super::npy::write_npz_values;
use crate::{DomaError, Result};

/// How the tracker is simulated.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackerConfig {
    /// The direction from the frame-0 box's centre to the camera (need not be unit).
    pub view: [f32; 3],
    /// The camera's distance in frame-0 box diagonals.
    pub distance: f32,
    /// The fraction of tracks that lose their point for a span of frames.
    pub dropout: f64,
    /// The longest such span, in frames.
    pub dropout_frames: usize,
    /// The fraction of tracks that start late (invalid before a frame in the first half).
    pub late: f64,
    /// Seeds the spans and the late starts.
    pub seed: u64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        TrackerConfig {
            view: [1.0, 0.4, 1.0],
            distance: 2.0,
            dropout: 0.3,
            dropout_frames: 15,
            late: 0.2,
            seed: 0,
        }
    }
}

/// A simulated tracker's output: the true positions, the camera, and which entries the
/// tracker reports.
#[derive(Clone, Debug)]
pub struct TrackerView {
    /// The true positions `[T, N, 3]`, world frame.
    pub truth: Trajectories,
    /// World to camera, `[4, 4]` row-major (the same in every frame).
    pub extrinsics: [f32; 16],
    /// `[T, N]`: the track exists (false before a late start).
    pub valid: Vec<bool>,
    /// `[T, N]`: the point faces the camera and is not in a dropout span.
    pub visible: Vec<bool>,
}

impl TrackerView {
    /// The mask of observed entries: valid and visible.
    pub fn observed(&self) -> Vec<bool> {
        self.valid
            .iter()
            .zip(&self.visible)
            .map(|(&a, &b)| a && b)
            .collect()
    }

    /// `truth` in the camera frame.
    pub fn camera_positions(&self) -> Vec<f32> {
        let e = &self.extrinsics;
        self.truth
            .positions()
            .chunks_exact(3)
            .flat_map(|p| {
                (0..3).map(move |r| {
                    e[4 * r] * p[0] + e[4 * r + 1] * p[1] + e[4 * r + 2] * p[2] + e[4 * r + 3]
                })
            })
            .collect()
    }

    /// Writes the view as a `.npz` in `layout` (PointOdyssey: `trajs_3d` as f16 in the world
    /// frame, `visibs`, `valids`, `extrinsics`, `intrinsics`; TAPVid-3D: `tracks_XYZ` in the
    /// camera frame, `visibility`, `queries_xyt`, `fx_fy_cx_cy`; masked: `tracks` in the
    /// world frame and `observed`), atomically.
    pub fn write(&self, path: &Path, layout: Layout) -> Result<()> {
        let (t, n) = (self.truth.frames(), self.truth.points());
        let (s3, s2) = ([t, n, 3], [t, n]);
        // A pinhole camera of 512 × 512 pixels with a 60° field of view.
        let (f, c) = (443.4f32, 256.0f32);
        let write = |members: &[(&str, &[usize], NpyValues)]| write_npz_values(path, members);
        match layout {
            Layout::PointOdyssey => {
                let extrinsics: Vec<f32> = (0..t).flat_map(|_| self.extrinsics).collect();
                let k = [f, 0.0, c, 0.0, f, c, 0.0, 0.0, 1.0];
                let intrinsics: Vec<f32> = (0..t).flat_map(|_| k).collect();
                write(&[
                    ("trajs_3d", &s3, NpyValues::F16(self.truth.positions())),
                    ("visibs", &s2, NpyValues::Bool(&self.visible)),
                    ("valids", &s2, NpyValues::Bool(&self.valid)),
                    ("extrinsics", &[t, 4, 4], NpyValues::F32(&extrinsics)),
                    ("intrinsics", &[t, 3, 3], NpyValues::F32(&intrinsics)),
                ])
            }
            Layout::TapVid3d => {
                let xyz = self.camera_positions();
                let observed = self.observed();
                // Each track's query: its first observed frame, projected.
                let queries: Vec<f32> = (0..n)
                    .flat_map(|i| {
                        let k = (0..t).find(|&k| observed[k * n + i]).unwrap_or(0);
                        let p = &xyz[3 * (k * n + i)..3 * (k * n + i) + 3];
                        [f * p[0] / p[2] + c, f * p[1] / p[2] + c, k as f32]
                    })
                    .collect();
                write(&[
                    ("tracks_XYZ", &s3, NpyValues::F32(&xyz)),
                    ("visibility", &s2, NpyValues::Bool(&observed)),
                    ("queries_xyt", &[n, 3], NpyValues::F32(&queries)),
                    ("fx_fy_cx_cy", &[4], NpyValues::F32(&[f, f, c, c])),
                ])
            }
            Layout::Masked => write(&[
                ("tracks", &s3, NpyValues::F32(self.truth.positions())),
                ("observed", &s2, NpyValues::Bool(&self.observed())),
            ]),
            Layout::Plain => Err(DomaError::Usage(
                "a simulated tracker writes a tracker's layout, not plain trajectories".into(),
            )),
        }
    }
}

/// What a tracker would report of `truth` (an animated mesh with `faces`): a camera looks
/// at frame 0's box from `config.view`; a vertex whose normal faces away from the camera is
/// not visible; a `dropout` fraction of the tracks lose their point for a span of 3 to
/// `dropout_frames` frames; a `late` fraction start (become valid) at a frame in the first
/// half.
pub fn simulate(
    truth: &Trajectories,
    faces: &[[u32; 3]],
    config: &TrackerConfig,
) -> Result<TrackerView> {
    let (t, n) = (truth.frames(), truth.points());
    let frame0 = as_points(truth.frame(0));
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in &frame0 {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let center: [f32; 3] = std::array::from_fn(|c| 0.5 * (lo[c] + hi[c]));
    let diagonal = (0..3).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f32>().sqrt();
    let norm = config.view.iter().map(|v| v * v).sum::<f32>().sqrt();
    if !(norm > 0.0 && diagonal > 0.0 && config.distance > 0.0) {
        return Err(DomaError::InvalidConfig(
            "the camera needs a view direction, a distance and a mesh with extent".into(),
        ));
    }
    let back: [f32; 3] = std::array::from_fn(|c| config.view[c] / norm);
    let eye: [f32; 3] = std::array::from_fn(|c| center[c] + config.distance * diagonal * back[c]);
    let extrinsics = look_at(eye, center);
    let mut visible = vec![true; t * n];
    for k in 0..t {
        let points = as_points(truth.frame(k));
        let normals = vertex_normals(&points, faces);
        for i in 0..n {
            let to_eye: [f32; 3] = std::array::from_fn(|c| eye[c] - points[i][c]);
            let facing: f32 = (0..3).map(|c| normals[i][c] * to_eye[c]).sum();
            visible[k * n + i] = facing > 0.0;
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mut valid = vec![true; t * n];
    for i in 0..n {
        if t > 3 && rng.random_bool(config.dropout.clamp(0.0, 1.0)) {
            let len = rng.random_range(3..=config.dropout_frames.clamp(3, t));
            let start = rng.random_range(0..=t - len);
            for k in start..start + len {
                visible[k * n + i] = false;
            }
        }
        if t > 2 && rng.random_bool(config.late.clamp(0.0, 1.0)) {
            let start = rng.random_range(1..=t / 2);
            for k in 0..start {
                valid[k * n + i] = false;
            }
        }
    }
    Ok(TrackerView {
        truth: truth.clone(),
        extrinsics,
        valid,
        visible,
    })
}

/// The world-to-camera matrix of a camera at `eye` looking at `target`, OpenCV's axes
/// (x right, y down, z forward), with the world's +y or +z (whichever is less parallel to
/// the view) as up.
fn look_at(eye: [f32; 3], target: [f32; 3]) -> [f32; 16] {
    let sub = |a: [f32; 3], b: [f32; 3]| -> [f32; 3] { std::array::from_fn(|c| a[c] - b[c]) };
    let cross = |a: [f32; 3], b: [f32; 3]| -> [f32; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let unit = |a: [f32; 3]| -> [f32; 3] {
        let l = a.iter().map(|v| v * v).sum::<f32>().sqrt();
        std::array::from_fn(|c| a[c] / l)
    };
    let z = unit(sub(target, eye));
    let up = if z[1].abs() < z[2].abs() {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    };
    let x = unit(cross(z, up));
    let y = cross(z, x);
    let dot = |a: [f32; 3], b: [f32; 3]| (0..3).map(|c| a[c] * b[c]).sum::<f32>();
    [
        x[0],
        x[1],
        x[2],
        -dot(x, eye), //
        y[0],
        y[1],
        y[2],
        -dot(y, eye), //
        z[0],
        z[1],
        z[2],
        -dot(z, eye), //
        0.0,
        0.0,
        0.0,
        1.0,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_camera_looks_at_the_target_from_its_eye() {
        let e = look_at([0.0, 0.0, 5.0], [0.0, 0.0, 0.0]);
        let apply = |p: [f32; 3]| -> [f32; 3] {
            std::array::from_fn(|r| {
                e[4 * r] * p[0] + e[4 * r + 1] * p[1] + e[4 * r + 2] * p[2] + e[4 * r + 3]
            })
        };
        // The target is straight ahead at depth 5; the eye is the camera's origin.
        assert_eq!(apply([0.0, 0.0, 0.0]), [0.0, 0.0, 5.0]);
        assert_eq!(apply([0.0, 0.0, 5.0]), [0.0, 0.0, 0.0]);
        // World +y is up, which is image −y.
        assert!(apply([0.0, 1.0, 0.0])[1] < 0.0);
    }
}

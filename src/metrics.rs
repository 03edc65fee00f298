//! Evaluation metrics (docs/reference.md §7).

use burn::tensor::Device;

use crate::data::Trajectories;
use crate::data::mesh::as_points;
use crate::field::MotionField;
use crate::numeric::knn::PointTree;
use crate::{DomaError, Result};

/// The factor by which tables report the EPE (the paper's "×10⁻⁴").
pub const EPE_SCALE: f64 = 1e4;

/// The end-point error per frame: for every point and frame `k`,
/// `‖(ŷ_k − x_0) − (y_k − x_0)‖₁ = ‖ŷ_k − y_k‖₁` (summed over x, y, z), averaged over
/// the points. Frame 0 is included, as in the authors' code (docs/reference.md §7). Where
/// `truth` has an observed mask, a frame's average is over its observed points, and a
/// frame with none is NaN.
pub fn epe_per_frame(predicted: &Trajectories, truth: &Trajectories) -> Result<Vec<f64>> {
    if predicted.frames() != truth.frames() || predicted.points() != truth.points() {
        return Err(DomaError::InvalidData(format!(
            "EPE of {}×{} predicted against {}×{} true positions",
            predicted.frames(),
            predicted.points(),
            truth.frames(),
            truth.points()
        )));
    }
    Ok((0..truth.frames())
        .map(|k| frame_epe(predicted.frame(k), truth, k))
        .collect())
}

/// The EPE of one frame's prediction `y` (`[N, 3]`) against `truth`'s frame `k`, over its
/// observed points: the complete-data sum in the same order when all are observed.
fn frame_epe(y: &[f32], truth: &Trajectories, k: usize) -> f64 {
    let target = truth.frame(k);
    match truth.observed_in_frame(k) {
        None => {
            let total: f64 = y
                .iter()
                .zip(target)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum();
            total / truth.points() as f64
        }
        Some(mask) => {
            let (mut total, mut count) = (0f64, 0usize);
            for (i, _) in mask.iter().enumerate().filter(|(_, o)| **o) {
                total += (0..3)
                    .map(|c| (y[3 * i + c] as f64 - target[3 * i + c] as f64).abs())
                    .sum::<f64>();
                count += 1;
            }
            if count == 0 {
                f64::NAN
            } else {
                total / count as f64
            }
        }
    }
}

/// The mean of the per-frame EPEs of the frames that have observations (all of them, for
/// complete data).
pub fn mean_over_frames(per_frame: &[f64]) -> f64 {
    let seen: Vec<f64> = per_frame.iter().copied().filter(|e| !e.is_nan()).collect();
    seen.iter().sum::<f64>() / seen.len() as f64
}

/// The EPE (docs/reference.md §7): [`epe_per_frame`] averaged over all frames (those with
/// observations), raw (multiply by [`EPE_SCALE`] for the paper's tables).
pub fn epe(predicted: &Trajectories, truth: &Trajectories) -> Result<f64> {
    Ok(mean_over_frames(&epe_per_frame(predicted, truth)?))
}

/// Warps the canonical points of `truth` ([`Trajectories::canonical`]) to every frame with `field`, in
/// chunks of points ([`crate::warp::WARP_CHUNK`]); the result holds every frame.
pub fn predict(
    field: &dyn MotionField,
    truth: &Trajectories,
    device: &Device,
) -> Result<Trajectories> {
    let x0 = as_points(truth.canonical());
    let mut positions = Vec::with_capacity(truth.positions().len());
    crate::warp::warp_frames(
        field,
        &x0,
        0..truth.frames(),
        truth.frames(),
        device,
        |_, y| {
            positions.extend_from_slice(y.as_flattened());
            Ok(())
        },
    )?;
    Trajectories::new(truth.frames(), truth.points(), positions)
}

/// [`epe_per_frame`] of `field`'s prediction of `truth`, computed frame by frame and chunk
/// by chunk: beside `truth`, memory holds one frame's prediction, not all of them.
pub fn field_epe_per_frame(
    field: &dyn MotionField,
    truth: &Trajectories,
    device: &Device,
) -> Result<Vec<f64>> {
    let x0 = as_points(truth.canonical());
    let mut per_frame = Vec::with_capacity(truth.frames());
    crate::warp::warp_frames(
        field,
        &x0,
        0..truth.frames(),
        truth.frames(),
        device,
        |k, y| {
            per_frame.push(frame_epe(y.as_flattened(), truth, k));
            Ok(())
        },
    )?;
    Ok(per_frame)
}

/// The EPE of `field` on the held-out trajectories `truth` (in bounded memory,
/// [`field_epe_per_frame`]).
pub fn evaluate_epe(field: &dyn MotionField, truth: &Trajectories, device: &Device) -> Result<f64> {
    Ok(mean_over_frames(&field_epe_per_frame(
        field, truth, device,
    )?))
}

/// One direction of the Chamfer distance: for each of `from` (with normals `from_n`), its
/// nearest point in `to`: (mean squared distance, mean `1 − |cos|` of the normals).
fn chamfer_direction(
    from: &[[f32; 3]],
    from_n: Option<&[[f32; 3]]>,
    to: &[[f32; 3]],
    to_n: Option<&[[f32; 3]]>,
) -> Result<(f64, f64)> {
    use rayon::prelude::*;
    let tree = PointTree::new(to)?;
    let (d, c) = from
        .par_iter()
        .enumerate()
        .map(|(i, q)| {
            let (j, d2) = tree.nearest(q);
            let cos = match (from_n, to_n) {
                (Some(a), Some(b)) => {
                    let (a, b) = (a[i], b[j]);
                    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs() as f64
                }
                _ => 1.0,
            };
            (d2 as f64, 1.0 - cos)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let n = from.len() as f64;
    Ok((d / n, c / n))
}

fn check_clouds(a: &[[f32; 3]], b: &[[f32; 3]]) -> Result<()> {
    if a.is_empty() || b.is_empty() {
        return Err(DomaError::InvalidData(format!(
            "Chamfer distance of an empty cloud ({} and {} points)",
            a.len(),
            b.len()
        )));
    }
    Ok(())
}

/// The Chamfer distance (docs/reference.md §4.5, pytorch3d's default): the mean squared distance
/// from each point of `a` to its nearest in `b`, plus the same from `b` to `a`. Exact,
/// through k-d trees; tables report it ×1e4.
pub fn chamfer(a: &[[f32; 3]], b: &[[f32; 3]]) -> Result<f64> {
    check_clouds(a, b)?;
    Ok(chamfer_direction(a, None, b, None)?.0 + chamfer_direction(b, None, a, None)?.0)
}

/// The Chamfer distance and the normal Chamfer distance (docs/reference.md §4.5): for each point,
/// `1 − |cos|` between its normal and its nearest neighbour's in the other cloud, averaged
/// per direction and summed over both. Returns `(CD, CDN)`.
pub fn chamfer_with_normals(
    a: &[[f32; 3]],
    a_normals: &[[f32; 3]],
    b: &[[f32; 3]],
    b_normals: &[[f32; 3]],
) -> Result<(f64, f64)> {
    check_clouds(a, b)?;
    if a.len() != a_normals.len() || b.len() != b_normals.len() {
        return Err(DomaError::InvalidData(format!(
            "{} points with {} normals, {} points with {} normals",
            a.len(),
            a_normals.len(),
            b.len(),
            b_normals.len()
        )));
    }
    let (d1, c1) = chamfer_direction(a, Some(a_normals), b, Some(b_normals))?;
    let (d2, c2) = chamfer_direction(b, Some(b_normals), a, Some(a_normals))?;
    Ok((d1 + d2, c1 + c2))
}

/// The unbiased standard deviation of `values`.
fn std_unbiased(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

fn distance(a: &[f32], b: &[f32]) -> f64 {
    (0..3)
        .map(|c| (a[c] as f64 - b[c] as f64).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// STD(E) (docs/reference.md §7): each edge's length in every frame of the warped template, its
/// unbiased standard deviation over time, and the maximum over edges. Low means the
/// surface stretches little. Needs at least two frames and one edge.
pub fn std_edges(frames: &Trajectories, edges: &[[u32; 2]]) -> Result<f64> {
    if frames.frames() < 2 || edges.is_empty() {
        return Err(DomaError::InvalidData(format!(
            "STD(E) needs two frames and an edge ({} frames, {} edges)",
            frames.frames(),
            edges.len()
        )));
    }
    if let Some(e) = edges
        .iter()
        .find(|e| e.iter().any(|&i| i as usize >= frames.points()))
    {
        return Err(DomaError::InvalidData(format!(
            "edge {e:?} indexes past the {} vertices",
            frames.points()
        )));
    }
    let mut lengths = vec![0f64; frames.frames()];
    let mut worst = 0f64;
    for &[a, b] in edges {
        for (k, l) in lengths.iter_mut().enumerate() {
            let f = frames.frame(k);
            let (a, b) = (3 * a as usize, 3 * b as usize);
            *l = distance(&f[a..a + 3], &f[b..b + 3]);
        }
        worst = worst.max(std_unbiased(&lengths));
    }
    Ok(worst)
}

/// STD(V) (docs/reference.md §7): each vertex's displacement norm between consecutive frames,
/// its unbiased standard deviation over time, and the mean over vertices. Low means the
/// vertices move smoothly (no jitter). Needs at least three frames.
pub fn std_vertices(frames: &Trajectories) -> Result<f64> {
    let t = frames.frames();
    if t < 3 {
        return Err(DomaError::InvalidData(format!(
            "STD(V) needs three frames, not {t}"
        )));
    }
    let mut steps = vec![0f64; t - 1];
    let mut total = 0f64;
    for v in 0..frames.points() {
        for (k, s) in steps.iter_mut().enumerate() {
            let i = 3 * v;
            *s = distance(&frames.frame(k)[i..i + 3], &frames.frame(k + 1)[i..i + 3]);
        }
        total += std_unbiased(&steps);
    }
    Ok(total / frames.points() as f64)
}

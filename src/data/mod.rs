//! Point trajectories and their splits.

pub mod anime;
pub mod c3d;
pub mod held_out;
pub mod layout;
pub mod mesh;
pub mod npy;
pub mod sequence;
pub mod synthetic;
pub mod textured;
pub mod tracker;
pub mod tracks;
pub mod traj;
pub mod trc;

use burn::tensor::{Device, Tensor, TensorData};

use crate::{DomaError, Result};

/// Parses a frame range `A..B` (B excluded) or `A..=B` (B included).
pub fn parse_frame_range(s: &str) -> std::result::Result<std::ops::Range<usize>, String> {
    let bad = || format!("`{s}` is not a frame range like 0..40 or 0..=39");
    let (a, b, inclusive) = if let Some((a, b)) = s.split_once("..=") {
        (a, b, true)
    } else {
        let (a, b) = s.split_once("..").ok_or_else(bad)?;
        (a, b, false)
    };
    let a: usize = a.trim().parse().map_err(|_| bad())?;
    let b: usize = b.trim().parse().map_err(|_| bad())?;
    let end = if inclusive { b + 1 } else { b };
    if end <= a {
        return Err(format!("the frame range `{s}` is empty"));
    }
    Ok(a..end)
}

/// The normalised time of frame `k` of `frames`: `t_k = −1 + 2k/(T−1)` (docs/reference.md §1),
/// so the canonical frame 0 is `t = −1` and the last frame `t = 1`. A single frame is
/// at `t = −1`.
pub fn normalized_time(k: usize, frames: usize) -> f64 {
    if frames < 2 {
        -1.0
    } else {
        -1.0 + 2.0 * k as f64 / (frames - 1) as f64
    }
}

/// Checked frames from a format parser are trajectories.
impl From<doma_formats::Frames> for Trajectories {
    fn from(f: doma_formats::Frames) -> Self {
        Trajectories {
            frames: f.frames,
            points: f.points,
            positions: f.positions,
            observed: None,
            canonical: None,
            reference: 0,
            weights: None,
        }
    }
}

/// `T` frames of `N` corresponding points, `[T, N, 3]`, frame-major, `f32`.
/// Point `i` is the same material point in every frame.
///
/// Tracks from a tracker are not seen in every frame: an optional observed mask `[T, N]`
/// says which entries are data. An unobserved entry stores a finite stand-in (the track's
/// linear interpolation between its observations, held constant past its ends,
/// [`crate::gaps::Marked::linear`]); the losses and metrics never read it. The field's input
/// `x` of each point, its *canonical* position, is frame 0's position for complete
/// data, and for masked data the position in a reference frame
/// ([`tracks::Tracks::into_trajectories`]). Not one type with [`tracks::Tracks`] (a
/// file's tracks as read, NaN where unobserved, no canonical frame yet) or
/// [`crate::gaps::Marked`] (the borrowed view gap filling reads): what the trainer
/// uploads must be finite everywhere and carry its canonical positions.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectories {
    frames: usize,
    points: usize,
    positions: Vec<f32>,
    /// `[T, N]`, whether each entry was observed; `None`: every entry was.
    observed: Option<Vec<bool>>,
    /// `[N, 3]`, the canonical positions when they are not frame 0's.
    canonical: Option<Vec<f32>>,
    /// The frame the canonical positions belong to.
    reference: usize,
    /// `[T, N]`, each observation's confidence weight; `None`: all weigh the same.
    weights: Option<Vec<f32>>,
}

impl Trajectories {
    /// Checks and wraps `positions` (`[T, N, 3]`, frame-major). Refuses an empty
    /// sequence, a length that is not `T·N·3`, and non-finite coordinates
    /// ([`doma_formats::check_positions`]).
    pub fn new(frames: usize, points: usize, positions: Vec<f32>) -> Result<Self> {
        doma_formats::check_positions(frames, points, &positions)
            .map_err(DomaError::InvalidData)?;
        Ok(Trajectories {
            frames,
            points,
            positions,
            observed: None,
            canonical: None,
            reference: 0,
            weights: None,
        })
    }

    /// These trajectories with a confidence weight per entry (`[T, N]`, finite and
    /// non-negative), which scales each observation's share of the trajectory loss.
    pub fn with_weights(mut self, weights: Vec<f32>) -> Result<Self> {
        if weights.len() != self.frames * self.points {
            return Err(DomaError::InvalidData(format!(
                "{} weights for {} frames of {} points",
                weights.len(),
                self.frames,
                self.points
            )));
        }
        if let Some(e) = weights.iter().position(|w| !(w.is_finite() && *w >= 0.0)) {
            return Err(DomaError::InvalidData(format!(
                "the weight of point {} in frame {} is {}: weights are finite and non-negative",
                e % self.points,
                e / self.points,
                weights[e]
            )));
        }
        self.weights = Some(weights);
        Ok(self)
    }

    /// Frame `k`'s confidence weights `[N]`, if the data has any.
    pub fn weights_in_frame(&self, k: usize) -> Option<&[f32]> {
        self.weights
            .as_deref()
            .map(|w| &w[k * self.points..(k + 1) * self.points])
    }

    /// These trajectories with the observed mask `observed` (`[T, N]`, frame-major) and
    /// canonical positions `canonical` (`[N, 3]`) in frame `reference`. A mask that is all
    /// true is stored as none, so that complete data runs the complete-data maths.
    pub fn with_observations(
        mut self,
        observed: Vec<bool>,
        reference: usize,
        canonical: Vec<f32>,
    ) -> Result<Self> {
        if observed.len() != self.frames * self.points
            || canonical.len() != self.points * 3
            || reference >= self.frames
        {
            return Err(DomaError::InvalidData(format!(
                "a mask of {} entries, {} canonical coordinates and reference frame {reference} \
                 do not fit {} frames of {} points",
                observed.len(),
                canonical.len(),
                self.frames,
                self.points
            )));
        }
        if let Some(i) = canonical.iter().position(|v| !v.is_finite()) {
            return Err(DomaError::InvalidData(format!(
                "the canonical position of point {} is not finite",
                i / 3
            )));
        }
        self.observed = (!observed.iter().all(|&o| o)).then_some(observed);
        self.canonical = (reference != 0 || self.observed.is_some()).then_some(canonical);
        self.reference = reference;
        Ok(self)
    }

    /// These trajectories with other canonical positions (`[N, 3]`, finite): those a fit
    /// learned for the tracks unseen in the reference frame.
    pub fn with_canonical(mut self, canonical: Vec<f32>) -> Result<Self> {
        if canonical.len() != self.points * 3 || canonical.iter().any(|v| !v.is_finite()) {
            return Err(DomaError::InvalidData(format!(
                "{} canonical coordinates (finite?) for {} points",
                canonical.len(),
                self.points
            )));
        }
        self.canonical = Some(canonical);
        Ok(self)
    }

    /// These trajectories with every coordinate, of the positions and of the canonical
    /// positions, mapped by `f(value, axis)` (a change of units or frame); the mask, the
    /// reference frame and the weights are kept. Refuses a result that is not finite.
    pub fn map_coordinates(&self, f: impl Fn(f32, usize) -> f32) -> Result<Self> {
        let map =
            |v: &[f32]| -> Vec<f32> { v.iter().enumerate().map(|(i, &x)| f(x, i % 3)).collect() };
        let mut out = Trajectories::new(self.frames, self.points, map(&self.positions))?;
        out.observed = self.observed.clone();
        out.reference = self.reference;
        out.weights = self.weights.clone();
        if let Some(c) = &self.canonical {
            out = out.with_canonical(map(c))?;
        }
        Ok(out)
    }

    /// The observed mask `[T, N]`; `None` when every entry is observed.
    pub fn observed(&self) -> Option<&[bool]> {
        self.observed.as_deref()
    }

    /// Frame `k`'s observed mask `[N]`; `None` when every entry of the data is observed.
    pub fn observed_in_frame(&self, k: usize) -> Option<&[bool]> {
        self.observed
            .as_deref()
            .map(|m| &m[k * self.points..(k + 1) * self.points])
    }

    /// Whether point `i` is observed in frame `k`.
    pub fn is_observed(&self, k: usize, i: usize) -> bool {
        self.observed_in_frame(k).is_none_or(|m| m[i])
    }

    /// The number of observed entries.
    pub fn observed_count(&self) -> usize {
        match &self.observed {
            None => self.frames * self.points,
            Some(m) => m.iter().filter(|&&o| o).count(),
        }
    }

    /// The canonical positions `[N, 3]`: every point's input `x` to the field (frame 0's
    /// positions for complete data).
    pub fn canonical(&self) -> &[f32] {
        self.canonical.as_deref().unwrap_or_else(|| self.frame(0))
    }

    /// The frame the canonical positions belong to (0 for complete data).
    pub fn reference(&self) -> usize {
        self.reference
    }

    /// The canonical positions as a `[N, 3]` tensor on `device`.
    pub fn canonical_tensor(&self, device: &Device) -> Tensor<2> {
        Tensor::from_data(
            TensorData::new(self.canonical().to_vec(), [self.points, 3]),
            device,
        )
    }

    /// The positions as the format crate's checked [`doma_formats::Frames`].
    pub fn to_frames(&self) -> doma_formats::Frames {
        doma_formats::Frames {
            frames: self.frames,
            points: self.points,
            positions: self.positions.clone(),
        }
    }

    /// The number of frames `T`.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The number of points `N`.
    pub fn points(&self) -> usize {
        self.points
    }

    /// All positions, `[T, N, 3]` frame-major.
    pub fn positions(&self) -> &[f32] {
        &self.positions
    }

    /// The positions `[T, N, 3]`, moved out.
    pub fn into_positions(self) -> Vec<f32> {
        self.positions
    }

    /// Frame `k`'s positions, `[N, 3]` row-major.
    pub fn frame(&self, k: usize) -> &[f32] {
        let len = self.points * 3;
        &self.positions[k * len..(k + 1) * len]
    }

    /// The normalised time of frame `k` ([`normalized_time`]).
    pub fn time(&self, k: usize) -> f64 {
        normalized_time(k, self.frames)
    }

    /// Frame `k` as a `[N, 3]` tensor on `device`.
    pub fn frame_tensor(&self, k: usize, device: &Device) -> Tensor<2> {
        Tensor::from_data(
            TensorData::new(self.frame(k).to_vec(), [self.points, 3]),
            device,
        )
    }

    /// The trajectories of the points at `indices` (in that order).
    pub fn select_points(&self, indices: &[usize]) -> Result<Self> {
        if let Some(&bad) = indices.iter().find(|&&i| i >= self.points) {
            return Err(DomaError::InvalidData(format!(
                "point index {bad} out of range for {} points",
                self.points
            )));
        }
        let mut positions = Vec::with_capacity(self.frames * indices.len() * 3);
        for k in 0..self.frames {
            let frame = self.frame(k);
            for &i in indices {
                positions.extend_from_slice(&frame[3 * i..3 * i + 3]);
            }
        }
        let mut out = Trajectories::new(self.frames, indices.len(), positions)?;
        if let Some(w) = &self.weights {
            out.weights = Some(
                (0..self.frames)
                    .flat_map(|k| indices.iter().map(move |&i| w[k * self.points + i]))
                    .collect(),
            );
        }
        if self.observed.is_none() && self.canonical.is_none() {
            return Ok(out);
        }
        let observed = (0..self.frames)
            .flat_map(|k| indices.iter().map(move |&i| self.is_observed(k, i)))
            .collect();
        let canonical = self.canonical();
        let canonical = indices
            .iter()
            .flat_map(|&i| canonical[3 * i..3 * i + 3].iter().copied())
            .collect();
        out.with_observations(observed, self.reference, canonical)
    }

    /// The frames `range` (a contiguous clip), every `stride`-th, as a new sequence whose
    /// first selected frame is canonical. Refuses an empty selection, frames past the end,
    /// and masked data (a clip of tracks is taken before their canonical positions are
    /// found, [`tracks::Tracks::select_frames`]).
    pub fn select_frames(&self, range: std::ops::Range<usize>, stride: usize) -> Result<Self> {
        if self.canonical.is_some() || self.weights.is_some() {
            return Err(DomaError::InvalidData(
                "a clip of masked or weighted tracks is taken before their canonical positions are found"
                    .into(),
            ));
        }
        if stride == 0 || range.start >= range.end || range.end > self.frames {
            return Err(DomaError::InvalidData(format!(
                "frames {}..{} (stride {stride}) do not select a clip of the {} frames",
                range.start, range.end, self.frames
            )));
        }
        let mut positions = Vec::new();
        let mut count = 0;
        for k in range.step_by(stride) {
            positions.extend_from_slice(self.frame(k));
            count += 1;
        }
        Trajectories::new(count, self.points, positions)
    }

    /// The sequence moved and scaled so that the canonical positions' bounding box (frame
    /// 0's, for complete data) is centred at the origin with its longest side spanning `[−1, 1]` (SIREN's `ω₀ = 30` assumes inputs of
    /// about that range). Returns the new sequence, the centre and the scale `s`
    /// (`x' = (x − c) / s`). A point whose normalised coordinate is not finite (a later
    /// frame ~10³⁸ box sizes away) is refused rather than fitted as zeros or infinities.
    pub fn normalized(mut self) -> Result<(Self, [f32; 3], f32)> {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in self.canonical().chunks_exact(3) {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        // Halved before they are added or subtracted, so that coordinates near f32's limit
        // (±3·10³⁸) do not overflow; halving is exact, so ordinary data is unchanged.
        let center: [f32; 3] = std::array::from_fn(|c| 0.5 * lo[c] + 0.5 * hi[c]);
        let half = (0..3)
            .map(|c| 0.5 * hi[c] - 0.5 * lo[c])
            .fold(0f32, f32::max);
        let scale = if half > 0.0 { half } else { 1.0 };
        // In place: a long recording is not held twice.
        for (i, v) in self.positions.iter_mut().enumerate() {
            let moved = (*v - center[i % 3]) / scale;
            if !moved.is_finite() {
                let (f, p) = (i / (3 * self.points), (i / 3) % self.points);
                return Err(DomaError::InvalidData(format!(
                    "point {p} of frame {f} is {v} frame-0 box sizes away: the coordinates span \
                     more than f32 can normalise"
                )));
            }
            *v = moved;
        }
        if let Some(canonical) = &mut self.canonical {
            for (i, v) in canonical.iter_mut().enumerate() {
                *v = (*v - center[i % 3]) / scale;
            }
        }
        Ok((self, center, scale))
    }

    /// Splits the points into the first `n_train` and the rest (the authors' split of
    /// i.i.d. synthetic points, docs/reference.md §6.1).
    pub fn split_first(&self, n_train: usize) -> Result<(Self, Self)> {
        if n_train == 0 || n_train >= self.points {
            return Err(DomaError::InvalidData(format!(
                "cannot split {} points into {n_train} training points and a non-empty rest",
                self.points
            )));
        }
        let train: Vec<usize> = (0..n_train).collect();
        let test: Vec<usize> = (n_train..self.points).collect();
        Ok((self.select_points(&train)?, self.select_points(&test)?))
    }
}

//! The classic gap fillers of the motion-capture literature, each a method of [`Marked`]:
//! each track's linear and natural-cubic-spline interpolation, the neighbours' motion (the
//! simplest form of the "pattern" or "rigid-body" fill of capture software); the low-rank
//! reconstruction is `pca.rs`. Each returns a copy of the positions (or values at given
//! entries) with the gaps filled from the observed entries alone.

use super::marked::Marked;
use super::spans::gaps;
use crate::numeric::linalg::{natural_second_derivatives, spline_at};

impl Marked<'_> {
    /// Each track's linear interpolation in frame index between the observations on
    /// either side of a gap, held at the first or last observation past the ends. Only
    /// observed entries are read; a track never observed is left as it is.
    pub fn linear(&self) -> Vec<f32> {
        let mut out = self.positions.to_vec();
        fill_linear(&mut out, self.observed, self.frames, self.points);
        out
    }

    /// [`Marked::linear`] at frame `k` of track `i`, between its observations at `before`
    /// and `after` (`None` past an end; neither: the entry as it is).
    pub(super) fn linear_at(
        &self,
        k: usize,
        i: usize,
        before: Option<usize>,
        after: Option<usize>,
    ) -> [f32; 3] {
        linear_between(self.positions, self.points, k, i, before, after)
    }

    /// Each track's natural cubic spline through its observed frames (per coordinate, in
    /// frame index), held at the first or last observation past the ends; linear for a
    /// track with fewer than 4 observations.
    pub fn spline(&self) -> Vec<f32> {
        let mut out = self.linear();
        let (t, n) = (self.frames, self.points);
        for i in 0..n {
            let knots: Vec<usize> = (0..t).filter(|&k| self.seen(k, i)).collect();
            if knots.len() < 4 || knots.len() == t {
                continue;
            }
            let x: Vec<f64> = knots.iter().map(|&k| k as f64).collect();
            for c in 0..3 {
                let y: Vec<f64> = knots.iter().map(|&k| self.at(k, i)[c] as f64).collect();
                let m = natural_second_derivatives(&x, &y);
                let mut j = 0;
                for k in knots[0] + 1..knots[knots.len() - 1] {
                    if self.seen(k, i) {
                        continue;
                    }
                    while x[j + 1] < k as f64 {
                        j += 1;
                    }
                    out[3 * (k * n + i) + c] = spline_at(&x, &y, &m, j, k as f64) as f32;
                }
            }
        }
        out
    }

    /// The neighbours' motion at each entry `(k, i)`: from the nearest frame `s` where track
    /// `i` is observed (the earlier of two as near), among the other tracks observed at both
    /// `s` and `k`, the [`MOTION_NEIGHBOURS`] nearest to `i` at `s`; `x_i(s)` moved by their mean
    /// motion `x_j(k) − x_j(s)`, or held at `x_i(s)` when no track is observed at both.
    /// An entry of a track never observed stays NaN.
    pub fn neighbours(&self, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        let n = self.points;
        let mut near: Vec<(f32, usize)> = Vec::with_capacity(n);
        entries
            .iter()
            .map(|&(k, i)| {
                let Some(s) = (0..self.frames)
                    .filter(|&s| self.seen(s, i))
                    .min_by_key(|&s| (s.abs_diff(k), s))
                else {
                    return [f32::NAN; 3];
                };
                let xi = self.at(s, i);
                near.clear();
                near.extend(
                    (0..n)
                        .filter(|&j| j != i && self.seen(s, j) && self.seen(k, j))
                        .map(|j| {
                            let xj = self.at(s, j);
                            let d: f32 = (0..3).map(|c| (xj[c] - xi[c]).powi(2)).sum();
                            (d, j)
                        }),
                );
                let m = MOTION_NEIGHBOURS.min(near.len());
                if m == 0 {
                    return xi;
                }
                near.select_nth_unstable_by(m - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                std::array::from_fn(|c| {
                    let motion: f64 = near[..m]
                        .iter()
                        .map(|&(_, j)| (self.at(k, j)[c] - self.at(s, j)[c]) as f64)
                        .sum::<f64>()
                        / m as f64;
                    (xi[c] as f64 + motion) as f32
                })
            })
            .collect()
    }
}

/// [`Marked::linear`] written into `positions` (`[T, N, 3]`, its mask `observed`) in
/// place: only observed entries are read, and only unobserved ones written, so that the
/// tracks need no second copy.
pub fn fill_linear(positions: &mut [f32], observed: &[bool], frames: usize, points: usize) {
    let gaps: Vec<_> = gaps(&Marked::new(frames, points, positions, observed)).collect();
    for gap in gaps {
        for k in gap.frames.clone() {
            let v = linear_between(positions, points, k, gap.track, gap.before, gap.after);
            let e = 3 * (k * points + gap.track);
            positions[e..e + 3].copy_from_slice(&v);
        }
    }
}

/// Frame `k` of track `i` of `positions` (`[T, N, 3]`), linear between its observations at
/// `before` and `after` (`None` past an end; neither: the entry as it is).
fn linear_between(
    positions: &[f32],
    points: usize,
    k: usize,
    i: usize,
    before: Option<usize>,
    after: Option<usize>,
) -> [f32; 3] {
    let at = |j: usize| -> [f32; 3] {
        let e = 3 * (j * points + i);
        [positions[e], positions[e + 1], positions[e + 2]]
    };
    match (before, after) {
        (Some(a), Some(b)) => {
            let w = (k - a) as f32 / (b - a) as f32;
            let (p, q) = (at(a), at(b));
            std::array::from_fn(|c| p[c] + w * (q[c] - p[c]))
        }
        (Some(a), None) => at(a),
        (None, Some(b)) => at(b),
        (None, None) => at(k),
    }
}

/// The neighbours averaged by [`Marked::neighbours`].
pub const MOTION_NEIGHBOURS: usize = 4;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_linear_between_observations_and_constant_past_the_ends() {
        let positions: Vec<f32> = (0..5)
            .flat_map(|k| [k as f32, 2.0 * k as f32, 0.0])
            .collect();
        // Seen in frames 1 and 3 only: frame 2 is their midpoint, 0 and 4 are held.
        let observed = [false, true, false, true, false];
        let mut poisoned = positions.clone();
        for k in [0, 2, 4] {
            poisoned[3 * k] = f32::NAN;
        }
        let out = Marked::new(5, 1, &poisoned, &observed).linear();
        assert_eq!(&out[6..9], &[2.0, 4.0, 0.0]);
        assert_eq!(&out[0..3], &[1.0, 2.0, 0.0]);
        assert_eq!(&out[12..15], &[3.0, 6.0, 0.0]);
    }

    /// One track per closure, `T` frames.
    fn tracks(t: usize, f: &[&dyn Fn(f64) -> [f64; 3]]) -> Vec<f32> {
        (0..t)
            .flat_map(|k| f.iter().flat_map(move |g| g(k as f64).map(|v| v as f32)))
            .collect()
    }

    #[test]
    fn the_spline_reproduces_a_cubic_inside_and_holds_past_the_ends() {
        // A natural spline is exact for a line, and reproduces a cubic closely inside.
        let line = |k: f64| [2.0 * k + 1.0, -k, 0.5];
        let positions = tracks(12, &[&line]);
        let observed: Vec<bool> = (0..12).map(|k| ![0, 4, 5, 6, 11].contains(&k)).collect();
        let filled = Marked::new(12, 1, &positions, &observed).spline();
        for k in 1..11 {
            for c in 0..3 {
                assert!((filled[3 * k + c] - positions[3 * k + c]).abs() < 1e-4);
            }
        }
        // Past the ends: held at the first and last observation.
        assert_eq!(&filled[0..3], &positions[3..6]);
        assert_eq!(&filled[33..36], &positions[30..33]);
    }

    #[test]
    fn the_neighbours_carry_a_hidden_marker_with_their_rigid_motion() {
        // A rigid translation of 5 markers; marker 0 hidden at frames 2..5.
        let t = 7;
        let offsets = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [9.0, 9.0, 9.0],
        ];
        let motion = |k: f64| [k * k * 0.1, (k * 0.7).sin(), 0.3 * k];
        let positions: Vec<f32> = (0..t)
            .flat_map(|k| {
                offsets.iter().flat_map(move |o| {
                    let m = motion(k as f64);
                    [0, 1, 2].map(|c| (o[c] + m[c]) as f32)
                })
            })
            .collect();
        let mut observed = vec![true; t * 5];
        for k in 2..5 {
            observed[k * 5] = false;
        }
        let marked = Marked::new(t, 5, &positions, &observed);
        let entries: Vec<(usize, usize)> = (2..5).map(|k| (k, 0)).collect();
        for (p, &(k, _)) in marked.neighbours(&entries).iter().zip(&entries) {
            for c in 0..3 {
                assert!((p[c] - positions[3 * k * 5 + c]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn the_neighbours_use_the_nearest_frame_and_the_nearest_tracks_there() {
        // Marker 0 seen at frame 0 only; marker 1 near it moves +1 per frame, marker 2 far
        // moves −5, marker 3 is not seen at frame 2.
        let positions: Vec<f32> = vec![
            0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 50.0, 0.0, 0.0, 0.2, 0.0, 0.0, // frame 0
            9.0, 9.0, 9.0, 1.1, 0.0, 0.0, 45.0, 0.0, 0.0, 9.0, 9.0, 9.0, // frame 1
            9.0, 9.0, 9.0, 2.1, 0.0, 0.0, 40.0, 0.0, 0.0, 9.0, 9.0, 9.0, // frame 2
        ];
        let observed = [
            true, true, true, true, //
            false, true, true, false, //
            false, true, true, false,
        ];
        let marked = Marked::new(3, 4, &positions, &observed);
        // Among 1 and 2 (3 is unseen at 2), the mean of both: (2 + (−10)) / 2 = −4.
        let p = marked.neighbours(&[(2, 0)])[0];
        assert!(
            (p[0] + 4.0).abs() < 1e-5 && p[1] == 0.0 && p[2] == 0.0,
            "{p:?}"
        );
    }
}

//! The classic gap fillers of the motion-capture literature, each a method of [`Marked`]:
//! each track's linear and natural-cubic-spline interpolation, the neighbours' motion (the
//! simplest form of the "pattern" or "rigid-body" fill of capture software), and a
//! low-rank (PCA) reconstruction of the marker trajectories (Gløersen & Federolf 2016; Tits
//! et al. 2018). Each returns a copy of the positions (or values at given entries) with
//! the gaps filled from the observed entries alone.

use super::marked::Marked;
use super::spans::gaps;
use crate::numeric::eigen::Eigensystem;
use crate::numeric::linalg::{column_gram, natural_second_derivatives, spline_at};

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

    /// A low-rank reconstruction: the `[T, 3N]` matrix of the tracks (those observed
    /// somewhere), its unobserved entries started at [`Marked::linear`], then replaced by
    /// the projection of the centred matrix onto its principal components that hold
    /// [`ITERATIVE_PCA_ENERGY`] of its variance, until they change by less than 10⁻⁶ of the
    /// data's spread (at most [`ITERATIVE_PCA_ITERATIONS`] rounds): the iterative PCA fill of
    /// the gap-filling literature.
    pub fn iterative_pca(&self) -> Vec<f32> {
        let (t, n) = (self.frames, self.points);
        let mut out = self.linear();
        let tracks = self.seen_tracks();
        let d = 3 * tracks.len();
        if t < 2 || d == 0 {
            return out;
        }
        // The matrix, row k = frame k, columns 3·r + c of track tracks[r].
        let mut x = vec![0f64; t * d];
        let mut missing = Vec::new();
        for k in 0..t {
            for (r, &i) in tracks.iter().enumerate() {
                for c in 0..3 {
                    x[k * d + 3 * r + c] = out[3 * (k * n + i) + c] as f64;
                    if !self.seen(k, i) {
                        missing.push(k * d + 3 * r + c);
                    }
                }
            }
        }
        if missing.is_empty() {
            return out;
        }
        let spread = x.iter().fold(0f64, |m, v| m.max(v.abs())).max(1e-30);
        for _ in 0..ITERATIVE_PCA_ITERATIONS {
            let r = pca_projection(&x, t, d, ITERATIVE_PCA_ENERGY, &missing);
            let mut change = 0f64;
            for (&e, &v) in missing.iter().zip(&r) {
                change = change.max((v - x[e]).abs());
                x[e] = v;
            }
            if change < 1e-6 * spread {
                break;
            }
        }
        for k in 0..t {
            for (r, &i) in tracks.iter().enumerate() {
                for c in 0..3 {
                    out[3 * (k * n + i) + c] = x[k * d + 3 * r + c] as f32;
                }
            }
        }
        out
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

/// The share of the variance kept by [`Marked::iterative_pca`].
pub const ITERATIVE_PCA_ENERGY: f64 = 0.99;

/// The most rounds of [`Marked::iterative_pca`].
pub const ITERATIVE_PCA_ITERATIONS: usize = 100;

/// `x` (`[t, d]`, row-major) projected onto its column means plus the principal components
/// that hold `energy` of its variance, at the entries `at` (row-major indices, increasing).
/// A tall matrix is projected one row at a time, where `at` asks, and never copied.
fn pca_projection(x: &[f64], t: usize, d: usize, energy: f64, at: &[usize]) -> Vec<f64> {
    let mut mean = vec![0f64; d];
    for row in x.chunks(d) {
        for (m, v) in mean.iter_mut().zip(row) {
            *m += v / t as f64;
        }
    }
    let centred = |row: &[f64]| -> Vec<f64> { row.iter().zip(&mean).map(|(v, m)| v - m).collect() };
    // The components from the smaller Gram matrix: frames × frames or columns × columns.
    if t <= d {
        return projection_by_frames(
            &x.chunks(d).flat_map(centred).collect::<Vec<_>>(),
            t,
            d,
            energy,
            &mean,
            at,
        );
    }
    let g = column_gram(x.chunks(d).map(centred), d);
    let kept = principal(g, d, energy);
    // The kept components side by side, `[d, K]`: a row's coordinates on all of them are
    // summed at once, each over the columns in order.
    let width = kept.len();
    let kept = &kept;
    let side: Vec<f64> = (0..d)
        .flat_map(|a| kept.iter().map(move |v| v[a]))
        .collect();
    // C v vᵀ at the entries asked, row by row: each row's coordinates p = C[k] · v once.
    let mut out = Vec::with_capacity(at.len());
    let (mut row, mut p) = (vec![0f64; d], vec![0f64; width]);
    let mut i = 0;
    while i < at.len() {
        let k = at[i] / d;
        for ((c, v), m) in row.iter_mut().zip(&x[k * d..(k + 1) * d]).zip(&mean) {
            *c = v - m;
        }
        // From −0, as `Iterator::sum` adds.
        p.fill(-0.0);
        for (&r, loadings) in row.iter().zip(side.chunks_exact(width.max(1))) {
            for (pu, &v) in p.iter_mut().zip(loadings) {
                *pu += r * v;
            }
        }
        while i < at.len() && at[i] / d == k {
            let j = at[i] % d;
            let mut o = 0f64;
            for (pv, v) in p.iter().zip(&side[j * width..(j + 1) * width]) {
                o += pv * v;
            }
            out.push(o + mean[j]);
            i += 1;
        }
    }
    out
}

/// The eigenvectors of the Gram matrix `g` (`[n, n]`) that hold `energy` of its trace,
/// largest first: only those are found ([`Eigensystem`]), a few of hundreds on a marker
/// set, where every round of the iterative PCA would otherwise pay for all of them.
fn principal(g: Vec<f64>, n: usize, energy: f64) -> Vec<Vec<f64>> {
    let system = Eigensystem::new(g, n);
    let values = &system.values;
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    let total: f64 = values.iter().map(|v| v.max(0.0)).sum();
    let mut kept = Vec::new();
    let mut held = 0f64;
    for &o in &order {
        if total <= 0.0 || held >= energy * total {
            break;
        }
        held += values[o].max(0.0);
        kept.push(o);
    }
    system.vectors(&kept)
}

/// [`pca_projection`] of a wide matrix, centred (`c`, `[t, d]` with `t <= d`), from its
/// frames' Gram matrix: u uᵀ C, the row combination of the frames.
fn projection_by_frames(
    c: &[f64],
    t: usize,
    d: usize,
    energy: f64,
    mean: &[f64],
    at: &[usize],
) -> Vec<f64> {
    let mut g = vec![0f64; t * t];
    for a in 0..t {
        for b in a..t {
            let v: f64 = (0..d).map(|j| c[a * d + j] * c[b * d + j]).sum();
            g[a * t + b] = v;
            g[b * t + a] = v;
        }
    }
    let mut out = vec![0f64; t * d];
    for v in principal(g, t, energy) {
        let mut row = vec![0f64; d];
        for (k, &vk) in v.iter().enumerate() {
            for j in 0..d {
                row[j] += vk * c[k * d + j];
            }
        }
        for (k, &vk) in v.iter().enumerate() {
            for j in 0..d {
                out[k * d + j] += vk * row[j];
            }
        }
    }
    at.iter().map(|&e| out[e] + mean[e % d]).collect()
}
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

    /// A tall matrix's projection, row by row from its columns' Gram matrix, is the one
    /// from its frames' Gram matrix (the other derivation, which a wide matrix takes), and
    /// the entries asked alone are those of every entry asked.
    #[test]
    fn a_tall_matrix_projects_as_from_its_frames_gram_at_the_entries_asked() {
        let (t, d) = (14, 5);
        let x: Vec<f64> = (0..t * d)
            .map(|i| ((i * 7919 % 101) as f64 / 101.0 - 0.5) + 0.1 * (i % d) as f64)
            .collect();
        let every: Vec<usize> = (0..t * d).collect();
        let tall = pca_projection(&x, t, d, 0.9, &every);
        let mut mean = vec![0f64; d];
        for row in x.chunks(d) {
            for (m, v) in mean.iter_mut().zip(row) {
                *m += v / t as f64;
            }
        }
        let centred: Vec<f64> = (0..t * d).map(|e| x[e] - mean[e % d]).collect();
        let by_frames = projection_by_frames(&centred, t, d, 0.9, &mean, &every);
        for (a, b) in tall.iter().zip(&by_frames) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
        // Not the data itself: 0.9 of the variance leaves some of it out.
        assert!(tall.iter().zip(&x).any(|(p, v)| (p - v).abs() > 1e-3));
        let some = [3, 4, 17, 40, 69];
        let picked = pca_projection(&x, t, d, 0.9, &some);
        assert_eq!(picked, some.map(|e| tall[e]));
    }

    #[test]
    fn the_iterative_pca_fill_recovers_a_hidden_span_of_rank_one_motion() {
        // Every coordinate of every track is a multiple of one time signal plus an offset:
        // rank 1 after centring. A span of track 2 is hidden.
        let (t, n) = (30, 6);
        let signal = |k: usize| (k as f64 * 0.3).sin() + 0.05 * k as f64;
        let positions: Vec<f32> = (0..t)
            .flat_map(|k| {
                (0..n).flat_map(move |i| {
                    [0, 1, 2].map(|c| {
                        (i as f64 + c as f64 + (1.0 + (i * 3 + c) as f64 * 0.2) * signal(k)) as f32
                    })
                })
            })
            .collect();
        let mut observed = vec![true; t * n];
        for k in 10..18 {
            observed[k * n + 2] = false;
        }
        let marked = Marked::new(t, n, &positions, &observed);
        let filled = marked.iterative_pca();
        let linear = marked.linear();
        let err = |f: &[f32]| {
            (10..18)
                .map(|k| {
                    (0..3)
                        .map(|c| (f[3 * (k * n + 2) + c] - positions[3 * (k * n + 2) + c]).abs())
                        .sum::<f32>()
                })
                .sum::<f32>()
        };
        assert!(
            err(&filled) < 1e-3 * err(&linear),
            "{} vs {}",
            err(&filled),
            err(&linear)
        );
    }
}

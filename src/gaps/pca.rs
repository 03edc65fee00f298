//! The iterative PCA fill of the gap-filling literature ([`Marked::iterative_pca`]): a
//! low-rank reconstruction of the `[T, 3N]` matrix of the marker trajectories (Gløersen &
//! Federolf 2016; Tits et al. 2018), its unobserved entries replaced round after round by
//! their projection onto the principal components that hold most of the variance.

use super::marked::Marked;
use crate::numeric::eigen::Eigensystem;
use crate::numeric::linalg::{MovingGram, column_gram};

impl Marked<'_> {
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
        // A tall matrix's Gram matrix follows its missing entries as they move (a round
        // changes those alone) rather than being summed afresh over every frame: a round
        // costs the rows with gaps, not the recording.
        let mut gram = (t > d).then(|| MovingGram::new(&x, d));
        let (mut old, mut columns) = (Vec::with_capacity(d), Vec::new());
        for _ in 0..ITERATIVE_PCA_ITERATIONS {
            let r = match gram.as_mut() {
                Some(gram) => {
                    let (mean, g) = gram.centred();
                    project_rows(&x, d, &mean, g, ITERATIVE_PCA_ENERGY, &missing)
                }
                None => pca_projection(&x, t, d, ITERATIVE_PCA_ENERGY, &missing),
            };
            let mut change = 0f64;
            let mut at = 0;
            while at < missing.len() {
                let k = missing[at] / d;
                let row = k * d..(k + 1) * d;
                old.clear();
                old.extend_from_slice(&x[row.clone()]);
                columns.clear();
                while at < missing.len() && missing[at] / d == k {
                    let (e, v) = (missing[at], r[at]);
                    change = change.max((v - x[e]).abs());
                    x[e] = v;
                    columns.push(e % d);
                    at += 1;
                }
                if let Some(gram) = gram.as_mut() {
                    gram.change_row(&old, &x[row], &columns);
                }
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
    project_rows(x, d, &mean, g, energy, at)
}

/// The tall matrix `x` (`[t, d]`, `t > d`) projected onto its column means `mean` plus the
/// principal components of its centred Gram matrix `g` (`[d, d]`) that hold `energy` of
/// its variance, at the entries `at` (increasing), one row at a time.
fn project_rows(
    x: &[f64],
    d: usize,
    mean: &[f64],
    g: Vec<f64>,
    energy: f64,
    at: &[usize],
) -> Vec<f64> {
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
        for ((c, v), m) in row.iter_mut().zip(&x[k * d..(k + 1) * d]).zip(mean) {
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

//! The fillers of motion-capture software that borrow other markers' motion through a gap
//! (Vicon Nexus's *pattern fill* and *rigid-body fill*): the *donors* of a track's gap are
//! the other tracks observed at every frame from the gap's last observation before it to
//! its first after it, nearest first (by the mean distance to the track at those two
//! frames).
//!
//! - **Pattern fill** ([`Marked::pattern`]): one donor. The track's linear interpolation
//!   across the gap plus the donor's motion away from its own:
//!   `x(k) = lerp(x(a), x(b)) + d(k) − lerp(d(a), d(b))`.
//! - **Rigid-body fill** ([`Marked::rigid_body`]): three donors, taken as a rigid body. The
//!   rotation and translation that best move the donors from a border frame to frame `k`
//!   (least squares, Horn's quaternion form of the Kabsch problem) move the track's
//!   position there; the moves from both borders are blended linearly in time, so that
//!   the fill meets both observations.
//!
//! Both fill interior gaps only. Where a gap has too few donors, or is not interior, they
//! give the track's linear interpolation (held past the ends), so that every filler has a
//! value at every entry of a blend.

use std::collections::HashMap;

use super::marked::Marked;
use crate::numeric::eigen::symmetric_eigen;

impl Marked<'_> {
    /// The pattern fill at each entry `(k, i)` (module docs); an entry of a track never
    /// observed is whatever its position holds.
    pub fn pattern(&self, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        self.by_donors(
            entries,
            |i, a, b| self.donors(i, a, b, 1),
            |gap, k| {
                let (a, b) = (gap.before, gap.after);
                let w = (k - a) as f64 / (b - a) as f64;
                let lerp = |j: usize, c: usize| {
                    let (p, q) = (self.at64(a, j)[c], self.at64(b, j)[c]);
                    p + w * (q - p)
                };
                let (i, d) = (gap.track, gap.donors[0]);
                std::array::from_fn(|c| lerp(i, c) + self.at64(k, d)[c] - lerp(d, c))
            },
        )
    }

    /// The rigid-body fill at each entry `(k, i)` (module docs); an entry of a track never
    /// observed is whatever its position holds.
    pub fn rigid_body(&self, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        self.by_donors(
            entries,
            |i, a, b| self.donors(i, a, b, RIGID_BODY_DONORS),
            |gap, k| self.rigid_fill(gap, k),
        )
    }

    /// The rigid-body fill of `gap` at frame `k`: the track moved with its donors from
    /// each border, the two blended linearly in time.
    pub(super) fn rigid_fill(&self, gap: &DonorGap, k: usize) -> [f64; 3] {
        let (a, b) = (gap.before, gap.after);
        let donors_at =
            |f: usize| -> Vec<[f64; 3]> { gap.donors.iter().map(|&j| self.at64(f, j)).collect() };
        let now = donors_at(k);
        let from = |f: usize| rigid_motion(&donors_at(f), &now).apply(self.at64(f, gap.track));
        let (pa, pb) = (from(a), from(b));
        let w = (k - a) as f64 / (b - a) as f64;
        std::array::from_fn(|c| pa[c] + w * (pb[c] - pa[c]))
    }

    /// Track `i` at frame `k` in `f64`.
    pub(super) fn at64(&self, k: usize, i: usize) -> [f64; 3] {
        self.at(k, i).map(f64::from)
    }

    /// `fill(gap, k)` at each entry of an interior gap whose donors `choose(track, before,
    /// after)` finds; the linear interpolation elsewhere, computed at that entry alone. The
    /// donors (whatever `choose` prepares for a gap) are found once per gap.
    pub(super) fn by_donors<G>(
        &self,
        entries: &[(usize, usize)],
        choose: impl Fn(usize, usize, usize) -> Option<G>,
        fill: impl Fn(&G, usize) -> [f64; 3],
    ) -> Vec<[f32; 3]> {
        let mut gaps: HashMap<(usize, usize), Option<G>> = HashMap::new();
        entries
            .iter()
            .map(|&(k, i)| {
                if self.seen(k, i) {
                    return self.at(k, i);
                }
                let before = (0..k).rev().find(|&f| self.seen(f, i));
                let after = (k + 1..self.frames).find(|&f| self.seen(f, i));
                let (Some(a), Some(b)) = (before, after) else {
                    return self.linear_at(k, i, before, after);
                };
                let gap = gaps.entry((i, a)).or_insert_with(|| choose(i, a, b));
                match gap {
                    Some(gap) => fill(gap, k).map(|v| v as f32),
                    None => self.linear_at(k, i, before, after),
                }
            })
            .collect()
    }

    /// The `count` donors of track `i`'s gap between its observations at `a` and `b`: the
    /// other tracks observed at every frame `a..=b`, nearest first by the mean distance to
    /// `i` at `a` and at `b` (the lower index of a tie); `None` if there are fewer.
    pub(super) fn donors(&self, i: usize, a: usize, b: usize, count: usize) -> Option<DonorGap> {
        let distance = |j: usize, f: usize| {
            let (p, q) = (self.at64(f, i), self.at64(f, j));
            (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt()
        };
        let mut near: Vec<(f64, usize)> = (0..self.points)
            .filter(|&j| j != i && (a..=b).all(|f| self.seen(f, j)))
            .map(|j| ((distance(j, a) + distance(j, b)) / 2.0, j))
            .filter(|(d, _)| d.is_finite())
            .collect();
        if near.len() < count {
            return None;
        }
        near.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        Some(DonorGap {
            track: i,
            before: a,
            after: b,
            donors: near[..count].iter().map(|&(_, j)| j).collect(),
        })
    }
}

/// The donors that [`Marked::rigid_body`] moves as a rigid body (Nexus's: 3).
pub const RIGID_BODY_DONORS: usize = 3;

/// An interior gap of a track with its donors.
pub(super) struct DonorGap {
    pub track: usize,
    /// The track's last observation before the gap.
    pub before: usize,
    /// Its first observation after the gap.
    pub after: usize,
    pub donors: Vec<usize>,
}

/// A rotation `R` (row-major) and a translation `t`: `p ↦ R p + t`.
#[derive(Clone, Copy, Debug)]
pub(super) struct RigidMotion {
    r: [[f64; 3]; 3],
    t: [f64; 3],
}

impl RigidMotion {
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|row| (0..3).map(|c| self.r[row][c] * p[c]).sum::<f64>() + self.t[row])
    }
}

/// The proper rigid motion that best maps the points `from` onto `to` (least squares): the
/// rotation is the unit quaternion of the largest eigenvalue of Horn's symmetric 4 × 4
/// matrix of the cross-covariance (Horn 1987, J. Opt. Soc. Am. A 4(4)), the same optimum
/// as the Kabsch SVD with its reflection corrected; the translation maps the centroids.
pub(super) fn rigid_motion(from: &[[f64; 3]], to: &[[f64; 3]]) -> RigidMotion {
    let n = from.len() as f64;
    let centroid = |p: &[[f64; 3]]| -> [f64; 3] {
        std::array::from_fn(|c| p.iter().map(|q| q[c]).sum::<f64>() / n)
    };
    let (ca, cb) = (centroid(from), centroid(to));
    // s[x][y] = Σ (a − ca)_x (b − cb)_y
    let mut s = [[0f64; 3]; 3];
    for (p, q) in from.iter().zip(to) {
        for x in 0..3 {
            for y in 0..3 {
                s[x][y] += (p[x] - ca[x]) * (q[y] - cb[y]);
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let horn = vec![
        sxx + syy + szz,
        syz - szy,
        szx - sxz,
        sxy - syx, //
        syz - szy,
        sxx - syy - szz,
        sxy + syx,
        szx + sxz, //
        szx - sxz,
        sxy + syx,
        -sxx + syy - szz,
        syz + szy, //
        sxy - syx,
        szx + sxz,
        syz + szy,
        -sxx - syy + szz,
    ];
    let (values, vectors) = symmetric_eigen(horn, 4);
    let top = (0..4)
        .max_by(|&x, &y| values[x].total_cmp(&values[y]))
        .unwrap_or(0);
    let q: [f64; 4] = std::array::from_fn(|row| vectors[row * 4 + top]);
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|v| v / norm);
    let r = [
        [
            w * w + x * x - y * y - z * z,
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            w * w - x * x + y * y - z * z,
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            w * w - x * x - y * y + z * z,
        ],
    ];
    let t = std::array::from_fn(|row| cb[row] - (0..3).map(|c| r[row][c] * ca[c]).sum::<f64>());
    RigidMotion { r, t }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `R_z(θ)` then `R_x(φ)`, a proper rotation.
    fn rotation(theta: f64, phi: f64) -> [[f64; 3]; 3] {
        let (c, s, cp, sp) = (theta.cos(), theta.sin(), phi.cos(), phi.sin());
        let rz = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
        let rx = [[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]];
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| rx[i][k] * rz[k][j]).sum()))
    }

    #[test]
    fn the_rigid_motion_of_rotated_points_is_found_exactly() {
        let from = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [0.3, 0.1, 1.5],
        ];
        let r = rotation(0.7, -1.9);
        let t = [0.5, -2.0, 3.0];
        let to: Vec<[f64; 3]> = from
            .iter()
            .map(|p| std::array::from_fn(|i| (0..3).map(|c| r[i][c] * p[c]).sum::<f64>() + t[i]))
            .collect();
        let m = rigid_motion(&from, &to);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(
            m.r.iter()
                .flatten()
                .zip(r.iter().flatten())
                .all(|(&a, &b)| close(a, b)),
            "{m:?}"
        );
        assert!(m.t.iter().zip(&t).all(|(&a, &b)| close(a, b)), "{m:?}");
        // A reflection is not a rotation: the best proper one is returned (det = +1).
        let mirrored: Vec<[f64; 3]> = from.iter().map(|p| [p[0], p[1], -p[2]]).collect();
        let r = rigid_motion(&from, &mirrored).r;
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert!((det - 1.0).abs() < 1e-12, "{det}");
    }

    /// Five markers of one rigid body turning and moving over 12 frames, and a sixth far
    /// away moving otherwise; marker 0 hidden at frames 3..8.
    fn rigid_clip() -> (Vec<f32>, Vec<bool>) {
        let body = [
            [0.0, 0.0, 0.0],
            [0.1, 0.0, 0.0],
            [0.0, 0.12, 0.0],
            [0.0, 0.0, 0.09],
            [0.08, 0.07, 0.0],
        ];
        let (t, n) = (12, 6);
        let mut positions = Vec::new();
        for k in 0..t {
            let f = k as f64;
            let r = rotation(0.3 * f, 0.1 * f * f);
            let shift = [0.2 * f, (0.5 * f).sin(), 0.05 * f * f];
            for p in &body {
                for i in 0..3 {
                    let v: f64 = (0..3).map(|c| r[i][c] * p[c]).sum::<f64>() + shift[i];
                    positions.push(v as f32);
                }
            }
            positions.extend([5.0 + (0.9 * f).cos() as f32, 5.0, 5.0 * f as f32]);
        }
        let mut observed = vec![true; t * n];
        for k in 3..8 {
            observed[k * n] = false;
        }
        (positions, observed)
    }

    #[test]
    fn a_marker_of_a_rigid_body_is_filled_exactly_and_a_pattern_fill_is_not() {
        let (positions, observed) = rigid_clip();
        let tracks = Marked::new(12, 6, &positions, &observed);
        let entries: Vec<(usize, usize)> = (3..8).map(|k| (k, 0)).collect();
        let error = |fill: &[[f32; 3]]| {
            fill.iter()
                .zip(&entries)
                .map(|(p, &(k, i))| {
                    let truth = tracks.at(k, i);
                    (0..3).map(|c| (p[c] - truth[c]).abs()).fold(0f32, f32::max)
                })
                .fold(0f32, f32::max)
        };
        let rigid = error(&tracks.rigid_body(&entries));
        assert!(rigid < 1e-5, "{rigid}");
        // One donor cannot follow the rotation.
        let pattern = error(&tracks.pattern(&entries));
        assert!(pattern > 1e-3, "{pattern}");
    }

    #[test]
    fn the_pattern_fill_matches_a_hand_computed_case() {
        // Track 0 seen at frames 0 and 4 at x = 0 and 4; its donor (track 1, nearer than
        // track 2) moves 0, 1, 3, 3, 4 in x, its own lerp 0, 1, 2, 3, 4: at frame 2,
        // 2 + 3 − 2 = 3; at frames 1 and 3 the donor is on its lerp.
        let xs = [
            [0.0, 0.0, 9.0],
            [f32::NAN, 1.0, 9.0],
            [f32::NAN, 3.0, 9.0],
            [f32::NAN, 3.0, 9.0],
            [4.0, 4.0, 9.0],
        ];
        let positions: Vec<f32> = xs
            .iter()
            .flat_map(|row| row.iter().flat_map(|&x| [x, 0.0, 0.0]))
            .collect();
        let observed: Vec<bool> = (0..15).map(|e| e % 3 != 0 || e == 0 || e == 12).collect();
        let tracks = Marked::new(5, 3, &positions, &observed);
        let fill = tracks.pattern(&[(1, 0), (2, 0), (3, 0)]);
        assert_eq!(
            fill,
            vec![[1.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 0.0, 0.0]]
        );
    }

    #[test]
    fn without_enough_donors_or_past_the_ends_the_fill_is_linear() {
        let (positions, mut observed) = rigid_clip();
        // Markers 2..5 unseen at frame 5: marker 0's gap (3..8) has two donors only, and
        // marker 1 has a run past the end.
        for i in 2..6 {
            observed[5 * 6 + i] = false;
        }
        for k in 9..12 {
            observed[k * 6 + 1] = false;
        }
        let tracks = Marked::new(12, 6, &positions, &observed);
        let entries = [(4, 0), (10, 1)];
        let linear = tracks.linear();
        let at = |k: usize, i: usize| {
            let e = 3 * (k * 6 + i);
            [linear[e], linear[e + 1], linear[e + 2]]
        };
        let want = vec![at(4, 0), at(10, 1)];
        assert_eq!(tracks.rigid_body(&entries), want);
        // The pattern fill has its one donor for marker 0 (marker 1 is seen through).
        assert_ne!(tracks.pattern(&entries)[0], want[0]);
        assert_eq!(tracks.pattern(&entries)[1], want[1]);
    }
}

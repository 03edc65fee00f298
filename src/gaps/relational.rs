//! Qualisys's *relational fill*: a track carried through its gap in the frame of three
//! donors. The first donor is the origin of a local frame, the second sets its x axis, the
//! third the xy plane; the track's coordinates in that frame, known at the gap's two
//! borders, are interpolated linearly in time across the gap and mapped back through the
//! donors' frame at each frame (PyPI `gapfill`'s `recover_marker_rel`, Qualisys's trajectory
//! editor). Unlike the rigid-body fill ([`Marked::rigid_body`]), no best-fit motion is
//! found: the frame is the donors' own, so a donor's noise moves the fill directly, and a
//! marker that slides in its donors' frame is followed by the interpolation.
//!
//! The donors are the rigid-body fill's: the three tracks seen through the gap, nearest
//! first. Where a gap has fewer, is not interior, or its donors are collinear at a frame,
//! the fill is the track's linear interpolation there.

use super::donors::{DonorGap, RIGID_BODY_DONORS};
use super::marked::Marked;

impl Marked<'_> {
    /// The relational fill at each entry `(k, i)` (module docs); an entry of a track never
    /// observed is whatever its position holds.
    pub fn relational(&self, entries: &[(usize, usize)]) -> Vec<[f32; 3]> {
        self.by_donors(
            entries,
            |i, a, b| self.donors(i, a, b, RIGID_BODY_DONORS),
            |gap, k| self.relational_fill(gap, k),
        )
    }

    /// The relational fill of `gap` at frame `k`, or the track's linear interpolation where
    /// the donors' frame is degenerate at `k` or at a border.
    fn relational_fill(&self, gap: &DonorGap, k: usize) -> [f64; 3] {
        let (a, b, i) = (gap.before, gap.after, gap.track);
        let frame = |f: usize| {
            let [p0, p1, p2] = [0, 1, 2].map(|d| self.at64(f, gap.donors[d]));
            LocalFrame::of(p0, p1, p2)
        };
        let local = |f: usize| frame(f).map(|l| l.local(self.at64(f, i)));
        match (local(a), local(b), frame(k)) {
            (Some(ra), Some(rb), Some(now)) => {
                // gapfill's weights, in its order: (b − k)·r_a + (k − a)·r_b over b − a.
                let (wa, wb) = ((b - k) as f64, (k - a) as f64);
                now.world(std::array::from_fn(|c| {
                    (wa * ra[c] + wb * rb[c]) / (wb + wa)
                }))
            }
            _ => {
                let (pa, pb) = (self.at64(a, i), self.at64(b, i));
                let w = (k - a) as f64 / (b - a) as f64;
                std::array::from_fn(|c| pa[c] + w * (pb[c] - pa[c]))
            }
        }
    }
}

/// An orthonormal frame at `origin` with axes `x`, `y`, `z`.
#[derive(Clone, Copy, Debug)]
struct LocalFrame {
    origin: [f64; 3],
    axes: [[f64; 3]; 3],
}

impl LocalFrame {
    /// The frame of three points: `p0` the origin, `x` toward `p1`, `z` normal to the plane
    /// of the three, `y = z × x`; `None` where two coincide or the three are collinear.
    fn of(p0: [f64; 3], p1: [f64; 3], p2: [f64; 3]) -> Option<LocalFrame> {
        let unit = |v: [f64; 3]| {
            let n = v.iter().map(|c| c * c).sum::<f64>().sqrt();
            (n > 0.0 && n.is_finite()).then(|| v.map(|c| c / n))
        };
        let x = unit(std::array::from_fn(|c| p1[c] - p0[c]))?;
        let u1 = unit(std::array::from_fn(|c| p2[c] - p0[c]))?;
        let z = unit(cross(x, u1))?;
        Some(LocalFrame {
            origin: p0,
            axes: [x, cross(z, x), z],
        })
    }

    /// `p`'s coordinates along the axes.
    fn local(&self, p: [f64; 3]) -> [f64; 3] {
        let d: [f64; 3] = std::array::from_fn(|c| p[c] - self.origin[c]);
        self.axes.map(|axis| (0..3).map(|c| d[c] * axis[c]).sum())
    }

    /// The point whose coordinates along the axes are `r`.
    fn world(&self, r: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|c| {
            self.origin[c] + (0..3).map(|j| self.axes[j][c] * r[j]).sum::<f64>()
        })
    }
}

fn cross(u: [f64; 3], v: [f64; 3]) -> [f64; 3] {
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_maps_a_point_to_its_coordinates_and_back() {
        let frame = LocalFrame::of([1.0, 2.0, 3.0], [3.0, 2.0, 3.0], [1.0, 5.0, 3.0]).unwrap();
        // x along +x, the plane is z = 3, z along +z (x × y), y along +y.
        assert_eq!(frame.local([2.0, 4.0, 7.0]), [1.0, 2.0, 4.0]);
        assert_eq!(frame.world([1.0, 2.0, 4.0]), [2.0, 4.0, 7.0]);
        assert!(LocalFrame::of([0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]).is_none());
        assert!(LocalFrame::of([0.0; 3], [0.0; 3], [0.0, 1.0, 0.0]).is_none());
    }

    /// Three donors moving as a rigid body and a fourth track that slides linearly in
    /// their frame: the relational fill follows it exactly, as an interpolation of its
    /// local coordinates should.
    #[test]
    fn a_track_sliding_in_its_donors_frame_is_filled_exactly() {
        let (t, n) = (9, 4);
        let mut positions = Vec::new();
        for k in 0..t {
            let (s, c) = (0.2 * k as f64).sin_cos();
            let shift = [0.3 * k as f64, -0.1 * k as f64, 0.05 * k as f64];
            // A rotation about z and a shift; the fourth track's local position slides.
            let place = |p: [f64; 3]| -> [f64; 3] {
                [
                    c * p[0] - s * p[1] + shift[0],
                    s * p[0] + c * p[1] + shift[1],
                    p[2] + shift[2],
                ]
            };
            let local = [0.5 + 0.1 * k as f64, 0.4, 0.2 - 0.02 * k as f64];
            for p in [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], local] {
                positions.extend(place(p).map(|v| v as f32));
            }
        }
        let mut observed = vec![true; t * n];
        for k in 2..7 {
            observed[k * n + 3] = false;
        }
        let tracks = Marked::new(t, n, &positions, &observed);
        let entries: Vec<(usize, usize)> = (2..7).map(|k| (k, 3)).collect();
        for (p, &(k, i)) in tracks.relational(&entries).iter().zip(&entries) {
            let truth = tracks.at(k, i);
            assert!(
                (0..3).all(|c| (p[c] - truth[c]).abs() < 1e-5),
                "{k}: {p:?} {truth:?}"
            );
        }
    }
}

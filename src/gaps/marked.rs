//! The one view of masked tracks that every filler, span and gap of gap filling reads.
//!
//! Three types hold masked tracks, one per layer, and cannot be one:
//! [`crate::data::Trajectories`] is what the trainer uploads (every entry finite, the
//! unobserved ones stand-ins, with the canonical positions the field reads);
//! [`crate::data::tracks::Tracks`] is a file's tracks as read, before any canonical frame
//! is chosen (owned, unobserved entries whatever the file held, NaN included); `Marked`
//! borrows either's arrays, so that gap filling owns nothing, a window of time is a view
//! too ([`Marked::window`]), and `gaps/` needs nothing above the numeric leaf.

/// Tracks with a mask: `positions` `[T, N, 3]` and `observed` `[T, N]`, frame-major. What
/// every filler, span and gap reads. A borrowed view, not an owner: a fill's windows and
/// validation masks are views of one recording (module docs for the other two types).
#[derive(Clone, Copy, Debug)]
pub struct Marked<'a> {
    /// Frames `T`.
    pub frames: usize,
    /// Tracks `N`.
    pub points: usize,
    /// `[T, N, 3]`; unobserved entries are never read.
    pub positions: &'a [f32],
    /// `[T, N]`.
    pub observed: &'a [bool],
}

impl<'a> Marked<'a> {
    /// The view of `positions` and `observed`; panics if their lengths are not `3·T·N` and
    /// `T·N` (a caller's bug, not bad data).
    pub fn new(frames: usize, points: usize, positions: &'a [f32], observed: &'a [bool]) -> Self {
        assert_eq!(positions.len(), 3 * frames * points);
        assert_eq!(observed.len(), frames * points);
        Marked {
            frames,
            points,
            positions,
            observed,
        }
    }

    /// The same tracks seen through another mask (`[T, N]`).
    pub fn with_observed(&self, observed: &'a [bool]) -> Self {
        Marked::new(self.frames, self.points, self.positions, observed)
    }

    /// Whether track `i` is observed at frame `k`.
    pub fn seen(&self, k: usize, i: usize) -> bool {
        self.observed[k * self.points + i]
    }

    /// The tracks observed in at least one frame, in order: what the PCA fillers fill.
    pub fn seen_tracks(&self) -> Vec<usize> {
        (0..self.points)
            .filter(|&i| (0..self.frames).any(|k| self.seen(k, i)))
            .collect()
    }

    /// Each track's first and last observed frames (`None`: never observed), in one pass
    /// over the mask: what tells an entry past a track's ends from one inside.
    pub fn track_ends(&self) -> Vec<Option<(usize, usize)>> {
        let mut ends: Vec<Option<(usize, usize)>> = vec![None; self.points];
        for k in 0..self.frames {
            for (i, end) in ends.iter_mut().enumerate() {
                if self.seen(k, i) {
                    *end = Some(end.map_or((k, k), |(a, _)| (a, k)));
                }
            }
        }
        ends
    }

    /// Track `i`'s position at frame `k` (whatever it holds there).
    pub fn at(&self, k: usize, i: usize) -> [f32; 3] {
        let e = 3 * (k * self.points + i);
        [
            self.positions[e],
            self.positions[e + 1],
            self.positions[e + 2],
        ]
    }
}

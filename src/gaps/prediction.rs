//! The fitted field's prediction of the tracks, as the field's fills read it: computed
//! before the fill, or computed for each window of time that a long recording's fill asks
//! for ([`FieldPrediction::on_demand`]), so that a fill never holds the prediction of the
//! whole recording at once.

use std::ops::Range;
use std::sync::OnceLock;

use crate::numeric::knn::PointTree;

/// How many of a track's nearest tracks (by canonical position) may lend it their residual
/// when the lenders are chosen frame by frame
/// ([`Lending::FrameByFrame`](super::field_fill::Lending::FrameByFrame)).
pub const LENDER_POOL: usize = 8;

/// The field's prediction at the frames asked, `[F, N, 3]` for `F` frames: what
/// `run/complete/` evaluates on the fill's behalf. Called from the windows' threads.
pub type Predict<'a> = dyn Fn(Range<usize>) -> Vec<f32> + Sync + 'a;

/// The fitted field's prediction of a set of tracks, with what its fill needs besides: each
/// track's nearest tracks by canonical position.
pub struct FieldPrediction<'a> {
    /// The recording's frames predicted here.
    frames: Range<usize>,
    /// `[F, N, 3]` at those frames, where given.
    given: Option<&'a [f32]>,
    /// Computes the prediction, where it is not given: at the first call of
    /// [`FieldPrediction::predicted`], kept until this prediction is dropped.
    predict: Option<&'a Predict<'a>>,
    computed: OnceLock<Vec<f32>>,
    /// For each track, the [`LENDER_POOL`] other tracks nearest to it in the
    /// canonical frame, among those observed somewhere, closest first.
    pub neighbours: Vec<Vec<usize>>,
}

impl<'a> FieldPrediction<'a> {
    /// `predicted` (`[T, N, 3]`) and the neighbours by `canonical` (`[N, 3]`, the positions
    /// the field was evaluated from) among the tracks observed somewhere in `observed`
    /// (`[T, N]`). A track whose canonical position is not finite has no neighbour and lends
    /// none.
    pub fn new(points: usize, predicted: &'a [f32], canonical: &[f32], observed: &[bool]) -> Self {
        FieldPrediction {
            given: Some(predicted),
            ..Self::with(points, None, canonical, observed)
        }
    }

    /// The prediction that `predict` computes when a fill first reads it: a long
    /// recording's fill reads it window by window ([`FieldPrediction::window`],
    /// [`super::window`]), each window's computed when its fill starts and dropped when it
    /// ends, and never the whole recording's at once. The neighbours as in
    /// [`FieldPrediction::new`].
    pub fn on_demand(
        points: usize,
        predict: &'a Predict<'a>,
        canonical: &[f32],
        observed: &[bool],
    ) -> Self {
        Self::with(points, Some(predict), canonical, observed)
    }

    fn with(
        points: usize,
        predict: Option<&'a Predict<'a>>,
        canonical: &[f32],
        observed: &[bool],
    ) -> Self {
        let n = points;
        debug_assert_eq!(canonical.len(), 3 * n);
        let frames = observed.len().checked_div(n).unwrap_or(0);
        FieldPrediction {
            frames: 0..frames,
            given: None,
            predict,
            computed: OnceLock::new(),
            neighbours: neighbours(n, frames, canonical, observed),
        }
    }

    /// The field at every frame and track, `[T, N, 3]`.
    pub fn predicted(&self) -> &[f32] {
        match (self.given, self.predict) {
            (Some(given), _) => given,
            (None, Some(predict)) => self.computed.get_or_init(|| predict(self.frames.clone())),
            (None, None) => &[],
        }
    }

    /// The same prediction at `frames` alone, with the same neighbours: a view where it is
    /// given or computed already, else computed when the window's fill first reads it.
    pub fn window(&self, frames: Range<usize>) -> FieldPrediction<'_> {
        let n = self.neighbours.len();
        let ready = self.given.or(self.computed.get().map(|c| &c[..]));
        FieldPrediction {
            frames: self.frames.start + frames.start..self.frames.start + frames.end,
            given: ready.map(|whole| &whole[3 * frames.start * n..3 * frames.end * n]),
            predict: self.predict,
            computed: OnceLock::new(),
            neighbours: self.neighbours.clone(),
        }
    }
}

/// For each of `n` tracks, the [`LENDER_POOL`] others nearest by `canonical` among
/// those observed somewhere in `observed` ([`FieldPrediction::new`]).
fn neighbours(n: usize, frames: usize, canonical: &[f32], observed: &[bool]) -> Vec<Vec<usize>> {
    let at = |i: usize| [canonical[3 * i], canonical[3 * i + 1], canonical[3 * i + 2]];
    let finite = |i: usize| at(i).iter().all(|v| v.is_finite());
    let lenders: Vec<usize> = (0..n)
        .filter(|&i| finite(i) && (0..frames).any(|k| observed[k * n + i]))
        .collect();
    let cloud: Vec<[f32; 3]> = lenders.iter().map(|&i| at(i)).collect();
    match PointTree::new(&cloud) {
        Ok(tree) if !cloud.is_empty() => (0..n)
            .map(|i| {
                if !finite(i) {
                    return Vec::new();
                }
                let want = (LENDER_POOL + 1).min(cloud.len());
                tree.nearest_k(&at(i), want)
                    .into_iter()
                    .map(|r| lenders[r])
                    .filter(|&j| j != i)
                    .take(LENDER_POOL)
                    .collect()
            })
            .collect(),
        _ => vec![Vec::new(); n],
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;
    use crate::gaps::blend::fill_with;
    use crate::gaps::window::window_frames;
    use crate::gaps::{Filler, Marked};

    #[test]
    fn a_long_recording_s_prediction_is_computed_window_by_window_and_fills_the_same() {
        // Three windows of 4 tracks, each hidden for 300 frames in every 500.
        let (t, n) = (3 * window_frames(4), 4);
        let positions: Vec<f32> = (0..3 * t * n)
            .map(|v| ((v / 3 / n) as f32 * 0.01 + (v % (3 * n)) as f32).sin())
            .collect();
        let observed: Vec<bool> = (0..t * n)
            .map(|e| e / n < 5 || (e / n + 7 * (e % n)) % 500 >= 300)
            .collect();
        let tracks = Marked::new(t, n, &positions, &observed);
        // A field off the tracks by a slow drift, so that the fill has a residual to carry.
        let at = |v: usize| positions[v] + 0.1 * ((v / 3 / n) as f32 * 1e-3).cos();
        let predicted: Vec<f32> = (0..3 * t * n).map(at).collect();
        let (asked, longest) = (AtomicUsize::new(0), AtomicUsize::new(0));
        let predict = |frames: Range<usize>| {
            asked.fetch_add(1, Ordering::Relaxed);
            longest.fetch_max(frames.len(), Ordering::Relaxed);
            (3 * frames.start * n..3 * frames.end * n).map(at).collect()
        };
        let canonical = &positions[..3 * n];
        let given = FieldPrediction::new(n, &predicted, canonical, &observed);
        let on_demand = FieldPrediction::on_demand(n, &predict, canonical, &observed);
        let entries: Vec<(usize, usize)> = (0..t * n)
            .filter(|&e| !observed[e])
            .map(|e| (e / n, e % n))
            .collect();
        let whole = fill_with(&tracks, &given, Filler::FieldFill, &entries);
        let windowed = fill_with(&tracks, &on_demand, Filler::FieldFill, &entries);
        assert!(whole.iter().flatten().all(|v| v.is_finite()));
        assert_eq!(whole, windowed);
        // Several windows asked for, none longer than a window.
        assert!(asked.load(Ordering::Relaxed) > 3);
        assert_eq!(longest.load(Ordering::Relaxed), window_frames(n));
        assert_eq!(
            given.window(10..20).predicted(),
            &predicted[3 * 10 * n..3 * 20 * n]
        );
        assert_eq!(
            on_demand.window(10..20).predicted(),
            given.window(10..20).predicted()
        );
    }
}

//! Long recordings in windows of time.
//!
//! The fillers that learn from the whole recording (iterative PCA, Gløersen's PCA, the
//! Kalman smoother) hold a few copies of it in `f64`, every filler returns a whole fill,
//! and a blend's validation draws run every filler, two draws at once: on a minute at
//! 200 Hz that is hundreds of megabytes, growing with the frame count. Past
//! [`WINDOW_ENTRIES`] entries (frames × tracks) the fillers run on windows of time
//! instead:
//!
//! - each gap is filled in one window that holds it whole with a margin of context on both
//!   sides ([`windowed`]): windows of [`window_frames`] frames whose cores (all but an
//!   eighth at each end) tile the recording, a gap going to the window whose core holds
//!   its middle, or to a window of its own if it is too long for one;
//! - each of a blend's validation draws hides its spans in one window
//!   ([`DrawWindows`]), centred on one of the data's own gaps.
//!
//! What a fill holds beyond the data (the tracks, the field's prediction, the fill) is then
//! bounded by the window, whatever the recording's length; a recording that fits in one
//! window is filled exactly as it was without windows. In a window, a filler that learns
//! from the recording learns from the window's frames alone, as the local PCA fillers of
//! the literature do (docs/departures.md).

use std::collections::BTreeMap;
use std::ops::Range;

use rayon::prelude::*;

use super::fillers::Sources;
use super::marked::Marked;
use super::spans::{GapIndex, gaps};

/// The entries (frames × tracks) of a window: 8,738 frames of 60 markers (44 s at
/// 200 Hz), so that a lab's trial is filled whole, as the published fillers fill it. The
/// shared recordings (at most 4,499 frames × 41 markers) fit in one.
pub const WINDOW_ENTRIES: usize = 1 << 19;

/// The fewest frames of a window, however many tracks: a window must hold the longest
/// gaps users fill (2 s at 240 Hz) with context on both sides.
pub const MIN_WINDOW_FRAMES: usize = 2048;

/// The frames of a window over `points` tracks.
pub fn window_frames(points: usize) -> usize {
    (WINDOW_ENTRIES / points.max(1)).max(MIN_WINDOW_FRAMES)
}

impl<'a> Marked<'a> {
    /// The same tracks at `frames` alone (frame `k` of the window is frame
    /// `frames.start + k`).
    pub fn window(&self, frames: Range<usize>) -> Marked<'a> {
        let n = self.points;
        Marked::new(
            frames.len(),
            n,
            &self.positions[3 * frames.start * n..3 * frames.end * n],
            &self.observed[frames.start * n..frames.end * n],
        )
    }
}

/// The window whose core holds the middle of a gap over `gap` frames of `frames`, or the
/// gap with a margin on both sides where that window does not hold it with half a margin.
fn window_of(gap: &Range<usize>, frames: usize, width: usize) -> Range<usize> {
    let margin = width / 8;
    let core = width - 2 * margin;
    let middle = (gap.start + gap.end - 1) / 2;
    let c = middle / core;
    let tiled = (c * core).saturating_sub(margin)..((c + 1) * core + margin).min(frames);
    let context = gap.start.saturating_sub(margin / 2)..(gap.end + margin / 2).min(frames);
    if tiled.start <= context.start && context.end <= tiled.end {
        tiled
    } else {
        gap.start.saturating_sub(margin)..(gap.end + margin).min(frames)
    }
}

/// `entries` `(frame, track, gap length)`, each unobserved in `tracks`, by the window that
/// fills it: each window's frames and the indices of its entries, in order.
fn plan(tracks: &Marked, entries: &[Entry]) -> Vec<(Range<usize>, Vec<usize>)> {
    let (t, n) = (tracks.frames, tracks.points);
    let width = window_frames(n);
    let index = GapIndex::new(tracks);
    let mut windows: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
    for (j, &(k, i, _)) in entries.iter().enumerate() {
        // An observed entry is no gap: any window serves it.
        let gap = index.gap_at(k, i).unwrap_or(k..k + 1);
        let w = window_of(&gap, t, width);
        windows.entry((w.start, w.end)).or_default().push(j);
    }
    windows.into_iter().map(|((a, b), j)| (a..b, j)).collect()
}

/// An entry to fill, `(frame, track, gap length)`: a gap's length is the same in the
/// window that holds it.
pub type Entry = (usize, usize, usize);

/// `fill`'s values at `entries`, unobserved entries of `sources`, each computed from the
/// sources of the window that fills it (module docs): `fill` is given a window's sources
/// and its entries in the window's frames, and returns one value per entry. One call on
/// the whole recording where it fits in one window, none where there is no entry. The
/// windows run on every core.
pub fn windowed<R, F>(sources: &Sources, entries: &[Entry], fill: F) -> Vec<R>
where
    R: Copy + Default + Send,
    F: Fn(&Sources, &[Entry]) -> Vec<R> + Sync,
{
    let tracks = &sources.marked;
    // Nothing to fill computes nothing: a filler given no entries would still learn from
    // the whole recording.
    if entries.is_empty() {
        return Vec::new();
    }
    if tracks.frames <= window_frames(tracks.points) {
        return fill(sources, entries);
    }
    let parts: Vec<(Vec<usize>, Vec<R>)> = plan(tracks, entries)
        .into_par_iter()
        .map(|(frames, js)| {
            let field = sources.field.window(frames.clone());
            let local: Vec<Entry> = js
                .iter()
                .map(|&j| (entries[j].0 - frames.start, entries[j].1, entries[j].2))
                .collect();
            let values = fill(&Sources::new(tracks.window(frames), &field), &local);
            (js, values)
        })
        .collect();
    let mut out = vec![R::default(); entries.len()];
    for (js, values) in parts {
        for (j, v) in js.into_iter().zip(values) {
            out[j] = v;
        }
    }
    out
}

/// The windows of a blend's validation draws over `tracks` ([`DrawWindows::at`]).
pub struct DrawWindows {
    frames: usize,
    width: usize,
    /// The middle frame of each interior gap, in order.
    middles: Vec<usize>,
}

impl DrawWindows {
    /// The draws' windows over `tracks`.
    pub fn new(tracks: &Marked) -> Self {
        let mut middles: Vec<usize> = gaps(tracks)
            .filter(|g| g.is_interior())
            .map(|g| (g.frames.start + g.frames.end) / 2)
            .collect();
        middles.sort_unstable();
        DrawWindows {
            frames: tracks.frames,
            width: window_frames(tracks.points),
            middles,
        }
    }

    /// The frames of draw `draw`'s window: the whole recording where it fits in one
    /// window, else a window centred on one of its interior gaps (where there is none, on
    /// a time), chosen by the golden-ratio sequence so that the draws spread over the gaps
    /// in time.
    pub fn at(&self, draw: usize) -> Range<usize> {
        let (t, width) = (self.frames, self.width);
        if t <= width {
            return 0..t;
        }
        let spread = ((draw as f64 + 0.5) * 0.618_033_988_749_894_9).fract();
        let middle = match self.middles.len() {
            0 => (spread * t as f64) as usize,
            m => self.middles[((spread * m as f64) as usize).min(m - 1)],
        };
        let start = middle.saturating_sub(width / 2).min(t - width);
        start..start + width
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaps::Filler;

    #[test]
    fn a_gap_goes_to_the_window_whose_core_holds_its_middle() {
        // Width 800: margins of 100, cores of 600.
        assert_eq!(window_of(&(10..20), 5000, 800), 0..700);
        assert_eq!(window_of(&(650..660), 5000, 800), 500..1300);
        // Its middle in the third core, but it starts too near the window's edge.
        assert_eq!(window_of(&(1150..1260), 5000, 800), 1100..1900);
        assert_eq!(window_of(&(1100..1310), 5000, 800), 1000..1410);
        // Too long for any window's margin: its own.
        assert_eq!(window_of(&(100..1500), 5000, 800), 0..1600);
        assert_eq!(window_of(&(4900..4990), 5000, 800), 4700..5000);
    }

    /// A walk of `t` frames of `n` tracks, track `i` hidden for `len` frames from every
    /// `every`-th frame offset by `7 i`.
    fn walk(t: usize, n: usize, every: usize, len: usize) -> (Vec<f32>, Vec<bool>) {
        let positions = (0..3 * t * n)
            .map(|v| ((v / 3 / n) as f32 * 0.01 + (v % (3 * n)) as f32).sin())
            .collect();
        let observed = (0..t * n)
            .map(|e| {
                let (k, i) = (e / n, e % n);
                k < 5 || (k + 7 * i) % every >= len
            })
            .collect();
        (positions, observed)
    }

    #[test]
    fn windows_hold_their_gaps_and_map_frames_back() {
        let (t, n) = (3 * window_frames(4), 4);
        let (positions, observed) = walk(t, n, 500, 300);
        let tracks = Marked::new(t, n, &positions, &observed);
        let field =
            crate::gaps::FieldPrediction::new(n, &positions, &positions[..3 * n], &observed);
        let sources = Sources::new(tracks, &field);
        let entries: Vec<Entry> = (0..t * n)
            .filter(|&e| !observed[e])
            .map(|e| (e / n, e % n, 0))
            .collect();
        let none: Vec<[f32; 2]> = windowed(&sources, &[], |_, _| unreachable!("no entry"));
        assert!(none.is_empty());
        let plan = plan(&tracks, &entries);
        assert!(plan.len() > 3, "{} windows", plan.len());
        for (frames, js) in &plan {
            for &j in js {
                let (k, i, _) = entries[j];
                // The gap's observed neighbours lie in the window.
                let before = (0..k).rev().find(|&f| observed[f * n + i]).unwrap_or(0);
                let after = (k..t).find(|&f| observed[f * n + i]).unwrap_or(t - 1);
                assert!(
                    frames.contains(&before) && frames.contains(&after),
                    "{frames:?} {k}"
                );
            }
        }
        // Each entry's value computed in its window, by its frame there.
        let frames = windowed(&sources, &entries, |s, local| {
            local
                .iter()
                .map(|&(k, i, _)| [s.marked.positions[3 * (k * n + i)], k as f32])
                .collect()
        });
        for (&(k, i, _), v) in entries.iter().zip(&frames) {
            assert_eq!(v[0], positions[3 * (k * n + i)]);
            assert!(v[1] as usize <= k);
        }
        // Linear fill reads only a gap's two ends: the same in windows as whole.
        let whole = tracks.linear();
        let windowed_linear = windowed(&sources, &entries, |s, local| {
            let pairs: Vec<(usize, usize)> = local.iter().map(|&(k, i, _)| (k, i)).collect();
            Filler::Linear.fill_at(s, &pairs)
        });
        for (&(k, i, _), v) in entries.iter().zip(&windowed_linear) {
            let e = 3 * (k * n + i);
            assert_eq!(v, &[whole[e], whole[e + 1], whole[e + 2]], "({k}, {i})");
        }
    }

    #[test]
    fn draws_spread_over_the_gaps_in_windows() {
        let (n, width) = (4, window_frames(4));
        let (positions, observed) = walk(4 * width, n, 500, 300);
        let tracks = Marked::new(4 * width, n, &positions, &observed);
        let windows = DrawWindows::new(&tracks);
        let starts: Vec<usize> = (0..6).map(|d| windows.at(d).start).collect();
        assert!(starts.iter().all(|&s| s + width <= 4 * width));
        assert!(starts.iter().max() > starts.iter().min());
        // A recording within one window is the whole.
        let short = tracks.window(0..width);
        assert_eq!(DrawWindows::new(&short).at(3), 0..width);
    }
}

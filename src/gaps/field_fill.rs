//! The field's fill: the fitted field's prediction of a track in its gap, corrected by the
//! residual (observation − prediction) of the tracks nearest it at that very frame (its
//! *lenders*), then by the track's own residual carried across the gap. The field knows how
//! the track's neighbourhood moves; its error is shared by nearby tracks at a frame, and
//! what is left of it is the track's own offset, so the fill meets the observations on both
//! sides of a gap (docs/design.md §7). Numbers in, numbers out: the field was evaluated
//! before ([`FieldPrediction`]).

use super::marked::Marked;
use super::prediction::FieldPrediction;
use super::spans::gaps;

/// The longest gap (in frames) whose residual [`carry_residuals`] carries by a spline;
/// longer gaps carry it linearly. Chosen among 9, 16 and no limit on five marker recordings
/// (docs/gap-filling.md, real markers): the spline's carry is the better one in short gaps on
/// every file, the linear one in long gaps (a cubic's slope carried that far overshoots),
/// and 16 was the best of the three on all ten file and gap-length pairs.
pub const SPLINE_CARRY_FRAMES: usize = 16;

/// How many tracks, nearest by canonical position, lend a track their residual in
/// [`field_fill`]. Chosen among 1–4 on five marker recordings, seed 0
/// (docs/gap-filling.md, real markers): every choice beat the residual carried alone in all ten
/// file and gap-length pairs, and 2 was within 11 % of the best everywhere. The same lenders
/// at every frame, their residual carried where they are unseen too: lenders chosen frame by
/// frame among those seen there were worse on the markers (nearby markers' residuals differ
/// by offsets, which a change of lenders adds as jumps).
pub const LENDERS: usize = 2;

/// Which tracks lend a track their residual in [`field_fill`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lending {
    /// The [`LENDERS`] nearest, at every frame: their observation where they
    /// are seen, their own residual carried across their gap where they are not. Smooth
    /// across a gap; what sparse markers need.
    Fixed,
    /// At each frame, the [`LENDERS`] nearest of the [`LENDER_POOL`](super::prediction::LENDER_POOL)
    /// nearest that are seen there (the nearest, carried, where none is). Where nearby tracks
    /// are occluded together (the far side of a surface), the fixed lenders are unseen
    /// exactly where the track is, and their carried residual is no better than its own.
    FrameByFrame,
}

/// The residual carry: `predicted` (`[T, N, 3]`, the field at every track and frame) plus,
/// in each gap of a track, the track's residual `observed − predicted` carried across the
/// gap: by the natural cubic spline through all of the track's residuals for a gap of at
/// most [`SPLINE_CARRY_FRAMES`] frames, linearly between the residuals on either side of a
/// longer one, and held at the nearest residual before the first or after the last
/// observation. Observed entries are returned as observed.
///
/// The fill is `S(y) + (f − S(f))` for a spline `S` through the observed frames: the
/// track's own interpolation plus the field's motion away from its own interpolation. Where
/// the field is exact, the fill is the field's; where it is off by an offset that drifts
/// smoothly, the fill is the track's interpolation, exact at both borders of the gap.
pub fn carry_residuals(tracks: &Marked, predicted: &[f32]) -> Vec<f32> {
    let (positions, n) = (tracks.positions, tracks.points);
    debug_assert_eq!(predicted.len(), positions.len());
    let residual: Vec<f32> = positions
        .iter()
        .zip(predicted)
        .map(|(a, b)| a - b)
        .collect();
    let residuals = Marked::new(tracks.frames, n, &residual, tracks.observed);
    let (linear, spline) = (residuals.linear(), residuals.spline());
    let mut out = positions.to_vec();
    for gap in gaps(tracks) {
        let short = !gap.is_interior() || gap.len() <= SPLINE_CARRY_FRAMES;
        let carried = if short { &spline } else { &linear };
        for k in gap.frames {
            let e = 3 * (k * n + gap.track);
            for c in e..e + 3 {
                out[c] = predicted[c] + carried[c];
            }
        }
    }
    out
}

/// The field's fill: in every gap of a track, the field's prediction plus the mean
/// residual (observation − prediction) at that frame of the tracks that `lending` picks
/// among the track's [`FieldPrediction::neighbours`] (carried across their own gaps by
/// [`carry_residuals`] where they are not seen either), plus the track's own residual from
/// that corrected prediction carried across the gap by [`carry_residuals`]. Observed
/// entries are returned as observed; a track never observed is left as it is; a track with
/// no neighbour observed anywhere gets the residual carried alone.
///
/// Why: a field fitted to a few tens of markers errs by tens of millimetres, but its error
/// at a frame is shared by nearby markers (a limb it tracks late, a turn it smooths), so the
/// neighbours' residual at the gap's own frames corrects what the track's residual, known
/// only at the gap's borders, cannot (docs/design.md §7).
pub fn field_fill(tracks: &Marked, field: &FieldPrediction, lending: Lending) -> Vec<f32> {
    let carried = carry_residuals(tracks, field.predicted());
    field_fill_from_carry(tracks, field, &carried, lending)
}

/// [`field_fill`] from `carried`, the [`carry_residuals`] of the same tracks and field,
/// so that both kinds of [`Lending`] share it.
pub fn field_fill_from_carry(
    tracks: &Marked,
    field: &FieldPrediction,
    carried: &[f32],
    lending: Lending,
) -> Vec<f32> {
    let (t, n, observed) = (tracks.frames, tracks.points, tracks.observed);
    let predicted = field.predicted();
    let seen: Vec<bool> = (0..n)
        .map(|i| (0..t).any(|k| observed[k * n + i]))
        .collect();
    let mut guide = predicted.to_vec();
    let mut now = Vec::with_capacity(LENDERS);
    for (i, near) in field.neighbours.iter().enumerate() {
        let near: Vec<usize> = near.iter().copied().filter(|&j| seen[j]).collect();
        if near.is_empty() {
            continue;
        }
        let fixed = &near[..near.len().min(LENDERS)];
        for k in 0..t {
            now.clear();
            if lending == Lending::FrameByFrame {
                now.extend(
                    near.iter()
                        .copied()
                        .filter(|&j| observed[k * n + j])
                        .take(LENDERS),
                );
            }
            let lenders = if now.is_empty() { fixed } else { &now[..] };
            for c in 0..3 {
                let e = |j: usize| 3 * (k * n + j) + c;
                let residual: f64 = lenders
                    .iter()
                    .map(|&j| (carried[e(j)] - predicted[e(j)]) as f64)
                    .sum::<f64>()
                    / lenders.len() as f64;
                guide[e(i)] = (predicted[e(i)] as f64 + residual) as f32;
            }
        }
    }
    carry_residuals(tracks, &guide)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_field_off_by_a_drifting_offset_is_corrected_exactly_across_a_gap() {
        // One track, 5 frames, moving along x; the field is off by 1 + k/4 in y.
        let truth: Vec<f32> = (0..5).flat_map(|k| [k as f32, 0.0, 2.0]).collect();
        let predicted: Vec<f32> = (0..5)
            .flat_map(|k| [k as f32, -1.0 - k as f32 / 4.0, 2.0])
            .collect();
        let observed = [true, false, false, false, true];
        let mut given = truth.clone();
        for k in 1..4 {
            given[3 * k..3 * k + 3].fill(f32::NAN);
        }
        let filled = carry_residuals(&Marked::new(5, 1, &given, &observed), &predicted);
        for (a, b) in filled.iter().zip(&truth) {
            assert!((a - b).abs() < 1e-6, "{filled:?}");
        }
    }

    #[test]
    fn a_short_gap_carries_the_spline_a_long_one_the_line() {
        // One track over 50 frames, gaps of 3 (frames 10..13) and 20 (frames 25..45).
        let t = 50;
        let truth: Vec<f32> = (0..t)
            .flat_map(|k| {
                let k = k as f32;
                [(k * 0.3).sin(), 0.01 * k * k, 1.0]
            })
            .collect();
        let field: Vec<f32> = (0..t)
            .flat_map(|k| {
                let k = k as f32;
                [(k * 0.3).sin() + 0.2 * (k * 0.1).cos(), 0.012 * k * k, 0.5]
            })
            .collect();
        let observed: Vec<bool> = (0..t)
            .map(|k| !(10..13).contains(&k) && !(25..45).contains(&k))
            .collect();
        let filled = carry_residuals(&Marked::new(t, 1, &truth, &observed), &field);
        // Short: S(y) + f − S(f), the spline being linear in the data.
        let s_y = Marked::new(t, 1, &truth, &observed).spline();
        let s_f = Marked::new(t, 1, &field, &observed).spline();
        for e in 30..39 {
            assert!(
                (filled[e] - (s_y[e] + field[e] - s_f[e])).abs() < 1e-5,
                "{e}"
            );
        }
        // Long: the residual interpolated linearly between frames 24 and 45.
        for k in 25..45 {
            let w = (k - 24) as f32 / 21.0;
            for c in 0..3 {
                let r = |j: usize| truth[3 * j + c] - field[3 * j + c];
                let want = field[3 * k + c] + r(24) + w * (r(45) - r(24));
                assert!((filled[3 * k + c] - want).abs() < 1e-5, "{k} {c}");
            }
        }
        // Observed entries unchanged.
        assert_eq!(&filled[..30], &truth[..30]);
    }

    #[test]
    fn past_the_ends_the_nearest_residual_is_held_and_unseen_tracks_are_left() {
        // Two tracks; the first seen at frame 1 only, the second never.
        let positions = vec![
            9.0,
            9.0,
            9.0,
            f32::NAN,
            f32::NAN,
            f32::NAN, // frame 0
            1.0,
            1.0,
            1.0,
            f32::NAN,
            f32::NAN,
            f32::NAN, // frame 1
            9.0,
            9.0,
            9.0,
            f32::NAN,
            f32::NAN,
            f32::NAN, // frame 2
        ];
        let observed = [false, false, true, false, false, false];
        let predicted: Vec<f32> = (0..3)
            .flat_map(|k| [k as f32, k as f32, k as f32, 0.0, 0.0, 0.0])
            .collect();
        let filled = carry_residuals(&Marked::new(3, 2, &positions, &observed), &predicted);
        // Residual at frame 1 is 0 → the fill is the field's prediction.
        assert_eq!(&filled[0..3], &[0.0, 0.0, 0.0]);
        assert_eq!(&filled[12..15], &[2.0, 2.0, 2.0]);
        assert!(filled[3].is_nan() && filled[17].is_nan());
    }

    #[test]
    fn the_neighbours_residual_is_added_before_the_track_s_own_is_carried() {
        // Three tracks, three frames, a field predicting 0 everywhere. Track 0 is unseen at
        // frame 1; tracks 1 and 2 are seen everywhere, at x = (0, 2, 0) and (0, 4, 0). By
        // hand: the guide for track 0 is their mean, (0, 3, 0); track 0's residual from it
        // is 1 at frame 0 and 3 at frame 2, carried to 2 at frame 1 (the spline through two
        // points is the line); the fill is 3 + 2 = 5. The residual carried alone gives 2.
        let (t, n) = (3, 3);
        let x = [[1.0, 0.0, 0.0], [f32::NAN, 2.0, 4.0], [3.0, 0.0, 0.0]];
        let positions: Vec<f32> = (0..t)
            .flat_map(|k| (0..n).flat_map(move |i| [x[k][i], 0.0, 0.0]))
            .collect();
        let observed = [true, true, true, false, true, true, true, true, true];
        let predicted = vec![0f32; 3 * t * n];
        let canonical = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0];
        let field = FieldPrediction::new(n, &predicted, &canonical, &observed);
        assert_eq!(field.neighbours[0], vec![1, 2]);
        let filled = field_fill(
            &Marked::new(t, n, &positions, &observed),
            &field,
            Lending::Fixed,
        );
        assert_eq!(&filled[9..12], &[5.0, 0.0, 0.0]);
        let alone = carry_residuals(&Marked::new(t, n, &positions, &observed), &predicted);
        assert_eq!(&alone[9..12], &[2.0, 0.0, 0.0]);
        // Observed entries as given.
        for (e, (a, b)) in filled.iter().zip(&positions).enumerate() {
            if observed[e / 3] {
                assert_eq!(a, b);
            }
        }
    }

    #[test]
    fn a_field_error_shared_by_the_neighbours_is_corrected_inside_the_gap() {
        // A rigid row of 6 tracks moving along x; the field lags them by a jittering offset
        // that no interpolation across a gap can follow, the same for every track (a limb it
        // tracks late). Track 2's gap of 5 frames is filled exactly with the neighbours'
        // residual, and not by the residual carried alone.
        let (n, truth, predicted, observed) = lagging_row(&[2]);
        let field = FieldPrediction::new(n, &predicted, &truth[..3 * n], &observed);
        let filled = field_fill(
            &Marked::new(30, n, &truth, &observed),
            &field,
            Lending::Fixed,
        );
        let alone = carry_residuals(&Marked::new(30, n, &truth, &observed), &predicted);
        let (filled, alone) = (gap_error(&filled, &truth, 2), gap_error(&alone, &truth, 2));
        assert!(filled < 1e-5, "{filled}");
        assert!(alone > 0.1, "{alone}");
    }

    #[test]
    fn neighbours_are_the_nearest_other_tracks_seen_somewhere_with_a_finite_position() {
        // Five tracks on a line at 0, 0.9, 2, 3, 10; track 1 never seen, track 3 at NaN.
        let (t, n) = (2, 5);
        let canonical = [
            0.0,
            0.0,
            0.0,
            0.9,
            0.0,
            0.0,
            2.0,
            0.0,
            0.0,
            f32::NAN,
            0.0,
            0.0,
            10.0,
            0.0,
            0.0,
        ];
        let mut observed = vec![true; t * n];
        observed[1] = false;
        observed[n + 1] = false;
        let predicted = vec![0f32; 3 * t * n];
        let field = FieldPrediction::new(n, &predicted, &canonical, &observed);
        assert_eq!(field.neighbours[0], vec![2, 4]);
        assert_eq!(field.neighbours[1], vec![0, 2, 4]);
        assert_eq!(field.neighbours[2], vec![0, 4]);
        assert!(field.neighbours[3].is_empty());
        assert_eq!(field.neighbours[4], vec![2, 0]);
        // With no neighbour the fill is the residual carried alone.
        let alone = FieldPrediction::new(n, &predicted, &[f32::NAN; 3].repeat(n), &observed);
        let positions: Vec<f32> = (0..3 * t * n).map(|v| v as f32).collect();
        let mut gappy = observed.clone();
        gappy[n] = false;
        assert_eq!(
            field_fill(
                &Marked::new(t, n, &positions, &gappy),
                &alone,
                Lending::Fixed
            ),
            carry_residuals(&Marked::new(t, n, &positions, &gappy), &predicted)
        );
    }

    #[test]
    fn frame_by_frame_lenders_are_the_nearest_seen_at_that_frame() {
        // A row of 6 tracks that the field lags by a jittering offset, the same for all.
        // Track 0 and its two nearest (1, 2) are unseen together at frames 10..15 (the far
        // side of a surface): the fixed lenders' residual is carried there and misses the
        // jitter; lenders chosen frame by frame are tracks 3 and 4, seen, and the fill is
        // exact.
        let (n, truth, predicted, observed) = lagging_row(&[0, 1, 2]);
        let field = FieldPrediction::new(n, &predicted, &truth[..3 * n], &observed);
        assert_eq!(field.neighbours[0], vec![1, 2, 3, 4, 5]);
        let framewise = field_fill(
            &Marked::new(30, n, &truth, &observed),
            &field,
            Lending::FrameByFrame,
        );
        let fixed = field_fill(
            &Marked::new(30, n, &truth, &observed),
            &field,
            Lending::Fixed,
        );
        let (framewise, fixed) = (
            gap_error(&framewise, &truth, 0),
            gap_error(&fixed, &truth, 0),
        );
        assert!(framewise < 1e-5, "{framewise}");
        assert!(fixed > 0.1, "{fixed}");
    }

    /// A row of 6 tracks moving along x over 30 frames, a field that lags them by a
    /// jittering offset in x, the same for every track, and a mask hiding the `hidden`
    /// tracks at frames 10..15: `(n, truth, predicted, observed)`.
    fn lagging_row(hidden: &[usize]) -> (usize, Vec<f32>, Vec<f32>, Vec<bool>) {
        let (t, n) = (30, 6);
        let lag = |k: usize| 0.3 * ((k * k) as f32 * 1.3).sin();
        let truth: Vec<f32> = (0..t)
            .flat_map(|k| (0..n).flat_map(move |i| [i as f32 + 0.1 * k as f32, 0.5, 0.0]))
            .collect();
        let predicted = truth
            .iter()
            .enumerate()
            .map(|(e, &v)| if e % 3 == 0 { v - lag(e / (3 * n)) } else { v })
            .collect();
        let mut observed = vec![true; t * n];
        for k in 10..15 {
            for &i in hidden {
                observed[k * n + i] = false;
            }
        }
        (n, truth, predicted, observed)
    }

    /// The largest x error of `fill` on track `i` of [`lagging_row`] inside its gap.
    fn gap_error(fill: &[f32], truth: &[f32], i: usize) -> f32 {
        (10..15)
            .map(|k| (fill[3 * (k * 6 + i)] - truth[3 * (k * 6 + i)]).abs())
            .fold(0f32, f32::max)
    }
}

//! Gap filling: every unobserved entry of a set of tracks, by the fitted field and by the
//! baselines of the motion-capture gap-filling literature ([`baselines`]).
//!
//! Every filler here takes the same view of the data: `positions` `[T, N, 3]` (frame-major)
//! and `observed` `[T, N]`, and returns a copy of `positions` with every unobserved entry of
//! a track that is observed somewhere filled (a track never observed is left as it is). Only
//! observed entries are read, so what an unobserved entry holds (NaN, zeros) never matters.
//!
//! The field's fill ([`carry_residuals`]) is the field's prediction plus each track's own
//! residual carried across the gap: the field knows how the track's neighbourhood moves, the
//! residual keeps the track's own offset from it, so the fill meets the observations on both
//! sides of a gap. doma's fill ([`blend`], what `doma complete` writes) blends it with the
//! baselines by weights validated on the data's own observations (docs/design.md §7).

pub mod baselines;
pub mod blend;

/// The runs of a track's observed frames: for each frame, the nearest observed frame at or
/// before it and at or after it (`None` past the ends).
pub(crate) fn borders(observed: impl Fn(usize) -> bool, frames: usize) -> Vec<[Option<usize>; 2]> {
    let mut out = vec![[None, None]; frames];
    let mut last = None;
    for (k, o) in out.iter_mut().enumerate() {
        if observed(k) {
            last = Some(k);
        }
        o[0] = last;
    }
    let mut next = None;
    for k in (0..frames).rev() {
        if observed(k) {
            next = Some(k);
        }
        out[k][1] = next;
    }
    out
}

/// The longest gap (in frames) whose residual [`carry_residuals`] carries by a spline;
/// longer gaps carry it linearly. Chosen among 9, 16 and no limit on five marker recordings
/// (docs/results.md, real markers): the spline's carry is the better one in short gaps on
/// every file, the linear one in long gaps (a cubic's slope carried that far overshoots),
/// and 16 was the best of the three on all ten file and gap-length pairs.
pub const SPLINE_CARRY_FRAMES: usize = 16;

/// The field's gap fill: `predicted` (`[T, N, 3]`, the field at every track and frame) plus,
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
pub fn carry_residuals(
    frames: usize,
    points: usize,
    positions: &[f32],
    observed: &[bool],
    predicted: &[f32],
) -> Vec<f32> {
    debug_assert_eq!(positions.len(), 3 * frames * points);
    debug_assert_eq!(predicted.len(), positions.len());
    let residual: Vec<f32> = positions
        .iter()
        .zip(predicted)
        .map(|(a, b)| a - b)
        .collect();
    let marked = baselines::Marked::new(frames, points, &residual, observed);
    let (linear, spline) = (marked.linear(), marked.spline());
    let mut out = positions.to_vec();
    for i in 0..points {
        let seen = |k: usize| observed[k * points + i];
        for (k, &[before, after]) in borders(seen, frames).iter().enumerate() {
            if seen(k) || (before, after) == (None, None) {
                continue;
            }
            let short = match (before, after) {
                (Some(a), Some(b)) => b - a - 1 <= SPLINE_CARRY_FRAMES,
                _ => true,
            };
            let carried = if short { &spline } else { &linear };
            let e = 3 * (k * points + i);
            for c in e..e + 3 {
                out[c] = predicted[c] + carried[c];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn borders_are_the_nearest_observed_frames_on_each_side() {
        let seen = [false, true, false, false, true, false];
        let b = borders(|k| seen[k], 6);
        assert_eq!(
            b,
            vec![
                [None, Some(1)],
                [Some(1), Some(1)],
                [Some(1), Some(4)],
                [Some(1), Some(4)],
                [Some(4), Some(4)],
                [Some(4), None],
            ]
        );
    }

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
        let filled = carry_residuals(5, 1, &given, &observed, &predicted);
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
        let filled = carry_residuals(t, 1, &truth, &observed, &field);
        // Short: S(y) + f − S(f), the spline being linear in the data.
        let s_y = baselines::Marked::new(t, 1, &truth, &observed).spline();
        let s_f = baselines::Marked::new(t, 1, &field, &observed).spline();
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
        let filled = carry_residuals(3, 2, &positions, &observed, &predicted);
        // Residual at frame 1 is 0 → the fill is the field's prediction.
        assert_eq!(&filled[0..3], &[0.0, 0.0, 0.0]);
        assert_eq!(&filled[12..15], &[2.0, 2.0, 2.0]);
        assert!(filled[3].is_nan() && filled[17].is_nan());
    }
}

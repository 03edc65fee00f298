//! `doma complete`: every track of a fitted run at every frame, gaps filled by the field,
//! as a `.npz` or, from a C3D input, a `.c3d`.

use std::ops::Range;
use std::path::Path;
use std::sync::Mutex;

use burn::tensor::Device;
use doma_formats::npy::NpyValues;

use super::{RunConfig, RunDir, field_at_frames};
use crate::data::c3d::{c3d_tracks, read_c3d, write_c3d_patched};
use crate::data::layout::Layout;
use crate::data::mesh::as_points;
use crate::data::sequence::{Sequence, read_tracks};
use crate::data::tracks::Tracks;
use crate::gaps::blend::{Blend, blended_fill_at, fill_with};
use crate::gaps::window::window_frames;
use crate::gaps::{FieldPrediction, Filler, Marked};
use crate::{DomaError, Result};
use doma_formats::c3d::PointEdit;

/// What [`complete_run`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct Completion {
    /// Frames.
    pub frames: usize,
    /// Tracks.
    pub tracks: usize,
    /// Entries the input observed (written as they were).
    pub observed: usize,
    /// Entries filled inside gaps (observed on both sides).
    pub filled: usize,
    /// Entries filled before a track's first observation or after its last
    /// ([`FillPolicy::extrapolate`]).
    pub extrapolated: usize,
    /// Entries left unfilled (a gap past [`FillPolicy::max_gap`], or past a track's ends
    /// without [`FillPolicy::extrapolate`]).
    pub unfilled: usize,
    /// The weights of the fill ([`crate::gaps::blend`]).
    pub blend: Blend,
}

/// Which unobserved entries a completion fills. The default fills every gap with
/// observations on both sides, whatever its length, and nothing before a track's first
/// observation or after its last (as Vicon Nexus fills; QTM adds a longest gap).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FillPolicy {
    /// The longest gap filled (`None`: every length).
    pub max_gap: Option<MaxGap>,
    /// Also fill before a track's first observation and after its last.
    pub extrapolate: bool,
    /// Fill with this filler alone (`None`: doma's fill, the blend), e.g. the field's
    /// fill alone, or rigid-body fill written into the input's C3D.
    pub method: Option<Filler>,
}

/// A gap length: frames of the input (`--stride` does not change it), or seconds at the
/// input's rate (a C3D input's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MaxGap {
    /// Frames of the input.
    Frames(usize),
    /// Seconds.
    Seconds(f64),
}

impl std::str::FromStr for MaxGap {
    type Err = String;
    /// `N` frames or `Xs` seconds.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let bad = || format!("`{s}` is not a gap length: N frames, or Xs seconds (e.g. 0.5s)");
        match s.strip_suffix('s') {
            Some(x) => match x.parse::<f64>() {
                Ok(v) if v.is_finite() && v >= 0.0 => Ok(MaxGap::Seconds(v)),
                _ => Err(bad()),
            },
            None => s.parse().map(MaxGap::Frames).map_err(|_| bad()),
        }
    }
}

/// Writes every track of the run in `run` at every frame of its clip into `out`, in the
/// input's frame, units and track order: an observed entry as the input holds it, every
/// other one filled by doma's fill ([`crate::gaps::blend`]): the fitted field from the
/// track's canonical position plus the track's own residual carried across the gap, blended
/// with the baselines by weights validated on this data. The observations held out of the
/// fit count as observed: they are the input's.
///
/// A `.npz` holds `tracks` (`f32 [T, N, 3]`) and `observed` (`bool [T, N]`, the input's
/// mask), plus `kept` (`i64 [N]`, the input's index of each track) when the fit dropped
/// tracks that were never observed. `layout` writes the keys of a tracker's layout
/// instead: PointOdyssey's `trajs_3d` (as `f32`), `visibs` (the mask) and `valids` (all
/// true), or TAPVid-3D's `tracks_XYZ` and `visibility`.
///
/// A `.c3d` (from a C3D input alone, [`crate::data::c3d`]) is the input file with only the
/// filled entries written, in its own byte order and number format: every group and
/// parameter in its order, the analog samples, the events, the frames, rate and scale,
/// and every marker (one never seen stays invalid). A filled entry has residual 0, which
/// marks a point computed rather than measured; the frames outside the fitted clip, or
/// between the frames of its stride, are as the input holds them.
pub fn complete_run(
    run: &RunDir,
    out: &Path,
    layout: Option<Layout>,
    device: &Device,
) -> Result<Completion> {
    complete_run_with(run, out, layout, FillPolicy::default(), device)
}

/// [`complete_run`] filling what `policy` asks for: an entry left unfilled is NaN in a
/// `.npz` (and not valid in PointOdyssey's `valids`) and stays as the input holds it in a
/// `.c3d`.
pub fn complete_run_with(
    run: &RunDir,
    out: &Path,
    layout: Option<Layout>,
    policy: FillPolicy,
    device: &Device,
) -> Result<Completion> {
    let to_c3d = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("c3d"));
    if to_c3d && layout.is_some() {
        return Err(DomaError::Usage(
            "--layout names the keys of a .npz; a .c3d output has none".into(),
        ));
    }
    let config = run.load_config()?;
    crate::io::check_output(out, Some(&run.dir), &[&config.data])?;
    if to_c3d && !is_c3d(&config.data) {
        return Err(DomaError::Usage(format!(
            "a .c3d output is the C3D input with its gaps filled, and this run fitted {}: \
             write a .npz",
            config.data.display()
        )));
    }
    let done = complete_with(run, &config, policy, device)?;
    let (t, n) = (done.frames, done.points);
    if to_c3d {
        // The input file itself, with only the filled entries written: every group,
        // parameter, analog sample and event kept, and the frames outside the fitted clip
        // (or between its strided frames) as they were.
        let source_points: Vec<usize> = done.kept.clone().unwrap_or_else(|| (0..n).collect());
        let edits: Vec<PointEdit> = (0..t * n)
            .filter(|&e| done.filled[e])
            .map(|e| PointEdit {
                frame: done.source_frames[e / n],
                point: source_points[e % n],
                position: [
                    done.tracks[3 * e],
                    done.tracks[3 * e + 1],
                    done.tracks[3 * e + 2],
                ],
                residual: 0.0,
                cameras: 0,
            })
            .collect();
        write_c3d_patched(out, &config.data, &edits)?;
    } else {
        write_npz(out, &done, layout)?;
    }
    let count = |mask: &[bool]| mask.iter().filter(|&&o| o).count();
    let (observed, filled) = (count(&done.observed), count(&done.filled));
    let extrapolated = count(&done.extrapolated);
    Ok(Completion {
        frames: t,
        tracks: n,
        observed,
        filled: filled - extrapolated,
        extrapolated,
        unfilled: t * n - observed - filled,
        blend: done.blend,
    })
}

/// Every track of a run at every frame of its clip ([`complete_tracks`]), in the input's
/// frame, units and track order.
#[derive(Clone, Debug, PartialEq)]
pub struct CompletedTracks {
    /// `T`, the clip's frames.
    pub frames: usize,
    /// `N`, the fitted tracks.
    pub points: usize,
    /// `[T, N, 3]`: observed entries as the input holds them, the filled ones filled, the
    /// others NaN.
    pub tracks: Vec<f32>,
    /// `[T, N]`: the input's mask (held-out observations count as observed).
    pub observed: Vec<bool>,
    /// `[T, N]`: the entries filled (the others unobserved are NaN in `tracks`).
    pub filled: Vec<bool>,
    /// `[T, N]`: the filled entries before a track's first observation or after its last.
    pub extrapolated: Vec<bool>,
    /// The input's index of each track when the fit dropped tracks never observed.
    pub kept: Option<Vec<usize>>,
    /// The input's frame of each of the clip's frames.
    pub source_frames: Vec<usize>,
    /// The weights of the fill ([`crate::gaps::blend`]).
    pub blend: Blend,
}

/// The completion that [`complete_run_with`] writes, in memory: every track of the run in
/// `run` at every frame of its clip, the gaps that `policy` asks for filled by doma's fill
/// ([`crate::gaps::blend`]).
pub fn complete_tracks(
    run: &RunDir,
    policy: FillPolicy,
    device: &Device,
) -> Result<CompletedTracks> {
    let config = run.load_config()?;
    complete_with(run, &config, policy, device)
}

fn is_c3d(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("c3d"))
}

/// [`complete_tracks`] of the run's `config`.
fn complete_with(
    run: &RunDir,
    config: &RunConfig,
    policy: FillPolicy,
    device: &Device,
) -> Result<CompletedTracks> {
    let field = run.load_field(config, device)?;
    let Sequence {
        trajectories: data,
        center: c,
        scale: s,
        blind,
        kept,
        ..
    } = run.load_data(config)?;
    let (t, n) = (data.frames(), data.points());
    // The field's prediction: of the whole recording where the fill takes it whole, else
    // of each window of time as its fill starts (`gaps::window`), from the windows'
    // threads; an evaluation that fails fills its window with NaN and fails the fill after.
    let canonical = data.canonical().to_vec();
    drop(data);
    let points = as_points(&canonical);
    let failed: Mutex<Option<DomaError>> = Mutex::new(None);
    let predict = |frames: Range<usize>| {
        let len = 3 * frames.len() * n;
        field_at_frames(&field, &points, frames, t, device).unwrap_or_else(|e| {
            if let Ok(mut first) = failed.lock() {
                first.get_or_insert(e);
            }
            vec![f32::NAN; len]
        })
    };
    let whole = (t <= window_frames(n))
        .then(|| field_at_frames(&field, &points, 0..t, t, device))
        .transpose()?;
    // The input again, clipped and kept as the fit's data was, for its own values (and a
    // C3D's rate, for a --max-gap in seconds); read when needed rather than kept through
    // the fill.
    let read_input = || -> Result<(Tracks, Range<usize>, Option<f32>)> {
        let (mut input, rate) = if is_c3d(&config.data) {
            let markers = read_c3d(&config.data)?;
            let rate = markers.rate;
            let tracks = c3d_tracks(markers).map_err(|reason| DomaError::Malformed {
                path: config.data.clone(),
                reason,
            })?;
            (tracks, Some(rate))
        } else {
            (read_tracks(&config.data, &config.tracks)?.0, None)
        };
        let frame_range = config.frames.map_or(0..input.frames(), |[a, b]| a..b);
        if config.frames.is_some() || config.stride > 1 {
            input = input
                .select_frames(frame_range.clone(), config.stride)
                .map_err(DomaError::InvalidData)?;
        }
        if let Some(kept) = &kept {
            input = input.select_points(kept);
        }
        if (input.frames(), input.points()) != (t, n) {
            return Err(DomaError::Malformed {
                path: config.data.clone(),
                reason: format!(
                    "now holds {} frames of {} tracks; the run fitted {t} of {n}",
                    input.frames(),
                    input.points(),
                ),
            });
        }
        Ok((input, frame_range, rate))
    };
    let (input, frame_range, rate) = read_input()?;
    let seen = input.observed().to_vec();
    // In the fit's normalised coordinates, where the field predicts.
    let normalised: Vec<f32> = input
        .positions()
        .iter()
        .enumerate()
        .map(|(e, &v)| (v - c[e % 3]) / s)
        .collect();
    drop(input);
    let field = match &whole {
        Some(predicted) => FieldPrediction::new(n, predicted, &canonical, &seen),
        None => FieldPrediction::on_demand(n, &predict, &canonical, &seen),
    };
    let tracks = Marked::new(t, n, &normalised, &seen);
    let stride = config.stride.max(1);
    let source_frames: Vec<usize> = frame_range.step_by(stride).collect();
    let rate = rate.map(f64::from);
    let (filled, extrapolated) = chosen(&tracks, &source_frames, policy, rate, &config.data)?;
    // The fill of the chosen entries alone: a long recording holds no second copy of itself.
    let mut entries = Vec::with_capacity(filled.iter().filter(|&&f| f).count());
    entries.extend((0..t * n).filter(|&e| filled[e]).map(|e| (e / n, e % n)));
    let (fills, blend) = match policy.method {
        None => {
            let blind = blind.as_ref().map_or(&[][..], |b| &b.entries[..]);
            blended_fill_at(&tracks, &field, config.fit.seed, blind, &entries)
        }
        Some(filler) => (
            fill_with(&tracks, &field, filler, &entries),
            Blend::only(filler),
        ),
    };
    drop(field);
    drop((whole, normalised));
    if let Some(e) = failed.into_inner().ok().flatten() {
        return Err(e);
    }
    // Observed entries exactly as the input holds them (read again rather than kept
    // through the fill); filled ones back in its units.
    let mut values = read_input()?.0.into_positions();
    for (e, v) in values.chunks_exact_mut(3).enumerate() {
        if !seen[e] {
            v.fill(f32::NAN);
        }
    }
    for (&(k, i), v) in entries.iter().zip(fills) {
        let e = 3 * (k * n + i);
        for d in 0..3 {
            values[e + d] = v[d] * s + c[d];
        }
    }
    Ok(CompletedTracks {
        frames: t,
        points: n,
        tracks: values,
        observed: seen,
        filled,
        extrapolated,
        kept,
        source_frames,
        blend,
    })
}

/// The unobserved entries `policy` fills, and those of them past a track's ends: `[T, N]`
/// each. A gap's length is counted in the input's frames (`source_frames` maps the clip's),
/// in seconds at `rate` for [`MaxGap::Seconds`].
fn chosen(
    tracks: &Marked,
    source_frames: &[usize],
    policy: FillPolicy,
    rate: Option<f64>,
    data: &Path,
) -> Result<(Vec<bool>, Vec<bool>)> {
    let longest = match policy.max_gap {
        None => usize::MAX,
        Some(MaxGap::Frames(f)) => f,
        Some(MaxGap::Seconds(secs)) => match rate {
            Some(rate) => (secs * rate).floor() as usize,
            None => {
                return Err(DomaError::Usage(format!(
                    "--max-gap {secs}s: {} has no frame rate (a .c3d has); give the length \
                     in frames",
                    data.display()
                )));
            }
        },
    };
    let n = tracks.points;
    let mut filled = vec![false; tracks.frames * n];
    let mut extrapolated = vec![false; tracks.frames * n];
    for gap in crate::gaps::spans::gaps(tracks) {
        let fill = match (gap.before, gap.after) {
            (Some(a), Some(b)) => source_frames[b] - source_frames[a] - 1 <= longest,
            _ => policy.extrapolate,
        };
        if fill {
            for k in gap.frames.clone() {
                filled[k * n + gap.track] = true;
                extrapolated[k * n + gap.track] = !gap.is_interior();
            }
        }
    }
    Ok((filled, extrapolated))
}

/// The completion as a `.npz`, in the keys of `layout` ([`complete_run`]).
fn write_npz(out: &Path, done: &CompletedTracks, layout: Option<Layout>) -> Result<()> {
    let (t, n) = (done.frames, done.points);
    let (tracks, observed, kept) = (&done.tracks, &done.observed, done.kept.as_deref());
    let kept: Option<Vec<i64>> = kept.map(|k| k.iter().map(|&i| i as i64).collect());
    // PointOdyssey's `valids`: every entry that holds a point.
    let all_valid: Vec<bool> = (0..t * n)
        .map(|e| done.observed[e] || done.filled[e])
        .collect();
    let (tracks_key, mask_key) = match layout {
        Some(Layout::PointOdyssey) => ("trajs_3d", "visibs"),
        Some(Layout::TapVid3d) => ("tracks_XYZ", "visibility"),
        Some(Layout::Plain | Layout::Masked) | None => ("tracks", "observed"),
    };
    let (shape3, shape2, shape1) = ([t, n, 3], [t, n], [n]);
    let mut members: Vec<(&str, &[usize], NpyValues)> = vec![
        (tracks_key, &shape3, NpyValues::F32(tracks)),
        (mask_key, &shape2, NpyValues::Bool(observed)),
    ];
    if layout == Some(Layout::PointOdyssey) {
        members.push(("valids", &shape2, NpyValues::Bool(&all_valid)));
    }
    if let Some(kept) = &kept {
        members.push(("kept", &shape1, NpyValues::I64(kept)));
    }
    crate::data::npy::write_npz_values(out, &members)
}

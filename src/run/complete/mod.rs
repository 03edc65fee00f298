//! `doma complete`: every track of a fitted run at every frame, gaps filled by the field,
//! as a `.npz` or, from a C3D input, a `.c3d`.

use std::ops::Range;
use std::path::Path;
use std::sync::Mutex;

use burn::tensor::Device;
use doma_formats::npy::NpyValues;

use super::{RunConfig, RunDir, field_at_frames};
use crate::data::c3d::{C3d, c3d_tracks, read_c3d, write_c3d, write_c3d_patched};
use crate::data::layout::Layout;
use crate::data::mesh::as_points;
use crate::data::sequence::{Sequence, read_points, read_tracks};
use crate::data::tracks::Tracks;
use crate::data::trc::{Trc, read_trc, trc_of, trc_tracks, write_trc};
use crate::gaps::blend::{Blend, blended_fill_at, fill_with};
use crate::gaps::window::window_frames;
use crate::gaps::{FieldPrediction, Filler, Marked};
use crate::{DomaError, Result};
use doma_formats::c3d::PointEdit;

mod combined;
mod policy;
use combined::median_of;
use policy::chosen;
pub use policy::{FillPolicy, MaxGap};

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
    /// The fits whose fills were combined ([`RunConfig::fits`]); `blend` is the first's.
    pub fits: usize,
    /// The weights of the fill ([`crate::gaps::blend`]).
    pub blend: Blend,
    /// Each run of filled entries of one track, in track then frame order.
    pub gaps: Vec<FilledGap>,
    /// Gaps with observations on both sides left unfilled: longer than
    /// [`FillPolicy::max_gap`].
    pub left_long: usize,
}

/// A run of consecutive filled frames of one track ([`Completion::gaps`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FilledGap {
    /// The input's index of the track (its point in a C3D file, its marker in a `.trc`).
    pub track: usize,
    /// The input's first and last frame filled (0-based, inclusive).
    pub frames: [usize; 2],
    /// Before the track's first observation or after its last.
    pub extrapolated: bool,
}

/// The filled entries of `fill` as runs of consecutive frames of one track.
fn filled_gaps(fill: &RunFill, past_ends: &impl Fn(usize, usize) -> bool) -> Vec<FilledGap> {
    let mut by_track: Vec<(usize, usize)> = fill.entries.iter().map(|&(k, i)| (i, k)).collect();
    by_track.sort_unstable();
    let input_track = |i: usize| fill.kept.as_ref().map_or(i, |kept| kept[i]);
    let mut gaps: Vec<FilledGap> = Vec::new();
    let mut last: Option<(usize, usize)> = None;
    for (i, k) in by_track {
        let frame = fill.source_frames[k];
        match (last, gaps.last_mut()) {
            (Some((li, lk)), Some(g)) if li == i && lk + 1 == k => g.frames[1] = frame,
            _ => gaps.push(FilledGap {
                track: input_track(i),
                frames: [frame, frame],
                extrapolated: past_ends(k, i),
            }),
        }
        last = Some((i, k));
    }
    gaps
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
/// A `.c3d` from a C3D input ([`crate::data::c3d`]) is the input file with only the
/// filled entries written, in its own byte order and number format: every group and
/// parameter in its order, the analog samples, the events, the frames, rate and scale,
/// and every marker (one never seen stays invalid). A filled entry has residual 0, which
/// marks a point computed rather than measured (−0.0 in a float file: a fill's); the
/// frames outside the fitted clip, or between the frames of its stride, are as the input
/// holds them. From a `.trc` input it is a new file of its markers. A `.trc` keeps a
/// `.trc` input's header, or takes a `.c3d`'s labels, rate and units.
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
    let config = run.load_config()?;
    let kind = checked_output(out, layout, &config, Some(&run.dir))?;
    let fill = fill_run(run, &config, policy, device)?;
    write_completion(out, kind, layout, &config, fill)
}

/// The recording `data` completed into `out` without a fit: the gaps that `policy` asks
/// for filled by its filler alone (by default [`Filler::Chain`], the best fill that needs
/// no field on the recordings of docs/results.md), written as [`complete_run_with`]
/// writes a fitted run's. A C3D file's model outputs are left as they are, as a fit
/// leaves them. An entry the filler cannot fill (no marker to carry it) is left unfilled.
pub fn complete_without_fit(
    data: &Path,
    out: &Path,
    layout: Option<Layout>,
    policy: FillPolicy,
) -> Result<Completion> {
    let filler = policy.method.unwrap_or(Filler::Chain);
    if filler.is_field() {
        return Err(DomaError::Usage(format!(
            "--method {}: the field's fills need a fit (leave out --no-fit)",
            filler.name()
        )));
    }
    let config = crate::run::RunSpec {
        data: Some(data.to_path_buf()),
        ..Default::default()
    }
    .run_config()?;
    let kind = checked_output(out, layout, &config, None)?;
    let read = read_points(data, &config.tracks)?;
    let kept = read.markers;
    let (t, n) = (
        read.tracks.frames(),
        kept.as_ref().map_or(read.tracks.points(), Vec::len),
    );
    drop(read.tracks);
    let (input, _, rate) = read_input(&config, kept.as_deref(), t, n)?;
    let (positions, seen) = input.into_parts();
    let tracks = Marked::new(t, n, &positions, &seen);
    let source_frames: Vec<usize> = (0..t).collect();
    let somewhere: Vec<bool> = (0..n).map(|i| (0..t).any(|k| seen[k * n + i])).collect();
    let (entries, left_long) = chosen(&tracks, &source_frames, policy, rate.map(f64::from), data)?;
    let entries: Vec<(usize, usize)> = entries.into_iter().filter(|&(_, i)| somewhere[i]).collect();
    let values = filler.fill_observed(&tracks, &entries).unwrap_or_default();
    let (entries, values): (Vec<_>, Vec<_>) = entries
        .into_iter()
        .zip(values)
        .filter(|(_, v)| v.iter().all(|c| c.is_finite()))
        .unzip();
    drop(positions);
    let fill = RunFill {
        frames: t,
        points: n,
        seen,
        entries,
        values,
        kept,
        source_frames,
        blend: Blend::only(filler),
        left_long,
    };
    write_completion(out, kind, layout, &config, fill)
}

/// The format of `out` and whether the run of `config` can be written there, checked
/// before anything is computed: a known extension, a `.c3d` from a C3D input, a `.trc`
/// from an input with marker names and a rate, no output over an input or the run.
fn checked_output(
    out: &Path,
    layout: Option<Layout>,
    config: &RunConfig,
    run: Option<&Path>,
) -> Result<OutputKind> {
    let kind = OutputKind::of(out);
    if layout.is_some() && kind.is_some_and(|k| k != OutputKind::Npz) {
        return Err(DomaError::Usage(format!(
            "--layout names the keys of a .npz; {} has none",
            out.display()
        )));
    }
    crate::io::check_output(out, run, &[&config.data])?;
    output_kind_for(&config.data, out)
}

/// The format that `out`'s extension names for a completion of the recording `data`;
/// refuses any other extension, a `.c3d` from an input that is not one (it is the input
/// with its gaps written), and a `.trc` from an input without marker names and a rate.
pub fn output_kind_for(data: &Path, out: &Path) -> Result<OutputKind> {
    let Some(kind) = OutputKind::of(out) else {
        return Err(DomaError::Usage(format!(
            "{}: the output's extension says its format: .c3d, .trc or .npz",
            out.display()
        )));
    };
    if kind == OutputKind::Trc && !(is_c3d(data) || is_trc(data)) {
        return Err(DomaError::Usage(format!(
            "{}: a .trc output needs marker names and a frame rate, and {} has neither: \
             give a .c3d or .trc input, or write a .npz",
            out.display(),
            data.display()
        )));
    }
    if kind == OutputKind::C3d && !(is_c3d(data) || is_trc(data)) {
        return Err(DomaError::Usage(format!(
            "{}: a .c3d output needs marker names and a frame rate (from a .c3d input, the \
             input with its gaps written; from a .trc, a new file), and the input is {}: \
             write a .npz",
            out.display(),
            data.display()
        )));
    }
    Ok(kind)
}

/// Writes `fill` of the recording of `config` to `out` in the format `kind`.
fn write_completion(
    out: &Path,
    kind: OutputKind,
    layout: Option<Layout>,
    config: &RunConfig,
    fill: RunFill,
) -> Result<Completion> {
    let to_c3d = kind == OutputKind::C3d;
    let (t, n) = (fill.frames, fill.points);
    let past_ends = fill.past_ends();
    let extrapolated = fill
        .entries
        .iter()
        .filter(|&&(k, i)| past_ends(k, i))
        .count();
    let observed = fill.seen.iter().filter(|&&o| o).count();
    let completion = Completion {
        frames: t,
        tracks: n,
        observed,
        filled: fill.entries.len() - extrapolated,
        extrapolated,
        unfilled: t * n - observed - fill.entries.len(),
        fits: config.fits,
        blend: fill.blend.clone(),
        gaps: filled_gaps(&fill, &past_ends),
        left_long: fill.left_long,
    };
    if to_c3d && is_trc(&config.data) {
        let tracks = fill.tracks(config)?;
        let trc = trc_output(out, config, &fill, tracks)?;
        write_c3d(out, &c3d_of_trc(trc, &fill))?;
    } else if to_c3d {
        // The input file itself, with only the filled entries written: every group,
        // parameter, analog sample and event kept, and the frames outside the fitted clip
        // (or between its strided frames) as they were. The input's other values are never
        // read again.
        let source_point = |i: usize| fill.kept.as_ref().map_or(i, |kept| kept[i]);
        let edits: Vec<PointEdit> = fill
            .entries
            .iter()
            .zip(&fill.values)
            .map(|(&(k, i), &position)| PointEdit {
                frame: fill.source_frames[k],
                point: source_point(i),
                position,
                // Computed, and by a fill: −0.0 in a float file (`C3d::residuals`).
                residual: -0.0,
                cameras: 0,
            })
            .collect();
        drop(fill);
        write_c3d_patched(out, &config.data, &edits)?;
    } else if kind == OutputKind::Trc {
        let tracks = fill.tracks(config)?;
        write_trc(out, &trc_output(out, config, &fill, tracks)?)?;
    } else {
        let tracks = fill.tracks(config)?;
        // PointOdyssey's `valids`: every entry that holds a point.
        let valid = (layout == Some(Layout::PointOdyssey)).then(|| {
            let mut valid = fill.seen.clone();
            for &(k, i) in &fill.entries {
                valid[k * n + i] = true;
            }
            valid
        });
        let RunFill { seen, kept, .. } = fill;
        let done = Written {
            frames: t,
            points: n,
            tracks: &tracks,
            observed: &seen,
            valid: valid.as_deref(),
            kept: kept.as_deref(),
        };
        write_npz(out, &done, layout)?;
    }
    Ok(completion)
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
    fill_run(run, &config, policy, device)?.into_completed(&config)
}

fn is_c3d(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("c3d"))
}

fn is_trc(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("trc"))
}

/// The formats a completion writes, by the output's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// `.npz`: the tracks and their masks.
    Npz,
    /// `.c3d`: the C3D input with its gaps written.
    C3d,
    /// `.trc`: OpenSim's marker file.
    Trc,
}

impl OutputKind {
    /// The format `path`'s extension names; `None` for any other.
    pub fn of(path: &Path) -> Option<OutputKind> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "npz" => Some(OutputKind::Npz),
            "c3d" => Some(OutputKind::C3d),
            "trc" => Some(OutputKind::Trc),
            _ => None,
        }
    }
}

/// A new C3D file (Intel floats, the `POINT` group) of a completed `.trc`: its labels,
/// rate, units and first frame number; a measured point of residual 0 (a TRC states no
/// residual), a filled one of −0.0 (doma's fill, [`doma_formats::c3d::C3d::residuals`]),
/// one left unfilled not measured.
fn c3d_of_trc(trc: Trc, fill: &RunFill) -> C3d {
    let (t, n) = (trc.frames(), trc.points());
    let mut residuals: Vec<f32> = fill
        .seen
        .iter()
        .map(|&seen| if seen { 0.0 } else { -1.0 })
        .collect();
    for &(k, i) in &fill.entries {
        residuals[k * n + i] = -0.0;
    }
    let positions = trc
        .positions
        .iter()
        .map(|&v| if v.is_finite() { v } else { 0.0 })
        .collect();
    C3d {
        frames: t,
        points: n,
        first_frame: u32::try_from(trc.frame_numbers.first().copied().unwrap_or(1)).unwrap_or(1),
        rate: trc.rate as f32,
        scale: -0.1,
        units: trc.units,
        labels: trc.labels,
        model_outputs: vec![None; n],
        positions,
        residuals,
        cameras: vec![0; t * n],
        notes: Vec::new(),
    }
}

/// The `.trc` of a completed recording: a `.trc` input's header kept (its rates, units and
/// original frame range), or a `.c3d` input's labels, rate, units and frame numbers; the
/// rows of the fitted clip's frames, unfilled entries empty.
fn trc_output(out: &Path, config: &RunConfig, fill: &RunFill, tracks: Vec<f32>) -> Result<Trc> {
    let name = out
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let kept = |labels: Vec<String>| match &fill.kept {
        Some(kept) => kept.iter().map(|&i| labels[i].clone()).collect(),
        None => labels,
    };
    // Markers without a name (a C3D may have them) are named by their index.
    let named = |labels: Vec<String>| -> Vec<String> {
        labels
            .into_iter()
            .enumerate()
            .map(|(i, l)| {
                if l.trim().is_empty() {
                    format!("M{i}")
                } else {
                    l
                }
            })
            .collect()
    };
    if is_trc(&config.data) {
        let input = read_trc(&config.data)?;
        let rows = |v: &[u64]| -> Vec<u64> { fill.source_frames.iter().map(|&k| v[k]).collect() };
        let times = fill.source_frames.iter().map(|&k| input.times[k]).collect();
        return Ok(Trc {
            name,
            labels: kept(input.labels.clone()),
            frame_numbers: rows(&input.frame_numbers),
            times,
            positions: tracks,
            ..input
        });
    }
    let c3d = read_c3d(&config.data)?;
    let rate = c3d.rate as f64;
    let mut trc = trc_of(
        &name,
        named(kept(c3d.labels)),
        rate,
        &c3d.units,
        c3d.first_frame as u64,
        tracks,
    );
    trc.frame_numbers = fill
        .source_frames
        .iter()
        .map(|&k| c3d.first_frame as u64 + k as u64)
        .collect();
    trc.times = fill
        .source_frames
        .iter()
        .map(|&k| k as f64 / rate)
        .collect();
    trc.orig_frames = c3d.frames as u64;
    Ok(trc)
}

/// The fill of a run's chosen entries ([`fill_run`]), before it is written anywhere.
struct RunFill {
    frames: usize,
    points: usize,
    /// `[T, N]`: the input's mask (held-out observations count as observed).
    seen: Vec<bool>,
    /// `(frame, track)` of each entry filled, in frame-major order.
    entries: Vec<(usize, usize)>,
    /// Each entry's value, in the input's frame and units.
    values: Vec<[f32; 3]>,
    kept: Option<Vec<usize>>,
    source_frames: Vec<usize>,
    blend: Blend,
    /// Gaps with observations on both sides left unfilled, longer than the longest asked.
    left_long: usize,
}

impl RunFill {
    /// Whether entry `(frame, track)` lies before the track's first observation or after
    /// its last.
    fn past_ends(&self) -> impl Fn(usize, usize) -> bool + use<> {
        let n = self.points;
        let mut ends: Vec<Option<(usize, usize)>> = vec![None; n];
        for (e, _) in self.seen.iter().enumerate().filter(|&(_, &o)| o) {
            let (k, i) = (e / n, e % n);
            ends[i] = Some(ends[i].map_or((k, k), |(a, _)| (a, k)));
        }
        move |k, i| ends[i].is_none_or(|(a, b)| k < a || k > b)
    }

    /// Every track at every frame, `[T, N, 3]`: the input read again for its
    /// observations (rather than kept through the fill), the filled entries written in, the
    /// others NaN.
    fn tracks(&self, config: &RunConfig) -> Result<Vec<f32>> {
        let n = self.points;
        let (input, _, _) = read_input(config, self.kept.as_deref(), self.frames, n)?;
        let mut tracks = input.into_positions();
        for (e, v) in tracks.chunks_exact_mut(3).enumerate() {
            if !self.seen[e] {
                v.fill(f32::NAN);
            }
        }
        for (&(k, i), v) in self.entries.iter().zip(&self.values) {
            let e = 3 * (k * n + i);
            tracks[e..e + 3].copy_from_slice(v);
        }
        Ok(tracks)
    }

    /// [`Self::tracks`] with the masks of what was filled.
    fn into_completed(self, config: &RunConfig) -> Result<CompletedTracks> {
        let (t, n) = (self.frames, self.points);
        let tracks = self.tracks(config)?;
        let past_ends = self.past_ends();
        let mut filled = vec![false; t * n];
        let mut extrapolated = vec![false; t * n];
        for &(k, i) in &self.entries {
            let e = k * n + i;
            filled[e] = true;
            extrapolated[e] = past_ends(k, i);
        }
        Ok(CompletedTracks {
            frames: t,
            points: n,
            tracks,
            observed: self.seen,
            filled,
            extrapolated,
            kept: self.kept,
            source_frames: self.source_frames,
            blend: self.blend,
        })
    }
}

/// The input of the run's `config` again, clipped and kept as the fit's data was (`kept`),
/// for its own values: `t` frames of `n` tracks, or an error naming the file; with the
/// input's frames that the clip covers, and a C3D's rate (for a `--max-gap` in seconds).
fn read_input(
    config: &RunConfig,
    kept: Option<&[usize]>,
    t: usize,
    n: usize,
) -> Result<(Tracks, Range<usize>, Option<f32>)> {
    let malformed = |reason| DomaError::Malformed {
        path: config.data.clone(),
        reason,
    };
    let (mut input, rate) = if is_c3d(&config.data) {
        let markers = read_c3d(&config.data)?;
        let rate = markers.rate;
        (c3d_tracks(markers).map_err(malformed)?, Some(rate))
    } else if is_trc(&config.data) {
        let markers = read_trc(&config.data)?;
        let rate = markers.rate as f32;
        (trc_tracks(markers).map_err(malformed)?, Some(rate))
    } else {
        (read_tracks(&config.data, &config.tracks)?.0, None)
    };
    let frame_range = config.frames.map_or(0..input.frames(), |[a, b]| a..b);
    if config.frames.is_some() || config.stride > 1 {
        input = input
            .select_frames(frame_range.clone(), config.stride)
            .map_err(DomaError::InvalidData)?;
    }
    if let Some(kept) = kept {
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
}

/// The fill that `policy` asks for of the run's `config`: the entries it chooses and their
/// values, what a long recording holds beyond its positions and mask. Of a run that
/// combines several fits ([`RunConfig::fits`]), each entry's value is the median of
/// theirs, coordinate by coordinate, and the blend reported is the run's own fit's.
fn fill_run(
    run: &RunDir,
    config: &RunConfig,
    policy: FillPolicy,
    device: &Device,
) -> Result<RunFill> {
    let mut fill = fill_one(run, config, policy, device)?;
    if config.fits == 1 {
        return Ok(fill);
    }
    let mut values = vec![std::mem::take(&mut fill.values)];
    for k in 2..=config.fits {
        let member = run.member(k);
        // The run's own field may be read from its last checkpoint; the others' fills are
        // combined with it only once they are fitted.
        if member.config().is_file() && !member.model().is_file() {
            return Err(DomaError::Usage(format!(
                "fit {k} of {} in {} is not finished: doma fit --resume {}",
                config.fits,
                member.dir.display(),
                run.dir.display()
            )));
        }
        let other = member.load_config()?;
        if other.data != config.data
            || other.frames != config.frames
            || other.stride != config.stride
        {
            return Err(DomaError::Malformed {
                path: member.config(),
                reason: format!("fits other data than the run in {}", run.dir.display()),
            });
        }
        let other = fill_one(&member, &other, policy, device)?;
        if other.entries != fill.entries {
            return Err(DomaError::Malformed {
                path: member.dir,
                reason: "fills other entries than the run's own fit".into(),
            });
        }
        values.push(other.values);
    }
    fill.values = median_of(&values);
    Ok(fill)
}

/// [`fill_run`] of one fit.
fn fill_one(
    run: &RunDir,
    config: &RunConfig,
    policy: FillPolicy,
    device: &Device,
) -> Result<RunFill> {
    let field = run.load_field(config, device)?;
    let Sequence {
        trajectories: data,
        center: c,
        scale: s,
        blind,
        kept,
        ..
    } = run.load_data(config)?;
    // The blind spans' places alone: their values are the input's.
    let blind = blind.map(|b| b.entries);
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
    let (input, frame_range, rate) = read_input(config, kept.as_deref(), t, n)?;
    // In the fit's normalised coordinates, where the field predicts, in place.
    let (mut normalised, seen) = input.into_parts();
    for (e, v) in normalised.iter_mut().enumerate() {
        *v = (*v - c[e % 3]) / s;
    }
    let field = match &whole {
        Some(predicted) => FieldPrediction::new(n, predicted, &canonical, &seen),
        None => FieldPrediction::on_demand(n, &predict, &canonical, &seen),
    };
    let tracks = Marked::new(t, n, &normalised, &seen);
    let stride = config.stride.max(1);
    let source_frames: Vec<usize> = frame_range.step_by(stride).collect();
    let rate = rate.map(f64::from);
    let (entries, left_long) = chosen(&tracks, &source_frames, policy, rate, &config.data)?;
    // The fill of the chosen entries alone: a long recording holds no second copy of itself.
    let (mut values, blend) = match policy.method {
        None => {
            let blind = blind.as_deref().unwrap_or(&[]);
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
    // Back in the input's units.
    for v in &mut values {
        for d in 0..3 {
            v[d] = v[d] * s + c[d];
        }
    }
    Ok(RunFill {
        frames: t,
        points: n,
        seen,
        entries,
        values,
        kept,
        source_frames,
        blend,
        left_long,
    })
}

/// What a `.npz` completion holds ([`complete_run`]).
struct Written<'a> {
    frames: usize,
    points: usize,
    /// `[T, N, 3]`.
    tracks: &'a [f32],
    /// `[T, N]`: the input's mask.
    observed: &'a [bool],
    /// `[T, N]`: every entry that holds a point (PointOdyssey's `valids`).
    valid: Option<&'a [bool]>,
    kept: Option<&'a [usize]>,
}

/// The completion as a `.npz`, in the keys of `layout` ([`complete_run`]).
fn write_npz(out: &Path, done: &Written, layout: Option<Layout>) -> Result<()> {
    let (t, n) = (done.frames, done.points);
    let kept: Option<Vec<i64>> = done.kept.map(|k| k.iter().map(|&i| i as i64).collect());
    let (tracks_key, mask_key) = match layout {
        Some(Layout::PointOdyssey) => ("trajs_3d", "visibs"),
        Some(Layout::TapVid3d) => ("tracks_XYZ", "visibility"),
        Some(Layout::Plain | Layout::Masked) | None => ("tracks", "observed"),
    };
    let (shape3, shape2, shape1) = ([t, n, 3], [t, n], [n]);
    let mut members: Vec<(&str, &[usize], NpyValues)> = vec![
        (tracks_key, &shape3, NpyValues::F32(done.tracks)),
        (mask_key, &shape2, NpyValues::Bool(done.observed)),
    ];
    if let Some(valid) = done.valid {
        members.push(("valids", &shape2, NpyValues::Bool(valid)));
    }
    if let Some(kept) = &kept {
        members.push(("kept", &shape1, NpyValues::I64(kept)));
    }
    crate::data::npy::write_npz_values(out, &members)
}

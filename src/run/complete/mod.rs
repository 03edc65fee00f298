//! `doma complete`: every track of a fitted run at every frame, gaps filled by the field,
//! as a `.npz` or, from a C3D input, a `.c3d`.

use std::ops::Range;
use std::path::Path;
use std::sync::Mutex;

use burn::tensor::Device;

use super::{RunConfig, RunDir, field_at_frames};
use crate::data::c3d::{c3d_tracks, read_c3d};
use crate::data::layout::Layout;
use crate::data::mesh::as_points;
use crate::data::sequence::{Sequence, read_points, read_tracks};
use crate::data::tracks::Tracks;
use crate::data::trc::{read_trc, trc_tracks};
use crate::gaps::blend::{Blend, doma_fill_at, fill_with};
use crate::gaps::window::window_frames;
use crate::gaps::{FieldPrediction, Filler, Marked};
use crate::{DomaError, Result};

mod combined;
mod output;
mod policy;
use combined::median_of;
pub use output::{FilledGap, OutputKind, output_kind_for};
use output::{checked_output, is_c3d, is_trc, write_completion};
use policy::chosen;
pub use policy::{FillPolicy, MaxGap, extrapolates_by_default};

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
/// no field on the recordings of docs/gap-filling.md), written as [`complete_run_with`]
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
            "--method {}: the field's fills need a fit (`doma fill --fit`)",
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
    let (entries, left_long) = chosen(
        &tracks,
        &source_frames,
        policy,
        rate.map(f64::from),
        data,
        &config.tracks,
    )?;
    let entries: Vec<(usize, usize)> = entries.into_iter().filter(|&(_, i)| somewhere[i]).collect();
    let mut values = filler.fill_observed(&tracks, &entries).unwrap_or_default();
    if policy.method.is_none() {
        // doma's fill without a fit: a marker on a rigid cluster from its mates first.
        crate::gaps::blend::clusters_first(&tracks, &entries, &mut values);
    }
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
    let (entries, left_long) = chosen(
        &tracks,
        &source_frames,
        policy,
        rate,
        &config.data,
        &config.tracks,
    )?;
    // The fill of the chosen entries alone: a long recording holds no second copy of itself.
    let (mut values, blend) = match policy.method {
        None => {
            let blind = blind.as_deref().unwrap_or(&[]);
            doma_fill_at(
                &tracks,
                &field,
                config.fit.seed,
                blind,
                &entries,
                &config.fit.validation(),
            )
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
        blend: blend.in_units(f64::from(s)),
        left_long,
    })
}

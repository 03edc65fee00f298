//! Where a completion goes: the format the output's extension names, checked before
//! anything is computed, and the writing of a fill as a `.c3d` (the input patched, or a new
//! file from a `.trc`), a `.trc` or a `.npz`.

use std::path::Path;

use doma_formats::c3d::PointEdit;
use doma_formats::npy::NpyValues;

use super::{Completion, RunFill};
use crate::data::c3d::{C3d, read_c3d, write_c3d, write_c3d_patched};
use crate::data::layout::Layout;
use crate::data::trc::{Trc, read_trc, trc_of, write_trc};
use crate::run::RunConfig;
use crate::{DomaError, Result};

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
pub(super) fn filled_gaps(
    fill: &RunFill,
    past_ends: &impl Fn(usize, usize) -> bool,
) -> Vec<FilledGap> {
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

/// The format of `out` and whether the run of `config` can be written there, checked
/// before anything is computed: a known extension, a `.c3d` from a C3D input, a `.trc`
/// from an input with marker names and a rate, no output over an input or the run.
pub(super) fn checked_output(
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
pub(super) fn write_completion(
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

pub(super) fn is_c3d(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("c3d"))
}

pub(super) fn is_trc(path: &Path) -> bool {
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

/// What a `.npz` completion holds ([`super::complete_run`]).
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

/// The completion as a `.npz`, in the keys of `layout` ([`super::complete_run`]).
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

//! A filled recording's gaps as a lab reads them: one row per gap with its marker, frames,
//! times, what filled it and its expected error ([`gap_rows`]), written as CSV beside the
//! output ([`gaps_csv`]).

use std::path::{Path, PathBuf};

use super::Completion;
use crate::Result;

/// One filled gap of a recording as a lab reads it ([`gap_rows`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GapRow {
    /// The marker's name (`track I` where the input names none).
    pub marker: String,
    /// The input's index of the marker.
    pub track: usize,
    /// The input's first and last frame filled (0-based, inclusive).
    pub first_frame: usize,
    /// See `first_frame`.
    pub last_frame: usize,
    /// The first filled frame's time (s), where the input has a rate.
    pub start_s: Option<f64>,
    /// The last filled frame's time (s).
    pub end_s: Option<f64>,
    /// The frames filled.
    pub length_frames: usize,
    /// Their length (s): frames over the rate.
    pub length_s: Option<f64>,
    /// Before the marker's first observation or after its last.
    pub past_ends: bool,
    /// What filled it: `doma` (the blend) or one filler's name.
    pub filled_by: &'static str,
    /// The expected error of the fill (the mean distance from the truth over the gap, in
    /// the input's units; [`crate::gaps::confidence`]); `None` where it cannot be told.
    pub expected_error: Option<f64>,
    /// `expected_error` is above the threshold asked for: a gap to look at.
    pub flagged: bool,
}

/// What [`gap_rows`] found: the rows (flagged gaps first, the largest expected error
/// first; then by marker and frame), the input's units, and the calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct GapTable {
    /// The filled gaps.
    pub rows: Vec<GapRow>,
    /// The input's units (`mm`, `m`, ...), where it states them.
    pub units: Option<String>,
    /// The factor from the donors' spread to the expected error, and its spans.
    pub calibration: Option<crate::gaps::confidence::Calibration>,
}

/// Millimetres per unit of `units` (`mm`, `cm`, `m`); `None` for others.
pub fn mm_per_unit(units: &str) -> Option<f64> {
    match units.trim().to_ascii_lowercase().as_str() {
        "mm" => Some(1.0),
        "cm" => Some(10.0),
        "m" => Some(1000.0),
        _ => None,
    }
}

/// The input's marker names and frame rate (a `.c3d`'s or a `.trc`'s; `None` elsewhere).
pub fn names_and_rate(input: &Path) -> Result<(Vec<String>, Option<f64>)> {
    let ext = input
        .extension()
        .map_or(String::new(), |e| e.to_string_lossy().to_ascii_lowercase());
    Ok(match ext.as_str() {
        "c3d" => {
            let c = crate::data::c3d::read_c3d(input)?;
            (c.labels, Some(c.rate as f64))
        }
        "trc" => {
            let t = crate::data::trc::read_trc(input)?;
            (t.labels, Some(t.rate))
        }
        _ => (Vec::new(), None),
    })
}

/// What filled a completion's gaps: one filler's name, or `doma` (the blend).
pub fn filled_by(c: &Completion) -> &'static str {
    let only = crate::gaps::Filler::ALL.into_iter().find(|&f| {
        let ends = c.blend.ends.is_none_or(|e| e.weights[f] == 1.0);
        c.blend.short[f] == 1.0 && c.blend.long[f] == 1.0 && c.blend.leans.is_empty() && ends
    });
    only.map_or("doma", crate::gaps::Filler::name)
}

/// The filled gaps of `c`, a completion of the recording `input`, with their markers'
/// names, times and expected errors; a gap is flagged where its expected error passes
/// `flag_above_mm` millimetres (in the input's units where they are not mm; as they are
/// where the input states none).
pub fn gap_rows(input: &Path, c: &Completion, flag_above_mm: f64) -> Result<GapTable> {
    let (labels, rate) = names_and_rate(input)?;
    let read = crate::data::sequence::read_points(input, &Default::default())?;
    let units = read.units.clone();
    let threshold = flag_above_mm / units.as_deref().and_then(mm_per_unit).unwrap_or(1.0);
    let (t, n) = (read.tracks.frames(), read.tracks.points());
    let (positions, observed) = read.tracks.into_parts();
    let marked = crate::gaps::Marked::new(t, n, &positions, &observed);
    let gaps: Vec<(usize, std::ops::Range<usize>)> = c
        .gaps
        .iter()
        .map(|g| (g.track, g.frames[0]..g.frames[1] + 1))
        .collect();
    let (expected, calibration) = crate::gaps::confidence::expected_errors(&marked, &gaps, 0);
    let by = filled_by(c);
    let mut rows: Vec<GapRow> = c
        .gaps
        .iter()
        .zip(&expected)
        .map(|(g, &e)| {
            let frames = g.frames[1] - g.frames[0] + 1;
            let expected_error = (e.is_finite() && calibration.is_some()).then_some(e);
            GapRow {
                marker: labels
                    .get(g.track)
                    .filter(|l| !l.is_empty())
                    .cloned()
                    .unwrap_or_else(|| format!("track {}", g.track)),
                track: g.track,
                first_frame: g.frames[0],
                last_frame: g.frames[1],
                start_s: rate.map(|r| g.frames[0] as f64 / r),
                end_s: rate.map(|r| g.frames[1] as f64 / r),
                length_frames: frames,
                length_s: rate.map(|r| frames as f64 / r),
                past_ends: g.extrapolated,
                filled_by: by,
                expected_error,
                flagged: expected_error.is_some_and(|e| e > threshold),
            }
        })
        .collect();
    // The gaps to look at first, the worst first.
    rows.sort_by(|a, b| {
        b.flagged.cmp(&a.flagged).then_with(|| {
            if a.flagged {
                b.expected_error
                    .unwrap_or(0.0)
                    .total_cmp(&a.expected_error.unwrap_or(0.0))
            } else {
                std::cmp::Ordering::Equal
            }
        })
    });
    Ok(GapTable {
        rows,
        units,
        calibration,
    })
}

/// Where the table of a recording's filled gaps goes: beside the output, `trial.c3d` →
/// `trial.gaps.csv`.
pub fn gaps_csv_path(output: &Path) -> PathBuf {
    let stem = output.file_stem().unwrap_or_default().to_string_lossy();
    output.with_file_name(format!("{stem}.gaps.csv"))
}

/// Where the page of a recording's filled gaps goes: `trial.c3d` → `trial.gaps.html`.
pub fn gaps_html_path(output: &Path) -> PathBuf {
    let stem = output.file_stem().unwrap_or_default().to_string_lossy();
    output.with_file_name(format!("{stem}.gaps.html"))
}

/// `table` as CSV, a header line first; a marker's name quoted where CSV needs it. The
/// expected error is in the input's units (the `units` column).
pub fn gaps_csv(table: &GapTable) -> String {
    let mut out = String::from(
        "marker,first_frame,last_frame,start_s,end_s,length_frames,length_s,past_ends,filled_by,\
         expected_error,units,flagged\n",
    );
    let time = |t: Option<f64>| t.map_or(String::new(), |t| format!("{t:.4}"));
    let units = table.units.as_deref().unwrap_or("");
    for r in &table.rows {
        let marker = if r.marker.contains([',', '"', '\n', '\r']) {
            format!("\"{}\"", r.marker.replace('"', "\"\""))
        } else {
            r.marker.clone()
        };
        let expected = r
            .expected_error
            .map_or(String::new(), |e| format!("{e:.3}"));
        out.push_str(&format!(
            "{marker},{},{},{},{},{},{},{},{},{expected},{units},{}\n",
            r.first_frame,
            r.last_frame,
            time(r.start_s),
            time(r.end_s),
            r.length_frames,
            time(r.length_s),
            r.past_ends,
            r.filled_by,
            r.flagged
        ));
    }
    out
}

//! Which unobserved entries a completion fills: every gap with observations on both sides,
//! a longest gap as QTM has, and past a track's ends on request or, for a tracker's
//! output, by default.

use std::path::Path;

use super::output::{is_c3d, is_trc};
use crate::data::layout::{Layout, TrackFile};
use crate::gaps::{Filler, Marked};
use crate::{DomaError, Result};

/// Whether a completion of `data` (read as `file` says) fills past the tracks' ends unless
/// told: a tracker's output (PointOdyssey's or TAPVid-3D's layout) is, as it is used and
/// scored at every point of every frame (TAPVid-3D's metrics, PointOdyssey's); a
/// motion-capture recording (.c3d, .trc) and other tracks are not, as a marker's absence
/// before its first sighting or after its last is often real (Vicon Nexus and QTM leave
/// it too).
pub fn extrapolates_by_default(data: &Path, file: &TrackFile) -> Result<bool> {
    let npz = data
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npz"));
    if is_c3d(data) || is_trc(data) || !npz {
        return Ok(false);
    }
    Ok(Layout::of_npz(data, file)?.is_tracker())
}

/// Which unobserved entries a completion fills. The default fills every gap with
/// observations on both sides, whatever its length; before a track's first observation
/// and after its last, a tracker's output is filled and a recording is not
/// ([`extrapolates_by_default`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FillPolicy {
    /// The longest gap filled (`None`: every length).
    pub max_gap: Option<MaxGap>,
    /// Also fill before a track's first observation and after its last (`None`: as the
    /// input asks by default, [`extrapolates_by_default`]).
    pub extrapolate: Option<bool>,
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

/// The unobserved entries `policy` fills of `data` (read as `file` says), `(frame, track)`
/// in frame-major order, and how many gaps with observations on both sides it leaves
/// (longer than its longest). A gap's
/// length is counted in the input's frames (`source_frames` maps the clip's), in seconds at
/// `rate` for [`MaxGap::Seconds`].
pub(super) fn chosen(
    tracks: &Marked,
    source_frames: &[usize],
    policy: FillPolicy,
    rate: Option<f64>,
    data: &Path,
    file: &TrackFile,
) -> Result<(Vec<(usize, usize)>, usize)> {
    let extrapolate = match policy.extrapolate {
        Some(e) => e,
        None => extrapolates_by_default(data, file)?,
    };
    let longest = match policy.max_gap {
        None => usize::MAX,
        Some(MaxGap::Frames(f)) => f,
        Some(MaxGap::Seconds(secs)) => match rate {
            Some(rate) => (secs * rate).floor() as usize,
            None => {
                return Err(DomaError::Usage(format!(
                    "--max-gap {secs}s: {} has no frame rate (a .c3d or .trc has); give the \
                     length in frames",
                    data.display()
                )));
            }
        },
    };
    let mut too_long = 0;
    let gaps: Vec<_> = crate::gaps::spans::gaps(tracks)
        .filter(|gap| match (gap.before, gap.after) {
            (Some(a), Some(b)) => {
                let fits = source_frames[b] - source_frames[a] - 1 <= longest;
                too_long += usize::from(!fits);
                fits
            }
            _ => extrapolate,
        })
        .collect();
    let mut entries = Vec::with_capacity(gaps.iter().map(|g| g.len()).sum());
    for gap in gaps {
        entries.extend(gap.frames.map(|k| (k, gap.track)));
    }
    // The gaps come track by track.
    entries.sort_unstable();
    Ok((entries, too_long))
}

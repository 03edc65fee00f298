//! Which unobserved entries a completion fills: every gap with observations on both sides
//! by default, a longest gap as QTM has, and past a track's ends on request.

use std::path::Path;

use crate::gaps::{Filler, Marked};
use crate::{DomaError, Result};

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

/// The unobserved entries `policy` fills, `(frame, track)` in frame-major order, and how
/// many gaps with observations on both sides it leaves (longer than its longest). A gap's
/// length is counted in the input's frames (`source_frames` maps the clip's), in seconds at
/// `rate` for [`MaxGap::Seconds`].
pub(super) fn chosen(
    tracks: &Marked,
    source_frames: &[usize],
    policy: FillPolicy,
    rate: Option<f64>,
    data: &Path,
) -> Result<(Vec<(usize, usize)>, usize)> {
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
            _ => policy.extrapolate,
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

//! OpenSim's `.trc` marker files ([`doma_formats::trc`]): the markers of every frame, a
//! missing marker (empty fields or NaN) unobserved, in the file's own units and axes, with
//! the header's rate, units and original frame range kept for the file written back.

use std::path::Path;

pub use doma_formats::trc::Trc;

use super::tracks::Tracks;
use crate::io::write_atomic;
use crate::{DomaError, Result};

/// The largest `.trc` read: text of 4 GB is far past any recording (a minute of 200
/// markers at 200 Hz is about 40 MB).
const MAX_BYTES: u64 = 4 << 30;

/// Reads a `.trc` file; every defect is a [`DomaError::Malformed`] naming the file (and
/// the line).
pub fn read_trc(path: impl AsRef<Path>) -> Result<Trc> {
    let path = path.as_ref();
    let malformed = |reason: String| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    };
    let size = std::fs::metadata(path)
        .map_err(|e| DomaError::io(path, e))?
        .len();
    if size > MAX_BYTES {
        return Err(malformed(format!(
            "{size} bytes, past the {MAX_BYTES} a .trc reader takes"
        )));
    }
    let bytes = std::fs::read(path).map_err(|e| DomaError::io(path, e))?;
    let text =
        std::str::from_utf8(&bytes).map_err(|e| malformed(format!("not text (UTF-8): {e}")))?;
    doma_formats::trc::parse(text).map_err(malformed)
}

/// The markers as tracks: an entry is observed where the file has its three coordinates.
/// Takes the markers, so that their positions are not copied.
pub fn trc_tracks(trc: Trc) -> std::result::Result<Tracks, String> {
    let (t, n) = (trc.frames(), trc.points());
    let observed = trc
        .positions
        .chunks_exact(3)
        .map(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    Tracks::new(t, n, trc.positions, observed)
}

/// Writes `trc` to `path`, atomically (temporary file, then rename).
pub fn write_trc(path: impl AsRef<Path>, trc: &Trc) -> Result<()> {
    let path = path.as_ref();
    let text = doma_formats::trc::encode(trc).map_err(|reason| {
        DomaError::InvalidData(format!("cannot write {}: {reason}", path.display()))
    })?;
    write_atomic(path, text.as_bytes())
}

/// The header of a `.trc` written from a recording of `labels` at `rate` frames per
/// second in `units`, its first frame numbered `first_frame`, holding `positions`
/// (`[T, N, 3]`, NaN where missing): the original frame range is the recording's.
pub fn trc_of(
    name: &str,
    labels: Vec<String>,
    rate: f64,
    units: &str,
    first_frame: u64,
    positions: Vec<f32>,
) -> Trc {
    let n = labels.len().max(1);
    let t = positions.len() / (3 * n);
    Trc {
        name: name.to_string(),
        rate,
        camera_rate: rate,
        units: units.to_string(),
        orig_rate: rate,
        orig_start_frame: first_frame,
        orig_frames: t as u64,
        labels,
        frame_numbers: (0..t as u64).map(|k| first_frame + k).collect(),
        times: (0..t).map(|k| k as f64 / rate).collect(),
        positions,
    }
}

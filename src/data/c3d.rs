//! C3D motion-capture files ([`doma_formats::c3d`]): the markers of every frame, a marker
//! that was not measured (a negative residual, or the origin as some systems write it)
//! unobserved, in the file's own units and axes.
//!
//! doma writes a completed recording back as C3D ([`crate::run::complete_run`]):
//! the same labels, rate and units, the measured entries as they were, and every filled
//! entry with a residual of 0, which C3D reserves for a point computed rather than
//! measured, as capture software marks its own gap fills.

use std::path::Path;

pub use doma_formats::c3d::C3d;
use doma_formats::source::FileSource;

use super::tracks::Tracks;
use crate::io::write_atomic;
use crate::{DomaError, Result};

/// Reads a C3D file's points (the analog channels are skipped), from the file a piece at a
/// time ([`FileSource`]): its bytes are never held whole. Every defect is a
/// [`DomaError::Malformed`] naming the file.
pub fn read_c3d(path: impl AsRef<Path>) -> Result<C3d> {
    let path = path.as_ref();
    let source = FileSource::open(path).map_err(|e| DomaError::io(path, e))?;
    doma_formats::c3d::parse_from(&source).map_err(|reason| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    })
}

/// Writes the C3D file `source` to `path` with only `edits` changed
/// ([`doma_formats::c3d::patch_words`]: every group, parameter, analog sample and event
/// kept), atomically. `source` is copied a piece at a time with the edits written over
/// each piece ([`doma_formats::c3d::write_patched`]), so that neither it nor the output is
/// held whole.
pub fn write_c3d_patched(
    path: impl AsRef<Path>,
    source: &Path,
    edits: &[doma_formats::c3d::PointEdit],
) -> Result<()> {
    let path = path.as_ref();
    let file = FileSource::open(source).map_err(|e| DomaError::io(source, e))?;
    let words = doma_formats::c3d::patch_words(&file, edits).map_err(|reason| {
        DomaError::InvalidData(format!(
            "cannot write {} from {}: {reason}",
            path.display(),
            source.display()
        ))
    })?;
    crate::io::write_atomic_with(path, |w| {
        doma_formats::c3d::write_patched(&file, &words, w)
            .map_err(|e| std::io::Error::other(format!("{}: {e}", source.display())))
    })
}

/// The markers as tracks: an entry is observed where the file holds a point
/// ([`C3d::present`]: a NaN coordinate, as some writers store a missing point, is not
/// one). Takes the markers, so that their positions are not copied.
pub fn c3d_tracks(c: C3d) -> std::result::Result<Tracks, String> {
    let present = c.present();
    Tracks::new(c.frames, c.points, c.positions, present)
}

/// Writes `data` to `path` as a C3D file, atomically (temporary file, then rename).
pub fn write_c3d(path: impl AsRef<Path>, data: &C3d) -> Result<()> {
    let path = path.as_ref();
    let bytes = doma_formats::c3d::encode(data).map_err(|reason| {
        DomaError::InvalidData(format!("cannot write {}: {reason}", path.display()))
    })?;
    write_atomic(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_coordinates_and_the_origin_are_not_observed() {
        let c = C3d {
            frames: 2,
            points: 2,
            first_frame: 1,
            rate: 100.0,
            scale: -0.1,
            units: "mm".into(),
            labels: vec!["LASI".into(), "RASI".into()],
            model_outputs: vec![None; 2],
            positions: vec![
                1.0,
                2.0,
                3.0,
                0.0,
                0.0,
                0.0,
                1.0,
                2.0,
                3.0,
                f32::NAN,
                1.0,
                1.0,
            ],
            residuals: vec![1.0, 1.0, f32::NAN, 1.0],
            cameras: vec![0; 4],
            notes: Vec::new(),
        };
        // The origin and a NaN coordinate are not points; a NaN residual over finite
        // coordinates is.
        let t = c3d_tracks(c).unwrap();
        assert_eq!(t.observed(), &[true, false, true, false]);
    }
}

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
use doma_formats::c3d::PointWords;
use doma_formats::source::{FILE_PIECE, FileSource, Source};

use super::tracks::Tracks;
use crate::io::write_atomic;
use crate::{DomaError, Result};
use std::io::Write;

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
/// each piece, so that neither it nor the output is held whole.
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
        copy_patched(&file, &words, FILE_PIECE, w)
            .map_err(|e| std::io::Error::other(format!("{}: {e}", source.display())))
    })
}

/// Copies `file` to `w` `piece` bytes at a time, with `words` (in the order of their bytes)
/// written over each piece.
fn copy_patched<S: Source + ?Sized>(
    file: &S,
    words: &[PointWords],
    piece: usize,
    w: &mut impl Write,
) -> std::io::Result<()> {
    let (size, mut first, mut at) = (file.size(), 0, 0);
    while at < size {
        let len = (size - at).min(piece.max(1));
        let mut bytes = file
            .bytes_at(at, len)
            .map_err(std::io::Error::other)?
            .into_owned();
        // The words that reach into this piece, each written in the part that falls here.
        while first < words.len() && words[first].at + words[first].bytes().len() <= at {
            first += 1;
        }
        for word in words[first..].iter().take_while(|word| word.at < at + len) {
            let new = word.bytes();
            let (from, to) = (word.at.max(at), (word.at + new.len()).min(at + len));
            bytes[from - at..to - at].copy_from_slice(&new[from - word.at..to - word.at]);
        }
        w.write_all(&bytes)?;
        at += len;
    }
    Ok(())
}

/// The markers as tracks: an entry is observed where the file holds a point
/// ([`C3d::present`]). A measured point that is not finite is refused, naming its frame
/// and marker. Takes the markers, so that their positions are not copied.
pub fn c3d_tracks(c: C3d) -> std::result::Result<Tracks, String> {
    let present = c.present();
    if let Some(e) = (0..present.len())
        .find(|&e| present[e] && c.positions[3 * e..3 * e + 3].iter().any(|v| !v.is_finite()))
    {
        return Err(format!(
            "marker {} ({:?}) of frame {} is measured but not finite ({:?})",
            e % c.points,
            c.labels[e % c.points],
            e / c.points,
            &c.positions[3 * e..3 * e + 3]
        ));
    }
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

    /// Copied a piece at a time with the words written over each piece, a file is the
    /// patch made in memory, whatever pieces the words straddle.
    #[test]
    fn a_file_copied_in_pieces_is_patched_as_in_memory() {
        let c = C3d {
            frames: 3,
            points: 3,
            first_frame: 1,
            rate: 100.0,
            scale: -0.1,
            units: "mm".into(),
            labels: vec!["A".into(), "B".into(), "C".into()],
            positions: (0..27).map(|v| v as f32 - 13.0).collect(),
            residuals: vec![0.5; 9],
            cameras: vec![1; 9],
        };
        let bytes = doma_formats::c3d::encode(&c).unwrap();
        let edit = |frame, point, x| doma_formats::c3d::PointEdit {
            frame,
            point,
            position: [x, -x, 2.0 * x],
            residual: 0.0,
            cameras: 0,
        };
        let edits = [
            edit(2, 1, 5.5),
            edit(0, 0, -1.25),
            edit(2, 1, 7.0),
            edit(1, 2, 3.0),
        ];
        let expected = doma_formats::c3d::patch(&bytes, &edits).unwrap();
        let words = doma_formats::c3d::patch_words(&bytes[..], &edits).unwrap();
        for piece in [1, 5, 16, 100, FILE_PIECE] {
            let mut out = Vec::new();
            copy_patched(&bytes[..], &words, piece, &mut out).unwrap();
            assert_eq!(out, expected, "piece {piece}");
        }
        assert_ne!(expected, bytes);
    }

    #[test]
    fn a_measured_nan_names_the_marker() {
        let c = C3d {
            frames: 2,
            points: 2,
            first_frame: 1,
            rate: 100.0,
            scale: -0.1,
            units: "mm".into(),
            labels: vec!["LASI".into(), "RASI".into()],
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
            residuals: vec![1.0, 1.0, 1.0, 1.0],
            cameras: vec![0; 4],
        };
        let e = c3d_tracks(c.clone()).unwrap_err();
        assert!(e.contains("frame 1") && e.contains("\"RASI\""), "{e}");
        // The origin counts as not measured, whatever its residual.
        let mut ok = c.clone();
        ok.residuals[3] = -1.0;
        let t = c3d_tracks(ok).unwrap();
        assert_eq!(t.observed(), &[true, false, true, false]);
    }
}

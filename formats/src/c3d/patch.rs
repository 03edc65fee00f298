//! Rewriting points of a C3D file: a copy of its bytes with only the given points
//! changed, in its own byte order and number format, so that every group and parameter
//! (in its order), every analog sample and every event is kept.

use std::io::{self, Write};

use super::Processor;
use super::layout::Layout;
use super::read::{head, parameters, tail};
use crate::source::Source;

/// One point to write over a file's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointEdit {
    /// The frame, counted from the file's first (0-based).
    pub frame: usize,
    /// The point (`POINT:USED` order).
    pub point: usize,
    /// `x, y, z` in the file's units.
    pub position: [f32; 3],
    /// The residual (in the file's units): negative for a point not measured, 0 for one
    /// computed rather than measured, −0.0 for one that a fill computed (written as −0.0
    /// in a float file, 0 in an integer one).
    pub residual: f32,
    /// The mask of the cameras that saw it (7 bits).
    pub cameras: u8,
}

/// `bytes` (a C3D file that [`super::parse`] reads) with each of `edits` written over its
/// point's `x y z w` words ([`patch_words`], [`write_patched`]), in a copy.
pub fn patch(bytes: &[u8], edits: &[PointEdit]) -> Result<Vec<u8>, String> {
    let words = patch_words(bytes, edits)?;
    let mut out = Vec::with_capacity(bytes.len());
    write_patched(bytes, &words, &mut out).map_err(|e| e.to_string())?;
    Ok(out)
}

/// Copies the C3D file `src` to `w` [`Source::piece`] bytes at a time, with `words` (as
/// [`patch_words`] orders them) written over each piece: a file read from disk is never
/// held whole, whichever pieces the words straddle.
pub fn write_patched<S: Source + ?Sized>(
    src: &S,
    words: &[PointWords],
    w: &mut impl Write,
) -> io::Result<()> {
    let (size, mut first, mut at) = (src.size(), 0, 0);
    while at < size {
        let len = (size - at).min(src.piece().max(1));
        let mut bytes = src.bytes_at(at, len).map_err(io::Error::other)?;
        // The words that reach into this piece, each written in the part that falls here.
        while first < words.len() && words[first].at + words[first].len <= at {
            first += 1;
        }
        let here = words[first..].iter().take_while(|word| word.at < at + len);
        for word in here {
            let (from, to) = (word.at.max(at), (word.at + word.len).min(at + len));
            bytes.to_mut()[from - at..to - at]
                .copy_from_slice(&word.bytes()[from - word.at..to - word.at]);
        }
        w.write_all(&bytes)?;
        at += len;
    }
    Ok(())
}

/// One point's `x y z w` words as a patch writes them, at byte `at` of the file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointWords {
    /// The byte of the file where the words start.
    pub at: usize,
    words: [u8; 16],
    len: usize,
}

impl PointWords {
    /// The words' bytes (8 in an integer file, 16 in a float one).
    pub fn bytes(&self) -> &[u8] {
        &self.words[..self.len]
    }
}

/// The words that `edits` write over their points in the C3D file `src`, in the order of
/// the bytes they go to (two edits of one point in the order given), in the file's
/// processor format (Intel, DEC or MIPS) and number format (floats, or `i16` multiples of
/// the scale). The residual word is encoded as the reader decodes it: `−1` for not
/// measured, NaN (a float file) or 0 (an integer one) for a NaN residual, else the residual in units of `|scale|` (rounded, at most 255) with the camera
/// mask above it. Refuses an edit outside the file's frames or points, a position that is
/// not finite, and a position that an integer file cannot hold (past ±32767 × the scale).
/// Reads the file's header and parameters alone.
pub fn patch_words<S: Source + ?Sized>(
    src: &S,
    edits: &[PointEdit],
) -> Result<Vec<PointWords>, String> {
    let head = head(src)?;
    let (processor, params) = parameters(&head)?;
    let layout = Layout::of(&head, &tail(src)?, src.size(), processor, &params)?;
    let mut words = edits
        .iter()
        .map(|e| point_words(e, processor, &layout))
        .collect::<Result<Vec<_>, _>>()?;
    words.sort_by_key(|w| w.at);
    Ok(words)
}

/// Where `edit`'s point is in the file, and its `x y z w` words.
fn point_words(
    edit: &PointEdit,
    processor: Processor,
    layout: &Layout,
) -> Result<PointWords, String> {
    let float = layout.scale < 0.0;
    let size = if float { 4 } else { 2 };
    let magnitude = layout.scale.abs();
    if edit.frame >= layout.frames || edit.point >= layout.points {
        return Err(format!(
            "point {} of frame {} is outside the file's {} points and {} frames",
            edit.point, edit.frame, layout.points, layout.frames
        ));
    }
    if let Some(v) = edit.position.iter().find(|v| !v.is_finite()) {
        return Err(format!(
            "point {} of frame {}: the coordinate {v} is not finite",
            edit.point, edit.frame
        ));
    }
    // A NaN residual is a point of unknown residual (`C3d::present`): NaN in a float
    // word, residual 0 in an integer one, which has no NaN.
    let w: i32 = if edit.residual.is_nan() {
        (edit.cameras as i32 & 0x7f) << 8
    } else if edit.residual < 0.0 {
        -1
    } else {
        let byte = (edit.residual / magnitude).round().clamp(0.0, 255.0) as i32;
        ((edit.cameras as i32 & 0x7f) << 8) | byte
    };
    let at = layout.start + edit.frame * layout.record + edit.point * 4 * size;
    let mut words = [0u8; 16];
    if float {
        let values = [
            edit.position[0],
            edit.position[1],
            edit.position[2],
            if edit.residual.is_nan() {
                f32::NAN
            } else if edit.residual == 0.0 && edit.residual.is_sign_negative() {
                // A fill's mark: readers see residual 0 (computed); −0.0 tells it from a
                // measured point of residual 0 ([`super::C3d::residuals`]).
                -0.0
            } else {
                w as f32
            },
        ];
        for (c, v) in values.into_iter().enumerate() {
            words[4 * c..4 * c + 4].copy_from_slice(&processor.put_f32(v));
        }
    } else {
        for c in 0..3 {
            let q = (edit.position[c] / magnitude).round();
            if !(-32767.0..=32767.0).contains(&q) {
                return Err(format!(
                    "point {} of frame {}: {} is past what an integer C3D of scale {} holds",
                    edit.point, edit.frame, edit.position[c], layout.scale
                ));
            }
            words[2 * c..2 * c + 2].copy_from_slice(&processor.put_u16(q as i16 as u16));
        }
        words[6..8].copy_from_slice(&processor.put_u16(w as i16 as u16));
    }
    Ok(PointWords {
        at,
        words,
        len: 4 * size,
    })
}

#[cfg(test)]
mod tests {
    use super::super::{C3d, encode, parse};
    use super::*;
    use crate::source::Pieces;

    fn sample(scale: f32) -> C3d {
        C3d {
            frames: 4,
            points: 3,
            first_frame: 1,
            rate: 100.0,
            scale,
            units: "mm".into(),
            labels: vec!["A".into(), "B".into(), "C".into()],
            model_outputs: vec![None; 3],
            positions: (0..36).map(|v| v as f32 * 2.5 - 20.0).collect(),
            residuals: vec![
                0.5, -1.0, 1.0, 0.5, 0.5, 0.5, -1.0, 0.5, 0.5, 0.5, 0.5, -1.0,
            ],
            cameras: vec![3, 0, 1, 3, 3, 3, 0, 3, 3, 3, 3, 0],
            notes: Vec::new(),
        }
    }

    #[test]
    fn a_patched_point_reads_back_and_no_other_byte_changes() {
        // `encode` writes float files; integer files are patched in the Python tests (the
        // independent writer writes them).
        for scale in [-0.5f32, -0.1] {
            let bytes = encode(&sample(scale)).unwrap();
            let edits = [
                PointEdit {
                    frame: 0,
                    point: 1,
                    position: [1.5, -2.0, 3.0],
                    residual: 0.0,
                    cameras: 0,
                },
                PointEdit {
                    frame: 2,
                    point: 0,
                    position: [7.0, 8.5, -9.0],
                    residual: 1.0,
                    cameras: 5,
                },
            ];
            let patched = patch(&bytes, &edits).unwrap();
            let (before, after) = (parse(&bytes).unwrap(), parse(&patched).unwrap());
            for e in &edits {
                let k = e.frame * 3 + e.point;
                assert_eq!(&after.positions[3 * k..3 * k + 3], &e.position, "{scale}");
                assert_eq!(after.residuals[k], e.residual, "{scale}");
                assert_eq!(after.cameras[k], e.cameras, "{scale}");
            }
            let edited = |k: usize| edits.iter().any(|e| e.frame * 3 + e.point == k);
            for k in (0..12).filter(|&k| !edited(k)) {
                assert_eq!(
                    after.positions[3 * k..3 * k + 3],
                    before.positions[3 * k..3 * k + 3]
                );
                assert_eq!(after.residuals[k], before.residuals[k]);
            }
            let changed = bytes.iter().zip(&patched).filter(|(a, b)| a != b).count();
            assert!(changed <= 2 * 4 * 4, "{changed} bytes changed");
            assert_eq!(after.labels, before.labels);
        }
    }

    #[test]
    fn the_byte_orders_and_float_formats_round_trip() {
        use super::super::Processor;
        for p in [Processor::Intel, Processor::Dec, Processor::Mips] {
            for v in [0.0f32, 1.0, -2.5, 1234.5678, -0.001, 3.0e5] {
                assert_eq!(p.f32(&p.put_f32(v)), v, "{p:?} {v}");
            }
            for v in [0u16, 1, 0x7fff, 0xffff, 0x1234] {
                assert_eq!(p.u16(&p.put_u16(v)), v, "{p:?} {v}");
            }
        }
    }

    #[test]
    fn edits_the_file_cannot_hold_are_refused() {
        let bytes = encode(&sample(-0.5)).unwrap();
        let outside = PointEdit {
            frame: 4,
            point: 0,
            position: [0.0; 3],
            residual: 0.0,
            cameras: 0,
        };
        assert!(patch(&bytes, &[outside]).unwrap_err().contains("outside"));
        let nan = PointEdit {
            frame: 0,
            point: 0,
            position: [f32::NAN, 0.0, 0.0],
            residual: 0.0,
            cameras: 0,
        };
        assert!(patch(&bytes, &[nan]).unwrap_err().contains("not finite"));
        assert_eq!(patch(&bytes, &[]).unwrap(), bytes);
    }

    /// Copied in pieces of a few bytes, with the words written over each piece, a file is
    /// the patch made in one piece, whatever pieces the words straddle.
    #[test]
    fn a_file_copied_in_pieces_is_patched_as_in_one() {
        let bytes = encode(&sample(-0.1)).unwrap();
        let edit = |frame, point, x| PointEdit {
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
            edit(3, 2, 3.0),
        ];
        let expected = patch(&bytes, &edits).unwrap();
        assert_ne!(expected, bytes);
        assert_eq!(
            parse(&expected).unwrap().positions[3 * 7..3 * 8],
            [7.0, -7.0, 14.0]
        );
        let words = patch_words(&bytes[..], &edits).unwrap();
        for piece in [1, 5, 16, 100] {
            let mut out = Vec::new();
            write_patched(&Pieces(&bytes, piece), &words, &mut out).unwrap();
            assert_eq!(out, expected, "piece {piece}");
        }
    }
}

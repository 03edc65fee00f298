//! C3D motion-capture files (c3d.org, "The C3D File Format: A Technical User Guide"): the
//! 3-D points of every frame with their residuals, labels, rate and units.
//!
//! A file is 512-byte blocks:
//! - block 1, the header: the first parameter block, the point count, the analog words per
//!   frame, the first and last frame numbers, the scale factor (negative: the data are
//!   floats), the first data block and the frame rate;
//! - the parameter section: groups (`POINT`, `ANALOG`, `TRIAL`, ...) of typed, dimensioned
//!   parameters (`POINT:USED`, `POINT:LABELS`, ...); its fourth byte names the processor
//!   (84 Intel: little-endian IEEE; 85 DEC: VAX floats; 86 MIPS: big-endian IEEE), which
//!   sets the byte order of every number in the file;
//! - the data: per frame, `x y z w` for each point, then the frame's analog samples, as
//!   floats or as `i16` multiples of the scale. The fourth word `w` holds the residual in
//!   its low byte (in units of `|scale|`) and the mask of the cameras that saw the point in
//!   the next 7 bits; `w < 0` marks a point that was not measured, and a residual of 0 one
//!   that was computed (filled or filtered) rather than measured.
//!
//! [`parse`] (`read.rs`) reads the points and skips the analog samples; [`encode`]
//! (`write.rs`) writes an Intel float file with the `POINT` group alone (and
//! `ANALOG:USED = 0`); [`patch`] (`patch.rs`) rewrites chosen points of a file in its own
//! format and keeps every other byte (groups, parameters, analog samples, events). Every count is checked against the file's length before anything is
//! allocated.

#[cfg(test)]
mod conventions;
mod layout;
mod patch;
mod read;
mod write;

pub use patch::{PointEdit, PointWords, patch, patch_words, write_patched};
pub use read::{parse, parse_from};
pub use write::encode;

/// The 3-D points of a C3D file.
#[derive(Clone, Debug, PartialEq)]
pub struct C3d {
    /// `T`, the frames.
    pub frames: usize,
    /// `N`, the points (`POINT:USED`).
    pub points: usize,
    /// The number of the first frame (the header's, or `TRIAL:ACTUAL_START_FIELD`).
    pub first_frame: u32,
    /// Frames per second (`POINT:RATE`).
    pub rate: f32,
    /// `POINT:SCALE`: its magnitude is the unit of the residuals (and of integer data).
    pub scale: f32,
    /// `POINT:UNITS` (`"mm"` when the file has none).
    pub units: String,
    /// The point labels (`POINT:LABELS`, `LABELS2`, ...), trimmed; `""` where missing.
    pub labels: Vec<String>,
    /// `[N]`: for a point that a model computed rather than a marker, the parameter of
    /// `POINT` that lists its label (`ANGLES`, `FORCES`, `MOMENTS`, `POWERS`, `SCALARS`,
    /// `REACTIONS`, or one that `POINT:TYPE_GROUPS` names, as Nexus writes joint angles,
    /// forces, moments and powers as points); `None` for a marker.
    pub model_outputs: Vec<Option<String>>,
    /// `[T, N, 3]` frame-major, as stored (whatever a point not measured holds).
    pub positions: Vec<f32>,
    /// `[T, N]`: the residual; negative where the point was not measured, 0 where it was
    /// computed rather than measured, NaN where a float file's residual word is NaN (a
    /// point whose coordinates are there, of unknown residual). −0.0 where a float file's
    /// residual word is −0.0, which doma writes for a point its fill computed: every reader
    /// takes it for residual 0 (computed), and it stays told apart from a measured point of
    /// residual 0, which many systems write for every point.
    pub residuals: Vec<f32>,
    /// `[T, N]`: the mask of the cameras that saw the point (7 bits).
    pub cameras: Vec<u8>,
    /// What the reader decided where the file was not plain, one sentence each: a frame
    /// count read by the file's length, a header that disagrees with the parameters, points
    /// stored as NaN. Not written by [`encode`].
    pub notes: Vec<String>,
}

impl C3d {
    /// `[T, N]`: the entries that hold a point, by the conventions of capture software:
    /// a residual that is not negative, finite coordinates (a NaN coordinate is how some
    /// writers, kineticstoolkit's among them, store a missing point) and not the origin
    /// `(0, 0, 0)`, which some systems write for a point they did not see. A NaN residual
    /// with finite coordinates is a point (as ezc3d reads it): a fill never writes over
    /// coordinates a file holds.
    pub fn present(&self) -> Vec<bool> {
        self.residuals
            .iter()
            .zip(self.positions.chunks_exact(3))
            .map(|(&r, p)| {
                (r >= 0.0 || r.is_nan())
                    && p.iter().all(|v| v.is_finite())
                    && p.iter().any(|&v| v != 0.0)
            })
            .collect()
    }

    /// The points that are markers, not a model's outputs ([`C3d::model_outputs`]).
    pub fn markers(&self) -> Vec<usize> {
        (0..self.points)
            .filter(|&i| self.model_outputs.get(i).is_none_or(Option::is_none))
            .collect()
    }
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Processor {
    Intel,
    Dec,
    Mips,
}

impl Processor {
    fn u16(self, b: &[u8]) -> u16 {
        match self {
            Processor::Mips => u16::from_be_bytes([b[0], b[1]]),
            _ => u16::from_le_bytes([b[0], b[1]]),
        }
    }

    fn put_u16(self, v: u16) -> [u8; 2] {
        match self {
            Processor::Mips => v.to_be_bytes(),
            _ => v.to_le_bytes(),
        }
    }

    /// `v` in this processor's float format (the inverse of [`Processor::f32`]).
    fn put_f32(self, v: f32) -> [u8; 4] {
        match self {
            Processor::Intel => v.to_le_bytes(),
            Processor::Mips => v.to_be_bytes(),
            Processor::Dec if v == 0.0 => [0; 4],
            Processor::Dec => {
                let b = (v * 4.0).to_le_bytes();
                [b[2], b[3], b[0], b[1]]
            }
        }
    }

    fn f32(self, b: &[u8]) -> f32 {
        match self {
            Processor::Intel => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            Processor::Mips => f32::from_be_bytes([b[0], b[1], b[2], b[3]]),
            // A VAX F-float: its 16-bit words swapped, and an exponent bias 2 above IEEE's.
            Processor::Dec => {
                if b[1] & 0x7f == 0 && b[0] & 0x80 == 0 {
                    0.0
                } else {
                    f32::from_le_bytes([b[2], b[3], b[0], b[1]]) / 4.0
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> C3d {
        C3d {
            frames: 3,
            points: 2,
            first_frame: 7,
            rate: 120.0,
            scale: -0.1,
            units: "mm".into(),
            labels: vec!["LASI".into(), "RASI".into()],
            model_outputs: vec![None; 2],
            positions: (0..18).map(|v| v as f32 * 10.5 - 3.0).collect(),
            residuals: vec![0.5, -1.0, 0.0, 1.2, 25.5, 0.3],
            cameras: vec![3, 0, 0, 127, 1, 64],
            notes: Vec::new(),
        }
    }

    #[test]
    fn encode_then_parse_is_the_same_points() {
        let c = sample();
        let bytes = encode(&c).unwrap();
        assert_eq!(bytes.len() % 512, 0);
        let back = parse(&bytes).unwrap();
        assert_eq!(back.positions, c.positions);
        assert_eq!(back.labels, c.labels);
        assert_eq!((back.frames, back.points, back.first_frame), (3, 2, 7));
        assert_eq!(
            (back.rate, back.scale, back.units.as_str()),
            (120.0, -0.1, "mm")
        );
        assert_eq!(back.cameras, c.cameras);
        for (a, b) in back.residuals.iter().zip(&c.residuals) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        assert_eq!(back.present(), vec![true, false, true, true, true, true]);
    }

    #[test]
    fn integer_and_big_endian_data_are_read() {
        // An integer (positive scale) MIPS file made by hand: one point, two frames.
        let mut b = vec![0u8; 512 * 3];
        b[0] = 2;
        b[1] = 0x50;
        let be =
            |b: &mut Vec<u8>, at: usize, v: u16| b[at..at + 2].copy_from_slice(&v.to_be_bytes());
        be(&mut b, 2, 1); // points
        be(&mut b, 6, 1); // first frame
        be(&mut b, 8, 2); // last frame
        b[12..16].copy_from_slice(&0.5f32.to_be_bytes());
        be(&mut b, 16, 3); // data block
        b[20..24].copy_from_slice(&50f32.to_be_bytes());
        b[512..516].copy_from_slice(&[1, 0x50, 1, 86]);
        let words: [i16; 8] = [2, -4, 6, 0x0102, 8, 10, 12, -1];
        for (i, w) in words.iter().enumerate() {
            b[1024 + 2 * i..1026 + 2 * i].copy_from_slice(&w.to_be_bytes());
        }
        let c = parse(&b).unwrap();
        assert_eq!(c.positions, vec![1.0, -2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(c.residuals, vec![1.0, -1.0]);
        assert_eq!(c.cameras, vec![1, 0]);
        assert_eq!((c.rate, c.first_frame, c.frames), (50.0, 1, 2));
        assert_eq!(c.labels, vec![String::new()]);
    }

    #[test]
    fn dec_floats_are_converted() {
        // 1.0 as a VAX F-float: exponent 129, stored as the words 0x4080, 0x0000.
        let p = Processor::Dec;
        assert_eq!(p.f32(&[0x80, 0x40, 0, 0]), 1.0);
        assert_eq!(p.f32(&[0, 0, 0, 0]), 0.0);
        assert_eq!(p.f32(&[0x80, 0xc0, 0, 0]), -1.0);
    }

    #[test]
    fn defects_are_named() {
        let good = encode(&sample()).unwrap();
        assert!(parse(&good[..100]).unwrap_err().contains("truncated"));
        assert!(
            parse(&good[..good.len() - 512])
                .unwrap_err()
                .contains("truncated")
        );
        let mut bad = good.clone();
        bad[1] = 0;
        assert!(parse(&bad).unwrap_err().contains("not a C3D"));
        let mut bad = good.clone();
        bad[512 + 3] = 90;
        assert!(parse(&bad).unwrap_err().contains("processor"));
        let mut c = sample();
        c.labels.pop();
        assert!(encode(&c).unwrap_err().contains("labels"));
    }

    #[test]
    fn fuzz_regressions_are_refused_or_read() {
        // A group id of −128, whose negation overflows an i8.
        let input = include_bytes!("../../../fuzz/regressions/c3d-group-id-overflow");
        let _ = parse(input);
    }

    /// Read in pieces, every file reads as it does whole: the same points or the same
    /// error, for a float and an integer file with analog samples and every corruption of
    /// them by a flipped byte or a cut.
    #[test]
    fn a_file_read_in_pieces_reads_as_it_does_whole() {
        use crate::source::Pieces;
        let float = encode(&sample()).unwrap();
        let corpus = include_bytes!("../../../fuzz/corpus/c3d/small.c3d");
        for file in [&float[..], &corpus[..]] {
            let mut variants = vec![file.to_vec()];
            for at in (0..file.len()).step_by(3) {
                let mut flipped = file.to_vec();
                flipped[at] ^= 0x5A;
                variants.push(flipped);
                variants.push(file[..at].to_vec());
            }
            for bytes in &variants {
                let whole = parse(bytes);
                for piece in [1, 40, 1 << 20] {
                    assert_eq!(parse_from(&Pieces(bytes, piece)), whole, "piece {piece}");
                }
            }
            assert!(parse(file).is_ok());
        }
    }

    #[test]
    fn frame_numbers_past_u16_go_through_trial() {
        let mut c = sample();
        c.first_frame = 70_000;
        let back = parse(&encode(&c).unwrap()).unwrap();
        assert_eq!((back.first_frame, back.frames), (70_000, 3));
    }

    #[test]
    fn many_labels_span_several_parameters() {
        let n = 300;
        let c = C3d {
            frames: 1,
            points: n,
            first_frame: 1,
            rate: 100.0,
            scale: -1.0,
            units: "m".into(),
            labels: (0..n).map(|i| format!("M{i}")).collect(),
            model_outputs: (0..n)
                .map(|i| (i % 7 == 3).then(|| ["ANGLES", "POWERS"][i % 2].to_string()))
                .collect(),
            positions: vec![1.0; 3 * n],
            residuals: vec![1.0; n],
            cameras: vec![0; n],
            notes: Vec::new(),
        };
        assert_eq!(parse(&encode(&c).unwrap()).unwrap(), c);
    }

    #[test]
    fn model_outputs_are_told_from_markers() {
        let mut c = sample();
        c.labels.push("LKneeAngles".into());
        c.labels.push("LQuad".into());
        c.points = 4;
        c.positions = (0..36).map(|v| v as f32).collect();
        c.residuals = vec![0.0; 12];
        c.cameras = vec![0; 12];
        c.model_outputs = vec![None, None, Some("ANGLES".into()), Some("MUSCLES".into())];
        let bytes = encode(&c).unwrap();
        let back = parse(&bytes).unwrap();
        assert_eq!(back, c);
        assert_eq!(back.markers(), vec![0, 1]);
        // MUSCLES is not a usual list: readers find it through TYPE_GROUPS, which pairs it
        // with its type. Without that entry it is a parameter like any other.
        let at = bytes.windows(11).position(|w| w == b"TYPE_GROUPS").unwrap();
        let mut plain = bytes.clone();
        plain[at..at + 11].copy_from_slice(b"TYPE_GROUPX");
        let back = parse(&plain).unwrap();
        assert_eq!(back.model_outputs[3], None);
        assert_eq!(back.model_outputs[2].as_deref(), Some("ANGLES"));
        // A list named as one of the parameters doma writes is refused.
        c.model_outputs[3] = Some("labels2".into());
        assert!(
            encode(&c)
                .unwrap_err()
                .contains("cannot list model outputs")
        );
        c.model_outputs.pop();
        assert!(encode(&c).unwrap_err().contains("point kinds"));
    }
}

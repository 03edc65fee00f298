//! Files whose header and parameters say different things, as writers make them: the
//! frame count past 16 bits by each vendor's convention, a header that disagrees with the
//! parameters on the frame layout, a float file with a positive `POINT:SCALE`, NaN in
//! the residual word or the coordinates. Each is made byte by byte here.

use super::write::Section;
use super::{PointEdit, parse, patch};

/// How a test file states what it holds.
struct Craft {
    frames: usize,
    points: usize,
    /// `POINT:USED`.
    used: u16,
    /// The analog words per frame the data hold (zeros).
    analog: usize,
    /// Header words (1-based) set over the plain ones.
    header: Vec<(usize, u16)>,
    /// The header's scale (the parameters' is in `params`).
    header_scale: f32,
    /// The parameters beside `POINT:USED`, `SCALE`, `RATE` (groups 1 POINT, 2 ANALOG,
    /// 3 TRIAL).
    params: fn(&mut Section),
    /// The residual word of frame `t`, point `i`.
    residual: fn(usize, usize) -> f32,
}

/// The coordinates of frame `t`, point `i`: distinct and never the origin.
fn truth(t: usize, i: usize) -> [f32; 3] {
    [
        t as f32 * 0.5 + 1.0,
        i as f32 + 2.0,
        (t % 97) as f32 - 300.0,
    ]
}

impl Craft {
    fn new(frames: usize, points: usize, params: fn(&mut Section)) -> Self {
        Craft {
            frames,
            points,
            used: points as u16,
            analog: 0,
            header: Vec::new(),
            header_scale: -0.1,
            params,
            residual: |_, _| 1.0,
        }
    }

    /// The file: an Intel float file (floats whatever the scales say).
    fn bytes(&self) -> Vec<u8> {
        let mut s = Section {
            bytes: vec![1, 0x50, 0, 84],
            last_offset: None,
        };
        s.group(1, "POINT");
        s.group(2, "ANALOG");
        s.group(3, "TRIAL");
        s.i16s(1, "USED", &[self.used]);
        s.f32(1, "RATE", 100.0);
        (self.params)(&mut s);
        let at = s.last_offset.unwrap();
        s.bytes[at..at + 2].copy_from_slice(&0u16.to_le_bytes());
        let blocks = s.bytes.len().div_ceil(512);
        s.bytes.resize(blocks * 512, 0);
        s.bytes[2] = blocks as u8;
        let mut out = vec![0u8; 512];
        out[0] = 2;
        out[1] = 0x50;
        let last = self.frames.min(u16::MAX as usize) as u16;
        let mut words = vec![(2, self.points as u16), (3, self.analog as u16), (4, 1)];
        words.extend([(5, last), (9, 2 + blocks as u16), (10, 1)]);
        words.extend(self.header.iter().copied());
        for (w, v) in words {
            out[2 * (w - 1)..2 * w].copy_from_slice(&v.to_le_bytes());
        }
        out[12..16].copy_from_slice(&self.header_scale.to_le_bytes());
        out[20..24].copy_from_slice(&100f32.to_le_bytes());
        out.extend_from_slice(&s.bytes);
        for t in 0..self.frames {
            for i in 0..self.points {
                for v in truth(t, i) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
                out.extend_from_slice(&(self.residual)(t, i).to_le_bytes());
            }
            out.resize(out.len() + 4 * self.analog, 0);
        }
        out.resize(out.len().div_ceil(512) * 512, 0);
        out
    }
}

fn float_scale(s: &mut Section) {
    s.f32(1, "SCALE", -0.1);
}

fn trial(s: &mut Section, first: u32, last: u32) {
    let words = |f: u32| [(f & 0xffff) as u16, (f >> 16) as u16];
    s.i16s(3, "ACTUAL_START_FIELD", &words(first));
    s.i16s(3, "ACTUAL_END_FIELD", &words(last));
}

/// Every frame of `bytes` read, each point where it was written; a point of the last
/// frame patched and read back.
fn reads_whole(bytes: &[u8], frames: usize, points: usize) {
    let c = parse(bytes).unwrap();
    assert_eq!((c.frames, c.points), (frames, points));
    for t in [0, 65_534, 65_535, frames - 1] {
        for i in 0..points {
            let e = t * points + i;
            assert_eq!(&c.positions[3 * e..3 * e + 3], &truth(t, i), "frame {t}");
        }
    }
    let edit = PointEdit {
        frame: frames - 1,
        point: points - 1,
        position: [7.0, 8.0, 9.0],
        residual: 0.0,
        cameras: 0,
    };
    let back = parse(&patch(bytes, &[edit]).unwrap()).unwrap();
    let e = frames * points - 1;
    assert_eq!(&back.positions[3 * e..3 * e + 3], &[7.0, 8.0, 9.0]);
    assert_eq!(back.residuals[e], 0.0);
}

#[test]
fn a_count_past_16_bits_is_read_by_every_convention() {
    for frames in [65_536, 70_000] {
        // POINT:FRAMES as a float, as c3d.org recommends.
        let mut c = Craft::new(frames, 2, |s| {
            float_scale(s);
            s.f32(1, "FRAMES", 70_000.0);
        });
        if frames == 70_000 {
            reads_whole(&c.bytes(), frames, 2);
        }
        // POINT:FRAMES full, the count in POINT:LONG_FRAMES (C-Motion's Visual3D).
        c.params = |s| {
            float_scale(s);
            s.i16s(1, "FRAMES", &[65_535]);
            s.f32(1, "LONG_FRAMES", 65_536.0);
        };
        if frames == 65_536 {
            reads_whole(&c.bytes(), frames, 2);
        }
        // The TRIAL range (Vicon's), from frame 1.
        c.params = |s| {
            float_scale(s);
            s.i16s(1, "FRAMES", &[65_535]);
            trial(s, 1, 70_000);
        };
        if frames == 70_000 {
            reads_whole(&c.bytes(), frames, 2);
        }
        // No longer count stated (ezc3d writes so): the file's length, less the padding.
        c.params = |s| {
            float_scale(s);
            s.i16s(1, "FRAMES", &[65_535]);
        };
        let bytes = c.bytes();
        reads_whole(&bytes, frames, 2);
        assert!(parse(&bytes).unwrap().notes[0].contains(&format!("holds {frames}")));
    }
}

#[test]
fn counts_that_disagree_are_refused_naming_both() {
    let c = Craft::new(70_000, 1, |s| {
        float_scale(s);
        s.i16s(1, "FRAMES", &[65_535]);
        s.f32(1, "LONG_FRAMES", 70_000.0);
        trial(s, 1, 69_000);
    });
    let e = parse(&c.bytes()).unwrap_err();
    assert!(e.contains("70000") && e.contains("69000"), "{e}");
}

#[test]
fn the_writer_states_a_long_count_for_every_reader() {
    let n = 70_000;
    let c = super::C3d {
        frames: n,
        points: 1,
        first_frame: 1,
        rate: 120.0,
        scale: -1.0,
        units: "mm".into(),
        labels: vec!["M".into()],
        model_outputs: vec![None],
        positions: (0..3 * n).map(|v| v as f32).collect(),
        residuals: vec![1.0; n],
        cameras: vec![0; n],
        notes: Vec::new(),
    };
    let bytes = super::encode(&c).unwrap();
    for name in [&b"LONG_FRAMES"[..], b"ACTUAL_END_FIELD"] {
        assert!(bytes.windows(name.len()).any(|w| w == name));
    }
    assert_eq!(parse(&bytes).unwrap(), c);
}

#[test]
fn a_header_that_disagrees_on_the_analog_words_is_read_as_the_length_says() {
    // The header says no analog words; ANALOG:USED × ANALOG:RATE / POINT:RATE says 64,
    // which the data hold.
    let mut c = Craft::new(100, 3, |s| {
        float_scale(s);
        s.i16s(1, "FRAMES", &[100]);
        s.i16s(2, "USED", &[4]);
        s.f32(2, "RATE", 1600.0);
    });
    c.analog = 64;
    c.header = vec![(3, 0)];
    let bytes = c.bytes();
    let read = parse(&bytes).unwrap();
    for t in 0..100 {
        for i in 0..3 {
            let e = t * 3 + i;
            assert_eq!(&read.positions[3 * e..3 * e + 3], &truth(t, i));
        }
    }
    assert!(read.present().iter().all(|&p| p));
    assert!(
        read.notes[0].contains("64 analog words"),
        "{:?}",
        read.notes
    );
    // A patch goes where the reader reads.
    let edit = PointEdit {
        frame: 99,
        point: 2,
        position: [1.0, 2.0, 3.0],
        residual: 0.0,
        cameras: 0,
    };
    let back = parse(&patch(&bytes, &[edit]).unwrap()).unwrap();
    assert_eq!(&back.positions[3 * 299..3 * 300], &[1.0, 2.0, 3.0]);
    // Cut to a length that holds neither layout whole: refused, naming both.
    let cut = &bytes[..bytes.len() - 3 * 512];
    let e = parse(cut).unwrap_err();
    assert!(
        e.contains("0 analog words") && e.contains("64 analog words"),
        "{e}"
    );
}

#[test]
fn a_positive_point_scale_on_a_float_file_is_read_as_floats() {
    let mut c = Craft::new(50, 2, |s| {
        s.f32(1, "SCALE", 0.1);
        s.i16s(1, "FRAMES", &[50]);
    });
    c.header_scale = -0.1;
    let read = parse(&c.bytes()).unwrap();
    assert!(read.scale < 0.0);
    assert_eq!(&read.positions[..3], &truth(0, 0));
    assert_eq!(&read.positions[3 * 99..], &truth(49, 1));
    assert!(read.notes[0].contains("as floats"), "{:?}", read.notes);
}

#[test]
fn a_nan_residual_is_a_point_and_nan_coordinates_are_not() {
    let mut c = Craft::new(20, 2, |s| {
        float_scale(s);
        s.i16s(1, "FRAMES", &[20]);
    });
    c.residual = |t, i| if i == 1 && t < 5 { f32::NAN } else { 1.0 };
    let bytes = c.bytes();
    let read = parse(&bytes).unwrap();
    let present = read.present();
    assert!(present.iter().all(|&p| p));
    assert!(read.residuals[1].is_nan() && read.notes.is_empty());
    // Written back as read: the NaN word kept.
    let again = super::encode(&read).unwrap();
    let back = parse(&again).unwrap();
    assert!(back.residuals[1].is_nan() && back.present() == present);
    // NaN coordinates (kineticstoolkit's missing point) are not a point, said once.
    let mut nan = read.clone();
    nan.positions[0] = f32::NAN;
    nan.residuals[0] = 0.0;
    let back = parse(&super::encode(&nan).unwrap()).unwrap();
    assert!(!back.present()[0] && back.present()[1..].iter().all(|&p| p));
    assert_eq!(back.notes.len(), 1, "{:?}", back.notes);
    assert!(back.notes[0].starts_with("1 points have NaN coordinates"));
}

#[test]
fn a_point_count_the_file_cannot_hold_is_refused_before_reading() {
    let mut c = Craft::new(60, 2, |s| {
        float_scale(s);
        s.i16s(1, "FRAMES", &[60]);
    });
    c.header = vec![(2, u16::MAX)];
    let bytes = c.bytes();
    // The parameters say 2 points and the length confirms them: read.
    assert_eq!(parse(&bytes).unwrap().points, 2);
    // POINT:USED claims 65535 too: refused, naming the bytes needed.
    c.used = u16::MAX;
    let e = parse(&c.bytes()).unwrap_err();
    assert!(
        e.starts_with("truncated") && e.contains("65535 points"),
        "{e}"
    );
}

#[test]
fn a_filled_point_is_told_from_a_measured_one_of_residual_zero() {
    let mut c = Craft::new(10, 2, |s| {
        float_scale(s);
        s.i16s(1, "FRAMES", &[10]);
    });
    // Every point measured with residual 0, as many systems write them.
    c.residual = |t, i| if t == 4 && i == 1 { -1.0 } else { 0.0 };
    let bytes = c.bytes();
    let edit = PointEdit {
        frame: 4,
        point: 1,
        position: [1.0, 2.0, 3.0],
        residual: -0.0,
        cameras: 0,
    };
    let back = parse(&patch(&bytes, &[edit]).unwrap()).unwrap();
    let filled: Vec<usize> = (0..20)
        .filter(|&e| back.residuals[e] == 0.0 && back.residuals[e].is_sign_negative())
        .collect();
    assert_eq!(filled, vec![9]);
    assert!(back.present().iter().all(|&p| p));
    // Written again as read, the mark stays.
    let again = parse(&super::encode(&back).unwrap()).unwrap();
    assert!(again.residuals[9].is_sign_negative() && !again.residuals[8].is_sign_negative());
}

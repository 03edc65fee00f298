//! C3D motion-capture files: a real vendor file, round trips through doma's writer, and bad
//! files refused with an error naming the file and the problem. (The Python tests check the
//! reader and the writer against an independent implementation, PyPI's `c3d`.)

use crate::common;

use doma::DomaError;
use doma::data::c3d::{C3d, c3d_tracks, read_c3d, write_c3d};
use doma::data::layout::TrackFile;
use doma::data::sequence::read_tracks;

const RIGHT_KNEE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/mocap/right_knee.c3d");

fn markers() -> C3d {
    C3d {
        frames: 4,
        points: 3,
        first_frame: 12,
        rate: 150.0,
        scale: -0.05,
        units: "mm".into(),
        labels: vec!["LASI".into(), "RASI".into(), "SACR".into()],
        model_outputs: vec![None; 3],
        positions: (0..36).map(|v| 100.0 + v as f32 * 3.5).collect(),
        residuals: vec![
            0.5, 1.0, -1.0, 0.5, 0.0, 0.25, -1.0, -1.0, 2.0, 0.5, 0.5, 0.5,
        ],
        cameras: vec![1, 2, 0, 3, 0, 127, 0, 0, 5, 6, 7, 8],
        notes: Vec::new(),
    }
}

#[test]
fn a_vendor_file_reads_with_its_labels_rate_and_units() {
    let c = read_c3d(RIGHT_KNEE).unwrap();
    assert_eq!((c.frames, c.points, c.first_frame), (922, 73, 100));
    assert_eq!((c.rate, c.units.as_str()), (100.0, "mm"));
    assert_eq!(
        (c.labels[0].as_str(), c.labels[72].as_str()),
        ("HV", "RLEG3")
    );
    assert!(c.present().iter().all(|&p| p), "every marker is measured");
    // Millimetres of a person in a capture volume.
    let (lo, hi) = c
        .positions
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(lo > -5000.0 && hi < 5000.0 && hi - lo > 500.0, "{lo}..{hi}");
    // `doma fit` reads it by its extension, as complete tracks.
    let (tracks, faces) = read_tracks(RIGHT_KNEE.as_ref(), &TrackFile::default()).unwrap();
    assert_eq!((tracks.frames(), tracks.points()), (922, 73));
    assert_eq!(tracks.positions(), &c.positions[..]);
    assert!(faces.is_none());
}

#[test]
fn a_written_file_reads_back_with_its_gaps() {
    let dir = common::scratch("doma-c3d-rt");
    let path = dir.join("m.c3d");
    let c = markers();
    write_c3d(&path, &c).unwrap();
    let back = read_c3d(&path).unwrap();
    assert_eq!(back.positions, c.positions);
    assert_eq!(
        (&back.labels, back.first_frame, back.rate),
        (&c.labels, 12, 150.0)
    );
    assert_eq!(back.cameras, c.cameras);
    for (a, b) in back.residuals.iter().zip(&c.residuals) {
        assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    }
    let tracks = c3d_tracks(back.clone()).unwrap();
    let gaps: Vec<usize> = (0..12).filter(|&e| !tracks.observed()[e]).collect();
    assert_eq!(gaps, vec![2, 6, 7]);
    // A vendor file through the writer reads as the same markers.
    let vendor = read_c3d(RIGHT_KNEE).unwrap();
    let again = dir.join("again.c3d");
    write_c3d(&again, &vendor).unwrap();
    let back = read_c3d(&again).unwrap();
    assert_eq!(back.positions, vendor.positions);
    assert_eq!(back.labels, vendor.labels);
    assert_eq!(back.present(), vendor.present());
}

#[test]
fn bad_files_are_refused_naming_the_file() {
    let dir = common::scratch("doma-c3d-bad");
    let good = std::fs::read(RIGHT_KNEE).unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.c3d", vec![], "truncated"),
        ("short.c3d", good[..good.len() / 2].to_vec(), "truncated"),
        ("text.c3d", b"x y z\n".repeat(200), "not a C3D"),
        (
            "proc.c3d",
            {
                let mut b = good.clone();
                b[512 + 3] = 0;
                b
            },
            "processor",
        ),
    ];
    for (name, bytes, reason) in cases {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        match read_tracks(&path, &TrackFile::default()) {
            Err(DomaError::Malformed { path: p, reason: r }) => {
                assert_eq!(p, path);
                assert!(r.contains(reason), "{name}: {r}");
            }
            other => panic!("{name}: {other:?}"),
        }
    }
    // A NaN coordinate is a missing point (kineticstoolkit writes them so), said once.
    let mut c = markers();
    c.positions[3 * 4 + 1] = f32::NAN;
    let path = dir.join("nan.c3d");
    write_c3d(&path, &c).unwrap();
    let (tracks, _) = read_tracks(&path, &TrackFile::default()).unwrap();
    let mut expected = c.present();
    expected[4] = false;
    assert_eq!(tracks.observed(), &expected[..]);
    let read = doma::data::sequence::read_points(&path, &TrackFile::default()).unwrap();
    assert_eq!(read.notes.len(), 1, "{:?}", read.notes);
    assert!(read.notes[0].contains("1 points have NaN coordinates"));
    // Tracker options do not apply to a C3D file.
    let file = TrackFile {
        count_hidden: true,
        ..TrackFile::default()
    };
    assert!(matches!(
        read_tracks(RIGHT_KNEE.as_ref(), &file),
        Err(DomaError::Usage(_))
    ));
}

//! The `.traj` format: round trips, the shipped real sequence, and every kind of bad file
//! refused with an error naming the file and the problem.

use crate::common;

use doma::DomaError;
use doma::data::Trajectories;
use doma::data::traj::{encode_traj, parse_traj, read_traj, write_traj};

fn temp_dir(tag: &str) -> common::Scratch {
    common::scratch(&format!("doma-traj-{tag}"))
}

fn sample() -> Trajectories {
    // 3 frames × 4 points with distinct, exactly representable values.
    let positions = (0..36).map(|i| i as f32 * 0.25 - 4.0).collect();
    Trajectories::new(3, 4, positions).unwrap()
}

fn header(frames: u32, points: u32) -> Vec<u8> {
    let mut b = b"TRAJ".to_vec();
    for v in [1u32, frames, points] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}

#[test]
fn a_file_round_trips_bit_exactly() {
    let dir = temp_dir("rt");
    let path = dir.join("a.traj");
    let data = sample();
    write_traj(&path, &data).unwrap();
    assert_eq!(std::fs::metadata(&path).unwrap().len(), 16 + 12 * 3 * 4);
    assert_eq!(read_traj(&path).unwrap(), data);
    // No temporary file is left beside it.
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("a.traj")]);
}

#[test]
fn the_layout_is_the_documented_one() {
    let bytes = encode_traj(&sample()).unwrap();
    assert_eq!(&bytes[0..4], b"TRAJ");
    assert_eq!(bytes[4..8], 1u32.to_le_bytes());
    assert_eq!(bytes[8..12], 3u32.to_le_bytes());
    assert_eq!(bytes[12..16], 4u32.to_le_bytes());
    // Frame 1, point 2, y = value index 1·12 + 2·3 + 1 = 19.
    let at = 16 + 4 * 19;
    assert_eq!(bytes[at..at + 4], (19.0f32 * 0.25 - 4.0).to_le_bytes());
}

#[test]
fn the_shipped_faerie_sequence_reads() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    let data = read_traj(path).unwrap();
    assert_eq!((data.frames(), data.points()), (198, 366));
    // About 52 Quake units tall, Z up (data/README.md).
    let z: Vec<f32> = data.frame(0).iter().skip(2).step_by(3).copied().collect();
    let height =
        z.iter().cloned().fold(f32::MIN, f32::max) - z.iter().cloned().fold(f32::MAX, f32::min);
    assert!((40.0..65.0).contains(&height), "height {height}");
}

#[test]
fn bad_bytes_are_refused_with_the_reason() {
    let good = encode_traj(&sample()).unwrap();
    let mut nan = good.clone();
    nan[16 + 4 * 17..16 + 4 * 18].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut inf = good.clone();
    inf[16..20].copy_from_slice(&f32::INFINITY.to_le_bytes());
    let mut version = good.clone();
    version[4..8].copy_from_slice(&2u32.to_le_bytes());
    let mut huge = header(u32::MAX, u32::MAX);
    huge.extend_from_slice(&[0; 12]);
    let mut large = header(100_000, 100_000);
    large.extend_from_slice(&[0; 12]);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty file", vec![], "truncated"),
        ("short header", good[..10].to_vec(), "truncated"),
        (
            "wrong magic",
            [b"TRAX".as_slice(), &good[4..]].concat(),
            "magic",
        ),
        ("wrong version", version, "version 2"),
        ("zero frames", header(0, 4), "empty sequence"),
        ("zero points", header(3, 0), "empty sequence"),
        (
            "truncated body",
            good[..good.len() - 1].to_vec(),
            "truncated",
        ),
        (
            "oversized body",
            [good.as_slice(), &[0; 4]].concat(),
            "oversized",
        ),
        ("counts larger than the file", large, "need"),
        ("counts that overflow", huge, "overflows"),
        ("NaN coordinate", nan, "NaN"),
        ("infinite coordinate", inf, "inf"),
    ];
    for (what, bytes, needle) in cases {
        let err = parse_traj(&bytes).expect_err(what);
        assert!(
            err.contains(needle),
            "{what}: `{err}` does not say `{needle}`"
        );
    }
}

#[test]
fn file_errors_name_the_file() {
    let dir = temp_dir("bad");
    let path = dir.join("broken.traj");
    std::fs::write(&path, b"TRAJ\x01\x00").unwrap();
    let err = read_traj(&path).unwrap_err();
    assert!(matches!(err, DomaError::Malformed { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains("broken.traj") && msg.contains("truncated"),
        "{msg}"
    );

    let missing = dir.join("missing.traj");
    let msg = read_traj(&missing).unwrap_err().to_string();
    assert!(msg.contains("missing.traj"), "{msg}");

    let unwritable = dir.join("no-such-folder").join("out.traj");
    let msg = write_traj(&unwritable, &sample()).unwrap_err().to_string();
    assert!(msg.contains("out.traj"), "{msg}");
}

//! `.npy` / `.npz`: round trips, a NumPy-style compressed zip64 archive, hand-built headers
//! (big-endian, Fortran order, integers), and every kind of bad file refused with an error
//! naming the file.

use crate::common;
use std::path::Path;

use doma::DomaError;
use doma::data::Trajectories;
use doma::data::npy::{
    encode_npy, encode_npz, parse_npy, parse_npz, read_npy_trajectories, read_npz,
    read_npz_trajectories, write_npy_trajectories, write_npz,
};

fn temp_dir(tag: &str) -> common::Scratch {
    common::scratch(&format!("doma-npy-{tag}"))
}

fn sample() -> Trajectories {
    let positions = (0..2 * 5 * 3).map(|i| i as f32 * 0.125 - 1.0).collect();
    Trajectories::new(2, 5, positions).unwrap()
}

/// A version-1 `.npy` with the given header dict and payload.
fn npy(dict: &str, payload: &[u8]) -> Vec<u8> {
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    b.extend_from_slice(dict.as_bytes());
    b.extend_from_slice(payload);
    b
}

fn malformed_reason(path: &Path, result: doma::Result<Trajectories>) -> String {
    match result {
        Err(DomaError::Malformed { path: p, reason }) => {
            assert_eq!(p, path);
            reason
        }
        other => panic!("expected Malformed, got {other:?}"),
    }
}

#[test]
fn npy_round_trips_trajectories_bit_exactly() {
    let dir = temp_dir("rt");
    let path = dir.join("a.npy");
    write_npy_trajectories(&path, &sample()).unwrap();
    assert_eq!(read_npy_trajectories(&path).unwrap(), sample());
    let bytes = std::fs::read(&path).unwrap();
    // NumPy aligns the data to 64 bytes.
    assert_eq!((bytes.len() - 4 * 30) % 64, 0);
}

#[test]
fn npz_round_trips_and_names_its_members() {
    let dir = temp_dir("npz");
    let path = dir.join("a.npz");
    let data = sample();
    let ids = [1.0f32, 2.0, 3.0];
    write_npz(
        &path,
        &[("train", &[2, 5, 3], data.positions()), ("ids", &[3], &ids)],
    )
    .unwrap();
    let members = read_npz(&path).unwrap();
    assert_eq!(members[0].0, "train");
    assert_eq!(members[1].1.data, vec![1.0, 2.0, 3.0]);
    assert_eq!(read_npz_trajectories(&path, Some("train")).unwrap(), data);
    // Two members and no name: the error lists them.
    let reason = malformed_reason(&path, read_npz_trajectories(&path, None));
    assert!(
        reason.contains("train") && reason.contains("ids"),
        "{reason}"
    );
    let reason = malformed_reason(&path, read_npz_trajectories(&path, Some("test")));
    assert!(reason.contains("no member \"test\""), "{reason}");
}

#[test]
fn a_numpy_style_compressed_zip64_archive_is_read() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/deflated_zip64.npz");
    let members = read_npz(&path).unwrap();
    assert_eq!(members.len(), 2);
    assert_eq!(members[0].0, "points");
    assert_eq!(members[0].1.shape, vec![2, 3, 3]);
    let expected: Vec<f32> = (0..18).map(|k| k as f32 * 0.5 - 2.0).collect();
    assert_eq!(members[0].1.data, expected);
    assert_eq!(members[1].1.data, vec![-1.0, 0.0, 1.0, 2.0]);
    let t = read_npz_trajectories(&path, Some("points")).unwrap();
    assert_eq!((t.frames(), t.points()), (2, 3));
}

#[test]
fn big_endian_fortran_order_and_integer_arrays_are_decoded() {
    // [[1, 2, 3], [4, 5, 6]] as big-endian f8, stored column-major.
    let mut payload = Vec::new();
    for v in [1.0f64, 4.0, 2.0, 5.0, 3.0, 6.0] {
        payload.extend_from_slice(&v.to_be_bytes());
    }
    let a = parse_npy(&npy(
        "{'descr': '>f8', 'fortran_order': True, 'shape': (2, 3), }\n",
        &payload,
    ))
    .unwrap();
    assert_eq!(a.shape, vec![2, 3]);
    assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    let mut ints = Vec::new();
    for v in [-7i16, 300] {
        ints.extend_from_slice(&v.to_le_bytes());
    }
    let b = parse_npy(&npy(
        "{'descr': '<i2', 'fortran_order': False, 'shape': (2,), }\n",
        &ints,
    ))
    .unwrap();
    assert_eq!(b.data, vec![-7.0, 300.0]);
    // f32 as encode_npy writes it.
    let c = parse_npy(&encode_npy(&[3], &[0.5, -1.5, 2.0])).unwrap();
    assert_eq!(c.data, vec![0.5, -1.5, 2.0]);
}

/// Each kind of defect, with a word the message must contain.
#[test]
fn every_kind_of_bad_npy_is_refused() {
    let good = encode_npy(&[1, 2, 3], &[0.0; 6]);
    let f4 =
        |shape: &str| format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}\n");
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("tiny", b"\x93NUM".to_vec(), "truncated"),
        ("truncated", good[..good.len() - 4].to_vec(), "truncated"),
        (
            "oversized",
            [good.clone(), vec![0; 4]].concat(),
            "oversized",
        ),
        (
            "magic",
            [b"\x93NUMPX".as_slice(), &good[6..]].concat(),
            "magic",
        ),
        (
            "version",
            [&good[..6], &[9, 0], &good[8..]].concat(),
            "version",
        ),
        (
            "header length",
            [&good[..8], &[0xff, 0x7f], &good[10..]].concat(),
            "truncated",
        ),
        (
            "dtype",
            npy(
                "{'descr': '<c16', 'fortran_order': False, 'shape': (1,), }\n",
                &[0; 16],
            ),
            "dtype",
        ),
        (
            "no shape",
            npy("{'descr': '<f4', 'fortran_order': False, }\n", &[]),
            "shape",
        ),
        ("bad shape", npy(&f4("(2, x)"), &[]), "dimension"),
        (
            "overflow",
            npy(&f4("(18446744073709551615, 2)"), &[]),
            "overflows",
        ),
        (
            "order",
            npy(
                "{'descr': '<f4', 'fortran_order': Maybe, 'shape': (1,), }\n",
                &[0; 4],
            ),
            "fortran_order",
        ),
    ];
    for (name, bytes, word) in cases {
        let reason = parse_npy(&bytes).expect_err(name);
        assert!(reason.contains(word), "{name}: {reason}");
    }
}

#[test]
fn npy_with_wrong_shape_or_nan_is_refused_naming_the_file() {
    let dir = temp_dir("bad");
    let path = dir.join("shape.npy");
    std::fs::write(&path, encode_npy(&[4, 2], &[0.0; 8])).unwrap();
    let reason = malformed_reason(&path, read_npy_trajectories(&path));
    assert!(reason.contains("[4, 2]"), "{reason}");
    let path = dir.join("nan.npy");
    let mut v = [0.0f32; 6];
    v[4] = f32::NAN;
    std::fs::write(&path, encode_npy(&[1, 2, 3], &v)).unwrap();
    let reason = malformed_reason(&path, read_npy_trajectories(&path));
    assert!(
        reason.contains("point 1") && reason.contains("NaN"),
        "{reason}"
    );
    // A missing file is an I/O error naming it.
    let missing = dir.join("missing.npy");
    match read_npy_trajectories(&missing) {
        Err(DomaError::Io { path, .. }) => assert_eq!(path, missing),
        other => panic!("{other:?}"),
    }
}

#[test]
fn every_kind_of_bad_npz_is_refused() {
    let good = encode_npz(&[("a", &[1, 3], &[1.0, 2.0, 3.0])]);
    // The stored payload starts after the 30-byte local header and "a.npy".
    let mut corrupt = good.clone();
    let last_value = 30 + 5 + encode_npy(&[1, 3], &[0.0; 3]).len() - 1;
    corrupt[last_value] ^= 0x40;
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", vec![], "truncated"),
        ("not zip", vec![7; 100], "not a .npz"),
        ("truncated", good[..good.len() - 10].to_vec(), "truncated"),
        (
            "cut member",
            [&good[..40], &good[good.len() - 80..]].concat(),
            "zip",
        ),
        ("crc", corrupt, "CRC"),
    ];
    for (name, bytes, word) in cases {
        let reason = parse_npz(&bytes).expect_err(name);
        assert!(reason.contains(word), "{name}: {reason}");
    }
    // A member that is not a valid .npy names the member.
    let mut inner = good.clone();
    inner[30 + 5] = b'X'; // the member's magic
    // Recompute nothing: the CRC check fires first, which is also a clear refusal.
    assert!(parse_npz(&inner).is_err());
}

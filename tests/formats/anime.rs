//! DeformingThings4D `.anime`: round trips on files we write (the dataset cannot be
//! downloaded here), the documented layout, and bad files refused with the reason.

use crate::common;
use doma::data::Trajectories;
use doma::data::anime::{AnimatedMesh, encode_anime, parse_anime, read_anime, write_anime};

/// A tetrahedron over 3 frames, with exactly representable coordinates so that the
/// offset encoding round-trips bit-exactly.
fn tetra() -> AnimatedMesh {
    let base = [
        0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0f32,
    ];
    let mut positions = base.to_vec();
    for k in 1..3 {
        positions.extend(
            base.iter()
                .enumerate()
                .map(|(i, v)| v + 0.25 * k as f32 * (i % 3) as f32),
        );
    }
    AnimatedMesh {
        trajectories: Trajectories::new(3, 4, positions).unwrap(),
        faces: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    }
}

fn words(bytes: &[u8]) -> Vec<[u8; 4]> {
    bytes
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect()
}

#[test]
fn a_mesh_round_trips() {
    let dir = common::scratch("doma-anime");
    let path = dir.join("tetra.anime");
    let mesh = tetra();
    write_anime(&path, &mesh).unwrap();
    assert_eq!(read_anime(&path).unwrap(), mesh);
}

#[test]
fn the_layout_is_the_loaders() {
    let bytes = encode_anime(&tetra()).unwrap();
    let w = words(&bytes);
    assert_eq!(bytes.len(), 12 + 4 * 12 + 4 * 12 + 2 * 4 * 12);
    assert_eq!(
        [w[0], w[1], w[2]],
        [3i32.to_le_bytes(), 4i32.to_le_bytes(), 4i32.to_le_bytes()]
    );
    // Base vertex 1 is (1, 0, 0).
    assert_eq!(w[3 + 3], 1.0f32.to_le_bytes());
    // Face 0 = (0, 2, 1).
    assert_eq!(w[15 + 1], 2i32.to_le_bytes());
    // Offset of frame 2, vertex 3, z: 0.25 · 2 · 2 = 1.0.
    assert_eq!(w[27 + 12 + 3 * 3 + 2], 1.0f32.to_le_bytes());
}

#[test]
fn bad_files_are_refused_with_the_reason() {
    let good = encode_anime(&tetra()).unwrap();
    let patch = |word: usize, v: [u8; 4]| {
        let mut b = good.clone();
        b[4 * word..4 * word + 4].copy_from_slice(&v);
        b
    };
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", vec![], "truncated"),
        ("short header", good[..8].to_vec(), "truncated"),
        (
            "zero frames",
            patch(0, 0i32.to_le_bytes()),
            "frame count is 0",
        ),
        (
            "negative vertices",
            patch(1, (-4i32).to_le_bytes()),
            "vertex count is -4",
        ),
        ("truncated", good[..good.len() - 2].to_vec(), "truncated"),
        (
            "oversized",
            [good.as_slice(), &[0; 4]].concat(),
            "oversized",
        ),
        ("wrong triangle count", patch(2, 5i32.to_le_bytes()), "need"),
        (
            "face index too large",
            patch(15, 4i32.to_le_bytes()),
            "vertex 4",
        ),
        (
            "negative face index",
            patch(16, (-1i32).to_le_bytes()),
            "vertex -1",
        ),
        ("NaN base vertex", patch(4, f32::NAN.to_le_bytes()), "NaN"),
        (
            "infinite offset",
            patch(30, f32::INFINITY.to_le_bytes()),
            "inf",
        ),
        ("huge counts", patch(1, i32::MAX.to_le_bytes()), "need"),
    ];
    for (what, bytes, needle) in cases {
        let err = parse_anime(&bytes).expect_err(what);
        assert!(
            err.contains(needle),
            "{what}: `{err}` does not say `{needle}`"
        );
    }
}

#[test]
fn file_errors_name_the_file() {
    let dir = common::scratch("doma-anime-bad");
    let path = dir.join("cut.anime");
    std::fs::write(&path, &encode_anime(&tetra()).unwrap()[..20]).unwrap();
    let msg = read_anime(&path).unwrap_err().to_string();
    assert!(
        msg.contains("cut.anime") && msg.contains("truncated"),
        "{msg}"
    );
}

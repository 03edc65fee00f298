//! Meshes: OBJ parsing and writing (vertex order kept), OBJ sequences, bad files, normals,
//! edges, surface sampling, and the mesh metrics (CD, CDN, STD(E), STD(V)) on hand-built
//! meshes with known answers.

use crate::common;
use std::path::PathBuf;

use doma::DomaError;
use doma::data::Trajectories;
use doma::data::mesh::{
    SurfaceSamples, TriMesh, encode_obj, face_areas, parse_obj, read_obj, read_obj_sequence,
    unique_edges, vertex_normals, write_obj, write_obj_sequence,
};
use doma::metrics::{chamfer, chamfer_with_normals, std_edges, std_vertices};

fn temp_dir(tag: &str) -> common::Scratch {
    common::scratch(&format!("doma-mesh-{tag}"))
}

/// A unit square in the z = 0 plane as two counter-clockwise triangles (normal +z).
fn square() -> TriMesh {
    TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap()
}

#[test]
fn obj_keeps_vertex_order_and_triangulates_polygons() {
    // Faces use the vertices out of order, with v/vt/vn corners and a negative index;
    // vertex 4 is unused. tobj would renumber and drop it; the point order must stay.
    let text = "# test\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 5 5 5\nvt 0 0\nvn 0 0 1\n\
                o quad\nf 3/1/1 4/1/1 1/1/1 -4/1/1\ns off\n";
    let mesh = parse_obj(text).unwrap();
    assert_eq!(mesh.vertices.len(), 5);
    assert_eq!(mesh.vertices[4], [5.0, 5.0, 5.0]);
    assert_eq!(mesh.faces, vec![[2, 3, 0], [2, 0, 1]]);
}

#[test]
fn obj_round_trips_with_and_without_normals() {
    let dir = temp_dir("rt");
    let mesh = square();
    let path = dir.join("sq.obj");
    write_obj(&path, &mesh, None).unwrap();
    assert_eq!(read_obj(&path).unwrap(), mesh);
    let normals = vertex_normals(&mesh.vertices, &mesh.faces);
    write_obj(&path, &mesh, Some(&normals)).unwrap();
    assert_eq!(read_obj(&path).unwrap(), mesh);
    assert!(encode_obj(&mesh.vertices, &mesh.faces, Some(&normals)).contains("vn 0 0 1"));
}

#[test]
fn the_shipped_meshes_match_their_trajectories() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data");
    for (name, vertices) in [("md2_faerie", 366), ("cdp_male_wave", 9293)] {
        let mesh = read_obj(root.join(format!("{name}.obj"))).unwrap();
        assert_eq!(mesh.vertices.len(), vertices, "{name}");
        let t = doma::data::traj::read_traj(root.join(format!("{name}.traj"))).unwrap();
        // OBJ vertex i is point i of frame 0 (to the OBJ's 6 printed decimals).
        let f0 = t.frame(0);
        for (i, v) in mesh.vertices.iter().enumerate().step_by(97) {
            for c in 0..3 {
                assert!(
                    (v[c] - f0[3 * i + c]).abs() < 1e-3 * (1.0 + v[c].abs()),
                    "{name} {i}"
                );
            }
        }
    }
}

#[test]
fn every_kind_of_bad_obj_is_refused_naming_the_line() {
    let cases = [
        ("v 0 0\n", "line 1", "three coordinates"),
        ("v 0 0 x\n", "line 1", "bad coordinate"),
        ("v 0 0 NaN\n", "line 1", "not finite"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            "face 0",
            "indexes past",
        ),
        ("v 0 0 0\nf 1 0 1\n", "line 2", "out of range"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "line 3", "three corners"),
        ("v 0 0 0\nf 1 -5 1\n", "line 2", "out of range"),
        ("# nothing\n", "", "no vertices"),
    ];
    for (text, place, word) in cases {
        let reason = parse_obj(text).expect_err(text);
        assert!(
            reason.contains(place) && reason.contains(word),
            "{text:?}: {reason}"
        );
    }
    let dir = temp_dir("bad");
    let path = dir.join("bad.obj");
    std::fs::write(&path, "v 0 0\n").unwrap();
    match read_obj(&path) {
        Err(DomaError::Malformed { path: p, reason }) => {
            assert_eq!(p, path);
            assert!(reason.contains("line 1"));
        }
        other => panic!("{other:?}"),
    }
    std::fs::write(&path, [0xffu8, 0xfe, 0x00]).unwrap();
    assert!(matches!(read_obj(&path), Err(DomaError::Malformed { .. })));
}

#[test]
fn obj_sequences_round_trip_and_refuse_mismatched_frames() {
    let dir = temp_dir("seq");
    let mesh = square();
    let mut positions = mesh.flat_vertices().to_vec();
    positions.extend(mesh.flat_vertices().iter().map(|v| v * 2.0));
    let frames = Trajectories::new(2, 4, positions).unwrap();
    let paths = write_obj_sequence(&dir, &frames, &mesh.faces).unwrap();
    assert_eq!(paths.len(), 2);
    assert!(paths[1].ends_with("frame_0001.obj"));
    let (read, faces) = read_obj_sequence(&dir).unwrap();
    assert_eq!(read, frames);
    assert_eq!(faces, mesh.faces);

    // A third frame with one vertex fewer is refused, naming it.
    let odd = dir.join("frame_0002.obj");
    std::fs::write(&odd, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    match read_obj_sequence(&dir) {
        Err(DomaError::Malformed { path, reason }) => {
            assert_eq!(path, odd);
            assert!(
                reason.contains("3 vertices") && reason.contains("has 4"),
                "{reason}"
            );
        }
        other => panic!("{other:?}"),
    }
    let empty = temp_dir("empty");
    assert!(matches!(
        read_obj_sequence(&empty),
        Err(DomaError::Malformed { .. })
    ));
}

#[test]
fn normals_edges_and_areas_of_hand_built_meshes() {
    let mesh = square();
    for n in vertex_normals(&mesh.vertices, &mesh.faces) {
        assert_eq!(n, [0.0, 0.0, 1.0]);
    }
    assert_eq!(face_areas(&mesh.vertices, &mesh.faces), vec![0.5, 0.5]);
    // Two triangles share the diagonal: 5 unique edges.
    assert_eq!(
        unique_edges(&mesh.faces),
        vec![[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    );
    // A tetrahedron's corner normal points away from the opposite face.
    let tet = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let n = vertex_normals(&tet, &faces);
    let s = 1.0 / 3f32.sqrt();
    for c in 0..3 {
        assert!((n[0][c] + s).abs() < 1e-6, "{:?}", n[0]);
    }
    assert_eq!(unique_edges(&faces).len(), 6);
}

#[test]
fn surface_samples_lie_on_the_faces_in_proportion_to_area() {
    // Triangle 0 has area 0.5, triangle 1 (scaled ×√3 in x) area 1.5: a 1 : 3 split.
    let s3 = 3f32.sqrt();
    let vertices = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [10.0, 0.0, 0.0],
        [10.0 + s3, 0.0, 0.0],
        [10.0, s3, 0.0],
    ];
    let faces = vec![[0, 1, 2], [3, 4, 5]];
    let samples = SurfaceSamples::seeded(&vertices, &faces, 40_000, 7).unwrap();
    let ones = samples.face.iter().filter(|&&f| f == 1).count() as f64 / 40_000.0;
    assert!((ones - 0.75).abs() < 0.01, "{ones}");
    for (p, (&f, w)) in samples
        .points(&vertices, &faces)
        .iter()
        .zip(samples.face.iter().zip(&samples.bary))
    {
        assert!(w.iter().all(|&x| (0.0..=1.0).contains(&x)));
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        let x0 = if f == 0 { 0.0 } else { 10.0 };
        assert!(p[0] >= x0 - 1e-5 && p[1] >= -1e-6 && p[2] == 0.0);
    }
    // Seeded: the same seed gives the same samples.
    assert_eq!(
        samples,
        SurfaceSamples::seeded(&vertices, &faces, 40_000, 7).unwrap()
    );
    // A degenerate mesh cannot be sampled.
    let flat = [[0.0; 3], [0.0; 3], [0.0; 3]];
    assert!(SurfaceSamples::seeded(&flat, &[[0, 1, 2]], 10, 0).is_err());
}

fn grid(shift: [f32; 3]) -> Vec<[f32; 3]> {
    let mut out = Vec::new();
    for i in 0..10 {
        for j in 0..10 {
            for k in 0..10 {
                out.push([
                    i as f32 + shift[0],
                    j as f32 + shift[1],
                    k as f32 + shift[2],
                ]);
            }
        }
    }
    out
}

#[test]
fn chamfer_is_zero_on_itself_and_known_under_a_shift() {
    let a = grid([0.0; 3]);
    assert_eq!(chamfer(&a, &a).unwrap(), 0.0);
    // Spacing 1, shift 0.1: every nearest neighbour is the shifted copy, 0.01 each way.
    let b = grid([0.1, 0.0, 0.0]);
    assert!((chamfer(&a, &b).unwrap() - 0.02).abs() < 1e-6);
    // Normals: equal → 0; perpendicular → 1 per direction.
    let up = vec![[0.0, 0.0, 1.0]; a.len()];
    let side = vec![[1.0, 0.0, 0.0]; a.len()];
    let down = vec![[0.0, 0.0, -1.0]; a.len()];
    let (cd, cdn) = chamfer_with_normals(&a, &up, &b, &down).unwrap();
    assert!((cd - 0.02).abs() < 1e-6);
    assert!(cdn.abs() < 1e-9, "flipped normals count as aligned: {cdn}");
    let (_, cdn) = chamfer_with_normals(&a, &up, &b, &side).unwrap();
    assert!((cdn - 2.0).abs() < 1e-9);
    assert!(chamfer(&a, &[]).is_err());
}

#[test]
fn kd_tree_chamfer_matches_brute_force() {
    let a: Vec<[f32; 3]> = (0..300)
        .map(|i| {
            let t = i as f32;
            [(t * 0.37).sin(), (t * 0.11).cos(), (t * 0.07).sin() * 2.0]
        })
        .collect();
    let b: Vec<[f32; 3]> = (0..200)
        .map(|i| {
            let t = i as f32;
            [(t * 0.23).cos(), (t * 0.41).sin(), (t * 0.05).cos()]
        })
        .collect();
    let one_way = |x: &[[f32; 3]], y: &[[f32; 3]]| {
        x.iter()
            .map(|p| {
                y.iter()
                    .map(|q| (0..3).map(|c| ((p[c] - q[c]) as f64).powi(2)).sum::<f64>())
                    .fold(f64::INFINITY, f64::min)
            })
            .sum::<f64>()
            / x.len() as f64
    };
    let brute = one_way(&a, &b) + one_way(&b, &a);
    assert!((chamfer(&a, &b).unwrap() - brute).abs() < 1e-6 * brute);
}

#[test]
fn std_e_and_std_v_on_hand_built_sequences() {
    // One edge 0–1 of lengths 1, 2, 3 over three frames: unbiased std 1.
    let frames = Trajectories::new(
        3,
        2,
        vec![
            0., 0., 0., 1., 0., 0., 0., 0., 0., 2., 0., 0., 0., 0., 0., 3., 0., 0.,
        ],
    )
    .unwrap();
    assert!((std_edges(&frames, &[[0, 1]]).unwrap() - 1.0).abs() < 1e-12);
    // Vertex 0 stays (std 0); vertex 1 steps 1 then 1: std 0. Mean 0.
    assert!(std_vertices(&frames).unwrap().abs() < 1e-12);
    // Vertex 1 steps 1 then 3: std √2; vertex 0 still 0 → mean √2 / 2.
    let jerky = Trajectories::new(
        3,
        2,
        vec![
            0., 0., 0., 1., 0., 0., 0., 0., 0., 2., 0., 0., 0., 0., 0., 5., 0., 0.,
        ],
    )
    .unwrap();
    assert!((std_vertices(&jerky).unwrap() - 2f64.sqrt() / 2.0).abs() < 1e-12);
    // A rigid motion keeps every edge's length: STD(E) 0.
    let mesh = square();
    let mut positions = Vec::new();
    for k in 0..4 {
        let (s, c) = (k as f32 * 0.3).sin_cos();
        for v in &mesh.vertices {
            positions.extend([
                c * v[0] - s * v[1] + k as f32,
                s * v[0] + c * v[1],
                v[2] + 0.5,
            ]);
        }
    }
    let rigid = Trajectories::new(4, 4, positions).unwrap();
    assert!(std_edges(&rigid, &unique_edges(&mesh.faces)).unwrap() < 1e-6);
    assert!(std_edges(&rigid, &[[0, 9]]).is_err());
    assert!(std_vertices(&Trajectories::new(2, 1, vec![0.0; 6]).unwrap()).is_err());
}

#[test]
fn obj_folders_are_read_in_natural_order() {
    let dir = common::scratch("doma-natural");
    // frame_10 sorts before frame_2 as plain text; its x is 10.
    for k in [1, 2, 10] {
        let obj = format!("v {k} 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n");
        std::fs::write(dir.join(format!("frame_{k}.obj")), obj).unwrap();
    }
    let (t, _) = read_obj_sequence(&dir).unwrap();
    let xs: Vec<f32> = (0..3).map(|k| t.frame(k)[0]).collect();
    assert_eq!(xs, vec![1.0, 2.0, 10.0]);
}

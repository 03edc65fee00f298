//! Seeing the motion, outside the browser: `doma export` writes `.glb` files that the
//! Khronos glTF validator accepts with zero errors (a mesh run, the same coloured by error,
//! a point cloud, a textured mesh), and `doma warp --mesh` carries a textured OBJ with
//! quads, negative indices, groups and a material library through every frame with its
//! UVs intact. Bad input gets one line naming the file.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use doma::data::textured::TexturedMesh;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
pub(crate) const FAERIE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
const FLUID: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/taichi_mpm3d_fluid.traj");
/// A 1×1 PNG.
pub(crate) const PNG: &[u8] = &[
    0x89, 0x50, 0x4E, 0x47, 0x0D, 0x0A, 0x1A, 0x0A, 0x00, 0x00, 0x00, 0x0D, 0x49, 0x48, 0x44, 0x52,
    0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x01, 0x08, 0x06, 0x00, 0x00, 0x00, 0x1F, 0x15, 0xC4,
    0x89, 0x00, 0x00, 0x00, 0x0D, 0x49, 0x44, 0x41, 0x54, 0x78, 0xDA, 0x63, 0xFC, 0xCF, 0xC0, 0xF0,
    0x1F, 0x00, 0x05, 0x05, 0x02, 0x00, 0x5F, 0xC8, 0xF1, 0xD2, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45,
    0x4E, 0x44, 0xAE, 0x42, 0x60, 0x82,
];

fn temp(tag: &str) -> common::Scratch {
    common::scratch(&format!("doma-export-{tag}"))
}

pub(crate) fn doma(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

pub(crate) fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A short fit: the faerie clip (mesh), or the fluid's first frames (points).
pub(crate) fn fitted(dir: &Path, data: &str, frames: &str) -> PathBuf {
    let run = dir.join("run");
    let (code, err) = doma(&[
        "fit",
        data,
        "--frames",
        frames,
        "--iters",
        "3",
        "--quiet",
        "--out",
        s(&run),
    ]);
    assert_eq!(code, Some(0), "{err}");
    run
}

/// A textured OBJ near the faerie (its units): a box of quads in two groups, written with
/// negative (relative) indices, normals, UVs and a material library with a PNG texture.
pub(crate) fn textured_box(dir: &Path) -> PathBuf {
    let (lo, hi) = ([-10.0f32, -8.0, -20.0], [2.0f32, 8.0, 20.0]);
    let corner = |i: usize| {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]
    };
    let quads = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    let mut obj = String::from("# a textured box\nmtllib box.mtl\n");
    for (g, faces) in [("front", &quads[..3]), ("back", &quads[3..])] {
        obj += &format!(
            "g {g}\nusemtl {}\n",
            if g == "front" { "painted" } else { "plain" }
        );
        for q in faces {
            // Each face's own four corners, UVs and normal, then one quad by negative indices.
            for (k, &c) in q.iter().enumerate() {
                let p = corner(c);
                obj += &format!(
                    "v {} {} {}\nvt {} {}\n",
                    p[0],
                    p[1],
                    p[2],
                    (k & 1) as f32,
                    (k >> 1) as f32
                );
            }
            obj += "vn 0 0 1\nf -4/-4/-1 -3/-3/-1 -2/-2/-1 -1/-1/-1\n";
        }
    }
    std::fs::write(dir.join("box.obj"), obj).unwrap();
    std::fs::write(
        dir.join("box.mtl"),
        "newmtl painted\nKd 0.8 0.3 0.2\nmap_Kd tex/paint.png\n\nnewmtl plain\nKd 0.2 0.5 0.9\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    std::fs::write(dir.join("tex/paint.png"), PNG).unwrap();
    dir.join("box.obj")
}

/// The JSON chunk of a `.glb` (glTF 2.0 §4.4: it follows the 12-byte header and its own
/// 8-byte chunk header).
pub(crate) fn glb_json(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..4], b"glTF");
    let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    serde_json::from_slice(&bytes[20..20 + len]).unwrap()
}

/// Runs the Khronos validator on `files`; `None` when it is not installed (skipped).
fn validate(test: &str, files: &[PathBuf]) -> Option<Vec<serde_json::Value>> {
    let tool = Path::new(ROOT).join("tools/gltf");
    let present = tool.join("node_modules/gltf-validator").is_dir()
        && Command::new("node")
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success());
    if !common::tool_or_skip(
        test,
        "node with gltf-validator (npm ci --prefix tools/gltf)",
        present,
    ) {
        return None;
    }
    let out = Command::new("node")
        .arg(tool.join("validate.mjs"))
        .args(files)
        .output()
        .unwrap();
    let reports: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        reports.len(),
        files.len(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(reports)
}

#[test]
fn exported_glb_files_pass_the_khronos_validator() {
    let dir = temp("gltf");
    let mesh_run = fitted(&dir.join("mesh"), FAERIE, "112..120");
    let cloud_run = fitted(&dir.join("cloud"), FLUID, "0..6");
    let tex = textured_box(&dir);
    let masked_run = crate::view::masked_run(&dir);
    let glb = |name: &str| dir.join(name);
    for (run, extra, name) in [
        (
            &masked_run,
            vec!["--up", "z", "--color-by-error"],
            "masked.glb",
        ),
        (&mesh_run, vec![], "mesh.glb"),
        (
            &mesh_run,
            vec!["--color-by-error", "--frames", "2..8"],
            "mesh_error.glb",
        ),
        (&cloud_run, vec!["--color-by-error"], "cloud.glb"),
        (&mesh_run, vec!["--mesh", s(&tex)], "textured.glb"),
    ] {
        let path = glb(name);
        let mut args = vec!["export", s(run), "--gltf", s(&path)];
        args.extend(extra);
        let (code, err) = doma(&args);
        assert_eq!(code, Some(0), "{args:?}: {err}");
    }
    // The document: one morph target per frame, the animation on the weights.
    let doc = glb_json(&glb("mesh.glb"));
    assert_eq!(
        doc["meshes"][0]["primitives"][0]["targets"]
            .as_array()
            .unwrap()
            .len(),
        8
    );
    // Triangles, glTF's default mode, which the writer leaves out.
    assert!(doc["meshes"][0]["primitives"][0]["mode"].is_null());
    assert!(doc["meshes"][0]["primitives"][0]["indices"].is_u64());
    assert_eq!(
        doc["animations"][0]["channels"][0]["target"]["path"],
        "weights"
    );
    // Tracks with gaps: every target recolours the filled points.
    let doc = glb_json(&glb("masked.glb"));
    let targets = doc["meshes"][0]["primitives"][0]["targets"]
        .as_array()
        .unwrap();
    assert!(
        targets
            .iter()
            .all(|t| t["COLOR_0"].is_u64() && t["POSITION"].is_u64())
    );
    assert!(doc["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"].is_u64());
    let files: Vec<PathBuf> = [
        "mesh.glb",
        "mesh_error.glb",
        "cloud.glb",
        "textured.glb",
        "masked.glb",
    ]
    .map(glb)
    .to_vec();
    let Some(reports) = validate("exported_glb_files_pass_the_khronos_validator", &files) else {
        return;
    };
    for r in &reports {
        assert_eq!(r["errors"], 0, "{r}");
    }
    // The textured export embeds its texture.
    let doc = glb_json(&glb("textured.glb"));
    assert_eq!(doc["images"][0]["mimeType"], "image/png");
    assert!(doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"].is_u64());
}

#[test]
fn a_textured_obj_warps_with_its_uvs_and_materials() {
    let dir = temp("warp");
    let run = fitted(&dir, FAERIE, "112..116");
    let tex = textured_box(&dir);
    let out = dir.join("frames");
    let (code, err) = doma(&["warp", s(&run), "--mesh", s(&tex), "--out", s(&out)]);
    assert_eq!(code, Some(0), "{err}");
    let input = TexturedMesh::read(&tex).unwrap();
    // 6 quads in 2 groups, each split by material: 12 triangles over 24 corners.
    assert_eq!(input.vertex_count(), 24);
    assert_eq!(
        input.parts.iter().map(|p| p.triangles.len()).sum::<usize>(),
        12
    );
    assert!(out.join("box.mtl").is_file() && out.join("tex/paint.png").is_file());
    let mut previous: Option<Vec<[f32; 3]>> = None;
    for k in 0..4 {
        let frame = out.join(format!("frame_{k:04}.obj"));
        let text = std::fs::read_to_string(&frame).unwrap();
        assert!(
            text.contains("mtllib box.mtl") && text.contains("usemtl painted"),
            "{text}"
        );
        let read = TexturedMesh::read(&frame).unwrap();
        assert_eq!(read.vertex_count(), 24);
        assert_eq!(read.materials.len(), 2);
        assert_eq!(
            read.materials[0].diffuse_texture.as_deref(),
            Some("tex/paint.png")
        );
        for (a, b) in read.parts.iter().zip(&input.parts) {
            assert_eq!(a.texcoords, b.texcoords, "frame {k}: the UVs changed");
            assert_eq!(a.triangles, b.triangles);
        }
        let positions = read.positions();
        assert!(positions.iter().flatten().all(|c| c.is_finite()));
        if let Some(p) = &previous {
            assert_ne!(p, &positions, "frame {k} did not move");
        }
        previous = Some(positions);
    }
}

#[test]
fn bad_meshes_and_outputs_are_refused_naming_the_file() {
    let dir = temp("bad");
    let run = fitted(&dir, FAERIE, "112..116");
    let tex = textured_box(&dir);
    let broken = dir.join("broken.obj");
    std::fs::write(&broken, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let bad_mtl_obj = dir.join("badmtl.obj");
    std::fs::write(
        &bad_mtl_obj,
        "mtllib bad.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    std::fs::write(dir.join("bad.mtl"), "newmtl x\nKd 1 zero 1\n").unwrap();
    let missing_mtl_obj = dir.join("nomtl.obj");
    std::fs::write(
        &missing_mtl_obj,
        "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let tri = dir.join("tri.obj");
    std::fs::write(&tri, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let glb = dir.join("out.glb");
    for (args, needles) in [
        (
            vec![
                "export",
                s(&run),
                "--gltf",
                s(&glb),
                "--mesh",
                s(&tri),
                "--color-by-error",
            ],
            vec!["tri.obj", "3 vertices", "366 points"],
        ),
        (
            vec![
                "export",
                s(&run),
                "--gltf",
                s(&glb),
                "--mesh",
                s(&tex),
                "--color-by-error",
            ],
            vec!["box.obj"],
        ),
        (
            vec!["export", s(&run), "--gltf", s(&glb), "--mesh", s(&broken)],
            vec!["broken.obj"],
        ),
        (
            vec![
                "warp",
                s(&run),
                "--mesh",
                s(&bad_mtl_obj),
                "--out",
                s(&dir.join("f1")),
            ],
            vec!["bad.mtl"],
        ),
        (
            vec![
                "warp",
                s(&run),
                "--mesh",
                s(&missing_mtl_obj),
                "--out",
                s(&dir.join("f2")),
            ],
            vec!["gone.mtl", "missing"],
        ),
        (
            vec!["export", s(&run), "--gltf", "/nonexistent/dir/out.glb"],
            vec!["/nonexistent/dir"],
        ),
        (
            vec!["export", s(&run), "--gltf", s(&glb), "--frames", "3..9"],
            vec!["frames 3..9"],
        ),
    ] {
        let (code, err) = doma(&args);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: no `{n}` in {err}");
        }
    }
    assert!(!glb.exists(), "a refused export left a file");
}

#[test]
fn the_files_an_obj_names_are_read_from_where_it_says_and_checked() {
    let dir = temp("named");
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n";
    let write = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, text).unwrap();
        path
    };
    // Every `mtllib` is read: a missing second library is refused, naming it.
    write("a.mtl", "newmtl a\nKd 1 0 0\n");
    let two = write(
        "two.obj",
        &format!("mtllib a.mtl\nmtllib gone.mtl\n{tri}usemtl a\nf 1/1 2/2 3/3\n"),
    );
    let err = TexturedMesh::read(&two).unwrap_err().to_string();
    assert!(err.contains("gone.mtl") && err.contains("missing"), "{err}");
    // A `.mtl` in a subfolder names its texture relative to itself.
    write("sub/m.mtl", "newmtl m\nmap_Kd t.png\n");
    std::fs::write(dir.join("sub/t.png"), PNG).unwrap();
    let sub = write(
        "sub.obj",
        &format!("mtllib sub/m.mtl\n{tri}usemtl m\nf 1/1 2/2 3/3\n"),
    );
    let mesh = TexturedMesh::read(&sub).unwrap();
    assert_eq!(
        mesh.materials[0].diffuse_texture.as_deref(),
        Some("sub/t.png")
    );
    let files = mesh.material_files().unwrap();
    assert_eq!(files[1].0, dir.join("sub/t.png").canonicalize().unwrap());
    // Vertices without faces are not "no vertices".
    let bare = write("bare.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
    let err = TexturedMesh::read(&bare).unwrap_err().to_string();
    assert!(err.contains("3 vertices but no faces"), "{err}");
    // A material library past its bound is refused before it is read.
    let big = dir.join("big.mtl");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(64 << 20)
        .unwrap();
    let heavy = write(
        "heavy.obj",
        &format!("mtllib big.mtl\n{tri}f 1/1 2/2 3/3\n"),
    );
    let err = TexturedMesh::read(&heavy).unwrap_err().to_string();
    assert!(err.contains("big.mtl") && err.contains("16 MiB"), "{err}");
}

#[test]
fn a_frame_rate_whose_key_times_overflow_is_refused() {
    let dir = temp("fps");
    let run = fitted(&dir, FAERIE, "112..116");
    let glb = dir.join("out.glb");
    let (code, err) = doma(&["export", s(&run), "--gltf", s(&glb), "--fps", "1e-45"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("--fps"), "{err}");
    assert!(!glb.exists());
}

//! What a file names never reaches outside the folder the user pointed at, and no special
//! file hangs or floods a run. For `doma warp --mesh` and `doma export --mesh`: a texture
//! or a `.mtl` that is a symbolic link to a file outside, a texture inside a linked
//! folder, `..` and an absolute path, each refused with the file and the name, and the
//! file outside never copied or embedded. FIFOs and `/dev/zero` given as a mesh, a config
//! or a manifest are refused at once.

use std::os::unix::fs::symlink;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use crate::export::{FAERIE, PNG, doma, fitted, s, textured_box};

/// The bytes of the file outside the mesh's folder: a valid PNG with a marker after it, so
/// that a copy or an embedding of it can be found.
fn secret() -> Vec<u8> {
    let mut png = PNG.to_vec();
    png.extend_from_slice(b"SECRET-OUTSIDE-THE-MESH-FOLDER");
    png
}

fn contains(haystack: &[u8], needle: &[u8]) -> bool {
    haystack.windows(needle.len()).any(|w| w == needle)
}

/// Every file under `dir` that holds the secret's marker.
fn leaked(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return found;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            found.extend(leaked(&p));
        } else if std::fs::read(&p).is_ok_and(|b| contains(&b, b"SECRET-OUTSIDE")) {
            found.push(p);
        }
    }
    found
}

/// A textured box in `root/mesh/` made hostile by `case`, beside `root/outside/` that holds
/// the secret; returns the OBJ and the name the error must quote.
fn hostile_box(root: &Path, case: &str) -> (PathBuf, &'static str) {
    let mesh = root.join("mesh");
    let outside = root.join("outside");
    std::fs::create_dir_all(&mesh).unwrap();
    std::fs::create_dir_all(outside.join("tex")).unwrap();
    std::fs::write(outside.join("secret.png"), secret()).unwrap();
    std::fs::write(outside.join("tex/paint.png"), secret()).unwrap();
    let obj = textured_box(&mesh);
    let mtl = |map_kd: &str| {
        std::fs::write(
            mesh.join("box.mtl"),
            format!(
                "newmtl painted\nKd 0.8 0.3 0.2\nmap_Kd {map_kd}\n\nnewmtl plain\nKd 0.2 0.5 0.9\n"
            ),
        )
        .unwrap()
    };
    let quoted = match case {
        "linked texture" => {
            std::fs::remove_file(mesh.join("tex/paint.png")).unwrap();
            symlink(outside.join("secret.png"), mesh.join("tex/paint.png")).unwrap();
            "tex/paint.png"
        }
        "linked material library" => {
            std::fs::write(
                outside.join("box.mtl"),
                "newmtl painted\nKd 0.8 0.3 0.2\n\nnewmtl plain\nKd 0.2 0.5 0.9\n",
            )
            .unwrap();
            std::fs::remove_file(mesh.join("box.mtl")).unwrap();
            symlink(outside.join("box.mtl"), mesh.join("box.mtl")).unwrap();
            "box.mtl"
        }
        "linked folder" => {
            std::fs::remove_dir_all(mesh.join("tex")).unwrap();
            symlink(outside.join("tex"), mesh.join("tex")).unwrap();
            "tex/paint.png"
        }
        "dot-dot" => {
            mtl("../outside/secret.png");
            "../outside/secret.png"
        }
        "absolute" => {
            mtl(s(&outside.join("secret.png")));
            "secret.png"
        }
        "linked device" => {
            std::fs::remove_file(mesh.join("tex/paint.png")).unwrap();
            symlink("/dev/zero", mesh.join("tex/paint.png")).unwrap();
            "tex/paint.png"
        }
        other => panic!("no case {other}"),
    };
    (obj, quoted)
}

const CASES: [&str; 6] = [
    "linked texture",
    "linked material library",
    "linked folder",
    "dot-dot",
    "absolute",
    "linked device",
];

#[test]
fn warp_copies_nothing_from_outside_the_meshs_folder() {
    let dir = common::scratch("doma-security-warp");
    let run = fitted(&dir, FAERIE, "112..115");
    for case in CASES {
        let root = dir.join(case.replace(' ', "-"));
        let (obj, quoted) = hostile_box(&root, case);
        let out = root.join("frames");
        let (code, err) = doma(&["warp", s(&run), "--mesh", s(&obj), "--out", s(&out)]);
        assert_eq!(code, Some(1), "{case}: {err}");
        assert!(!err.contains("panicked"), "{case}: {err}");
        assert!(err.contains(quoted), "{case}: no `{quoted}` in {err}");
        assert!(
            err.contains("box."),
            "{case}: the naming file is not named: {err}"
        );
        assert_eq!(
            leaked(&out),
            Vec::<PathBuf>::new(),
            "{case}: copied from outside"
        );
        assert!(
            !out.exists(),
            "{case}: a refused warp left its output folder"
        );
    }
}

#[test]
fn export_embeds_nothing_from_outside_the_meshs_folder() {
    let dir = common::scratch("doma-security-export");
    let run = fitted(&dir, FAERIE, "112..115");
    for case in CASES {
        let root = dir.join(case.replace(' ', "-"));
        let (obj, quoted) = hostile_box(&root, case);
        let glb = root.join("out.glb");
        let (code, err) = doma(&["export", s(&run), "--gltf", s(&glb), "--mesh", s(&obj)]);
        assert_eq!(code, Some(1), "{case}: {err}");
        assert!(err.contains(quoted), "{case}: no `{quoted}` in {err}");
        assert!(!glb.exists(), "{case}: a refused export wrote its file");
    }
    // A texture inside the folder is embedded under its relative name: no machine path.
    let root = dir.join("clean");
    std::fs::create_dir_all(&root).unwrap();
    let obj = textured_box(&root);
    let glb = root.join("out.glb");
    let (code, err) = doma(&["export", s(&run), "--gltf", s(&glb), "--mesh", s(&obj)]);
    assert_eq!(code, Some(0), "{err}");
    let bytes = std::fs::read(&glb).unwrap();
    assert!(
        !contains(&bytes, s(&root).as_bytes()),
        "the .glb holds a machine path"
    );
    assert!(contains(&bytes, b"tex/paint.png"));
}

/// Runs `doma args`, killed after 30 s: a refusal must come at once, not after a read that
/// never ends.
fn refused_in_time(args: &[&str], needle: &str) {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            panic!("{args:?} still running after 30 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
    assert!(err.contains(needle), "{args:?}: no `{needle}` in {err}");
    assert!(err.contains("not a regular file"), "{args:?}: {err}");
}

#[test]
fn fifos_and_devices_as_mesh_config_or_manifest_are_refused_at_once() {
    let dir = common::scratch("doma-security-special");
    let run = fitted(&dir, FAERIE, "112..115");
    let fifo = dir.join("fifo.obj");
    let c = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a valid C string and permission bits.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
    let out = dir.join("frames");
    for special in [s(&fifo), "/dev/zero"] {
        refused_in_time(
            &["warp", s(&run), "--mesh", special, "--out", s(&out)],
            special,
        );
        let glb = dir.join("out.glb");
        refused_in_time(
            &["export", s(&run), "--gltf", s(&glb), "--mesh", special],
            special,
        );
        let page = dir.join("view.html");
        refused_in_time(
            &["view", s(&run), "--out", s(&page), "--mesh", special],
            special,
        );
        let fit = dir.join("fit");
        refused_in_time(
            &["fit", FAERIE, "--config", special, "--out", s(&fit)],
            special,
        );
        refused_in_time(&["batch", special, "--out", s(&dir.join("batch"))], special);
    }
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            files.extend(snapshot(&p));
        } else if let Ok(b) = std::fs::read(&p) {
            files.push((p, b));
        }
    }
    files.sort();
    files
}

#[test]
fn no_writer_replaces_the_run_or_its_data() {
    let dir = common::scratch("doma-nooverwrite");
    let data = dir.join("faerie.traj");
    std::fs::copy(FAERIE, &data).unwrap();
    let run = fitted(&dir, s(&data), "112..116");
    let mesh = dir.join("canonical.obj");
    std::fs::write(&mesh, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    symlink(run.join("config.json"), dir.join("link.glb")).unwrap();
    symlink(&run, dir.join("alias")).unwrap();
    let before = (snapshot(&run), std::fs::read(&data).unwrap());
    let frames = dir.join("frames");
    std::fs::create_dir(&frames).unwrap();
    let first = frames.join("frame_0000.obj");
    std::fs::copy(&mesh, &first).unwrap();
    let cases: Vec<Vec<String>> = vec![
        vec![
            "complete".into(),
            s(&run).into(),
            "--out".into(),
            s(&run.join("config.json")).into(),
        ],
        vec![
            "complete".into(),
            s(&run).into(),
            "--out".into(),
            s(&run.join("model.bpk")).into(),
        ],
        vec![
            "complete".into(),
            s(&run).into(),
            "--out".into(),
            s(&data).into(),
        ],
        vec![
            "complete".into(),
            s(&run).into(),
            "--out".into(),
            s(&dir.join("alias/filled.npz")).into(),
        ],
        vec![
            "view".into(),
            s(&run).into(),
            "--out".into(),
            s(&run.join("report.json")).into(),
        ],
        vec![
            "view".into(),
            s(&run).into(),
            "--out".into(),
            s(&data).into(),
        ],
        vec![
            "export".into(),
            s(&run).into(),
            "--gltf".into(),
            s(&dir.join("link.glb")).into(),
        ],
        vec![
            "warp".into(),
            s(&run).into(),
            "--out".into(),
            s(&run.join("frames")).into(),
        ],
        // A mesh warped into its own folder would replace it with frame 0.
        vec![
            "warp".into(),
            s(&run).into(),
            "--mesh".into(),
            s(&first).into(),
            "--out".into(),
            s(&frames).into(),
        ],
    ];
    for args in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, err) = doma(&args);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        assert!(err.contains("refusing to write there"), "{args:?}: {err}");
    }
    assert_eq!((snapshot(&run), std::fs::read(&data).unwrap()), before);
    assert_eq!(
        std::fs::read(&first).unwrap(),
        std::fs::read(&mesh).unwrap()
    );
}

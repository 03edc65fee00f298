//! Hostile input and concurrent use of the `doma` binary: each case ends with a non-zero
//! exit and one line naming the file and the reason, no panic, no half-made output, and no
//! folder left locked. (The `.npz` bombs are in `npz_bombs.rs`.)

use crate::common;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

const FAERIE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");

fn temp(tag: &str) -> common::Scratch {
    common::scratch(&format!("doma-rel-{tag}"))
}

fn doma(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args(args)
        .output()
        .expect("the binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A refusal: exit 1, no panic, and a message holding every `needle`.
fn refused(args: &[&str], needles: &[&str]) -> String {
    let (code, _, err) = doma(args);
    assert_eq!(code, Some(1), "{args:?}:\n{err}");
    assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: no `{n}` in:\n{err}");
    }
    err
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A short finished run of the faerie clip.
fn finished_run(tag: &str) -> PathBuf {
    let run = temp(tag).join("run");
    fit_clip(Path::new(FAERIE), &run);
    run
}

/// A 2-iteration fit of frames 112..116 of `data` (the faerie's layout) into `run`.
fn fit_clip(data: &Path, run: &Path) {
    let (code, _, err) = doma(&[
        "fit",
        s(data),
        "--frames",
        "112..116",
        "--iters",
        "2",
        "--quiet",
        "--out",
        s(run),
    ]);
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn a_run_folder_has_one_writer_and_sigterm_checkpoints_like_ctrl_c() {
    let lock_dir = temp("lock");
    let run = lock_dir.join("run");
    let child = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args([
            "fit", FAERIE, "--frames", "112..118", "--iters", "100000", "--quiet",
        ])
        .arg("--out")
        .arg(&run)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    for _ in 0..400 {
        if run.join("config.json").exists() {
            break;
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    assert!(run.join("config.json").exists(), "the fit did not start");
    // A second writer of the same folder is refused, naming the folder and the holder.
    let pid = child.id().to_string();
    refused(&["fit", "--resume", s(&run)], &[s(&run), &pid]);
    refused(
        &["fit", FAERIE, "--frames", "112..118", "--out", s(&run)],
        &[s(&run), &pid, ".lock"],
    );
    // SIGTERM (schedulers, `timeout`, `docker stop`): a checkpoint and exit 143.
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: sending a signal to our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(143), "{err}");
    assert!(
        err.contains("--resume") && run.join("resume.ckpt").is_file(),
        "{err}"
    );
    // The lock went with the process: the fit resumes (shortened to end soon).
    let config = run.join("config.json");
    let mut c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&config).unwrap()).unwrap();
    let done: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(run.join("history.json")).unwrap()).unwrap();
    c["fit"]["schedule"]["iterations"] = serde_json::json!(done.len() + 1);
    std::fs::write(&config, c.to_string()).unwrap();
    // A resumed fit keeps its backend.
    refused(
        &["fit", "--resume", s(&run), "--backend", "ndarray"],
        &["--backend", "flex"],
    );
    // A temporary file that a killed writer left behind is cleared by the next writer.
    let stale = run.join(".history.json.tmp4000000000");
    std::fs::write(&stale, b"half").unwrap();
    let (code, _, err) = doma(&["fit", "--resume", s(&run), "--quiet"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!stale.exists(), "the stale temporary file is still there");
}

#[test]
fn oversized_models_are_refused_before_anything_is_allocated_or_written() {
    refused(
        &["synthetic", "--hidden", "200000", "--iters", "1"],
        &["parameters"],
    );
    refused(
        &["mesh-alignment", "--n-hidden", "1000000000", "--iters", "1"],
        &["parameters is over the limit"],
    );
    let dir = temp("huge");
    let config = dir.join("fit.json");
    for model in [
        r#"{"model": {"doma": {"variant": "trans", "shape": {"hidden": 200000}}}}"#,
        r#"{"model": {"doma": {"variant": "trans", "shape": {"n_hidden": 100000}}}}"#,
    ] {
        std::fs::write(&config, model).unwrap();
        let out = dir.join("run");
        refused(
            &["fit", FAERIE, "--out", s(&out), "--config", s(&config)],
            &["fit.json", "parameters"],
        );
        assert!(!out.exists(), "a refused fit left {}", out.display());
    }
}

#[test]
fn a_reference_frame_where_nothing_is_seen_is_refused_before_the_fit() {
    // A PointOdyssey annotation whose frame 5 has no visible point.
    let mut view = common::faerie_tracker_view(112..124).0;
    let n = view.truth.points();
    view.visible[5 * n..6 * n].fill(false);
    let dir = temp("emptyref");
    let (anno, run) = (dir.join("anno.npz"), dir.join("run"));
    view.write(&anno, doma::data::layout::Layout::PointOdyssey)
        .unwrap();
    let args = [
        "fit",
        s(&anno),
        "--reference-frame",
        "5",
        "--iters",
        "1",
        "--drop-unobserved",
        "--out",
        s(&run),
    ];
    refused(&args, &["reference frame 5: no track is observed there"]);
    assert!(!run.exists(), "a refused fit left {}", run.display());
    // Frame 6 sees tracks: the same fit goes on from there.
    let mut args = args;
    args[3] = "6";
    let (code, _, err) = doma(&args);
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn data_behind_a_symlink_keeps_the_links_extension() {
    let dir = temp("link");
    // A download cache or git-annex: the blob has no extension, the link has.
    let blob = dir.join("SHA256-e3b0c44298fc1c14");
    std::fs::copy(FAERIE, &blob).unwrap();
    let link = dir.join("faerie.traj");
    std::os::unix::fs::symlink(&blob, &link).unwrap();
    let run = dir.join("run");
    let (code, _, err) = doma(&[
        "fit",
        s(&link),
        "--frames",
        "112..114",
        "--iters",
        "1",
        "--quiet",
        "--out",
        s(&run),
    ]);
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn a_fifo_is_refused_instead_of_blocking() {
    let dir = temp("fifo");
    let fifo = dir.join("points.traj");
    let c = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a valid C string and permission bits.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
    let started = std::time::Instant::now();
    refused(
        &["fit", s(&fifo), "--out", s(&dir.join("run"))],
        &["points.traj", "not a regular file"],
    );
    assert!(started.elapsed() < Duration::from_secs(30));
}

#[test]
fn run_readers_name_the_broken_file() {
    let run = finished_run("readers");
    // A corrupt history: eval, like info and plot, refuses it and names it.
    let history = run.join("history.json");
    let good = std::fs::read(&history).unwrap();
    std::fs::write(&history, b"[{ broken").unwrap();
    for cmd in ["eval", "info", "plot"] {
        refused(&[cmd, s(&run)], &["history.json"]);
    }
    std::fs::write(&history, good).unwrap();
    // A frame past the end writes no picture at all.
    refused(&["plot", s(&run), "--frames", "999"], &["999"]);
    assert!(!run.join("plots").exists(), "plot wrote before it failed");
}

#[test]
fn a_garbage_model_in_resume_ckpt_names_the_file() {
    let dir = temp("ckpt");
    let run = dir.join("run");
    let child = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args([
            "fit", FAERIE, "--frames", "112..116", "--iters", "100000", "--quiet",
        ])
        .args(["--checkpoint-every", "1", "--out", s(&run)])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    for _ in 0..400 {
        if run.join("resume.ckpt").exists() {
            break;
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    // SAFETY: sending a signal to our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let _ = child.wait_with_output();
    // Keep the framing (magic and lengths), scramble the model part.
    let ckpt = run.join("resume.ckpt");
    let mut bytes = std::fs::read(&ckpt).unwrap();
    let meta_len = u64::from_le_bytes(bytes[8..16].try_into().unwrap()) as usize;
    let model_at = 16 + meta_len + 8;
    for b in &mut bytes[model_at..model_at + 64] {
        *b = 0xA5;
    }
    std::fs::write(&ckpt, &bytes).unwrap();
    refused(&["fit", "--resume", s(&run)], &["resume.ckpt"]);
    refused(&["eval", s(&run)], &["resume.ckpt"]);
}

#[test]
fn json_outputs_that_cannot_be_written_fail_before_any_fit() {
    // Root writes anywhere it may, but nobody creates files in /proc.
    let started = std::time::Instant::now();
    for args in [
        vec![
            "synthetic",
            "--iters",
            "1000",
            "--json",
            "/proc/self/runs.json",
        ],
        vec!["bench", "--json", "/proc/self/bench.json"],
    ] {
        refused(&args, &["/proc/self"]);
    }
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "it fitted first"
    );
}

#[test]
fn fit_runs_any_model_of_the_config_and_checks_its_frames() {
    let dir = temp("models");
    let config = dir.join("fit.json");
    // A frame-indexed model built for 3 frames, on 4: refused, nothing left behind.
    std::fs::write(&config, r#"{"model": {"dpf": {"frames": 3}}}"#).unwrap();
    let out = dir.join("wrong");
    refused(
        &[
            "fit",
            FAERIE,
            "--frames",
            "112..116",
            "--out",
            s(&out),
            "--config",
            s(&config),
        ],
        &["DPF", "3 frames", "4"],
    );
    assert!(!out.exists());
    // The right count fits, and the run folder's tools read it back.
    std::fs::write(
        &config,
        r#"{"model": {"dpf": {"frames": 4, "shape": {"hidden": 16}}}, "schedule": {"iterations": 2}}"#,
    )
    .unwrap();
    let fit = |run: &Path| {
        let (code, _, err) = doma(&[
            "fit",
            FAERIE,
            "--frames",
            "112..116",
            "--quiet",
            "--out",
            s(run),
            "--config",
            s(&config),
        ]);
        assert_eq!(code, Some(0), "{err}");
    };
    let run = dir.join("dpf");
    fit(&run);
    let (code, out, err) = doma(&["info", s(&run)]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("\"DPF\""), "{out}");
    let (code, _, err) = doma(&["eval", s(&run)]);
    assert_eq!(code, Some(0), "{err}");
    // BANMO (at a test's size) through the same paths: fit, info, eval, warp, export.
    std::fs::write(
        &config,
        r#"{"model": {"banmo": {"frames": 4, "code_size": 8, "transform_width": 16, "skin_width": 8}},
            "schedule": {"iterations": 2, "learning_rate": 1e-3}, "jacobian": "autodiff"}"#,
    )
    .unwrap();
    let run = dir.join("banmo");
    fit(&run);
    let (code, out, err) = doma(&["info", s(&run)]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("\"BANMO\""), "{out}");
    let (code, first, err) = doma(&["eval", s(&run)]);
    assert_eq!(code, Some(0), "{err}");
    // eval re-evaluates the model read back from model.bpk: the fit's own report.
    let epe =
        |text: &str| serde_json::from_str::<serde_json::Value>(text).unwrap()["epe_x1e4"].clone();
    let report = std::fs::read_to_string(run.join("report.json")).unwrap();
    assert!(epe(&first).is_number(), "{first}");
    assert_eq!(epe(&first), epe(&report));
    let obj = dir.join("banmo_obj");
    let (code, _, err) = doma(&["warp", s(&run), "--out", s(&obj)]);
    assert_eq!(code, Some(0), "{err}");
    assert!(obj.join("frame_0003.obj").exists());
    let glb = dir.join("banmo.glb");
    let (code, _, err) = doma(&["export", s(&run), "--gltf", s(&glb)]);
    assert_eq!(code, Some(0), "{err}");
    assert!(std::fs::metadata(&glb).unwrap().len() > 0);
}

#[test]
fn a_run_refuses_a_model_or_data_that_its_config_no_longer_describes() {
    let dir = temp("edited");
    let data = dir.join("clip.traj");
    let original = doma::data::traj::read_traj(FAERIE).unwrap();
    doma::data::traj::write_traj(&data, &original).unwrap();
    let run = dir.join("run");
    fit_clip(&data, &run);
    // The run records the reference frame it used and what its data read as.
    let config = run.join("config.json");
    let text = std::fs::read_to_string(&config).unwrap();
    let saved: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(saved["reference_frame"], 0, "{text}");
    assert!(
        saved["data_digest"]
            .as_str()
            .unwrap()
            .starts_with("fnv1a64:")
    );
    // A hidden size edited away from model.bpk's.
    let edited = text.replace("\"hidden\": 128", "\"hidden\": 64");
    assert_ne!(edited, text);
    std::fs::write(&config, &edited).unwrap();
    refused(&["eval", s(&run)], &["model.bpk", "config.json", "shape"]);
    std::fs::write(&config, &text).unwrap();
    assert_eq!(doma(&["eval", s(&run)]).0, Some(0));
    // The data edited in place: one coordinate of one frame of the clip, moved by 1 mm.
    let (t, n) = (original.frames(), original.points());
    let mut moved = original.positions().to_vec();
    moved[3 * (113 * n + 5)] += 1e-3;
    let moved = doma::data::Trajectories::new(t, n, moved).unwrap();
    doma::data::traj::write_traj(&data, &moved).unwrap();
    let out = dir.join("filled.npz");
    for args in [
        vec!["eval", s(&run)],
        vec!["complete", s(&run), "--out", s(&out)],
        vec!["fit", "--resume", s(&run)],
    ] {
        refused(&args, &["clip.traj", "replaced or edited"]);
    }
    assert!(!out.exists());
    // Put back, it reads as before.
    doma::data::traj::write_traj(&data, &original).unwrap();
    assert_eq!(doma(&["eval", s(&run)]).0, Some(0));
}

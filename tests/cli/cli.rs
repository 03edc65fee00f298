//! The `doma` binary: bad flags are refused with a clear message, and a tiny run
//! prints the table and writes one JSON record per run.

use crate::common;
use doma::prelude::*;
use std::process::Command;

fn doma(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args(args)
        .output()
        .expect("the binary runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bad_flags_are_refused_with_a_message() {
    for (args, needle) in [
        (vec!["synthetic", "--iters", "0"], "--iters"),
        (vec!["synthetic", "--iters", "-3"], "--iters"),
        (vec!["synthetic", "--iters", "many"], "--iters"),
        (vec!["synthetic", "--motion", "wobble"], "wobble"),
        (vec!["synthetic", "--recipe", "fastest"], "fastest"),
        (
            vec!["synthetic", "--until-converged", "0"],
            "--until-converged",
        ),
        (vec!["synthetic", "--variant", "bones"], "bones"),
        (vec!["synthetic", "--backend", "cuda"], "cuda"),
        (vec!["synthetic", "--h-weight", "-0.1"], "non-negative"),
        (vec!["synthetic", "--h-weight", "nan"], "non-negative"),
        (vec!["synthetic", "--hidden", "0"], "--hidden"),
        // A model too large names the flag that sized it, not the model's own count.
        (vec!["synthetic", "--hidden", "100000"], "--hidden 100000"),
        (
            vec!["mesh-alignment", "--n-hidden", "1000000000", "--iters", "1"],
            "--n-hidden 1000000000",
        ),
        (
            vec!["fill", "no-such-trial.c3d", "--out", "x.trc"],
            "no-such-trial.c3d",
        ),
        (vec!["frobnicate"], "frobnicate"),
        (vec!["bench", "--steps", "0"], "--steps"),
        (vec!["bench", "--points", "0"], "--points"),
        (vec!["bench", "--jacobian", "numeric"], "numeric"),
        (vec!["bench", "--backend", "tpu"], "tpu"),
        (vec!["bench", "--scaling-cell", "10"], "N,T"),
        (vec!["bench", "--scaling-cell", "10,x"], "N,T"),
        (vec!["bench", "--plot", "out"], "--scaling"),
        (
            vec!["fit", "x.traj", "--out", "r", "--points-per-step", "0"],
            "--points-per-step",
        ),
        (
            vec!["fit", "x.traj", "--out", "r", "--frames-per-iteration", "0"],
            "--frames-per-iteration",
        ),
        (
            vec!["complete", "r", "--out", "f.npz", "--method", "nearest"],
            "rigid-body",
        ),
        // A fit's settings without a fit are refused, not ignored.
        (
            vec!["fill", "a.c3d", "--out", "b.c3d", "--iters", "5"],
            "--fit",
        ),
        (
            vec!["fill", "a.c3d", "--out", "b.c3d", "--fit", "--no-fit"],
            "--no-fit",
        ),
    ] {
        let (ok, _, err) = doma(&args);
        assert!(!ok, "{args:?} was accepted");
        assert!(
            err.contains(needle),
            "{args:?}: message does not name `{needle}`:\n{err}"
        );
        assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    }
}

#[test]
fn a_missing_json_folder_is_refused_before_fitting() {
    let (ok, _, err) = doma(&[
        "synthetic",
        "--iters",
        "1",
        "--json",
        "/nonexistent-doma-dir/out.json",
    ]);
    assert!(!ok);
    assert!(err.contains("/nonexistent-doma-dir"), "{err}");
}

#[test]
fn a_tiny_run_prints_the_table_and_writes_json() {
    let dir = common::scratch("doma-cli");
    let json = dir.join("runs.json");
    let (ok, stdout, stderr) = doma(&[
        "synthetic",
        "--motion",
        "translation",
        "--variant",
        "trans",
        "--reg",
        "h",
        "--iters",
        "2",
        "--hidden",
        "16",
        "--quiet",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("translation") && stdout.contains("Trans-H"),
        "{stdout}"
    );
    let runs: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let runs = runs.as_array().unwrap();
    assert_eq!(runs.len(), 1);
    let r = &runs[0];
    for key in [
        "motion", "variant", "reg", "iters", "backend", "jacobian", "epe_x1e4", "seconds", "steps",
    ] {
        assert!(r.get(key).is_some(), "missing {key} in {r}");
    }
    assert_eq!(r["motion"], "translation");
    assert_eq!(r["variant"], "trans");
    assert_eq!(r["reg"], "h");
    assert_eq!(r["iters"], 2);
    assert_eq!(r["backend"], "flex");
    assert_eq!(r["jacobian"], "analytic");
    assert_eq!(r["steps"], 40);
    assert!(r["epe_x1e4"].as_f64().unwrap() > 0.0);
}

#[test]
fn bench_prints_the_table_and_writes_exactly_the_record_fields() {
    let dir = common::scratch("doma-bench");
    let json = dir.join("bench.json");
    let (ok, stdout, stderr) = doma(&[
        "bench",
        "--points",
        "16",
        "--warmup",
        "0",
        "--steps",
        "1",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("fit_step") && stdout.contains("GFLOP/s"),
        "{stdout}"
    );
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = rows.as_array().unwrap();
    // flex: the GEMM peak, then {autodiff, analytic} × {fit_step, fit_step_l1, jacobian at
    // 16 points, warp}.
    assert_eq!(rows.len(), 9);
    for r in rows {
        let mut keys: Vec<&str> = r.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        keys.sort_unstable();
        let mut expected = vec![
            "backend",
            "gflops",
            "kind",
            "method",
            "ms",
            "peak_percent",
            "points",
        ];
        // Analytic's training-step rows, timed in turn with Autodiff's, state the paired
        // speed-up; no other row does.
        let paired =
            r["method"] == "analytic" && (r["kind"] == "fit_step" || r["kind"] == "fit_step_l1");
        if paired {
            expected.push("speedup");
            assert!(r["speedup"].as_f64().unwrap() > 0.0);
        }
        assert_eq!(keys, expected, "{r}");
        assert_eq!(r["backend"], "flex");
        assert!(r["ms"].as_f64().unwrap() > 0.0 && r["gflops"].as_f64().unwrap() > 0.0);
        // Every row's share of the peak is its GFLOP/s over the peak's.
        let share = 100.0 * r["gflops"].as_f64().unwrap() / rows[0]["gflops"].as_f64().unwrap();
        assert!((r["peak_percent"].as_f64().unwrap() - share).abs() < 1e-9);
    }
    assert_eq!(rows[0]["kind"], "gemm");
    assert!(rows[0]["method"].is_null());
    assert_eq!(rows[1]["kind"], "fit_step");
    assert_eq!(rows[1]["points"], 750);
    assert_eq!(rows[3]["kind"], "fit_step_l1");
    assert_eq!(rows[6]["kind"], "jacobian");
    assert_eq!(rows[6]["method"], "analytic");
    assert_eq!(rows[8]["kind"], "warp");
    assert_eq!(rows[8]["points"], 16384);
    // A missing interpreter for the PyTorch comparison is named, not a panic.
    let (ok, _, err) = doma(&["bench", "--compare-torch", "/nonexistent/python3"]);
    assert!(!ok && err.contains("/nonexistent/python3"), "{err}");
}

#[test]
fn mesh_experiments_refuse_bad_flags_and_bad_data_naming_the_file() {
    let dir = common::scratch("doma-cli-mesh");
    let no_faces = dir.join("points.npy");
    std::fs::write(
        &no_faces,
        doma::data::npy::encode_npy(&[3, 4, 3], &[0.5; 36]),
    )
    .unwrap();
    let truncated = dir.join("cut.traj");
    std::fs::write(&truncated, b"TRAJ\x01\x00\x00\x00").unwrap();
    let missing = dir.join("missing.traj");
    let faerie = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    for (args, needles) in [
        (
            vec!["novel-points", "--frames", "5..2"],
            vec!["--frames", "empty"],
        ),
        (
            vec!["novel-points", "--frames", "a..b"],
            vec!["frame range"],
        ),
        (vec!["novel-points", "--stride", "0"], vec!["--stride"]),
        (vec!["novel-points", "--variant", "bones"], vec!["bones"]),
        (vec!["mesh-alignment", "--reg", "x"], vec!["--reg"]),
        (vec!["mesh-alignment", "--model", "banmo"], vec!["banmo"]),
        (
            vec!["novel-points", "--data", missing.to_str().unwrap()],
            vec!["missing.traj", "No such file"],
        ),
        (
            vec!["novel-points", "--data", truncated.to_str().unwrap()],
            vec!["cut.traj", "truncated"],
        ),
        (
            vec!["mesh-alignment", "--data", no_faces.to_str().unwrap()],
            vec!["needs faces"],
        ),
        (
            vec!["novel-points", "--data", faerie, "--frames", "190..250"],
            vec!["190..250", "198 frames"],
        ),
        (
            vec![
                "novel-points",
                "--data",
                faerie,
                "--mesh",
                concat!(env!("CARGO_MANIFEST_DIR"), "/data/cdp_male_wave.obj"),
            ],
            vec!["cdp_male_wave.obj", "9293 vertices"],
        ),
    ] {
        let (ok, _, err) = doma(&args);
        assert!(!ok, "{args:?} was accepted");
        assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
        for needle in needles {
            assert!(err.contains(needle), "{args:?}: no `{needle}` in:\n{err}");
        }
    }
}

#[test]
fn a_tiny_novel_points_run_writes_its_records() {
    let dir = common::scratch("doma-cli-np");
    let json = dir.join("np.json");
    let faerie = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    let (ok, out, err) = doma(&[
        "novel-points",
        "--data",
        faerie,
        "--frames",
        "112..=122",
        "--iters",
        "2",
        "--variant",
        "trans,affinity",
        "--samples",
        "2000",
        "--quiet",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("Affinity") && out.contains("CD x1e-4"),
        "{out}"
    );
    let records: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(records.len(), 2);
    for key in [
        "experiment",
        "variant",
        "reg",
        "epe_x1e4",
        "cd_x1e4",
        "cdn",
        "params",
        "checkpoint_bytes",
        "seconds",
    ] {
        assert!(records[1].get(key).is_some(), "no {key} in {}", records[1]);
    }
    assert_eq!(records[1]["params"], 35_212);
    assert_eq!(records[0]["sequence"], "md2_faerie[112..123]");
}

/// Runs `doma` and returns (exit code, stderr).
fn doma_code(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("the binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_user_subcommands_refuse_bad_input_with_one_line_naming_the_file() {
    let dir = common::scratch("doma-cli-bad");
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    std::fs::write(p("cut.traj"), b"TRAJ\x01\x00\x00\x00\x02\x00").unwrap();
    std::fs::write(
        p("magic.traj"),
        b"JART\x01\x00\x00\x00\x01\x00\x00\x00\x01\x00\x00\x00\0\0\0\0\0\0\0\0\0\0\0\0",
    )
    .unwrap();
    let mut nan = b"TRAJ\x01\x00\x00\x00\x01\x00\x00\x00\x01\x00\x00\x00".to_vec();
    for v in [0.0f32, f32::NAN, 1.0] {
        nan.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(p("nan.traj"), nan).unwrap();
    let empty = b"TRAJ\x01\x00\x00\x00\x00\x00\x00\x00\x05\x00\x00\x00";
    std::fs::write(p("empty.traj"), empty).unwrap();
    std::fs::create_dir_all(p("frames")).unwrap();
    std::fs::write(p("frames/a.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(p("frames/b.obj"), "v 0 0 0\nv 1 0 0\nf 1 2 1\n").unwrap();
    std::fs::create_dir_all(p("no_frames")).unwrap();
    std::fs::create_dir_all(p("not_a_run")).unwrap();
    std::fs::write(p("a_file"), b"x").unwrap();
    let faerie = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    let out = p("out");
    let cases: Vec<(Vec<String>, Vec<String>)> = vec![
        (
            vec!["fit".into(), p("missing.traj"), "--out".into(), out.clone()],
            vec!["missing.traj".into(), "No such file".into()],
        ),
        (
            vec!["fit".into(), p("cut.traj"), "--out".into(), out.clone()],
            vec!["cut.traj".into(), "truncated".into()],
        ),
        (
            vec!["fit".into(), p("magic.traj"), "--out".into(), out.clone()],
            vec!["magic.traj".into(), "magic".into()],
        ),
        (
            vec!["fit".into(), p("nan.traj"), "--out".into(), out.clone()],
            vec!["nan.traj".into(), "NaN".into()],
        ),
        (
            vec!["fit".into(), p("empty.traj"), "--out".into(), out.clone()],
            vec!["empty.traj".into(), "empty sequence".into()],
        ),
        (
            vec!["fit".into(), p("frames"), "--out".into(), out.clone()],
            vec!["b.obj".into(), "vertices".into()],
        ),
        (
            vec!["fit".into(), p("no_frames"), "--out".into(), out.clone()],
            vec!["no_frames".into(), "no .obj".into()],
        ),
        (
            vec![
                "fit".into(),
                faerie.into(),
                "--out".into(),
                p("a_file/run"),
                "--iters".into(),
                "1".into(),
            ],
            vec!["a_file".into()],
        ),
        (
            vec!["fit".into(), "--resume".into(), p("not_a_run")],
            vec!["not_a_run".into(), "not a doma run".into()],
        ),
        (
            vec!["eval".into(), p("not_a_run")],
            vec!["not_a_run".into(), "not a doma run".into()],
        ),
        (
            vec!["info".into(), p("not_a_run")],
            vec!["not_a_run".into(), "not a doma run".into()],
        ),
        (
            vec![
                "warp".into(),
                p("not_a_run"),
                "--mesh".into(),
                p("x.obj"),
                "--out".into(),
                out.clone(),
            ],
            vec!["not_a_run".into()],
        ),
        (
            vec![
                "fit".into(),
                faerie.into(),
                "--out".into(),
                out.clone(),
                "--test-fraction".into(),
                "1.5".into(),
            ],
            vec!["--test-fraction".into()],
        ),
    ];
    for (args, needles) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, err) = doma_code(&args);
        // 1: a refused input, one line; 2: clap's refusal of a flag value.
        assert!(
            matches!(code, Some(1 | 2)),
            "{args:?}: exit {code:?}\n{err}"
        );
        assert!(
            !err.contains("panicked") && !err.contains("stack backtrace"),
            "{args:?}:\n{err}"
        );
        if code == Some(1) {
            assert_eq!(
                err.trim_end().lines().count(),
                1,
                "{args:?}: not one line:\n{err}"
            );
        }
        for n in needles {
            assert!(err.contains(&n), "{args:?}: no `{n}` in:\n{err}");
        }
    }
    // None of the failures left a half-made run behind.
    assert!(!std::path::Path::new(&out).join("model.bpk").exists());
}

#[test]
fn ctrl_c_saves_a_checkpoint_and_the_fit_resumes() {
    let dir = common::scratch_path("doma-cli-sigint");
    let faerie = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    let run = dir.join("run");
    let child = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args([
            "fit", faerie, "--frames", "112..118", "--iters", "100000", "--quiet",
        ])
        .arg("--out")
        .arg(&run)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the fit is running (its config is written first), then interrupt it.
    for _ in 0..200 {
        if run.join("config.json").exists() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    std::thread::sleep(std::time::Duration::from_millis(500));
    // SAFETY: sending a signal to our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(err.contains("--resume"), "{err}");
    assert!(run.join("resume.ckpt").is_file());
    let history: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(run.join("history.json")).unwrap()).unwrap();
    assert!(!history.is_empty());
    // Shorten the fit, then resume it to the end.
    let config = run.join("config.json");
    let mut c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&config).unwrap()).unwrap();
    c["fit"]["schedule"]["iterations"] = serde_json::json!(history.len() + 2);
    std::fs::write(&config, c.to_string()).unwrap();
    let (ok, _, err) = doma(&["fit", "--resume", run.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(run.join("model.bpk").is_file() && run.join("report.json").is_file());
}

#[test]
fn the_supplement_experiments_refuse_bad_flags() {
    for (args, needle) in [
        (vec!["fluid", "--widths", "0"], "--widths"),
        (vec!["fluid", "--clip-len", "1"], "--clip-len"),
        (vec!["fluid", "--model", "banmo"], "banmo"),
        (
            vec!["fluid", "--data", "/nonexistent/fluid.traj"],
            "fluid.traj",
        ),
        (vec!["fluid", "--clips", "10,95", "--iters", "1"], "clip 95"),
        (vec!["fluid", "--clips", "10", "--start", "5"], "--start"),
        (vec!["fluid", "--png-dir", "/tmp/x"], "--eval-every"),
        (
            vec!["fluid", "--records", "/nonexistent/records.json"],
            "records.json",
        ),
        (vec!["image2d", "--resolution", "1"], "--resolution"),
        (vec!["image2d", "--widths", "0"], "--widths"),
        (vec!["image2d", "--motion", "twist"], "twist"),
        (vec!["novel-points", "--baselines", "banana"], "banana"),
        (vec!["novel-points", "--reg", "x"], "x"),
        (vec!["novel-points", "--h-weight", "-1"], "--h-weight"),
        (vec!["novel-points", "--h-weight", "lots"], "auto"),
        (
            vec![
                "novel-points",
                "--h-weight",
                "auto",
                "--validation-fraction",
                "1.5",
            ],
            "--validation-fraction",
        ),
        (
            vec![
                "synthetic",
                "--reg",
                "h",
                "--h-weight",
                "auto",
                "--weight-grid",
                "0,-1",
            ],
            "--weight-grid",
        ),
    ] {
        let (ok, _, err) = doma(&args);
        assert!(!ok, "{args:?} was accepted");
        assert!(
            err.contains(needle) && !err.contains("panicked"),
            "{args:?}:\n{err}"
        );
        // The operating system's reason is said once, not once per error in the chain.
        assert!(err.matches("No such file").count() <= 1, "{args:?}:\n{err}");
    }
}

#[test]
fn fit_reads_a_config_file_and_flags_override_it() {
    let dir = common::scratch("doma-cli-config");
    let config = dir.join("fit.json");
    // A FitConfig as a run's config.json holds it: Scaled SE(3), width 16, 50 iterations.
    let fit = doma::train::FitConfig::doma(
        doma::field::DomaFieldConfig::new(doma::field::Variant::ScaledSe3).with_hidden(16),
    )
    .with_iterations(50);
    std::fs::write(&config, serde_json::to_string(&fit).unwrap()).unwrap();
    let run = dir.join("run");
    let faerie = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    let (ok, _, err) = doma(&[
        "fit",
        faerie,
        "--frames",
        "112..116",
        "--out",
        run.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--iters",
        "2",
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap();
    let model = &saved["fit"]["model"]["doma"];
    assert_eq!(model["variant"], "scaled-se3");
    assert_eq!(model["shape"]["hidden"], 16);
    assert_eq!(
        saved["fit"]["schedule"]["iterations"], 2,
        "the flag overrides the file"
    );
    // The saved recipe holds no display flags.
    assert!(saved["fit"].get("quiet").is_none());
    // A partial config takes defaults for the rest: only the variant and the budget.
    std::fs::write(
        &config,
        r#"{"model": {"doma": {"variant": "trans"}}, "schedule": {"iterations": 1}}"#,
    )
    .unwrap();
    let partial = dir.join("partial");
    let (ok, _, err) = doma(&[
        "fit",
        faerie,
        "--frames",
        "112..116",
        "--out",
        partial.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(partial.join("config.json")).unwrap())
            .unwrap();
    assert_eq!(saved["fit"]["model"]["doma"]["variant"], "trans");
    assert_eq!(saved["fit"]["model"]["doma"]["shape"]["hidden"], 128);
    assert_eq!(saved["fit"]["schedule"]["learning_rate"], 1e-4);
    assert_eq!(
        saved["fit"]["smoothness_sampling"]["jitter"], 0.0,
        "Trans: no jitter"
    );
    // An analytic Jacobian for a model without SIREN layers is refused, not substituted.
    std::fs::write(&config, r#"{"model": {"mlp": {}}, "jacobian": "analytic"}"#).unwrap();
    let (ok, _, err) = doma(&[
        "fit",
        faerie,
        "--out",
        dir.join("r3").to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("fit.json") && err.contains("analytic"),
        "{err}"
    );
    // A config file that is not JSON names the file.
    std::fs::write(&config, "{ nope").unwrap();
    let (ok, _, err) = doma(&[
        "fit",
        faerie,
        "--out",
        dir.join("r2").to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("fit.json"), "{err}");
}

#[test]
fn fit_chooses_its_smoothness_weight_by_validation_and_plots_the_grid() {
    let dir = common::scratch("doma-cli-auto");
    let run = dir.join("run");
    let faerie = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    let (ok, _, err) = doma(&[
        "fit",
        faerie,
        "--frames",
        "112..116",
        "--iters",
        "2",
        "--h-weight",
        "auto",
        "--weight-grid",
        "0,0.1,10",
        "--search-iters",
        "2",
        "--quiet",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap();
    let grid = saved["weight_search"]["grid"].as_array().unwrap();
    assert_eq!(grid.len(), 3);
    // The chosen weight is the grid's best, and it is the fit's weight.
    let best = grid
        .iter()
        .min_by(|a, b| {
            let e = |p: &serde_json::Value| p["validation_epe_x1e4"].as_f64().unwrap();
            e(a).total_cmp(&e(b))
        })
        .unwrap();
    assert_eq!(saved["weight_search"]["weight"], best["weight"]);
    assert_eq!(saved["fit"]["loss"]["smoothness_weight"], best["weight"]);
    let (ok, _, err) = doma(&["plot", run.to_str().unwrap()]);
    assert!(ok && err.contains("weight_search.png"), "{err}");
}

#[test]
fn a_scaling_cell_reports_its_step_time_and_peak_memory() {
    let (ok, out, err) = doma(&[
        "bench",
        "--scaling-cell",
        "300,4,100",
        "--warmup",
        "1",
        "--steps",
        "2",
    ]);
    assert!(ok, "{err}");
    let cell: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(cell["points"], 300);
    assert_eq!(cell["frames"], 4);
    assert_eq!(cell["points_per_step"], 100);
    assert!(cell["step_ms"].as_f64().unwrap() > 0.0, "{cell}");
    // A fit of a few hundred points still loads the binary and Burn: some MiB.
    assert!(cell["peak_mib"].as_f64().unwrap() > 1.0, "{cell}");
}

#[test]
fn tracker_flags_that_do_not_fit_the_data_are_refused_naming_the_file_or_flag() {
    let dir = common::scratch("doma-cli-tracks");
    let faerie = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
    let npz = dir.join("clip.npz");
    let positions: Vec<f32> = (0..2 * 3 * 3).map(|i| (i % 5) as f32).collect();
    doma::data::npy::write_npz(&npz, &[("tracks", &[2, 3, 3], &positions)]).unwrap();
    let npz = npz.to_str().unwrap();
    let out = dir.join("run");
    let out = out.to_str().unwrap();
    for (args, needles) in [
        (
            vec!["fit", faerie, "--frames", "0..4", "--layout", "tapvid3d"],
            vec!["md2_faerie.traj", "--layout"],
        ),
        (
            vec!["fit", faerie, "--frames", "0..4", "--confidence", "conf"],
            vec!["md2_faerie.traj", "--confidence applies"],
        ),
        (
            vec!["fit", npz, "--frame", "camera"],
            vec!["clip.npz", "--frame needs a tracker layout"],
        ),
        (
            vec!["fit", npz, "--layout", "pointodyssey"],
            vec!["clip.npz", "no key \"trajs_3d\""],
        ),
        (
            vec!["fit", faerie, "--frames", "0..4", "--reference-frame", "4"],
            vec!["md2_faerie.traj", "reference frame 4"],
        ),
        (
            vec!["fit", faerie, "--holdout-observations", "1.5"],
            vec!["--holdout-observations"],
        ),
        (
            vec!["fit", faerie, "--robust", "huber:-1"],
            vec!["--robust"],
        ),
    ] {
        let (code, err) = doma_code(&[&args[..], &["--out", out, "--iters", "1"]].concat());
        // 2 for a flag clap refuses, 1 for data the flags do not fit.
        assert!(matches!(code, Some(1 | 2)), "{args:?}: {err}");
        if code == Some(1) {
            assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
        }
        for n in needles {
            assert!(err.contains(n), "{args:?}: {err} lacks {n}");
        }
        assert!(
            !std::path::Path::new(out).exists(),
            "{args:?} left a run folder"
        );
    }
}

#[test]
fn bench_time_to_accuracy_writes_the_curves_the_targets_and_the_plots() {
    let dir = common::scratch("doma-tta");
    let json = dir.join("tta.json");
    let recipe = dir.join("short.json");
    std::fs::write(
        &recipe,
        r#"{"schedule": {"iterations": 4, "decay": "cosine"}, "points_per_step": 64}"#,
    )
    .unwrap();
    let (ok, stdout, stderr) = doma(&[
        "bench",
        "--time-to-accuracy",
        "--motion",
        "rotation",
        "--recipe",
        "paper",
        "--paper-iters",
        "3",
        "--recipe-file",
        recipe.to_str().unwrap(),
        "--curve-points",
        "3",
        "--json",
        json.to_str().unwrap(),
        "--plot",
        dir.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("to authors (10.52)"), "{stdout}");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let curves = record["curves"].as_array().unwrap();
    let names: Vec<&str> = curves
        .iter()
        .map(|c| c["contender"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["paper", "short"]);
    let iterations = |c: &serde_json::Value| -> Vec<u64> {
        c["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["iteration"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(iterations(&curves[0]), [1, 2, 3]);
    assert_eq!(iterations(&curves[1]), [1, 2, 3, 4]);
    // The file's fields over the protocol's, and the curve's seconds only grow.
    assert_eq!(curves[1]["config"]["schedule"]["iterations"], 4);
    assert_eq!(curves[1]["config"]["points_per_step"], 64);
    for c in curves {
        let s: Vec<f64> = c["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["seconds"].as_f64().unwrap())
            .collect();
        assert!(s.windows(2).all(|w| w[0] <= w[1]), "{s:?}");
        assert!(c["eval_seconds"].as_f64().unwrap() > 0.0);
    }
    // The authors' EPE, the protocol's, each +10 %.
    let targets: Vec<&str> = record["targets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        targets,
        [
            "authors",
            "authors +10 %",
            "paper final",
            "paper final +10 %"
        ]
    );
    for ext in ["png", "svg"] {
        assert!(
            dir.join(format!("time_to_accuracy_rotation.{ext}"))
                .is_file()
        );
    }
    // A recipe file with a field no fit config has is refused, naming the file and field.
    std::fs::write(&recipe, r#"{"schedule": {"iters": 4}}"#).unwrap();
    let (ok, _, stderr) = doma(&[
        "bench",
        "--time-to-accuracy",
        "--recipe-file",
        recipe.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("short.json") && stderr.contains("schedule.iters"),
        "{stderr}"
    );
}

#[test]
fn a_fit_refused_by_its_trainer_leaves_no_run_folder() {
    let dir = common::scratch("doma-halfmade");
    let data = dir.join("tiny.traj");
    let positions: Vec<f32> = (0..5 * 4 * 3).map(|v| (v as f32 * 0.37).sin()).collect();
    doma::data::traj::write_traj(
        &data,
        &doma::data::Trajectories::new(5, 4, positions).unwrap(),
    )
    .unwrap();
    let run = dir.join("run");
    let (ok, _, err) = doma(&[
        "fit",
        data.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
        "--until-converged",
        "5",
    ]);
    assert!(!ok && err.contains("validate"), "{err}");
    assert!(
        !run.exists(),
        "{:?}",
        std::fs::read_dir(&run).map(|d| d.count())
    );
}

#[test]
fn fit_takes_soap_from_the_flag_and_refuses_it_without_the_fused_step() {
    let dir = common::scratch("doma-soap");
    let data = dir.join("tiny.traj");
    let positions: Vec<f32> = (0..5 * 16 * 3).map(|v| (v as f32 * 0.37).sin()).collect();
    doma::data::traj::write_traj(
        &data,
        &doma::data::Trajectories::new(5, 16, positions).unwrap(),
    )
    .unwrap();
    let run = dir.join("run");
    let fit = |extra: &[&str]| {
        let mut args = vec![
            "fit",
            data.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
            "--iters",
            "2",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        doma(&args)
    };
    let (ok, _, err) = fit(&["--optimizer", "soap", "--step", "composed"]);
    assert!(!ok && err.contains("SOAP"), "{err}");
    assert!(!run.exists());
    let (ok, _, err) = fit(&["--optimizer", "soap"]);
    assert!(ok, "{err}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["fit"]["soap"]["every"], 100);
    assert_eq!(config["fit"]["step"], "auto");
}

#[test]
fn a_motion_capture_fit_reports_its_error_in_millimetres_and_quiet_is_quiet() {
    let dir = common::scratch("doma-cli-mm");
    let knee = concat!(env!("CARGO_MANIFEST_DIR"), "/data/mocap/right_knee.c3d");
    let run = dir.join("run");
    let json = dir.join("report.json");
    let (ok, stdout, stderr) = doma(&[
        "fit",
        knee,
        "--frames",
        "0..30",
        "--iters",
        "2",
        "--quiet",
        "--json",
        json.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.is_empty() && stderr.is_empty(), "{stdout}{stderr}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["units"], "mm");
    let (epe, x1e4) = (
        report["epe"].as_f64().unwrap(),
        report["epe_x1e4"].as_f64().unwrap(),
    );
    // The normalisation divides by a scale of the recording's size: metres of a person.
    let scale = epe / (x1e4 * 1e-4);
    assert!(
        epe > 0.0 && (100.0..10_000.0).contains(&scale),
        "{epe} {x1e4}"
    );
}

/// Every filler is listed by `complete --help` and `fill --help` under its command-line
/// name, and in docs/usage.md's table under both its names: the lists are held to
/// `Filler::ALL`, not kept by hand.
#[test]
fn every_filler_is_listed_in_the_help_and_the_docs() {
    use doma::gaps::Filler;
    let docs = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/usage.md"))
        .expect("docs/usage.md");
    let table: Vec<&str> = docs
        .split("## The fillers")
        .nth(1)
        .expect("a section on the fillers")
        .lines()
        .filter(|l| l.starts_with("| `"))
        .collect();
    assert_eq!(table.len(), Filler::COUNT, "{table:?}");
    for (row, f) in table.iter().zip(Filler::ALL) {
        let want = format!("| `{}` | `{}` |", f.flag(), f.name());
        assert!(row.starts_with(&want), "{row} is not {want}");
    }
    for command in ["complete", "fill"] {
        let (ok, out, err) = doma(&[command, "-h"]);
        assert!(ok, "{err}");
        let values = out
            .split("--method <FILLER>")
            .nth(1)
            .and_then(|m| m.split("[possible values: ").nth(1))
            .and_then(|v| v.split(']').next())
            .unwrap_or_else(|| panic!("{command} -h lists no fillers:\n{out}"));
        let listed: Vec<&str> = values.split(", ").collect();
        let all: Vec<&str> = Filler::ALL.iter().map(|f| f.flag()).collect();
        assert_eq!(listed, all, "{command} -h");
    }
    // The old spelling still reads.
    let (_, _, err) = doma(&[
        "complete",
        "no-such-run",
        "--out",
        "x.npz",
        "--method",
        "rigid_body",
    ]);
    assert!(!err.contains("invalid value"), "{err}");
}

/// `--extrapolate` alone, `--extrapolate=false`, and what each input does without it, said
/// in both commands' help; any other value is refused naming the flag.
#[test]
fn extrapolate_says_its_default_by_input_and_takes_a_boolean() {
    for command in ["complete", "fill"] {
        let (ok, out, err) = doma(&[command, "--help"]);
        assert!(ok, "{err}");
        let flag = out
            .split("--extrapolate")
            .nth(1)
            .unwrap_or_else(|| panic!("{command} --help has no --extrapolate:\n{out}"));
        let said = flag.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(said.contains("PointOdyssey or TAPVid-3D"), "{said}");
        assert!(said.contains("motion-capture recording"), "{said}");
    }
    for value in ["--extrapolate", "--extrapolate=false", "--extrapolate=true"] {
        let (_, _, err) = doma(&["complete", "no-such-run", "--out", "x.npz", value]);
        assert!(!err.contains("--extrapolate"), "{value}: {err}");
    }
    let (ok, _, err) = doma(&[
        "complete",
        "no-such-run",
        "--out",
        "x.npz",
        "--extrapolate=maybe",
    ]);
    assert!(!ok && err.contains("--extrapolate"), "{err}");
}

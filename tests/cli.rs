//! The `doma` binary: bad flags are refused with a clear message, and a tiny run
//! prints the table and writes one JSON record per run.

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
        (vec!["synthetic", "--variant", "bones"], "bones"),
        (vec!["synthetic", "--backend", "cuda"], "cuda"),
        (vec!["synthetic", "--h-weight", "-0.1"], "non-negative"),
        (vec!["synthetic", "--h-weight", "nan"], "non-negative"),
        (vec!["synthetic", "--hidden", "0"], "--hidden"),
        (vec!["frobnicate"], "frobnicate"),
        (vec!["bench", "--steps", "0"], "--steps"),
        (vec!["bench", "--points", "0"], "--points"),
        (vec!["bench", "--jacobian", "numeric"], "numeric"),
        (vec!["bench", "--backend", "tpu"], "tpu"),
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
    let dir = std::env::temp_dir().join(format!("doma-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
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
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bench_prints_the_table_and_writes_exactly_the_record_fields() {
    let dir = std::env::temp_dir().join(format!("doma-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
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
    // flex × {autodiff, analytic} × {fit_step, jacobian at 16 points}.
    assert_eq!(rows.len(), 4);
    for r in rows {
        let mut keys: Vec<&str> = r.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        keys.sort_unstable();
        assert_eq!(
            keys,
            ["backend", "gflops", "kind", "method", "ms", "points"]
        );
        assert_eq!(r["backend"], "flex");
        assert!(r["ms"].as_f64().unwrap() > 0.0 && r["gflops"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(rows[0]["kind"], "fit_step");
    assert_eq!(rows[0]["points"], 750);
    assert_eq!(rows[3]["kind"], "jacobian");
    assert_eq!(rows[3]["method"], "analytic");
    std::fs::remove_dir_all(&dir).unwrap();
}

//! `doma batch` as a cluster runs it: shards as separate processes at once, a shard killed
//! and rerun, failures recorded without stopping the shard, `--collect`, and the Slurm and
//! Kubernetes recipes in docs/batch/ checked against the binary.

use crate::common;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const FAERIE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");

fn temp(tag: &str) -> common::Scratch {
    common::scratch(&format!("doma-batch-{tag}"))
}

fn doma() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_doma"));
    // The recipes' environment must not leak in from a test machine that is itself a
    // Slurm or Kubernetes task.
    for v in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_STEP",
        "JOB_COMPLETION_INDEX",
    ] {
        c.env_remove(v);
    }
    c
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Writes a manifest of faerie clips; `extra` entries are appended verbatim.
fn manifest(dir: &Path, entries: &[Value]) -> PathBuf {
    let path = dir.join("manifest.json");
    let m = serde_json::json!({
        "defaults": { "frames": [112, 116], "iterations": 40, "checkpoint_every": 5 },
        "sequences": entries,
    });
    std::fs::write(&path, m.to_string()).unwrap();
    path
}

fn faerie(name: &str, seed: u64) -> Value {
    serde_json::json!({ "name": name, "data": FAERIE, "seed": seed })
}

/// One whole batch of `manifest` into `out`, quietly.
fn batch_quietly(manifest: &Path, out: &Path) -> Output {
    doma()
        .arg("batch")
        .arg(manifest)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .output()
        .unwrap()
}

/// The names of a shard report's entries with the given status.
fn with_status(report: &Value, status: &str) -> Vec<String> {
    report["items"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|i| i["status"] == status)
        .map(|i| i["name"].as_str().unwrap().to_string())
        .collect()
}

fn report(out: &Output) -> Value {
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{e}: stdout {}\nstderr {}",
            text(&out.stdout),
            text(&out.stderr)
        )
    })
}

fn collect(dir: &Path) -> Vec<Value> {
    let out = doma()
        .arg("batch")
        .arg("--collect")
        .arg(dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let rows: Vec<Value> =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let csv = std::fs::read_to_string(dir.join("summary.csv")).unwrap();
    assert_eq!(csv.lines().count(), rows.len() + 1, "{csv}");
    rows
}

#[test]
fn two_shards_at_once_fit_every_entry_exactly_once() {
    let dir = temp("two");
    let names = ["s0", "s1", "s2", "s3", "s4"];
    let entries: Vec<Value> = names.iter().zip(0..).map(|(n, s)| faerie(n, s)).collect();
    let m = manifest(&dir, &entries);
    let out = dir.join("out");
    let shard = |i: usize| {
        doma()
            .arg("batch")
            .arg(&m)
            .arg("--out")
            .arg(&out)
            .args(["--shard", &format!("{i}/2"), "--quiet"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (shard(0), shard(1));
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    assert!(a.status.success(), "{}", text(&a.stderr));
    assert!(b.status.success(), "{}", text(&b.stderr));
    let (fa, fb) = (
        with_status(&report(&a), "fitted"),
        with_status(&report(&b), "fitted"),
    );
    assert_eq!(fa, ["s0", "s2", "s4"]);
    assert_eq!(fb, ["s1", "s3"]);
    let rows = collect(&out);
    let listed: Vec<&str> = rows.iter().map(|r| r["name"].as_str().unwrap()).collect();
    assert_eq!(listed, names);
    for r in &rows {
        assert_eq!(r["status"], "done", "{r}");
        assert_eq!(r["iterations"], 40, "{r}");
        assert!(r["epe_x1e4"].as_f64().unwrap() > 0.0, "{r}");
        assert!(r["seconds"].as_f64().unwrap() > 0.0, "{r}");
    }
    // Rerunning the whole batch in one process now fits nothing.
    let again = doma()
        .arg("batch")
        .arg(&m)
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(again.status.success(), "{}", text(&again.stderr));
    assert_eq!(with_status(&report(&again), "done"), names);
}

#[test]
fn a_killed_shard_reruns_to_finish_the_rest() {
    let dir = temp("kill");
    let mut long = faerie("long", 1);
    long["iterations"] = serde_json::json!(2000);
    let m = manifest(&dir, &[faerie("first", 0), long, faerie("last", 2)]);
    let out = dir.join("out");
    let run = || {
        let mut c = doma();
        c.arg("batch")
            .arg(&m)
            .arg("--out")
            .arg(&out)
            .arg("--quiet")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        c
    };
    let mut child = run().spawn().unwrap();
    // Wait until `long` has saved a checkpoint, then kill the shard outright.
    let ckpt = out.join("long/resume.ckpt");
    let start = Instant::now();
    while !ckpt.is_file() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no checkpoint of `long`"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(out.join("first/report.json").is_file());
    assert!(
        !out.join("long/report.json").is_file(),
        "`long` finished before the kill"
    );
    let statuses: Vec<Value> = collect(&out).iter().map(|r| r["status"].clone()).collect();
    assert_eq!(statuses, ["done", "unfinished", "pending"]);
    // The rerun skips `first`, resumes `long` from its checkpoint and fits `last`.
    let again = run().output().unwrap();
    assert!(again.status.success(), "{}", text(&again.stderr));
    let r = report(&again);
    assert_eq!(with_status(&r, "done"), ["first"]);
    assert_eq!(with_status(&r, "resumed"), ["long"]);
    assert_eq!(with_status(&r, "fitted"), ["last"]);
    let rows = collect(&out);
    assert!(rows.iter().all(|r| r["status"] == "done"), "{rows:?}");
    assert_eq!(rows[1]["iterations"], 2000);
}

#[test]
fn a_failed_entry_is_recorded_and_the_shard_goes_on() {
    let dir = temp("fail");
    let truncated = dir.join("truncated.traj");
    let bytes = std::fs::read(FAERIE).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let mut bad = faerie("truncated", 0);
    bad["data"] = Value::String(truncated.to_string_lossy().into_owned());
    let mut missing = faerie("missing", 0);
    missing["data"] = Value::String("no/such.traj".into());
    let mut good = faerie("good", 0);
    good["iterations"] = serde_json::json!(3);
    let m = manifest(&dir, &[bad, missing, good]);
    let out = dir.join("out");
    let run = batch_quietly(&m, &out);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let r = report(&run);
    assert_eq!(with_status(&r, "failed"), ["truncated", "missing"]);
    assert_eq!(with_status(&r, "fitted"), ["good"]);
    let rows = collect(&out);
    assert_eq!(rows[0]["status"], "failed");
    let e0 = rows[0]["error"].as_str().unwrap();
    assert!(e0.contains("truncated.traj"), "{e0}");
    let e1 = rows[1]["error"].as_str().unwrap();
    assert!(e1.contains("no/such.traj"), "{e1}");
    assert_eq!(rows[2]["status"], "done");
    // Nothing half-made: a failed entry's folder holds its error record alone.
    let left: Vec<String> = std::fs::read_dir(out.join("missing"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, ["error.json"]);
}

#[test]
fn a_folder_taken_by_a_file_is_a_recorded_failure_and_collect_stays_inside() {
    let dir = temp("taken");
    let mut blocked = faerie("blocked", 0);
    blocked["iterations"] = serde_json::json!(3);
    let mut good = faerie("good", 0);
    good["iterations"] = serde_json::json!(3);
    let m = manifest(&dir, &[blocked, good]);
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("blocked"), "a file where the run folder would go").unwrap();
    let run = batch_quietly(&m, &out);
    let err = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    let r = report(&run);
    assert_eq!(with_status(&r, "failed"), ["blocked"], "{r}");
    assert_eq!(with_status(&r, "fitted"), ["good"], "{r}");
    collect(&out);

    // Both summaries or neither: summary.csv cannot be replaced, so summary.json is not
    // written either.
    std::fs::remove_file(out.join("summary.json")).unwrap();
    std::fs::remove_file(out.join("summary.csv")).unwrap();
    std::fs::create_dir_all(out.join("summary.csv/x")).unwrap();
    let failed = doma()
        .arg("batch")
        .arg("--collect")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(failed.status.code(), Some(1), "{}", text(&failed.stderr));
    assert!(
        !out.join("summary.json").exists(),
        "one summary without the other"
    );
    std::fs::remove_dir_all(out.join("summary.csv")).unwrap();

    // A name in the batch's copy of the manifest that leads outside is refused.
    let copy = out.join("batch-manifest.json");
    let edited = std::fs::read_to_string(&copy)
        .unwrap()
        .replace("\"good\"", "\"../elsewhere\"");
    std::fs::write(&copy, edited).unwrap();
    let outside = doma()
        .arg("batch")
        .arg("--collect")
        .arg(&out)
        .output()
        .unwrap();
    let err = text(&outside.stderr);
    assert_eq!(outside.status.code(), Some(1), "{err}");
    assert!(
        err.contains("batch-manifest.json") && err.contains("../elsewhere"),
        "{err}"
    );
}

#[test]
fn bad_manifests_and_flags_are_refused_with_the_file_named() {
    let dir = temp("bad");
    let m = dir.join("m.json");
    std::fs::write(&m, r#"{"sequences": [{"data": "a.traj", "iteratons": 5}]}"#).unwrap();
    let out = doma()
        .arg("batch")
        .arg(&m)
        .args(["--out", "x"])
        .output()
        .unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("m.json") && err.contains("iteratons"), "{err}");
    let ok = manifest(&dir, &[faerie("a", 0)]);
    for (args, needle) in [
        (vec!["--shard", "2/2"], "below the count"),
        (vec!["--shard", "1"], "I/N"),
    ] {
        let out = doma()
            .arg("batch")
            .arg(&ok)
            .args(["--out", "x"])
            .args(&args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(text(&out.stderr).contains(needle), "{}", text(&out.stderr));
    }
    let out = doma()
        .arg("batch")
        .arg(&ok)
        .args(["--out", "x", "--list"])
        .env("JOB_COMPLETION_INDEX", "1")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("--shard-count"),
        "{}",
        text(&out.stderr)
    );
    let out = doma()
        .arg("batch")
        .arg("--collect")
        .arg(dir.join("nope"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("nope"), "{}", text(&out.stderr));
}

/// The `doma …` command of a recipe, split into words (double quotes group; the recipes
/// use no other shell syntax on that line).
fn words(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    for c in line.chars() {
        match c {
            '"' => quoted = !quoted,
            c if c.is_whitespace() && !quoted => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
            c => cur.push(c),
        }
    }
    out.extend((!cur.is_empty()).then_some(cur));
    out
}

/// Runs the recipe's `doma` command with `--list` in the repository root under `env`,
/// for each array index: every manifest entry must be listed by exactly one index.
fn check_recipe(args: &[String], envs: &[Vec<(&str, String)>]) {
    assert_eq!(args[0], "doma", "{args:?}");
    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(Path::new(ROOT).join(&args[2])).unwrap())
            .unwrap();
    let all: BTreeSet<String> = manifest["sequences"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap().to_string())
        .collect();
    let mut seen = Vec::new();
    for env in envs {
        let mut c = doma();
        c.current_dir(ROOT).args(&args[1..]).arg("--list");
        for (k, v) in env {
            c.env(k, v);
        }
        let out = c.output().unwrap();
        assert!(out.status.success(), "{env:?}: {}", text(&out.stderr));
        seen.extend(text(&out.stdout).lines().map(str::to_string));
    }
    assert_eq!(seen.len(), all.len(), "{seen:?}");
    assert_eq!(seen.into_iter().collect::<BTreeSet<_>>(), all);
}

#[test]
fn the_slurm_recipe_runs_every_entry_once_across_its_array() {
    let script = std::fs::read_to_string(Path::new(ROOT).join("docs/batch/slurm.sbatch")).unwrap();
    let array = script
        .lines()
        .find_map(|l| l.strip_prefix("#SBATCH --array="))
        .expect("an --array line");
    let (lo, hi) = array.split_once('-').unwrap();
    let (lo, hi): (usize, usize) = (lo.parse().unwrap(), hi.parse().unwrap());
    let command: Vec<&str> = script.lines().filter(|l| l.starts_with("doma ")).collect();
    assert_eq!(command.len(), 1, "one doma command");
    let args = words(command[0]);
    assert!(
        !args.contains(&"--shard".to_string()),
        "Slurm's variables name the shard"
    );
    let count = hi - lo + 1;
    let envs: Vec<Vec<(&str, String)>> = (lo..=hi)
        .map(|id| {
            vec![
                ("SLURM_ARRAY_TASK_ID", id.to_string()),
                ("SLURM_ARRAY_TASK_MIN", lo.to_string()),
                ("SLURM_ARRAY_TASK_COUNT", count.to_string()),
            ]
        })
        .collect();
    check_recipe(&args, &envs);
}

#[test]
fn the_kubernetes_recipe_runs_every_entry_once_across_its_completions() {
    let yaml =
        std::fs::read_to_string(Path::new(ROOT).join("docs/batch/k8s-indexed-job.yaml")).unwrap();
    let field = |key: &str| {
        yaml.lines()
            .find_map(|l| l.trim().strip_prefix(key))
            .unwrap_or_else(|| panic!("no {key}"))
            .trim()
            .to_string()
    };
    assert_eq!(field("completionMode:"), "Indexed");
    let completions: usize = field("completions:").parse().unwrap();
    // The command is a YAML flow sequence, which is JSON.
    let args: Vec<String> = serde_json::from_str(&field("command:")).unwrap();
    let at = args
        .iter()
        .position(|a| a == "--shard-count")
        .expect("--shard-count");
    assert_eq!(args[at + 1].parse::<usize>().unwrap(), completions);
    let envs: Vec<Vec<(&str, String)>> = (0..completions)
        .map(|i| vec![("JOB_COMPLETION_INDEX", i.to_string())])
        .collect();
    check_recipe(&args, &envs);
}

#[test]
fn the_batch_folder_s_files_never_replace_the_manifest() {
    let dir = temp("own-manifest");
    let written = manifest(&dir, &[faerie("a", 0)]);
    // The manifest kept in the batch folder under a name the batch writes.
    let kept = dir.join("summary.json");
    std::fs::rename(&written, &kept).unwrap();
    let before = std::fs::read(&kept).unwrap();
    let out = batch_quietly(&kept, &dir);
    assert_eq!(out.status.code(), Some(1));
    let err = text(&out.stderr);
    assert!(
        err.contains("refusing to write there") && err.contains("summary.json"),
        "{err}"
    );
    assert_eq!(std::fs::read(&kept).unwrap(), before);
    assert!(!dir.join("a").exists());
}

/// Three small C3D trials, each with a gap in one marker.
fn trials(dir: &Path) -> PathBuf {
    use doma::data::c3d::{C3d, write_c3d};
    let folder = dir.join("trials");
    std::fs::create_dir_all(&folder).unwrap();
    let (t, n) = (40, 4);
    for k in 0..3 {
        let positions: Vec<f32> = (0..t * n * 3)
            .map(|e| {
                let (f, i, d) = (e / (3 * n), e / 3 % n, e % 3);
                100.0 * i as f32 + 10.0 * d as f32 + (0.1 * f as f32 + k as f32).sin() * 20.0
            })
            .collect();
        let residuals = (0..t * n)
            .map(|e| {
                if e % n == 1 && (10..18).contains(&(e / n)) {
                    -1.0
                } else {
                    1.0
                }
            })
            .collect();
        let c = C3d {
            frames: t,
            points: n,
            first_frame: 1,
            rate: 100.0,
            scale: -0.1,
            units: "mm".into(),
            labels: (0..n).map(|i| format!("M{i}")).collect(),
            model_outputs: vec![None; n],
            positions,
            residuals,
            cameras: vec![1; t * n],
            notes: Vec::new(),
        };
        write_c3d(folder.join(format!("trial{k}.c3d")), &c).unwrap();
    }
    folder
}

#[test]
fn a_folder_or_a_pattern_of_recordings_is_filled_shard_by_shard() {
    let dir = temp("fill");
    let folder = trials(&dir);
    let out = dir.join("filled");
    // `doma fill --shard 0/2` of the folder: its trials 0 and 2, without a fit.
    let done = doma()
        .args([
            "fill",
            folder.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--no-fit",
        ])
        .args(["--shard", "0/2"])
        .output()
        .unwrap();
    assert!(done.status.success(), "{}", text(&done.stderr));
    let written = |out: &Path| -> BTreeSet<String> {
        std::fs::read_dir(out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".c3d"))
            .collect()
    };
    assert_eq!(
        written(&out),
        ["trial0.c3d", "trial2.c3d"].map(String::from).into()
    );
    // `doma batch` of a pattern, shard 1 of 2 from Slurm's environment: trial 1, fitted.
    let pattern = folder.join("trial*.c3d");
    let done = doma()
        .args([
            "batch",
            pattern.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ])
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env("SLURM_ARRAY_TASK_COUNT", "2")
        .output()
        .unwrap();
    assert!(done.status.success(), "{}", text(&done.stderr));
    assert_eq!(written(&out).len(), 3);
    let table = std::fs::read_to_string(out.join("trial1.gaps.csv")).unwrap();
    assert!(
        table.lines().nth(1).unwrap().starts_with("M1,10,17,"),
        "{table}"
    );
    // A pattern that matches nothing is refused, naming it.
    let none = doma()
        .args([
            "fill",
            folder.join("*.trc").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!none.status.success() && text(&none.stderr).contains("no file matches"));
}

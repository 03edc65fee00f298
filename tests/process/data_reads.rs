//! A fit reads its data file once: a new fit through the command line's own code (plain,
//! with `--h-weight auto`, and DPF), and a resumed one. Its own process, since the count
//! ([`doma::data::sequence::sequence_reads`]) is process-wide.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use burn::tensor::Device;
use doma::cli::Cli;
use doma::data::sequence::sequence_reads;
use doma::run::{FitOutcome, RunDir, RunSpec, fit_run};
use doma::train::select::WeightSearch;

fn faerie() -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("data/md2_faerie.traj")
        .display()
        .to_string()
}

/// The sequence files that `f` reads.
fn reads(f: impl FnOnce()) -> usize {
    let before = sequence_reads();
    f();
    sequence_reads() - before
}

/// `doma fit` with `args`, run in this process as the binary runs it.
fn doma_fit(args: &[&str]) {
    use clap::Parser;
    let cli = Cli::try_parse_from([&["doma", "fit"], args].concat()).unwrap();
    cli.command.run().unwrap();
}

#[test]
fn a_fit_parses_its_data_once() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).display().to_string();
    let data = faerie();
    let clip = ["--frames", "112..116", "--iters", "2", "--quiet"];
    let plain = out("plain");
    let n = reads(|| doma_fit(&[&[&data[..], "--out", &plain][..], &clip].concat()));
    assert_eq!(n, 1, "a new fit");
    let auto = out("auto");
    let search = [
        "--h-weight",
        "auto",
        "--weight-grid",
        "0,0.1",
        "--search-iters",
        "1",
    ];
    let n = reads(|| doma_fit(&[&[&data[..], "--out", &auto][..], &clip, &search].concat()));
    assert_eq!(n, 1, "a new fit with its weight search");
    let dpf = out("dpf");
    let n =
        reads(|| doma_fit(&[&[&data[..], "--out", &dpf, "--variant", "dpf"][..], &clip].concat()));
    assert_eq!(n, 1, "a new DPF fit, whose size is the data's frame count");

    // Interrupted after one iteration, then resumed: one read each.
    let spec = RunSpec {
        data: Some(data.into()),
        frames: Some([112, 116]),
        iterations: Some(3),
        ..RunSpec::default()
    };
    let run = RunDir::new(out("resumed"));
    let never = AtomicBool::new(false);
    let device = Device::flex();
    let n = reads(|| {
        let new = spec.prepare(&WeightSearch::default(), |_| {}).unwrap();
        let outcome = fit_run(&run, Some(new), &device, &never, Some(1), false).unwrap();
        assert!(
            matches!(outcome, FitOutcome::Interrupted { .. }),
            "{outcome:?}"
        );
    });
    assert_eq!(n, 1, "a new fit, interrupted");
    let n = reads(|| {
        let outcome = fit_run(&run, None, &device, &never, None, false).unwrap();
        assert!(matches!(outcome, FitOutcome::Finished(_)), "{outcome:?}");
    });
    assert_eq!(n, 1, "a resumed fit");
}

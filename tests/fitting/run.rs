//! Run folders: a resumed fit reaches bit-exactly the weights of an uninterrupted one, a
//! non-finite loss leaves the last good checkpoint in place, and eval / warp / info read a
//! finished run.

use crate::common;

use doma::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use burn::tensor::Device;
use common::{backward_lock, new_fit};
use doma::DomaError;
use doma::checkpoint::Precision;
use doma::field::model::Model;
use doma::field::{DomaFieldConfig, Variant};
use doma::jacobian::JacobianKind;
use doma::run::{FitOutcome, RunConfig, RunDir, eval_run, fit_run, info, warp_run};
use doma::train::{FitConfig, IterationRecord};

fn faerie() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/md2_faerie.traj")
}

/// A run folder that does not exist yet, and the scratch folder that holds it.
fn run_dir(tag: &str) -> (common::Scratch, RunDir) {
    let dir = temp(tag);
    let run = RunDir::new(dir.to_path_buf());
    (dir, run)
}

fn temp(tag: &str) -> common::Scratch {
    common::scratch_path(&format!("doma-run-{tag}"))
}

fn config() -> RunConfig {
    let fit = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(32))
        .with_iterations(6)
        .with_smoothness_weight(0.1)
        .with_jacobian(JacobianKind::Analytic)
        .with_seed(3);
    let mut c = RunConfig::new(faerie(), fit);
    c.test_fraction = 0.75;
    c.frames = Some([112, 118]);
    c.checkpoint_every = 2;
    c
}

fn weights(run: &RunDir, c: &RunConfig) -> Vec<doma::siren::LayerWeights> {
    match run.load_field(c, &Device::flex()).unwrap() {
        Model::Doma(field) => field.siren.to_weights(),
        other => panic!("a DOMA run loaded as {other:?}"),
    }
}

#[test]
fn a_resumed_fit_equals_an_uninterrupted_one_bit_exactly() {
    let _g = backward_lock();
    let device = Device::flex();
    let never = AtomicBool::new(false);
    let (_whole_dir, whole) = run_dir("whole");
    let outcome = fit_run(&whole, new_fit(config()), &device, &never, None, false).unwrap();
    assert!(matches!(outcome, FitOutcome::Finished(_)));

    // Interrupted after 3 iterations (between two checkpoints), then resumed twice over.
    let (_parts_dir, parts) = run_dir("parts");
    let outcome = fit_run(&parts, new_fit(config()), &device, &never, Some(3), false).unwrap();
    assert_eq!(outcome, FitOutcome::Interrupted { iterations_done: 3 });
    assert!(
        !parts.model().exists(),
        "no final model before the fit ends"
    );
    let outcome = fit_run(&parts, None, &device, &never, Some(5), false).unwrap();
    assert_eq!(outcome, FitOutcome::Interrupted { iterations_done: 5 });
    let FitOutcome::Finished(report) = fit_run(&parts, None, &device, &never, None, false).unwrap()
    else {
        panic!("the resumed fit did not finish");
    };
    assert_eq!(report.iterations, 6);

    let c = config();
    assert_eq!(
        weights(&whole, &c),
        weights(&parts, &c),
        "weights differ after resume"
    );
    // Parameter ids are stable, so the same weights are the same file: a checksum checks a
    // reproduction.
    assert_eq!(
        std::fs::read(whole.model()).unwrap(),
        std::fs::read(parts.model()).unwrap(),
        "model.bpk differs between identical fits"
    );
    let history = |r: &RunDir| -> Vec<(f64, f64)> {
        let h: Vec<IterationRecord> =
            serde_json::from_str(&std::fs::read_to_string(r.history()).unwrap()).unwrap();
        h.iter()
            .map(|r| (r.trajectory_loss, r.total_loss))
            .collect()
    };
    assert_eq!(history(&whole), history(&parts));
    // A finished run cannot be started again in the same folder.
    assert!(matches!(
        fit_run(&whole, new_fit(config()), &device, &never, None, false),
        Err(DomaError::RunExists(_))
    ));
}

#[test]
fn a_non_finite_loss_keeps_the_last_good_checkpoint() {
    let _g = backward_lock();
    let device = Device::flex();
    let never = AtomicBool::new(false);
    let (_run_dir, run) = run_dir("nan");
    fit_run(&run, new_fit(config()), &device, &never, Some(2), false).unwrap();
    let good = std::fs::read(run.resume()).unwrap();
    // Make the continuation diverge: an absurd learning rate overflows the outputs.
    let mut c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.config()).unwrap()).unwrap();
    c["fit"]["schedule"]["learning_rate"] = serde_json::json!(1e37);
    std::fs::write(run.config(), c.to_string()).unwrap();
    match fit_run(&run, None, &device, &never, None, false) {
        Err(DomaError::NonFiniteLoss { iteration, .. }) => assert!(iteration >= 2),
        other => panic!("expected NonFiniteLoss, got {other:?}"),
    }
    assert_eq!(
        std::fs::read(run.resume()).unwrap(),
        good,
        "the checkpoint was overwritten"
    );
}

#[test]
fn eval_warp_and_info_read_a_finished_run() {
    let _g = backward_lock();
    let device = Device::flex();
    let never = AtomicBool::new(false);
    let (_run_dir, run) = run_dir("done");
    // Trans: `y = x + o` starts near the identity, so even a short fit keeps the shape.
    let mut c = config();
    c.fit = FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(32))
        .with_iterations(6)
        .with_smoothness_weight(0.1)
        .with_jacobian(JacobianKind::Analytic)
        .with_seed(3);
    let FitOutcome::Finished(report) =
        fit_run(&run, new_fit(c), &device, &never, None, false).unwrap()
    else {
        panic!()
    };
    // 75 % of 366 vertices held out, 6 frames.
    assert_eq!((report.points, report.frames), (274, 6));
    let again = eval_run(&run, None, &device).unwrap();
    assert_eq!(again.epe_x1e4, report.epe_x1e4);
    // On the whole sequence's first 6 frames of the clip, as new data: all 366 points.
    let clip_dir = temp("clip");
    let clip = clip_dir.with_extension("traj");
    let seq = doma::data::traj::read_traj(faerie()).unwrap();
    doma::data::traj::write_traj(&clip, &seq.select_frames(112..118, 1).unwrap()).unwrap();
    let on_new = eval_run(&run, Some(&clip), &device).unwrap();
    assert_eq!(on_new.points, 366);
    assert!(on_new.evaluated_on.contains("every point"));

    let out = temp("frames");
    let mesh = faerie().with_extension("obj");
    let paths = warp_run(&run, Some(&mesh), &out, Some(1..3), &device).unwrap();
    assert_eq!(paths.len(), 2);
    let warped = doma::data::mesh::read_obj(&paths[0]).unwrap();
    let canonical = doma::data::mesh::read_obj(&mesh).unwrap();
    assert_eq!(warped.faces, canonical.faces);
    // In the data's own units (the model is about 52 tall), not the normalised ones (≤ 2).
    let height = |m: &doma::data::mesh::TriMesh| {
        let zs = m.vertices.iter().map(|v| v[2]);
        zs.clone().fold(f32::MIN, f32::max) - zs.fold(f32::MAX, f32::min)
    };
    assert!(
        (height(&warped) / height(&canonical) - 1.0).abs() < 0.3,
        "{}",
        height(&warped)
    );
    assert!(warp_run(&run, Some(&mesh), &out, Some(4..9), &device).is_err());
    // Without --mesh: the run's own canonical frame (the clip's first frame) and faces.
    let own = warp_run(&run, None, &out, Some(0..1), &device).unwrap();
    let own = doma::data::mesh::read_obj(&own[0]).unwrap();
    assert_eq!(own.faces, canonical.faces);
    let clip0 = doma::data::traj::read_traj(faerie())
        .unwrap()
        .select_frames(112..113, 1)
        .unwrap();
    let err: f32 = own
        .vertices
        .iter()
        .flatten()
        .zip(clip0.positions())
        .map(|(a, b)| (a - b).abs())
        .sum::<f32>()
        / clip0.positions().len() as f32;
    assert!(err < 3.0, "mean |Δ| {err} (the model is about 52 tall)");

    // Plots: valid PNGs (signature, header, and pixel data that inflates to the size).
    let plots = doma::run::plot_run(&run, Some(&[0, 5]), &device).unwrap();
    assert_eq!(plots.len(), 4);
    for path in &plots {
        let png = std::fs::read(path).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(&png[12..16], b"IHDR");
        let w = u32::from_be_bytes(png[16..20].try_into().unwrap()) as usize;
        let h = u32::from_be_bytes(png[20..24].try_into().unwrap()) as usize;
        let idat_len = u32::from_be_bytes(png[33..37].try_into().unwrap()) as usize;
        assert_eq!(&png[37..41], b"IDAT");
        let zlib = &png[41..41 + idat_len];
        let mut out = vec![0u8; h * (1 + 3 * w)];
        let (status, _, n) = miniz_oxide::inflate::core::decompress(
            &mut Box::<miniz_oxide::inflate::core::DecompressorOxide>::default(),
            &zlib[2..zlib.len() - 4],
            &mut out,
            0,
            miniz_oxide::inflate::core::inflate_flags::TINFL_FLAG_USING_NON_WRAPPING_OUTPUT_BUF,
        );
        assert_eq!(
            (status, n),
            (miniz_oxide::inflate::TINFLStatus::Done, out.len()),
            "{path:?}"
        );
    }
    assert!(doma::run::plot_run(&run, Some(&[6]), &device).is_err());

    let i = info(&run).unwrap();
    assert_eq!((i.params, i.frames, i.points), (2_371, 6, 366));
    assert_eq!(i.iterations_done, 6);
    assert!(i.checkpoint_bytes > 0);

    // A folder that is not a run.
    let empty = temp("empty");
    std::fs::create_dir_all(&empty).unwrap();
    match info(&RunDir::new(&empty)) {
        Err(DomaError::Malformed { reason, .. }) => assert!(reason.contains("not a doma run")),
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_unfinished_run_is_read_in_memory_without_writing_into_its_folder() {
    let _g = backward_lock();
    let device = Device::flex();
    let never = AtomicBool::new(false);
    let (_run_dir, run) = run_dir("unfinished");
    fit_run(&run, new_fit(config()), &device, &never, Some(2), false).unwrap();
    let listing = |dir: &std::path::Path| -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    let before = listing(&run.dir);
    let report = eval_run(&run, None, &device).unwrap();
    assert!(report.epe_x1e4.is_finite());
    assert_eq!(listing(&run.dir), before, "eval wrote into the run folder");
    // The field read from the checkpoint is the one the fit had reached: the same
    // as that run's own report after finishing.
    let FitOutcome::Finished(done) = fit_run(&run, None, &device, &never, None, false).unwrap()
    else {
        panic!()
    };
    assert_eq!(
        eval_run(&run, None, &device).unwrap().epe_x1e4,
        done.epe_x1e4
    );
}

/// Every float parameter times NaN.
struct Poison;

impl burn::module::ModuleMapper for Poison {
    fn map_float<const D: usize>(
        &mut self,
        param: burn::module::Param<burn::tensor::Tensor<D>>,
    ) -> burn::module::Param<burn::tensor::Tensor<D>> {
        param.map(|t| t.mul_scalar(f64::NAN))
    }
}

#[test]
fn nan_weights_are_blamed_on_model_bpk_not_on_the_data() {
    use burn::module::Module;
    let _g = backward_lock();
    let device = Device::flex();
    let never = AtomicBool::new(false);
    let (_run_dir, run) = run_dir("poison");
    let mut c = config();
    c.fit = c.fit.with_iterations(1);
    fit_run(&run, new_fit(c.clone()), &device, &never, None, false).unwrap();
    let poisoned = run.load_field(&c, &device).unwrap().map(&mut Poison);
    std::fs::write(run.model(), poisoned.encode(Precision::F32).unwrap()).unwrap();
    match eval_run(&run, None, &device) {
        Err(DomaError::Malformed { path, reason }) => {
            assert_eq!(path, run.model());
            assert!(reason.contains("NaN"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_sequence_too_small_to_split_names_its_file() {
    let one_point = doma::data::Trajectories::new(3, 1, vec![0.0; 9]).unwrap();
    let fit = FitConfig::doma(DomaFieldConfig::new(Variant::Trans));
    let mut run = RunConfig::new(PathBuf::from("/data/one_point.traj"), fit);
    run.test_fraction = 0.75;
    let err = run.split(&one_point).unwrap_err().to_string();
    assert!(
        err.contains("one_point.traj") && err.contains("--test-fraction"),
        "{err}"
    );
}

#[test]
fn an_edited_config_json_is_refused_naming_the_field_or_both_files() {
    let _g = backward_lock();
    let device = Device::flex();
    let never = AtomicBool::new(false);
    let (_run_dir, run) = run_dir("edited");
    let mut c = config();
    c.fit = FitConfig::doma(DomaFieldConfig::new(Variant::Trans).with_hidden(16))
        .with_iterations(2)
        .with_jacobian(JacobianKind::Analytic);
    fit_run(&run, new_fit(c), &device, &never, None, false).unwrap();
    let original = std::fs::read_to_string(run.config()).unwrap();
    let mut value: serde_json::Value = serde_json::from_str(&original).unwrap();
    // A field that no run config has: refused, not ignored.
    value["fit"]["schedule"]["iterationz"] = serde_json::json!(0);
    std::fs::write(run.config(), value.to_string()).unwrap();
    let err = eval_run(&run, None, &device).unwrap_err().to_string();
    assert!(
        err.contains("config.json") && err.contains("fit.schedule.iterationz"),
        "{err}"
    );
    // A model that model.bpk does not hold: both files are named.
    let mut value: serde_json::Value = serde_json::from_str(&original).unwrap();
    value["fit"]["model"]["doma"]["shape"]["hidden"] = serde_json::json!(32);
    std::fs::write(run.config(), value.to_string()).unwrap();
    let err = eval_run(&run, None, &device).unwrap_err().to_string();
    assert!(
        err.contains("model.bpk") && err.contains("config.json"),
        "{err}"
    );
}

//! Fitting tracker output: complete tracks fit exactly as complete trajectories do, held-out
//! observations are reported beside the two baselines, and `complete` writes every track
//! at every frame in the input's order, with the input's observations untouched.

use crate::common::{self, new_fit};

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use burn::tensor::Device;
use doma::data::c3d::{C3d, read_c3d, write_c3d};
use doma::data::layout::{Layout, TrackFile, read_npz_tracks};
use doma::data::npy::read_npz;
use doma::data::tracker::TrackerView;
use doma::data::traj::write_traj;
use doma::field::{DomaFieldConfig, Variant};
use doma::jacobian::JacobianKind;
use doma::run::{
    FillPolicy, FitOutcome, MaxGap, Report, RunConfig, RunDir, complete_run, complete_run_with,
    eval_run, fit_run,
};
use doma::siren::WithSirenShape;
use doma::train::{Convergence, FitConfig, WithSchedule};
use doma_formats::npy::NpyValues;
use doma_formats::npz::encode_npz_values;

fn view() -> TrackerView {
    common::faerie_tracker_view(112..120).0
}

fn fit(data: &Path, run: &RunDir, edit: impl FnOnce(&mut RunConfig)) -> Report {
    let config = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(32))
        .with_iterations(4)
        .with_smoothness_weight(0.1)
        .with_jacobian(JacobianKind::Analytic)
        .with_seed(2);
    let mut c = RunConfig::new(data.to_path_buf(), config);
    c.test_fraction = 0.25;
    edit(&mut c);
    let never = AtomicBool::new(false);
    let _g = common::backward_lock();
    match fit_run(run, new_fit(c), &Device::flex(), &never, None, false).unwrap() {
        FitOutcome::Finished(report) => report,
        other => panic!("{other:?}"),
    }
}

#[test]
fn complete_tracks_in_a_tracker_layout_fit_bit_for_bit_as_complete_trajectories() {
    let v = view();
    let dir = common::scratch("doma-allvisible");
    let (traj, npz) = (dir.join("clip.traj"), dir.join("clip.npz"));
    write_traj(&traj, &v.truth).unwrap();
    let (t, n) = (v.truth.frames(), v.truth.points());
    let all = vec![true; t * n];
    std::fs::write(
        &npz,
        encode_npz_values(&[
            (
                "tracks_XYZ",
                &[t, n, 3],
                NpyValues::F32(v.truth.positions()),
            ),
            ("visibility", &[t, n], NpyValues::Bool(&all)),
        ]),
    )
    .unwrap();
    let a = fit(&traj, &RunDir::new(dir.join("a")), |_| {});
    let b = fit(&npz, &RunDir::new(dir.join("b")), |_| {});
    assert_eq!(a.epe_x1e4.to_bits(), b.epe_x1e4.to_bits());
    assert_eq!(a.epe_per_frame_x1e4, b.epe_per_frame_x1e4);
}

/// Real recordings have frames where no marker is seen (a subject who walks out of the
/// capture volume): such frames add nothing to the fit, which neither panics nor moves on
/// them, with or without `L_H`, with every point or a subset per step.
#[test]
fn frames_where_nothing_is_observed_add_nothing_and_never_panic() {
    let v = view();
    let dir = common::scratch("doma-emptyframes");
    let npz = dir.join("clip.npz");
    let (t, n) = (v.truth.frames(), v.truth.points());
    let mut observed = v.observed();
    for k in [2, 3, t - 1] {
        observed[k * n..(k + 1) * n].fill(false);
    }
    std::fs::write(
        &npz,
        encode_npz_values(&[
            ("tracks", &[t, n, 3], NpyValues::F32(v.truth.positions())),
            ("observed", &[t, n], NpyValues::Bool(&observed)),
        ]),
    )
    .unwrap();
    for (i, (w_h, subset)) in [(0.0, None), (0.0, Some(16)), (0.1, None)]
        .into_iter()
        .enumerate()
    {
        let report = fit(&npz, &RunDir::new(dir.join(format!("r{i}"))), |c| {
            c.fit.loss.smoothness_weight = w_h;
            c.fit.points_per_step = subset;
            c.drop_unobserved = true;
        });
        assert!(report.epe_x1e4.is_finite(), "{w_h} {subset:?}: {report:?}");
        // Nothing observed there: nothing to measure.
        assert!(report.epe_per_frame_x1e4[2].is_nan(), "{report:?}");
    }
    // The completion fills the empty frames too, every value finite.
    let out = dir.join("complete.npz");
    let done = complete_run_with(
        &RunDir::new(dir.join("r2")),
        &out,
        None,
        EVERY_ENTRY,
        &Device::flex(),
    )
    .unwrap();
    let (filled, _) = doma::data::sequence::read_tracks(&out, &TrackFile::default()).unwrap();
    assert_eq!(done.frames, t);
    assert!(filled.positions().iter().all(|v| v.is_finite()));
    assert_eq!(
        done.observed + done.filled + done.extrapolated,
        t * done.tracks
    );
    // The last frame sees nothing: every track's run past its last observation.
    assert!(done.extrapolated >= done.tracks && done.unfilled == 0);
}

#[test]
fn held_out_observations_are_reported_beside_every_baseline_and_eval_repeats_them() {
    let v = view();
    let dir = common::scratch("doma-holdout");
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let run = RunDir::new(dir.join("run"));
    let report = fit(&npz, &run, |c| {
        c.drop_unobserved = true;
        c.holdout_observations = Some(0.2);
    });
    let gaps = report.held_out_observations.clone().expect("a gap report");
    assert!(gaps.entries > 0);
    for m in [gaps.epe_x1e4, gaps.distance] {
        let fillers = m
            .fillers
            .iter()
            .map(|(_, e)| e.expect("every filler's error"));
        for e in [m.doma, m.field].into_iter().chain(fillers) {
            assert!(e.is_finite() && e > 0.0, "{gaps:?}");
        }
    }
    // doma's fill: convex weights per class of gaps, validated on entries of this data.
    let blend = gaps.blend.clone().expect("the fill's weights");
    assert!(blend.validated.iter().sum::<usize>() > 0, "{blend:?}");
    let by_length = blend.by_length.iter().map(|b| b.weights);
    for w in [blend.short, blend.long].into_iter().chain(by_length) {
        assert!(w.0.iter().all(|&v| v >= 0.0), "{blend:?}");
        assert!((w.0.iter().sum::<f64>() - 1.0).abs() < 1e-9, "{blend:?}");
    }
    // Held out of their choice, the short and the pooled long gaps' weights never do worse
    // than their best filler alone.
    let held: Vec<_> = blend.held_out.iter().flatten().collect();
    assert!(!held.is_empty(), "{blend:?}");
    for h in held {
        assert!(h.chosen <= h.best_alone * (1.0 + 1e-9), "{h:?}");
    }
    let again = eval_run(&run, None, &Device::flex()).unwrap();
    assert_eq!(again.held_out_observations, Some(gaps));
    assert_eq!(again.epe_x1e4.to_bits(), report.epe_x1e4.to_bits());
    // info tells what the fit saw.
    let about = doma::run::info(&run).unwrap();
    assert!(about.observed_entries.unwrap() < about.frames * about.points);
    assert!(about.reference_frame.unwrap() < about.frames);
    assert!(about.tracks_unseen_in_reference.is_some());
    assert_eq!(about.test_fraction, 0.25);
    assert!(about.fitted_tracks < about.points && about.fitted_tracks > 0);
    // The plots of a run with gaps: the points observed in each plotted frame, and its
    // longest gaps as they are filled.
    let plots = doma::run::plot_run(&run, None, &Device::flex()).unwrap();
    assert!(
        plots.len() >= 3 && plots.iter().all(|p| p.is_file()),
        "{plots:?}"
    );
    let gaps = plots
        .iter()
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("gap_"))
        .count();
    assert_eq!(gaps, doma::run::GAP_FIGURES, "{plots:?}");
}

/// With blind validation (a new fit's default) the fit never sees the validation spans,
/// the field's fills are weighed on them alone, and the completion still returns them as
/// observed.
#[test]
fn blind_validation_spans_are_hidden_from_the_fit_and_validate_the_blend() {
    let v = view();
    let dir = common::scratch("doma-blind-fit");
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let run = RunDir::new(dir.join("run"));
    let report = fit(&npz, &run, |c| {
        c.drop_unobserved = true;
        c.test_fraction = 0.0;
        c.holdout_observations = Some(0.2);
    });
    let config = run.load_config().unwrap();
    assert!(config.blind_validation);
    let data = run.load_data(&config).unwrap();
    let blind = data.blind.clone().expect("blind spans");
    let held = data.held_out.clone().expect("held-out spans");
    let n = data.trajectories.points();
    let fitted = data.trajectories.observed().unwrap();
    assert!(blind.entries.iter().all(|&(k, i)| !fitted[k * n + i]));
    assert!(
        blind
            .entries
            .iter()
            .all(|e| held.entries.binary_search(e).is_err())
    );
    // The report's blend weighs the field's fills on the blind spans alone.
    let gaps = report.held_out_observations.expect("a gap report");
    let learned = gaps.blend.expect("the fill's weights");
    assert_eq!(learned.field_validated, blind.entries.len());

    let done = doma::run::complete_tracks(&run, FillPolicy::default(), &Device::flex()).unwrap();
    assert_eq!(done.blend.field_validated, blind.entries.len());
    let (input, _) = doma::data::sequence::read_tracks(&npz, &TrackFile::default()).unwrap();
    let kept = data.kept.clone().unwrap_or_else(|| (0..n).collect());
    let input = input.select_points(&kept);
    for &(k, i) in &blind.entries {
        let e = k * n + i;
        assert!(done.observed[e] && !done.filled[e]);
        assert_eq!(
            done.tracks[3 * e..3 * e + 3],
            input.positions()[3 * e..3 * e + 3]
        );
    }
}

/// A completion of every unobserved entry, past the tracks' ends too.
const EVERY_ENTRY: FillPolicy = FillPolicy {
    max_gap: None,
    extrapolate: Some(true),
    method: None,
};

/// A completion fills the gaps with observations on both sides, and past a track's ends
/// where asked: by default for a tracker's file, never for a recording; `max_gap` leaves
/// longer gaps; seconds need a rate.
#[test]
fn a_completion_fills_what_its_policy_asks_for() {
    let v = view();
    let dir = common::scratch("doma-policy");
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let run = RunDir::new(dir.join("run"));
    fit(&npz, &run, |c| c.drop_unobserved = true);
    let read = |policy: FillPolicy| {
        let out = dir.join("done.npz");
        let done = complete_run_with(&run, &out, None, policy, &Device::flex()).unwrap();
        let (tracks, _) = doma::data::sequence::read_tracks(&out, &TrackFile::default()).unwrap();
        // The completion in memory is the file's, its masks the printed counts.
        let memory = doma::run::complete_tracks(&run, policy, &Device::flex()).unwrap();
        let same = |a: &f32, b: &f32| a.to_bits() == b.to_bits();
        assert!(
            memory
                .tracks
                .iter()
                .zip(tracks.positions())
                .all(|(a, b)| same(a, b))
        );
        assert_eq!(memory.observed, tracks.observed());
        let count = |mask: &[bool]| mask.iter().filter(|&&f| f).count();
        assert_eq!(count(&memory.extrapolated), done.extrapolated);
        assert_eq!(count(&memory.filled), done.filled + done.extrapolated);
        assert!(
            memory
                .extrapolated
                .iter()
                .zip(&memory.filled)
                .all(|(&x, &f)| f || !x)
        );
        (done, tracks)
    };
    let (every, all) = read(EVERY_ENTRY);
    let bounded = FillPolicy {
        extrapolate: Some(false),
        ..FillPolicy::default()
    };
    let (inner, some) = read(bounded);
    // A tracker's file is filled at every point of every frame unless told otherwise.
    let (default, _) = read(FillPolicy::default());
    assert_eq!(
        (default.filled, default.extrapolated, default.unfilled),
        (every.filled, every.extrapolated, every.unfilled)
    );
    let by_default =
        |path: &Path, file: &TrackFile| doma::run::extrapolates_by_default(path, file).unwrap();
    assert!(by_default(&npz, &TrackFile::default()));
    let masked = TrackFile {
        layout: Some(Layout::Masked),
        ..TrackFile::default()
    };
    assert!(!by_default(&npz, &masked));
    let recording = dir.join("walk.c3d");
    assert!(!by_default(&recording, &TrackFile::default()));
    let (t, n) = (all.frames(), all.points());
    assert_eq!((inner.filled, inner.extrapolated), (every.filled, 0));
    assert_eq!(inner.unfilled, every.extrapolated);
    assert!(inner.unfilled > 0 && inner.filled > 0);
    let seen = all.observed();
    for i in 0..n {
        let first = (0..t).find(|&k| seen[k * n + i]);
        let last = (0..t).rev().find(|&k| seen[k * n + i]);
        for k in 0..t {
            let e = 3 * (k * n + i);
            let edge = first.is_none_or(|f| k < f) || last.is_none_or(|l| k > l);
            if edge {
                assert!(some.positions()[e].is_nan(), "frame {k}, track {i}");
            } else {
                assert_eq!(some.positions()[e..e + 3], all.positions()[e..e + 3]);
            }
        }
    }
    let (none, _) = read(FillPolicy {
        max_gap: Some(MaxGap::Frames(0)),
        extrapolate: Some(false),
        method: None,
    });
    assert_eq!((none.filled, none.extrapolated), (0, 0));
    let seconds = FillPolicy {
        max_gap: Some(MaxGap::Seconds(0.5)),
        extrapolate: Some(false),
        method: None,
    };
    let refused = complete_run_with(&run, &dir.join("x.npz"), None, seconds, &Device::flex());
    assert!(
        matches!(&refused, Err(doma::DomaError::Usage(m)) if m.contains("no frame rate")),
        "{refused:?}"
    );
    assert!(!dir.join("x.npz").exists());
    assert_eq!("12".parse(), Ok(MaxGap::Frames(12)));
    assert_eq!("0.25s".parse(), Ok(MaxGap::Seconds(0.25)));
    assert!("-1s".parse::<MaxGap>().is_err() && "a".parse::<MaxGap>().is_err());
}

#[test]
fn a_completed_file_has_the_input_s_shape_order_and_observations() {
    let v = view();
    let dir = common::scratch("doma-complete");
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let run = RunDir::new(dir.join("run"));
    fit(&npz, &run, |c| c.drop_unobserved = true);
    let input = read_npz_tracks(&npz, &TrackFile::default()).unwrap();
    let (t, n) = (input.frames(), input.points());
    let out = dir.join("done.npz");
    let done = complete_run_with(&run, &out, None, EVERY_ENTRY, &Device::flex()).unwrap();
    let members = read_npz(&out).unwrap();
    let get = |k: &str| members.iter().find(|m| m.0 == k).unwrap().1.clone();
    let kept: Vec<usize> = get("kept").data.iter().map(|&i| i as usize).collect();
    assert!(kept.len() < n && kept.windows(2).all(|w| w[0] < w[1]));
    let m = kept.len();
    assert_eq!((done.frames, done.tracks), (t, m));
    let (tracks, observed) = (get("tracks"), get("observed"));
    assert_eq!(
        (tracks.shape, observed.shape.clone()),
        (vec![t, m, 3], vec![t, m])
    );
    for k in 0..t {
        for (r, &i) in kept.iter().enumerate() {
            let seen = input.observed()[k * n + i];
            assert_eq!(observed.data[k * m + r] == 1.0, seen);
            let got = &tracks.data[3 * (k * m + r)..3 * (k * m + r) + 3];
            let had = &input.positions()[3 * (k * n + i)..3 * (k * n + i) + 3];
            if seen {
                assert_eq!(got, had, "frame {k}, track {i}");
            } else {
                assert!(got.iter().all(|x| x.is_finite()));
            }
        }
    }
    assert_eq!(
        done.filled + done.extrapolated,
        observed.data.iter().filter(|&&o| o == 0.0).count()
    );
    // The default keys are the masked layout, so the completed file is data for a new fit.
    let again = read_npz_tracks(&out, &TrackFile::default()).unwrap();
    assert_eq!(again.positions(), &tracks.data[..]);
    assert!(
        again
            .observed()
            .iter()
            .zip(&observed.data)
            .all(|(&a, &b)| a == (b == 1.0))
    );
    // In PointOdyssey's layout the file reads back as tracks whose every entry is valid.
    let po = dir.join("done_po.npz");
    let po_layout = Some(Layout::PointOdyssey);
    complete_run_with(&run, &po, po_layout, EVERY_ENTRY, &Device::flex()).unwrap();
    let back = read_npz_tracks(&po, &TrackFile::default()).unwrap();
    assert_eq!(back.positions(), &tracks.data[..]);
    let counted = read_npz_tracks(
        &po,
        &TrackFile {
            count_hidden: true,
            ..TrackFile::default()
        },
    )
    .unwrap();
    assert!(counted.observed().iter().all(|&o| o));
}

#[test]
fn a_run_config_written_before_tracker_support_still_opens() {
    let v = view();
    let dir = common::scratch("doma-oldconfig");
    let traj = dir.join("clip.traj");
    write_traj(&traj, &v.truth).unwrap();
    let run = RunDir::new(dir.join("run"));
    let report = fit(&traj, &run, |_| {});
    let mut config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.config()).unwrap()).unwrap();
    let top = config.as_object_mut().unwrap();
    for key in [
        "tracks",
        "reference_frame",
        "drop_unobserved",
        "holdout_observations",
    ] {
        assert!(top.remove(key).is_some(), "{key}");
    }
    let fit = top["fit"].as_object_mut().unwrap();
    for key in [
        "frames_per_step",
        "frames_per_iteration",
        "until_converged",
        "recipe",
    ] {
        assert!(fit.remove(key).is_some(), "{key}");
    }
    let schedule = fit["schedule"].as_object_mut().unwrap();
    for key in ["decay", "warmup_iterations"] {
        assert!(schedule.remove(key).is_some(), "{key}");
    }
    let loss = fit["loss"].as_object_mut().unwrap();
    assert!(loss.remove("data_penalty").is_some());
    std::fs::write(run.config(), serde_json::to_string(&config).unwrap()).unwrap();
    let again = eval_run(&run, None, &Device::flex()).unwrap();
    assert_eq!(again.epe_x1e4.to_bits(), report.epe_x1e4.to_bits());
}

#[test]
fn learned_canonical_positions_resume_bit_for_bit_and_are_used_by_eval() {
    let v = view();
    let dir = common::scratch("doma-learned");
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let config = || {
        let fit = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(32))
            .with_iterations(4)
            .with_jacobian(JacobianKind::Analytic)
            .with_seed(5);
        let mut c = RunConfig::new(npz.clone(), fit);
        c.test_fraction = 0.25;
        c.drop_unobserved = true;
        c.checkpoint_every = 1;
        c
    };
    let never = AtomicBool::new(false);
    let device = Device::flex();
    let _g = common::backward_lock();
    let whole = RunDir::new(dir.join("whole"));
    let report = match fit_run(&whole, new_fit(config()), &device, &never, None, false).unwrap() {
        FitOutcome::Finished(r) => r,
        other => panic!("{other:?}"),
    };
    let parts = RunDir::new(dir.join("parts"));
    assert!(matches!(
        fit_run(&parts, new_fit(config()), &device, &never, Some(2), false).unwrap(),
        FitOutcome::Interrupted { iterations_done: 2 }
    ));
    let resumed = match fit_run(&parts, None, &device, &never, None, false).unwrap() {
        FitOutcome::Finished(r) => r,
        other => panic!("{other:?}"),
    };
    let bytes = |run: &RunDir, p: fn(&RunDir) -> PathBuf| std::fs::read(p(run)).unwrap();
    assert_eq!(bytes(&whole, RunDir::model), bytes(&parts, RunDir::model));
    assert_eq!(
        bytes(&whole, RunDir::canonical),
        bytes(&parts, RunDir::canonical)
    );
    assert_eq!(report.epe_x1e4.to_bits(), resumed.epe_x1e4.to_bits());
    // The learned positions moved off their neighbour placement, and eval reads them.
    let placed = whole.load_config().unwrap().load().unwrap();
    let learned = whole.load_data(&whole.load_config().unwrap()).unwrap();
    assert_ne!(
        placed.trajectories.canonical(),
        learned.trajectories.canonical()
    );
    let again = eval_run(&whole, None, &device).unwrap();
    assert_eq!(again.epe_x1e4.to_bits(), report.epe_x1e4.to_bits());
}

#[test]
fn eval_on_another_tracker_file_reads_it_as_the_run_read_its_own() {
    let v = view();
    let dir = common::scratch("doma-eval-other");
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let run = RunDir::new(dir.join("run"));
    fit(&npz, &run, |c| c.drop_unobserved = true);
    // The same file as new data: its never-observed tracks are dropped as the run's were
    // (the default reading refuses them), and every frame has observed entries to measure.
    let report = eval_run(&run, Some(&npz), &Device::flex()).unwrap();
    let kept = doma::data::sequence::load_sequence_with(
        &npz,
        &doma::data::sequence::LoadOptions {
            drop_unobserved: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(report.points, kept.trajectories.points());
    assert!(report.epe_x1e4.is_finite() && report.epe_x1e4 > 0.0);
    assert!(report.epe_per_frame_x1e4.iter().all(|e| e.is_finite()));
}

#[test]
fn a_fit_that_holds_tracks_back_for_convergence_keeps_every_tracks_canonical_position() {
    let v = view();
    let dir = common::scratch("doma-converge-tracks");
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let run = RunDir::new(dir.join("run"));
    let report = fit(&npz, &run, |c| {
        c.drop_unobserved = true;
        c.fit.schedule.iterations = 6;
        c.fit.until_converged = Some(Convergence::new(2).with_every(2));
    });
    assert!(report.epe_x1e4.is_finite());
    let history: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(run.history()).unwrap()).unwrap();
    assert!(history.len() <= 6);
    assert!(history[1]["validation_epe"].as_f64().unwrap().is_finite());
    // The held-back tracks are left where the data placed them; eval reads the run's
    // canonical positions for every training track and repeats the report.
    let again = eval_run(&run, None, &Device::flex()).unwrap();
    assert_eq!(again.epe_x1e4.to_bits(), report.epe_x1e4.to_bits());
}

#[test]
fn a_c3d_clip_completes_into_the_input_file_with_only_the_fitted_gaps_filled() {
    let v = view();
    let dir = common::scratch("doma-c3d-complete");
    let (t, n) = (v.truth.frames(), v.truth.points());
    let seen = v.observed();
    let input = dir.join("markers.c3d");
    // Two gapped tracks are a model's outputs, as Nexus lists joint angles (one by a usual
    // parameter, one by a parameter that TYPE_GROUPS names): never fitted, never filled.
    let fitted: Vec<usize> = (1..t).step_by(2).collect();
    let gapped: Vec<usize> = (0..n)
        .filter(|&i| fitted.iter().any(|&k| !seen[k * n + i]))
        .filter(|&i| fitted.iter().any(|&k| seen[k * n + i]))
        .collect();
    let (angle, muscle) = (gapped[0], gapped[1]);
    let markers = C3d {
        frames: t,
        points: n,
        first_frame: 10,
        rate: 120.0,
        scale: -0.01,
        units: "mm".into(),
        labels: (0..n).map(|i| format!("M{i:03}")).collect(),
        model_outputs: (0..n)
            .map(|i| match i {
                _ if i == angle => Some("ANGLES".into()),
                _ if i == muscle => Some("MUSCLES".into()),
                _ => None,
            })
            .collect(),
        positions: v.truth.positions().to_vec(),
        residuals: seen.iter().map(|&s| if s { 0.5 } else { -1.0 }).collect(),
        cameras: (0..t * n).map(|e| (e % 100) as u8).collect(),
        notes: Vec::new(),
    };
    write_c3d(&input, &markers).unwrap();
    let run = RunDir::new(dir.join("run"));
    fit(&input, &run, |c| {
        c.frames = Some([1, t]);
        c.stride = 2;
        c.drop_unobserved = true;
    });
    let out = dir.join("filled.c3d");
    let done = complete_run_with(&run, &out, None, EVERY_ENTRY, &Device::flex()).unwrap();
    let (back, given) = (read_c3d(&out).unwrap(), read_c3d(&input).unwrap());
    let kept = run.load_data(&run.load_config().unwrap()).unwrap().kept;
    let kept = kept.unwrap_or_else(|| (0..n).collect());
    // The markers seen in a fitted frame, the model outputs left out.
    let expected: Vec<usize> = (0..n)
        .filter(|&i| i != angle && i != muscle)
        .filter(|&i| fitted.iter().any(|&k| seen[k * n + i]))
        .collect();
    assert_eq!(kept, expected);
    // A run fitted before model outputs were told apart fitted every point, and reads so.
    let mut saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.config()).unwrap()).unwrap();
    assert_eq!(saved["model_outputs"], false);
    saved.as_object_mut().unwrap().remove("model_outputs");
    let old: RunConfig = serde_json::from_value(saved).unwrap();
    assert!(old.model_outputs);
    // The input file with only the fitted frames' gaps filled: every frame and marker,
    // its labels, rate and first frame.
    assert_eq!((back.frames, back.points), (t, n));
    assert_eq!(
        (back.first_frame, back.rate, back.units.as_str()),
        (10, 120.0, "mm")
    );
    assert_eq!(back.labels, markers.labels);
    assert_eq!(back.model_outputs, markers.model_outputs);
    let mut filled = 0;
    for k in 0..t {
        for i in 0..n {
            let e = k * n + i;
            let got = &back.positions[3 * e..3 * e + 3];
            if seen[e] || !fitted.contains(&k) || !kept.contains(&i) {
                // As the input holds it: measured, or a gap outside what was fitted.
                assert_eq!(got, &given.positions[3 * e..3 * e + 3]);
                assert_eq!(
                    back.residuals[e], given.residuals[e],
                    "frame {k}, marker {i}"
                );
                assert_eq!(back.cameras[e], given.cameras[e]);
            } else {
                assert!(back.present()[e], "frame {k}, marker {i} is left missing");
                assert!(got.iter().all(|x| x.is_finite()));
                assert_eq!((back.residuals[e], back.cameras[e]), (0.0, 0));
                filled += 1;
            }
        }
    }
    assert!(filled > 0);
    assert_eq!(done.filled + done.extrapolated, filled);
    // A .c3d takes no tracker keys, and needs a C3D input for its labels and rate.
    let refused = complete_run(&run, &out, Some(Layout::TapVid3d), &Device::flex());
    assert!(
        matches!(refused, Err(doma::DomaError::Usage(_))),
        "{refused:?}"
    );
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    let from_npz = RunDir::new(dir.join("npz_run"));
    fit(&npz, &from_npz, |c| c.drop_unobserved = true);
    let refused = complete_run(&from_npz, &dir.join("x.c3d"), None, &Device::flex());
    match refused {
        Err(doma::DomaError::Usage(m)) => assert!(m.contains("clip.npz"), "{m}"),
        other => panic!("{other:?}"),
    }
    assert!(!dir.join("x.c3d").exists());
}

#[test]
fn tracks_with_gaps_take_the_gap_filling_defaults_unless_the_options_set_them() {
    use doma::run::RunSpec;
    use doma::run::{GAP_FILLING_H_WEIGHT, GAP_FILLING_ITERATIONS};
    use doma::train::select::WeightSearch;
    let v = view();
    let dir = common::scratch("doma-gapdefaults");
    let (npz, traj) = (dir.join("clip.npz"), dir.join("clip.traj"));
    v.write(&npz, Layout::TapVid3d).unwrap();
    write_traj(&traj, &v.truth).unwrap();
    let prepared = |data: &Path, edit: fn(&mut RunSpec)| {
        let mut spec = RunSpec {
            data: Some(data.to_path_buf()),
            drop_unobserved: Some(true),
            ..RunSpec::default()
        };
        edit(&mut spec);
        let fit = spec.prepare(&WeightSearch::default(), |_| {}).unwrap();
        let f = &fit.config.fit;
        (f.schedule.iterations, f.loss.smoothness_weight)
    };
    assert_eq!(
        prepared(&npz, |_| {}),
        (GAP_FILLING_ITERATIONS, GAP_FILLING_H_WEIGHT)
    );
    assert_eq!(
        prepared(&npz, |s| s.iterations = Some(20)),
        (20, GAP_FILLING_H_WEIGHT)
    );
    assert_eq!(
        prepared(&npz, |s| s.recipe = Some(doma::train::Recipe::Fast)).0,
        1000
    );
    // Complete data keeps the paper's protocol.
    assert_eq!(prepared(&traj, |_| {}), (1000, 0.0));
    // One fit unless the options ask for more.
    let fits = |edit: fn(&mut RunSpec)| {
        let mut spec = RunSpec {
            data: Some(npz.clone()),
            drop_unobserved: Some(true),
            ..RunSpec::default()
        };
        edit(&mut spec);
        spec.prepare(&WeightSearch::default(), |_| {})
            .unwrap()
            .config
            .fits
    };
    assert_eq!((fits(|_| {}), fits(|s| s.fits = Some(3))), (1, 3));
}

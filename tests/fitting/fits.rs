//! A run that combines several fits (`RunConfig::fits`, `doma fit --fits K`): the other
//! fits are run folders of their own with the next seeds, the completion is their median
//! entry by entry (the mean of two), and an interrupted run resumes into the fit it was in.

use crate::common::{self, new_fit};

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use burn::tensor::Device;
use doma::DomaError;
use doma::data::layout::Layout;
use doma::data::tracker::TrackerView;
use doma::field::{DomaFieldConfig, Variant};
use doma::jacobian::JacobianKind;
use doma::run::{
    CompletedTracks, FillPolicy, FitOutcome, RunConfig, RunDir, complete_tracks, fit_run,
};
use doma::siren::WithSirenShape;
use doma::train::{FitConfig, IterationRecord, Progress, WithSchedule};

const ITERATIONS: usize = 4;

fn config(data: &Path) -> RunConfig {
    let fit = FitConfig::doma(DomaFieldConfig::new(Variant::Affinity).with_hidden(32))
        .with_iterations(ITERATIONS)
        .with_smoothness_weight(0.1)
        .with_jacobian(JacobianKind::Analytic)
        .with_seed(2);
    let mut c = RunConfig::new(data.to_path_buf(), fit);
    c.drop_unobserved = true;
    c.fits = 2;
    c
}

fn clip(dir: &Path) -> std::path::PathBuf {
    let v: TrackerView = common::faerie_tracker_view(112..120).0;
    let npz = dir.join("clip.npz");
    v.write(&npz, Layout::TapVid3d).unwrap();
    npz
}

fn completed(run: &RunDir) -> CompletedTracks {
    complete_tracks(run, FillPolicy::default(), &Device::flex()).unwrap()
}

#[test]
fn two_fits_fill_with_the_mean_of_their_fills() {
    let dir = common::scratch("doma-fits");
    let npz = clip(&dir);
    let run = RunDir::new(dir.join("run"));
    let never = AtomicBool::new(false);
    {
        let _g = common::backward_lock();
        let outcome = fit_run(
            &run,
            new_fit(config(&npz)),
            &Device::flex(),
            &never,
            None,
            false,
        );
        assert!(
            matches!(outcome, Ok(FitOutcome::Finished(_))),
            "{outcome:?}"
        );
    }
    // The second fit: a run folder of its own, fitted with the next seed.
    let member = run.member(2);
    assert!(member.model().is_file());
    let second = member.load_config().unwrap();
    assert_eq!((second.fit.seed, second.fits), (3, 1));
    assert_eq!(run.load_config().unwrap().fits, 2);

    // The run's own fit alone: its folder without the other fit, its config saying one.
    let alone = RunDir::new(dir.join("alone"));
    std::fs::create_dir(&alone.dir).unwrap();
    for f in ["model.bpk", "canonical.npy"] {
        if run.dir.join(f).is_file() {
            std::fs::copy(run.dir.join(f), alone.dir.join(f)).unwrap();
        }
    }
    let mut own = run.load_config().unwrap();
    own.fits = 1;
    std::fs::write(alone.config(), serde_json::to_vec(&own).unwrap()).unwrap();

    let (both, a, b) = (completed(&run), completed(&alone), completed(&member));
    assert_eq!(
        (both.filled.clone(), both.observed.clone()),
        (a.filled.clone(), a.observed.clone())
    );
    assert_eq!(both.filled, b.filled);
    let mut differ = 0;
    for (e, _) in both.filled.iter().enumerate().filter(|&(_, &f)| f) {
        for d in 3 * e..3 * e + 3 {
            assert_eq!(
                both.tracks[d],
                0.5 * (a.tracks[d] + b.tracks[d]),
                "entry {e}"
            );
            differ += usize::from(a.tracks[d] != b.tracks[d]);
        }
    }
    assert!(differ > 0, "the two fits filled every entry alike");
    // The observed entries are the input's, whatever the fits.
    for (e, _) in both.observed.iter().enumerate().filter(|&(_, &o)| o) {
        assert_eq!(both.tracks[3 * e..3 * e + 3], a.tracks[3 * e..3 * e + 3]);
    }

    // A run whose other fit is gone is refused, naming its folder.
    std::fs::remove_dir_all(&member.dir).unwrap();
    let refused = complete_tracks(&run, FillPolicy::default(), &Device::flex()).unwrap_err();
    assert!(refused.to_string().contains("fits"), "{refused}");
}

#[test]
fn a_run_interrupted_in_its_second_fit_resumes_there_bit_for_bit() {
    let dir = common::scratch("doma-fits-resume");
    let npz = clip(&dir);
    let (whole, parts) = (
        RunDir::new(dir.join("whole")),
        RunDir::new(dir.join("parts")),
    );
    let device = Device::flex();
    let never = AtomicBool::new(false);
    let _g = common::backward_lock();
    fit_run(&whole, new_fit(config(&npz)), &device, &never, None, false).unwrap();

    // Interrupted two iterations into the second fit (the hook is polled after each one).
    let interrupt = AtomicBool::new(false);
    let seen = AtomicUsize::new(0);
    let each = |_: &IterationRecord, _: usize| -> doma::Result<()> {
        if seen.fetch_add(1, Ordering::SeqCst) + 1 == ITERATIONS + 2 {
            interrupt.store(true, Ordering::SeqCst);
        }
        Ok(())
    };
    let outcome = fit_run(
        &parts,
        new_fit(config(&npz)),
        &device,
        &interrupt,
        None,
        Progress::Each(Box::new(each)),
    )
    .unwrap();
    assert_eq!(outcome, FitOutcome::Interrupted { iterations_done: 2 });
    assert!(parts.model().is_file() && !parts.member(2).model().is_file());
    let refused = complete_tracks(&parts, FillPolicy::default(), &device).unwrap_err();
    assert!(refused.to_string().contains("--resume"), "{refused}");

    let FitOutcome::Finished(report) = fit_run(&parts, None, &device, &never, None, false).unwrap()
    else {
        panic!("the resumed run did not finish");
    };
    assert_eq!(report.iterations, ITERATIONS);
    for (a, b) in [
        (whole.model(), parts.model()),
        (whole.member(2).model(), parts.member(2).model()),
    ] {
        assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    }
    // Bit for bit, NaN (unfilled) entries included.
    let bits =
        |run: &RunDir| -> Vec<u32> { completed(run).tracks.iter().map(|v| v.to_bits()).collect() };
    assert!(
        bits(&whole) == bits(&parts),
        "the resumed run fills otherwise"
    );
    // A finished run resumed again fits nothing more.
    assert!(matches!(
        fit_run(&parts, None, &device, &never, None, false),
        Ok(FitOutcome::Finished(_))
    ));
}

#[test]
fn a_fit_count_out_of_range_is_refused() {
    let dir = common::scratch("doma-fits-bad");
    let npz = clip(&dir);
    for k in [0, doma::run::MAX_FITS + 1] {
        let mut c = config(&npz);
        c.fits = k;
        let refused = doma::run::NewFit::load(c).err().expect("refused");
        assert!(matches!(refused, DomaError::InvalidConfig(_)), "{refused}");
        assert!(refused.to_string().contains("fits"), "{refused}");
    }
}

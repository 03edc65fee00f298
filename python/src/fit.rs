//! `doma._native.fit`, `resume` and `load`: fits from NumPy into run folders, and run
//! folders opened as [`Field`]s.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use doma::DomaError;
use doma::Result;
use doma::backend::BackendKind;
use doma::data::layout::Layout;
use doma::run::{Claim, FitOutcome, NewFit, RunDir, RunLock, fit_run, fit_run_locked};
use doma::train::select::WeightSearch;
use doma::train::{IterationRecord, Progress};
use doma_formats::npy::NpyValues;
use pyo3::buffer::PyBuffer;
use pyo3::exceptions::{PyFileExistsError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::contiguous;
use crate::convert::{Wrap, run_spec};
use crate::errors::{self, IntoPy, guarded};
use crate::field::{DataShape, Field};
use crate::interrupt;

/// The data file of a fit from NumPy, inside its run folder.
const DATA_FILE: &str = "tracks.npz";

/// The options that read a data file, which a fit of arrays has no use for.
const FILE_OPTIONS: [&str; 6] = [
    "data",
    "layout",
    "frame",
    "count_hidden",
    "confidence",
    "visibility_threshold",
];

/// Fits a field to `tracks` ([T, N, 3] float32) with the mask `observed` ([T, N] uint8,
/// `None`: every entry observed) into the run folder `out` (a new temporary folder when
/// `None`, removed with the field), as `doma fit` would with the same options: `options`
/// are [`doma::run::RunSpec`]'s fields by name (`variant`, `iters`, `h_weight`, …).
/// `each`, if given, is called after every iteration with `(iteration, iterations, loss,
/// validation EPE or None, seconds)` in place of the bar; an exception it raises stops the
/// fit as Ctrl-C does (checkpoint saved) and is raised.
#[pyfunction]
#[pyo3(signature = (tracks, observed=None, *, out=None, progress=true, each=None, overwrite=false, **options))]
// The keywords of the Python call, one parameter each, as PyO3 maps them.
#[allow(clippy::too_many_arguments)]
pub fn fit(
    py: Python<'_>,
    tracks: PyBuffer<f32>,
    observed: Option<PyBuffer<u8>>,
    out: Option<PathBuf>,
    progress: bool,
    each: Option<Py<PyAny>>,
    overwrite: bool,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Field> {
    let named = out.clone();
    guarded("fit", named.as_deref(), || {
        if let Some(given) = options {
            for key in FILE_OPTIONS {
                if given.contains(key)? {
                    return Err(PyTypeError::new_err(format!(
                        "fit() does not take '{key}': the tracks are the arrays given (read a \
                         file with doma.read_tracks)"
                    )));
                }
            }
        }
        let mut spec = run_spec(options)?;
        let (dims, positions) = contiguous(&tracks, "tracks", &[None, None, Some(3)], false)?;
        let (t, n) = (dims[0], dims[1]);
        // SAFETY: the caller holds the buffer for this call.
        let positions = unsafe { positions.slice() };
        let mask = read_mask(observed.as_ref(), t, n)?;
        check_tracks(t, n, positions, mask.as_deref())?;
        let (dir, temporary) = match out {
            Some(dir) => (dir, false),
            None => (temporary_dir().py()?, true),
        };
        let (mut claim, lock) = Claim::take(&dir).py()?;
        // The files a fit writes beside `config.json`: the run's own, its data and its plots.
        let written = crate::field::RUN_FILES.iter().chain(&[DATA_FILE, "plots"]);
        if !overwrite && let Some(file) = claim.holds(written.copied()) {
            claim.undo(Some(lock));
            return Err(PyFileExistsError::new_err(format!(
                "{}: the folder is not a doma run but holds {}, which a fit writes; choose \
                 another `out`, or pass overwrite=True to replace it",
                dir.display(),
                file.display()
            )));
        }
        // The data file is written once and read once, by `prepare`; the fit runs on what it
        // read.
        let prepared = (|| -> Result<NewFit> {
            let data = claim.replace(DATA_FILE)?;
            let (s3, s2) = ([t, n, 3], [t, n]);
            let mut members = vec![("tracks", &s3[..], NpyValues::F32(positions))];
            if let Some(mask) = &mask {
                members.push(("observed", &s2[..], NpyValues::Bool(mask)));
            }
            doma::data::npy::write_npz_values(&data, &members)?;
            spec.data = Some(data);
            spec.layout = Some(if mask.is_some() {
                Layout::Masked
            } else {
                Layout::Plain
            });
            spec.prepare(&WeightSearch::default(), |p| {
                if progress {
                    eprintln!(
                        "weight {:e}: validation EPE {:.2}e-4",
                        p.weight, p.validation_epe_x1e4
                    );
                }
            })
        })();
        let new = match prepared {
            Ok(new) => new,
            Err(e) => {
                claim.undo(Some(lock));
                return Err(errors::to_py(e));
            }
        };
        let shape = DataShape::of(&new.sequence);
        let run = RunDir::new(&dir);
        let result = run_fit(py, &run, Some((new, lock)), progress, each);
        if result.is_err() {
            // The lock went with the fit: the undo takes it again, and touches nothing of
            // another process that took the folder meanwhile.
            claim.undo(None);
            if temporary {
                let _ = std::fs::remove_dir_all(&dir);
            }
        } else {
            claim.keep();
        }
        let device = result?;
        Field::fitted(&dir, temporary, device, shape).py()
    })
}

/// The mask `observed` ([T, N] uint8) as booleans, checked against the tracks' shape.
fn read_mask(observed: Option<&PyBuffer<u8>>, t: usize, n: usize) -> PyResult<Option<Vec<bool>>> {
    let Some(o) = observed else {
        return Ok(None);
    };
    let (_, mask) = contiguous(o, "observed", &[Some(t), Some(n)], false)?;
    // SAFETY: the caller holds the buffer for this call.
    Ok(Some(
        unsafe { mask.slice() }.iter().map(|&b| b != 0).collect(),
    ))
}

/// Refuses tracks that no fit can read, naming the entry: an observed coordinate that is
/// not finite, or no observation at all.
fn check_tracks(t: usize, n: usize, positions: &[f32], mask: Option<&[bool]>) -> PyResult<()> {
    if t == 0 || n == 0 {
        return Err(PyValueError::new_err(format!(
            "tracks of {t} frames and {n} points: nothing to fit"
        )));
    }
    let seen = |e: usize| mask.is_none_or(|m| m[e]);
    if let Some(c) = (0..positions.len()).find(|&c| seen(c / 3) && !positions[c].is_finite()) {
        let (e, axis) = (c / 3, c % 3);
        return Err(PyValueError::new_err(format!(
            "tracks[{}, {}, {axis}] is {}, and observed{}",
            e / n,
            e % n,
            positions[c],
            if mask.is_some() {
                ""
            } else {
                " (give `observed` to mark the entries a tracker did not see)"
            }
        )));
    }
    Ok(())
}

/// Fits (a `new` fit, or the run's own to resume when `None`) on the worker thread of
/// [`interrupt::run_interruptible`]; returns the device on success. Ctrl-C raises
/// `KeyboardInterrupt` after the checkpoint is saved and the lock released.
fn run_fit(
    py: Python<'_>,
    run: &RunDir,
    new: Option<(NewFit, RunLock)>,
    progress: bool,
    each: Option<Py<PyAny>>,
) -> PyResult<burn::tensor::Device> {
    let backend = match &new {
        Some((n, _)) => n.config.backend,
        None => run.load_config().py()?.backend,
    };
    let device = backend.device().py()?;
    // The callable's own exception, which stops the fit as Ctrl-C does.
    let failed = std::sync::Mutex::new(None::<PyErr>);
    let (outcome, raised) = interrupt::run_interruptible(py, |flag| {
        let shown: Progress = match &each {
            Some(each) => Progress::Each(Box::new(|record: &IterationRecord, total: usize| {
                Python::attach(|py| {
                    let args = (
                        record.iteration + 1,
                        total,
                        record.trajectory_loss,
                        record.validation_epe,
                        record.seconds,
                    );
                    if let Err(e) = each.call1(py, args) {
                        let mut slot = failed.lock().unwrap_or_else(|e| e.into_inner());
                        slot.get_or_insert(e);
                        flag.store(true, Ordering::SeqCst);
                    }
                });
                Ok(())
            })),
            None => progress.into(),
        };
        match new {
            Some((new, lock)) => fit_run_locked(run, new, lock, &device, flag, None, shown),
            None => fit_run(run, None, &device, flag, None, shown),
        }
    });
    let failed = failed.into_inner().unwrap_or_else(|e| e.into_inner());
    match (outcome.py()?, raised.or(failed)) {
        (FitOutcome::Finished(_), None) => Ok(device),
        (FitOutcome::Interrupted { iterations_done }, raised) => {
            let error = raised.unwrap_or_else(|| {
                pyo3::exceptions::PyKeyboardInterrupt::new_err("the fit was interrupted")
            });
            let note = format!(
                "doma: the fit stopped after {iterations_done} iterations; its checkpoint is \
                 in {} (doma.resume, or `doma fit --resume`, continues it)",
                run.dir.display()
            );
            let _ = error.value(py).call_method1("add_note", (note,));
            Err(error)
        }
        // The signal came as the last iteration ended: the fit is whole, and the
        // interrupt is still the caller's.
        (FitOutcome::Finished(_), Some(raised)) => Err(raised),
    }
}

/// A new empty folder under the system's temporary folder.
fn temporary_dir() -> Result<PathBuf> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let base = std::env::temp_dir();
    loop {
        let name = format!(
            "doma-fit-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        let dir = base.join(name);
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(DomaError::io(&base, e)),
        }
    }
}

/// Continues the interrupted fit in `run_dir` from its checkpoint, on the backend it was
/// started on.
#[pyfunction]
#[pyo3(signature = (run_dir, progress, each=None))]
pub fn resume(
    py: Python<'_>,
    run_dir: PathBuf,
    progress: bool,
    each: Option<Py<PyAny>>,
) -> PyResult<Field> {
    guarded("resume", Some(&run_dir), || {
        let run = RunDir::new(&run_dir);
        let device = run_fit(py, &run, None, progress, each)?;
        Field::open(&run_dir, false, device).py()
    })
}

/// Opens the fitted run in `run_dir` (written by `doma fit` or by `doma.fit(out=...)`), on
/// its own backend or `backend`.
#[pyfunction]
#[pyo3(signature = (run_dir, backend=None))]
pub fn load(
    py: Python<'_>,
    run_dir: PathBuf,
    backend: Option<Wrap<BackendKind>>,
) -> PyResult<Field> {
    guarded("load", Some(&run_dir), || {
        let run = RunDir::new(&run_dir);
        let kind = match backend {
            Some(Wrap(kind)) => kind,
            None => run.load_config().py()?.backend,
        };
        let device = kind.device().py()?;
        py.detach(|| Field::open(&run_dir, false, device)).py()
    })
}

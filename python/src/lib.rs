//! `doma._native`: the compiled part of the `doma` Python package. Each function is the
//! library's own ([`doma::run`]), called in process; `doma/__init__.py` is the API over
//! it, which turns any array into the C-contiguous `float32` / `bool` buffers read here.

mod arrays;
mod errors;
mod field;
mod interrupt;

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use doma::data::layout::{Layout, TrackFile};
use doma::run::{FitOutcome, RunConfig, RunDir, RunSpec, fit_run};
use doma::train::select::WeightSearch;
use doma::{DomaError, Result};
use doma_formats::npy::NpyValues;
use pyo3::buffer::PyBuffer;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use arrays::{contiguous, to_bytearray};
use errors::IntoPy;
use field::Field;

/// The data file of a fit from NumPy, inside its run folder.
const DATA_FILE: &str = "tracks.npz";

/// Fits a field to `tracks` ([T, N, 3] float32) with the mask `observed` ([T, N] uint8,
/// `None`: every entry observed) into the run folder `out` (a new temporary folder when
/// `None`, removed with the field), as `doma fit` would with the options of `spec` (a
/// JSON [`RunSpec`] without `data`) and `robust` (`huber[:δ]`, `charbonnier[:ε]`, `l1`).
#[pyfunction]
#[pyo3(signature = (tracks, observed, spec, robust, out, progress))]
fn fit(
    py: Python<'_>,
    tracks: PyBuffer<f32>,
    observed: Option<PyBuffer<u8>>,
    spec: &str,
    robust: Option<&str>,
    out: Option<PathBuf>,
    progress: bool,
) -> PyResult<Field> {
    let mut spec: RunSpec = serde_json::from_str(spec)
        .map_err(|e| PyValueError::new_err(format!("fit options: {e}")))?;
    if spec.data.is_some() {
        return Err(PyValueError::new_err(
            "fit options: the data are the tracks given, not a file",
        ));
    }
    if let Some(r) = robust {
        spec.data_penalty = Some(doma::cli::fit::data_penalty(r).map_err(PyValueError::new_err)?);
    }
    let (dims, positions) = contiguous(&tracks, "tracks", &[None, None, Some(3)], false)?;
    let (t, n) = (dims[0], dims[1]);
    // SAFETY: the caller holds both buffers for this call.
    let positions = unsafe { positions.slice() };
    let mask = match &observed {
        Some(o) => {
            let (_, mask) = contiguous(o, "observed", &[Some(t), Some(n)], false)?;
            // SAFETY: as above.
            Some(
                unsafe { mask.slice() }
                    .iter()
                    .map(|&b| b != 0)
                    .collect::<Vec<bool>>(),
            )
        }
        None => None,
    };
    check_tracks(t, n, positions, mask.as_deref())?;
    let (dir, temporary) = match out {
        Some(dir) => (dir, false),
        None => (temporary_dir().py()?, true),
    };
    let run = RunDir::new(&dir);
    if run.config().exists() {
        return Err(errors::to_py(DomaError::RunExists(dir)));
    }
    let made = !dir.exists();
    std::fs::create_dir_all(&dir)
        .map_err(|e| DomaError::io(&dir, e))
        .py()?;
    let data = dir.join(DATA_FILE);
    // Nothing of a fit that does not start is left behind: the data file, and the folder
    // when this call made it.
    let clean_up = || {
        if !run.config().exists() {
            let _ = std::fs::remove_file(&data);
            if made {
                let _ = std::fs::remove_dir(&dir);
            }
        }
    };
    let started = (|| -> Result<RunConfig> {
        let (s3, s2) = ([t, n, 3], [t, n]);
        let mut members = vec![("tracks", &s3[..], NpyValues::F32(positions))];
        if let Some(mask) = &mask {
            members.push(("observed", &s2[..], NpyValues::Bool(mask)));
        }
        doma::io::write_atomic(&data, &doma_formats::npz::encode_npz_values(&members))?;
        spec.data = Some(data.clone());
        spec.layout = Some(if mask.is_some() {
            Layout::Masked
        } else {
            Layout::Plain
        });
        spec.run_config(&WeightSearch::default(), |p| {
            if progress {
                eprintln!(
                    "weight {:e}: validation EPE {:.2}e-4",
                    p.weight, p.validation_epe_x1e4
                );
            }
        })
    })();
    let config = match started {
        Ok(c) => c,
        Err(e) => {
            clean_up();
            return Err(errors::to_py(e));
        }
    };
    let result = run_fit(py, &run, Some(config), progress);
    if result.is_err() {
        clean_up();
        if temporary {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
    let device = result?;
    Field::open(&dir, temporary, device).py()
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

/// Fits (a new `config`, or the run's own to resume when `None`) on the worker thread of
/// [`interrupt::run_interruptible`]; returns the device on success. Ctrl-C raises
/// `KeyboardInterrupt` after the checkpoint is saved and the lock released.
fn run_fit(
    py: Python<'_>,
    run: &RunDir,
    config: Option<RunConfig>,
    progress: bool,
) -> PyResult<burn::tensor::Device> {
    let backend = match &config {
        Some(c) => c.backend,
        None => run.load_config().py()?.backend,
    };
    let device = backend.device().py()?;
    let (outcome, raised) = interrupt::run_interruptible(py, |flag| {
        fit_run(run, config, &device, flag, None, progress)
    });
    match (outcome.py()?, raised) {
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
#[pyo3(signature = (run_dir, progress))]
fn resume(py: Python<'_>, run_dir: PathBuf, progress: bool) -> PyResult<Field> {
    let run = RunDir::new(&run_dir);
    let device = run_fit(py, &run, None, progress)?;
    Field::open(&run_dir, false, device).py()
}

/// Opens the fitted run in `run_dir` (written by `doma fit` or by `doma.fit(out=...)`), on
/// its own backend or `backend`.
#[pyfunction]
#[pyo3(signature = (run_dir, backend=None))]
fn load(py: Python<'_>, run_dir: PathBuf, backend: Option<&str>) -> PyResult<Field> {
    let run = RunDir::new(&run_dir);
    let kind = match backend {
        Some(name) => <doma::backend::BackendKind as clap::ValueEnum>::from_str(name, false)
            .map_err(|_| {
                PyValueError::new_err(format!("backend {name:?} is not flex, ndarray or wgpu"))
            })?,
        None => run.load_config().py()?.backend,
    };
    let device = kind.device().py()?;
    py.detach(|| Field::open(&run_dir, false, device)).py()
}

/// Reads a sequence file as `doma fit` reads it: `(tracks bytes, [T, N], observed bytes,
/// faces bytes or None, weights bytes or None, layout)`.
#[pyfunction]
#[pyo3(signature = (path, layout=None, frame=None, count_hidden=false, confidence=None))]
#[allow(clippy::type_complexity)]
fn read_tracks<'py>(
    py: Python<'py>,
    path: PathBuf,
    layout: Option<&str>,
    frame: Option<&str>,
    count_hidden: bool,
    confidence: Option<String>,
) -> PyResult<(
    Bound<'py, pyo3::types::PyByteArray>,
    (usize, usize),
    Bound<'py, pyo3::types::PyByteArray>,
    Option<Bound<'py, pyo3::types::PyByteArray>>,
    Option<Bound<'py, pyo3::types::PyByteArray>>,
)> {
    let value = |what: &str, name: &str, choices: &str| {
        PyValueError::new_err(format!("{what} {name:?} is not one of {choices}"))
    };
    let file = TrackFile {
        layout: layout
            .map(|l| {
                <Layout as clap::ValueEnum>::from_str(l, false)
                    .map_err(|_| value("layout", l, "plain, pointodyssey, tapvid3d, masked"))
            })
            .transpose()?,
        frame: frame
            .map(|f| {
                <doma::data::layout::CoordFrame as clap::ValueEnum>::from_str(f, false)
                    .map_err(|_| value("frame", f, "world, camera"))
            })
            .transpose()?,
        count_hidden,
        confidence,
    };
    let (tracks, faces) = py
        .detach(|| doma::data::sequence::read_tracks(&path, &file))
        .py()?;
    // An entry the file does not observe holds no value: NaN, never a stand-in.
    let mut positions = tracks.positions().to_vec();
    for (e, &seen) in tracks.observed().iter().enumerate() {
        if !seen {
            positions[3 * e..3 * e + 3].fill(f32::NAN);
        }
    }
    let observed: Vec<u8> = tracks.observed().iter().map(|&o| o as u8).collect();
    let faces = faces.map(|f| to_bytearray(py, f.as_flattened()));
    let weights = tracks.weights().map(|w| to_bytearray(py, w));
    Ok((
        to_bytearray(py, &positions),
        (tracks.frames(), tracks.points()),
        to_bytearray(py, &observed),
        faces,
        weights,
    ))
}

/// The version of the library this module was built from.
const VERSION: &str = env!("CARGO_PKG_VERSION");

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(resume, m)?)?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(read_tracks, m)?)?;
    m.add_class::<Field>()?;
    m.add("__version__", VERSION)?;
    Ok(())
}

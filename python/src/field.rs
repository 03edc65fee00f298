//! `doma._native.Field`: a fitted run folder opened in memory, warped and differentiated
//! from NumPy.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use burn::tensor::{Device, Tensor, TensorData};
use doma::data::sequence::Sequence;
use doma::field::MotionField;
use doma::field::model::Model;
use doma::jacobian::{Analytic, Autodiff, JacobianMethod};
use doma::run::{RunConfig, RunDir};
use doma::{DomaError, Result};
use pyo3::buffer::PyBuffer;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::arrays::{contiguous, to_bytearray};
use crate::errors::{IntoPy, guarded};

/// Rows sent through the field at once by `warp` ([`doma::warp::WARP_CHUNK`]), and by
/// `jacobian`, whose tangents are three times the values.
const JACOBIAN_CHUNK: usize = doma::warp::WARP_CHUNK / 4;

/// A fitted motion field and the run folder it lives in.
#[pyclass(module = "doma._native", frozen)]
pub struct Field {
    run: RunDir,
    /// A temporary folder (a fit without `out`), removed with the field.
    temporary: bool,
    config: RunConfig,
    /// Burn's modules are not `Sync`; one call at a time uses the field.
    model: Mutex<Model>,
    device: Device,
    center: [f32; 3],
    scale: f32,
    frames: usize,
    points: usize,
    reference: usize,
}

impl Drop for Field {
    fn drop(&mut self) {
        if self.temporary {
            // Best effort: a temporary folder that cannot be removed is the system's to clean.
            let _ = std::fs::remove_dir_all(&self.run.dir);
        }
    }
}

/// What a [`Field`] keeps of its run's data: the clip's shape and the normalisation.
#[derive(Clone, Copy, Debug)]
pub struct DataShape {
    frames: usize,
    points: usize,
    center: [f32; 3],
    scale: f32,
    reference: usize,
}

impl DataShape {
    /// The shape and normalisation of `data`.
    pub fn of(data: &Sequence) -> Self {
        DataShape {
            frames: data.trajectories.frames(),
            points: data.trajectories.points(),
            center: data.center,
            scale: data.scale,
            reference: data.trajectories.reference(),
        }
    }
}

impl Field {
    /// Opens the fitted run in `dir` on `device` (its data read once, for its shape).
    pub fn open(dir: &Path, temporary: bool, device: Device) -> Result<Self> {
        let run = RunDir::new(dir);
        let config = run.load_config()?;
        let shape = DataShape::of(&config.load()?);
        Self::assemble(run, config, temporary, device, shape)
    }

    /// Opens the run in `dir` that was just fitted to data of `shape`, without reading the
    /// data again.
    pub fn fitted(dir: &Path, temporary: bool, device: Device, shape: DataShape) -> Result<Self> {
        let run = RunDir::new(dir);
        let config = run.load_config()?;
        Self::assemble(run, config, temporary, device, shape)
    }

    fn assemble(
        run: RunDir,
        config: RunConfig,
        temporary: bool,
        device: Device,
        shape: DataShape,
    ) -> Result<Self> {
        let model = run.load_field(&config, &device)?;
        Ok(Field {
            temporary,
            frames: shape.frames,
            points: shape.points,
            center: shape.center,
            scale: shape.scale,
            reference: shape.reference,
            config,
            model: Mutex::new(model),
            device,
            run,
        })
    }

    /// The normalised time of frame `k` (a real number in `[0, T − 1]`).
    fn time(&self, k: f64) -> PyResult<f64> {
        let last = self.frames.saturating_sub(1) as f64;
        if !(k.is_finite() && (0.0..=last).contains(&k)) {
            return Err(PyValueError::new_err(format!(
                "frame {k} is outside the field's frames, 0 to {last}"
            )));
        }
        Ok(if self.frames < 2 {
            -1.0
        } else {
            -1.0 + 2.0 * k / last
        })
    }

    /// Runs `each(chunk of normalised points [n, 3], t, out rows)` over every time and chunk
    /// of `points` with the GIL released; `width` is the output's values per point.
    #[allow(clippy::too_many_arguments)]
    fn over_chunks(
        &self,
        py: Python<'_>,
        points: &PyBuffer<f32>,
        times: &[f64],
        out: &PyBuffer<f32>,
        width: usize,
        chunk: usize,
        each: impl Fn(&dyn MotionField, Tensor<2>, f64, &mut [f32]) -> Result<()> + Sync,
    ) -> PyResult<()> {
        let (dims, input) = contiguous(points, "points", &[None, Some(3)], false)?;
        let m = dims[0];
        let shape: Vec<Option<usize>> = [Some(times.len()), Some(m)]
            .into_iter()
            .chain(match width {
                3 => vec![Some(3)],
                _ => vec![Some(3), Some(3)],
            })
            .collect();
        let (_, output) = contiguous(out, "out", &shape, true)?;
        let ts = times
            .iter()
            .map(|&k| self.time(k))
            .collect::<PyResult<Vec<f64>>>()?;
        let (center, scale) = (self.center, self.scale);
        py.detach(|| -> Result<()> {
            // SAFETY: both buffers are held by the caller for this call; `out` is a fresh
            // array that the Python layer allocated for it.
            let (input, output) = unsafe { (input.slice(), output.slice_mut()) };
            if let Some(row) = input.iter().position(|v| !v.is_finite()) {
                return Err(DomaError::InvalidData(format!(
                    "points[{}, {}] is {}",
                    row / 3,
                    row % 3,
                    input[row]
                )));
            }
            let model = self.model.lock().unwrap_or_else(|e| e.into_inner());
            let field = model.as_field();
            for (k, &t) in ts.iter().enumerate() {
                let frame_out = &mut output[k * m * width..(k + 1) * m * width];
                for (rows, out_rows) in input
                    .chunks(3 * chunk)
                    .zip(frame_out.chunks_mut(width * chunk))
                {
                    // Burn takes the chunk's buffer; one allocation per chunk, no copy of it.
                    let normalised: Vec<f32> = rows
                        .iter()
                        .enumerate()
                        .map(|(i, &v)| (v - center[i % 3]) / scale)
                        .collect();
                    let x = Tensor::<2>::from_data(
                        TensorData::new(normalised, [rows.len() / 3, 3]),
                        &self.device,
                    );
                    each(field, x, t, out_rows)?;
                }
            }
            Ok(())
        })
        .py()
    }
}

#[pymethods]
impl Field {
    /// Warps `points` ([M, 3], float32, C order) to each frame of `times` into `out`
    /// ([K, M, 3], float32): `y = A x + u` (Eq. 4), in the data's units.
    fn warp_into(
        &self,
        py: Python<'_>,
        points: PyBuffer<f32>,
        times: Vec<f64>,
        out: PyBuffer<f32>,
    ) -> PyResult<()> {
        guarded("Field.warp", self.run_dir().as_deref(), || {
            let (center, scale) = (self.center, self.scale);
            self.over_chunks(
                py,
                &points,
                &times,
                &out,
                3,
                doma::warp::WARP_CHUNK,
                |field, x, t, out| {
                    let y = doma::readback::to_vec::<f32, 2, _>(field.warp(x, t))?;
                    for (i, (o, v)) in out.iter_mut().zip(y).enumerate() {
                        *o = v * scale + center[i % 3];
                    }
                    Ok(())
                },
            )
        })
    }

    /// The Jacobians `∂y/∂x` of the warp at `points` ([M, 3]) and each frame of `times` into
    /// `out` ([K, M, 3, 3], `out[k, m, i, j] = ∂y_i/∂x_j`), through the fused analytic
    /// forward mode where the model is a SIREN, else Burn's autodiff (the normalisation's
    /// scale cancels: the Jacobian is the same in the data's units).
    fn jacobian_into(
        &self,
        py: Python<'_>,
        points: PyBuffer<f32>,
        times: Vec<f64>,
        out: PyBuffer<f32>,
    ) -> PyResult<()> {
        guarded("Field.jacobian", self.run_dir().as_deref(), || {
            self.over_chunks(
                py,
                &points,
                &times,
                &out,
                9,
                JACOBIAN_CHUNK,
                |field, x, t, out| {
                    let analytic = Analytic;
                    let method: &dyn JacobianMethod = if field.accepts(&analytic) {
                        &analytic
                    } else {
                        &Autodiff
                    };
                    let warped = field.warp_dual(x, t, method).warped;
                    let tangent = warped.tangent.ok_or_else(|| {
                        DomaError::InvalidData("the warp carried no spatial tangents".into())
                    })?;
                    // [3 (x_j), n, 3 (y_i)] → [n, 3 (y_i), 3 (x_j)].
                    let j = doma::readback::to_vec::<f32, 3, _>(tangent.permute([1, 2, 0]))?;
                    out.copy_from_slice(&j);
                    Ok(())
                },
            )
        })
    }

    /// The metrics of the run as `doma eval` computes them, as JSON: on the held-out points
    /// of its own data, or on `data` (another file of the same tracks).
    /// With `masked`, `data` is a masked `.npz` written from a `Tracks` (not read as the
    /// run read its own data).
    #[pyo3(signature = (data=None, masked=false))]
    fn evaluate(&self, py: Python<'_>, data: Option<PathBuf>, masked: bool) -> PyResult<String> {
        guarded("Field.evaluate", data.as_deref(), || {
            let file = masked.then(|| doma::data::layout::TrackFile {
                layout: Some(doma::data::layout::Layout::Masked),
                ..Default::default()
            });
            let report = py
                .detach(|| {
                    doma::run::eval_run_as(&self.run, data.as_deref(), file.as_ref(), &self.device)
                })
                .py()?;
            serde_json::to_string(&report).map_err(|e| PyValueError::new_err(e.to_string()))
        })
    }

    /// Copies the run into the new folder `dir` (it must not hold a run), so that the
    /// command line and `doma.load` open it: its files, and the data file when it lives in
    /// the run (a fit from NumPy), with `config.json` written last and pointed at the copy.
    fn save(&self, dir: PathBuf) -> PyResult<()> {
        guarded("Field.save", Some(&dir), || {
            save_run(&self.run, &self.config, &dir).py()
        })
    }

    /// Every track at every frame of the clip, as `doma complete` writes it with
    /// `--max-gap` (`N` frames or `Xs` seconds) and `--extrapolate`: `(tracks bytes
    /// [T, N, 3] f32 in the input's units, NaN where left unfilled, [T, N], observed bytes
    /// [T, N], the input's index of each track or None, the weights the fill used and
    /// their held-out figures as JSON)`; `method` fills with that filler alone instead of
    /// doma's blend.
    #[allow(clippy::type_complexity)]
    #[pyo3(signature = (max_gap=None, extrapolate=None, method=None))]
    fn complete<'py>(
        &self,
        py: Python<'py>,
        max_gap: Option<String>,
        extrapolate: Option<bool>,
        method: Option<String>,
    ) -> PyResult<(
        Bound<'py, pyo3::types::PyByteArray>,
        (usize, usize),
        Bound<'py, pyo3::types::PyByteArray>,
        Option<Vec<usize>>,
        String,
    )> {
        guarded("Field.complete", self.run_dir().as_deref(), || {
            let max_gap = max_gap
                .map(|g| g.parse::<doma::run::MaxGap>())
                .transpose()
                .map_err(|e| PyValueError::new_err(format!("max_gap: {e}")))?;
            let method = method
                .map(|m| doma::gaps::Filler::parse(&m))
                .transpose()
                .map_err(|e| PyValueError::new_err(format!("method: {e}")))?;
            let policy = doma::run::FillPolicy {
                max_gap,
                extrapolate,
                method,
            };
            let done = py
                .detach(|| doma::run::complete_tracks(&self.run, policy, &self.device))
                .py()?;
            let observed: Vec<u8> = done.observed.iter().map(|&o| o as u8).collect();
            let blend = serde_json::to_string(&done.blend)
                .map_err(|e| PyValueError::new_err(format!("the blend: {e}")))?;
            Ok((
                to_bytearray(py, &done.tracks),
                (done.frames, done.points),
                to_bytearray(py, &observed),
                done.kept,
                blend,
            ))
        })
    }

    /// The canonical positions `[N, 3]` (f32 bytes) in the data's units: each track's
    /// point at the reference frame, as the fit placed it (learned, where it learned
    /// them).
    #[getter]
    fn canonical<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyByteArray>> {
        guarded("Field.canonical", self.run_dir().as_deref(), || {
            let data = py.detach(|| self.run.load_data(&self.config)).py()?;
            let (center, scale) = (self.center, self.scale);
            let placed: Vec<f32> = data
                .trajectories
                .canonical()
                .iter()
                .enumerate()
                .map(|(i, v)| v * scale + center[i % 3])
                .collect();
            Ok(to_bytearray(py, &placed))
        })
    }

    /// The frame of the clip whose positions are the field's input `x`: the one with the
    /// most observed tracks, unless the fit named one.
    #[getter]
    fn reference_frame(&self) -> usize {
        self.reference
    }

    /// The run folder, or `None` for a temporary one (a fit without `out`).
    #[getter]
    fn run_dir(&self) -> Option<PathBuf> {
        (!self.temporary).then(|| self.run.dir.clone())
    }

    /// The frames of the fitted clip.
    #[getter]
    fn frames(&self) -> usize {
        self.frames
    }

    /// The tracks of the fitted data (training and held-out).
    #[getter]
    fn tracks(&self) -> usize {
        self.points
    }

    /// The run's `config.json`, as JSON.
    #[getter]
    fn config(&self) -> PyResult<String> {
        serde_json::to_string(&self.config).map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// The run's `report.json`, as JSON, or `None` before the fit finished.
    #[getter]
    fn report(&self) -> PyResult<Option<String>> {
        let path = self.run.report();
        if !path.is_file() {
            return Ok(None);
        }
        std::fs::read_to_string(&path)
            .map(Some)
            .map_err(|e| DomaError::io(&path, e))
            .py()
    }

    /// The normalisation of the data: `x' = (x − center) / scale`.
    #[getter]
    fn normalisation(&self) -> ([f32; 3], f32) {
        (self.center, self.scale)
    }

    /// The backend the field runs on.
    #[getter]
    fn backend(&self) -> String {
        self.config.backend.to_string()
    }

    /// The model's paper name (e.g. `DOMA-Affinity`).
    #[getter]
    fn model(&self) -> String {
        self.config.fit.model.paper_name().to_string()
    }
}

/// The files a run folder may hold, copied in this order (`config.json` last: a folder
/// without it is not a run, so a copy cut short is not mistaken for one).
pub(crate) const RUN_FILES: [&str; 5] = [
    "model.bpk",
    "resume.ckpt",
    "history.json",
    "report.json",
    "canonical.npy",
];

/// Copies the run `from` (with config `config`) into the new folder `dir`.
pub fn save_run(from: &RunDir, config: &RunConfig, dir: &Path) -> Result<()> {
    let to = RunDir::new(dir);
    if to.config().exists() {
        return Err(DomaError::RunExists(dir.to_path_buf()));
    }
    std::fs::create_dir_all(dir).map_err(|e| DomaError::io(dir, e))?;
    let copy = |name: &std::ffi::OsStr| -> Result<()> {
        let src = from.dir.join(name);
        let bytes = std::fs::read(&src).map_err(|e| DomaError::io(&src, e))?;
        doma::io::write_atomic(&dir.join(name), &bytes)
    };
    let mut config = config.clone();
    let home = std::path::absolute(&from.dir).map_err(|e| DomaError::io(&from.dir, e))?;
    // The data of a fit from NumPy lives in its run; the copy takes it along.
    if config.data.parent() == Some(home.as_path())
        && let Some(name) = config.data.file_name()
    {
        copy(name)?;
        config.data = std::path::absolute(dir.join(name)).map_err(|e| DomaError::io(dir, e))?;
    }
    for name in RUN_FILES {
        if from.dir.join(name).is_file() {
            copy(name.as_ref())?;
        }
    }
    doma::io::save_json(&config, &to.config())
}

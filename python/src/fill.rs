//! `doma._native.fill_into`: the classic gap fillers on NumPy tracks, without a field.

use doma::DomaError;
use doma::gaps::{Filler, Marked};
use pyo3::buffer::PyBuffer;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::arrays::contiguous;
use crate::errors::{IntoPy, guarded};

/// The fillers that need no field, by name.
pub fn names() -> Vec<&'static str> {
    Filler::ALL
        .into_iter()
        .filter(|f| !f.is_field())
        .map(Filler::name)
        .collect()
}

/// Fills every gap of `tracks` ([T, N, 3] float32) that `observed` ([T, N] uint8) leaves,
/// by the filler named `filler` (one of [`names`]), into `out` ([T, N, 3] float32): observed
/// entries as given, the unobserved ones of a track observed somewhere filled, those of a
/// track never observed as given.
#[pyfunction]
pub fn fill_into(
    py: Python<'_>,
    tracks: PyBuffer<f32>,
    observed: PyBuffer<u8>,
    filler: &str,
    out: PyBuffer<f32>,
) -> PyResult<()> {
    guarded("fill", None, || {
        let filler = Filler::from_name(filler)
            .filter(|f| !f.is_field() && f.name() == filler)
            .ok_or_else(|| {
                PyValueError::new_err(format!(
                    "method: `{filler}` is not one of {} (the field's fills need a fit: \
                     Field.complete)",
                    names().join(", ")
                ))
            })?;
        let (dims, positions) = contiguous(&tracks, "tracks", &[None, None, Some(3)], false)?;
        let (t, n) = (dims[0], dims[1]);
        let (_, mask) = contiguous(&observed, "observed", &[Some(t), Some(n)], false)?;
        let (_, output) = contiguous(&out, "out", &[Some(t), Some(n), Some(3)], true)?;
        py.detach(|| -> doma::Result<()> {
            // SAFETY: the caller holds the three buffers for this call; `out` is a fresh
            // array that the Python layer allocated for it.
            let (positions, mask, output) =
                unsafe { (positions.slice(), mask.slice(), output.slice_mut()) };
            let seen: Vec<bool> = mask.iter().map(|&b| b != 0).collect();
            if let Some(c) =
                (0..positions.len()).find(|&c| seen[c / 3] && !positions[c].is_finite())
            {
                return Err(DomaError::InvalidData(format!(
                    "tracks[{}, {}, {}] is {}, and observed",
                    c / 3 / n,
                    (c / 3) % n,
                    c % 3,
                    positions[c]
                )));
            }
            let marked = Marked::new(t, n, positions, &seen);
            let somewhere: Vec<bool> = (0..n).map(|i| (0..t).any(|k| seen[k * n + i])).collect();
            let entries: Vec<(usize, usize)> = (0..t)
                .flat_map(|k| (0..n).map(move |i| (k, i)))
                .filter(|&(k, i)| !seen[k * n + i] && somewhere[i])
                .collect();
            let values = filler.fill_observed(&marked, &entries).unwrap_or_default();
            output.copy_from_slice(positions);
            for (&(k, i), v) in entries.iter().zip(values) {
                let e = 3 * (k * n + i);
                output[e..e + 3].copy_from_slice(&v);
            }
            Ok(())
        })
        .py()
    })
}

/// Fills the gaps of the recording at `path` into `out` (its format by its extension), as
/// `doma fill` does for one file, and writes the table of filled gaps beside it; returns
/// the report as JSON: `input`, `output`, `markers`, `frames`, `filled`, `extrapolated`,
/// `unfilled`, `left_long`, `filled_by`, `gaps` (one row per filled gap, with its expected
/// error and whether it passes `flag_above_mm`), `units`, `calibration` and `csv`.
#[pyfunction]
#[pyo3(signature = (path, out, fit=false, max_gap=None, extrapolate=None, method=None, overwrite=false, flag_above_mm=5.0))]
// The keywords of `doma.fill_file`, one argument each, as PyO3 takes them.
#[allow(clippy::too_many_arguments)]
pub fn fill_file(
    py: Python<'_>,
    path: std::path::PathBuf,
    out: std::path::PathBuf,
    fit: bool,
    max_gap: Option<String>,
    extrapolate: Option<bool>,
    method: Option<String>,
    overwrite: bool,
    flag_above_mm: f64,
) -> PyResult<String> {
    use doma::run::{FillPolicy, MaxGap, RecordingFill};
    guarded("fill_file", Some(&path), || {
        let max_gap = max_gap
            .map(|m| m.parse::<MaxGap>())
            .transpose()
            .map_err(|e| PyValueError::new_err(format!("max_gap: {e}")))?;
        let method = method
            .map(|m| Filler::parse(&m))
            .transpose()
            .map_err(|e| PyValueError::new_err(format!("method: {e}")))?;
        if !(flag_above_mm.is_finite() && flag_above_mm > 0.0) {
            return Err(PyValueError::new_err(format!(
                "flag_above_mm={flag_above_mm} is not a positive length"
            )));
        }
        if out.exists() && !overwrite {
            return Err(pyo3::exceptions::PyFileExistsError::new_err(format!(
                "{} exists: overwrite=True writes over it",
                out.display()
            )));
        }
        let how = RecordingFill {
            fit,
            policy: FillPolicy {
                max_gap,
                extrapolate,
                method,
            },
            ..Default::default()
        };
        let device = doma::backend::BackendKind::Flex.device().py()?;
        let (done, raised) = crate::interrupt::run_interruptible(py, |flag| {
            doma::run::fill_recording(&path, &out, &how, &device, flag).and_then(|c| {
                let table = doma::run::write_gap_report(&path, &out, &c, flag_above_mm)?;
                Ok((c, table, doma::run::gaps_csv_path(&out)))
            })
        });
        if let Some(e) = raised {
            return Err(e);
        }
        let (c, table, csv) = done.py()?;
        let report = serde_json::json!({
            "input": path,
            "output": out,
            "markers": c.tracks,
            "frames": c.frames,
            "filled": c.filled,
            "extrapolated": c.extrapolated,
            "unfilled": c.unfilled,
            "left_long": c.left_long,
            "filled_by": doma::run::filled_by(&c),
            "gaps": table.rows,
            "units": table.units,
            "calibration": table.calibration.map(|k| serde_json::json!({
                "factor": k.factor,
                "spans": k.spans,
            })),
            "csv": csv,
            "html": doma::run::gaps_html_path(&out),
        });
        Ok(report.to_string())
    })
}

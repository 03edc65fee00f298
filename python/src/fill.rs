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

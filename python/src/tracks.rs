//! `doma._native.read_tracks`: a sequence file read as `doma fit` reads it.

use std::path::PathBuf;

use doma::data::layout::{CoordFrame, Layout, TrackFile};
use pyo3::prelude::*;

use crate::arrays::to_bytearray;
use crate::convert::Wrap;
use crate::errors::{IntoPy, guarded};

/// Reads a sequence file as `doma fit` reads it: `(tracks bytes, [T, N], observed bytes,
/// faces bytes or None, weights bytes or None, kept bytes or None, (labels, rate, units)
/// or None)`; `kept` (`i64`, the file's index of each track) where a C3D file's model
/// outputs were left out; the labels those of the tracks read.
#[pyfunction]
#[pyo3(signature = (path, layout=None, frame=None, count_hidden=false, confidence=None, visibility_threshold=None, model_outputs=false))]
// The keywords of `doma.read_tracks`, one argument each, as PyO3 takes them.
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
pub fn read_tracks<'py>(
    py: Python<'py>,
    path: PathBuf,
    layout: Option<Wrap<Layout>>,
    frame: Option<Wrap<CoordFrame>>,
    count_hidden: bool,
    confidence: Option<String>,
    visibility_threshold: Option<f64>,
    model_outputs: bool,
) -> PyResult<(
    Bound<'py, pyo3::types::PyByteArray>,
    (usize, usize),
    Bound<'py, pyo3::types::PyByteArray>,
    Option<Bound<'py, pyo3::types::PyByteArray>>,
    Option<Bound<'py, pyo3::types::PyByteArray>>,
    Option<Bound<'py, pyo3::types::PyByteArray>>,
    Option<(Vec<String>, f64, String)>,
)> {
    guarded("read_tracks", Some(&path), || {
        let file = TrackFile {
            layout: layout.map(|Wrap(l)| l),
            frame: frame.map(|Wrap(f)| f),
            count_hidden,
            confidence,
            visibility_threshold,
        };
        let read = py
            .detach(|| doma::data::sequence::read_points(&path, &file))
            .py()?;
        // What the reader decided where the file was not plain, said once, as a warning.
        for note in &read.notes {
            let message =
                std::ffi::CString::new(format!("{}: {note}", path.display())).unwrap_or_default();
            PyErr::warn(
                py,
                &py.get_type::<pyo3::exceptions::PyUserWarning>(),
                &message,
                1,
            )?;
        }
        let (mut tracks, faces) = (read.tracks, read.faces);
        let named = match (read.labels, read.rate, read.units) {
            (Some(labels), Some(rate), Some(units)) => Some((labels, rate, units)),
            _ => None,
        };
        // A model's outputs left out, as `doma fit` leaves them (a C3D file has no faces).
        let kept = read.markers.filter(|_| !model_outputs);
        let named = named.map(|(labels, rate, units)| match &kept {
            Some(markers) => (
                markers.iter().map(|&i| labels[i].clone()).collect(),
                rate,
                units,
            ),
            None => (labels, rate, units),
        });
        if let Some(markers) = &kept {
            tracks = tracks.select_points(markers);
        }
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
            kept.map(|k| to_bytearray(py, &k.iter().map(|&i| i as i64).collect::<Vec<_>>())),
            named,
        ))
    })
}

/// How many sequence files this process has parsed: a fit reads its data once.
#[pyfunction]
pub fn sequence_reads() -> usize {
    doma::data::sequence::sequence_reads()
}

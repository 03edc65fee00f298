//! `doma._native.read_tracks`: a sequence file read as `doma fit` reads it.

use std::path::PathBuf;

use doma::data::layout::{CoordFrame, Layout, TrackFile};
use pyo3::prelude::*;

use crate::arrays::to_bytearray;
use crate::convert::Wrap;
use crate::errors::{IntoPy, guarded};

/// Reads a sequence file as `doma fit` reads it: `(tracks bytes, [T, N], observed bytes,
/// faces bytes or None, weights bytes or None, layout)`.
#[pyfunction]
#[pyo3(signature = (path, layout=None, frame=None, count_hidden=false, confidence=None, visibility_threshold=None))]
#[allow(clippy::type_complexity)]
pub fn read_tracks<'py>(
    py: Python<'py>,
    path: PathBuf,
    layout: Option<Wrap<Layout>>,
    frame: Option<Wrap<CoordFrame>>,
    count_hidden: bool,
    confidence: Option<String>,
    visibility_threshold: Option<f64>,
) -> PyResult<(
    Bound<'py, pyo3::types::PyByteArray>,
    (usize, usize),
    Bound<'py, pyo3::types::PyByteArray>,
    Option<Bound<'py, pyo3::types::PyByteArray>>,
    Option<Bound<'py, pyo3::types::PyByteArray>>,
)> {
    guarded("read_tracks", Some(&path), || {
        let file = TrackFile {
            layout: layout.map(|Wrap(l)| l),
            frame: frame.map(|Wrap(f)| f),
            count_hidden,
            confidence,
            visibility_threshold,
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
    })
}

/// How many sequence files this process has parsed: a fit reads its data once.
#[pyfunction]
pub fn sequence_reads() -> usize {
    doma::data::sequence::sequence_reads()
}

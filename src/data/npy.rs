//! NumPy's `.npy` arrays and `.npz` archives, the format the authors' data comes in
//! (docs/reference.md §6.3: `[T, N, 3]` float64 trajectories).
//!
//! `.npy` (NumPy's format spec, versions 1–3): the magic `\x93NUMPY`, a version, a header
//! length, then a Python-literal dict `{'descr': '<f8', 'fortran_order': False,
//! 'shape': (T, N, 3), }` and the raw values. The reader takes floats (`f2` is refused,
//! `f4`, `f8`) and integers (1–8 bytes), either byte order, C or Fortran order, and returns
//! the values in C order as `f64`.
//!
//! `.npz` is a zip archive of `.npy` members (`np.savez` stores them, `np.savez_compressed`
//! deflates them; NumPy writes zip64 records). The reader walks the central directory, checks
//! every member's CRC-32, and inflates with `miniz_oxide`.
//!
//! Written by hand, not through `npyz`: that crate's header parser pulls in a dependency tree
//! whose features would rebuild all of Burn here. Every defect (truncated, oversized, a bad
//! header, an unsupported dtype, a count that overflows, a bad CRC) is a
//! [`DomaError::Malformed`] naming the file; nothing panics.

use std::path::Path;

pub use doma_formats::npy::{
    NPY_MAGIC, NpyArray, NpyHeader, NpyValues, encode_npy, parse_npy, parse_npy_header,
};
pub use doma_formats::npz::{
    NpzMember, encode_npz, npz_member_header, npz_members, parse_npz, read_npz_member,
};
pub use doma_formats::source::{FileSource, Source};

use super::Trajectories;
use crate::io::{write_atomic, write_atomic_with};
use crate::{DomaError, Result};

/// An array as trajectories: `[T, N, 3]` gives `T` frames, `[N, 3]` one frame. Refuses
/// other shapes and non-finite values (the error names the frame and point).
pub fn to_trajectories(array: NpyArray) -> std::result::Result<Trajectories, String> {
    let (frames, points) = trajectory_shape(&array.shape)?;
    doma_formats::Frames::new(frames, points, array.data).map(Trajectories::from)
}

/// `(T, N)` of a trajectory array's shape, `[T, N, 3]` or `[N, 3]`; checked from the header
/// alone, before any value is read.
pub fn trajectory_shape(shape: &[usize]) -> std::result::Result<(usize, usize), String> {
    match shape[..] {
        [t, n, 3] => Ok((t, n)),
        [n, 3] => Ok((1, n)),
        _ => Err(format!(
            "shape {shape:?} is not [T, N, 3] or [N, 3] point coordinates"
        )),
    }
}

fn malformed(path: &Path) -> impl FnOnce(String) -> DomaError + '_ {
    move |reason| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    }
}

/// Reads a `.npy` file.
pub fn read_npy(path: impl AsRef<Path>) -> Result<NpyArray> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| DomaError::io(path, e))?;
    parse_npy(&bytes).map_err(malformed(path))
}

/// Reads point trajectories (`[T, N, 3]` or `[N, 3]`) from a `.npy` file.
pub fn read_npy_trajectories(path: impl AsRef<Path>) -> Result<Trajectories> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| DomaError::io(path, e))?;
    let header = parse_npy_header(&bytes).map_err(malformed(path))?;
    trajectory_shape(&header.shape).map_err(malformed(path))?;
    to_trajectories(parse_npy(&bytes).map_err(malformed(path))?).map_err(malformed(path))
}

/// Writes `data` (`f32`, C order, of `shape`) as a `.npy` file, atomically.
pub fn write_npy(path: impl AsRef<Path>, shape: &[usize], data: &[f32]) -> Result<()> {
    write_atomic(path.as_ref(), &encode_npy(shape, data))
}

/// Writes trajectories as a `[T, N, 3]` `f32` `.npy` file, atomically.
pub fn write_npy_trajectories(path: impl AsRef<Path>, data: &Trajectories) -> Result<()> {
    write_npy(path, &[data.frames(), data.points(), 3], data.positions())
}

/// Reads a `.npz` archive's members, `(name, array)`.
pub fn read_npz(path: impl AsRef<Path>) -> Result<Vec<(String, NpyArray)>> {
    let path = path.as_ref();
    let source = FileSource::open(path).map_err(|e| DomaError::io(path, e))?;
    parse_npz(&source).map_err(malformed(path))
}

/// Reads trajectories from member `key` of a `.npz` archive; with `key = None` the archive
/// must hold exactly one member. The member's count, name and `.npy` header (shape
/// `[T, N, 3]` or `[N, 3]`) are checked before any of its values are inflated, and those
/// are inflated into no more than the header declares ([`read_npz_member`]), read from the
/// file a piece at a time ([`FileSource`]): the archive's bytes are never held whole.
pub fn read_npz_trajectories(path: impl AsRef<Path>, key: Option<&str>) -> Result<Trajectories> {
    let path = path.as_ref();
    let source = FileSource::open(path).map_err(|e| DomaError::io(path, e))?;
    let members = npz_members(&source).map_err(malformed(path))?;
    let names: Vec<&str> = members.iter().map(|m| m.name.as_str()).collect();
    let member = match key {
        Some(k) => members.iter().find(|m| m.name == k).ok_or_else(|| {
            malformed(path)(format!("no member {k:?}; the archive holds {names:?}"))
        })?,
        None if members.len() == 1 => &members[0],
        None => {
            return Err(malformed(path)(format!(
                "{} members {names:?}; name the one to read",
                members.len()
            )));
        }
    };
    let header = npz_member_header(&source, member).map_err(malformed(path))?;
    trajectory_shape(&header.shape)
        .map_err(|m| malformed(path)(format!("member {}: {m}", member.name)))?;
    let array = read_npz_member(&source, member).map_err(malformed(path))?;
    to_trajectories(array).map_err(malformed(path))
}

/// Writes a `.npz` archive of `f32` arrays atomically ([`encode_npz`]).
pub fn write_npz(path: impl AsRef<Path>, members: &[(&str, &[usize], &[f32])]) -> Result<()> {
    let typed: Vec<(&str, &[usize], NpyValues)> = members
        .iter()
        .map(|&(name, shape, data)| (name, shape, NpyValues::F32(data)))
        .collect();
    write_npz_values(path.as_ref(), &typed)
}

/// Writes a `.npz` archive of arrays of any [`NpyValues`] kind atomically, streamed to the
/// file ([`doma_formats::npz::write_npz_values`]): no array is copied whole on the way.
pub fn write_npz_values(path: &Path, members: &[(&str, &[usize], NpyValues)]) -> Result<()> {
    write_atomic_with(path, |w| doma_formats::npz::write_npz_values(w, members))
}

//! Loading a user's sequence: any supported file (`.traj`, `.anime`, `.npy`, `.npz`,
//! `.c3d`, a folder of OBJ frames) with its faces, a clip and a stride, normalised; and the seeded
//! split of its points into training and held-out sets (the paper's Tab. 1 protocol).

use std::ops::Range;
use std::path::Path;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

pub use super::held_out::{HeldOut, HoldOut};
use super::held_out::{hide_blind_spans, hold_out};
use super::layout::TrackFile;
use super::mesh::read_obj;
use super::tracks::Tracks;
use super::{Trajectories, anime, c3d, layout, npy, traj, trc};
use crate::{DomaError, Result};

/// An animated mesh: vertex trajectories `[T, V, 3]` and, when known, the triangles.
#[derive(Clone, Debug)]
pub struct Sequence {
    /// A short name for the records (the file stem).
    pub name: String,
    /// The vertices' positions in every frame.
    pub trajectories: Trajectories,
    /// The triangles (vertex order = trajectory point order).
    pub faces: Option<Vec<[u32; 3]>>,
    /// The normalisation applied: `x' = (x − center) / scale`.
    pub center: [f32; 3],
    /// See `center`.
    pub scale: f32,
    /// The observations hidden from the fit to measure gap filling
    /// ([`LoadOptions::hold_out`]), normalised like the trajectories.
    pub held_out: Option<HeldOut>,
    /// The validation spans hidden from the fit so that doma's fill is validated where the
    /// field has not seen the answer ([`LoadOptions::blind_validation`]), normalised like
    /// the trajectories.
    pub blind: Option<HeldOut>,
    /// The input's indices of the tracks kept ([`LoadOptions::drop_unobserved`], and a C3D
    /// file's markers without its model outputs, [`LoadOptions::model_outputs`]); `None`:
    /// every track, in order.
    pub kept: Option<Vec<usize>>,
    /// How many of a C3D file's points were left out as a model's outputs
    /// ([`LoadOptions::model_outputs`]).
    pub model_outputs_left_out: usize,
    /// What the reader decided where the file was not plain ([`c3d::C3d::notes`]), to be
    /// said once to the user.
    pub notes: Vec<String>,
    /// The units a motion-capture file states (`mm`, `m`, ...); `None` for other formats.
    pub units: Option<String>,
}

/// How a sequence is loaded: beside the file, everything that decides which entries a fit
/// sees and where its canonical positions are.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// An OBJ whose vertices are the points in order, for the faces.
    pub mesh: Option<std::path::PathBuf>,
    /// A clip of the frames.
    pub frames: Option<Range<usize>>,
    /// Every `stride`-th frame (0 is taken as 1).
    pub stride: usize,
    /// How a tracker's `.npz` is read.
    pub file: TrackFile,
    /// The reference frame of the canonical positions (default: the most observed).
    pub reference: Option<usize>,
    /// Go on without the tracks that are never observed (in the clip) rather than refuse.
    pub drop_unobserved: bool,
    /// Fit a C3D file's model outputs ([`c3d::C3d::model_outputs`]) as markers; without
    /// it they are left out, and [`Sequence::kept`] lists the markers.
    pub model_outputs: bool,
    /// Hide this fraction of the observations, in spans, with this seed
    /// ([`hold_out_spans`]).
    pub hold_out: Option<HoldOut>,
    /// With tracks that have gaps (after `hold_out`), hide the validation spans of doma's
    /// fill drawn with this seed ([`blind_spans`]) from the fit.
    pub blind_validation: Option<u64>,
    /// The validation whose share of the observations the blind spans hide.
    pub validation: crate::gaps::blend::Validation,
}

/// Loads `data` (`.traj`, `.anime`, `.npy`, `.npz`, or a folder of OBJ frames with equal
/// vertex counts); the faces come from `mesh` (an OBJ
/// whose vertices are the points in order), else from the `.anime`, else from a sibling
/// `NAME.obj` next to a `.traj`. Then keeps `frames` every `stride`-th frame, and
/// normalises the coordinates ([`Trajectories::normalized`]: frame 0's bounding box centred,
/// its longest side spanning `[−1, 1]`); every metric is in these units. An OBJ whose
/// vertex count differs from the point count is refused, naming the file.
pub fn load_sequence(
    data: &Path,
    mesh: Option<&Path>,
    frames: Option<Range<usize>>,
    stride: usize,
) -> Result<Sequence> {
    load_sequence_with(
        data,
        &LoadOptions {
            mesh: mesh.map(Path::to_path_buf),
            frames,
            stride,
            ..LoadOptions::default()
        },
    )
}

/// [`load_sequence`] of tracks that may be unobserved in some frames (a tracker's `.npz`,
/// [`layout`]): after the clip, tracks never observed are refused or dropped, the
/// held-out observations are hidden, and the canonical positions are found in the
/// reference frame ([`Tracks::into_trajectories`]) before the coordinates are normalised
/// by their bounding box. Complete data loads exactly as [`load_sequence`] loads it.
pub fn load_sequence_with(data: &Path, options: &LoadOptions) -> Result<Sequence> {
    let malformed = |reason: String| DomaError::Malformed {
        path: data.to_path_buf(),
        reason,
    };
    let PointsRead {
        mut tracks,
        mut faces,
        markers,
        notes,
        units,
        ..
    } = read_points(data, &options.file)?;
    // A model's outputs (joint angles, moments, ...) are not positions of the scene.
    let mut kept = None;
    let mut model_outputs_left_out = 0;
    if let Some(markers) = markers.filter(|_| !options.model_outputs) {
        if markers.is_empty() {
            return Err(malformed(
                "every point is a model's output (listed by POINT:ANGLES, FORCES, MOMENTS, \
                 POWERS, ... or POINT:TYPE_GROUPS), none a marker; --model-outputs fits them"
                    .into(),
            ));
        }
        model_outputs_left_out = tracks.points() - markers.len();
        tracks = tracks.select_points(&markers);
        kept = Some(markers);
    }
    if let Some(mesh) = mesh_faces(data, options, faces.is_none(), tracks.points())? {
        faces = Some(mesh);
    }
    let stride = options.stride.max(1);
    tracks = match options.frames.clone() {
        Some(r) => tracks
            .select_frames(r, stride)
            .map_err(DomaError::InvalidData)?,
        None if stride > 1 => tracks
            .select_frames(0..tracks.frames(), stride)
            .map_err(DomaError::InvalidData)?,
        None => tracks,
    };
    if options.drop_unobserved && !tracks.never_observed().is_empty() {
        let keep = observed_somewhere(&tracks).map_err(malformed)?;
        (tracks, faces) = (tracks.select_points(&keep), renumber(faces, &keep));
        // The input's indices, through the markers kept before.
        kept = Some(match kept {
            Some(markers) => keep.iter().map(|&i| markers[i]).collect(),
            None => keep,
        });
    }
    let held_out = match &options.hold_out {
        Some(h) => Some(hold_out(&mut tracks, h).map_err(malformed)?),
        None => None,
    };
    let blind = hide_blind_spans(&mut tracks, options.blind_validation, &options.validation);
    let trajectories = tracks
        .into_trajectories(options.reference)
        .map_err(|e| match e {
            DomaError::InvalidData(reason) | DomaError::InvalidConfig(reason) => malformed(reason),
            other => other,
        })?;
    // Fit and measure in normalised coordinates, so that one ω₀ suits every user's units.
    let (trajectories, center, scale) = trajectories
        .normalized()
        .map_err(|e| malformed(e.to_string()))?;
    let normalise = |h: HeldOut| HeldOut {
        truth: h
            .truth
            .iter()
            .map(|p| std::array::from_fn(|c| (p[c] - center[c]) / scale))
            .collect(),
        entries: h.entries,
    };
    let held_out = held_out.map(normalise);
    let blind = blind.map(normalise);
    let name = data
        .file_stem()
        .map_or("data".into(), |s| s.to_string_lossy().into_owned());
    Ok(Sequence {
        name,
        trajectories,
        faces,
        center,
        scale,
        held_out,
        blind,
        kept,
        model_outputs_left_out,
        notes,
        units,
    })
}

/// The faces of the mesh `options` names, or of a `.traj` file's sibling `.obj` where the
/// file has none of its own (`has_none`), checked against the `points` read from `data`.
fn mesh_faces(
    data: &Path,
    options: &LoadOptions,
    has_none: bool,
    points: usize,
) -> Result<Option<Vec<[u32; 3]>>> {
    let sibling = data.with_extension("obj");
    let obj = options.mesh.clone().or_else(|| {
        (has_none && extension(data) == "traj" && sibling.is_file()).then_some(sibling)
    });
    let Some(obj) = obj else {
        return Ok(None);
    };
    let m = read_obj(&obj)?;
    if m.vertices.len() != points {
        return Err(DomaError::Malformed {
            path: obj,
            reason: format!(
                "{} vertices, but {} has {} points",
                m.vertices.len(),
                data.display(),
                points
            ),
        });
    }
    Ok(Some(m.faces))
}

/// The tracks observed in some frame; refuses tracks none of which is.
fn observed_somewhere(tracks: &Tracks) -> std::result::Result<Vec<usize>, String> {
    let never = tracks.never_observed();
    if never.len() == tracks.points() {
        return Err("no track is observed in any frame".into());
    }
    Ok((0..tracks.points())
        .filter(|i| never.binary_search(i).is_err())
        .collect())
}

/// The faces of the `kept` vertices alone, renumbered.
fn renumber(faces: Option<Vec<[u32; 3]>>, kept: &[usize]) -> Option<Vec<[u32; 3]>> {
    let total = kept.last().map_or(0, |&i| i + 1);
    let mut new_index = vec![u32::MAX; total];
    for (r, &i) in kept.iter().enumerate() {
        new_index[i] = r as u32;
    }
    faces.map(|f| {
        f.iter()
            .filter_map(|t| {
                let m = t.map(|v| new_index.get(v as usize).copied().unwrap_or(u32::MAX));
                m.iter().all(|&v| v != u32::MAX).then_some(m)
            })
            .collect()
    })
}

/// The file's extension, lower-case ("" if none).
fn extension(data: &Path) -> String {
    data.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

/// Sequence files parsed by [`read_tracks`] in this process.
static READS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// How many sequence files this process has parsed (every load of a fit's data goes
/// through [`read_tracks`]): a fit reads its data once, and tests count it.
pub fn sequence_reads() -> usize {
    READS.load(std::sync::atomic::Ordering::Relaxed)
}

/// Reads any supported sequence file (or OBJ folder) by its extension as tracks (a
/// tracker's `.npz` with its mask, [`layout`]; a C3D file's points with theirs,
/// [`c3d`], a model's outputs among them; every other file complete), and the faces
/// where the format has them. A `file` other than the default applies to `.npz` alone.
pub fn read_tracks(data: &Path, file: &TrackFile) -> Result<(Tracks, Option<Vec<[u32; 3]>>)> {
    let read = read_points(data, file)?;
    Ok((read.tracks, read.faces))
}

/// What [`read_points`] reads.
#[derive(Clone, Debug)]
pub struct PointsRead {
    /// Every point of the file, as [`read_tracks`] reads them.
    pub tracks: Tracks,
    /// The triangles, where the format has them.
    pub faces: Option<Vec<[u32; 3]>>,
    /// A C3D file's markers, where some of its points are a model's outputs
    /// ([`c3d::C3d::model_outputs`]); `None`: every point is a marker.
    pub markers: Option<Vec<usize>>,
    /// What the reader decided where the file was not plain ([`c3d::C3d::notes`]).
    pub notes: Vec<String>,
    /// A motion-capture file's marker names (every point's, before any is left out), frame
    /// rate and units; `None` for formats without them.
    pub labels: Option<Vec<String>>,
    /// See `labels`.
    pub rate: Option<f64>,
    /// See `labels`.
    pub units: Option<String>,
}

/// [`read_tracks`], and which points are markers rather than a model's outputs.
pub fn read_points(data: &Path, file: &TrackFile) -> Result<PointsRead> {
    check_readable(data)?;
    READS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let plain = |tracks, faces| PointsRead {
        tracks,
        faces,
        markers: None,
        notes: Vec::new(),
        labels: None,
        rate: None,
        units: None,
    };
    if extension(data) == "npz" && !data.is_dir() {
        return Ok(plain(layout::read_npz_tracks(data, file)?, None));
    }
    if !file.is_default() {
        return Err(DomaError::Usage(format!(
            "{} applies to a tracker's .npz, not to {}",
            file.flags_set().join(", "),
            data.display()
        )));
    }
    if extension(data) == "c3d" && !data.is_dir() {
        let c = c3d::read_c3d(data)?;
        let markers = c.markers();
        let markers = (markers.len() < c.points).then_some(markers);
        let notes = c.notes.clone();
        let (labels, rate, units) = (c.labels.clone(), c.rate as f64, c.units.clone());
        return Ok(PointsRead {
            markers,
            notes,
            labels: Some(labels),
            rate: Some(rate),
            units: Some(units),
            ..plain(c3d_as_tracks(data, c)?, None)
        });
    }
    if extension(data) == "trc" && !data.is_dir() {
        let trc = trc::read_trc(data)?;
        let (labels, rate, units) = (trc.labels.clone(), trc.rate, trc.units.clone());
        let tracks = trc::trc_tracks(trc).map_err(|reason| DomaError::Malformed {
            path: data.to_path_buf(),
            reason,
        })?;
        return Ok(PointsRead {
            labels: Some(labels),
            rate: Some(rate),
            units: Some(units),
            ..plain(tracks, None)
        });
    }
    let (t, faces) = read_any(data)?;
    Ok(plain(Tracks::complete(t), faces))
}

/// A C3D file's points as tracks ([`c3d::c3d_tracks`]), every defect naming the file.
fn read_c3d_tracks(data: &Path) -> Result<Tracks> {
    c3d_as_tracks(data, c3d::read_c3d(data)?)
}

/// A `.trc` file's markers as tracks ([`trc::trc_tracks`]), every defect naming the file.
fn read_trc_tracks(data: &Path) -> Result<Tracks> {
    trc::trc_tracks(trc::read_trc(data)?).map_err(|reason| DomaError::Malformed {
        path: data.to_path_buf(),
        reason,
    })
}

/// [`c3d::c3d_tracks`] of `c`, read from `data`, every defect naming the file.
fn c3d_as_tracks(data: &Path, c: c3d::C3d) -> Result<Tracks> {
    c3d::c3d_tracks(c).map_err(|reason| DomaError::Malformed {
        path: data.to_path_buf(),
        reason,
    })
}

/// Reads any supported sequence file (or OBJ folder) by its extension: the trajectories,
/// and the faces where the format has them.
pub fn read_any(data: &Path) -> Result<(Trajectories, Option<Vec<[u32; 3]>>)> {
    check_readable(data)?;
    Ok(match extension(data).as_str() {
        _ if data.is_dir() => {
            let (t, f) = super::mesh::read_obj_sequence(data)?;
            (t, Some(f))
        }
        "traj" => (traj::read_traj(data)?, None),
        "anime" => {
            let a = anime::read_anime(data)?;
            (a.trajectories, Some(a.faces))
        }
        "npy" => (npy::read_npy_trajectories(data)?, None),
        "npz" => (npy::read_npz_trajectories(data, None)?, None),
        ext @ ("c3d" | "trc") => {
            let tracks = if ext == "c3d" {
                read_c3d_tracks(data)?
            } else {
                read_trc_tracks(data)?
            };
            if tracks.observed_count() != tracks.frames() * tracks.points() {
                return Err(DomaError::Malformed {
                    path: data.to_path_buf(),
                    reason: "some markers are not measured in some frames: read it as tracks \
                             (doma fit reads the gaps, doma complete fills them)"
                        .into(),
                });
            }
            (tracks.into_trajectories(None)?, None)
        }
        _ => {
            return Err(DomaError::Malformed {
                path: data.to_path_buf(),
                reason:
                    "unknown format: expected .traj, .anime, .npy, .npz, .c3d, .trc or a folder of .obj frames"
                        .into(),
            });
        }
    })
}

/// Refuses what is neither a regular file nor a folder: a FIFO or a device would block a
/// read forever, or never end.
fn check_readable(data: &Path) -> Result<()> {
    let meta = std::fs::metadata(data).map_err(|e| DomaError::io(data, e))?;
    if !(meta.is_file() || meta.is_dir()) {
        return Err(DomaError::Malformed {
            path: data.to_path_buf(),
            reason: "not a regular file or folder (a FIFO, a socket or a device)".into(),
        });
    }
    Ok(())
}

/// A seeded split of `n` indices into `round(fraction · n)` and the rest.
pub fn split_indices(n: usize, fraction: f64, seed: u64) -> Result<(Vec<usize>, Vec<usize>)> {
    let n_train = (fraction * n as f64).round() as usize;
    if !(fraction > 0.0 && fraction < 1.0) || n_train == 0 || n_train >= n {
        return Err(DomaError::InvalidConfig(format!(
            "a training fraction of {fraction} does not split {n} points into two non-empty sets"
        )));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    let test = order.split_off(n_train);
    Ok((order, test))
}

//! The `.npz` layouts of tracker output, detected by their keys:
//!
//! | layout | tracks | mask | frame |
//! |---|---|---|---|
//! | PointOdyssey `anno.npz` | `trajs_3d` `[T, N, 3]` (f16) | `valids` and `visibs` `[T, N]` (bool) | world; `extrinsics` `[T, 4, 4]` (world to camera) |
//! | TAPVid-3D clip | `tracks_XYZ` `[T, N, 3]` | `visibility` `[T, N]` (bool) | camera |
//! | masked (doma's own: `doma complete`, the Python package) | `tracks` `[T, N, 3]` | `observed` `[T, N]` (bool) | as given |
//!
//! Any other archive is read as plain trajectories (one member, or the one named).
//! PointOdyssey's `trajs_3d` holds ground truth even where a point is hidden; an entry
//! counts as observed when it is valid and visible, or valid alone with
//! [`TrackFile::count_hidden`]. Unobserved entries are never read ([`super::tracks`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::npy::{
    FileSource, npz_member_header, npz_members, read_npz_member, read_npz_trajectories,
};
use super::tracks::Tracks;
use crate::{DomaError, Result};
use doma_formats::npy::ValueKind;
use doma_formats::npz::NpzMember;

/// The layout of a `.npz` file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// Complete trajectories `[T, N, 3]` (or `[N, 3]`): one member, every entry observed.
    Plain,
    /// PointOdyssey's `anno.npz`.
    #[value(name = "pointodyssey")]
    #[serde(rename = "pointodyssey")]
    PointOdyssey,
    /// A TAPVid-3D clip.
    #[value(name = "tapvid3d")]
    #[serde(rename = "tapvid3d")]
    TapVid3d,
    /// doma's own tracks with a mask: `tracks` `[T, N, 3]` and `observed` `[T, N]`, which
    /// `doma complete` writes and the Python package fits from.
    Masked,
}

crate::names::value_names!(Layout, CoordFrame);

impl Layout {
    /// The layout that `keys` (an archive's member names) show: PointOdyssey's
    /// `trajs_3d`, TAPVid-3D's `tracks_XYZ`, `tracks` beside `observed`, else plain.
    pub fn detect<'a>(keys: impl IntoIterator<Item = &'a str>) -> Layout {
        let keys: Vec<&str> = keys.into_iter().collect();
        if keys.contains(&"trajs_3d") {
            Layout::PointOdyssey
        } else if keys.contains(&"tracks_XYZ") {
            Layout::TapVid3d
        } else if keys.contains(&"tracks") && keys.contains(&"observed") {
            Layout::Masked
        } else {
            Layout::Plain
        }
    }

    /// Whether this is a tracker's output (PointOdyssey's or TAPVid-3D's layout), used and
    /// scored at every point of every frame.
    pub fn is_tracker(self) -> bool {
        matches!(self, Layout::PointOdyssey | Layout::TapVid3d)
    }

    /// The layout of the `.npz` at `path` as `file` reads it: its own, else detected from
    /// the archive's keys (read from its directory alone).
    pub fn of_npz(path: &Path, file: &TrackFile) -> Result<Layout> {
        if let Some(layout) = file.layout {
            return Ok(layout);
        }
        let source = FileSource::open(path).map_err(|e| DomaError::io(path, e))?;
        let members = npz_members(&source).map_err(|reason| malformed(path, reason))?;
        Ok(Layout::detect(members.iter().map(|m| m.name.as_str())))
    }

    /// The keys of the tracks and the mask(s) this layout reads.
    fn keys(self) -> &'static [&'static str] {
        match self {
            Layout::Plain => &[],
            Layout::PointOdyssey => &["trajs_3d", "valids", "visibs"],
            Layout::TapVid3d => &["tracks_XYZ", "visibility"],
            Layout::Masked => &["tracks", "observed"],
        }
    }
}

/// The coordinate frame tracks are fitted in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum CoordFrame {
    /// The world frame (PointOdyssey's own).
    World,
    /// The camera frame of each frame (TAPVid-3D's own; PointOdyssey's through its
    /// `extrinsics`).
    Camera,
}

/// How a tracker's file is read.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackFile {
    /// The layout (default: detected from the keys).
    #[serde(default)]
    pub layout: Option<Layout>,
    /// The coordinate frame (default: the layout's own).
    #[serde(default)]
    pub frame: Option<CoordFrame>,
    /// Count PointOdyssey's valid but hidden entries as observed.
    #[serde(default)]
    pub count_hidden: bool,
    /// The key of a `[T, N]` array of per-observation confidence weights.
    #[serde(default)]
    pub confidence: Option<String>,
    /// The probability from which a float visibility counts as observed (default
    /// [`VISIBILITY_THRESHOLD`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility_threshold: Option<f64>,
}

/// The probability from which a float visibility (a tracker's confidence that the point
/// is seen) counts as observed.
pub const VISIBILITY_THRESHOLD: f64 = 0.5;

/// A visibility array as a mask, by its dtype: bools as they are; integers 0 or 1; floats
/// a probability in `[0, 1]`, observed from `threshold` on. Any other value (an integer
/// code such as 2 or −1, a NaN, a probability outside `[0, 1]`) is refused, naming the
/// entry of `key`.
pub fn visibility_mask(
    key: &str,
    kind: ValueKind,
    values: &[f32],
    points: usize,
    threshold: f64,
) -> std::result::Result<Vec<bool>, String> {
    let at = |e: usize| format!("{key}[{}, {}]", e / points.max(1), e % points.max(1));
    // Sized up front: collected through `Result`, the mask would grow by doubling and keep
    // up to twice its length for the whole fit.
    let mut mask = Vec::with_capacity(values.len());
    for (e, &v) in values.iter().enumerate() {
        mask.push(match kind {
            ValueKind::Bool => Ok(v != 0.0),
            ValueKind::Integer if v == 0.0 || v == 1.0 => Ok(v == 1.0),
            ValueKind::Integer => Err(format!(
                "{} is {v}: an integer visibility holds 0 or 1 (a float one, a probability)",
                at(e)
            )),
            ValueKind::Float if (0.0..=1.0).contains(&v) => Ok(v as f64 >= threshold),
            ValueKind::Float => Err(format!(
                "{} is {v}: a float visibility is a probability in [0, 1] (observed from {threshold})",
                at(e)
            )),
        }?);
    }
    Ok(mask)
}

impl TrackFile {
    /// Whether every field is its default (a file read as it says).
    pub fn is_default(&self) -> bool {
        *self == TrackFile::default()
    }

    /// The command-line flags that set a field away from its default, in the order of
    /// `doma fit --help`: what a refusal names when they do not apply.
    pub fn flags_set(&self) -> Vec<&'static str> {
        let d = TrackFile::default();
        [
            (self.layout != d.layout, "--layout"),
            (self.frame != d.frame, "--frame"),
            (self.count_hidden, "--count-hidden"),
            (self.confidence.is_some(), "--confidence"),
            (
                self.visibility_threshold.is_some(),
                "--visibility-threshold",
            ),
        ]
        .into_iter()
        .filter_map(|(set, flag)| set.then_some(flag))
        .collect()
    }
}

/// Reads the tracks of a `.npz` file in its layout ([`Layout::detect`], or `file.layout`).
/// Errors name the file and the key: a missing key, a mask whose shape is not the tracks'
/// `[T, N]`, an observed coordinate that is not finite (an f16 overflow reads as
/// infinity), a frame or flag that the layout does not have. The file is read member by
/// member, a piece at a time ([`FileSource`]), never whole.
pub fn read_npz_tracks(path: &Path, file: &TrackFile) -> Result<Tracks> {
    let source = FileSource::open(path).map_err(|e| DomaError::io(path, e))?;
    let members = npz_members(&source).map_err(|reason| malformed(path, reason))?;
    let names: Vec<&str> = members.iter().map(|m| m.name.as_str()).collect();
    let layout = file
        .layout
        .unwrap_or_else(|| Layout::detect(names.iter().copied()));
    check_flags(path, layout, file)?;
    if layout == Layout::Plain {
        return Ok(Tracks::complete(read_npz_trajectories(path, None)?));
    }
    let archive = Archive::open(path, &source, &members, layout, file)?;
    let observed = archive.observed(file.count_hidden)?;
    let mut positions = read_npz_member(&source, archive.member(archive.tracks_key)?)
        .map_err(|reason| malformed(path, reason))?
        .data;
    if layout == Layout::PointOdyssey && file.frame == Some(CoordFrame::Camera) {
        archive.to_camera(&mut positions, &observed)?;
    }
    let (t, n, key) = (archive.frames, archive.points, archive.tracks_key);
    let tracks = Tracks::new(t, n, positions, observed).map_err(|reason| {
        let hint = if archive.half && reason.contains("inf") {
            " (an f16 value past ±65504 reads as infinity)"
        } else {
            ""
        };
        malformed(path, format!("{key}: {reason}{hint}"))
    })?;
    match &file.confidence {
        Some(key) => tracks
            .with_weights(archive.entries(key)?)
            .map_err(|reason| malformed(path, format!("{key}: {reason}"))),
        None => Ok(tracks),
    }
}

fn malformed(path: &Path, reason: String) -> DomaError {
    DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    }
}

/// Refuses a flag that `layout` does not have, naming it.
fn check_flags(path: &Path, layout: Layout, file: &TrackFile) -> Result<()> {
    let usage =
        |what: &str| DomaError::Usage(format!("{what}: {} is read as {layout}", path.display()));
    match (layout, file.frame) {
        (Layout::Plain | Layout::Masked, Some(_)) => {
            return Err(usage(
                "--frame needs a tracker layout that records its frame (pointodyssey, tapvid3d)",
            ));
        }
        (Layout::TapVid3d, Some(CoordFrame::World)) => {
            return Err(usage(
                "--frame world: TAPVid-3D's tracks are in the camera frame and it stores no camera pose",
            ));
        }
        _ => {}
    }
    if file.count_hidden && layout != Layout::PointOdyssey {
        return Err(usage("--count-hidden applies to PointOdyssey's valids"));
    }
    if let Some(p) = file.visibility_threshold
        && !(p > 0.0 && p <= 1.0)
    {
        return Err(DomaError::Usage(format!(
            "--visibility-threshold {p} is not a probability in (0, 1]"
        )));
    }
    if layout == Layout::Plain {
        if file.confidence.is_some() {
            return Err(usage("--confidence needs a tracker layout"));
        }
        if file.visibility_threshold.is_some() {
            return Err(usage("--visibility-threshold needs a tracker layout"));
        }
    }
    Ok(())
}

/// A tracker's archive: its members, its layout, and the shape of its tracks, read from
/// the headers before any values are inflated.
struct Archive<'a> {
    path: &'a Path,
    /// The file, read member by member: its bytes are never held whole.
    source: &'a FileSource,
    members: &'a [NpzMember],
    layout: Layout,
    tracks_key: &'static str,
    frames: usize,
    points: usize,
    /// Whether the tracks are stored as f16.
    half: bool,
    threshold: f64,
}

impl<'a> Archive<'a> {
    fn open(
        path: &'a Path,
        source: &'a FileSource,
        members: &'a [NpzMember],
        layout: Layout,
        file: &TrackFile,
    ) -> Result<Self> {
        let mut archive = Archive {
            path,
            source,
            members,
            layout,
            tracks_key: layout.keys()[0],
            frames: 0,
            points: 0,
            half: false,
            threshold: file.visibility_threshold.unwrap_or(VISIBILITY_THRESHOLD),
        };
        let header = archive.header(archive.tracks_key)?;
        (archive.frames, archive.points) = match header.shape[..] {
            [t, n, 3] => (t, n),
            _ => {
                return Err(archive.malformed(format!(
                    "{} has shape {:?}, not [T, N, 3]",
                    archive.tracks_key, header.shape
                )));
            }
        };
        archive.half = header.is_half();
        Ok(archive)
    }

    fn malformed(&self, reason: String) -> DomaError {
        malformed(self.path, reason)
    }

    fn member(&self, key: &str) -> Result<&'a NpzMember> {
        self.members.iter().find(|m| m.name == key).ok_or_else(|| {
            let names: Vec<&str> = self.members.iter().map(|m| m.name.as_str()).collect();
            self.malformed(format!(
                "no key {key:?}, which the {} layout needs ({:?}); the archive holds {names:?}",
                self.layout,
                self.layout.keys()
            ))
        })
    }

    fn header(&self, key: &str) -> Result<doma_formats::npy::NpyHeader> {
        npz_member_header(self.source, self.member(key)?).map_err(|r| self.malformed(r))
    }

    /// A `[T, N]` array beside the tracks: a mask or the confidence weights.
    fn entries(&self, key: &str) -> Result<Vec<f32>> {
        let (t, n) = (self.frames, self.points);
        let h = self.header(key)?;
        if h.shape != [t, n] {
            return Err(self.malformed(format!(
                "{key} has shape {:?}, but {} of shape [{t}, {n}, 3] needs [{t}, {n}]",
                h.shape, self.tracks_key
            )));
        }
        Ok(read_npz_member(self.source, self.member(key)?)
            .map_err(|r| self.malformed(r))?
            .data)
    }

    fn mask(&self, key: &str) -> Result<Vec<bool>> {
        let kind = self.header(key)?.kind();
        visibility_mask(key, kind, &self.entries(key)?, self.points, self.threshold)
            .map_err(|r| self.malformed(r))
    }

    /// The observed mask of the layout: PointOdyssey's valid and visible entries (or its
    /// valid ones, `count_hidden`), TAPVid-3D's visibility, the masked layout's `observed`.
    fn observed(&self, count_hidden: bool) -> Result<Vec<bool>> {
        Ok(match self.layout {
            Layout::PointOdyssey => {
                let valid = self.mask("valids")?;
                if count_hidden {
                    valid
                } else {
                    let visible = self.mask("visibs")?;
                    valid.iter().zip(visible).map(|(&a, b)| a && b).collect()
                }
            }
            Layout::TapVid3d => self.mask("visibility")?,
            Layout::Masked => self.mask("observed")?,
            Layout::Plain => unreachable!("plain archives are read as trajectories"),
        })
    }

    /// `positions` moved to the camera frame by PointOdyssey's `extrinsics`.
    fn to_camera(&self, positions: &mut [f32], observed: &[bool]) -> Result<()> {
        let (t, n) = (self.frames, self.points);
        let h = self.header("extrinsics")?;
        if h.shape != [t, 4, 4] {
            return Err(self.malformed(format!(
                "extrinsics has shape {:?}, but {t} frames need [{t}, 4, 4]",
                h.shape
            )));
        }
        let e = read_npz_member(self.source, self.member("extrinsics")?)
            .map_err(|r| self.malformed(r))?
            .data;
        // A frame's matrix matters where one of its points is observed; a non-finite entry
        // there would reach the points and be blamed on the tracks.
        let seen = |k: usize| observed[k * n..(k + 1) * n].iter().any(|&o| o);
        if let Some(i) = (0..16 * t).find(|&i| seen(i / 16) && !e[i].is_finite()) {
            return Err(self.malformed(format!(
                "extrinsics[{}, {}, {}] is {}: frame {} has observed points, so its \
                 world-to-camera matrix must be finite",
                i / 16,
                (i % 16) / 4,
                i % 4,
                e[i],
                i / 16
            )));
        }
        to_camera(positions, &e, observed, n).map_err(|r| self.malformed(r))
    }
}

/// Applies frame `k`'s world-to-camera matrix (`extrinsics[k]`, `[4, 4]` row-major) to
/// its `n` points: `p_cam = R p + t`. Refuses an observed point that the matrix takes past
/// the `f32` range (finite entries can overflow), naming the entry that did: the stored
/// point is finite, so the tracks are not to blame.
fn to_camera(
    positions: &mut [f32],
    extrinsics: &[f32],
    observed: &[bool],
    n: usize,
) -> std::result::Result<(), String> {
    for (k, frame) in positions.chunks_exact_mut(3 * n).enumerate() {
        let e = &extrinsics[16 * k..16 * (k + 1)];
        for (i, p) in frame.chunks_exact_mut(3).enumerate() {
            let term = |r: usize, c: usize| {
                if c < 3 {
                    e[4 * r + c] * p[c]
                } else {
                    e[4 * r + 3]
                }
            };
            let q: [f32; 3] =
                std::array::from_fn(|r| term(r, 0) + term(r, 1) + term(r, 2) + term(r, 3));
            if observed[k * n + i]
                && p.iter().all(|v| v.is_finite())
                && let Some(r) = (0..3).find(|&r| !q[r].is_finite())
            {
                // The entry whose term overflowed, else (a sum past the range) the largest.
                let c = (0..4)
                    .find(|&c| !term(r, c).is_finite())
                    .unwrap_or_else(|| {
                        (0..4)
                            .max_by(|&a, &b| term(r, a).abs().total_cmp(&term(r, b).abs()))
                            .unwrap_or(0)
                    });
                return Err(format!(
                    "extrinsics[{k}, {r}, {c}] = {:e} takes observed point {i} of frame {k} \
                     ({:?}, finite) to {:?} in the camera frame, past the float32 range: \
                     the world-to-camera matrix is not a camera pose",
                    e[4 * r + c],
                    [p[0], p[1], p[2]],
                    q
                ));
            }
            p.copy_from_slice(&q);
        }
    }
    Ok(())
}

//! Reading a C3D file: the header, the parameter section and the points.

use std::collections::{HashMap, HashSet};

use super::layout::Layout;
use super::{C3d, Processor};
use crate::source::Source;

/// One parameter of the parameter section.
pub(super) struct Param<'a> {
    group: u8,
    name: String,
    pub(super) kind: i8,
    dims: Vec<usize>,
    pub(super) data: &'a [u8],
}

pub(super) struct Params<'a> {
    pub(super) processor: Processor,
    groups: Vec<(u8, String)>,
    params: Vec<Param<'a>>,
}

impl<'a> Params<'a> {
    pub(super) fn get(&self, group: &str, name: &str) -> Option<&Param<'a>> {
        let id = self
            .groups
            .iter()
            .find(|(_, g)| g.eq_ignore_ascii_case(group))?
            .0;
        self.params
            .iter()
            .find(|p| p.group == id && p.name.eq_ignore_ascii_case(name))
    }

    /// The first value as an unsigned 16-bit count (C3D stores counts in `i16`s that
    /// writers fill up to 65535).
    pub(super) fn u16(&self, group: &str, name: &str) -> Option<u16> {
        let p = self.get(group, name)?;
        match p.kind {
            2 if p.data.len() >= 2 => Some(self.processor.u16(p.data)),
            1 if !p.data.is_empty() => Some(p.data[0] as u16),
            4 if p.data.len() >= 4 => {
                let v = self.processor.f32(p.data);
                (v.is_finite() && (0.0..=65535.0).contains(&v)).then_some(v as u16)
            }
            _ => None,
        }
    }

    pub(super) fn f32(&self, group: &str, name: &str) -> Option<f32> {
        let p = self.get(group, name)?;
        match p.kind {
            4 if p.data.len() >= 4 => Some(self.processor.f32(p.data)),
            2 if p.data.len() >= 2 => Some(self.processor.u16(p.data) as i16 as f32),
            _ => None,
        }
    }

    /// A frame number stored as two 16-bit words, low then high.
    pub(super) fn frame(&self, group: &str, name: &str) -> Option<u32> {
        let p = self.get(group, name)?;
        (p.kind == 2 && p.data.len() >= 4).then(|| {
            self.processor.u16(&p.data[0..2]) as u32
                | ((self.processor.u16(&p.data[2..4]) as u32) << 16)
        })
    }

    /// A character parameter as strings: `dims = [length, count]` (or `[length]`: one).
    fn strings(&self, group: &str, name: &str) -> Option<Vec<String>> {
        self.get(group, name).and_then(Param::strings)
    }

    /// The parameters of `group` (its first, where a file names a group twice).
    fn of_group(&self, group: &str) -> impl Iterator<Item = &Param<'a>> {
        let id = self
            .groups
            .iter()
            .find(|(_, g)| g.eq_ignore_ascii_case(group))
            .map(|g| g.0);
        self.params.iter().filter(move |p| Some(p.group) == id)
    }
}

impl Param<'_> {
    /// A character parameter's strings, trimmed; `None` for a number.
    fn strings(&self) -> Option<Vec<String>> {
        if self.kind != -1 {
            return None;
        }
        let len = self.dims.first().copied().unwrap_or(self.data.len()).max(1);
        Some(
            self.data
                .chunks(len)
                .map(|s| {
                    String::from_utf8_lossy(s)
                        .trim_matches(|c: char| c == '\0' || c.is_whitespace())
                        .to_string()
                })
                .collect(),
        )
    }
}

fn parse_params(section: &[u8], processor: Processor) -> Result<Params<'_>, String> {
    let mut groups = Vec::new();
    let mut params = Vec::new();
    let truncated = |what: &str| format!("the parameter section ends inside {what}");
    let mut pos = 4;
    while pos + 2 <= section.len() {
        let name_len = (section[pos] as i8).unsigned_abs() as usize;
        if name_len == 0 {
            break;
        }
        let id = section[pos + 1] as i8;
        let at = pos + 2;
        let name = section
            .get(at..at + name_len)
            .ok_or_else(|| truncated("a name"))?;
        let name = String::from_utf8_lossy(name).trim().to_string();
        let offset_at = at + name_len;
        let offset = section
            .get(offset_at..offset_at + 2)
            .map(|b| processor.u16(b) as i16)
            .ok_or_else(|| truncated(&format!("the entry of {name}")))?;
        let body = offset_at + 2;
        if id < 0 {
            // −128 names a group no parameter can belong to (ids reach 127).
            groups.push((id.unsigned_abs(), name.clone()));
        } else if id > 0 {
            let head = section
                .get(body..body + 2)
                .ok_or_else(|| truncated(&format!("parameter {name}")))?;
            let kind = head[0] as i8;
            let ndims = head[1] as usize;
            let dims: Vec<usize> = section
                .get(body + 2..body + 2 + ndims)
                .ok_or_else(|| truncated(&format!("the dimensions of {name}")))?
                .iter()
                .map(|&d| d as usize)
                .collect();
            let size = match kind {
                -1 | 1 => 1,
                2 => 2,
                4 => 4,
                k => return Err(format!("parameter {name} has the unknown type {k}")),
            };
            // At most 255^255 by the format; the section's length bounds it first.
            let len = dims
                .iter()
                .try_fold(size, |a: usize, &d| a.checked_mul(d))
                .filter(|&l| l <= section.len())
                .ok_or_else(|| truncated(&format!("the values of {name}")))?;
            let start = body + 2 + ndims;
            let data = section
                .get(start..start + len)
                .ok_or_else(|| truncated(&format!("the values of {name}")))?;
            params.push(Param {
                group: id as u8,
                name: name.clone(),
                kind,
                dims,
                data,
            });
        }
        if offset == 0 {
            break;
        }
        if offset < 0 {
            return Err(format!("the entry of {name} points backwards ({offset})"));
        }
        pos = offset_at + offset as usize;
    }
    Ok(Params {
        processor,
        groups,
        params,
    })
}

/// Parses the bytes of a C3D file: its points, residuals, labels, rate and units (the
/// analog samples are skipped). The error says what is wrong (the caller adds the file
/// name).
pub fn parse(bytes: &[u8]) -> Result<C3d, String> {
    parse_from(bytes)
}

/// [`parse`] of a C3D file read from `src`: its header and parameter section first, then
/// its frames [`Source::piece`] bytes at a time, so that a file read from disk
/// ([`crate::source::FileSource`]) is never held whole (its analog samples are read past).
pub fn parse_from<S: Source + ?Sized>(src: &S) -> Result<C3d, String> {
    let head = head(src)?;
    let (processor, params) = parameters(&head)?;
    let layout = Layout::of(&head, &tail(src)?, src.size(), processor, &params)?;
    let (positions, residuals, cameras) = read_points(src, processor, &layout)?;
    let units = params
        .strings("POINT", "UNITS")
        .and_then(|u| u.into_iter().next())
        .filter(|u| !u.is_empty())
        .unwrap_or_else(|| "mm".into());
    let labels = labels(&params, layout.points);
    let mut notes = layout.notes;
    let unmarked_nan = residuals
        .iter()
        .zip(positions.chunks_exact(3))
        .filter(|(r, p)| (**r >= 0.0 || r.is_nan()) && p.iter().any(|v| v.is_nan()))
        .count();
    if unmarked_nan > 0 {
        notes.push(format!(
            "{unmarked_nan} points have NaN coordinates without a negative residual: read as \
             not measured"
        ));
    }
    Ok(C3d {
        frames: layout.frames,
        points: layout.points,
        first_frame: layout.first_frame,
        rate: layout.rate,
        scale: layout.scale,
        units,
        model_outputs: model_outputs(&params, &labels),
        labels,
        positions,
        residuals,
        cameras,
        notes,
    })
}

/// The last block of the file `src` (all of it, if shorter): where [`Layout::of`] tells
/// padding from frames.
pub(super) fn tail<S: Source + ?Sized>(src: &S) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    let len = src.size();
    let from = len.saturating_sub(512);
    src.bytes_at(from, len - from)
}

/// The first bytes of the file `src`, through the end of its parameter section: all that
/// [`parameters`] and [`Layout::of`] read (the whole file when its header cannot say where
/// that section ends).
pub(super) fn head<S: Source + ?Sized>(src: &S) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    let len = src.size();
    let whole = || src.bytes_at(0, len);
    if len < 512 {
        return whole();
    }
    let header = src.bytes_at(0, 512)?;
    let pstart = (header[0] as usize).saturating_sub(1) * 512;
    if header[0] == 0 || pstart + 4 > len {
        return whole();
    }
    let blocks = src.bytes_at(pstart + 2, 1)?[0];
    let pend = len.min(pstart + (blocks as usize).max(1) * 512);
    src.bytes_at(0, pend.max(512))
}

/// The header's checks, the processor, and the parameter section.
pub(super) fn parameters(bytes: &[u8]) -> Result<(Processor, Params<'_>), String> {
    if bytes.len() < 512 {
        return Err(format!(
            "truncated: {} bytes, shorter than the 512-byte header",
            bytes.len()
        ));
    }
    if bytes[1] != 0x50 {
        return Err(format!(
            "not a C3D file: its second byte is {:#04x}, not 0x50",
            bytes[1]
        ));
    }
    let param_block = bytes[0] as usize;
    if param_block == 0 {
        return Err("the header names parameter block 0".into());
    }
    let pstart = (param_block - 1) * 512;
    let phead = bytes.get(pstart..pstart + 4).ok_or_else(|| {
        format!(
            "truncated: the parameters start at byte {pstart}, past its {} bytes",
            bytes.len()
        )
    })?;
    let processor = match phead[3] {
        84 => Processor::Intel,
        85 => Processor::Dec,
        86 => Processor::Mips,
        p => {
            return Err(format!(
                "unknown processor type {p} (84 Intel, 85 DEC, 86 MIPS)"
            ));
        }
    };
    let pend = bytes.len().min(pstart + (phead[2] as usize).max(1) * 512);
    Ok((processor, parse_params(&bytes[pstart..pend], processor)?))
}

/// A file's positions `[T, N, 3]`, residuals `[T, N]` and camera masks `[T, N]`.
type Points = (Vec<f32>, Vec<f32>, Vec<u8>);

/// The positions `[T, N, 3]`, residuals `[T, N]` and camera masks `[T, N]` of every frame,
/// read from `src` as many whole frames at a time as [`Source::piece`] allows.
fn read_points<S: Source + ?Sized>(
    src: &S,
    processor: Processor,
    layout: &Layout,
) -> Result<Points, String> {
    let (frames, points, start, record) =
        (layout.frames, layout.points, layout.start, layout.record);
    let float = layout.scale < 0.0;
    let size = if float { 4 } else { 2 };
    let magnitude = layout.scale.abs();
    let mut positions = Vec::with_capacity(frames * points * 3);
    let mut residuals = Vec::with_capacity(frames * points);
    let mut cameras = Vec::with_capacity(frames * points);
    let per_read = (src.piece() / record.max(1)).clamp(1, frames.max(1));
    for first in (0..frames).step_by(per_read) {
        let count = per_read.min(frames - first);
        // Through the last frame's points: its analog samples are not needed.
        let len = (count - 1) * record + 4 * points * size;
        let chunk = src.bytes_at(start + first * record, len)?;
        for k in 0..count {
            let row = &chunk[k * record..k * record + 4 * points * size];
            for p in row.chunks_exact(4 * size) {
                let w = if float {
                    for c in 0..3 {
                        positions.push(processor.f32(&p[4 * c..4 * c + 4]));
                    }
                    let w = processor.f32(&p[12..16]);
                    // The word is an integer stored as a float. NaN says nothing of the
                    // residual: the point counts by its coordinates (`C3d::present`).
                    if w.is_nan() || w.to_bits() == (-0.0f32).to_bits() {
                        residuals.push(if w.is_nan() { f32::NAN } else { -0.0 });
                        cameras.push(0);
                        continue;
                    }
                    w as i32
                } else {
                    for c in 0..3 {
                        let v = processor.u16(&p[2 * c..2 * c + 2]) as i16;
                        positions.push(v as f32 * magnitude);
                    }
                    processor.u16(&p[6..8]) as i16 as i32
                };
                if w < 0 {
                    residuals.push(-1.0);
                    cameras.push(0);
                } else {
                    residuals.push((w & 0xff) as f32 * magnitude);
                    cameras.push(((w & 0x7f00) >> 8) as u8);
                }
            }
        }
    }
    Ok((positions, residuals, cameras))
}

/// The `points` labels: `POINT:LABELS`, then `LABELS2`, ... until there are enough, `""`
/// where missing.
fn labels(params: &Params, points: usize) -> Vec<String> {
    let mut labels: Vec<String> = params.strings("POINT", "LABELS").unwrap_or_default();
    for more in 2.. {
        match params.strings("POINT", &format!("LABELS{more}")) {
            Some(l) if labels.len() < points => labels.extend(l),
            _ => break,
        }
    }
    labels.resize(points, String::new());
    labels
}

/// The parameters of `POINT` that list a model's outputs by default, as Nexus and BTK
/// name them.
pub(super) const OUTPUT_PARAMS: [&str; 6] = [
    "ANGLES",
    "FORCES",
    "MOMENTS",
    "POWERS",
    "SCALARS",
    "REACTIONS",
];

/// For each point, the parameter of `POINT` that lists its label as a model's output:
/// one of [`OUTPUT_PARAMS`], or one that `POINT:TYPE_GROUPS` names (its pairs of a
/// parameter and a type, the parameter first); `None` for a marker.
fn model_outputs(params: &Params, labels: &[String]) -> Vec<Option<String>> {
    let mut names: HashSet<String> = OUTPUT_PARAMS.iter().map(|s| s.to_string()).collect();
    if let Some(pairs) = params.strings("POINT", "TYPE_GROUPS") {
        names.extend(pairs.iter().step_by(2).map(|n| n.to_ascii_uppercase()));
    }
    // Each listed label is looked up once: a hostile file's lists cost their length.
    let mut points: HashMap<&str, Vec<usize>> = HashMap::new();
    for (i, label) in labels.iter().enumerate().filter(|(_, l)| !l.is_empty()) {
        points.entry(label.as_str()).or_default().push(i);
    }
    let mut outputs = vec![None; labels.len()];
    for p in params.of_group("POINT") {
        let name = p.name.to_ascii_uppercase();
        if !names.contains(&name) {
            continue;
        }
        for listed in p.strings().unwrap_or_default() {
            for &i in points.get(listed.as_str()).into_iter().flatten() {
                outputs[i].get_or_insert_with(|| name.clone());
            }
        }
    }
    outputs
}

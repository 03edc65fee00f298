//! Writing a C3D file: an Intel float file of the points and their labels.

use super::C3d;
use super::read::OUTPUT_PARAMS;

/// The most labels one `POINT:LABELS` parameter holds (a dimension is a byte).
const LABELS_PER_PARAM: usize = 255;

/// A parameter section under construction (Intel byte order).
pub(super) struct Section {
    pub(super) bytes: Vec<u8>,
    /// Where the last entry's offset field is, to zero it at the end.
    pub(super) last_offset: Option<usize>,
}

impl Section {
    pub(super) fn entry(&mut self, id: i8, name: &str, body: &[u8]) {
        self.bytes.push(name.len() as u8);
        self.bytes.push(id as u8);
        self.bytes.extend_from_slice(name.as_bytes());
        self.last_offset = Some(self.bytes.len());
        let offset = (2 + body.len() + 1) as u16;
        self.bytes.extend_from_slice(&offset.to_le_bytes());
        self.bytes.extend_from_slice(body);
        self.bytes.push(0); // no description
    }

    pub(super) fn group(&mut self, id: i8, name: &str) {
        self.bytes.push(name.len() as u8);
        self.bytes.push((-id) as u8);
        self.bytes.extend_from_slice(name.as_bytes());
        self.last_offset = Some(self.bytes.len());
        self.bytes.extend_from_slice(&3u16.to_le_bytes());
        self.bytes.push(0);
    }

    pub(super) fn param(&mut self, id: i8, name: &str, kind: i8, dims: &[usize], data: &[u8]) {
        let mut body = vec![kind as u8, dims.len() as u8];
        body.extend(dims.iter().map(|&d| d as u8));
        body.extend_from_slice(data);
        self.entry(id, name, &body);
    }

    pub(super) fn i16s(&mut self, id: i8, name: &str, values: &[u16]) {
        let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let dims: &[usize] = if values.len() == 1 {
            &[]
        } else {
            &[values.len()]
        };
        self.param(id, name, 2, dims, &data);
    }

    pub(super) fn f32(&mut self, id: i8, name: &str, value: f32) {
        self.param(id, name, 4, &[], &value.to_le_bytes());
    }

    pub(super) fn strings(&mut self, id: i8, name: &str, values: &[&str]) {
        let len = values.iter().map(|s| s.len()).max().unwrap_or(0).max(1);
        let mut data = Vec::with_capacity(len * values.len());
        for s in values {
            data.extend_from_slice(s.as_bytes());
            data.resize(data.len() + len - s.len(), b' ');
        }
        self.param(id, name, -1, &[len, values.len()], &data);
    }
}

/// The bytes of `data` as a C3D file: Intel floats, the header and the `POINT` group
/// (`USED`, `FRAMES`, `SCALE`, `RATE`, `DATA_START`, `UNITS`, `LABELS`, `LABELS2`, ...,
/// and blank `DESCRIPTIONS` beside them, and the parameters that list model outputs),
/// `ANALOG:USED = 0` (at the points' rate), `TRIAL:ACTUAL_START_FIELD`/`ACTUAL_END_FIELD` when a frame
/// number passes 65535, and `POINT:LONG_FRAMES` and the `TRIAL` range when the frame count
/// reaches it (exactly: at most 2²⁴ frames are written). A negative residual is written as `−1` (not measured), NaN as NaN (a point
/// of unknown residual, [`C3d::present`]); every other is rounded to the nearest multiple of `|scale|` up to 255 of them. Refuses what the
/// format cannot hold: more than 65535 points, a label or unit over 255 bytes, a frame
/// number past `u32`, a scale that is zero or not finite.
pub fn encode(data: &C3d) -> Result<Vec<u8>, String> {
    let (entries, last) = check(data)?;
    let n = data.points;
    let scale = -data.scale.abs();
    let (section, data_block) = parameters(data, scale, last)?;
    let mut out = vec![0u8; 512];
    out[0] = 2;
    out[1] = 0x50;
    let mut put = |w: usize, v: u16| out[2 * (w - 1)..2 * w].copy_from_slice(&v.to_le_bytes());
    put(2, n as u16);
    put(3, 0);
    // One analog sample per frame, of no channel: ANALOG:RATE / POINT:RATE, as readers
    // check.
    put(10, 1);
    put(4, data.first_frame.min(u16::MAX as u32) as u16);
    put(5, last.min(u16::MAX as u32) as u16);
    put(9, data_block as u16);
    out[12..16].copy_from_slice(&scale.to_le_bytes());
    out[20..24].copy_from_slice(&data.rate.to_le_bytes());
    out.extend_from_slice(&section);
    out.reserve(entries * 16 + 512);
    let magnitude = scale.abs();
    for e in 0..entries {
        for c in 0..3 {
            out.extend_from_slice(&data.positions[3 * e + c].to_le_bytes());
        }
        let r = data.residuals[e];
        // A NaN residual is a point of unknown residual, as the reader reads it.
        let w = if r.is_nan() {
            f32::NAN
        } else if r == 0.0 && r.is_sign_negative() {
            -0.0
        } else if r < 0.0 {
            -1.0f32
        } else {
            let byte = (r / magnitude).round().clamp(0.0, 255.0) as u32;
            (((data.cameras[e] as u32 & 0x7f) << 8) | byte) as f32
        };
        out.extend_from_slice(&w.to_le_bytes());
    }
    out.resize(out.len().div_ceil(512) * 512, 0);
    Ok(out)
}

/// The frame and entry counts of `data`, checked against what the format holds: the
/// entries `T·N` and the last frame's number.
fn check(data: &C3d) -> Result<(usize, u32), String> {
    let (t, n) = (data.frames, data.points);
    let entries = t
        .checked_mul(n)
        .ok_or_else(|| format!("{t} frames of {n} points overflow"))?;
    if t == 0 || n == 0 {
        return Err(format!("{t} frames of {n} points: nothing to write"));
    }
    if n > u16::MAX as usize {
        return Err(format!("{n} points: a C3D file holds at most 65535"));
    }
    // POINT:LONG_FRAMES is a float: past 2^24 it no longer states the count exactly.
    if t > 1 << 24 {
        return Err(format!("{t} frames: doma writes at most 16777216"));
    }
    if data.positions.len() != 3 * entries
        || data.residuals.len() != entries
        || data.cameras.len() != entries
        || data.labels.len() != n
        || data.model_outputs.len() != n
    {
        return Err(format!(
            "{} coordinates, {} residuals, {} camera masks, {} labels and {} point kinds for \
             {t} frames of {n} points",
            data.positions.len(),
            data.residuals.len(),
            data.cameras.len(),
            data.labels.len(),
            data.model_outputs.len()
        ));
    }
    for (name, listed) in output_lists(data) {
        if name.is_empty() || name.len() > 127 || !name.is_ascii() {
            return Err(format!(
                "the parameter {name:?} that lists model outputs is not 1 to 127 ASCII bytes"
            ));
        }
        let own = [
            "USED",
            "FRAMES",
            "LONG_FRAMES",
            "SCALE",
            "RATE",
            "DATA_START",
            "UNITS",
            "TYPE_GROUPS",
        ];
        let upper = name.to_ascii_uppercase();
        if own.contains(&upper.as_str())
            || upper.starts_with("LABELS")
            || upper.starts_with("DESCRIPTIONS")
        {
            return Err(format!(
                "POINT:{name} cannot list model outputs: doma writes its own POINT:{name}"
            ));
        }
        if listed.len() > LABELS_PER_PARAM {
            return Err(format!(
                "POINT:{name} would list {} model outputs, more than {LABELS_PER_PARAM}",
                listed.len()
            ));
        }
    }
    if !(data.scale.is_finite() && data.scale != 0.0) {
        return Err(format!("the point scale is {}", data.scale));
    }
    if !(data.rate.is_finite() && data.rate > 0.0) {
        return Err(format!("the frame rate is {}", data.rate));
    }
    if let Some(l) = data.labels.iter().find(|l| l.len() > 255) {
        return Err(format!("the label {l:?} is longer than 255 bytes"));
    }
    if data.units.len() > 255 {
        return Err("the units are longer than 255 bytes".into());
    }
    let last = data
        .first_frame
        .checked_add(t as u32 - 1)
        .filter(|_| t <= u32::MAX as usize)
        .ok_or_else(|| format!("{t} frames from frame {} pass u32", data.first_frame))?;
    Ok((entries, last))
}

/// The parameters that list `data`'s model outputs ([`C3d::model_outputs`]), in the order
/// of their first point, each with the labels it lists.
fn output_lists(data: &C3d) -> Vec<(String, Vec<&str>)> {
    let mut lists: Vec<(String, Vec<&str>)> = Vec::new();
    for (label, name) in data.labels.iter().zip(&data.model_outputs) {
        let Some(name) = name else { continue };
        match lists.iter_mut().find(|(n, _)| n == name) {
            Some((_, listed)) => listed.push(label),
            None => lists.push((name.clone(), vec![label])),
        }
    }
    lists
}

/// The parameter section of `data` (blocks of 512 bytes) and the block where the data
/// start.
fn parameters(data: &C3d, scale: f32, last: u32) -> Result<(Vec<u8>, usize), String> {
    let (t, n) = (data.frames, data.points);
    let (point, analog, trial) = (1i8, 2i8, 3i8);
    let mut s = Section {
        bytes: vec![1, 0x50, 0, 84],
        last_offset: None,
    };
    s.group(point, "POINT");
    s.i16s(point, "USED", &[n as u16]);
    s.i16s(point, "FRAMES", &[t.min(u16::MAX as usize) as u16]);
    // A longer count goes where Visual3D and the `c3d` package read it (and where Vicon's
    // software does, the TRIAL range below): c3d.org's "Reading the frame count".
    if t >= u16::MAX as usize {
        s.f32(point, "LONG_FRAMES", t as f32);
    }
    s.f32(point, "SCALE", scale);
    s.f32(point, "RATE", data.rate);
    let data_start_at = s.bytes.len() + "DATA_START".len() + 2 + 2 + 2;
    s.i16s(point, "DATA_START", &[0]);
    s.strings(point, "UNITS", &[data.units.as_str()]);
    for (i, chunk) in data.labels.chunks(LABELS_PER_PARAM).enumerate() {
        let name = match i {
            0 => "LABELS".to_string(),
            i => format!("LABELS{}", i + 1),
        };
        let labels: Vec<&str> = chunk.iter().map(String::as_str).collect();
        s.strings(point, &name, &labels);
        // Readers expect a description beside each label; doma has none to give.
        let blank = vec![""; chunk.len()];
        s.strings(point, &name.replace("LABELS", "DESCRIPTIONS"), &blank);
    }
    let lists = output_lists(data);
    for (name, listed) in &lists {
        s.strings(point, name, listed);
    }
    // A parameter other than the usual ones is found by readers through TYPE_GROUPS.
    let types: Vec<&str> = lists
        .iter()
        .filter(|(name, _)| !OUTPUT_PARAMS.contains(&name.to_ascii_uppercase().as_str()))
        .flat_map(|(name, _)| [name.as_str(), name.as_str()])
        .collect();
    if !types.is_empty() {
        s.strings(point, "TYPE_GROUPS", &types);
    }
    s.group(analog, "ANALOG");
    s.i16s(analog, "USED", &[0]);
    s.f32(analog, "RATE", data.rate);
    if last > u16::MAX as u32 || t >= u16::MAX as usize {
        let words = |f: u32| [(f & 0xffff) as u16, (f >> 16) as u16];
        s.group(trial, "TRIAL");
        s.i16s(trial, "ACTUAL_START_FIELD", &words(data.first_frame));
        s.i16s(trial, "ACTUAL_END_FIELD", &words(last));
    }
    if let Some(at) = s.last_offset {
        s.bytes[at..at + 2].copy_from_slice(&0u16.to_le_bytes());
    }
    let blocks = s.bytes.len().div_ceil(512);
    if blocks > 255 {
        return Err(format!("{n} labels need more than 255 parameter blocks"));
    }
    s.bytes.resize(blocks * 512, 0);
    s.bytes[2] = blocks as u8;
    let data_block = 2 + blocks;
    if data_block > u16::MAX as usize {
        return Err("the parameter section is too long".into());
    }
    s.bytes[data_start_at..data_start_at + 2].copy_from_slice(&(data_block as u16).to_le_bytes());
    Ok((s.bytes, data_block))
}

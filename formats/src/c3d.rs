//! C3D motion-capture files (c3d.org, "The C3D File Format: A Technical User Guide"): the
//! 3-D points of every frame with their residuals, labels, rate and units.
//!
//! A file is 512-byte blocks:
//! - block 1, the header: the first parameter block, the point count, the analog words per
//!   frame, the first and last frame numbers, the scale factor (negative: the data are
//!   floats), the first data block and the frame rate;
//! - the parameter section: groups (`POINT`, `ANALOG`, `TRIAL`, ...) of typed, dimensioned
//!   parameters (`POINT:USED`, `POINT:LABELS`, ...); its fourth byte names the processor
//!   (84 Intel: little-endian IEEE; 85 DEC: VAX floats; 86 MIPS: big-endian IEEE), which
//!   sets the byte order of every number in the file;
//! - the data: per frame, `x y z w` for each point, then the frame's analog samples, as
//!   floats or as `i16` multiples of the scale. The fourth word `w` holds the residual in
//!   its low byte (in units of `|scale|`) and the mask of the cameras that saw the point in
//!   the next 7 bits; `w < 0` marks a point that was not measured, and a residual of 0 one
//!   that was computed (filled or filtered) rather than measured.
//!
//! [`parse`] reads the points and skips the analog samples; [`encode`] writes an Intel
//! float file with the `POINT` group alone (and `ANALOG:USED = 0`). Every count is checked
//! against the file's length before anything is allocated.

/// The 3-D points of a C3D file.
#[derive(Clone, Debug, PartialEq)]
pub struct C3d {
    /// `T`, the frames.
    pub frames: usize,
    /// `N`, the points (`POINT:USED`).
    pub points: usize,
    /// The number of the first frame (the header's, or `TRIAL:ACTUAL_START_FIELD`).
    pub first_frame: u32,
    /// Frames per second (`POINT:RATE`).
    pub rate: f32,
    /// `POINT:SCALE`: its magnitude is the unit of the residuals (and of integer data).
    pub scale: f32,
    /// `POINT:UNITS` (`"mm"` when the file has none).
    pub units: String,
    /// The point labels (`POINT:LABELS`, `LABELS2`, ...), trimmed; `""` where missing.
    pub labels: Vec<String>,
    /// `[T, N, 3]` frame-major, as stored (whatever a point not measured holds).
    pub positions: Vec<f32>,
    /// `[T, N]`: the residual; negative where the point was not measured, 0 where it was
    /// computed rather than measured.
    pub residuals: Vec<f32>,
    /// `[T, N]`: the mask of the cameras that saw the point (7 bits).
    pub cameras: Vec<u8>,
}

impl C3d {
    /// `[T, N]`: the entries that hold a point, by the two conventions of capture
    /// software: a residual `≥ 0` and not the origin `(0, 0, 0)`, which some systems write
    /// for a point they did not see.
    pub fn present(&self) -> Vec<bool> {
        self.residuals
            .iter()
            .zip(self.positions.chunks_exact(3))
            .map(|(&r, p)| r >= 0.0 && p.iter().any(|&v| v != 0.0))
            .collect()
    }
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Processor {
    Intel,
    Dec,
    Mips,
}

impl Processor {
    fn u16(self, b: &[u8]) -> u16 {
        match self {
            Processor::Mips => u16::from_be_bytes([b[0], b[1]]),
            _ => u16::from_le_bytes([b[0], b[1]]),
        }
    }

    fn f32(self, b: &[u8]) -> f32 {
        match self {
            Processor::Intel => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            Processor::Mips => f32::from_be_bytes([b[0], b[1], b[2], b[3]]),
            // A VAX F-float: its 16-bit words swapped, and an exponent bias 2 above IEEE's.
            Processor::Dec => {
                if b[1] & 0x7f == 0 && b[0] & 0x80 == 0 {
                    0.0
                } else {
                    f32::from_le_bytes([b[2], b[3], b[0], b[1]]) / 4.0
                }
            }
        }
    }
}

/// One parameter of the parameter section.
struct Param<'a> {
    group: u8,
    name: String,
    kind: i8,
    dims: Vec<usize>,
    data: &'a [u8],
}

struct Params<'a> {
    processor: Processor,
    groups: Vec<(u8, String)>,
    params: Vec<Param<'a>>,
}

impl<'a> Params<'a> {
    fn get(&self, group: &str, name: &str) -> Option<&Param<'a>> {
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
    fn u16(&self, group: &str, name: &str) -> Option<u16> {
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

    fn f32(&self, group: &str, name: &str) -> Option<f32> {
        let p = self.get(group, name)?;
        match p.kind {
            4 if p.data.len() >= 4 => Some(self.processor.f32(p.data)),
            2 if p.data.len() >= 2 => Some(self.processor.u16(p.data) as i16 as f32),
            _ => None,
        }
    }

    /// A frame number stored as two 16-bit words, low then high.
    fn frame(&self, group: &str, name: &str) -> Option<u32> {
        let p = self.get(group, name)?;
        (p.kind == 2 && p.data.len() >= 4).then(|| {
            self.processor.u16(&p.data[0..2]) as u32
                | ((self.processor.u16(&p.data[2..4]) as u32) << 16)
        })
    }

    /// A character parameter as strings: `dims = [length, count]` (or `[length]`: one).
    fn strings(&self, group: &str, name: &str) -> Option<Vec<String>> {
        let p = self.get(group, name)?;
        if p.kind != -1 {
            return None;
        }
        let len = p.dims.first().copied().unwrap_or(p.data.len()).max(1);
        Some(
            p.data
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
    let params = parse_params(&bytes[pstart..pend], processor)?;
    let word = |w: usize| processor.u16(&bytes[2 * (w - 1)..2 * w]);
    let points = params.u16("POINT", "USED").unwrap_or_else(|| word(2)) as usize;
    if points == 0 {
        return Err("no 3-D points (POINT:USED is 0)".into());
    }
    let scale = params
        .f32("POINT", "SCALE")
        .unwrap_or_else(|| processor.f32(&bytes[12..16]));
    if !scale.is_finite() || scale == 0.0 {
        return Err(format!("the point scale is {scale}"));
    }
    let rate = params
        .f32("POINT", "RATE")
        .unwrap_or_else(|| processor.f32(&bytes[20..24]));
    if !(rate.is_finite() && rate > 0.0) {
        return Err(format!("the frame rate is {rate}"));
    }
    let first_frame = params
        .frame("TRIAL", "ACTUAL_START_FIELD")
        .unwrap_or(word(4) as u32);
    let header_last = word(5) as u32;
    let last = params
        .frame("TRIAL", "ACTUAL_END_FIELD")
        .filter(|&l| l >= header_last)
        .unwrap_or(header_last);
    if last < first_frame {
        return Err(format!(
            "the last frame ({last}) comes before the first ({first_frame})"
        ));
    }
    let frames = (last - first_frame) as usize + 1;
    let data_block = match word(9) {
        0 => params.u16("POINT", "DATA_START").unwrap_or(0),
        b => b,
    } as usize;
    if data_block < 2 {
        return Err(format!("the data start at block {data_block}"));
    }
    let analog = word(3) as usize;
    let float = scale < 0.0;
    let size = if float { 4 } else { 2 };
    let record = (4 * points + analog) * size;
    let start = (data_block - 1) * 512;
    let needed = frames
        .checked_mul(record)
        .and_then(|d| d.checked_add(start))
        .ok_or_else(|| format!("{frames} frames of {points} points overflow"))?;
    if bytes.len() < needed {
        return Err(format!(
            "truncated: {frames} frames of {points} points (and {analog} analog words) \
             need {needed} bytes, the file has {}",
            bytes.len()
        ));
    }
    let magnitude = scale.abs();
    let mut positions = Vec::with_capacity(frames * points * 3);
    let mut residuals = Vec::with_capacity(frames * points);
    let mut cameras = Vec::with_capacity(frames * points);
    for k in 0..frames {
        let row = &bytes[start + k * record..start + k * record + 4 * points * size];
        for p in row.chunks_exact(4 * size) {
            let w = if float {
                for c in 0..3 {
                    positions.push(processor.f32(&p[4 * c..4 * c + 4]));
                }
                let w = processor.f32(&p[12..16]);
                // The word is an integer stored as a float; NaN counts as not measured.
                if w.is_nan() { -1 } else { w as i32 }
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
    let mut labels: Vec<String> = params.strings("POINT", "LABELS").unwrap_or_default();
    for more in 2.. {
        match params.strings("POINT", &format!("LABELS{more}")) {
            Some(l) if labels.len() < points => labels.extend(l),
            _ => break,
        }
    }
    labels.resize(points, String::new());
    let units = params
        .strings("POINT", "UNITS")
        .and_then(|u| u.into_iter().next())
        .filter(|u| !u.is_empty())
        .unwrap_or_else(|| "mm".into());
    Ok(C3d {
        frames,
        points,
        first_frame,
        rate,
        scale,
        units,
        labels,
        positions,
        residuals,
        cameras,
    })
}

/// The most labels one `POINT:LABELS` parameter holds (a dimension is a byte).
const LABELS_PER_PARAM: usize = 255;

/// A parameter section under construction (Intel byte order).
struct Section {
    bytes: Vec<u8>,
    /// Where the last entry's offset field is, to zero it at the end.
    last_offset: Option<usize>,
}

impl Section {
    fn entry(&mut self, id: i8, name: &str, body: &[u8]) {
        self.bytes.push(name.len() as u8);
        self.bytes.push(id as u8);
        self.bytes.extend_from_slice(name.as_bytes());
        self.last_offset = Some(self.bytes.len());
        let offset = (2 + body.len() + 1) as u16;
        self.bytes.extend_from_slice(&offset.to_le_bytes());
        self.bytes.extend_from_slice(body);
        self.bytes.push(0); // no description
    }

    fn group(&mut self, id: i8, name: &str) {
        self.bytes.push(name.len() as u8);
        self.bytes.push((-id) as u8);
        self.bytes.extend_from_slice(name.as_bytes());
        self.last_offset = Some(self.bytes.len());
        self.bytes.extend_from_slice(&3u16.to_le_bytes());
        self.bytes.push(0);
    }

    fn param(&mut self, id: i8, name: &str, kind: i8, dims: &[usize], data: &[u8]) {
        let mut body = vec![kind as u8, dims.len() as u8];
        body.extend(dims.iter().map(|&d| d as u8));
        body.extend_from_slice(data);
        self.entry(id, name, &body);
    }

    fn i16s(&mut self, id: i8, name: &str, values: &[u16]) {
        let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let dims: &[usize] = if values.len() == 1 {
            &[]
        } else {
            &[values.len()]
        };
        self.param(id, name, 2, dims, &data);
    }

    fn f32(&mut self, id: i8, name: &str, value: f32) {
        self.param(id, name, 4, &[], &value.to_le_bytes());
    }

    fn strings(&mut self, id: i8, name: &str, values: &[&str]) {
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
/// and blank `DESCRIPTIONS` beside them),
/// `ANALOG:USED = 0` (at the points' rate), and `TRIAL:ACTUAL_START_FIELD`/`ACTUAL_END_FIELD` when a frame
/// number passes 65535. A negative residual is written as `−1` (not measured); every other
/// is rounded to the nearest multiple of `|scale|` up to 255 of them. Refuses what the
/// format cannot hold: more than 65535 points, a label or unit over 255 bytes, a frame
/// number past `u32`, a scale that is zero or not finite.
pub fn encode(data: &C3d) -> Result<Vec<u8>, String> {
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
    if data.positions.len() != 3 * entries
        || data.residuals.len() != entries
        || data.cameras.len() != entries
        || data.labels.len() != n
    {
        return Err(format!(
            "{} coordinates, {} residuals, {} camera masks and {} labels for {t} frames of {n} points",
            data.positions.len(),
            data.residuals.len(),
            data.cameras.len(),
            data.labels.len()
        ));
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
    let scale = -data.scale.abs();

    let (point, analog, trial) = (1i8, 2i8, 3i8);
    let mut s = Section {
        bytes: vec![1, 0x50, 0, 84],
        last_offset: None,
    };
    s.group(point, "POINT");
    s.i16s(point, "USED", &[n as u16]);
    s.i16s(point, "FRAMES", &[t.min(u16::MAX as usize) as u16]);
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
    s.group(analog, "ANALOG");
    s.i16s(analog, "USED", &[0]);
    s.f32(analog, "RATE", data.rate);
    if last > u16::MAX as u32 {
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
    out.extend_from_slice(&s.bytes);
    out.reserve(entries * 16 + 512);
    let magnitude = scale.abs();
    for e in 0..entries {
        for c in 0..3 {
            out.extend_from_slice(&data.positions[3 * e + c].to_le_bytes());
        }
        let r = data.residuals[e];
        let w = if r.is_nan() || r < 0.0 {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> C3d {
        C3d {
            frames: 3,
            points: 2,
            first_frame: 7,
            rate: 120.0,
            scale: -0.1,
            units: "mm".into(),
            labels: vec!["LASI".into(), "RASI".into()],
            positions: (0..18).map(|v| v as f32 * 10.5 - 3.0).collect(),
            residuals: vec![0.5, -1.0, 0.0, 1.2, 25.5, 0.3],
            cameras: vec![3, 0, 0, 127, 1, 64],
        }
    }

    #[test]
    fn encode_then_parse_is_the_same_points() {
        let c = sample();
        let bytes = encode(&c).unwrap();
        assert_eq!(bytes.len() % 512, 0);
        let back = parse(&bytes).unwrap();
        assert_eq!(back.positions, c.positions);
        assert_eq!(back.labels, c.labels);
        assert_eq!((back.frames, back.points, back.first_frame), (3, 2, 7));
        assert_eq!(
            (back.rate, back.scale, back.units.as_str()),
            (120.0, -0.1, "mm")
        );
        assert_eq!(back.cameras, c.cameras);
        for (a, b) in back.residuals.iter().zip(&c.residuals) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
        assert_eq!(back.present(), vec![true, false, true, true, true, true]);
    }

    #[test]
    fn integer_and_big_endian_data_are_read() {
        // An integer (positive scale) MIPS file made by hand: one point, two frames.
        let mut b = vec![0u8; 512 * 3];
        b[0] = 2;
        b[1] = 0x50;
        let be =
            |b: &mut Vec<u8>, at: usize, v: u16| b[at..at + 2].copy_from_slice(&v.to_be_bytes());
        be(&mut b, 2, 1); // points
        be(&mut b, 6, 1); // first frame
        be(&mut b, 8, 2); // last frame
        b[12..16].copy_from_slice(&0.5f32.to_be_bytes());
        be(&mut b, 16, 3); // data block
        b[20..24].copy_from_slice(&50f32.to_be_bytes());
        b[512..516].copy_from_slice(&[1, 0x50, 1, 86]);
        let words: [i16; 8] = [2, -4, 6, 0x0102, 8, 10, 12, -1];
        for (i, w) in words.iter().enumerate() {
            b[1024 + 2 * i..1026 + 2 * i].copy_from_slice(&w.to_be_bytes());
        }
        let c = parse(&b).unwrap();
        assert_eq!(c.positions, vec![1.0, -2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(c.residuals, vec![1.0, -1.0]);
        assert_eq!(c.cameras, vec![1, 0]);
        assert_eq!((c.rate, c.first_frame, c.frames), (50.0, 1, 2));
        assert_eq!(c.labels, vec![String::new()]);
    }

    #[test]
    fn dec_floats_are_converted() {
        // 1.0 as a VAX F-float: exponent 129, stored as the words 0x4080, 0x0000.
        let p = Processor::Dec;
        assert_eq!(p.f32(&[0x80, 0x40, 0, 0]), 1.0);
        assert_eq!(p.f32(&[0, 0, 0, 0]), 0.0);
        assert_eq!(p.f32(&[0x80, 0xc0, 0, 0]), -1.0);
    }

    #[test]
    fn defects_are_named() {
        let good = encode(&sample()).unwrap();
        assert!(parse(&good[..100]).unwrap_err().contains("truncated"));
        assert!(
            parse(&good[..good.len() - 512])
                .unwrap_err()
                .contains("truncated")
        );
        let mut bad = good.clone();
        bad[1] = 0;
        assert!(parse(&bad).unwrap_err().contains("not a C3D"));
        let mut bad = good.clone();
        bad[512 + 3] = 90;
        assert!(parse(&bad).unwrap_err().contains("processor"));
        let mut c = sample();
        c.labels.pop();
        assert!(encode(&c).unwrap_err().contains("labels"));
    }

    #[test]
    fn fuzz_regressions_are_refused_or_read() {
        // A group id of −128, whose negation overflows an i8.
        let input = include_bytes!("../../fuzz/regressions/c3d-group-id-overflow");
        let _ = parse(input);
    }

    #[test]
    fn frame_numbers_past_u16_go_through_trial() {
        let mut c = sample();
        c.first_frame = 70_000;
        let back = parse(&encode(&c).unwrap()).unwrap();
        assert_eq!((back.first_frame, back.frames), (70_000, 3));
    }

    #[test]
    fn many_labels_span_several_parameters() {
        let n = 300;
        let c = C3d {
            frames: 1,
            points: n,
            first_frame: 1,
            rate: 100.0,
            scale: -1.0,
            units: "m".into(),
            labels: (0..n).map(|i| format!("M{i}")).collect(),
            positions: vec![1.0; 3 * n],
            residuals: vec![1.0; n],
            cameras: vec![0; n],
        };
        assert_eq!(parse(&encode(&c).unwrap()).unwrap(), c);
    }
}

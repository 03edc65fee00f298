//! Reading a C3D file: the header, the parameter section and the points.

use std::collections::{HashMap, HashSet};

use super::{C3d, Processor};
use crate::source::Source;

/// One parameter of the parameter section.
struct Param<'a> {
    group: u8,
    name: String,
    kind: i8,
    dims: Vec<usize>,
    data: &'a [u8],
}

pub(super) struct Params<'a> {
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

/// Where the points are and how they are stored: what the header and the parameters say,
/// checked against the file's length.
pub(super) struct Layout {
    pub(super) points: usize,
    pub(super) frames: usize,
    pub(super) first_frame: u32,
    pub(super) scale: f32,
    pub(super) rate: f32,
    /// The byte where the first frame starts.
    pub(super) start: usize,
    /// The bytes of one frame, points and analog samples.
    pub(super) record: usize,
    /// What the reader decided where the file was not plain ([`C3d::notes`]).
    pub(super) notes: Vec<String>,
}

/// The largest count a 16-bit frame count holds: a file stating it may hold more.
const CLIPPED: usize = u16::MAX as usize;

/// How one frame is stored: the points, the analog words after them and the word size.
#[derive(Clone, Copy, PartialEq, Debug)]
struct Record {
    points: usize,
    analog: usize,
    float: bool,
}

impl Record {
    fn bytes(self) -> Option<usize> {
        let size = if self.float { 4 } else { 2 };
        self.points
            .checked_mul(4)?
            .checked_add(self.analog)?
            .checked_mul(size)
    }

    fn describe(self) -> String {
        format!(
            "{} points and {} analog words per frame as {}",
            self.points,
            self.analog,
            if self.float { "floats" } else { "integers" }
        )
    }
}

/// Where `frames` frames of `record` bytes from byte `start` end, if that is addressable.
fn end_of(start: usize, frames: usize, record: usize) -> Option<usize> {
    frames.checked_mul(record)?.checked_add(start)
}

/// `frames` frames fit in a file of `len` bytes, and account for all of it but the last
/// block's padding: the file's length confirms the count.
fn confirmed(start: usize, frames: usize, record: usize, len: usize) -> bool {
    end_of(start, frames, record).is_some_and(|end| end <= len && len - end < 512)
}

fn fits(start: usize, frames: usize, record: usize, len: usize) -> bool {
    end_of(start, frames, record).is_some_and(|end| end <= len)
}

impl Layout {
    /// The layout of a file of `len` bytes whose first bytes are `bytes` (at least its
    /// header, [`head`]) and whose last are `tail` ([`tail`]).
    ///
    /// The frame count is read as c3d.org's "Reading the frame count" says: `POINT:FRAMES`
    /// (an integer or a float), and where that holds 65535, `POINT:LONG_FRAMES` or the
    /// `TRIAL:ACTUAL_START_FIELD`..`ACTUAL_END_FIELD` range (refused where the two
    /// disagree); the header's frame range where the parameters state none. Where the
    /// header and the parameters disagree on the frame layout (the points, the analog words
    /// per frame, floats or integers) or the count, the file is read as its length
    /// confirms, or refused naming both: never misaligned.
    pub(super) fn of(
        bytes: &[u8],
        tail: &[u8],
        len: usize,
        processor: Processor,
        params: &Params,
    ) -> Result<Self, String> {
        let word = |w: usize| processor.u16(&bytes[2 * (w - 1)..2 * w]);
        let header_scale = processor.f32(&bytes[12..16]);
        let scale = params.f32("POINT", "SCALE").unwrap_or(header_scale);
        if !scale.is_finite() || scale == 0.0 {
            return Err(format!("the point scale is {scale}"));
        }
        let rate = params
            .f32("POINT", "RATE")
            .unwrap_or_else(|| processor.f32(&bytes[20..24]));
        if !(rate.is_finite() && rate > 0.0) {
            return Err(format!("the frame rate is {rate}"));
        }
        let data_block = match word(9) {
            0 => params.u16("POINT", "DATA_START").unwrap_or(0),
            b => b,
        } as usize;
        if data_block < 2 {
            return Err(format!("the data start at block {data_block}"));
        }
        let start = (data_block - 1) * 512;
        let first_frame = params
            .frame("TRIAL", "ACTUAL_START_FIELD")
            .unwrap_or(word(4) as u32);

        // The record as the parameters say it, and as the header does.
        let by_params = Record {
            points: params.u16("POINT", "USED").unwrap_or_else(|| word(2)) as usize,
            analog: analog_words(params, rate).unwrap_or(word(3) as usize),
            float: scale < 0.0,
        };
        let by_header = Record {
            points: word(2) as usize,
            analog: word(3) as usize,
            float: !(header_scale.is_finite() && header_scale > 0.0),
        };
        if by_params.points == 0 {
            return Err("no 3-D points (POINT:USED is 0)".into());
        }
        let stated = stated_frames(params)?;
        let header_frames = (word(5) >= word(4)).then(|| (word(5) - word(4)) as usize + 1);
        let counts = Counts {
            stated,
            header: header_frames,
            start,
            len,
            tail,
        };

        let mut notes = Vec::new();
        let record = if by_params == by_header || by_header.points == 0 {
            by_params
        } else {
            // Every mix of the two: the one the file's length confirms, or none. One that
            // merely fits is no evidence (a file cut short fits a smaller record).
            let mut mixes = Vec::new();
            for points in [by_params.points, by_header.points] {
                for analog in [by_params.analog, by_header.analog] {
                    for float in [by_params.float, by_header.float] {
                        let r = Record {
                            points,
                            analog,
                            float,
                        };
                        if r.points > 0 && !mixes.contains(&r) {
                            mixes.push(r);
                        }
                    }
                }
            }
            let confirmed: Vec<Record> = mixes
                .into_iter()
                .filter(|r| r.bytes().is_some_and(|b| counts.confirms(b)))
                .collect();
            let [chosen] = confirmed[..] else {
                return Err(format!(
                    "the header and the parameters disagree: the header says {}, the \
                     parameters {}, and the file's length ({len} bytes) confirms {} \
                     (header words 2, 3 and 7 against POINT:USED, ANALOG:USED × ANALOG:RATE \
                     / POINT:RATE and the sign of POINT:SCALE)",
                    by_header.describe(),
                    by_params.describe(),
                    if confirmed.is_empty() {
                        "neither"
                    } else {
                        "more than one layout"
                    }
                ));
            };
            notes.push(format!(
                "the header says {} where the parameters say {}: read as {}, which the file's \
                 length confirms",
                by_header.describe(),
                by_params.describe(),
                chosen.describe()
            ));
            chosen
        };
        let record_bytes = record.bytes().ok_or_else(|| {
            format!(
                "{} points and {} analog words overflow",
                record.points, record.analog
            )
        })?;
        let frames = counts.frames(record_bytes, &mut notes)?;
        let end = end_of(start, frames, record_bytes)
            .ok_or_else(|| format!("{frames} frames of {} points overflow", record.points))?;
        if len < end {
            return Err(format!(
                "truncated: {frames} frames of {} points (and {} analog words) need {end} \
                 bytes, the file has {len}",
                record.points, record.analog
            ));
        }
        let scale = if record.float == (scale < 0.0) {
            scale
        } else {
            -scale
        };
        Ok(Layout {
            points: record.points,
            frames,
            first_frame,
            scale,
            rate,
            start,
            record: record_bytes,
            notes,
        })
    }
}

/// The analog words per frame the parameters say: `ANALOG:USED` channels of
/// `ANALOG:RATE / POINT:RATE` samples each; `None` where they do not say it whole.
fn analog_words(params: &Params, rate: f32) -> Option<usize> {
    let used = params.u16("ANALOG", "USED")? as usize;
    if used == 0 {
        return Some(0);
    }
    let per_frame = params.f32("ANALOG", "RATE")? / rate;
    let whole = per_frame.round();
    (per_frame.is_finite() && whole >= 1.0 && (per_frame - whole).abs() < 1e-3)
        .then(|| used * whole as usize)
}

/// The frame count the parameters state, by c3d.org's rules, with where it was read:
/// `POINT:FRAMES` unless it holds 65535; then `POINT:LONG_FRAMES` or the `TRIAL` range,
/// which must agree where both are there; `None` where no parameter states one.
fn stated_frames(params: &Params) -> Result<Option<(usize, String)>, String> {
    let count = |group: &str, name: &str| -> Result<Option<usize>, String> {
        let Some(p) = params.get(group, name) else {
            return Ok(None);
        };
        let value = match p.kind {
            2 if p.data.len() >= 2 => params.processor.u16(p.data) as f64,
            1 if !p.data.is_empty() => p.data[0] as f64,
            4 if p.data.len() >= 4 => params.processor.f32(p.data) as f64,
            _ => return Ok(None),
        };
        if !(value.is_finite() && value >= 0.0 && value.fract() == 0.0 && value < 1e12) {
            return Err(format!("{group}:{name} states {value} frames"));
        }
        Ok(Some(value as usize))
    };
    let frames = count("POINT", "FRAMES")?;
    if let Some(f) = frames.filter(|&f| f != CLIPPED) {
        return Ok(Some((f, "POINT:FRAMES".into())));
    }
    let long = count("POINT", "LONG_FRAMES")?;
    let trial = match (
        params.frame("TRIAL", "ACTUAL_START_FIELD"),
        params.frame("TRIAL", "ACTUAL_END_FIELD"),
    ) {
        (Some(s), Some(e)) if e >= s => Some((e - s) as usize + 1),
        _ => None,
    };
    Ok(match (long, trial) {
        (Some(l), Some(t)) if l != t => {
            return Err(format!(
                "POINT:LONG_FRAMES states {l} frames and TRIAL:ACTUAL_START_FIELD..\
                 ACTUAL_END_FIELD {t}: they disagree"
            ));
        }
        (Some(l), _) => Some((l, "POINT:LONG_FRAMES".into())),
        (None, Some(t)) => Some((t, "TRIAL:ACTUAL_START_FIELD..ACTUAL_END_FIELD".into())),
        (None, None) => frames.map(|f| (f, "POINT:FRAMES".into())),
    })
}

/// The frame counts a file states, and where its frames are, to choose between them by
/// the file's length.
struct Counts<'a> {
    stated: Option<(usize, String)>,
    header: Option<usize>,
    start: usize,
    len: usize,
    /// The file's last bytes (up to 512).
    tail: &'a [u8],
}

impl Counts<'_> {
    /// The candidate counts: the parameters' first, then the header's where it differs.
    fn candidates(&self) -> Vec<usize> {
        let mut c: Vec<usize> = self.stated.iter().map(|(f, _)| *f).collect();
        c.extend(self.header.filter(|h| !c.contains(h)));
        c
    }

    fn confirms(&self, record: usize) -> bool {
        let c = self.candidates();
        c.iter()
            .any(|&f| confirmed(self.start, f, record, self.len))
            || c.contains(&CLIPPED) && self.beyond_clipped(record).is_some()
    }

    /// Where every count the file states is 65535 and its length holds more whole frames
    /// than that, the frames it holds: the last block's padding (frames of zero bytes
    /// alone, inside the file's last 512 bytes) not counted.
    fn beyond_clipped(&self, record: usize) -> Option<usize> {
        let c = self.candidates();
        if c.iter().any(|&f| f != CLIPPED) || record == 0 || self.len < self.start {
            return None;
        }
        let mut held = (self.len - self.start) / record;
        let tail_from = self.len - self.tail.len();
        while held > CLIPPED {
            let at = self.start + (held - 1) * record;
            let frame = at
                .checked_sub(tail_from)
                .and_then(|from| self.tail.get(from..from + record));
            match frame {
                Some(f) if f.iter().all(|&b| b == 0) => held -= 1,
                _ => break,
            }
        }
        (held > CLIPPED).then_some(held)
    }

    /// The frame count for frames of `record` bytes: the stated one where the header
    /// agrees or says none; else the one the length confirms; else the stated one where it
    /// fits, else the header's. A count of 65535 (all a 16-bit count holds) over a file
    /// that holds more frames is read by its length, with a note.
    fn frames(&self, record: usize, notes: &mut Vec<String>) -> Result<usize, String> {
        if let Some(held) = self.beyond_clipped(record) {
            notes.push(format!(
                "the file states 65535 frames, all a 16-bit count holds, and no longer count \
                 (POINT:LONG_FRAMES, TRIAL:ACTUAL_END_FIELD, a float POINT:FRAMES); its length \
                 holds {held}: read {held}"
            ));
            return Ok(held);
        }
        let (stated, from) = match (&self.stated, self.header) {
            (None, None) => return Err("no frames: the last frame comes before the first".into()),
            (None, Some(h)) => return Ok(h),
            (Some((f, _)), Some(h)) if *f == h => return Ok(h),
            (Some((f, _)), None) => return Ok(*f),
            (Some((f, from)), Some(_)) => (*f, from),
        };
        let header = self.header.unwrap_or(stated);
        let (s_ok, h_ok) = (
            confirmed(self.start, stated, record, self.len),
            confirmed(self.start, header, record, self.len),
        );
        let chosen = if s_ok != h_ok {
            if s_ok { stated } else { header }
        } else if fits(self.start, stated, record, self.len) {
            stated
        } else if fits(self.start, header, record, self.len) {
            header
        } else {
            stated
        };
        // A header count below the stated one is the 16-bit range clipped, or the raw
        // range the frames came from (c3d.org): said only where it was read instead.
        if chosen != stated {
            notes.push(format!(
                "{from} states {stated} frames, the header's frame range {header}: read \
                 {header}, which the file's length confirms"
            ));
        }
        Ok(chosen)
    }
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

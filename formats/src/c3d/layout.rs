//! Where a C3D file's frames are and how many: the header and the parameter section
//! cross-checked against the file's length ([`Layout::of`]), so that a frame is never read
//! misaligned and no count is trusted past what the file holds.

use super::Processor;
use super::read::Params;

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
    /// What the reader decided where the file was not plain ([`super::C3d::notes`]).
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
    /// header, [`super::read::head`]) and whose last are `tail` ([`super::read::tail`]).
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
            reconciled(by_params, by_header, &counts, &mut notes)?
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

/// The record of a file whose header (`by_header`) and parameters (`by_params`)
/// disagree: of every mix of the two, the one the file's length confirms, with a note;
/// refused where none or several are. One that merely fits is no evidence (a file cut
/// short fits a smaller record).
fn reconciled(
    by_params: Record,
    by_header: Record,
    counts: &Counts,
    notes: &mut Vec<String>,
) -> Result<Record, String> {
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
            "the header and the parameters disagree: the header says {}, the parameters {}, \
             and the file's length ({} bytes) confirms {} (header words 2, 3 and 7 against \
             POINT:USED, ANALOG:USED × ANALOG:RATE / POINT:RATE and the sign of POINT:SCALE)",
            by_header.describe(),
            by_params.describe(),
            counts.len,
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
    Ok(chosen)
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

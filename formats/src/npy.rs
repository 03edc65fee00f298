//! NumPy's `.npy` arrays and `.npz` archives, the format the authors' data comes in
//! (REFERENCE §6: `[T, N, 3]` float64 trajectories).
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
//! header, an unsupported dtype, a count that overflows, a bad CRC) is an error saying what
//! is wrong; nothing panics.

use crate::{crc32, size_mismatch};

/// The six magic bytes of a `.npy` file.
pub const NPY_MAGIC: &[u8; 6] = b"\x93NUMPY";

/// An n-dimensional array read from a `.npy`, values in C (row-major) order, converted
/// straight to `f32` (the precision doma fits in) as they are read.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The shape, outermost first.
    pub shape: Vec<usize>,
    /// `shape.iter().product()` values, C order.
    pub data: Vec<f32>,
}

/// A `.npy` header: what the array is, known before any of its values are read.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyHeader {
    /// The shape, outermost first.
    pub shape: Vec<usize>,
    /// Elements: the product of `shape` (checked not to overflow).
    pub count: usize,
    /// Bytes of the values: `count` × the element size (checked not to overflow).
    pub payload_bytes: usize,
    /// Where the values start: the magic, version, length and header text.
    pub data_start: usize,
    dtype: Dtype,
    big: bool,
    fortran: bool,
}

/// The longest `.npy` header read (NumPy writes about 128 bytes; version 1 caps it at 64 KiB).
pub const MAX_HEADER_BYTES: usize = 1 << 16;

/// The element types the reader accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Dtype {
    Float(usize),
    Int(usize),
    Uint(usize),
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Dtype::Float(s) | Dtype::Int(s) | Dtype::Uint(s) => s,
        }
    }

    /// The value of one element; `b` is little-endian.
    fn value(self, b: &[u8]) -> f32 {
        let mut le = [0u8; 8];
        le[..b.len()].copy_from_slice(b);
        let raw = u64::from_le_bytes(le);
        match self {
            Dtype::Float(4) => f32::from_bits(raw as u32),
            Dtype::Float(_) => f64::from_bits(raw) as f32,
            Dtype::Uint(_) => raw as f32,
            Dtype::Int(s) => {
                // Sign-extend from `s` bytes.
                let shift = 64 - 8 * s as u32;
                (((raw << shift) as i64) >> shift) as f32
            }
        }
    }
}

fn parse_descr(descr: &str) -> Result<(Dtype, bool), String> {
    let bad = || format!("unsupported dtype {descr:?} (need a float or integer, e.g. '<f4')");
    let (order, rest) = match descr.chars().next() {
        Some(c @ ('<' | '>' | '|' | '=')) => (c, &descr[1..]),
        _ => ('=', descr),
    };
    let kind = rest.chars().next().ok_or_else(bad)?;
    // `kind` may be any character (fuzzing found a two-byte one), so slice past its bytes.
    let size: usize = rest[kind.len_utf8()..].parse().map_err(|_| bad())?;
    let dtype = match (kind, size) {
        ('f', 4 | 8) => Dtype::Float(size),
        ('i', 1 | 2 | 4 | 8) => Dtype::Int(size),
        ('u', 1 | 2 | 4 | 8) => Dtype::Uint(size),
        _ => return Err(bad()),
    };
    // '=' is native order; every target doma builds for is little-endian.
    let big = order == '>' && size > 1;
    Ok((dtype, big))
}

/// The value of `key` in a Python-literal dict header, as the raw text up to its
/// delimiter (a quoted string, a parenthesised tuple or a bare word).
fn header_value<'a>(header: &'a str, key: &str) -> Result<&'a str, String> {
    let missing = || format!("the header has no '{key}' entry");
    let at = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))
        .ok_or_else(missing)?;
    let rest = header[at + key.len() + 2..].trim_start();
    let rest = rest
        .strip_prefix(':')
        .ok_or_else(|| format!("the header's '{key}' entry has no ':'"))?
        .trim_start();
    let end = match rest.chars().next() {
        Some(q @ ('\'' | '"')) => rest[1..].find(q).map(|e| e + 2),
        Some('(') => rest.find(')').map(|e| e + 1),
        Some(_) => rest.find([',', '}']),
        None => None,
    }
    .ok_or_else(|| format!("the header's '{key}' entry is not terminated"))?;
    Ok(rest[..end].trim())
}

fn parse_shape(text: &str) -> Result<Vec<usize>, String> {
    let inner = text
        .strip_prefix('(')
        .and_then(|t| t.strip_suffix(')'))
        .ok_or_else(|| format!("the shape {text} is not a tuple"))?;
    inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.trim_end_matches('L')
                .parse::<usize>()
                .map_err(|_| format!("the shape {text} has a bad dimension {s:?}"))
        })
        .collect()
}

/// Parses a `.npy` header from the first bytes of a file (at least up to the end of the
/// header text); the error says what is wrong.
pub fn parse_npy_header(bytes: &[u8]) -> Result<NpyHeader, String> {
    if bytes.len() < 10 {
        return Err(format!(
            "truncated: {} bytes, shorter than the smallest .npy header",
            bytes.len()
        ));
    }
    if &bytes[..6] != NPY_MAGIC {
        return Err("not a .npy file: the magic is not \\x93NUMPY".into());
    }
    let (header_len, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        2 | 3 => return Err("truncated: the version 2 header length is cut off".into()),
        v => return Err(format!("unsupported .npy version {v}.{}", bytes[7])),
    };
    if header_len > MAX_HEADER_BYTES {
        return Err(format!(
            "the header says it is {header_len} bytes long, over the {MAX_HEADER_BYTES} read"
        ));
    }
    let data_start = start
        .checked_add(header_len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| {
            format!(
                "truncated: the header says {header_len} header bytes, the file has {}",
                bytes.len() - start
            )
        })?;
    let header = std::str::from_utf8(&bytes[start..data_start])
        .map_err(|_| "the header is not text".to_string())?;
    let descr = header_value(header, "descr")?;
    let descr = descr.trim_matches(|c| c == '\'' || c == '"');
    let (dtype, big) = parse_descr(descr)?;
    let fortran = match header_value(header, "fortran_order")? {
        "False" => false,
        "True" => true,
        other => return Err(format!("fortran_order is {other}, not True or False")),
    };
    let shape = parse_shape(header_value(header, "shape")?)?;
    let overflow = || format!("the shape {shape:?} overflows");
    let count = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(overflow)?;
    let payload_bytes = count.checked_mul(dtype.size()).ok_or_else(overflow)?;
    data_start.checked_add(payload_bytes).ok_or_else(overflow)?;
    Ok(NpyHeader {
        shape,
        count,
        payload_bytes,
        data_start,
        dtype,
        big,
        fortran,
    })
}

impl NpyHeader {
    /// The descriptor text, for messages.
    fn describe(&self) -> String {
        format!("shape {:?} of {:?}", self.shape, self.dtype)
    }
}

/// Converts a stream of `.npy` value bytes, in pieces of any length, straight to `f32`.
struct Values<'h> {
    header: &'h NpyHeader,
    out: Vec<f32>,
    element: [u8; 8],
    filled: usize,
}

impl<'h> Values<'h> {
    fn new(header: &'h NpyHeader) -> Self {
        Values {
            header,
            out: Vec::with_capacity(header.count),
            element: [0; 8],
            filled: 0,
        }
    }

    fn push(&mut self, mut bytes: &[u8]) {
        let size = self.header.dtype.size();
        while !bytes.is_empty() {
            let take = (size - self.filled).min(bytes.len());
            self.element[self.filled..self.filled + take].copy_from_slice(&bytes[..take]);
            self.filled += take;
            bytes = &bytes[take..];
            if self.filled == size {
                if self.header.big {
                    self.element[..size].reverse();
                }
                self.out
                    .push(self.header.dtype.value(&self.element[..size]));
                self.filled = 0;
            }
        }
    }

    fn finish(self) -> NpyArray {
        let shape = self.header.shape.clone();
        let data = if self.header.fortran && shape.len() > 1 {
            fortran_to_c(&self.out, &shape)
        } else {
            self.out
        };
        NpyArray { shape, data }
    }
}

/// Parses the bytes of a `.npy` file; the error says what is wrong.
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray, String> {
    let header = parse_npy_header(bytes)?;
    let payload = &bytes[header.data_start..];
    if payload.len() != header.payload_bytes {
        return Err(size_mismatch(
            payload.len(),
            header.payload_bytes,
            &format!("{} needs", header.describe()),
        ));
    }
    let mut values = Values::new(&header);
    values.push(payload);
    Ok(values.finish())
}

/// Reorders column-major values of `shape` into row-major order.
fn fortran_to_c(values: &[f32], shape: &[usize]) -> Vec<f32> {
    let mut strides = vec![1usize; shape.len()];
    for d in 1..shape.len() {
        strides[d] = strides[d - 1] * shape[d - 1];
    }
    let mut index = vec![0usize; shape.len()];
    let mut out = Vec::with_capacity(values.len());
    for _ in 0..values.len() {
        let offset: usize = index.iter().zip(&strides).map(|(i, s)| i * s).sum();
        out.push(values[offset]);
        // Advance the C-order multi-index (last axis fastest).
        for d in (0..shape.len()).rev() {
            index[d] += 1;
            if index[d] < shape[d] {
                break;
            }
            index[d] = 0;
        }
    }
    out
}

/// The bytes of a version-1 `.npy` of little-endian `f32` values, C order.
///
/// # Panics
/// If `data.len()` is not the product of `shape` (a programming error).
pub fn encode_npy(shape: &[usize], data: &[f32]) -> Vec<u8> {
    assert_eq!(
        shape.iter().product::<usize>(),
        data.len(),
        "encode_npy: the data does not fill the shape"
    );
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {tuple}, }}");
    // Pad so that the data starts on a 64-byte boundary, as NumPy does.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 4 * data.len());
    out.extend_from_slice(NPY_MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

fn le_u16(b: &[u8], at: usize) -> Result<u64, String> {
    b.get(at..at + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]) as u64)
        .ok_or_else(|| "truncated zip record".to_string())
}

fn le_u32(b: &[u8], at: usize) -> Result<u64, String> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as u64)
        .ok_or_else(|| "truncated zip record".to_string())
}

fn le_u64(b: &[u8], at: usize) -> Result<u64, String> {
    b.get(at..at + 8)
        .map(|s| u64::from_le_bytes(s.try_into().expect("8 bytes")))
        .ok_or_else(|| "truncated zip record".to_string())
}

/// One member of a `.npz` archive, as its directory describes it; nothing is inflated yet.
#[derive(Clone, Debug, PartialEq)]
pub struct NpzMember {
    /// The member's name without `.npy`.
    pub name: String,
    /// The zip compression method (0 stored, 8 deflated).
    method: u64,
    crc: u32,
    /// The member's bytes in the file.
    data: std::ops::Range<usize>,
    /// The bytes it holds once inflated (the `.npy` file).
    pub size: usize,
}

/// Deflate's largest possible expansion: 258 output bytes from 2 bits, so no stream inflates
/// to more than about 1032 times its length. A directory that says otherwise is lying.
pub const DEFLATE_MAX_RATIO: usize = 1032;

/// Reads the zip directory of a `.npz`: every member's name, method and sizes, checked
/// against the file (a stored member must be in the file; a deflated one cannot hold more
/// than [`DEFLATE_MAX_RATIO`] times its bytes). Inflates nothing and allocates nothing in
/// proportion to a declared size.
pub fn npz_members(bytes: &[u8]) -> Result<Vec<NpzMember>, String> {
    const EOCD: [u8; 4] = [0x50, 0x4b, 0x05, 0x06];
    if bytes.len() < 22 {
        return Err(format!(
            "truncated: {} bytes, shorter than a zip directory",
            bytes.len()
        ));
    }
    let search_from = bytes.len().saturating_sub(22 + 65_535);
    let eocd = (search_from..=bytes.len() - 22)
        .rev()
        .find(|&i| bytes[i..i + 4] == EOCD)
        .ok_or("not a .npz (zip) file, or truncated: no end-of-central-directory record")?;
    let mut entries = le_u16(bytes, eocd + 10)?;
    let mut dir = le_u32(bytes, eocd + 16)?;
    // Zip64: the 32-bit fields are saturated and a zip64 record precedes the locator.
    if (entries == 0xFFFF || dir == 0xFFFF_FFFF) && eocd >= 20 {
        let locator = eocd - 20;
        if le_u32(bytes, locator)? == 0x0706_4b50 {
            let record = offset(le_u64(bytes, locator + 8)?)?;
            if le_u32(bytes, record)? != 0x0606_4b50 {
                return Err("the zip64 directory record is missing".into());
            }
            entries = le_u64(bytes, record + 32)?;
            dir = le_u64(bytes, record + 48)?;
        }
    }
    // Each directory entry takes at least 46 bytes, so a count past that is a lie.
    if entries > (bytes.len() / 46) as u64 {
        return Err(format!(
            "the zip directory claims {entries} members, more than the file can hold"
        ));
    }
    let mut at = offset(dir)?;
    let mut members = Vec::new();
    for _ in 0..entries {
        let (member, next) = directory_entry(bytes, at)?;
        members.push(member);
        at = next;
    }
    Ok(members)
}

/// A `u64` from the file as an offset or size, refused when it cannot be one.
fn offset(v: u64) -> Result<usize, String> {
    usize::try_from(v).map_err(|_| format!("a zip offset or size ({v}) overflows"))
}

/// The directory entry at `at`, and where the next one starts.
fn directory_entry(bytes: &[u8], at: usize) -> Result<(NpzMember, usize), String> {
    if le_u32(bytes, at)? != 0x0201_4b50 {
        return Err(format!("the zip directory is corrupt at byte {at}"));
    }
    let method = le_u16(bytes, at + 10)?;
    let crc = le_u32(bytes, at + 16)? as u32;
    let mut packed = le_u32(bytes, at + 20)?;
    let mut size = le_u32(bytes, at + 24)?;
    let name_len = le_u16(bytes, at + 28)? as usize;
    let extra_len = le_u16(bytes, at + 30)? as usize;
    let comment_len = le_u16(bytes, at + 32)? as usize;
    let mut local = le_u32(bytes, at + 42)?;
    let name_bytes = bytes
        .get(at + 46..at + 46 + name_len)
        .ok_or("truncated zip directory")?;
    let full_name = String::from_utf8_lossy(name_bytes).into_owned();
    // Zip64 extra field (id 1): the saturated sizes and offset, in this order.
    let extra = bytes
        .get(at + 46 + name_len..at + 46 + name_len + extra_len)
        .ok_or("truncated zip directory")?;
    let mut e = 0;
    while e + 4 <= extra.len() {
        let id = le_u16(extra, e)?;
        let len = le_u16(extra, e + 2)? as usize;
        if id == 1 {
            let mut f = e + 4;
            for field in [&mut size, &mut packed, &mut local] {
                if *field == 0xFFFF_FFFF {
                    *field = le_u64(extra, f)?;
                    f += 8;
                }
            }
        }
        e += 4 + len;
    }
    let next = at + 46 + name_len + extra_len + comment_len;
    let name = full_name
        .strip_suffix(".npy")
        .unwrap_or(&full_name)
        .to_string();
    let err = |m: String| format!("member {name}: {m}");
    let local = offset(local).map_err(err)?;
    if le_u32(bytes, local)? != 0x0403_4b50 {
        return Err(err("its local header is missing".into()));
    }
    let start =
        local + 30 + le_u16(bytes, local + 26)? as usize + le_u16(bytes, local + 28)? as usize;
    let (packed, size) = (offset(packed).map_err(err)?, offset(size).map_err(err)?);
    let end = start
        .checked_add(packed)
        .filter(|&end| end <= bytes.len())
        .ok_or_else(|| format!("truncated: member {name} is cut off"))?;
    match method {
        0 if packed != size => {
            return Err(err(format!("stored, yet {packed} bytes hold {size}")));
        }
        8 if size
            > packed
                .saturating_mul(DEFLATE_MAX_RATIO)
                .saturating_add(1024) =>
        {
            return Err(err(format!(
                "the directory says {packed} deflated bytes hold {size}, more than deflate can"
            )));
        }
        0 | 8 => {}
        m => return Err(err(format!("unsupported zip compression method {m}"))),
    }
    let member = NpzMember {
        name,
        method,
        crc,
        data: start..end,
        size,
    };
    Ok((member, next))
}

/// Inflates `data` piece by piece into `sink`, through a 64 KiB window: never more than
/// `limit` bytes (the stream is cut off, with an error, as soon as it would exceed them).
/// `sink` returns whether it wants more. Returns the bytes produced.
fn inflate_into(
    data: &[u8],
    limit: usize,
    mut sink: impl FnMut(&[u8]) -> bool,
) -> Result<usize, String> {
    use miniz_oxide::inflate::TINFLStatus;
    use miniz_oxide::inflate::core::{DecompressorOxide, decompress};
    const WINDOW: usize = 1 << 16; // a power of two over deflate's 32 KiB history
    let mut state = Box::<DecompressorOxide>::default();
    let mut window = vec![0u8; WINDOW];
    let (mut read, mut out_pos, mut total) = (0usize, 0usize, 0usize);
    loop {
        let (status, consumed, written) =
            decompress(&mut state, &data[read..], &mut window, out_pos, 0);
        read += consumed;
        // Hand over what fits under `limit`, then stop if the stream runs past it.
        let allowed = written.min(limit - total);
        total += written;
        if !sink(&window[out_pos..out_pos + allowed]) {
            return Ok(total.min(limit));
        }
        if total > limit {
            return Err(format!(
                "the deflated data holds more than the {limit} bytes said"
            ));
        }
        out_pos = (out_pos + written) & (WINDOW - 1);
        match status {
            TINFLStatus::Done => return Ok(total),
            TINFLStatus::HasMoreOutput => {}
            TINFLStatus::NeedsMoreInput => return Err("the deflated data is cut off".into()),
            other => return Err(format!("bad deflate data ({other:?})")),
        }
    }
}

/// The `.npy` header of `member`, from its first bytes alone (for a deflated member, at
/// most [`MAX_HEADER_BYTES`] are inflated): what its array is, before reading it.
pub fn npz_member_header(bytes: &[u8], member: &NpzMember) -> Result<NpyHeader, String> {
    let err = |m: String| format!("member {}: {m}", member.name);
    let data = &bytes[member.data.clone()];
    let header = match member.method {
        0 => parse_npy_header(data),
        _ => {
            let want = member.size.min(MAX_HEADER_BYTES + 12);
            let mut prefix = Vec::with_capacity(want);
            // Stop early: the rest of the stream is not needed yet.
            let _ = inflate_into(data, member.size, |piece| {
                let room = want - prefix.len();
                prefix.extend_from_slice(&piece[..piece.len().min(room)]);
                prefix.len() < want
            });
            parse_npy_header(&prefix)
        }
    }
    .map_err(err)?;
    let declared = header.data_start + header.payload_bytes;
    if declared != member.size {
        return Err(err(format!(
            "its .npy header ({}) says {declared} bytes, the zip directory {}",
            header.describe(),
            member.size
        )));
    }
    Ok(header)
}

/// Reads `member` of the archive `bytes`: its header first ([`npz_member_header`]), then its
/// values, inflated in pieces and converted straight to `f32`, its CRC-32 checked on the
/// way. The memory it takes is the `f32` array the header declares, which the directory
/// and deflate's ratio bound (a small multiple of the file's size), plus a 64 KiB window.
pub fn read_npz_member(bytes: &[u8], member: &NpzMember) -> Result<NpyArray, String> {
    let header = npz_member_header(bytes, member)?;
    let err = |m: String| format!("member {}: {m}", member.name);
    let data = &bytes[member.data.clone()];
    let mut crc = crate::Crc32::default();
    let mut values = Values::new(&header);
    let mut seen = 0usize;
    let mut take = |piece: &[u8]| {
        crc.update(piece);
        // The header was parsed already: values start at `data_start`.
        let skip = header.data_start.saturating_sub(seen).min(piece.len());
        values.push(&piece[skip..]);
        seen += piece.len();
        true
    };
    let produced = match member.method {
        0 => {
            take(data);
            data.len()
        }
        _ => inflate_into(data, member.size, &mut take).map_err(err)?,
    };
    if produced != member.size {
        return Err(err(format!(
            "{produced} bytes, but the directory says {}",
            member.size
        )));
    }
    if crc.finish() != member.crc {
        return Err(err("CRC-32 mismatch (corrupt data)".into()));
    }
    Ok(values.finish())
}

/// Parses the bytes of a `.npz` archive into its members, `(name without ".npy", array)`,
/// in archive order ([`npz_members`], then [`read_npz_member`] for each).
pub fn parse_npz(bytes: &[u8]) -> Result<Vec<(String, NpyArray)>, String> {
    npz_members(bytes)?
        .iter()
        .map(|m| Ok((m.name.clone(), read_npz_member(bytes, m)?)))
        .collect()
}

/// The bytes of a `.npz` archive (stored, like `np.savez`) of `f32` arrays
/// `(name, shape, values)`; each member is named `name.npy`.
pub fn encode_npz(members: &[(&str, &[usize], &[f32])]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut directory = Vec::new();
    for (name, shape, data) in members {
        let payload = encode_npy(shape, data);
        let file = format!("{name}.npy");
        let crc = crc32(&payload);
        let offset = out.len() as u32;
        let common = |buf: &mut Vec<u8>| {
            buf.extend_from_slice(&20u16.to_le_bytes()); // version needed
            buf.extend_from_slice(&0u16.to_le_bytes()); // flags
            buf.extend_from_slice(&0u16.to_le_bytes()); // stored
            buf.extend_from_slice(&0u32.to_le_bytes()); // time, date
            buf.extend_from_slice(&crc.to_le_bytes());
            buf.extend_from_slice(&(payload.len() as u32).to_le_bytes());
            buf.extend_from_slice(&(payload.len() as u32).to_le_bytes());
            buf.extend_from_slice(&(file.len() as u16).to_le_bytes());
            buf.extend_from_slice(&0u16.to_le_bytes()); // extra
        };
        out.extend_from_slice(&0x0403_4b50u32.to_le_bytes());
        common(&mut out);
        out.extend_from_slice(file.as_bytes());
        out.extend_from_slice(&payload);

        directory.extend_from_slice(&0x0201_4b50u32.to_le_bytes());
        directory.extend_from_slice(&20u16.to_le_bytes()); // made by
        common(&mut directory);
        directory.extend_from_slice(&[0u8; 6]); // comment length, disk, internal attributes
        directory.extend_from_slice(&0u32.to_le_bytes()); // external attributes
        directory.extend_from_slice(&offset.to_le_bytes());
        directory.extend_from_slice(file.as_bytes());
    }
    let dir_offset = out.len() as u32;
    out.extend_from_slice(&directory);
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    out.extend_from_slice(&[0u8; 4]); // disk numbers
    out.extend_from_slice(&(members.len() as u16).to_le_bytes());
    out.extend_from_slice(&(members.len() as u16).to_le_bytes());
    out.extend_from_slice(&(directory.len() as u32).to_le_bytes());
    out.extend_from_slice(&dir_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_ascii_dtype_is_refused_not_a_panic() {
        // Found by `cargo fuzz run npy`: the kind character was 'ě' (two bytes).
        let header = "{'descr': '\u{11b}4', 'fortran_order': False, 'shape': (1,), }\n";
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(&[0; 4]);
        assert!(parse_npy(&bytes).unwrap_err().contains("unsupported dtype"));
    }

    #[test]
    fn fortran_order_is_transposed() {
        // [[1, 2, 3], [4, 5, 6]] stored column-major.
        let c = fortran_to_c(&[1.0, 4.0, 2.0, 5.0, 3.0, 6.0], &[2, 3]);
        assert_eq!(c, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    #[test]
    fn signed_integers_are_sign_extended() {
        assert_eq!(Dtype::Int(2).value(&(-3i16).to_le_bytes()), -3.0);
        assert_eq!(Dtype::Uint(2).value(&(65533u16).to_le_bytes()), 65533.0);
    }
}

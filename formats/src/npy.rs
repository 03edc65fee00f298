//! NumPy's `.npy` arrays, the format the authors' data comes in (docs/reference.md §6.3:
//! `[T, N, 3]` float64 trajectories); `.npz` archives of them are in [`crate::npz`].
//!
//! `.npy` (NumPy's format spec, versions 1–3): the magic `\x93NUMPY`, a version, a header
//! length, then a Python-literal dict `{'descr': '<f8', 'fortran_order': False,
//! 'shape': (T, N, 3), }` and the raw values. The reader takes floats (`f2`, `f4`, `f8`),
//! integers (1–8 bytes) and bools (`b1`, read as 0 or 1), either byte order, C or Fortran
//! order, and returns the values in C order as `f32`.
//!
//! Written by hand, not through `npyz`: that crate's header parser pulls in a dependency tree
//! whose features would rebuild all of Burn here. Every defect (truncated, oversized, a bad
//! header, an unsupported dtype, a count that overflows, a bad CRC) is an error saying what
//! is wrong; nothing panics.

use crate::size_mismatch;

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

/// What an array's values are ([`NpyHeader::kind`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueKind {
    /// `f2`, `f4`, `f8`.
    Float,
    /// Signed or unsigned integers.
    Integer,
    /// NumPy's `?`.
    Bool,
}

/// The element types the reader accepts.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Dtype {
    Float(usize),
    Int(usize),
    Uint(usize),
    /// NumPy's `?` (`|b1`): one byte, 0 or not; read as 0.0 or 1.0 (visibility masks).
    Bool,
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Dtype::Float(s) | Dtype::Int(s) | Dtype::Uint(s) => s,
            Dtype::Bool => 1,
        }
    }

    /// The value of one element; `b` is little-endian.
    fn value(self, b: &[u8]) -> f32 {
        let mut le = [0u8; 8];
        le[..b.len()].copy_from_slice(b);
        let raw = u64::from_le_bytes(le);
        match self {
            Dtype::Float(2) => f16_to_f32(raw as u16),
            Dtype::Float(4) => f32::from_bits(raw as u32),
            Dtype::Float(_) => f64::from_bits(raw) as f32,
            Dtype::Bool => f32::from(u8::from(raw != 0)),
            Dtype::Uint(_) => raw as f32,
            Dtype::Int(s) => {
                // Sign-extend from `s` bytes.
                let shift = 64 - 8 * s as u32;
                (((raw << shift) as i64) >> shift) as f32
            }
        }
    }
}

/// An IEEE half (`f2`, as PointOdyssey stores its tracks) as `f32`, exactly: every half
/// is a float; infinities and NaN stay so.
fn f16_to_f32(h: u16) -> f32 {
    let sign = u32::from(h >> 15) << 31;
    let exp = u32::from((h >> 10) & 0x1f);
    let man = u32::from(h & 0x3ff);
    let bits = match (exp, man) {
        (0, 0) => sign,
        // Subnormal: man · 2⁻²⁴, exact in f32.
        (0, _) => {
            let v = man as f32 * f32::from_bits(0x3380_0000);
            return if sign == 0 { v } else { -v };
        }
        (0x1f, _) => sign | 0x7f80_0000 | (man << 13),
        _ => sign | ((exp + 112) << 23) | (man << 13),
    };
    f32::from_bits(bits)
}

fn parse_descr(descr: &str) -> Result<(Dtype, bool), String> {
    let bad = || format!("unsupported dtype {descr:?} (need a float, integer or bool, e.g. '<f4')");
    let (order, rest) = match descr.chars().next() {
        Some(c @ ('<' | '>' | '|' | '=')) => (c, &descr[1..]),
        _ => ('=', descr),
    };
    let kind = rest.chars().next().ok_or_else(bad)?;
    // `kind` may be any character (fuzzing found a two-byte one), so slice past its bytes.
    let size: usize = rest[kind.len_utf8()..].parse().map_err(|_| bad())?;
    let dtype = match (kind, size) {
        ('f', 2 | 4 | 8) => Dtype::Float(size),
        ('b', 1) => Dtype::Bool,
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
    // Python's dict literal keeps the last of two equal keys, a first-match reader the
    // first: refused rather than read either way.
    let count =
        header.matches(&format!("'{key}'")).count() + header.matches(&format!("\"{key}\"")).count();
    if count > 1 {
        return Err(format!("the header has {count} '{key}' entries"));
    }
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
    /// Whether the values are IEEE halves (`f2`), whose overflow reads as infinity.
    pub fn is_half(&self) -> bool {
        self.dtype == Dtype::Float(2)
    }

    /// What its values are: floats, integers or bools.
    pub fn kind(&self) -> ValueKind {
        match self.dtype {
            Dtype::Float(_) => ValueKind::Float,
            Dtype::Int(_) | Dtype::Uint(_) => ValueKind::Integer,
            Dtype::Bool => ValueKind::Bool,
        }
    }

    pub(crate) fn describe(&self) -> String {
        format!("shape {:?} of {:?}", self.shape, self.dtype)
    }
}

/// Converts a stream of `.npy` value bytes, in pieces of any length, straight to `f32`.
pub(crate) struct Values<'h> {
    header: &'h NpyHeader,
    out: Vec<f32>,
    element: [u8; 8],
    filled: usize,
}

impl<'h> Values<'h> {
    pub(crate) fn new(header: &'h NpyHeader) -> Self {
        Values {
            header,
            out: Vec::with_capacity(header.count),
            element: [0; 8],
            filled: 0,
        }
    }

    pub(crate) fn push(&mut self, mut bytes: &[u8]) {
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

    pub(crate) fn finish(self) -> NpyArray {
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

mod encode;
pub use encode::{NpyValues, encode_npy, encode_npy_values, f32_to_f16, npy_header};

#[cfg(test)]
mod tests;

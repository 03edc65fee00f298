//! Writing `.npy` arrays: the header, and the values of each kind as the tracker files
//! store them, as bytes or a few kilobytes at a time.

use super::NPY_MAGIC;

/// The values of an array to encode, each kind as the tracker files store it: `f32`
/// positions, `f16` (PointOdyssey's `trajs_3d`, rounded from `f32` to the nearest half),
/// `bool` masks (`|b1`) and `i64` indices.
#[derive(Clone, Copy, Debug)]
pub enum NpyValues<'a> {
    /// `<f4`.
    F32(&'a [f32]),
    /// `<f2`, rounded to nearest, ties to even; beyond ±65504 a value becomes ±inf.
    F16(&'a [f32]),
    /// `|b1`.
    Bool(&'a [bool]),
    /// `<i8`.
    I64(&'a [i64]),
}

impl NpyValues<'_> {
    fn len(&self) -> usize {
        match self {
            NpyValues::F32(v) | NpyValues::F16(v) => v.len(),
            NpyValues::Bool(v) => v.len(),
            NpyValues::I64(v) => v.len(),
        }
    }

    /// The bytes of the data in a `.npy`.
    pub fn byte_len(&self) -> usize {
        self.len()
            * match self {
                NpyValues::F32(_) => 4,
                NpyValues::F16(_) => 2,
                NpyValues::Bool(_) => 1,
                NpyValues::I64(_) => 8,
            }
    }

    /// The data as a `.npy` holds it (little-endian), handed to `f` a few kilobytes at a
    /// time: a large array is never copied whole.
    pub fn for_each_chunk(&self, mut f: impl FnMut(&[u8])) {
        const VALUES: usize = 4096;
        let mut buf = Vec::with_capacity(8 * VALUES);
        macro_rules! chunks {
            ($v:expr, $bytes:expr) => {
                for chunk in $v.chunks(VALUES) {
                    buf.clear();
                    chunk.iter().for_each(|x| buf.extend_from_slice(&$bytes(x)));
                    f(&buf);
                }
            };
        }
        match self {
            NpyValues::F32(v) => chunks!(v, |x: &f32| x.to_le_bytes()),
            NpyValues::F16(v) => chunks!(v, |x: &f32| f32_to_f16(*x).to_le_bytes()),
            NpyValues::Bool(v) => chunks!(v, |x: &bool| [u8::from(*x)]),
            NpyValues::I64(v) => chunks!(v, |x: &i64| x.to_le_bytes()),
        }
    }

    fn descr(&self) -> &'static str {
        match self {
            NpyValues::F32(_) => "<f4",
            NpyValues::F16(_) => "<f2",
            NpyValues::Bool(_) => "|b1",
            NpyValues::I64(_) => "<i8",
        }
    }
}

/// `x` rounded to the nearest IEEE half (ties to even), as its bits: what NumPy's
/// `astype(np.float16)` gives. Overflow is ±inf, NaN stays NaN.
pub fn f32_to_f16(x: f32) -> u16 {
    let bits = x.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let exp = ((bits >> 23) & 0xff) as i32;
    let man = bits & 0x7f_ffff;
    if exp == 0xff {
        return sign | 0x7c00 | if man != 0 { 0x200 } else { 0 };
    }
    // The value's exponent as a half's, and the 24-bit significand with its implicit 1.
    let e = exp - 127 + 15;
    if e >= 0x1f {
        return sign | 0x7c00;
    }
    let full = man | 0x80_0000;
    // Bits to drop: 13 for a normal half, more for a subnormal one.
    let shift = if e >= 1 { 13 } else { (14 - e) as u32 };
    if shift > 24 {
        return sign;
    }
    let kept = full >> shift;
    let rest = full & ((1u32 << shift) - 1);
    let half = 1u32 << (shift - 1);
    let rounded = if rest > half || (rest == half && kept & 1 == 1) {
        kept + 1
    } else {
        kept
    };
    if e >= 1 {
        // A carry out of the significand moves into the exponent, and at the top to inf.
        let value = ((e as u32) << 10) + (rounded - 0x400);
        sign | value.min(0x7c00) as u16
    } else {
        sign | rounded as u16
    }
}

/// The bytes of a version-1 `.npy` of little-endian `f32` values, C order.
///
/// # Panics
/// If `data.len()` is not the product of `shape` (a programming error).
pub fn encode_npy(shape: &[usize], data: &[f32]) -> Vec<u8> {
    encode_npy_values(shape, NpyValues::F32(data))
}

/// The bytes of a version-1 `.npy` of `values` (little-endian), C order.
///
/// # Panics
/// If the number of values is not the product of `shape` (a programming error).
pub fn encode_npy_values(shape: &[usize], values: NpyValues) -> Vec<u8> {
    let mut out = npy_header(shape, values);
    out.reserve(values.byte_len());
    values.for_each_chunk(|bytes| out.extend_from_slice(bytes));
    out
}

/// The header of [`encode_npy_values`]' `.npy` (magic, version, the padded dictionary):
/// the bytes before the data.
pub fn npy_header(shape: &[usize], values: NpyValues) -> Vec<u8> {
    assert_eq!(
        shape.iter().product::<usize>(),
        values.len(),
        "encode_npy: the data does not fill the shape"
    );
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {tuple}, }}",
        values.descr()
    );
    // Pad so that the data starts on a 64-byte boundary, as NumPy does.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len());
    out.extend_from_slice(NPY_MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out
}

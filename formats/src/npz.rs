//! NumPy's `.npz` archives: a zip archive of `.npy` members ([`crate::npy`]); `np.savez`
//! stores them, `np.savez_compressed` deflates them, and NumPy writes zip64 records. The
//! reader walks the central directory, refuses a member whose declared size deflate cannot
//! produce from its bytes, checks every member's CRC-32, and inflates with `miniz_oxide`
//! through a bounded window straight into the array the member's header declares. It reads
//! the archive from memory or from its file a piece at a time ([`Source`]). Every
//! defect is an error saying what is wrong; nothing panics.

use std::ops::Range;

use crate::Crc32;
use crate::npy::{MAX_HEADER_BYTES, NpyArray, NpyHeader, Values, parse_npy_header};
use crate::source::Source;

mod write;

pub use write::{encode_npz, encode_npz_values, write_npz_values};

/// The little-endian integers of a zip record at `at`; an `at` near `usize::MAX` (a lying
/// offset field) is a truncated record, not an overflow (found by fuzzing with overflow
/// checks).
fn le_u16(b: &[u8], at: usize) -> Result<u64, String> {
    at.checked_add(2)
        .and_then(|end| b.get(at..end))
        .map(|s| u16::from_le_bytes([s[0], s[1]]) as u64)
        .ok_or_else(|| "truncated zip record".to_string())
}

fn le_u32(b: &[u8], at: usize) -> Result<u64, String> {
    at.checked_add(4)
        .and_then(|end| b.get(at..end))
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as u64)
        .ok_or_else(|| "truncated zip record".to_string())
}

fn le_u64(b: &[u8], at: usize) -> Result<u64, String> {
    at.checked_add(8)
        .and_then(|end| b.get(at..end))
        .map(|s| u64::from_le_bytes(s.try_into().expect("8 bytes")))
        .ok_or_else(|| "truncated zip record".to_string())
}

/// The `len` bytes of a zip record at `at` of `src`: a record past the end is a truncated
/// one, as [`le_u32`] says it.
fn record<S: Source + ?Sized>(
    src: &S,
    at: usize,
    len: usize,
) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    if at.checked_add(len).is_none_or(|end| end > src.size()) {
        return Err("truncated zip record".into());
    }
    src.bytes_at(at, len)
}

/// The same integers read from a source ([`record`]).
fn u16_at<S: Source + ?Sized>(src: &S, at: usize) -> Result<u64, String> {
    le_u16(&record(src, at, 2)?, 0)
}

fn u32_at<S: Source + ?Sized>(src: &S, at: usize) -> Result<u64, String> {
    le_u32(&record(src, at, 4)?, 0)
}

fn u64_at<S: Source + ?Sized>(src: &S, at: usize) -> Result<u64, String> {
    le_u64(&record(src, at, 8)?, 0)
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
    data: Range<usize>,
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
pub fn npz_members<S: Source + ?Sized>(src: &S) -> Result<Vec<NpzMember>, String> {
    const EOCD: [u8; 4] = [0x50, 0x4b, 0x05, 0x06];
    let len = src.size();
    if len < 22 {
        return Err(format!(
            "truncated: {len} bytes, shorter than a zip directory"
        ));
    }
    // The end record is in the last 22 bytes, or before a comment of at most 65,535.
    let search_from = len.saturating_sub(22 + 65_535);
    let tail = src.bytes_at(search_from, len - search_from)?;
    let in_tail = (0..=tail.len() - 22)
        .rev()
        .find(|&i| tail[i..i + 4] == EOCD)
        .ok_or("not a .npz (zip) file, or truncated: no end-of-central-directory record")?;
    let mut entries = le_u16(&tail, in_tail + 10)?;
    let mut dir = le_u32(&tail, in_tail + 16)?;
    let eocd = search_from + in_tail;
    // Zip64: the 32-bit fields are saturated and a zip64 record precedes the locator.
    if (entries == 0xFFFF || dir == 0xFFFF_FFFF) && eocd >= 20 {
        let locator = eocd - 20;
        if u32_at(src, locator)? == 0x0706_4b50 {
            let record = offset(u64_at(src, locator + 8)?)?;
            if u32_at(src, record)? != 0x0606_4b50 {
                return Err("the zip64 directory record is missing".into());
            }
            entries = u64_at(src, record + 32)?;
            dir = u64_at(src, record + 48)?;
        }
    }
    // Each directory entry takes at least 46 bytes, so a count past that is a lie.
    if entries > (len / 46) as u64 {
        return Err(format!(
            "the zip directory claims {entries} members, more than the file can hold"
        ));
    }
    let mut at = offset(dir)?;
    let mut members = Vec::new();
    for _ in 0..entries {
        let (member, next) = directory_entry(src, at)?;
        // NumPy reads the last of two members of one name, a first-match reader the
        // first: neither reading is the file's, so it has none.
        if members.iter().any(|m: &NpzMember| m.name == member.name) {
            return Err(format!(
                "two members are named {:?}: which one is meant is ambiguous",
                member.name
            ));
        }
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
fn directory_entry<S: Source + ?Sized>(src: &S, at: usize) -> Result<(NpzMember, usize), String> {
    if u32_at(src, at)? != 0x0201_4b50 {
        return Err(format!("the zip directory is corrupt at byte {at}"));
    }
    let entry = record(src, at, 46)?;
    let method = le_u16(&entry, 10)?;
    let crc = le_u32(&entry, 16)? as u32;
    let mut packed = le_u32(&entry, 20)?;
    let mut size = le_u32(&entry, 24)?;
    let name_len = le_u16(&entry, 28)? as usize;
    let extra_len = le_u16(&entry, 30)? as usize;
    let comment_len = le_u16(&entry, 32)? as usize;
    let mut local = le_u32(&entry, 42)?;
    let named = src
        .bytes_at(at + 46, name_len + extra_len)
        .map_err(|_| "truncated zip directory")?;
    let full_name = String::from_utf8_lossy(&named[..name_len]).into_owned();
    // Zip64 extra field (id 1): the saturated sizes and offset, in this order.
    let extra = &named[name_len..];
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
    if u32_at(src, local)? != 0x0403_4b50 {
        return Err(err("its local header is missing".into()));
    }
    let start = local + 30 + u16_at(src, local + 26)? as usize + u16_at(src, local + 28)? as usize;
    let (packed, size) = (offset(packed).map_err(err)?, offset(size).map_err(err)?);
    let end = start
        .checked_add(packed)
        .filter(|&end| end <= src.size())
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

/// Inflates the bytes `data` of `src` piece by piece into `sink`, through a 64 KiB window,
/// reading them [`Source::piece`] bytes at a time: never more than `limit` bytes (the
/// stream is cut off, with an error, as soon as it would exceed them). `sink` returns
/// whether it wants more. Returns the bytes produced.
fn inflate_into<S: Source + ?Sized>(
    src: &S,
    data: Range<usize>,
    limit: usize,
    mut sink: impl FnMut(&[u8]) -> bool,
) -> Result<usize, String> {
    use miniz_oxide::inflate::TINFLStatus;
    use miniz_oxide::inflate::core::inflate_flags::TINFL_FLAG_HAS_MORE_INPUT;
    use miniz_oxide::inflate::core::{DecompressorOxide, decompress};
    const WINDOW: usize = 1 << 16; // a power of two over deflate's 32 KiB history
    let mut state = Box::<DecompressorOxide>::default();
    let mut window = vec![0u8; WINDOW];
    let (mut out_pos, mut total) = (0usize, 0usize);
    // The piece of input in hand, how much of it was consumed, and where the next starts.
    let (mut input, mut read, mut next) = (std::borrow::Cow::Borrowed(&[][..]), 0, data.start);
    loop {
        if read == input.len() && next < data.end {
            let len = (data.end - next).min(src.piece());
            input = src.bytes_at(next, len)?;
            (read, next) = (0, next + len);
        }
        let more = if next < data.end {
            TINFL_FLAG_HAS_MORE_INPUT
        } else {
            0
        };
        let (status, consumed, written) =
            decompress(&mut state, &input[read..], &mut window, out_pos, more);
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
            // The piece in hand is used up; the next is read above.
            TINFLStatus::NeedsMoreInput if next < data.end => {}
            TINFLStatus::NeedsMoreInput => return Err("the deflated data is cut off".into()),
            other => return Err(format!("bad deflate data ({other:?})")),
        }
    }
}

/// The `.npy` header of `member`, from its first bytes alone (for a deflated member, at
/// most [`MAX_HEADER_BYTES`] are inflated): what its array is, before reading it.
pub fn npz_member_header<S: Source + ?Sized>(
    src: &S,
    member: &NpzMember,
) -> Result<NpyHeader, String> {
    let err = |m: String| format!("member {}: {m}", member.name);
    // The longest header with its magic, version and length fields: what the header is
    // parsed from, as much of it as the member has.
    let want = member.size.min(MAX_HEADER_BYTES + 12);
    let header = match member.method {
        0 => src
            .bytes_at(member.data.start, want)
            .and_then(|prefix| parse_npy_header(&prefix)),
        _ => {
            let mut prefix = Vec::with_capacity(want);
            // Stop early: the rest of the stream is not needed yet.
            let _ = inflate_into(src, member.data.clone(), member.size, |piece| {
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
pub fn read_npz_member<S: Source + ?Sized>(
    src: &S,
    member: &NpzMember,
) -> Result<NpyArray, String> {
    let header = npz_member_header(src, member)?;
    let err = |m: String| format!("member {}: {m}", member.name);
    let mut crc = Crc32::default();
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
            let data = member.data.clone();
            let mut at = data.start;
            while at < data.end {
                let len = (data.end - at).min(src.piece());
                take(&src.bytes_at(at, len).map_err(err)?);
                at += len;
            }
            data.len()
        }
        _ => inflate_into(src, member.data.clone(), member.size, &mut take).map_err(err)?,
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
pub fn parse_npz<S: Source + ?Sized>(src: &S) -> Result<Vec<(String, NpyArray)>, String> {
    npz_members(src)?
        .iter()
        .map(|m| Ok((m.name.clone(), read_npz_member(src, m)?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use std::io::{self, Write};

    use super::*;
    use crate::npy::NpyValues;

    #[test]
    fn two_members_of_one_name_are_refused_naming_it() {
        let (a, b) = ([1.0f32, 2.0, 3.0], [4.0f32, 5.0, 6.0]);
        let bytes = encode_npz_values(&[
            ("tracks", &[1, 1, 3], NpyValues::F32(&a)),
            ("tracks", &[1, 1, 3], NpyValues::F32(&b)),
        ]);
        let e = npz_members(&bytes).unwrap_err();
        assert!(e.contains("\"tracks\""), "{e}");
        assert!(parse_npz(&bytes).is_err());
    }

    #[test]
    fn a_streamed_archive_reads_back_member_by_member() {
        // More values than one chunk of the writer, in every kind it writes.
        let big: Vec<f32> = (0..10_001).map(|v| (v as f32 * 0.37).sin()).collect();
        let mask: Vec<bool> = (0..10_001).map(|v| v % 3 == 0).collect();
        let ids: Vec<i64> = (0..5).map(|v| 1000 - 7 * v).collect();
        let halves = [0.5f32, -2.0, 65504.0];
        let members = [
            ("tracks", &[10_001][..], NpyValues::F32(&big)),
            ("observed", &[10_001][..], NpyValues::Bool(&mask)),
            ("kept", &[5][..], NpyValues::I64(&ids)),
            ("half", &[3][..], NpyValues::F16(&halves)),
        ];
        let mut streamed = Vec::new();
        write_npz_values(&mut streamed, &members).unwrap();
        assert_eq!(streamed, encode_npz_values(&members));
        let read = parse_npz(&streamed).unwrap();
        let names: Vec<&str> = read.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["tracks", "observed", "kept", "half"]);
        assert_eq!(read[0].1.data, big);
        let as_f32: Vec<f32> = mask.iter().map(|&b| f32::from(u8::from(b))).collect();
        assert_eq!(read[1].1.data, as_f32);
        assert_eq!(
            read[2].1.data,
            ids.iter().map(|&i| i as f32).collect::<Vec<_>>()
        );
        assert_eq!(read[3].1.data, halves);
        // A writer that fails stops the archive with its error.
        struct Full;
        impl Write for Full {
            fn write(&mut self, _: &[u8]) -> io::Result<usize> {
                Err(io::Error::other("disk full"))
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        let e = write_npz_values(&mut Full, &members).unwrap_err();
        assert_eq!(e.to_string(), "disk full");
    }

    #[test]
    fn a_lying_offset_near_the_top_of_memory_is_a_truncated_record() {
        // Found by the `npy` fuzz target with overflow checks: `at + 4` overflowed.
        let input = include_bytes!("../../fuzz/regressions/npz-offset-overflow");
        assert!(npz_members(&input[..]).is_err());
        assert!(le_u32(&[0; 8], usize::MAX - 1).is_err());
    }
}

//! Writing a `.npz` archive: stored members, like `np.savez`, streamed to the writer.

use std::io::{self, Write};

use crate::Crc32;
use crate::npy::{NpyValues, npy_header};

/// The bytes of a `.npz` archive (stored, like `np.savez`) of `f32` arrays
/// `(name, shape, values)`; each member is named `name.npy`.
pub fn encode_npz(members: &[(&str, &[usize], &[f32])]) -> Vec<u8> {
    let typed: Vec<(&str, &[usize], NpyValues)> = members
        .iter()
        .map(|&(name, shape, data)| (name, shape, NpyValues::F32(data)))
        .collect();
    encode_npz_values(&typed)
}

/// The bytes of a `.npz` archive (stored, like `np.savez`) of arrays of any
/// [`NpyValues`] kind, `(name, shape, values)`; each member is named `name.npy`. Panics
/// on a member of 4 GiB or more ([`write_npz_values`] refuses it).
pub fn encode_npz_values(members: &[(&str, &[usize], NpyValues)]) -> Vec<u8> {
    let mut out = Vec::new();
    if let Err(e) = write_npz_values(&mut out, members) {
        panic!("encode_npz_values: {e}");
    }
    out
}

/// [`encode_npz_values`]' archive written to `w` as it is made: each member's data goes
/// from its slice to `w` a few kilobytes at a time (read twice: once for its CRC, which
/// the member's header carries before it), so that a large array is never copied whole.
/// Refuses a member or an archive of 4 GiB or more (a `.npz` past that needs ZIP64).
pub fn write_npz_values(
    w: &mut impl Write,
    members: &[(&str, &[usize], NpyValues)],
) -> io::Result<()> {
    let too_large = |what: &str| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{what} of 4 GiB or more: a .npz past that needs ZIP64, which this writer does not write"
            ),
        )
    };
    let mut written = 0u64;
    let mut directory = Vec::new();
    for (name, shape, values) in members {
        let header = npy_header(shape, *values);
        let size = u32::try_from(header.len() + values.byte_len())
            .map_err(|_| too_large(&format!("member {name}")))?;
        let mut crc = Crc32::default();
        crc.update(&header);
        values.for_each_chunk(|bytes| crc.update(bytes));
        let crc = crc.finish();
        let file = format!("{name}.npy");
        let offset = u32::try_from(written).map_err(|_| too_large("an archive"))?;
        let common = |buf: &mut Vec<u8>| {
            buf.extend_from_slice(&20u16.to_le_bytes()); // version needed
            buf.extend_from_slice(&0u16.to_le_bytes()); // flags
            buf.extend_from_slice(&0u16.to_le_bytes()); // stored
            buf.extend_from_slice(&0u32.to_le_bytes()); // time, date
            buf.extend_from_slice(&crc.to_le_bytes());
            buf.extend_from_slice(&size.to_le_bytes());
            buf.extend_from_slice(&size.to_le_bytes());
            buf.extend_from_slice(&(file.len() as u16).to_le_bytes());
            buf.extend_from_slice(&0u16.to_le_bytes()); // extra
        };
        let mut local = 0x0403_4b50u32.to_le_bytes().to_vec();
        common(&mut local);
        local.extend_from_slice(file.as_bytes());
        local.extend_from_slice(&header);
        w.write_all(&local)?;
        let mut result = Ok(());
        values.for_each_chunk(|bytes| {
            if result.is_ok() {
                result = w.write_all(bytes);
            }
        });
        result?;
        written += (local.len() + values.byte_len()) as u64;

        directory.extend_from_slice(&0x0201_4b50u32.to_le_bytes());
        directory.extend_from_slice(&20u16.to_le_bytes()); // made by
        common(&mut directory);
        directory.extend_from_slice(&[0u8; 6]); // comment length, disk, internal attributes
        directory.extend_from_slice(&0u32.to_le_bytes()); // external attributes
        directory.extend_from_slice(&offset.to_le_bytes());
        directory.extend_from_slice(file.as_bytes());
    }
    let dir_offset = u32::try_from(written).map_err(|_| too_large("an archive"))?;
    let mut end = directory;
    let dir_len = end.len() as u32;
    end.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    end.extend_from_slice(&[0u8; 4]); // disk numbers
    end.extend_from_slice(&(members.len() as u16).to_le_bytes());
    end.extend_from_slice(&(members.len() as u16).to_le_bytes());
    end.extend_from_slice(&dir_len.to_le_bytes());
    end.extend_from_slice(&dir_offset.to_le_bytes());
    end.extend_from_slice(&0u16.to_le_bytes());
    w.write_all(&end)
}

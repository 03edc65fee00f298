//! Where a file's bytes are read from: memory, or the file a piece at a time, so that
//! reading a large `.npz` archive or C3D file never holds its bytes beside the arrays they
//! decode to.

use std::borrow::Cow;
use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::Mutex;

/// A file's bytes, read by range ([`crate::npz::npz_members`], [`crate::c3d::parse_from`]).
pub trait Source {
    /// The file's length in bytes.
    fn size(&self) -> usize;

    /// The `len` bytes from `at`: an error when the file ends before them.
    fn bytes_at(&self, at: usize, len: usize) -> Result<Cow<'_, [u8]>, String>;

    /// The most bytes a reader asks for at once when it reads a long stretch (an archive
    /// member's data, a C3D file's frames): all of them from memory.
    fn piece(&self) -> usize {
        usize::MAX
    }
}

impl Source for [u8] {
    fn size(&self) -> usize {
        self.len()
    }

    fn bytes_at(&self, at: usize, len: usize) -> Result<Cow<'_, [u8]>, String> {
        at.checked_add(len)
            .and_then(|end| self.get(at..end))
            .map(Cow::Borrowed)
            .ok_or_else(|| past_the_end(at, len, self.len()))
    }
}

/// The error of a read past the end of a file of `size` bytes.
fn past_the_end(at: usize, len: usize, size: usize) -> String {
    format!("truncated: {len} bytes at byte {at}, past the end of its {size}")
}

/// As its slice, so that `&Vec<u8>` reads as `&[u8]` does.
impl Source for Vec<u8> {
    fn size(&self) -> usize {
        self.len()
    }

    fn bytes_at(&self, at: usize, len: usize) -> Result<Cow<'_, [u8]>, String> {
        self.as_slice().bytes_at(at, len)
    }
}

/// The bytes a file source reads at once from a long stretch: large enough that the reads
/// cost nothing beside decoding, small beside an array of a long recording.
pub const FILE_PIECE: usize = 1 << 20;

/// A file read as it is parsed: the directory, headers and parameters in small reads, long
/// stretches (an archive member's data, a C3D file's frames) in pieces of [`FILE_PIECE`]
/// bytes. The file is expected not to change
/// while it is read; if it does, the reads fail or the members' CRC-32s do not match. What
/// cannot be read at an offset (a pipe) is read whole at once.
pub struct FileSource {
    backing: Backing,
    size: usize,
    piece: usize,
}

enum Backing {
    File(Mutex<File>),
    Memory(Vec<u8>),
}

impl FileSource {
    /// Opens the file at `path`.
    pub fn open(path: &Path) -> io::Result<Self> {
        let mut file = File::open(path)?;
        let metadata = file.metadata()?;
        if !metadata.is_file() {
            let mut bytes = Vec::new();
            file.read_to_end(&mut bytes)?;
            return Ok(FileSource {
                size: bytes.len(),
                backing: Backing::Memory(bytes),
                piece: usize::MAX,
            });
        }
        let size = usize::try_from(metadata.len())
            .map_err(|_| io::Error::other("the file is larger than this machine can address"))?;
        Ok(FileSource {
            backing: Backing::File(Mutex::new(file)),
            size,
            piece: FILE_PIECE,
        })
    }

    /// The same file, its long stretches read `bytes` at a time (at least one).
    pub fn with_piece(mut self, bytes: usize) -> Self {
        self.piece = bytes.max(1);
        self
    }
}

impl Source for FileSource {
    fn size(&self) -> usize {
        self.size
    }

    fn bytes_at(&self, at: usize, len: usize) -> Result<Cow<'_, [u8]>, String> {
        let file = match &self.backing {
            Backing::File(file) => file,
            Backing::Memory(bytes) => return bytes.as_slice().bytes_at(at, len),
        };
        let end = at
            .checked_add(len)
            .filter(|&end| end <= self.size)
            .ok_or_else(|| past_the_end(at, len, self.size))?;
        let mut file = file
            .lock()
            .map_err(|_| "a reader of the archive panicked".to_string())?;
        let mut bytes = vec![0; len];
        file.seek(SeekFrom::Start(at as u64))
            .and_then(|_| file.read_exact(&mut bytes))
            .map_err(|e| format!("reading bytes {at}..{end}: {e}"))?;
        Ok(Cow::Owned(bytes))
    }

    fn piece(&self) -> usize {
        self.piece
    }
}

/// Bytes in memory served in owned pieces of at most `.1` bytes, as a file is (for tests).
#[cfg(test)]
pub(crate) struct Pieces<'a>(pub &'a [u8], pub usize);

#[cfg(test)]
impl Source for Pieces<'_> {
    fn size(&self) -> usize {
        self.0.len()
    }
    fn bytes_at(&self, at: usize, len: usize) -> Result<Cow<'_, [u8]>, String> {
        self.0.bytes_at(at, len).map(|b| Cow::Owned(b.into_owned()))
    }
    fn piece(&self) -> usize {
        self.1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::npy::NpyValues;
    use crate::npz::{encode_npz_values, parse_npz};

    fn deflated() -> &'static [u8] {
        include_bytes!("../../tests/fixtures/deflated_zip64.npz")
    }

    fn stored() -> Vec<u8> {
        let values: Vec<f32> = (0..301).map(|v| (v as f32 * 0.37).sin()).collect();
        let mask: Vec<bool> = (0..301).map(|v| v % 3 == 0).collect();
        encode_npz_values(&[
            ("tracks", &[301][..], NpyValues::F32(&values)),
            ("observed", &[301][..], NpyValues::Bool(&mask)),
        ])
    }

    /// Read in pieces, every archive reads as it does whole: the same arrays, or the same
    /// error, for a stored and a deflated zip64 archive and every corruption of them by a
    /// flipped byte or a cut.
    #[test]
    fn an_archive_read_in_pieces_reads_as_it_does_whole() {
        let stored = stored();
        for archive in [deflated(), &stored[..]] {
            let mut variants = vec![archive.to_vec()];
            for at in 0..archive.len() {
                let mut flipped = archive.to_vec();
                flipped[at] ^= 0x5A;
                variants.push(flipped);
                variants.push(archive[..at].to_vec());
            }
            for bytes in &variants {
                let whole = parse_npz(&bytes[..]);
                for piece in [1, 5, 64] {
                    assert_eq!(parse_npz(&Pieces(bytes, piece)), whole, "piece {piece}");
                }
            }
        }
    }

    #[test]
    fn a_file_reads_as_its_bytes_and_a_cut_one_is_refused_alike() {
        let dir = std::env::temp_dir().join(format!("doma-npz-source-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let stored = stored();
        for (name, bytes) in [
            ("deflated.npz", deflated()),
            ("stored.npz", &stored[..]),
            ("cut.npz", &stored[..stored.len() - 30]),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, bytes).unwrap();
            let whole = parse_npz(bytes);
            for piece in [3, FILE_PIECE] {
                let file = FileSource::open(&path).unwrap().with_piece(piece);
                assert_eq!(parse_npz(&file), whole, "{name}, piece {piece}");
            }
        }
        assert!(parse_npz(&stored[..stored.len() - 30]).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A pipe cannot be read at an offset: it is read whole, and reads as its bytes.
    #[cfg(unix)]
    #[test]
    fn a_pipe_is_read_whole() {
        let dir = std::env::temp_dir().join(format!("doma-npz-pipe-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("piped.npz");
        let made = std::process::Command::new("mkfifo").arg(&path).status();
        if !made.is_ok_and(|s| s.success()) {
            std::fs::remove_dir_all(&dir).unwrap();
            return; // no mkfifo here: nothing to test
        }
        let bytes = stored();
        let writer = {
            let (path, bytes) = (path.clone(), bytes.clone());
            std::thread::spawn(move || std::fs::write(path, bytes).unwrap())
        };
        let file = FileSource::open(&path).unwrap();
        writer.join().unwrap();
        assert_eq!(parse_npz(&file), parse_npz(&bytes));
        assert!(parse_npz(&file).is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

//! Files in and out. Out: atomically, to a temporary file beside the target, then a
//! rename, so that an interrupted run never leaves a half-written output. In: through
//! [`read_input`] for a file the user named (a regular file, read up to a bound for its
//! kind, so that a FIFO cannot hang a run and a device cannot fill memory), and through
//! [`read_named`] for a file that another file names (an `.mtl`, a texture): resolved
//! against the naming file's folder and refused unless, symbolic links resolved, it lies
//! inside the folder the user pointed at.

mod json;

pub use json::{load_json, merge, read_object, save_json, unknown_field};

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use crate::{DomaError, Result};

/// Writes `bytes` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Writes several files, each atomically, and all or none of them: every file goes to its
/// temporary first, and only when all are written are they renamed into place.
pub fn write_atomic_all(files: &[(&Path, &[u8])]) -> Result<()> {
    // A rename cannot replace a folder: refuse before anything is renamed into place.
    if let Some((path, _)) = files.iter().find(|(p, _)| p.is_dir()) {
        return Err(DomaError::Io {
            path: path.to_path_buf(),
            error: std::io::Error::new(std::io::ErrorKind::IsADirectory, "a folder is in the way"),
        });
    }
    let mut temporaries = Vec::with_capacity(files.len());
    let written = files.iter().try_for_each(|(path, bytes)| {
        let tmp = temporary_for(path)?;
        temporaries.push(tmp.clone());
        std::fs::write(&tmp, bytes)
            .and_then(|()| std::fs::File::open(&tmp)?.sync_all())
            .map_err(|e| DomaError::io(path, e))
    });
    let renamed = written.and_then(|()| {
        files
            .iter()
            .zip(&temporaries)
            .try_for_each(|((path, _), tmp)| {
                std::fs::rename(tmp, path).map_err(|e| DomaError::io(path, e))
            })
    });
    if renamed.is_err() {
        for tmp in &temporaries {
            let _ = std::fs::remove_file(tmp);
        }
    }
    renamed
}

/// The folder `path` is in (`.` for a bare file name).
pub fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// The temporary name [`write_atomic`] writes `path` under: hidden, beside it, with this
/// process's id.
fn temporary_for(path: &Path) -> Result<PathBuf> {
    let dir = folder_of(path);
    let name = path.file_name().ok_or_else(|| {
        DomaError::InvalidConfig(format!("{} is not a file path", path.display()))
    })?;
    Ok(dir.join(format!(
        ".{}.tmp{}",
        name.to_string_lossy(),
        std::process::id()
    )))
}

/// Like [`write_atomic`], but `write` streams the contents into a buffered writer of the
/// temporary file, so that a large file is never held in memory whole.
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<()> {
    let tmp = temporary_for(path)?;
    let result = (|| {
        let mut w = std::io::BufWriter::with_capacity(1 << 16, std::fs::File::create(&tmp)?);
        write(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        DomaError::io(path, e)
    })
}

/// What an input file is, which bounds how much of it is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputKind {
    /// A mesh (OBJ) for display or warping.
    Mesh,
    /// A material library (`.mtl`).
    Material,
    /// A texture image.
    Texture,
    /// A JSON config or record (`--config`, a run's `config.json` and `history.json`).
    Config,
    /// A batch manifest.
    Manifest,
}

impl InputKind {
    /// The largest file of this kind that is read: far above any real one, far below
    /// what would exhaust memory.
    pub fn max_bytes(self) -> u64 {
        match self {
            InputKind::Mesh => 1 << 30,
            InputKind::Material => 16 << 20,
            InputKind::Texture => 256 << 20,
            InputKind::Config => 16 << 20,
            InputKind::Manifest => 64 << 20,
        }
    }

    fn noun(self) -> &'static str {
        match self {
            InputKind::Mesh => "mesh",
            InputKind::Material => "material library",
            InputKind::Texture => "texture",
            InputKind::Config => "config",
            InputKind::Manifest => "manifest",
        }
    }
}

/// Reads a file the user named: it must be a regular file (a FIFO would block the read,
/// a device never end) of at most [`InputKind::max_bytes`]. The error names the file.
pub fn read_input(path: &Path, kind: InputKind) -> Result<Vec<u8>> {
    let len = check_input(path, kind)?;
    let max = kind.max_bytes();
    let refuse = |reason: String| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    };
    let file = std::fs::File::open(path).map_err(|e| DomaError::io(path, e))?;
    let mut bytes = Vec::with_capacity(len as usize);
    // A file that grows while it is read is still cut at the bound.
    file.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| DomaError::io(path, e))?;
    if bytes.len() as u64 > max {
        return Err(refuse(format!(
            "it grew past the {} MiB bound while read",
            max >> 20
        )));
    }
    Ok(bytes)
}

/// What [`read_input`] checks before it opens `path`: a regular file of at most
/// [`InputKind::max_bytes`]. Returns its length.
pub fn check_input(path: &Path, kind: InputKind) -> Result<u64> {
    let refuse = |reason: String| DomaError::Malformed {
        path: path.to_path_buf(),
        reason,
    };
    let meta = std::fs::metadata(path).map_err(|e| DomaError::io(path, e))?;
    if !meta.is_file() {
        return Err(refuse(format!(
            "the {} is not a regular file (a folder, a FIFO, a socket or a device)",
            kind.noun()
        )));
    }
    let max = kind.max_bytes();
    if meta.len() > max {
        return Err(refuse(format!(
            "{} bytes, more than the {} MiB a {} may have",
            meta.len(),
            max >> 20,
            kind.noun()
        )));
    }
    Ok(meta.len())
}

/// [`read_input`] as UTF-8 text.
pub fn read_input_text(path: &Path, kind: InputKind) -> Result<String> {
    String::from_utf8(read_input(path, kind)?).map_err(|_| DomaError::Malformed {
        path: path.to_path_buf(),
        reason: format!("the {} is not UTF-8 text", kind.noun()),
    })
}

/// Where `name`, written inside `referrer` (a file the user gave), points: `name` joined
/// to `referrer`'s folder, with symbolic links resolved, which must lie inside that folder
/// (itself resolved). An absolute name, a `..`, or a link that leads outside is refused
/// naming `referrer` and `name`.
pub fn resolve_named(referrer: &Path, name: &str) -> Result<PathBuf> {
    let refuse = |reason: &str| DomaError::Malformed {
        path: referrer.to_path_buf(),
        reason: format!("`{name}`: {reason}"),
    };
    let rel = Path::new(name);
    if name.is_empty() || rel.is_absolute() || rel.has_root() {
        return Err(refuse(
            "an absolute path; only paths relative to the file are read",
        ));
    }
    if rel
        .components()
        .any(|c| c == std::path::Component::ParentDir)
    {
        return Err(refuse(
            "`..` in a path; only files in the file's folder or below are read",
        ));
    }
    let root = folder_of(referrer);
    let resolved = std::fs::canonicalize(root.join(rel)).map_err(|e| DomaError::Malformed {
        path: referrer.to_path_buf(),
        reason: match e.kind() {
            std::io::ErrorKind::NotFound => format!("`{name}`, which it names, is missing"),
            _ => format!("`{name}`: {e}"),
        },
    })?;
    let root = std::fs::canonicalize(root).map_err(|e| DomaError::io(root, e))?;
    if !resolved.starts_with(&root) {
        return Err(refuse(&format!(
            "leads outside {} (symbolic links resolved); only files inside it are read",
            root.display()
        )));
    }
    Ok(resolved)
}

/// Reads a file that `referrer` names (see [`resolve_named`]) as a [`read_input`] of
/// `kind`.
pub fn read_named(referrer: &Path, name: &str, kind: InputKind) -> Result<Vec<u8>> {
    read_input(&resolve_named(referrer, name)?, kind)
}

/// Removes the temporary files that [`write_atomic`] left in `dir` when a process was
/// killed between its write and its rename (`.NAME.tmpPID` whose process has ended). The
/// caller must be the folder's only writer (a run folder's lock holder). Returns how many
/// it removed.
pub fn remove_stale_temporaries(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = name
            .strip_prefix('.')
            .and_then(|n| n.rsplit_once(".tmp"))
            .and_then(|(_, pid)| pid.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !process_alive(pid) {
            removed += usize::from(std::fs::remove_file(entry.path()).is_ok());
        }
    }
    removed
}

/// Whether process `pid` exists (signal 0 probes without sending anything).
fn process_alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: kill with signal 0 only checks that the process exists.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// Where `path` leads: absolute, with the links of its longest existing prefix followed and
/// the rest appended as written.
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|d| d.join(path))
            .unwrap_or_else(|_| path.to_path_buf())
    };
    let mut rest = Vec::new();
    let mut prefix = absolute.as_path();
    loop {
        if let Ok(mut real) = prefix.canonicalize() {
            real.extend(rest.iter().rev());
            return real;
        }
        match (prefix.parent(), prefix.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                prefix = parent;
            }
            _ => return absolute,
        }
    }
}

/// Refuses an output that would replace what a run reads: `out` resolving (links followed,
/// [`resolved`]) to anything inside the run folder `run`, or to one of `inputs` (the run's
/// data file, a mesh). Every writer of a run's products calls it before it writes; the
/// error names the output and what it would replace.
pub fn check_output(out: &Path, run: Option<&Path>, inputs: &[&Path]) -> Result<()> {
    let target = resolved(out);
    if let Some(run) = run {
        let folder = resolved(run);
        if target.starts_with(&folder) {
            return Err(DomaError::WouldReplaceInput {
                out: out.to_path_buf(),
                why: format!(
                    "it lies inside the run folder {}, whose files the run reads",
                    run.display()
                ),
            });
        }
    }
    if let Some(input) = inputs.iter().find(|i| resolved(i) == target) {
        return Err(DomaError::WouldReplaceInput {
            out: out.to_path_buf(),
            why: format!("it is the input {}", input.display()),
        });
    }
    Ok(())
}

/// Fails early, before minutes of work, when `path` cannot be written: its folder is
/// missing or not writable. Probes with a temporary file that it removes. The error names
/// `path`, the file meant, and its folder.
pub fn check_writable(path: &Path) -> Result<()> {
    let dir = folder_of(path);
    if !dir.is_dir() {
        return Err(DomaError::Io {
            path: path.to_path_buf(),
            error: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("its folder {} does not exist", dir.display()),
            ),
        });
    }
    let probe = dir.join(format!(".doma-write-probe{}", std::process::id()));
    std::fs::File::create(&probe).map_err(|e| DomaError::Io {
        path: path.to_path_buf(),
        error: std::io::Error::new(
            e.kind(),
            format!("its folder {} cannot be written: {e}", dir.display()),
        ),
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

#[cfg(test)]
mod output_tests {
    use super::*;

    #[test]
    fn outputs_that_reach_an_input_are_refused_through_links() {
        let root = std::env::temp_dir().join(format!("doma-check-output-{}", std::process::id()));
        let run = root.join("run");
        std::fs::create_dir_all(&run).unwrap();
        let data = root.join("data.npz");
        std::fs::write(&data, b"x").unwrap();
        std::fs::write(run.join("config.json"), b"{}").unwrap();
        let refused = |out: &Path| {
            matches!(
                check_output(out, Some(&run), &[&data]),
                Err(DomaError::WouldReplaceInput { .. })
            )
        };
        assert!(refused(&run.join("config.json")));
        assert!(refused(&run.join("new.npz")));
        assert!(refused(&root.join("run/../run/model.bpk")));
        assert!(refused(&data));
        // Links are followed: to a run file, to the run folder, to the data.
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(run.join("config.json"), root.join("a.json")).unwrap();
            std::os::unix::fs::symlink(&run, root.join("alias")).unwrap();
            std::os::unix::fs::symlink(&data, root.join("b.npz")).unwrap();
            assert!(refused(&root.join("a.json")));
            assert!(refused(&root.join("alias").join("out.npz")));
            assert!(refused(&root.join("b.npz")));
        }
        assert!(check_output(&root.join("out.npz"), Some(&run), &[&data]).is_ok());
        assert!(check_output(&root.join("run2/out.npz"), Some(&run), &[&data]).is_ok());
        let _ = std::fs::remove_dir_all(&root);
    }
}

#[cfg(test)]
mod writable_tests {
    use super::*;

    #[test]
    fn an_unwritable_output_is_named_with_its_folder() {
        let missing = Path::new("/nonexistent-doma-folder/out.json");
        let e = check_writable(missing).unwrap_err().to_string();
        assert!(
            e.starts_with("/nonexistent-doma-folder/out.json:") && e.contains("does not exist"),
            "{e}"
        );
    }
}

//! The lock of a run folder: one writer at a time. `doma fit` and `doma fit --resume` hold
//! an advisory lock (`flock`) on `RUN/.lock` for the whole fit; a second writer is refused
//! with the folder and the holder's process id. The kernel drops the lock when its holder
//! exits, however it exits, so a killed fit never leaves a folder locked.

use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::Path;

use crate::{DomaError, Result};

/// A held lock; released when dropped (or when the process ends).
#[derive(Debug)]
pub struct RunLock {
    _file: File,
}

impl RunLock {
    /// Takes the lock of the run folder `dir` (which must exist), or says who holds it.
    pub fn acquire(dir: &Path) -> Result<Self> {
        let path = dir.join(".lock");
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| DomaError::io(&path, e))?;
        // SAFETY: flock on a file descriptor that `file` owns and keeps open.
        let locked = unsafe {
            use std::os::fd::AsRawFd;
            libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB)
        };
        if locked != 0 {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            let holder = holder.trim();
            let who = if holder.is_empty() {
                "another process".to_string()
            } else {
                format!("process {holder}")
            };
            return Err(DomaError::Busy {
                path: dir.to_path_buf(),
                holder: who,
            });
        }
        let pid = std::process::id().to_string();
        file.set_len(0)
            .and_then(|()| file.rewind())
            .and_then(|()| file.write_all(pid.as_bytes()))
            .map_err(|e| DomaError::io(&path, e))?;
        // Now the only writer here: clear what a killed writer left half-done.
        crate::io::remove_stale_temporaries(dir);
        Ok(RunLock { _file: file })
    }
}

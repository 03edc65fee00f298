//! A new run's folder, claimed before anything is written into it: made if missing, locked,
//! refused if it holds a run, and put back as it was if the fit never starts. `doma fit`
//! claims its folder once its data are read; the Python package claims it first, writes
//! the arrays into it as the run's data, and then fits.

use std::path::{Path, PathBuf};

use super::{RunDir, RunLock};
use crate::{DomaError, Result};

/// A folder claimed for a new fit ([`Claim::take`]). Undone explicitly ([`Claim::undo`]) or
/// kept ([`Claim::keep`]); dropped, it leaves the folder as it is.
#[derive(Debug)]
pub struct Claim {
    run: RunDir,
    made: bool,
    had_lock_file: bool,
    /// Files moved aside to be written anew, and where they wait: put back by an undo.
    aside: Vec<(PathBuf, PathBuf)>,
    /// Files this claim writes: removed by an undo.
    writes: Vec<PathBuf>,
}

impl Claim {
    /// Claims `dir` for a new run: makes it if missing, takes its lock (before anything in
    /// it is read or written, so that a second caller is refused naming the process that
    /// holds it, and touches nothing), and refuses a folder that holds a run's
    /// `config.json`. The lock is the caller's, to hand
    /// to the fit.
    pub fn take(dir: &Path) -> Result<(Claim, RunLock)> {
        let run = RunDir::new(dir);
        let made = !dir.exists();
        std::fs::create_dir_all(dir).map_err(|e| DomaError::io(dir, e))?;
        let had_lock_file = dir.join(".lock").exists();
        let lock = match RunLock::acquire(dir) {
            Ok(lock) => lock,
            Err(e) => {
                if made {
                    // Empty unless the other caller is in it; then it stays.
                    let _ = std::fs::remove_dir(dir);
                }
                return Err(e);
            }
        };
        let claim = Claim {
            run,
            made,
            had_lock_file,
            aside: Vec::new(),
            writes: Vec::new(),
        };
        if claim.run.config().exists() {
            claim.undo(Some(lock));
            return Err(DomaError::RunExists(dir.to_path_buf()));
        }
        Ok((claim, lock))
    }

    /// The claimed folder.
    pub fn dir(&self) -> &Path {
        &self.run.dir
    }

    /// The first of `files` (names in the folder) that is already there.
    pub fn holds<'a>(&self, files: impl IntoIterator<Item = &'a str>) -> Option<PathBuf> {
        files
            .into_iter()
            .map(|f| self.run.dir.join(f))
            .find(|f| f.exists())
    }

    /// The path of `name` in the folder, to be written by the caller: a file already there
    /// is set aside until the fit starts, so that an undo puts it back.
    pub fn replace(&mut self, name: &str) -> Result<PathBuf> {
        let path = self.run.dir.join(name);
        if path.exists() {
            let aside = self.run.dir.join(format!(".{name}.replaced"));
            std::fs::rename(&path, &aside).map_err(|e| DomaError::io(&path, e))?;
            self.aside.push((path.clone(), aside));
        }
        self.writes.push(path.clone());
        Ok(path)
    }

    /// Puts the folder back as it was, unless the fit started (its `config.json` exists:
    /// then only the set-aside files go), under `lock`, or the lock taken again when it went
    /// with the fit; if another process holds it by then, the folder is that process's and
    /// stays as it is.
    pub fn undo(mut self, lock: Option<RunLock>) {
        let _held = match lock {
            Some(lock) => lock,
            None => match RunLock::acquire(&self.run.dir) {
                Ok(lock) => lock,
                Err(_) => return,
            },
        };
        if self.run.config().exists() {
            self.keep_started();
            return;
        }
        for path in &self.writes {
            let _ = std::fs::remove_file(path);
        }
        for (path, aside) in &self.aside {
            let _ = std::fs::rename(aside, path);
        }
        if !self.had_lock_file {
            let _ = std::fs::remove_file(self.run.dir.join(".lock"));
        }
        if self.made {
            let _ = std::fs::remove_dir(&self.run.dir);
        }
    }

    /// The fit started: the set-aside files are removed.
    pub fn keep(mut self) {
        self.keep_started();
    }

    fn keep_started(&mut self) {
        for (_, aside) in self.aside.drain(..) {
            let _ = std::fs::remove_file(aside);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_undone_claim_leaves_the_folder_as_it_was() {
        let root = tempfile::tempdir().unwrap();
        // A folder it made goes.
        let new = root.path().join("new");
        let (mut claim, lock) = Claim::take(&new).unwrap();
        std::fs::write(claim.replace("tracks.npz").unwrap(), b"x").unwrap();
        claim.undo(Some(lock));
        assert!(!new.exists());
        // A user's folder keeps its files, the replaced one put back.
        let mine = root.path().join("mine");
        std::fs::create_dir(&mine).unwrap();
        std::fs::write(mine.join("tracks.npz"), b"theirs").unwrap();
        let (mut claim, lock) = Claim::take(&mine).unwrap();
        assert_eq!(
            claim.holds(["a", "tracks.npz"]),
            Some(mine.join("tracks.npz"))
        );
        std::fs::write(claim.replace("tracks.npz").unwrap(), b"ours").unwrap();
        // The lock went with a fit that failed: the undo takes it again.
        drop(lock);
        claim.undo(None);
        let names: Vec<_> = std::fs::read_dir(&mine)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["tracks.npz"]);
        assert_eq!(std::fs::read(mine.join("tracks.npz")).unwrap(), b"theirs");
        // A folder that holds a run is refused, and kept.
        std::fs::write(mine.join("config.json"), b"{}").unwrap();
        assert!(matches!(Claim::take(&mine), Err(DomaError::RunExists(_))));
        assert!(mine.join("config.json").exists());
    }
}

//! Atomic outputs (docs/case.md "Outputs").
//!
//! A run's output directory is one unit ([`RunDir`]): its files are written into a temporary
//! directory beside it and the directory is swapped in at the end, so a killed run leaves the
//! previous complete output (or none), never a mix of two runs. Single files outside a run
//! ([`write_atomic`]) are written under a temporary name and renamed into place.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// Call `write` with a temporary path that has the same file name as `dest` (so writers that
/// look at the extension, like the NIfTI writer, behave), then rename it onto `dest`.
pub fn write_atomic<F>(dest: &Path, write: F) -> Result<()>
where
    F: FnOnce(&Path) -> Result<()>,
{
    let dir = dest
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = dest
        .file_name()
        .ok_or_else(|| Error::output(dest, "not a file name"))?;
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp_dir: PathBuf = dir.join(format!(".facesim-tmp-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&tmp_dir).map_err(|e| Error::output(dest, e))?;
    let tmp = tmp_dir.join(name);
    let result =
        write(&tmp).and_then(|()| std::fs::rename(&tmp, dest).map_err(|e| Error::output(dest, e)));
    let _ = std::fs::remove_dir_all(&tmp_dir);
    result
}

/// Atomically write bytes produced by `fill` into `dest`.
pub fn write_bytes_atomic<F>(dest: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    write_atomic(dest, |tmp| {
        let f = std::fs::File::create(tmp).map_err(|e| Error::output(dest, e))?;
        let mut w = std::io::BufWriter::new(f);
        fill(&mut w).map_err(|e| Error::output(dest, e))?;
        w.flush().map_err(|e| Error::output(dest, e))?;
        w.get_ref().sync_all().map_err(|e| Error::output(dest, e))
    })
}

/// Files one of which a directory that facesim wrote as a unit holds (report.json of `run` and
/// `replan`, sweep.csv of `sweep`, validation.csv of `validate`, calibration.csv of
/// `calibrate`, measurements.json of `landmarks`): a non-empty directory without any is not
/// replaced, since the swap removes everything in it.
const UNIT_FILES: [&str; 5] = [
    "report.json",
    "sweep.csv",
    "validation.csv",
    "calibration.csv",
    "measurements.json",
];

/// Names of a unit's temporaries in the output directory's parent: `.{name}.facesim-run-{pid}-{n}`
/// plus `.new` (the directory being written), `.old` (the previous output during the swap) and
/// `.lock` (a file locked while the writing process lives).
const RUN_TAG: &str = ".facesim-run-";

/// An output directory written as one unit: write into [`RunDir::path`], then
/// `RunDir::commit` swaps it in for `dest`. Dropped without a commit (an error, a panic), the
/// temporary is removed and `dest` stays as it was; a process killed mid-write leaves its
/// temporaries, which the next `RunDir::create` in the same parent removes (their lock is free).
pub struct RunDir {
    dest: PathBuf,
    new: PathBuf,
    old: PathBuf,
    lock_path: PathBuf,
    /// Held (locked) for the life of the unit: how other processes tell it is still running.
    _lock: File,
    committed: bool,
}

impl RunDir {
    /// Start writing the unit that will become `dest`: remove stale temporaries of dead runs
    /// beside it, check `dest` is absent, empty or a previous facesim output, and create the
    /// temporary directory (same parent, so the swap is a rename on one filesystem).
    pub(crate) fn create(dest: &Path) -> Result<RunDir> {
        let name = dest
            .file_name()
            .ok_or_else(|| Error::output(dest, "not a directory name"))?
            .to_string_lossy()
            .to_string();
        let parent = dest
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(|e| Error::output(parent, e))?;
        remove_stale(parent);
        check_replaceable(dest)?;
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let stem = format!(".{name}{RUN_TAG}{}-{n}", std::process::id());
        let lock_path = parent.join(format!("{stem}.lock"));
        // The lock first, then the directory: a directory without a held lock is stale.
        let lock = File::create(&lock_path).map_err(|e| Error::output(&lock_path, e))?;
        lock.try_lock()
            .map_err(|e| Error::output(&lock_path, format!("cannot lock: {e}")))?;
        let new = parent.join(format!("{stem}.new"));
        std::fs::create_dir(&new).map_err(|e| Error::output(&new, e))?;
        Ok(RunDir {
            dest: dest.to_path_buf(),
            new,
            old: parent.join(format!("{stem}.old")),
            lock_path,
            _lock: lock,
            committed: false,
        })
    }

    /// Where the unit's files are written until `RunDir::commit`.
    pub fn path(&self) -> &Path {
        &self.new
    }

    /// The output directory the unit becomes.
    pub fn dest(&self) -> &Path {
        &self.dest
    }

    /// Swap the written directory in for `dest`: the previous output is renamed aside, the new
    /// one renamed in, the previous one removed. Killed in between, `dest` is absent for the
    /// moment of two renames and the next run removes the one set aside.
    pub(crate) fn commit(mut self) -> Result<PathBuf> {
        sync_dir(&self.new);
        let had_old = match std::fs::rename(&self.dest, &self.old) {
            Ok(()) => true,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
            Err(e) => return Err(Error::output(&self.dest, e)),
        };
        if let Err(e) = std::fs::rename(&self.new, &self.dest) {
            // Put the previous output back; the new one is removed on drop.
            if had_old {
                let _ = std::fs::rename(&self.old, &self.dest);
            }
            return Err(Error::output(&self.dest, e));
        }
        self.committed = true;
        if let Some(parent) = self.dest.parent() {
            sync_dir(parent);
        }
        if had_old {
            std::fs::remove_dir_all(&self.old).map_err(|e| Error::output(&self.old, e))?;
        }
        Ok(self.dest.clone())
    }
}

impl Drop for RunDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.new);
        }
        // The lock file last: a temporary directory whose lock file is gone is stale too.
        let _ = std::fs::remove_file(&self.lock_path);
    }
}

/// Flush a directory's entries (the renames into it) to disk; best effort, as not every
/// platform can open a directory.
fn sync_dir(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

/// `dest` may be replaced: absent, an empty directory, or a directory holding one of
/// [`UNIT_FILES`].
fn check_replaceable(dest: &Path) -> Result<()> {
    let mut entries = match std::fs::read_dir(dest) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) if dest.exists() && !dest.is_dir() => {
            return Err(Error::output(dest, format!("not a directory ({e})")));
        }
        Err(e) => return Err(Error::output(dest, e)),
    };
    if entries.next().is_none() || UNIT_FILES.iter().any(|f| dest.join(f).is_file()) {
        return Ok(());
    }
    Err(Error::output(
        dest,
        format!(
            "exists and holds no facesim output ({}); the run would replace it: choose another output directory or empty it",
            UNIT_FILES.join(", ")
        ),
    ))
}

/// Remove the temporaries in `parent` of units whose process is gone: each `.new`/`.old`
/// directory whose `.lock` file is missing or can be locked (the lock dies with its process,
/// however it ended). Best effort: what cannot be removed now is tried by the next run.
fn remove_stale(parent: &Path) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    let mut stems: Vec<String> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().to_string();
            let stem = name
                .strip_suffix(".new")
                .or_else(|| name.strip_suffix(".old"))
                .or_else(|| name.strip_suffix(".lock"))?;
            (stem.starts_with('.') && stem.contains(RUN_TAG)).then(|| stem.to_string())
        })
        .collect();
    stems.sort();
    stems.dedup();
    for stem in stems {
        let lock_path = parent.join(format!("{stem}.lock"));
        let lock = match File::options().write(true).open(&lock_path) {
            Ok(f) => match f.try_lock() {
                Ok(()) => Some(f),
                Err(_) => continue, // a live run (this process's own units included)
            },
            Err(_) => None,
        };
        let _ = std::fs::remove_dir_all(parent.join(format!("{stem}.new")));
        let _ = std::fs::remove_dir_all(parent.join(format!("{stem}.old")));
        drop(lock);
        let _ = std::fs::remove_file(&lock_path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_previous_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.txt");
        write_bytes_atomic(&p, |w| w.write_all(b"old")).unwrap();
        let r = write_bytes_atomic(&p, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("interrupted"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        // No temporary directory is left behind.
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1);
    }

    fn listing(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_unit_replaces_the_previous_output_whole() {
        let d = tempfile::tempdir().unwrap();
        let dest = d.path().join("out");
        for (files, expect) in [
            (&["a.txt", "report.json"][..], vec!["a.txt", "report.json"]),
            (&["b.txt", "report.json"][..], vec!["b.txt", "report.json"]),
        ] {
            let u = RunDir::create(&dest).unwrap();
            for f in files {
                std::fs::write(u.path().join(f), f).unwrap();
            }
            // Nothing of the unit shows in dest before the commit.
            assert!(!dest.join(files[0]).exists());
            assert_eq!(u.commit().unwrap(), dest);
            assert_eq!(listing(&dest), expect);
            assert_eq!(listing(d.path()), vec!["out"], "temporaries left");
        }
    }

    #[test]
    fn a_dropped_unit_leaves_the_previous_output() {
        let d = tempfile::tempdir().unwrap();
        let dest = d.path().join("out");
        let u = RunDir::create(&dest).unwrap();
        std::fs::write(u.path().join("report.json"), "old").unwrap();
        u.commit().unwrap();
        let u = RunDir::create(&dest).unwrap();
        std::fs::write(u.path().join("report.json"), "new").unwrap();
        drop(u);
        assert_eq!(std::fs::read(dest.join("report.json")).unwrap(), b"old");
        assert_eq!(listing(d.path()), vec!["out"]);
    }

    #[test]
    fn stale_temporaries_are_removed_and_live_ones_kept() {
        let d = tempfile::tempdir().unwrap();
        let dest = d.path().join("out");
        // A dead run's: directories with a free lock, or with no lock file at all.
        for stem in [".out.facesim-run-1-0", ".x.facesim-run-2-5"] {
            std::fs::create_dir(d.path().join(format!("{stem}.new"))).unwrap();
            std::fs::write(d.path().join(format!("{stem}.new/f")), "x").unwrap();
        }
        std::fs::create_dir(d.path().join(".out.facesim-run-1-0.old")).unwrap();
        std::fs::write(d.path().join(".out.facesim-run-1-0.lock"), "").unwrap();
        // A live one (held by this process).
        let live = RunDir::create(&d.path().join("other")).unwrap();
        let u = RunDir::create(&dest).unwrap();
        // Only the two live units' directory and lock each.
        assert_eq!(listing(d.path()).len(), 4, "{:?}", listing(d.path()));
        assert!(live.path().is_dir() && u.path().is_dir());
        drop((live, u));
        assert!(listing(d.path()).is_empty(), "{:?}", listing(d.path()));
    }

    #[test]
    fn a_directory_that_is_not_an_output_is_not_replaced() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("notes.txt"), "mine").unwrap();
        let e = RunDir::create(d.path()).err().unwrap().to_string();
        assert!(e.contains(&d.path().display().to_string()), "{e}");
        assert!(d.path().join("notes.txt").exists());
        let f = d.path().join("notes.txt");
        assert!(RunDir::create(&f).is_err(), "a file is not a directory");
    }
}

//! Atomic outputs (docs/reference/case.md "Outputs").
//!
//! A run's output directory is one unit ([`RunDir`]): its files are written into a private
//! directory beside it and swapped in at the end, so a killed run leaves the previous complete
//! output or the new one, never a mix of two runs, and a run beside it (another output in the
//! same parent) can neither lose nor take its files. Single files outside a run
//! ([`write_atomic`]) are written under a temporary name and renamed into place.
//!
//! # The unit's protocol
//!
//! A unit `OUT` in `PARENT` lives in one directory, `PARENT/.OUT.facesim-run-PID-N`, holding
//! `lock` (a file locked with `flock` for the life of the unit), `new/` (the files being
//! written, [`RunDir::path`]) and, during the swap, `old/`. The steps:
//!
//! 1. **Prepare in private.** `PARENT/.OUT.facesim-prep-PID-N` is made with `mkdir` (which fails
//!    if the name exists, so no two units share it); `lock` is created in it and locked, and
//!    `new/` made.
//! 2. **Publish.** The prepared directory is renamed to `.OUT.facesim-run-PID-N`. So every unit
//!    directory another process can see already holds a held lock: no window between
//!    creating the lock and taking it.
//! 3. **Write** into `new/`. A write creates only its own temporary with `mkdir`, never the
//!    directories above it, so a unit whose directory vanished fails with that directory named.
//! 4. **Commit.** `new/` is exchanged with `OUT` (`renameat2(RENAME_EXCHANGE)`, one step; where
//!    the filesystem cannot, `OUT` is renamed to `old/` and `new/` to `OUT`). The unit's
//!    directory, now holding the previous output, is removed while the lock is still held.
//!
//! **Sweep.** Before step 1, [`RunDir::create`] removes dead units in `PARENT`. It removes a
//! `.…facesim-run-…` directory only after it has itself locked that directory's `lock` (the
//! lock dies with its process, however it ended), and never unlinks a lock it does not hold; a
//! unit directory with no `lock` is one its owner (or a sweep) was already removing. A
//! `.…facesim-prep-…` directory is removed only once it is older than [`PREP_STALE`]: preparing
//! takes microseconds, and an owner paused for longer finds its directory gone at step 2 and
//! fails with nothing written.
//!
//! What this rules out, step by step:
//! - a sweep between a unit's `mkdir` and its lock: the sweep does not look at `prep`
//!   directories, and a `run` directory is never without its held lock;
//! - a sweep that opens a dead unit's lock while another sweep removes it: only the one that
//!   holds the lock removes; the other's lock, if it gets one, is on an unlinked file in a
//!   directory already gone;
//! - a live unit's `new/` removed under it: nobody but its owner removes a directory whose lock
//!   is held, and a write never recreates what vanished, so the loss cannot be silent;
//! - two units under one name: `mkdir` and the rename onto a non-empty directory both refuse.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// A prepared unit directory older than this is a dead run's (preparing takes microseconds).
pub(crate) const PREP_STALE: Duration = Duration::from_secs(60);

/// Tags in the names of a unit's directories in the output's parent:
/// `.{name}.facesim-run-{pid}-{n}` once published, `.{name}.facesim-prep-{pid}-{n}` before.
const RUN_TAG: &str = ".facesim-run-";
const PREP_TAG: &str = ".facesim-prep-";

/// The tag of a single file's temporary directory ([`write_atomic`]).
const TMP_TAG: &str = ".facesim-tmp-";

/// Create `dir` and any missing parents, but never a unit's own directory (its
/// `.…facesim-run-…` directory or the `new/` in it): those are made once, by
/// [`RunDir::create`], and one that vanished is an error naming it, not something to recreate.
pub fn create_dir_guarded(dir: &Path) -> Result<()> {
    if dir.as_os_str().is_empty() || dir.is_dir() {
        return Ok(());
    }
    if let Some(unit) = dir.ancestors().find(|a| is_unit_dir(a)) {
        let unit_new = unit.join("new");
        if !unit_new.is_dir() {
            return Err(Error::output(
                &unit_new,
                "the run's temporary output directory vanished while it was being written",
            ));
        }
    }
    if let Some(parent) = dir.parent() {
        create_dir_guarded(parent)?;
    }
    match std::fs::create_dir(dir) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && dir.is_dir() => Ok(()),
        Err(e) => Err(Error::output(dir, e)),
    }
}

/// A published unit's directory: `.{name}.facesim-run-{pid}-{n}`.
fn is_unit_dir(p: &Path) -> bool {
    p.file_name()
        .map(|n| n.to_string_lossy())
        .is_some_and(|n| n.starts_with('.') && n.contains(RUN_TAG))
}

/// Make a new directory `{stem}{pid}-{n}` in `parent` with `mkdir`, which refuses an existing
/// name: the directory is this call's alone.
pub(crate) fn fresh_dir(parent: &Path, stem: &str) -> Result<PathBuf> {
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let dir = parent.join(format!("{stem}{}-{n}", std::process::id()));
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(Error::output(
                    parent,
                    "cannot write into it: the directory no longer exists",
                ));
            }
            Err(e) => return Err(Error::output(&dir, e)),
        }
    }
}

/// Call `write` with a temporary path that has the same file name as `dest` (so writers that
/// look at the extension, like the NIfTI writer, behave), then rename it onto `dest`. The
/// temporary lives in a directory of its own beside `dest`; `dest`'s directory is created if
/// missing, unless it is (or lies in) a unit's directory that vanished.
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
    create_dir_guarded(dir)?;
    let tmp_dir = fresh_dir(dir, TMP_TAG).map_err(|e| match e {
        Error::Output { msg, .. } => Error::output(dest, msg),
        e => e,
    })?;
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

/// An output directory written as one unit (the protocol is in this module's doc): write
/// into [`RunDir::path`], then `RunDir::commit` swaps it in for `dest`. Dropped without a
/// commit (an error, a panic), the unit's directory is removed and `dest` stays as it was; a
/// process killed mid-write leaves it, and the next `RunDir::create` in the same parent
/// removes it (its lock is free).
pub struct RunDir {
    dest: PathBuf,
    /// `.{name}.facesim-run-{pid}-{n}`: holds `lock`, `new/` and, during the swap, `old/`.
    unit: PathBuf,
    new: PathBuf,
    /// Held (locked) for the life of the unit: how other processes tell it is still running.
    _lock: File,
    committed: bool,
}

impl RunDir {
    /// Start writing the unit that will become `dest`: remove dead units beside it, check
    /// `dest` is absent, empty or a previous facesim output, and prepare and publish the unit's
    /// directory (same parent, so the swap is a rename on one filesystem).
    pub fn create(dest: &Path) -> Result<RunDir> {
        let name = dest
            .file_name()
            .ok_or_else(|| Error::output(dest, "not a directory name"))?
            .to_string_lossy()
            .to_string();
        let parent = dest
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        create_dir_guarded(parent)?;
        remove_stale(parent);
        check_replaceable(dest)?;
        // 1. Prepare in private: a directory no sweep touches while it is young.
        let prep = fresh_dir(parent, &format!(".{name}{PREP_TAG}"))?;
        pause("prepared");
        let prepared = (|| {
            let lock_path = prep.join("lock");
            let lock = File::create(&lock_path).map_err(|e| Error::output(&lock_path, e))?;
            pause("lock created");
            lock.try_lock()
                .map_err(|e| Error::output(&lock_path, format!("cannot lock: {e}")))?;
            std::fs::create_dir(prep.join("new")).map_err(|e| Error::output(&prep, e))?;
            Ok::<File, Error>(lock)
        })();
        let lock = match prepared {
            Ok(lock) => lock,
            Err(e) => {
                let _ = std::fs::remove_dir_all(&prep);
                return Err(e);
            }
        };
        pause("locked");
        // 2. Publish: from here on the unit is seen with its lock held.
        let unit = loop {
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let unit = parent.join(format!(".{name}{RUN_TAG}{}-{n}", std::process::id()));
            match std::fs::rename(&prep, &unit) {
                Ok(()) => break unit,
                // A dead unit of an earlier process with this PID holds the name.
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::DirectoryNotEmpty | std::io::ErrorKind::AlreadyExists
                    ) => {}
                Err(e) => {
                    let _ = std::fs::remove_dir_all(&prep);
                    return Err(Error::output(
                        &prep,
                        format!("cannot publish the run's temporary output directory: {e}"),
                    ));
                }
            }
        };
        pause("published");
        Ok(RunDir {
            dest: dest.to_path_buf(),
            new: unit.join("new"),
            unit,
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

    /// Swap the written directory in for `dest` and remove the previous output. A unit whose
    /// directory vanished is an error naming it, and `dest` stays as it was.
    pub fn commit(mut self) -> Result<PathBuf> {
        pause("commit");
        if !self.new.is_dir() {
            return Err(Error::output(
                &self.new,
                "the run's temporary output directory vanished before it was complete; the output was not replaced",
            ));
        }
        sync_dir(&self.new);
        swap_in(&self.new, &self.dest, &self.unit.join("old"))?;
        self.committed = true;
        if let Some(parent) = self.dest.parent() {
            sync_dir(parent);
        }
        pause("committed");
        remove_unit(&self.unit).map_err(|e| Error::output(&self.unit, e))?;
        Ok(self.dest.clone())
    }
}

impl Drop for RunDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = remove_unit(&self.unit);
        }
    }
}

/// Put directory `new` in place of `dest`. Where the platform can exchange two paths in one
/// step, `dest` is never absent and the previous output ends up at `new` (removed with the
/// unit); otherwise `dest` is renamed to `old` first and put back if `new` cannot follow.
fn swap_in(new: &Path, dest: &Path, old: &Path) -> Result<()> {
    #[cfg(target_os = "linux")]
    if dest.is_dir() {
        match exchange(new, dest) {
            Ok(()) => return Ok(()),
            // The filesystem cannot exchange: the two renames below.
            Err(e) if matches!(e.raw_os_error(), Some(libc::EINVAL | libc::ENOSYS)) => {}
            Err(e) => return Err(Error::output(dest, e)),
        }
    }
    let had_old = match std::fs::rename(dest, old) {
        Ok(()) => true,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
        Err(e) => return Err(Error::output(dest, e)),
    };
    pause("set aside");
    if let Err(e) = std::fs::rename(new, dest) {
        if had_old {
            let _ = std::fs::rename(old, dest);
        }
        return Err(Error::output(dest, e));
    }
    Ok(())
}

/// Put the finished directory `new` in place of directory `dest` (absent or not), and remove
/// the previous one: for directories written whole that are not a run's outputs (a DICOM series).
pub(crate) fn replace_dir(new: &Path, dest: &Path) -> Result<()> {
    let mut old = new.as_os_str().to_owned();
    old.push(".old");
    let old = PathBuf::from(old);
    swap_in(new, dest, &old)?;
    // After an exchange `new` holds the previous directory; after two renames `old` does.
    let _ = std::fs::remove_dir_all(new);
    let _ = std::fs::remove_dir_all(&old);
    Ok(())
}

/// `renameat2(a, b, RENAME_EXCHANGE)`: swap two existing paths atomically.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        CString::new(p.as_os_str().as_bytes()).map_err(|e| std::io::Error::other(e.to_string()))
    };
    let (a, b) = (c(a)?, c(b)?);
    // SAFETY: both are valid NUL-terminated paths that outlive the call.
    let r = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
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

/// Remove the units in `parent` whose process is gone (the rules are in this module's doc).
/// Best effort: what cannot be removed now is tried by the next run.
fn remove_stale(parent: &Path) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for entry in entries.filter_map(|e| e.ok()) {
        let name = entry.file_name().to_string_lossy().to_string();
        if !name.starts_with('.') {
            continue;
        }
        let path = entry.path();
        if name.contains(RUN_TAG) {
            remove_if_dead(&path);
        } else if name.contains(PREP_TAG) {
            let age = entry
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok());
            if age.is_some_and(|a| a > PREP_STALE) {
                let _ = std::fs::remove_dir_all(&path);
            }
        }
    }
}

/// Remove published unit `unit` if its lock can be taken: its process is gone.
fn remove_if_dead(unit: &Path) {
    let lock_path = unit.join("lock");
    let lock = match File::open(&lock_path) {
        Ok(f) => f,
        // Its owner (or a sweep holding its lock) is already removing it.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let _ = std::fs::remove_dir_all(unit);
            return;
        }
        Err(_) => return,
    };
    pause("sweep opened");
    if lock.try_lock().is_err() {
        return; // a live unit (this process's own included)
    }
    pause("sweep locked");
    let _ = remove_unit(unit);
    drop(lock);
}

/// Remove unit directory `unit` whose lock the caller holds: `new/` and `old/`, then the lock
/// file, then the directory. Every step is tried; the first error (a missing piece is none) is
/// returned.
fn remove_unit(unit: &Path) -> std::io::Result<()> {
    let gone = |r: std::io::Result<()>| match r {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    };
    let new = gone(std::fs::remove_dir_all(unit.join("new")));
    let old = gone(std::fs::remove_dir_all(unit.join("old")));
    // The lock file's own error does not count: the directory's removal says it.
    let _ = std::fs::remove_file(unit.join("lock"));
    let dir = gone(std::fs::remove_dir(unit));
    new.and(old).and(dir)
}

/// A point of the protocol where the concurrency tests pause a thread; nothing otherwise.
#[cfg(not(test))]
#[inline(always)]
fn pause(_step: &str) {}

#[cfg(test)]
fn pause(step: &str) {
    tests::pause_here(step);
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;
    use std::collections::BTreeMap;
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;

    thread_local! {
        /// This thread's pause generator (xorshift state); 0: no pauses.
        static PAUSES: Cell<u64> = const { Cell::new(0) };
    }

    /// Sleep up to 300 µs at half the protocol's steps, on threads that asked for pauses.
    pub(super) fn pause_here(_step: &str) {
        let us = PAUSES.with(|p| {
            let mut s = p.get();
            if s == 0 {
                return 0;
            }
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            p.set(s);
            if s & 1 == 0 { 0 } else { (s >> 8) % 300 }
        });
        if us > 0 {
            std::thread::sleep(Duration::from_micros(us));
        }
    }

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

    /// Lay out in `parent` what a process killed at each step of the protocol leaves, under
    /// names tagged `tag`; returns the young prepared directory, which must stay.
    fn dead_units(parent: &Path, tag: &str) -> PathBuf {
        // Errors are ignored: run beside live units, a sweep may remove a piece as it is laid.
        let dir = |n: &str| {
            let p = parent.join(n);
            let _ = std::fs::create_dir_all(&p);
            p
        };
        let file = |p: PathBuf| {
            let _ = std::fs::write(p, "");
        };
        // Killed right after preparing's mkdir: young (kept) and old (removed).
        let young = dir(&format!(".a{tag}{PREP_TAG}1-0"));
        let old = dir(&format!(".b{tag}{PREP_TAG}1-1"));
        file(old.join("lock"));
        let _ = File::open(&old)
            .and_then(|f| f.set_modified(std::time::SystemTime::now() - 2 * PREP_STALE));
        // Killed while writing: a free lock and half the files.
        let w = dir(&format!(".c{tag}{RUN_TAG}2-0"));
        file(w.join("lock"));
        file(dir(&format!(".c{tag}{RUN_TAG}2-0/new")).join("f"));
        // Killed between the two renames of the swap: the previous output set aside.
        let s = dir(&format!(".d{tag}{RUN_TAG}3-0"));
        file(s.join("lock"));
        file(dir(&format!(".d{tag}{RUN_TAG}3-0/old")).join("report.json"));
        // Killed while removing its directory, the lock file already gone.
        dir(&format!(".e{tag}{RUN_TAG}4-0/new"));
        young
    }

    #[test]
    fn stale_temporaries_are_removed_and_live_ones_kept() {
        let d = tempfile::tempdir().unwrap();
        let young = dead_units(d.path(), "");
        // A live one (held by this process).
        let live = RunDir::create(&d.path().join("other")).unwrap();
        let u = RunDir::create(&d.path().join("out")).unwrap();
        // The two live units and the young prepared directory.
        assert_eq!(listing(d.path()).len(), 3, "{:?}", listing(d.path()));
        assert!(live.path().is_dir() && u.path().is_dir() && young.is_dir());
        drop((live, u));
        assert_eq!(listing(d.path()), vec![".a.facesim-prep-1-0"]);
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

    #[test]
    fn a_unit_whose_directory_vanished_fails_and_commits_nothing() {
        let d = tempfile::tempdir().unwrap();
        let dest = d.path().join("out");
        let u = RunDir::create(&dest).unwrap();
        write_bytes_atomic(&u.path().join("face.obj"), |w| w.write_all(b"a")).unwrap();
        std::fs::remove_dir_all(u.path()).unwrap();
        // A write neither recreates the unit's directory nor succeeds.
        let e = write_bytes_atomic(&u.path().join("report.json"), |w| w.write_all(b"{}"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("vanished") && e.contains(".out.facesim-run-"),
            "{e}"
        );
        assert!(!u.path().exists());
        let nested = u.path().join("runs").join("a");
        assert!(create_dir_guarded(&nested).is_err());
        assert!(RunDir::create(&nested.join("out")).is_err());
        assert!(!u.path().exists());
        let e = u.commit().unwrap_err().to_string();
        assert!(e.contains("vanished"), "{e}");
        assert!(!dest.exists(), "nothing was committed");
        assert!(listing(d.path()).is_empty(), "{:?}", listing(d.path()));
    }

    /// One output as a unit: `files` files of known content, written with pauses.
    fn write_unit(dest: &Path, round: usize, files: usize) -> Result<()> {
        let u = RunDir::create(dest)?;
        for f in 0..files {
            let body = format!("{} round {round} file {f}\n", dest.display()).repeat(50);
            write_bytes_atomic(&u.path().join(format!("f{f}.txt")), |w| {
                w.write_all(body.as_bytes())
            })?;
            pause_here("write");
        }
        write_bytes_atomic(&u.path().join("report.json"), |w| {
            write!(w, "{{\"round\": {round}}}")
        })?;
        u.commit().map(|_| ())
    }

    /// What [`write_unit`] must leave: each file's name and content.
    fn expected(dest: &Path, round: usize, files: usize) -> BTreeMap<String, Vec<u8>> {
        let mut m: BTreeMap<String, Vec<u8>> = (0..files)
            .map(|f| {
                let body = format!("{} round {round} file {f}\n", dest.display()).repeat(50);
                (format!("f{f}.txt"), body.into_bytes())
            })
            .collect();
        m.insert(
            "report.json".into(),
            format!("{{\"round\": {round}}}").into_bytes(),
        );
        m
    }

    fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
        match std::fs::read_dir(dir) {
            Ok(entries) => entries
                .map(|e| e.unwrap().path())
                .map(|p| {
                    let name = p.file_name().unwrap().to_string_lossy().to_string();
                    (name, std::fs::read(&p).unwrap_or_default())
                })
                .collect(),
            Err(_) => BTreeMap::new(),
        }
    }

    /// Units in sibling folders of one parent, at once, each thread pausing at random at every
    /// step of create, write, commit and sweep (and a thread laying out what killed runs leave):
    /// every unit commits, and every output holds exactly its own round's files.
    #[test]
    fn concurrent_units_in_one_parent_lose_nothing() {
        const THREADS: usize = 8;
        const ROUNDS: usize = 60;
        const FILES: usize = 6;
        let d = tempfile::tempdir().unwrap();
        let parent = Arc::new(d.path().to_path_buf());
        let done = Arc::new(AtomicBool::new(false));
        let killer = {
            let (parent, done) = (parent.clone(), done.clone());
            std::thread::spawn(move || {
                let mut k = 0;
                while !done.load(Ordering::Relaxed) {
                    dead_units(&parent, &format!("k{k}"));
                    k += 1;
                    std::thread::sleep(Duration::from_millis(2));
                }
                k
            })
        };
        let workers: Vec<_> = (0..THREADS)
            .map(|t| {
                let parent = parent.clone();
                std::thread::spawn(move || {
                    PAUSES.with(|p| p.set(0x9E37_79B9_7F4A_7C15 ^ ((t as u64 + 1) * 7919)));
                    let dest = parent.join(format!("out{t}"));
                    let mut bad = Vec::new();
                    for round in 0..ROUNDS {
                        if let Err(e) = write_unit(&dest, round, FILES) {
                            bad.push(format!("round {round}: {e}"));
                            continue;
                        }
                        if contents(&dest) != expected(&dest, round, FILES) {
                            let got: Vec<String> = contents(&dest).into_keys().collect();
                            bad.push(format!("round {round}: incomplete output {got:?}"));
                        }
                    }
                    bad
                })
            })
            .collect();
        let bad: Vec<String> = workers
            .into_iter()
            .flat_map(|w| w.join().unwrap())
            .collect();
        done.store(true, Ordering::Relaxed);
        let killed = killer.join().unwrap();
        assert!(
            bad.is_empty(),
            "{} of {} units lost files: {:?}",
            bad.len(),
            THREADS * ROUNDS,
            &bad[..bad.len().min(5)]
        );
        assert!(killed > 0);
        // A last unit sweeps every dead unit; only young prepared directories stay.
        drop(RunDir::create(&parent.join("out0")).unwrap());
        let left: Vec<String> = listing(&parent)
            .into_iter()
            .filter(|n| n.starts_with('.') && !n.contains(PREP_TAG))
            .collect();
        assert!(left.is_empty(), "{left:?}");
    }
}

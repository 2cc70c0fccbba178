//! Atomic outputs: every file is written under a temporary name in the destination directory
//! and renamed into place, so an interrupted run never leaves a half-written file and the
//! previous output stays intact until the new one is complete.

use crate::error::{Error, Result};
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
}

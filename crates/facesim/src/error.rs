//! One error type for the whole pipeline. Every user-facing error is one line that names the
//! file (when there is one) and the problem, so the CLI can print it as is.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A bad or unreadable input file (or directory).
    #[error("{}: {msg}", path.display())]
    Input { path: PathBuf, msg: String },
    /// A case or parameter that is inconsistent or impossible.
    #[error("{0}")]
    Config(String),
    /// A numerical failure reported as a result (singular system, divergence, no convergence).
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// Writing an output failed.
    #[error("{}: cannot write: {msg}", path.display())]
    Output { path: PathBuf, msg: String },
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn input(path: impl AsRef<Path>, msg: impl std::fmt::Display) -> Self {
        Error::Input {
            path: path.as_ref().to_path_buf(),
            msg: one_line(&msg.to_string()),
        }
    }
    pub fn output(path: impl AsRef<Path>, msg: impl std::fmt::Display) -> Self {
        Error::Output {
            path: path.as_ref().to_path_buf(),
            msg: one_line(&msg.to_string()),
        }
    }
    pub fn config(msg: impl std::fmt::Display) -> Self {
        Error::Config(one_line(&msg.to_string()))
    }
}

/// Library errors (toml, dicom) can span lines; the CLI contract is one line.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Attach a path to any displayable error.
pub trait Context<T> {
    fn at(self, path: impl AsRef<Path>) -> Result<T>;
}

impl<T, E: std::fmt::Display> Context<T> for std::result::Result<T, E> {
    fn at(self, path: impl AsRef<Path>) -> Result<T> {
        self.map_err(|e| Error::input(path, e))
    }
}

thread_local! {
    static GUARDED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Whether the current thread is inside [`guard`] (the CLI's panic hook stays silent there:
/// the panic becomes an ordinary input error).
pub fn in_guard() -> bool {
    GUARDED.with(|g| g.get())
}

/// Run a reader that leans on third-party parsers (NIfTI, DICOM, PLY, tar, plist). Should one of
/// them panic on malformed bytes, the panic is caught and reported as a one-line error about the
/// file — a hostile input must never crash the tool. Our own code is held to no panics by the
/// fuzz tests (docs/reliability.md); this is the second line of defence.
pub fn guard<T>(path: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    let was = GUARDED.with(|g| g.replace(true));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    GUARDED.with(|g| g.set(was));
    match r {
        Ok(r) => r,
        Err(p) => {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            Err(Error::input(
                path,
                format!("malformed file: the parser gave up ({msg})"),
            ))
        }
    }
}

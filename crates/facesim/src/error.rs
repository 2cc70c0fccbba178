//! One error type for the whole pipeline, structured so that a library caller can match on what
//! went wrong (a bad file, a bad parameter, a skin surface the model cannot use, an impossible
//! plan, a numerical failure and its kind) without reading message text. Every error still
//! displays as one line that names the file (when there is one) and the problem, so the CLI
//! prints it as is.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A bad or unreadable input file (or directory).
    #[error("{}: {msg}", path.display())]
    Input { path: PathBuf, msg: String },
    /// A case or parameter that is inconsistent or impossible.
    #[error("{0}")]
    Config(String),
    /// The skin surface cannot carry the C1 model (its (u, v) map folds, an element is
    /// degenerate, a vertex has too few neighbours): a property of the input surface, not a
    /// numerical failure. The pipeline names the surface's source with `Error::in_file`.
    #[error("{0}")]
    Surface(String),
    /// The plan moves bone where no skin can follow (through the skin; wrong units or
    /// direction). `file` is the case file once the pipeline knows it.
    #[error("{}impossible plan: {msg}", file.as_ref().map(|f| format!("{}: ", f.display())).unwrap_or_default())]
    ImpossiblePlan { file: Option<PathBuf>, msg: String },
    /// A numerical failure reported as a result, never a crash or a silent wrong answer.
    #[error("numerical failure: {msg}")]
    Numerical { kind: NumericalKind, msg: String },
    /// Writing an output failed.
    #[error("{}: cannot write: {msg}", path.display())]
    Output { path: PathBuf, msg: String },
}

/// What kind of numerical failure: a caller may retry differently (more load steps for
/// `NotConverged`, rigid nodes for `Singular`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NumericalKind {
    /// A system matrix is singular or not positive definite.
    Singular,
    /// An iteration did not reach its tolerance within its limit.
    NotConverged,
    /// An iteration blew up (non-finite values, growing residual).
    Diverged,
    /// An element is flat or inverted.
    DegenerateElement,
    /// The model is too large for this machine's memory (its factor would not fit).
    TooLarge,
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
    pub fn numerical(kind: NumericalKind, msg: impl std::fmt::Display) -> Self {
        Error::Numerical {
            kind,
            msg: one_line(&msg.to_string()),
        }
    }
    pub fn surface(msg: impl std::fmt::Display) -> Self {
        Error::Surface(one_line(&msg.to_string()))
    }
    pub(crate) fn impossible_plan(msg: impl std::fmt::Display) -> Self {
        Error::ImpossiblePlan {
            file: None,
            msg: one_line(&msg.to_string()),
        }
    }

    /// Name the file an input-shaped error comes from: a surface problem becomes an input error
    /// about `file`, an impossible plan names `file`; other errors are returned as they are.
    pub(crate) fn in_file(self, file: impl AsRef<Path>) -> Self {
        match self {
            Error::Surface(msg) => Error::Input {
                path: file.as_ref().to_path_buf(),
                msg,
            },
            Error::ImpossiblePlan { file: None, msg } => Error::ImpossiblePlan {
                file: Some(file.as_ref().to_path_buf()),
                msg,
            },
            other => other,
        }
    }
}

/// Library errors (toml, dicom) can span lines; the CLI contract is one line.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Attach a path to any displayable error.
pub(crate) trait Context<T> {
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
/// fuzz tests (docs/lab/reliability.md); this is the second line of defence.
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

//! `facesim._facesim`, the native module of the Python package `facesim` (docs/guide/python.md).
//!
//! A thin layer over the library, like the command line: `run`, `replan` and `sweep` call the
//! same functions `facesim run`, `facesim replan` and `facesim sweep` call, so the arrays equal
//! the files those commands write. The work runs with the interpreter lock released
//! (`Python::detach`); facesim's errors raise `FacesimError` with facesim's one-line message.
//!
//! - `tables`: a Python dict (case, plan, sweep) turned into TOML text, read as a file would be;
//! - `results`: the `Result` class and the numpy arrays (LPS mm).

mod results;
mod tables;

use facesim::case::Case;
use facesim::observe::Quiet;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

pyo3::create_exception!(
    facesim,
    FacesimError,
    PyException,
    "facesim refused or failed: bad input (the message names the file and the problem) or a numerical failure."
);

/// facesim's error as the Python exception, message unchanged.
fn raise(e: facesim::Error) -> PyErr {
    FacesimError::new_err(e.to_string())
}

/// Run `f` without the interpreter lock, on `threads` worker threads (None: rayon's global
/// pool, all cores). A panic (a facesim bug) becomes a FacesimError rather than killing Python.
fn work<T: Send>(
    py: Python<'_>,
    threads: Option<usize>,
    f: impl FnOnce() -> facesim::Result<T> + Send,
) -> PyResult<T> {
    let r = py.detach(|| {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match threads {
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map_err(|e| facesim::Error::config(format!("threads = {n}: {e}")))
                .and_then(|pool| pool.install(f)),
            None => f(),
        }))
    });
    match r {
        Ok(r) => r.map_err(raise),
        Err(p) => {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(FacesimError::new_err(format!(
                "internal error: {} (please report this with the case)",
                msg.replace('\n', " ")
            )))
        }
    }
}

/// A path argument: str or os.PathLike.
fn path_of(obj: &Bound<'_, PyAny>) -> PyResult<PathBuf> {
    obj.extract::<PathBuf>()
}

/// Run the pipeline on a case and return its outputs as arrays (docs/guide/python.md).
///
/// `case`: a case directory or .toml file (str or os.PathLike), or the case.toml as a dict.
/// A dict behaves as a case.toml in `base_dir` (default: the working directory): its relative
/// paths resolve there and the default `out` is `base_dir/out`. `out`: the output directory
/// (default as `facesim run`: CASE_DIR/out). `threads`: worker threads (default: all cores).
#[pyfunction]
#[pyo3(signature = (case, out = None, threads = None, base_dir = None))]
fn run(
    py: Python<'_>,
    case: &Bound<'_, PyAny>,
    out: Option<PathBuf>,
    threads: Option<usize>,
    base_dir: Option<PathBuf>,
) -> PyResult<results::Result> {
    let started = std::time::SystemTime::now();
    let outcome = if let Ok(dict) = case.cast::<PyDict>() {
        let dir = match base_dir {
            Some(d) => d,
            None => std::env::current_dir()
                .map_err(|e| FacesimError::new_err(format!("working directory: {e}")))?,
        };
        // Errors name the dict as if it were a file in base_dir (Slicer plan files in it
        // resolve there too).
        let file = dir.join(tables::DICT_CASE);
        let text = tables::to_toml_text(dict, &file)?;
        let out = out.unwrap_or_else(|| dir.join("out"));
        work(py, threads, move || {
            let case = Case::from_text(&text, &file, &dir)?;
            facesim::commands::run_parsed(case, &file, &dir, &out, &Quiet)
        })?
    } else {
        if base_dir.is_some() {
            return Err(FacesimError::new_err(
                "base_dir is for a case given as a dict; a case path has its own directory",
            ));
        }
        let path = path_of(case)?;
        work(py, threads, move || {
            facesim::commands::run(&path, out.as_deref(), &Quiet)
        })?
    };
    results::from_run(py, &outcome, started)
}

/// A plan argument: a PLAN.toml path, or its content as a dict (its relative paths resolve
/// against the working directory).
fn plan_of(plan: &Bound<'_, PyAny>) -> PyResult<(PathBuf, Option<String>)> {
    if let Ok(dict) = plan.cast::<PyDict>() {
        let dir = std::env::current_dir()
            .map_err(|e| FacesimError::new_err(format!("working directory: {e}")))?;
        let file = dir.join(tables::DICT_PLAN);
        let text = tables::to_toml_text(dict, &file)?;
        Ok((file, Some(text)))
    } else {
        Ok((path_of(plan)?, None))
    }
}

/// The face outputs for a new plan from the plan basis of the run in `out_dir`, without
/// re-solving (as `facesim replan`, and writing the same files into `out`, default
/// OUT_DIR/replan). `plan`: a PLAN.toml path or a dict `{"osteotomy": [...]}` or
/// `{"surgery": [...]}` (docs/guide/planning.md).
#[pyfunction]
#[pyo3(signature = (out_dir, plan, out = None))]
fn replan(
    py: Python<'_>,
    out_dir: PathBuf,
    plan: &Bound<'_, PyAny>,
    out: Option<PathBuf>,
) -> PyResult<results::Result> {
    let (file, text) = plan_of(plan)?;
    let r = work(py, None, move || {
        let basis = facesim::plan::file::read(&out_dir.join(facesim::plan::file::FILE_NAME))?;
        let plan = match &text {
            Some(t) => facesim::commands::replan::plan_from_text(t, &file)?,
            None => facesim::commands::replan::read_plan(&file)?,
        };
        let r =
            facesim::commands::replan::replan_with(&out_dir, &basis, &plan, &file, out.as_deref())?;
        Ok((basis, r))
    })?;
    results::from_replan(py, &r.0, &r.1)
}

/// Many plans from the plan basis of the run in `out_dir` (as `facesim sweep`): the table as a
/// dict of columns — `plan` (int64, from 1), `label` (list of str) and sweep.csv's numeric
/// columns (float64; NaN for a region absent on this face). `sweep`: a SWEEP.toml path or its
/// content as a dict. With `out`, sweep.csv and sweep.svg are written there too.
#[pyfunction]
#[pyo3(signature = (out_dir, sweep, out = None))]
fn sweep<'py>(
    py: Python<'py>,
    out_dir: PathBuf,
    sweep: &Bound<'py, PyAny>,
    out: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let (file, text) = if let Ok(dict) = sweep.cast::<PyDict>() {
        let dir = std::env::current_dir()
            .map_err(|e| FacesimError::new_err(format!("working directory: {e}")))?;
        let file = dir.join(tables::DICT_SWEEP);
        let text = tables::to_toml_text(dict, &file)?;
        (file, Some(text))
    } else {
        (path_of(sweep)?, None)
    };
    let (names, labels, columns) = work(py, None, move || {
        use facesim::commands::sweep as sw;
        let basis = facesim::plan::file::read(&out_dir.join(facesim::plan::file::FILE_NAME))?;
        let plans = match &text {
            Some(t) => sw::sweep_from_text(t, &file, &basis)?,
            None => sw::read_sweep(&file, &basis)?,
        };
        let rows = sw::evaluate(&basis, plans, &file, sw::run_landmarks(&out_dir)?.as_ref())?;
        if let Some(o) = &out {
            sw::write(o, &basis, &rows)?;
            facesim_charts::sweep::write(&o.join("sweep.svg"), &rows)?;
        }
        let names = sw::value_columns(&basis, &rows);
        let mut columns = vec![Vec::with_capacity(rows.len()); names.len()];
        for row in &rows {
            for (c, v) in columns.iter_mut().zip(sw::row_values(&basis, row)) {
                c.push(v);
            }
        }
        let labels: Vec<String> = rows.iter().map(|r| r.plan.label.clone()).collect();
        Ok((names, labels, columns))
    })?;
    let d = PyDict::new(py);
    let plan: Vec<i64> = (1..=labels.len() as i64).collect();
    d.set_item("plan", numpy::PyArray1::from_vec(py, plan))?;
    d.set_item("label", PyList::new(py, labels)?)?;
    for (n, c) in names.into_iter().zip(columns) {
        d.set_item(n, numpy::PyArray1::from_vec(py, c))?;
    }
    Ok(d)
}

#[pymodule]
fn _facesim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FacesimError", m.py().get_type::<FacesimError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<results::Result>()?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(replan, m)?)?;
    m.add_function(wrap_pyfunction!(sweep, m)?)?;
    Ok(())
}

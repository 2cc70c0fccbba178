//! A case, plan or sweep given as a Python dict, turned into TOML text and then read by the
//! library exactly as the file would be (same defaults, checks and error messages).
//!
//! Accepted values: dict (str keys), list or tuple, str, os.PathLike (as its path string),
//! bool, int, float, and numpy arrays and scalars (through `tolist()`). None has no TOML form:
//! leave the key out instead.

use crate::FacesimError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use std::path::Path;

/// The names that stand for a dict in error messages, as if it were a file in its base
/// directory.
pub const DICT_CASE: &str = "<case dict>";
pub const DICT_PLAN: &str = "<plan dict>";
pub const DICT_SWEEP: &str = "<sweep dict>";

/// `dict` as TOML text; a value with no TOML form is a FacesimError naming `file` and the key.
pub fn to_toml_text(dict: &Bound<'_, PyDict>, file: &Path) -> PyResult<String> {
    let table = table(dict, "", file)?;
    toml::to_string(&table).map_err(|e| FacesimError::new_err(format!("{}: {e}", file.display())))
}

fn table(dict: &Bound<'_, PyDict>, at: &str, file: &Path) -> PyResult<toml::Table> {
    let mut t = toml::Table::new();
    for (k, v) in dict.iter() {
        let key: String = k.extract().map_err(|_| {
            bad(
                file,
                at,
                &format!("a key that is not a string ({})", type_name(&k)),
            )
        })?;
        let here = if at.is_empty() {
            key.clone()
        } else {
            format!("{at}.{key}")
        };
        t.insert(key, value(&v, &here, file)?);
    }
    Ok(t)
}

fn value(v: &Bound<'_, PyAny>, at: &str, file: &Path) -> PyResult<toml::Value> {
    // bool before int: Python's bool is an int.
    if let Ok(b) = v.cast::<PyBool>() {
        return Ok(toml::Value::Boolean(b.is_true()));
    }
    if v.is_instance_of::<PyInt>() {
        let i: i64 = v
            .extract()
            .map_err(|_| bad(file, at, "an integer beyond 64 bits"))?;
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = v.cast::<PyFloat>() {
        return Ok(toml::Value::Float(f.value()));
    }
    if let Ok(s) = v.cast::<PyString>() {
        return Ok(toml::Value::String(s.to_cow()?.into_owned()));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        return Ok(toml::Value::Table(table(d, at, file)?));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut a = Vec::new();
        for (i, item) in v.try_iter()?.enumerate() {
            a.push(value(&item?, &format!("{at}[{i}]"), file)?);
        }
        return Ok(toml::Value::Array(a));
    }
    if v.is_none() {
        return Err(bad(file, at, "None (leave the key out for its default)"));
    }
    // os.PathLike: its path string.
    if v.hasattr("__fspath__")? {
        let p: std::path::PathBuf = v.extract()?;
        return Ok(toml::Value::String(p.to_string_lossy().into_owned()));
    }
    // numpy arrays and scalars: their Python values.
    if v.hasattr("tolist")? {
        let plain = v.call_method0("tolist")?;
        if !plain.is(v) {
            return value(&plain, at, file);
        }
    }
    Err(bad(file, at, &format!("a {} (no TOML form)", type_name(v))))
}

fn type_name(v: &Bound<'_, PyAny>) -> String {
    v.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "value".into())
}

fn bad(file: &Path, at: &str, what: &str) -> PyErr {
    FacesimError::new_err(format!(
        "{}: key '{}' holds {what}",
        file.display(),
        if at.is_empty() { "(top level)" } else { at }
    ))
}

//! The `facesim.Result` class: a run's (or replan's) face as numpy arrays, in LPS millimetres,
//! equal to the files the command line writes (face_pre/face_post vertex order).

use facesim::vec3::{norm, sub};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::Path;
use std::time::SystemTime;

/// What `facesim.run` and `facesim.replan` return (docs/guide/python.md).
#[pyclass(frozen, module = "facesim", name = "Result")]
pub struct Result {
    /// The output directory the files were written to (str).
    #[pyo3(get)]
    out_dir: String,
    /// face_pre's vertices: float64, shape (n, 3), LPS mm.
    #[pyo3(get)]
    vertices_pre: Py<PyAny>,
    /// face_post's vertices, same order: float64, shape (n, 3), LPS mm.
    #[pyo3(get)]
    vertices_post: Py<PyAny>,
    /// The triangles (shared by face_pre and face_post): int64, shape (m, 3), vertex indices.
    #[pyo3(get)]
    triangles: Py<PyAny>,
    /// |vertices_post − vertices_pre| per vertex (displacement.csv's `dist`): float64, (n,), mm.
    #[pyo3(get)]
    displacement: Py<PyAny>,
    /// Label → {"pre", "post": float64 (3,) LPS mm, "change_mm": float, "kind": str}, the
    /// landmarks found (report.json `landmarks` says why a missing one is missing); for a
    /// replan, the run's landmarks carried with the new plan.
    #[pyo3(get)]
    landmarks: Py<PyAny>,
    /// report.json as a dict.
    #[pyo3(get)]
    report: Py<PyAny>,
    /// With `[uncertainty] samples > 0` (face_band.ply written by this run): {"mean", "p05",
    /// "p95"}, float64 (n,) displacement magnitudes in mm; otherwise None.
    #[pyo3(get)]
    band: Py<PyAny>,
}

#[pymethods]
impl Result {
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let n = self.vertices_pre.bind(py).len()?;
        let m = self.triangles.bind(py).len()?;
        Ok(format!(
            "facesim.Result(out_dir={:?}, vertices={n}, triangles={m})",
            self.out_dir
        ))
    }
}

/// Points as a float64 (n, 3) array.
fn points<'py>(py: Python<'py>, v: &[[f64; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = v.iter().flatten().copied().collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([v.len(), 3])?
        .into_any())
}

fn triangles<'py>(py: Python<'py>, t: &[[u32; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<i64> = t.iter().flatten().map(|&i| i64::from(i)).collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([t.len(), 3])?
        .into_any())
}

/// displacement.csv's `dist`, computed the same way (pre − post, Euclidean norm).
fn distances(pre: &[[f64; 3]], post: &[[f64; 3]]) -> Vec<f64> {
    pre.iter()
        .zip(post)
        .map(|(a, b)| norm(sub(*a, *b)))
        .collect()
}

/// The report as the Python object `json.loads` makes of report.json, keys in sorted order as
/// they have always been (made through a sorted JSON map).
fn json<'py>(py: Python<'py>, report: &facesim::report::Report) -> PyResult<Bound<'py, PyAny>> {
    let err = |e: serde_json::Error| crate::FacesimError::new_err(format!("report: {e}"));
    let text = serde_json::to_value(report)
        .and_then(|v| serde_json::to_string(&v))
        .map_err(err)?;
    py.import("json")?.call_method1("loads", (text,))
}

/// The landmarks with both positions, from the report's `landmarks`, in label order (the dict's
/// order since it was first made from report.json as a sorted JSON map).
fn landmarks<'py>(
    py: Python<'py>,
    report: &facesim::report::Report,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let mut carried: Vec<_> = report.landmarks.0.iter().collect();
    carried.sort_by(|a, b| a.0.cmp(&b.0));
    for (label, l) in carried {
        let (Some(pre), Some(post)) = (l.pre, l.post) else {
            continue;
        };
        let e = PyDict::new(py);
        e.set_item("pre", PyArray1::from_vec(py, pre.to_vec()))?;
        e.set_item("post", PyArray1::from_vec(py, post.to_vec()))?;
        e.set_item("change_mm", l.change_mm)?;
        e.set_item("kind", kind_name(l.kind))?;
        d.set_item(label, e)?;
    }
    Ok(d)
}

/// A landmark's kind as report.json writes it.
fn kind_name(k: facesim::landmarks::Kind) -> &'static str {
    match k {
        facesim::landmarks::Kind::Soft => "soft",
        facesim::landmarks::Kind::Bone => "bone",
    }
}

/// face_band.ply's `mean`, `p05`, `p95` columns when this run wrote it (modified at or after
/// `since`: an older file left in a reused output directory is not this run's).
fn band<'py>(py: Python<'py>, out_dir: &Path, since: SystemTime) -> PyResult<Bound<'py, PyAny>> {
    let path = out_dir.join("face_band.ply");
    let fresh = std::fs::metadata(&path)
        .and_then(|m| m.modified())
        .is_ok_and(|t| t >= since);
    if !fresh {
        return Ok(py.None().into_bound(py));
    }
    let mesh = facesim::mesh::read_mesh(&path).map_err(crate::raise)?;
    let d = PyDict::new(py);
    for name in ["mean", "p05", "p95"] {
        let c = mesh
            .vertex_columns
            .iter()
            .find(|c| c.name == name)
            .ok_or_else(|| {
                crate::FacesimError::new_err(format!(
                    "{}: no vertex property '{name}'",
                    path.display()
                ))
            })?;
        d.set_item(name, PyArray1::from_vec(py, c.values.clone()))?;
    }
    Ok(d.into_any())
}

/// A run's outputs (`since`: when the run started).
pub fn from_run(
    py: Python<'_>,
    o: &facesim::commands::Outcome,
    since: SystemTime,
) -> PyResult<Result> {
    Ok(Result {
        out_dir: o.out_dir.display().to_string(),
        vertices_pre: points(py, &o.skin.vertices)?.unbind(),
        vertices_post: points(py, &o.face_post.vertices)?.unbind(),
        triangles: triangles(py, &o.skin.triangles)?.unbind(),
        displacement: PyArray1::from_vec(py, distances(&o.skin.vertices, &o.face_post.vertices))
            .into_any()
            .unbind(),
        landmarks: landmarks(py, &o.report)?.into_any().unbind(),
        report: json(py, &o.report)?.unbind(),
        band: band(py, &o.out_dir, since)?.unbind(),
    })
}

/// A replan's outputs: the basis's face_pre, the predicted face and its band when PLAN.toml
/// asked for one.
pub fn from_replan(
    py: Python<'_>,
    basis: &facesim::plan::PlanBasis,
    r: &facesim::commands::replan::Replanned,
) -> PyResult<Result> {
    Ok(Result {
        out_dir: r.out_dir.display().to_string(),
        vertices_pre: points(py, &basis.face_pre)?.unbind(),
        vertices_post: points(py, &r.face_post)?.unbind(),
        triangles: triangles(py, &basis.triangles)?.unbind(),
        displacement: PyArray1::from_vec(py, distances(&basis.face_pre, &r.face_post))
            .into_any()
            .unbind(),
        landmarks: landmarks(py, &r.report)?.into_any().unbind(),
        report: json(py, &r.report)?.unbind(),
        // A replan's output directory is written whole: a face_band.ply in it is its own
        // (PLAN.toml's [uncertainty], from the run's stored reduced model).
        band: band(py, &r.out_dir, SystemTime::UNIX_EPOCH)?.unbind(),
    })
}

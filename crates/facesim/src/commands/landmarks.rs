//! `facesim landmarks MESH [--out DIR] [--frame auto|lps]` (docs/guide/landmarks.md "A face mesh
//! alone"): the soft-tissue landmarks and measurements of any face mesh — a 3D photo, no CT —
//! written as `DIR/landmarks.mrk.json` (Slicer markups in the mesh file's own coordinates) and
//! `DIR/measurements.json`, as one unit (`output::RunDir`): a mesh that is not a face writes
//! nothing.

use crate::error::{Error, Result};
use crate::landmarks::scan::{self, FaceLandmarks, FrameFrom};
use crate::landmarks::{markups, positions};
use crate::output::RunDir;
use std::path::{Path, PathBuf};

/// The output directory when none is given: `<stem>_landmarks` beside the mesh.
pub fn default_out(mesh: &Path) -> PathBuf {
    let stem = mesh
        .file_stem()
        .map_or("mesh".into(), |s| s.to_string_lossy().to_string());
    mesh.with_file_name(format!("{stem}_landmarks"))
}

/// Find the landmarks of the face mesh at `mesh_path` and write them into `out`; returns the
/// directory written and what was found. Not a face: an input error naming the file and the
/// search that failed.
pub fn landmarks(
    mesh_path: &Path,
    out: &Path,
    from: FrameFrom,
) -> Result<(PathBuf, FaceLandmarks)> {
    let mesh = crate::mesh::read_mesh(mesh_path)?;
    let found = scan::landmarks_of(&mesh, from).map_err(|e| Error::input(mesh_path, e))?;
    let unit = RunDir::create(out)?;
    let dir = unit.path();
    let mut doc = markups::document("landmarks", &positions(&found.landmarks));
    doc["markups"][0]["coordinateUnits"] = found.unit.name.into();
    let json = |v: &serde_json::Value, p: &Path| -> Result<()> {
        let text = serde_json::to_string_pretty(v).map_err(|e| Error::output(p, e))?;
        std::fs::write(p, text).map_err(|e| Error::output(p, e))
    };
    let lm_path = dir.join("landmarks.mrk.json");
    json(&doc, &lm_path)?;
    let mut meas = serde_json::to_value(&found).map_err(|e| Error::output(out, e))?;
    meas["mesh"] = mesh_path.display().to_string().into();
    json(&meas, &dir.join("measurements.json"))?;
    Ok((unit.commit()?, found))
}

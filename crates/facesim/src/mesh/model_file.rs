//! Surface models as other programs (3D Slicer above all) save them: STL, PLY, OBJ, legacy VTK
//! and VTK XML PolyData, brought to LPS millimetres.
//!
//! Slicer marks the frame of a model file: "SPACE=RAS" or "SPACE=LPS" in the STL header, the
//! legacy VTK header line, a PLY `comment` or an OBJ `#` comment, and a `SPACE` field-data
//! string in .vtp. A file saying RAS has x and y negated; a file saying nothing is LPS (Slicer's
//! default since 4.11, and facesim's frame).

use super::surface::Mesh;
use super::{obj, ply, stl, vtk, vtp};
use crate::error::{Error, Result};
use std::path::Path;

/// The frame a header text declares, if any.
pub(crate) fn declared_ras(header: &str) -> Option<bool> {
    let h = header.to_ascii_uppercase();
    if h.contains("SPACE=RAS") {
        Some(true)
    } else if h.contains("SPACE=LPS") {
        Some(false)
    } else {
        None
    }
}

/// Read a model file by extension (.stl, .ply, .obj, .vtk, .vtp) into LPS: the format dispatch
/// of the one mesh reader. The mesh is not checked (callers check what they need: a closed
/// surface, a manifold skin; [`super::read_mesh`] adds the general check).
pub fn read_model(path: &Path) -> Result<Mesh> {
    if !path.is_file() {
        return Err(Error::input(path, "no such file"));
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let head = || -> Result<String> {
        // The header of a PLY (up to end_header) or the comments of an OBJ are in the first KB:
        // read only those, not the whole mesh a second time.
        use std::io::Read;
        let mut b = Vec::with_capacity(4096);
        std::fs::File::open(path)
            .and_then(|f| f.take(4096).read_to_end(&mut b))
            .map_err(|e| Error::input(path, e))?;
        Ok(String::from_utf8_lossy(&b).into_owned())
    };
    let (mut mesh, ras) = crate::error::guard(path, || match ext.as_str() {
        "stl" => {
            let (m, h) = stl::read(path)?;
            Ok((m, declared_ras(&h)))
        }
        "vtk" => {
            let (m, h) = vtk::read_legacy(path)?;
            Ok((m, declared_ras(&h)))
        }
        "vtp" => {
            let v = vtp::read(path)?;
            let ras = v.space().map(|s| s.eq_ignore_ascii_case("RAS"));
            Ok((v.mesh, ras))
        }
        "ply" => {
            let h = head()?;
            let header = h.split("end_header").next().unwrap_or_default().to_string();
            Ok((ply::read(path)?, declared_ras(&header)))
        }
        "obj" => {
            let h = head()?;
            let comments: String = h
                .lines()
                .filter(|l| l.starts_with('#'))
                .collect::<Vec<_>>()
                .join("\n");
            Ok((obj::read(path)?, declared_ras(&comments)))
        }
        _ => Err(Error::input(
            path,
            "unknown model format (expected .stl, .ply, .obj, .vtk or .vtp)",
        )),
    })?;
    if ras == Some(true) {
        for v in &mut mesh.vertices {
            v[0] = -v[0];
            v[1] = -v[1];
        }
    }
    if mesh.vertices.iter().flatten().any(|c| !c.is_finite()) {
        return Err(Error::input(path, "non-finite vertex coordinates"));
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ras_headers_flip_x_and_y() {
        let dir = tempfile::tempdir().unwrap();
        let m = Mesh::new(
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 10.0]],
            vec![[0, 1, 2]],
        );
        let ras = dir.path().join("ras.stl");
        stl::write(&m, &ras, "3D Slicer output. SPACE=RAS").unwrap();
        assert_eq!(read_model(&ras).unwrap().vertices[0], [-1.0, -2.0, 3.0]);
        let lps = dir.path().join("lps.stl");
        stl::write(&m, &lps, "3D Slicer output. SPACE=LPS").unwrap();
        assert_eq!(read_model(&lps).unwrap().vertices[0], [1.0, 2.0, 3.0]);
        let obj = dir.path().join("m.obj");
        std::fs::write(
            &obj,
            "# 3D Slicer output. SPACE=RAS\nv 1 2 3\nv 4 5 6\nv 7 8 10\nf 1 2 3\n",
        )
        .unwrap();
        assert_eq!(read_model(&obj).unwrap().vertices[1], [-4.0, -5.0, 6.0]);
    }
}

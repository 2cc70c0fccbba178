//! Triangle meshes (skin and skull surfaces, face scans): the data type, its checks, one reader
//! of every format (OBJ, PLY, STL, legacy VTK, VTP: [`read_mesh`] over
//! [`model_file::read_model`]) and OBJ/PLY output. Coordinates are LPS millimetres.

pub mod inside;
pub mod model_file;
pub mod obj;
pub mod ply;
pub mod stl;
mod surface;
pub mod vtk;
pub mod vtp;

pub(crate) use surface::one_rings;
pub use surface::{Column, Edges, Mesh, MeshStats, checksum};
#[cfg(test)]
pub(crate) use surface::{kuhn_cell, kuhn_grid, sheet, two_triangles};

use crate::error::{Error, Result};
use std::path::Path;

pub fn read_mesh(path: &Path) -> Result<Mesh> {
    let mesh = model_file::read_model(path)?;
    mesh.check(path)?;
    Ok(mesh)
}

/// Write OBJ or PLY (binary little-endian) by extension, atomically.
pub fn write_mesh(mesh: &Mesh, path: &Path) -> Result<()> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "obj" => obj::write(mesh, path),
        "ply" => ply::write(mesh, path, ply::Encoding::BinaryLittleEndian),
        _ => Err(Error::output(
            path,
            "unknown mesh format (expected .obj or .ply)",
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Mesh {
        Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn read_mesh_reads_every_format_a_run_writes_to_the_same_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let m = two_triangles();
        let at = |name: &str| dir.path().join(name);
        write_mesh(&m, &at("m.obj")).unwrap();
        write_mesh(&m, &at("m.ply")).unwrap();
        stl::write(&m, &at("m.stl"), "facesim SPACE=LPS").unwrap();
        vtk::write_legacy(&m, &[], &at("m.vtk")).unwrap();
        vtp::write_vtp(&m, &[], &at("m.vtp")).unwrap();
        for name in ["m.obj", "m.ply", "m.stl", "m.vtk", "m.vtp"] {
            let back = read_mesh(&at(name)).unwrap();
            // The coordinates are exact in f32, so even the STL reads back bit for bit.
            assert_eq!(back.vertices, m.vertices, "{name}");
            assert_eq!(back.triangles, m.triangles, "{name}");
        }
        std::fs::write(at("m.off"), "OFF\n").unwrap();
        let e = read_mesh(&at("m.off")).unwrap_err().to_string();
        assert!(e.contains("m.off") && e.contains("unknown"), "{e}");
    }

    #[test]
    fn good_mesh_passes_and_counts_boundary() {
        let s = square().check(Path::new("sq")).unwrap();
        assert_eq!(s.boundary_edges, 4);
        assert!((square().area() - 1.0).abs() < 1e-15);
        let n = square().vertex_normals();
        assert!(n.iter().all(|v| (v[2] - 1.0).abs() < 1e-15));
    }

    #[test]
    fn bad_meshes_are_refused_with_reason() {
        let p = Path::new("m.ply");
        let mut m = square();
        m.triangles.push([0, 1, 1]);
        assert!(m.check(p).unwrap_err().to_string().contains("degenerate"));
        let mut m = square();
        m.vertices.push([0.5, 0.5, 1.0]);
        m.triangles.push([0, 2, 4]);
        assert!(m.check(p).unwrap_err().to_string().contains("non-manifold"));
        let mut m = square();
        m.triangles[1] = [0, 3, 2];
        assert!(m.check(p).unwrap_err().to_string().contains("orientation"));
        let mut m = square();
        m.vertices[2][0] = f64::NAN;
        assert!(m.check(p).unwrap_err().to_string().contains("non-finite"));
        let mut m = square();
        m.triangles[0][2] = 9;
        assert!(m.check(p).unwrap_err().to_string().contains("index 9"));
    }
}

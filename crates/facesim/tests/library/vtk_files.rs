//! Models as VTK itself saves them (docs/guide/slicer.md "Model files"): facesim's `.vtp` is read by
//! VTK (the PyPI wheel in the test venv, the library 3D Slicer and ParaView save models with),
//! which re-saves it in every encoding its writers have (tests/python/vtk_variants.py); facesim
//! reads each back to the same mesh, point data and frame.

use crate::common;

use facesim::mesh::Mesh;
use facesim::mesh::vtk::PointArray;
use std::path::PathBuf;
use std::sync::OnceLock;

/// A curved 80 × 80 grid (13 122 triangles, arrays of many zlib blocks) with coordinates that
/// use all of a double's digits, and a 3-component point array.
fn surface() -> (Mesh, PointArray) {
    let n = 80;
    let mut v = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 * 0.7 + 0.1, j as f64 * 0.9 - 31.0);
            v.push([x, y, 60.0 + 5.0 * (x / 9.0).sin() * (y / 13.0).cos()]);
        }
    }
    let d: Vec<f64> = v
        .iter()
        .flat_map(|p| [p[2].sin(), -p[0] / 7.0, p[1].cos() * 1e-3])
        .collect();
    (
        Mesh::new(v, common::grid_triangles(n)),
        PointArray {
            name: "displacement_mm".into(),
            components: 3,
            values: d,
        },
    )
}

/// facesim's `.vtp` of [`surface`] and VTK's re-saves of it (tests/python/vtk_variants.py):
/// the directory of the variants and the script's log (`read …` and one `wrote NAME` line per
/// file). Made once per test binary.
fn variants() -> &'static (PathBuf, String) {
    static V: OnceLock<(PathBuf, String)> = OnceLock::new();
    V.get_or_init(|| {
        let dir = common::kept_dir("facesim-vtk");
        let (mesh, disp) = surface();
        let ours = dir.join("ours.vtp");
        facesim::mesh::vtp::write_vtp(&mesh, &[disp], &ours).unwrap();
        let out = dir.join("variants");
        let log =
            common::run_python_script("vtk_variants.py", &[ours.as_os_str(), out.as_os_str()]);
        (out, log)
    })
}

#[test]
fn every_encoding_vtk_writes_reads_back_exactly() {
    let (mesh, disp) = surface();
    let (out, log) = variants();
    // VTK read facesim's file whole.
    assert!(
        log.contains(&format!(
            "read {} points {} polys",
            mesh.vertices.len(),
            mesh.triangles.len()
        )),
        "{log}"
    );

    let mut vtp = 0;
    for line in log.lines() {
        let Some(name) = line.strip_prefix("wrote ") else {
            continue;
        };
        let path = out.join(name);
        if name.ends_with(".vtk") {
            // Legacy (VTK 9 writes version 5.1 with field data and array metadata): binary
            // keeps the doubles, ASCII rounds them to 11 significant digits.
            let (m, header) = facesim::mesh::vtk::read_legacy(&path).unwrap();
            assert!(header.contains("SPACE=RAS"), "{name}: {header}");
            assert_eq!(m.triangles, mesh.triangles, "{name}");
            let tol = if name.contains("ascii") { 1e-8 } else { 0.0 };
            for (a, b) in m.vertices.iter().zip(&mesh.vertices) {
                assert!(
                    (0..3).all(|k| (a[k] - b[k]).abs() <= tol),
                    "{name}: {a:?} {b:?}"
                );
            }
            assert_eq!(m.vertices.len(), mesh.vertices.len(), "{name}");
            continue;
        }
        vtp += 1;
        let v = facesim::mesh::vtp::read(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(v.space(), Some("RAS"), "{name}");
        assert_eq!(v.mesh.triangles, mesh.triangles, "{name}");
        if name.starts_with("float32") {
            for (a, b) in v.mesh.vertices.iter().zip(&mesh.vertices) {
                assert_eq!(*a, b.map(|x| x as f32 as f64), "{name}");
            }
        } else {
            assert_eq!(v.mesh.vertices, mesh.vertices, "{name}");
        }
        let d = v
            .point_data
            .iter()
            .find(|a| a.name == disp.name)
            .unwrap_or_else(|| panic!("{name}: no {}", disp.name));
        assert_eq!(d, &disp, "{name}");
        // As a model file (a region surface, a skin): RAS turned to LPS.
        let m = facesim::mesh::model_file::read_model(&path).unwrap();
        assert_eq!(m.vertices[7], {
            let p = v.mesh.vertices[7];
            [-p[0], -p[1], p[2]]
        });
    }
    assert_eq!(vtp, 15, "{log}");
}

#[test]
fn damaged_binary_vtp_is_one_clear_line() {
    let dir = common::kept_dir("facesim-vtk-bad");
    let (out, _) = variants();
    for name in [
        "appended-raw-zlib-UInt64.vtp",
        "appended-raw-none-UInt32.vtp",
        "binary-zlib-UInt32.vtp",
    ] {
        let bytes = std::fs::read(out.join(name)).unwrap();
        // Cut in the middle of the data, and (separately) the compressed bytes scrambled.
        let cut = dir.join(format!("cut-{name}"));
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let e = match facesim::mesh::model_file::read_model(&cut) {
            Ok(_) => panic!("{name} cut short was read"),
            Err(e) => e.to_string(),
        };
        assert!(
            !e.contains('\n') && e.contains(&format!("cut-{name}")),
            "{name}: {e}"
        );
    }
    let mut bytes = std::fs::read(out.join("appended-raw-zlib-UInt64.vtp")).unwrap();
    let mark = bytes
        .windows(14)
        .position(|w| w == b"<AppendedData ")
        .unwrap();
    let n = bytes.len();
    for b in &mut bytes[mark + 200..n - 200] {
        *b ^= 0x5A;
    }
    let bad = dir.join("scrambled.vtp");
    std::fs::write(&bad, &bytes).unwrap();
    let e = match facesim::mesh::model_file::read_model(&bad) {
        Ok(_) => panic!("scrambled zlib data was read"),
        Err(e) => e.to_string(),
    };
    assert!(!e.contains('\n') && e.contains("scrambled.vtp"), "{e}");
}

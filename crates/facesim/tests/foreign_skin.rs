//! A skin exported by another program (issue 16 item 6): an iso-surface of the whole CT made by
//! scikit-image's marching cubes (tests/python/isosurface.py, in the venv target/slicer-venv),
//! with the airway and sinuses joined to the face, internal surfaces and islands, given as the
//! case's `[skin]`. facesim keeps its outer face — what a cylindrical range scan of it sees — and
//! reports what it dropped (docs/pipeline.md "A skin from another program").

mod common;

use std::path::Path;
use std::process::Command;

/// The whole-CT iso-surface at `level` HU, written by scikit-image to `out` (.stl or .obj).
fn isosurface(ct: &facesim::volume::Volume, level: f64, out: &Path) {
    let dir = out.parent().unwrap();
    let raw = dir.join("ct.f32");
    let bytes: Vec<u8> = ct.data.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&raw, bytes).unwrap();
    let meta = serde_json::json!({
        "dims": ct.dims, "spacing": ct.spacing, "origin": ct.origin, "direction": ct.direction,
    });
    let meta_path = dir.join("ct.json");
    std::fs::write(&meta_path, meta.to_string()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/isosurface.py");
    let st = Command::new(common::venv_python())
        .arg(script)
        .arg(&raw)
        .arg(&meta_path)
        .arg(level.to_string())
        .arg(out)
        .status()
        .unwrap();
    assert!(st.success(), "isosurface.py failed");
    std::fs::remove_file(raw).unwrap();
}

/// Whether the horizontal ray from `p` straight away from the vertical axis through `axis`
/// leaves the CT without meeting tissue (HU above `level`), starting `skip` mm out.
fn clear_outward(ct: &facesim::volume::Volume, p: [f64; 3], axis: [f64; 2], level: f32) -> bool {
    let d = [p[0] - axis[0], p[1] - axis[1]];
    let l = d[0].hypot(d[1]);
    let d = [d[0] / l, d[1] / l];
    let skip = 1.5;
    (0..400).all(|k| {
        let t = skip + 0.5 * k as f64;
        ct.sample([p[0] + t * d[0], p[1] + t * d[1], p[2]], -1000.0) < level
    })
}

/// The whole iso-surface as the case's skin: the run keeps the face a range scan sees, matching
/// the CT's own skin, with nothing from inside the head, and says what it dropped.
#[test]
fn a_whole_ct_isosurface_is_cut_to_its_outer_face() {
    let real = common::real_ct();
    let ct = facesim::volume::read_volume(&real).unwrap();
    let d = common::kept_dir("facesim-foreign");
    let iso = d.join("iso.stl");
    isosurface(&ct, -500.0, &iso);
    let case = std::fs::read_to_string(real.parent().unwrap().join("case.toml")).unwrap();
    let case = case.replace(
        "[ct]\npath = \"Cranium.inv3\"",
        &format!(
            "[skin]\npath = \"iso.stl\"\n\n[ct]\npath = {:?}",
            real.display().to_string()
        ),
    );
    assert!(case.contains("iso.stl"));
    std::fs::write(d.join("case.toml"), case).unwrap();
    let out = facesim::pipeline::run(&d, None, &facesim::observe::Quiet).unwrap();

    let fs = out
        .report
        .surfaces
        .foreign_skin
        .as_ref()
        .expect("foreign_skin in report");
    let whole = facesim::mesh::model_file::read_model(&iso).unwrap();
    assert_eq!(fs.triangles_in, whole.triangles.len());
    assert!(fs.pieces > 1 && fs.island_triangles_dropped > 0, "{fs:?}");
    assert!(fs.hidden_triangles_dropped > 10_000, "{fs:?}");
    assert_eq!(
        fs.triangles_kept
            + fs.hidden_triangles_dropped
            + fs.island_triangles_dropped
            + fs.degenerate_triangles_dropped,
        fs.triangles_in
    );
    assert!(
        out.report
            .warnings
            .iter()
            .any(|w| w.contains("kept its outer face"))
    );
    // The model's skin is the kept face (written as face_pre.ply).
    let kept = facesim::mesh::read_mesh(&out.out_dir.join("face_pre.ply")).unwrap();
    assert_eq!(kept.triangles.len(), fs.triangles_kept);

    // Independent of the mesh: from a kept vertex of the face the CT is air all the way out,
    // radially; the whole iso-surface fails this at its inner surfaces (the test could fail).
    let axis = out.report.surfaces.axis_xy.unwrap();
    let clear = |m: &facesim::mesh::Mesh| {
        let n = m.vertices.len().div_ceil(20_000);
        // The face (anterior of the axis): behind the head the head rest blocks the view.
        let sample: Vec<_> = m
            .vertices
            .iter()
            .step_by(n)
            .filter(|p| p[1] < axis[1])
            .collect();
        let c = sample
            .iter()
            .filter(|p| clear_outward(&ct, ***p, axis, -500.0))
            .count();
        c as f64 / sample.len() as f64
    };
    let (k, w) = (clear(&kept), clear(&whole));
    eprintln!("clear line of sight outward: kept {k:.4}, whole iso-surface {w:.4}");
    assert!(k > 0.99, "kept {k}");
    assert!(w < 0.8, "whole {w}");
    // And it lies on the skin the product scans from the CT itself (report's distance from the
    // face to the extracted CT skin, 0.5 mm at the 90th percentile; max 5 mm at the nostrils).
    let st = out.report.surfaces.scan_to_ct_skin_mm.as_ref().unwrap();
    eprintln!("kept face to the CT's own skin: {st:?}");
    assert!(st.p90 < 0.5 && st.max < 6.0, "{st:?}");
}

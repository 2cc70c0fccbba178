//! Plans the way 3D Slicer users make them (docs/guide/slicer.md): an osteotomy's move as an ITK
//! transform file, its region as a closed surface or a markups plane; and the face written as
//! VTK PolyData and STL.

use crate::common;

use facesim::case::{Case, Region};
use facesim::osteotomy::Plan;
use std::path::Path;

/// A known rigid move, spelled out independently of the product: 5° about the x axis through
/// `C`, then the translation `T` (LPS mm).
const C: [f64; 3] = [0.0, -60.0, -50.0];
const T: [f64; 3] = [1.0, -6.0, 2.0];
const ANGLE: f64 = 5.0;

fn rx() -> [[f64; 3]; 3] {
    let (s, c) = ANGLE.to_radians().sin_cos();
    [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
}

fn known_move(p: [f64; 3]) -> [f64; 3] {
    let r = rx();
    let d = [p[0] - C[0], p[1] - C[1], p[2] - C[2]];
    std::array::from_fn(|i| (0..3).map(|k| r[i][k] * d[k]).sum::<f64>() + C[i] + T[i])
}

fn known_inverse(q: [f64; 3]) -> [f64; 3] {
    let r = rx();
    let d = [q[0] - C[0] - T[0], q[1] - C[1] - T[1], q[2] - C[2] - T[2]];
    // Rᵀ d + C
    std::array::from_fn(|i| (0..3).map(|k| r[k][i] * d[k]).sum::<f64>() + C[i])
}

/// An AffineTransform file holding x ↦ M x + o, written as ITK does: Parameters = M row-major
/// then the translation, FixedParameters = the centre (0 here: the offset holds it all).
fn affine_file(m: [[f64; 3]; 3], o: [f64; 3]) -> String {
    let mut p: Vec<String> = m.iter().flatten().map(|x| format!("{x:.17e}")).collect();
    p.extend(o.iter().map(|x| format!("{x:.17e}")));
    format!(
        "#Insight Transform File V1.0\n#Transform 0\nTransform: AffineTransform_double_3_3\nParameters: {}\nFixedParameters: 0 0 0\n",
        p.join(" ")
    )
}

/// The resampling (Slicer-saved) form of the known move: its inverse, y ↦ Rᵀ y + (C − Rᵀ(C + T)).
fn slicer_file() -> String {
    let r = rx();
    let rt: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]));
    let o = known_inverse([0.0; 3]);
    affine_file(rt, o)
}

fn sample_points() -> Vec<[f64; 3]> {
    (0..27)
        .map(|i| {
            [
                -40.0 + 40.0 * (i % 3) as f64,
                -90.0 + 30.0 * ((i / 3) % 3) as f64,
                -80.0 + 35.0 * (i / 9) as f64,
            ]
        })
        .collect()
}

fn load(dir: &Path, osteotomy: &str) -> facesim::Result<Case> {
    std::fs::write(
        dir.join("case.toml"),
        format!("[ct]\npath = \"ct.nii.gz\"\n\n[[osteotomy]]\nname = \"maxilla\"\n{osteotomy}\n"),
    )
    .unwrap();
    let (mut case, _) = Case::load(dir)?;
    facesim::pipeline::inputs::read_masks(&mut case)?;
    Ok(case)
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() < 1e-9)
}

#[test]
fn a_slicer_transform_file_gives_the_move_it_was_saved_for() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("maxilla.tfm"), slicer_file()).unwrap();
    let region = "region = { sphere = { center = [0.0, 0.0, 0.0], radius = 1000.0 } }";
    let case = load(
        dir.path(),
        &format!("{region}\ntransform = \"maxilla.tfm\""),
    )
    .unwrap();
    let pts = sample_points();
    let moved = Plan::new(&case.osteotomy).apply(&pts, 1.0).0;
    for (p, q) in pts.iter().zip(&moved) {
        assert!(
            close(*q, known_move(*p)),
            "{p:?} -> {q:?}, want {:?}",
            known_move(*p)
        );
    }
    // The same file read as a modelling transform is the inverse move.
    let case = load(
        dir.path(),
        &format!("{region}\ntransform = \"maxilla.tfm\"\ntransform_direction = \"modelling\""),
    )
    .unwrap();
    let moved = Plan::new(&case.osteotomy).apply(&pts, 1.0).0;
    for (p, q) in pts.iter().zip(&moved) {
        assert!(close(*q, known_inverse(*p)));
    }
    // A Slicer-style Euler3D file about a centre: 5° about x (ITK angles in radians) through
    // C, translation T, is the resampling form of the inverse of... the move it describes read
    // as modelling must equal known_move.
    let euler = format!(
        "#Insight Transform File V1.0\n#Transform 0\nTransform: Euler3DTransform_double_3_3\nParameters: {} 0 0 {} {} {}\nFixedParameters: {} {} {} 0\n",
        ANGLE.to_radians(),
        T[0],
        T[1],
        T[2],
        C[0],
        C[1],
        C[2]
    );
    std::fs::write(dir.path().join("euler.tfm"), euler).unwrap();
    let case = load(
        dir.path(),
        &format!("{region}\ntransform = \"euler.tfm\"\ntransform_direction = \"modelling\""),
    )
    .unwrap();
    let moved = Plan::new(&case.osteotomy).apply(&pts, 1.0).0;
    for (p, q) in pts.iter().zip(&moved) {
        assert!(close(*q, known_move(*p)));
    }
}

#[test]
fn bad_transform_files_and_keys_are_one_line_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let region = "region = { sphere = { center = [0.0, 0.0, 0.0], radius = 1000.0 } }";
    let scaled = affine_file(
        [[1.02, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        [0.0; 3],
    );
    std::fs::write(dir.path().join("scaled.tfm"), scaled).unwrap();
    let e = load(dir.path(), &format!("{region}\ntransform = \"scaled.tfm\""))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("scaled.tfm") && e.contains("scaling") && !e.contains('\n'),
        "{e}"
    );
    std::fs::write(dir.path().join("ok.tfm"), slicer_file()).unwrap();
    let e = load(
        dir.path(),
        &format!("{region}\ntransform = \"ok.tfm\"\ntranslate = [0.0, 1.0, 0.0]"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("case.toml") && e.contains("not both"), "{e}");
    let e = load(
        dir.path(),
        &format!("{region}\ntransform = \"missing.tfm\""),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("missing.tfm"), "{e}");
}

/// A box as 12 triangles in binary STL, written in RAS (x and y negated, header SPACE=RAS) as
/// 3D Slicer does when asked for RAS.
fn write_box_stl_ras(path: &Path, min: [f64; 3], max: [f64; 3]) {
    let m = facesim::mesh::Mesh::cuboid(min, max);
    let mut b = vec![0u8; 80];
    let h = b"3D Slicer output. SPACE=RAS";
    b[..h.len()].copy_from_slice(h);
    b.extend((m.triangles.len() as u32).to_le_bytes());
    for t in &m.triangles {
        b.extend([0u8; 12]);
        for v in t {
            let p = m.vertices[*v as usize];
            for c in [-p[0], -p[1], p[2]] {
                b.extend((c as f32).to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn surface_and_plane_regions_select_what_a_box_and_a_half_space_select() {
    let dir = tempfile::tempdir().unwrap();
    let (min, max) = ([-30.25, -80.25, -70.25], [30.25, -20.25, -30.25]);
    write_box_stl_ras(&dir.path().join("seg.stl"), min, max);
    let case = load(dir.path(), "region = { surface = \"seg.stl\" }").unwrap();
    let boxed = Region::Box { min, max };
    let mut inside = 0;
    for i in 0..15 {
        for j in 0..15 {
            for k in 0..15 {
                let p = [
                    -40.0 + 6.0 * i as f64,
                    -95.0 + 6.0 * j as f64,
                    -85.0 + 5.0 * k as f64,
                ];
                assert_eq!(
                    case.osteotomy[0].region.contains(p),
                    boxed.contains(p),
                    "{p:?}"
                );
                inside += boxed.contains(p) as usize;
            }
        }
    }
    assert!(inside > 100, "{inside}");
    // A markups plane (pointNormal, RAS) as a half-space: the side its normal points to.
    std::fs::write(
        dir.path().join("cut.mrk.json"),
        r#"{"markups": [{"type": "Plane", "coordinateSystem": "RAS", "planeType": "pointNormal",
        "baseToNode": [1,0,0,0, 0,1,0,0, 0,0,-1,0, 0,0,0,1],
        "controlPoints": [{"position": [5.0, 10.0, -40.0]}]}]}"#,
    )
    .unwrap();
    let case = load(dir.path(), "region = { plane = \"cut.mrk.json\" }").unwrap();
    let r = &case.osteotomy[0].region;
    assert!(r.contains([0.0, 0.0, -41.0]) && !r.contains([0.0, 0.0, -39.0]));
    // An open surface is refused, naming the file.
    let mut b = std::fs::read(dir.path().join("seg.stl")).unwrap();
    b.truncate(84 + 50 * 11);
    b[80..84].copy_from_slice(&11u32.to_le_bytes());
    std::fs::write(dir.path().join("open.stl"), b).unwrap();
    let e = load(dir.path(), "region = { surface = \"open.stl\" }")
        .unwrap_err()
        .to_string();
    assert!(e.contains("open.stl") && e.contains("not closed"), "{e}");
}

/// The phantom run with the plan as numbers and with the plan as Slicer files (a transform file
/// and a segment surface) predict the same face; the face is also written as .vtp and .stl.
#[test]
fn a_run_planned_with_slicer_files_equals_the_run_planned_with_numbers() {
    // A coarse phantom (3 mm voxels) on an 8/16 mm mesh, with no discretisation estimate,
    // keeps the two runs short; the comparison is exact on any mesh.
    let phantom = common::kept_dir("facesim-slicer-phantom");
    let opts = facesim_validate::phantom::PhantomOptions {
        spacing: [3.0; 3],
        supersample: 1,
        scan_step_mm: 5.0,
        ..Default::default()
    };
    facesim_validate::phantom::write_case(&phantom, &opts).unwrap();
    let (min, max) = ([-70.05, -75.05, -125.05], [70.05, -1.45, -26.45]);
    let head = format!(
        "[ct]\npath = \"{}\"\n[skin]\npath = \"{}\"\n[surface]\nmovable = {{ sphere = {{ center = [0.0, -60.0, -45.0], radius = 70.0 }} }}\n[tet]\nskin_size_mm = 8.0\ndeep_size_mm = 16.0\nerror_estimate = false\n",
        phantom.join("ct.nii.gz").display(),
        phantom.join("face.ply").display()
    );
    let numbers = common::kept_dir("facesim-slicer-numbers");
    std::fs::write(
        numbers.join("case.toml"),
        format!(
            "{head}[[osteotomy]]\nname = \"mandible\"\nregion = {{ box = {{ min = {min:?}, max = {max:?} }} }}\ntranslate = [0.0, -6.0, 0.0]\n"
        ),
    )
    .unwrap();
    let files = common::kept_dir("facesim-slicer-files");
    write_box_stl_ras(&files.join("mandible.stl"), min, max);
    // 6 mm anterior (−y) as Slicer saves it: the resampling transform, +6 mm in y.
    std::fs::write(
        files.join("mandible.tfm"),
        affine_file(
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [0.0, 6.0, 0.0],
        ),
    )
    .unwrap();
    std::fs::write(
        files.join("case.toml"),
        format!(
            "{head}[[osteotomy]]\nname = \"mandible\"\nregion = {{ surface = \"mandible.stl\" }}\ntransform = \"mandible.tfm\"\n"
        ),
    )
    .unwrap();
    let quiet = facesim::observe::Quiet;
    let a = facesim::commands::run(&numbers, None, &quiet).unwrap();
    let b = facesim::commands::run(&files, None, &quiet).unwrap();
    assert_eq!(a.face_post.vertices.len(), b.face_post.vertices.len());
    let mut dmax = 0.0f64;
    for (p, q) in a.face_post.vertices.iter().zip(&b.face_post.vertices) {
        for i in 0..3 {
            assert!((p[i] - q[i]).abs() < 1e-9, "{p:?} vs {q:?}");
        }
    }
    for (p, q) in a.skin.vertices.iter().zip(&a.face_post.vertices) {
        dmax = dmax.max(facesim::vec3::norm(facesim::vec3::sub(*q, *p)));
    }
    assert!(dmax > 1.0, "the plan moved the face ({dmax} mm)");
    // face_post.vtp: the same points as face_post.obj, displacement_mm = post − pre.
    let out = files.join("out");
    let (m, arrays) = facesim::mesh::vtp::read_vtp(&out.join("face_post.vtp")).unwrap();
    let obj = facesim::mesh::read_mesh(&out.join("face_post.obj")).unwrap();
    let pre = facesim::mesh::read_mesh(&out.join("face_pre.obj")).unwrap();
    assert_eq!(m.vertices, obj.vertices);
    assert_eq!(m.triangles, obj.triangles);
    let d = arrays.iter().find(|a| a.name == "displacement_mm").unwrap();
    assert_eq!(d.components, 3);
    for (i, (p, q)) in pre.vertices.iter().zip(&obj.vertices).enumerate() {
        for c in 0..3 {
            assert!((d.values[3 * i + c] - (q[c] - p[c])).abs() < 1e-9);
        }
    }
    let (stl, header) = facesim::mesh::stl::read(&out.join("face_post.stl")).unwrap();
    assert!(header.contains("SPACE=LPS"));
    assert_eq!(stl.triangles.len(), obj.triangles.len());
}

//! `facesim run`, `facesim compare` and `facesim render` through the real CLI: good runs write every output,
//! bad inputs fail with one line naming the file, and nothing is written or changed.

use crate::cli;
use crate::common;

use cli::{assert_clean_failure, facesim};
use common::{phantom_dir, snapshot};
use std::path::{Path, PathBuf};

/// A case directory whose case.toml points at the shared phantom CT, with `extra` appended.
fn case_with(extra: &str) -> PathBuf {
    let d = common::kept_dir("facesim-case");
    let ct = phantom_dir().join("ct.nii.gz");
    std::fs::write(
        d.join("case.toml"),
        format!("name = \"t\"\n[ct]\npath = \"{}\"\n{extra}", ct.display()),
    )
    .unwrap();
    d
}

fn run(case: &Path) -> cli::CliResult {
    facesim(&["run", case.to_str().unwrap()])
}

/// The run failed cleanly and left no output directory behind.
fn fails_writing_nothing(case: &Path, file: &str, problem: &str) {
    let before = snapshot(case);
    let r = run(case);
    assert_clean_failure(&r, file, problem);
    assert!(
        !case.join("out").exists(),
        "an output directory was created"
    );
    assert_eq!(snapshot(case), before, "the case directory changed");
}

/// One full run of the bundled sample, shared by the tests that read its outputs (a run costs
/// ~15 s; CI time matters). Its output lies apart from the shared phantom case, which the tests
/// only read.
fn bundled_run() -> &'static Path {
    static OUT: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    OUT.get_or_init(|| {
        let out = common::out_dir("facesim-bundled-run");
        let r = facesim(&[
            "run",
            phantom_dir().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(r.code, 0, "{}", r.stderr);
        out
    })
}

/// A model-only `--set` that leaves every stage before the solve as it is: a coarse tetrahedral
/// mesh and no error estimate, for tests of what happens before and around the solve.
const COARSE: [&str; 6] = [
    "--set",
    "tet.skin_size_mm=12",
    "--set",
    "tet.deep_size_mm=24",
    "--set",
    "tet.error_estimate=false",
];

/// The same in case.toml.
const COARSE_TOML: &str = "[tet]\nskin_size_mm = 12\ndeep_size_mm = 24\nerror_estimate = false\n";

#[test]
fn phantom_case_runs_and_writes_every_output() {
    let out = bundled_run();
    for f in [
        "face_pre.obj",
        "face_pre.ply",
        "skull_pre.ply",
        "labels.nii.gz",
        "report.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    for stage in [
        "read_ct",
        "segment",
        "surfaces",
        "read_scan",
        "write",
        "total",
    ] {
        assert!(
            report["timings"][stage].as_f64().unwrap() >= 0.0,
            "timing {stage}"
        );
    }
    // The given face scan is the face, vertex for vertex (docs/reference/case.md: same vertices, same order).
    let scan = facesim::mesh::read_mesh(&phantom_dir().join("face.ply")).unwrap();
    let pre = facesim::mesh::read_mesh(&out.join("face_pre.ply")).unwrap();
    assert!(
        scan.vertices == pre.vertices,
        "face_pre is not the scan's vertices in order"
    );
    let obj = facesim::mesh::read_mesh(&out.join("face_pre.obj")).unwrap();
    assert!(
        obj.triangles == pre.triangles && obj.vertices == pre.vertices,
        "OBJ and PLY differ"
    );
    // The labels read back on the CT's grid with the six classes.
    let labels = facesim::volume::read_volume(&out.join("labels.nii.gz")).unwrap();
    let ct = facesim::volume::read_volume(&phantom_dir().join("ct.nii.gz")).unwrap();
    assert_eq!(labels.dims, ct.dims);
    assert_eq!(labels.data.iter().cloned().fold(0.0, f32::max), 5.0);

    // Running again gives byte-identical meshes (determinism with rayon); what is compared is
    // made before the solve, so the second run's model may be coarse.
    let run2 = common::out_dir("facesim-bundled-run2");
    let mut args = vec![
        "run",
        phantom_dir().to_str().unwrap(),
        "--out",
        run2.to_str().unwrap(),
    ];
    args.extend(COARSE);
    let r = facesim(&args);
    assert_eq!(r.code, 0, "{}", r.stderr);
    for f in ["face_pre.ply", "skull_pre.ply", "labels.nii.gz"] {
        assert_eq!(
            std::fs::read(out.join(f)).unwrap(),
            std::fs::read(run2.join(f)).unwrap(),
            "{f}"
        );
    }
}

#[test]
fn compare_reports_distances_and_refuses_bad_meshes() {
    let face = phantom_dir().join("face.ply");
    let r = facesim(&[
        "compare",
        face.to_str().unwrap(),
        face.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let j: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    for k in [
        "mean",
        "rms",
        "max",
        "pct_within_1mm",
        "pct_within_2mm",
        "vertex_mean",
        "vertex_max",
    ] {
        assert!(j[k].is_number(), "{k}");
    }
    assert_eq!(j["max"].as_f64().unwrap(), 0.0);
    assert_eq!(j["pct_within_1mm"].as_f64().unwrap(), 100.0);

    let d = tempfile::tempdir().unwrap();
    let bad = d.path().join("garbage.ply");
    std::fs::write(&bad, [0u8, 159, 146, 150, 1, 2, 3]).unwrap();
    assert_clean_failure(
        &facesim(&["compare", face.to_str().unwrap(), bad.to_str().unwrap()]),
        "garbage.ply",
        "PLY",
    );
}

/// `compare` and `render` read every face format a run writes: the .vtp gives the .ply's
/// figures exactly (ASCII, shortest round-trip decimals) and the same picture; the .stl (f32
/// coordinates, welded vertices) the same printed summary figures.
#[test]
fn compare_and_render_read_every_format_a_run_writes() {
    let out = bundled_run();
    let pre = out.join("face_pre.obj");
    let compare = |post: &str, json: bool| {
        let post = out.join(post);
        let mut args = vec!["compare", pre.to_str().unwrap(), post.to_str().unwrap()];
        if json {
            args.push("--json");
        }
        let r = facesim(&args);
        assert_eq!(r.code, 0, "{}: {}", post.display(), r.stderr);
        r.stdout
    };
    let ply = compare("face_post.ply", true);
    let j: serde_json::Value = serde_json::from_str(&ply).unwrap();
    assert!(
        j["max"].as_f64().unwrap() > 0.1,
        "the plan moved nothing: {ply}"
    );
    assert_eq!(compare("face_post.vtp", true), ply, "VTP");
    // The headline line (surface distances); the per-vertex line needs the vertex order, which
    // an STL does not keep.
    let headline = |s: String| s.lines().next().unwrap_or_default().to_string();
    let want = headline(compare("face_post.ply", false));
    assert!(want.starts_with("mean "), "{want}");
    assert_eq!(headline(compare("face_post.stl", false)), want, "STL");

    // The pictures go to a directory of this test's own: the run's is read by other tests.
    let pictures = common::kept_dir("facesim-render");
    let picture = |mesh: &str| {
        let png = pictures.join(format!("{mesh}.png"));
        let r = facesim(&[
            "render",
            out.join(mesh).to_str().unwrap(),
            "--out",
            png.to_str().unwrap(),
            "--size",
            "64",
        ]);
        assert_eq!(r.code, 0, "render {mesh}: {}", r.stderr);
        std::fs::read(png).unwrap()
    };
    let vtp = picture("face_post.vtp");
    assert!(vtp.starts_with(b"\x89PNG"), "not a PNG");
    assert_eq!(
        vtp,
        picture("face_post.ply"),
        "the .vtp renders unlike the .ply"
    );
}

#[test]
fn bad_case_files_fail_before_anything_is_written() {
    let c = case_with("[springs]\nmax_lenght_mm = 30.0\n");
    fails_writing_nothing(&c, "case.toml", "max_lenght_mm");

    let c = case_with("[surface]\nalpha = \"soft\"\n");
    fails_writing_nothing(&c, "case.toml", "");

    let c = case_with(
        "[[osteotomy]]\nname = \"m\"\nregion = { box = { min = [0, 0, 0], max = [1, 1, 1] } }\ntranslate = [0, nan, 0]\n",
    );
    fails_writing_nothing(&c, "case.toml", "finite");

    let c =
        case_with("[registration]\nscan = [[0, 0, 0], [1, 0, 0]]\nct = [[0, 0, 0], [1, 0, 0]]\n");
    fails_writing_nothing(&c, "case.toml", "landmark");

    // A landmark typed in metres for millimetres, 9 m off: one line, not a hang (the closest
    // point search walked every empty shell of cells between it and the face).
    let c = case_with("[[landmark]]\nlabel = \"Prn\"\nposition = [9000.0, 0.0, 0.0]\n");
    fails_writing_nothing(&c, "case.toml", "from the face");

    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("case.toml"),
        "[ct]\npath = \"nowhere.nii.gz\"\n",
    )
    .unwrap();
    fails_writing_nothing(d.path(), "nowhere.nii.gz", "no such file");

    let r = facesim(&["run", "/definitely/not/a/case"]);
    assert_clean_failure(&r, "/definitely/not/a/case", "no such file");
}

#[test]
fn bad_face_scans_fail_with_the_scan_named() {
    let write_case = |name: &str, body: &[u8], extra: &str| {
        let c = case_with(&format!("[skin]\npath = \"{name}\"\n{extra}"));
        std::fs::write(c.join(name), body).unwrap();
        c
    };
    let tri = |verts: &str, faces: &str| format!("{verts}{faces}").into_bytes();
    // Three vertices on the phantom's face and one triangle, as OBJ.
    let v = "v 0 -80 0\nv 10 -79 0\nv 0 -80 10\nv 10 -79 10\n";

    fails_writing_nothing(&write_case("empty.obj", b"", ""), "empty.obj", "empty mesh");
    fails_writing_nothing(
        &write_case(
            "nan.obj",
            &tri("v 0 -80 0\nv nan -79 0\nv 0 -80 10\n", "f 1 2 3\n"),
            "",
        ),
        "nan.obj",
        "non-finite",
    );
    fails_writing_nothing(
        &write_case("index.obj", &tri(v, "f 1 2 9\n"), ""),
        "index.obj",
        "",
    );
    fails_writing_nothing(
        &write_case("degenerate.obj", &tri(v, "f 1 2 3\nf 2 2 4\n"), ""),
        "degenerate.obj",
        "degenerate",
    );
    let nm = "v 0 -80 0\nv 10 -80 0\nv 0 -80 10\nv 0 -70 -10\nv 5 -90 5\n";
    fails_writing_nothing(
        &write_case(
            "nonmanifold.obj",
            &tri(nm, "f 1 2 3\nf 2 1 4\nf 1 2 5\n"),
            "",
        ),
        "nonmanifold.obj",
        "non-manifold",
    );
    fails_writing_nothing(
        &write_case(
            "garbage.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n\x00\x01",
            "",
        ),
        "garbage.ply",
        "",
    );
    fails_writing_nothing(&write_case("truncated.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\x00\x00", ""), "truncated.ply", "");
    // A scan 1 m away from the CT.
    let far = "v 1000 -80 0\nv 1010 -79 0\nv 1000 -80 10\nv 1010 -79 10\n";
    fails_writing_nothing(
        &write_case("far.obj", &tri(far, "f 1 2 3\nf 2 4 3\n"), ""),
        "far.obj",
        "does not overlap",
    );
}

#[test]
fn a_failed_run_leaves_previous_outputs_intact() {
    let c = case_with("");
    assert_eq!(run(&c).code, 0);
    let before = snapshot(&c.join("out"));
    // Now break the case (a scan that does not exist) and run again.
    let text =
        std::fs::read_to_string(c.join("case.toml")).unwrap() + "[skin]\npath = \"gone.ply\"\n";
    std::fs::write(c.join("case.toml"), text).unwrap();
    assert_clean_failure(&run(&c), "gone.ply", "not found");
    assert_eq!(snapshot(&c.join("out")), before);
}

#[test]
fn a_ct_without_bone_is_refused() {
    // A ball of soft tissue: a head with no skull.
    let n = 40;
    let mut v = facesim::volume::Volume {
        dims: [n, n, n],
        spacing: [2.0; 3],
        origin: [-39.0; 3],
        direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        data: vec![-1000.0; n * n * n],
    };
    for a in 0..v.data.len() {
        let p = v.to_world(v.ijk(a).map(|x| x as f64));
        if (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() < 30.0 {
            v.data[a] = 40.0;
        }
    }
    let d = tempfile::tempdir().unwrap();
    facesim::volume::nifti_io::write(&v, &d.path().join("soft.nii.gz")).unwrap();
    std::fs::write(d.path().join("case.toml"), "[ct]\npath = \"soft.nii.gz\"\n").unwrap();
    fails_writing_nothing(d.path(), "soft.nii.gz", "no bone");
}

#[test]
fn a_moved_scan_is_registered_back_by_landmarks() {
    // Move the phantom's face scan by a known rigid motion, give four landmark pairs, and the
    // pipeline must put it back: face_pre = the original scan to rounding, residual ≈ 0.
    let scan = facesim::mesh::read_mesh(&phantom_dir().join("face.ply")).unwrap();
    let (c, s) = (10f64.to_radians().cos(), 10f64.to_radians().sin());
    let mv = |p: [f64; 3]| {
        [
            c * p[0] - s * p[1] + 20.0,
            s * p[0] + c * p[1] - 35.0,
            p[2] + 7.5,
        ]
    };
    let mut moved = scan.clone();
    moved.vertices = scan.vertices.iter().map(|p| mv(*p)).collect();
    let ct_pts = [
        [0.0, -98.0, 0.0],
        [40.0, -69.0, 20.0],
        [-40.0, -69.0, -20.0],
        [0.0, -80.0, 35.0],
    ];
    let fmt = |pts: Vec<[f64; 3]>| {
        pts.iter()
            .map(|p| format!("[{}, {}, {}]", p[0], p[1], p[2]))
            .collect::<Vec<_>>()
            .join(", ")
    };
    // The registration is checked, not the solve: a coarse model.
    let c_dir = case_with(&format!(
        "{COARSE_TOML}[skin]\npath = \"moved.ply\"\n[registration]\nscan = [{}]\nct = [{}]\n",
        fmt(ct_pts.iter().map(|p| mv(*p)).collect()),
        fmt(ct_pts.to_vec())
    ));
    facesim::mesh::ply::write(
        &moved,
        &c_dir.join("moved.ply"),
        facesim::mesh::ply::Encoding::Ascii,
    )
    .unwrap();
    let r = run(&c_dir);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let pre = facesim::mesh::read_mesh(&c_dir.join("out/face_pre.ply")).unwrap();
    let worst = pre
        .vertices
        .iter()
        .zip(&scan.vertices)
        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*a, *b)))
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-6,
        "registered scan is {worst} mm from the original"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(c_dir.join("out/report.json")).unwrap())
            .unwrap();
    assert!(report["registration"]["rms_residual"].as_f64().unwrap() < 1e-6);
    // Without the registration, the moved scan is far from the CT skin and the report warns.
    let c2 = case_with(&format!("{COARSE_TOML}[skin]\npath = \"moved.ply\"\n"));
    facesim::mesh::ply::write(
        &moved,
        &c2.join("moved.ply"),
        facesim::mesh::ply::Encoding::Ascii,
    )
    .unwrap();
    let r = run(&c2);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stderr.contains("check the registration"), "{}", r.stderr);
}

#[test]
fn impossible_plans_and_empty_cts_are_refused() {
    // A segment that selects nothing.
    let c = case_with(
        "[[osteotomy]]\nname = \"nowhere\"\nregion = { box = { min = [500, 500, 500], max = [501, 501, 501] } }\ntranslate = [0, -5, 0]\n",
    );
    fails_writing_nothing(&c, "case.toml", "contains none");
    // A movable-region mask that does not exist.
    let c = case_with("[surface]\nmovable = { mask = \"nomask.nii.gz\" }\n");
    fails_writing_nothing(&c, "nomask.nii.gz", "not found");
    // The mandible moved 40 mm forward through 13 mm of soft tissue (cm typed as mm, say): the
    // C1 model's skin hangs on springs and the bone passes through it, an impossible plan.
    let forty = "[[osteotomy]]\nname = \"mandible\"\nregion = { box = { min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] } }\ntranslate = [0.0, -40.0, 0.0]\n";
    let c = case_with(&format!("[solve]\nmodel = \"equilibrium\"\n{forty}"));
    fails_writing_nothing(&c, "case.toml", "moves through the skin");
    // The volumetric model (default): the tissue follows its bone, the solution turns elements
    // inside out, and the run says so with a non-zero exit, the move beyond orthognathic size
    // and what to check (the outputs written for inspection).
    let c = case_with(&format!("{COARSE_TOML}{forty}"));
    let r = run(&c);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains("moves bone up to 40 mm")
            && r.stderr.contains("translate (mm)")
            && r.stderr.contains("inside out: not a valid prediction"),
        "{}",
        r.stderr
    );
    // A CT of air only: no head, no skin.
    let n = 24;
    let v = facesim::volume::Volume {
        dims: [n, n, n],
        spacing: [2.0; 3],
        origin: [-23.0; 3],
        direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        data: vec![-1000.0; n * n * n],
    };
    let d = tempfile::tempdir().unwrap();
    facesim::volume::nifti_io::write(&v, &d.path().join("air.nii.gz")).unwrap();
    std::fs::write(d.path().join("case.toml"), "[ct]\npath = \"air.nii.gz\"\n").unwrap();
    fails_writing_nothing(d.path(), "air.nii.gz", "");
}

#[test]
fn numerical_faults_are_reported_with_what_to_change() {
    // Every spring misses: bone is never within half a millimetre of the skin. That is the
    // input's (CT and [springs]) problem, not a numerical failure: the error names the CT.
    let c = case_with("[springs]\nmax_length_mm = 0.5\n");
    let r = run(&c);
    assert_clean_failure(&r, "ct.nii.gz", "max_length_mm");
    assert!(!r.stderr.contains("numerical failure"), "{}", r.stderr);
    assert!(!c.join("out").exists());
    // koch1996 with no rigid skin: K alone has rigid-body modes (singular).
    let c = case_with(
        "[surface]\nmovable = { sphere = { center = [0.0, 0.0, 0.0], radius = 5000.0 } }\n[solve]\nmodel = \"koch1996\"\n[[osteotomy]]\nname = \"mandible\"\nregion = { box = { min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] } }\ntranslate = [0.0, -6.0, 0.0]\n",
    );
    let r = run(&c);
    assert_ne!(r.code, 0);
    assert_eq!(r.stderr.trim().lines().count(), 1, "{}", r.stderr);
    assert!(
        r.stderr.contains("numerical failure") && r.stderr.contains("rigid"),
        "{}",
        r.stderr
    );
    assert!(!c.join("out").exists());
}

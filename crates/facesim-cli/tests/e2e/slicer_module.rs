//! `FaceSimPredict`, the 3D Slicer CLI module (docs/guide/slicer.md): its Execution Model XML read by
//! an independent parser (ctk-cli, the CommonTK CLI parser from PyPI, in the venv
//! scripts/test-setup.sh makes), and the executable called the way Slicer calls it — the CT as a
//! temporary .nrrd, segments as .vtk, transforms as .tfm, flags as the XML declares them.

use crate::common;

use facesim::mesh::{self, Mesh};
use std::path::PathBuf;
use std::process::Command;

fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_FaceSimPredict"))
}

/// What ctk-cli makes of the module: category, title and per parameter its type, channel,
/// long flag, multiple, file extensions, enumeration and default; plus any warning it logged.
fn parsed_by_ctk_cli() -> serde_json::Value {
    let script = r#"
import json, logging, sys, ctk_cli
warnings = []
class Keep(logging.Handler):
    def emit(self, record): warnings.append(record.getMessage())
logging.getLogger().addHandler(Keep())
m = ctk_cli.CLIModule(sys.argv[1])
params = [dict(typ=p.typ, name=p.name, channel=p.channel, longflag=p.longflag,
               multiple=p.multiple, ext=p.fileExtensions, elements=p.elements, default=p.default)
          for p in m.parameters()]
print(json.dumps(dict(category=m.category, title=m.title, description=m.description,
      version=m.version, contributor=m.contributor, params=params, warnings=warnings)))
"#;
    let out = Command::new(common::venv_python())
        .args(["-c", script, exe().to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ctk-cli failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn param<'a>(spec: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    spec["params"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("no parameter {name}"))
}

#[test]
fn the_xml_is_a_valid_execution_model_for_ctk_cli() {
    let spec = parsed_by_ctk_cli();
    assert_eq!(spec["warnings"], serde_json::json!([]), "{spec}");
    assert_eq!(spec["category"], "Surgery");
    for k in ["title", "description", "version", "contributor"] {
        assert!(spec[k].as_str().is_some_and(|s| !s.is_empty()), "{k}");
    }
    let want = [
        ("ct", "image", "input", false),
        ("face", "geometry", "input", false),
        ("segments", "geometry", "input", true),
        ("transforms", "transform", "input", true),
        ("movable", "geometry", "input", false),
        ("predictedFace", "geometry", "output", false),
        ("landmarks", "pointfile", "output", false),
    ];
    for (name, typ, channel, multiple) in want {
        let p = param(&spec, name);
        assert_eq!(p["typ"], typ, "{name}");
        assert_eq!(p["channel"], channel, "{name}");
        assert_eq!(p["multiple"].as_bool().unwrap_or(false), multiple, "{name}");
    }
    let m = param(&spec, "model");
    assert_eq!(m["typ"], "string-enumeration");
    assert_eq!(m["elements"], serde_json::json!(["tet", "equilibrium"]));
    assert_eq!(m["default"], "tet");
}

const TFM_6MM_FORWARD: &str = "#Insight Transform File V1.0\n#Transform 0\nTransform: AffineTransform_double_3_3\nParameters: 1 0 0 0 1 0 0 0 1 0 6 0\nFixedParameters: 0 0 0\n";

#[test]
fn called_as_slicer_calls_it_the_module_predicts_the_face_of_the_same_plan() {
    let spec = parsed_by_ctk_cli();
    let flag = |name: &str| param(&spec, name)["longflag"].as_str().unwrap().to_string();
    // Slicer's temporary files: the CT as NRRD, the segment as .vtk, the transform as .tfm.
    let dir = common::kept_dir("facesim-slicer-module");
    let opts = facesim_validate::phantom::PhantomOptions {
        spacing: [3.0; 3],
        supersample: 1,
        ..Default::default()
    };
    let ct = dir.join("ct.nrrd");
    facesim::volume::nrrd::write(&facesim_validate::phantom::ct(&opts), &ct).unwrap();
    let (min, max) = ([-70.05, -75.05, -125.05], [70.05, -1.45, -26.45]);
    let seg = dir.join("mandible.vtk");
    mesh::vtk::write_legacy(&Mesh::cuboid(min, max), &[], &seg).unwrap();
    // Slicer saves the resampling transform: +6 mm in y for a 6 mm anterior (−y) move.
    let tfm = dir.join("mandible.tfm");
    std::fs::write(&tfm, TFM_6MM_FORWARD).unwrap();
    let movable = dir.join("movable.vtk");
    mesh::vtk::write_legacy(
        &Mesh::cuboid([-80.3, -130.3, -110.3], [80.3, -20.3, 20.3]),
        &[],
        &movable,
    )
    .unwrap();
    let face_out = dir.join("predicted.vtp");
    let landmarks_out = dir.join("landmarks.mrk.json");
    let out = Command::new(exe())
        .args([
            flag("ct").as_str(),
            ct.to_str().unwrap(),
            &flag("segments"),
            seg.to_str().unwrap(),
            &flag("transforms"),
            tfm.to_str().unwrap(),
            &flag("movable"),
            movable.to_str().unwrap(),
            &flag("model"),
            "tet",
            &flag("predictedFace"),
            face_out.to_str().unwrap(),
            &flag("landmarks"),
            landmarks_out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Slicer's progress protocol.
    assert!(stdout.starts_with("<filter-start>"), "{stdout}");
    assert!(stdout.contains("<filter-name>FaceSimPredict</filter-name>"));
    assert!(stdout.trim_end().ends_with("</filter-end>"), "{stdout}");
    let progress: Vec<f64> = stdout
        .lines()
        .filter_map(|l| {
            l.strip_prefix("<filter-progress>")?
                .strip_suffix("</filter-progress>")
        })
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(progress.len() >= 4, "{stdout}");
    assert!(progress.windows(2).all(|w| w[0] <= w[1]));
    assert!(progress.iter().all(|p| (0.0..=1.0).contains(p)) && *progress.last().unwrap() == 1.0);
    // The same plan as numbers, run by the library on the same CT: the same face.
    let case = dir.join("numbers");
    std::fs::create_dir_all(&case).unwrap();
    std::fs::write(
        case.join("case.toml"),
        format!(
            "[ct]\npath = \"{}\"\n[surface]\nmovable = {{ box = {{ min = [-80.3, -130.3, -110.3], max = [80.3, -20.3, 20.3] }} }}\n[[osteotomy]]\nname = \"m\"\nregion = {{ box = {{ min = {min:?}, max = {max:?} }} }}\ntranslate = [0.0, -6.0, 0.0]\n",
            ct.display()
        ),
    )
    .unwrap();
    let want = facesim::commands::run(&case, None, &facesim::observe::Quiet).unwrap();
    let (got, arrays) = mesh::vtp::read_vtp(&face_out).unwrap();
    assert_eq!(got.vertices.len(), want.face_post.vertices.len());
    assert_eq!(got.triangles, want.face_post.triangles);
    let mut moved = 0.0f64;
    for (i, (g, w)) in got
        .vertices
        .iter()
        .zip(&want.face_post.vertices)
        .enumerate()
    {
        for c in 0..3 {
            assert!((g[c] - w[c]).abs() < 1e-9, "vertex {i}: {g:?} vs {w:?}");
        }
        moved = moved.max(facesim::vec3::norm(facesim::vec3::sub(
            *w,
            want.skin.vertices[i],
        )));
    }
    assert!(moved > 1.0, "{moved}");
    let d = arrays.iter().find(|a| a.name == "displacement_mm").unwrap();
    for (i, (g, p)) in got.vertices.iter().zip(&want.skin.vertices).enumerate() {
        for c in 0..3 {
            assert!((d.values[3 * i + c] - (g[c] - p[c])).abs() < 1e-9);
        }
    }
    // Landmarks are written only when the run found some; never an empty or partial file.
    if landmarks_out.exists() {
        let v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&landmarks_out).unwrap()).unwrap();
        assert!(v["markups"].is_array());
    }
}

#[test]
fn a_non_rigid_transform_is_one_line_naming_the_file_and_nothing_is_written() {
    let dir = common::kept_dir("facesim-slicer-bad");
    let opts = facesim_validate::phantom::PhantomOptions {
        spacing: [6.0; 3],
        supersample: 1,
        ..Default::default()
    };
    let ct = dir.join("ct.nrrd");
    facesim::volume::nrrd::write(&facesim_validate::phantom::ct(&opts), &ct).unwrap();
    let seg = dir.join("seg.vtk");
    mesh::vtk::write_legacy(&Mesh::cuboid([-10.0; 3], [10.0; 3]), &[], &seg).unwrap();
    let tfm = dir.join("sheared.tfm");
    std::fs::write(
        &tfm,
        TFM_6MM_FORWARD.replace("1 0 0 0 1 0 0 0 1", "1 0.3 0 0 1 0 0 0 1"),
    )
    .unwrap();
    let face_out = dir.join("predicted.vtp");
    let out = Command::new(exe())
        .args([
            "--ct",
            ct.to_str().unwrap(),
            "--segments",
            seg.to_str().unwrap(),
        ])
        .args(["--transforms", tfm.to_str().unwrap()])
        .args(["--predictedFace", face_out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("sheared.tfm") && err.contains("not rigid"),
        "{err}"
    );
    assert!(!face_out.exists());
}

/// `--surgery` entries become `[[surgery]]` tables: a malformed one, or one the case's checks
/// refuse, is one line and nothing is written.
#[test]
fn a_surgery_in_clinical_terms_is_checked_like_case_toml() {
    let spec = parsed_by_ctk_cli();
    let p = param(&spec, "surgery");
    assert_eq!(p["typ"], "string");
    assert_eq!(p["multiple"].as_bool(), Some(true));
    let dir = common::kept_dir("facesim-slicer-surgery");
    let opts = facesim_validate::phantom::PhantomOptions {
        spacing: [6.0; 3],
        supersample: 1,
        ..Default::default()
    };
    let ct = dir.join("ct.nrrd");
    facesim::volume::nrrd::write(&facesim_validate::phantom::ct(&opts), &ct).unwrap();
    let face_out = dir.join("predicted.vtp");
    for (entry, problem) in [
        ("bsso advance_mm", "is not key=value"),
        ("le-fort-i advance_mm=30", "more than 20 mm"),
        ("le-fort-i pivot=nose yaw_deg=2", "is not a landmark"),
    ] {
        let out = Command::new(exe())
            .args(["--ct", ct.to_str().unwrap(), "--surgery", entry])
            .args(["--predictedFace", face_out.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(!out.status.success(), "{entry}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(problem), "{entry}: {err}");
        assert!(!face_out.exists());
    }
}

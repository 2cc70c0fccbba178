//! `facesim phantom DIR --anatomy jaws` through the real CLI: the case it writes runs with the
//! default (C1) model, and each plan moves the face the way its bone moves.

use crate::cli;
use crate::common;

use cli::facesim;
use facesim_validate::phantom_jaws as pj;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The jaws case at 2 mm, written once per test binary by the CLI.
fn jaws_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = common::kept_dir("facesim-jaws");
        let r = facesim(&[
            "phantom",
            d.to_str().unwrap(),
            "--anatomy",
            "jaws",
            "--spacing",
            "2",
            "--slice",
            "2",
        ]);
        assert_eq!(r.code, 0, "{}", r.stderr);
        d
    })
}

/// Run one plan of the jaws case; the displacements of the face vertices nearest to
/// `landmarks`.
fn run_plan(file: &str, landmarks: &[&str]) -> Vec<[f64; 3]> {
    let dir = jaws_dir();
    // Apart from the shared case: the tests run their plans at once.
    let out = common::out_dir(&format!("facesim-jaws-{}", file.trim_end_matches(".toml")));
    let r = facesim(&[
        "run",
        dir.join(file).to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    if file == "case_rotation.toml" {
        // Turning the mandible 5° about the condyles without moving the maxilla drives the lower
        // incisors about 6 mm up into the upper ones: the lip tissue caught between the teeth is
        // crushed. Rather than a few elements turning inside out and the run refused, that tissue
        // tears (`[tet] tear_gap`; 3 tetrahedra between the incisors, 2 at the
        // volume's bottom) and the run says so. It also says that the plan
        // drives the mandible's teeth into the maxilla's (`pipeline::bone_overlap`: 2 mm deep
        // along the move, in the incisors' region, y < -55).
        assert_eq!(r.code, 0, "{file}: {}", r.stderr);
        assert!(r.stderr.contains("the move tears"), "{}", r.stderr);
        let overlap = r
            .stderr
            .lines()
            .find(|l| l.contains("the plan drives segment 'mandible' into bone that stays"))
            .unwrap_or_else(|| panic!("no overlap warning: {}", r.stderr));
        let deep: f64 = overlap
            .split("up to ")
            .nth(1)
            .and_then(|t| t.split(" mm deep").next())
            .and_then(|t| t.parse().ok())
            .unwrap();
        assert!((1.0..=6.0).contains(&deep), "{overlap}");
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        assert!(report["tet"]["torn_elements"].as_u64().unwrap() > 0);
        assert_eq!(report["tet"]["inverted_elements"], 0);
    } else {
        assert_eq!(r.code, 0, "{file}: {}", r.stderr);
    }
    if file == "case.toml" {
        // An advance moves the teeth away from bone: nothing overlaps.
        assert!(!r.stderr.contains("into bone that stays"), "{}", r.stderr);
    }
    let pre = facesim::mesh::read_mesh(&out.join("face_pre.ply")).unwrap();
    let post = facesim::mesh::read_mesh(&out.join("face_post.ply")).unwrap();
    assert_eq!(pre.vertices.len(), post.vertices.len());
    let moved = |landmark: &str| {
        let p = pj::landmark(landmark).unwrap();
        let d2 = |q: &[f64; 3]| (0..3).map(|a| (q[a] - p[a]).powi(2)).sum::<f64>();
        let i = (0..pre.vertices.len())
            .min_by(|&a, &b| d2(&pre.vertices[a]).total_cmp(&d2(&pre.vertices[b])))
            .unwrap();
        assert!(
            d2(&pre.vertices[i]).sqrt() < 3.0,
            "no face vertex near {landmark}"
        );
        let d = [0, 1, 2].map(|a| post.vertices[i][a] - pre.vertices[i][a]);
        println!("{file}: {landmark} moves by {d:.2?} mm");
        d
    };
    landmarks.iter().map(|l| moved(l)).collect()
}

#[test]
fn jaws_phantom_writes_a_case_the_default_model_runs() {
    let dir = jaws_dir();
    for f in [
        "ct.nii.gz",
        "face.ply",
        "case.toml",
        "case_setback.toml",
        "case_rotation.toml",
        "case_maxilla.toml",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    // No model line unless asked for: the default model runs.
    let text = std::fs::read_to_string(dir.join("case.toml")).unwrap();
    assert!(!text.contains("[solve]"));
    // Advancement 5 mm: the soft-tissue chin over the moved bone goes forwards (−y), by no
    // more than the bone.
    let d = run_plan("case.toml", &["soft tissue pogonion"])[0];
    assert!(d[1] < -2.5 && d[1] >= -5.0 - 1e-6, "{d:?}");
}

#[test]
fn setback_rotation_and_le_fort_move_the_face_their_way() {
    let d = run_plan("case_setback.toml", &["soft tissue pogonion"])[0];
    assert!(d[1] > 2.0 && d[1] <= 4.0 + 1e-6, "{d:?}");
    // Counter-clockwise rotation: the chin goes up and forwards.
    let d = run_plan("case_rotation.toml", &["soft tissue pogonion"])[0];
    assert!(d[1] < -1.0 && d[2] > 1.0, "{d:?}");
    // Le Fort I advancement: the upper lip goes forwards, the chin stays.
    let d = run_plan(
        "case_maxilla.toml",
        &["labrale superius", "soft tissue pogonion"],
    );
    assert!(d[0][1] < -2.0 && d[0][1] >= -4.0 - 1e-6, "{d:?}");
    assert!(d[1][1].abs() < 0.5, "{d:?}");
}

/// README's first command (`facesim run data-samples/jaws`) on a face: every
/// soft-tissue landmark found, no warning, no inverted element; the upper face stays where
/// it was, and the BSSO advance moves the lower face inside the published soft/hard ranges
/// (docs/guide/validation.md) with the defaults; the page is written.
#[test]
fn the_first_sample_shows_a_face_with_every_soft_landmark() {
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws");
    let out = common::out_dir("facesim-first-sample");
    let report = cli::run_ok(&case, &out, &[]);
    assert_eq!(
        report["warnings"],
        serde_json::json!([]),
        "{}",
        report["warnings"]
    );
    assert_eq!(report["tet"]["inverted_elements"], 0);
    let lms = &report["landmarks"];
    for l in [
        "G'", "N'", "Prn", "Sn", "Ls", "Sto", "Li", "B'", "Pog'", "Me'",
    ] {
        assert!(lms[l]["pre"].is_array(), "{l}: {}", lms[l]);
    }
    for l in ["G'", "N'", "Prn"] {
        let c = lms[l]["change_mm"].as_f64().unwrap();
        assert!(c < 0.1, "{l} moved {c} mm under a mandibular move");
    }
    let published = &report["published_ratios"];
    assert_eq!(published["surgery"], "bsso-advance", "{published}");
    let rows = published["rows"].as_array().unwrap();
    assert!(rows.len() >= 3, "{published}");
    for r in rows {
        assert_eq!(r["inside"], true, "{r}");
    }
    assert!(out.join("report.html").is_file());
}

#[test]
fn a_hollow_nose_is_asked_for_by_name_and_only_the_jaws_head_has_one() {
    // `--nose hollow` (docs/design/phantom.md "Nasal passages"), of `phantom` and `phantom-cohort`:
    // the case's phantom.toml says so and
    // its CT is air inside the nose beside the septum, where the standard head's is tissue;
    // the capsule head refuses it in one line.
    let d = common::kept_dir("facesim-jaws-hollow");
    cli::hollow_jaws_phantom(&d, &["--slice", "2", "--noise", "0"]);
    let toml = std::fs::read_to_string(d.join("phantom.toml")).unwrap();
    assert!(toml.contains("\nnasal_passages = true\n"), "{toml}");
    let vol = facesim::volume::read_volume(&d.join("ct.nii.gz")).unwrap();
    let hu = |p: [f64; 3]| f64::from(vol.sample(p, f32::NAN));
    // A passage point and the septum beside it (standard head: scale 1, no shift).
    let (passage, septum) = ([8.0, -90.0, 14.0], [0.0, -90.0, 14.0]);
    assert_eq!(pj::tissue_at(passage), pj::Tissue::Soft);
    assert!(hu(passage) < -900.0, "passage {} HU", hu(passage));
    assert!(hu(septum) > -200.0, "septum {} HU", hu(septum));
    // A cohort's noses the same way.
    let c = common::kept_dir("facesim-cohort-hollow");
    let r = facesim(&[
        "phantom-cohort",
        c.to_str().unwrap(),
        "--cases",
        "1",
        "--nose",
        "hollow",
        "--spacing",
        "3",
        "--slice",
        "3",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let toml = std::fs::read_to_string(c.join("case001/phantom.toml")).unwrap();
    assert!(toml.contains("\nnasal_passages = true\n"), "{toml}");
    let e = common::kept_dir("facesim-capsule-hollow");
    let r = facesim(&["phantom", e.to_str().unwrap(), "--nose", "hollow"]);
    cli::assert_clean_failure(&r, "phantom", "--nose hollow needs --anatomy jaws");
}

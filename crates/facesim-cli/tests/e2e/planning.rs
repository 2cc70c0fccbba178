//! Plans in the surgeon's words through `facesim run` (docs/guide/planning.md): on both real CTs a
//! case.toml holding only the CT and `[[surgery]]` entries predicts the face, every bony
//! landmark moves exactly as stated in the head frame, and a plan the CT cannot carry is one
//! line naming case.toml with nothing written.

use crate::cli;
use crate::common;

use cli::{assert_clean_failure, facesim};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// A case directory holding a case.toml of `ct` (the `[ct]` table's body) and `plan`.
fn case(prefix: &str, ct: &str, plan: &str) -> PathBuf {
    let dir = common::out_dir(prefix);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("case.toml"), format!("[ct]\n{ct}\n\n{plan}")).unwrap();
    dir
}

fn real_ct() -> String {
    format!("path = {:?}", common::real_ct().display().to_string())
}

fn headsq_ct() -> String {
    format!(
        "path = {:?}\naxes = \"LAI\"\nintercept = -1024.0",
        common::real_mandible_ct().display().to_string()
    )
}

fn v3(v: &Value) -> [f64; 3] {
    [0, 1, 2].map(|k| v[k].as_f64().unwrap())
}

/// report.json `plan.landmarks[label]`: its move forward, up, left (mm) and in LPS.
fn moved(report: &Value, label: &str) -> ([f64; 3], [f64; 3]) {
    let l = &report["plan"]["landmarks"][label];
    let (pre, post) = (v3(&l["pre"]), v3(&l["post"]));
    (
        [
            l["forward_mm"].as_f64().unwrap(),
            l["up_mm"].as_f64().unwrap(),
            l["left_mm"].as_f64().unwrap(),
        ],
        [0, 1, 2].map(|k| post[k] - pre[k]),
    )
}

fn close(a: [f64; 3], b: [f64; 3], tol: f64) {
    assert!((0..3).all(|k| (a[k] - b[k]).abs() <= tol), "{a:?} vs {b:?}");
}

fn run(case: &Path, out: &Path) -> Value {
    let r = facesim(&[
        "run",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

#[test]
fn le_fort_i_advance_5_and_bsso_setback_4_on_the_pitched_head_move_along_its_forward() {
    let dir = case(
        "facesim-plan-headsq",
        &headsq_ct(),
        "[[surgery]]\nkind = \"le-fort-i\"\nadvance_mm = 5.0\n\n[[surgery]]\nkind = \"bsso\"\nadvance_mm = -4.0\n",
    );
    let out = dir.join("out");
    let report = run(&dir, &out);
    let frame = &report["clinical_frame"];
    let forward = v3(&frame["forward"]);
    // headsq lies face-down: the head's forward dips well below the scanner's horizontal.
    assert!(forward[2] < -0.15, "{frame}");
    for (label, mm) in [
        ("A", 5.0),
        ("ANS", 5.0),
        ("U1", 5.0),
        ("Pog", -4.0),
        ("B", -4.0),
        ("L1", -4.0),
    ] {
        let (clinical, lps) = moved(&report, label);
        close(clinical, [mm, 0.0, 0.0], 1e-9);
        close(lps, forward.map(|f| f * mm), 1e-9);
    }
    // The condyles stay with the proximal segments.
    for label in ["Co-R", "Co-L"] {
        let (clinical, _) = moved(&report, label);
        close(clinical, [0.0; 3], 0.0);
    }
    // The segments are written; a maxillary advance with a mandibular setback is none of the
    // published table's surgery types, and the report says so.
    for f in [
        "segment_maxilla.ply",
        "segment_maxilla.nii.gz",
        "segment_mandible.ply",
        "report.html",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    assert!(
        report["published_ratios"]["surgery"].is_null(),
        "{}",
        report["published_ratios"]
    );
}

#[test]
fn le_fort_i_advance_5_on_the_promed_ct_and_a_bsso_it_cannot_carry() {
    let dir = case(
        "facesim-plan-promed",
        &real_ct(),
        "[[surgery]]\nkind = \"le-fort-i\"\nadvance_mm = 5.0\n",
    );
    let out = dir.join("out");
    let report = run(&dir, &out);
    let forward = v3(&report["clinical_frame"]["forward"]);
    for label in ["A", "ANS"] {
        let (clinical, lps) = moved(&report, label);
        close(clinical, [5.0, 0.0, 0.0], 1e-9);
        close(lps, forward.map(|f| f * 5.0), 1e-9);
    }
    assert_eq!(report["published_ratios"]["surgery"], "lefort-advance");
    // No mandible in this field of view: a BSSO names what is missing, writes nothing.
    let bad = case(
        "facesim-plan-promed-bsso",
        &real_ct(),
        "[[surgery]]\nkind = \"bsso\"\nadvance_mm = -4.0\n",
    );
    let out = bad.join("out");
    let r = facesim(&["run", bad.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_clean_failure(&r, "case.toml", "a BSSO needs the mandible; needs L1 (");
    assert!(!out.exists(), "a refused plan wrote {}", out.display());
}

#[test]
fn bad_plans_on_the_jaws_phantom_are_one_line_and_write_nothing() {
    let jaws = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws");
    let ct = format!("path = {:?}", jaws.join("ct.nii.gz").display().to_string());
    for (plan, problem) in [
        ("kind = \"le-fort-i\"\nadvance_mm = 25.0", "more than 20 mm"),
        ("kind = \"genioplasty\"\npitch_deg = 40.0", "more than 30"),
        (
            "kind = \"bsso\"\nyaw_deg = 2.0\npivot = \"nose\"",
            "is not a landmark",
        ),
        ("kind = \"le-fort-ii\"", "unknown variant"),
    ] {
        let dir = case("facesim-plan-bad", &ct, &format!("[[surgery]]\n{plan}\n"));
        let out = dir.join("out");
        let r = facesim(&["run", dir.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        assert_clean_failure(&r, "case.toml", problem);
        assert!(!out.exists(), "{plan}: wrote {}", out.display());
    }
}

//! The plan basis (docs/design/plan-basis.md) on the phantom with jaws and the volumetric model: a
//! replanned face equals a full `run` of the same plan (two segments, translation and rotation),
//! the run's own plan comes back, bad plans, bad basis files and a missing or corrupt report.json
//! are refused naming the file with nothing written, a sweep writes one row per plan, and
//! report.json reads back into `Report` unchanged.

use crate::browser;
use crate::common;

use facesim::case::{Case, Osteotomy, SolveModel};
use facesim::commands::{self, Outcome};
use facesim::commands::{replan, sweep};
use facesim::observe::Quiet;
use facesim::plan::file;
use facesim::report::Report;
use facesim_validate::phantom::PhantomOptions;
use facesim_validate::phantom_jaws::{self, JawsOptions};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn jaws_case() -> Case {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    let dir = DIR.get_or_init(|| {
        let d = common::kept_dir("facesim-replan-jaws");
        let opts = JawsOptions {
            phantom: PhantomOptions {
                spacing: [2.0; 3],
                ..PhantomOptions::default()
            },
            solve_model: Some("tet".into()),
        };
        phantom_jaws::write_case(&d, &opts).unwrap();
        d
    });
    let (mut case, _) = Case::load(&dir.join("case_maxilla.toml")).unwrap();
    assert_eq!(case.solve.model, SolveModel::Tet);
    case.tet.skin_size_mm = 6.0;
    case.tet.deep_size_mm = 12.0;
    // Tissue lifting off the bone at a saw line (the lift-off rounds, docs/design/pipeline.md) is a
    // contact state the plan chooses: the face is linear in the plan, and the basis exact, within
    // one state. With nothing sliding every released node is free, one state for every plan.
    case.tet.sliding = false;
    // The re-plans turn the maxilla 4° into the phantom's 3 mm nasal floor, which 6 mm elements
    // cannot follow without a few turning inside out; these tests are of the basis, not the mesh.
    case.tet.accept_inverted = true;
    // Tearing the tissue such a plan inverts is a state the plan chooses too (docs/design/pipeline.md
    // "Large moves"): kept off, so that every plan is in the run's state.
    case.tet.tear_gap = false;
    case
}

/// Two segments, maxilla above the occlusal plane and the mandible's front below it (apart by
/// 2 mm so no bone node lies in both), with `moves` (translate, rotate_deg, pivot) each.
fn two_segments(moves: [([f64; 3], [f64; 3], [f64; 3]); 2]) -> Vec<Osteotomy> {
    let boxed = |min: [f64; 3], max: [f64; 3]| facesim::case::Region::Box { min, max };
    let regions = [
        ("maxilla", boxed([-90.0, -120.0, -24.0], [90.0, -11.0, 3.0])),
        (
            "mandible",
            boxed([-90.0, -120.0, -110.0], [90.0, -11.0, -26.0]),
        ),
    ];
    regions
        .into_iter()
        .zip(moves)
        .map(
            |((name, region), (translate, rotate_deg, pivot))| Osteotomy {
                name: name.into(),
                region,
                translate,
                rotate_deg,
                pivot,
            },
        )
        .collect()
}

fn run_plan(osteotomy: Vec<Osteotomy>, prefix: &str) -> Outcome {
    let mut case = jaws_case();
    case.osteotomy = osteotomy;
    commands::run_case(case, &common::out_dir(prefix), &Quiet).unwrap()
}

/// The run whose basis the tests re-plan from: both segments advanced.
fn basis_run() -> &'static Outcome {
    static RUN: OnceLock<Outcome> = OnceLock::new();
    RUN.get_or_init(|| {
        run_plan(
            two_segments([
                ([0.0, -4.0, 0.0], [0.0; 3], [0.0; 3]),
                ([0.0, -5.0, 0.0], [0.0; 3], [0.0; 3]),
            ]),
            "facesim-replan-a",
        )
    })
}

/// A full run of plan B, the independent path the re-planned results are checked against.
fn plan_b_run() -> &'static Outcome {
    static RUN: OnceLock<Outcome> = OnceLock::new();
    RUN.get_or_init(|| run_plan(plan_b(), "facesim-replan-b"))
}

/// A different plan: both segments translated and rotated about their own pivots.
fn plan_b() -> Vec<Osteotomy> {
    two_segments([
        ([1.0, -3.0, 2.0], [3.0, -2.0, 4.0], [0.0, -60.0, -10.0]),
        ([0.0, -6.0, 1.0], [-4.0, 0.0, 0.0], [0.0, 7.0, -3.0]),
    ])
}

fn write_plan(path: &Path, plan: &[Osteotomy]) {
    #[derive(serde::Serialize)]
    struct P<'a> {
        osteotomy: &'a [Osteotomy],
    }
    std::fs::write(path, toml::to_string(&P { osteotomy: plan }).unwrap()).unwrap();
}

fn max_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| facesim::vec3::norm(facesim::vec3::sub(*p, *q)))
        .fold(0.0, f64::max)
}

#[test]
fn replanning_equals_a_full_run_of_the_new_plan_and_gives_the_runs_own_face_back() {
    let a = basis_run();
    let report = a.report.plan_basis.as_ref().unwrap();
    assert_eq!(report.model, "tet-linear");
    assert!(report.exact, "{report:?}");
    // The run's own plan, replanned from its stored basis, is its own face.
    let tmp = common::kept_dir("facesim-replan-own");
    let own = tmp.join("own.toml");
    write_plan(&own, &basis_run_plan());
    let r = replan::replan(&a.out_dir, &own, Some(&tmp.join("own"))).unwrap();
    let err = max_distance(&r.face_post, &a.face_post.vertices);
    assert!(err < 1e-6, "own plan: {err} mm");
    // Plan B: rotations and translations of both segments, against a full run of plan B.
    let b_file = tmp.join("b.toml");
    write_plan(&b_file, &plan_b());
    let r = replan::replan(&a.out_dir, &b_file, None).unwrap();
    assert_eq!(r.out_dir, a.out_dir.join("replan"));
    let full = plan_b_run();
    let err = max_distance(&r.face_post, &full.face_post.vertices);
    let moved = max_distance(&full.face_post.vertices, &full.skin.vertices);
    println!("plan B: replan vs full run {err:.3e} mm (face moves up to {moved:.2} mm)");
    assert!(moved > 3.0, "plan B must move the face: {moved}");
    assert!(err < 1e-6, "plan B: {err} mm");
    // The files written are the run's face outputs, read back equal.
    for f in [
        "face_post.obj",
        "face_post.ply",
        "face_displacement.ply",
        "displacement.csv",
        "report.json",
        "skull_post.ply",
    ] {
        assert!(r.out_dir.join(f).is_file(), "{f}");
    }
    let back = facesim::mesh::read_mesh(&r.out_dir.join("face_post.ply")).unwrap();
    assert!(max_distance(&back.vertices, &full.face_post.vertices) < 1e-6);
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(r.out_dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["replan"]["basis_model"], "tet-linear");
    assert_eq!(json["replan"]["exact"], true);
}

fn basis_run_plan() -> Vec<Osteotomy> {
    basis_run()
        .report
        .parameters
        .as_ref()
        .unwrap()
        .osteotomy
        .clone()
}

/// `f` must fail with a message naming `names`, leaving `out` unwritten.
fn refused(f: impl FnOnce(&Path) -> facesim::Result<()>, names: &Path, what: &str) {
    let out = common::kept_dir("facesim-replan-bad").join("out");
    let e = f(&out).expect_err(what).to_string();
    assert!(
        e.contains(&names.display().to_string()),
        "{what}: '{e}' does not name {}",
        names.display()
    );
    assert!(!e.contains('\n'), "{what}: one line");
    assert!(!out.exists(), "{what}: something was written");
}

#[test]
fn bad_plans_and_bad_basis_files_are_refused_naming_the_file_with_nothing_written() {
    let a = basis_run();
    let tmp = common::kept_dir("facesim-replan-inputs");
    let go = |dir: &Path, plan: &Path| {
        let (dir, plan) = (dir.to_path_buf(), plan.to_path_buf());
        move |out: &Path| replan::replan(&dir, &plan, Some(out)).map(|_| ())
    };
    // A segment the run does not have.
    let mut unknown = plan_b();
    unknown[1].name = "chin".into();
    let p = tmp.join("unknown.toml");
    write_plan(&p, &unknown);
    refused(go(&a.out_dir, &p), &p, "unknown segment");
    // A changed region.
    let mut changed = plan_b();
    changed[0].region = facesim::case::Region::Sphere {
        center: [0.0; 3],
        radius: 50.0,
    };
    let p = tmp.join("region.toml");
    write_plan(&p, &changed);
    refused(go(&a.out_dir, &p), &p, "changed region");
    // Not a plan file.
    let p = tmp.join("junk.toml");
    std::fs::write(&p, "[[osteotomy]]\nname = 3\n").unwrap();
    refused(go(&a.out_dir, &p), &p, "junk plan");
    // Basis files: missing, truncated, another format version, another facesim version, not a
    // basis at all.
    let good = tmp.join("good.toml");
    write_plan(&good, &plan_b());
    let bytes = std::fs::read(a.out_dir.join(file::FILE_NAME)).unwrap();
    let broken = |name: &str, b: Option<Vec<u8>>| {
        let d = tmp.join(name);
        std::fs::create_dir_all(&d).unwrap();
        if let Some(b) = b {
            std::fs::write(d.join(file::FILE_NAME), b).unwrap();
        }
        d
    };
    let d = broken("missing", None);
    refused(go(&d, &good), &d.join(file::FILE_NAME), "missing basis");
    let d = broken("truncated", Some(bytes[..bytes.len() - 100].to_vec()));
    refused(go(&d, &good), &d.join(file::FILE_NAME), "truncated basis");
    let d = broken("short", Some(bytes[..10].to_vec()));
    refused(go(&d, &good), &d.join(file::FILE_NAME), "cut header");
    let mut v = bytes.clone();
    v[8] = 99;
    let d = broken("format", Some(v));
    refused(go(&d, &good), &d.join(file::FILE_NAME), "format version");
    let mut v = bytes.clone();
    v[16] = b'X'; // the first byte of the facesim version string
    let d = broken("version", Some(v));
    refused(go(&d, &good), &d.join(file::FILE_NAME), "facesim version");
    let mut v = bytes.clone();
    v[0] = b'P';
    let d = broken("magic", Some(v));
    refused(go(&d, &good), &d.join(file::FILE_NAME), "magic");
    let mut v = bytes.clone();
    v.extend_from_slice(&[0; 8]);
    let d = broken("long", Some(v));
    refused(go(&d, &good), &d.join(file::FILE_NAME), "trailing bytes");
    // The sweep refuses the same way.
    let s = tmp.join("bad-sweep.toml");
    std::fs::write(
        &s,
        "[grid]\nsegment = \"chin\"\ntranslate_y = { from = 0, to = -5, steps = 3 }\n",
    )
    .unwrap();
    let dir = a.out_dir.clone();
    refused(
        move |out| sweep::sweep(&dir, &s, out).map(|_| ()),
        &tmp.join("bad-sweep.toml"),
        "sweep with an unknown segment",
    );
}

#[test]
fn a_sweep_writes_one_row_per_plan() {
    let a = basis_run();
    let tmp = common::kept_dir("facesim-sweep");
    let s = tmp.join("sweep.toml");
    std::fs::write(
        &s,
        "[[plan]]\nlabel = \"advance, 5\"\n[[plan.move]]\nsegment = \"mandible\"\ntranslate = [0, -5, 0]\n\n\
         [grid]\nsegment = \"maxilla\"\ntranslate_y = { from = 0, to = -6, steps = 3 }\nrotate_x = { from = 0, to = 4, steps = 2 }\n",
    )
    .unwrap();
    let out = tmp.join("out");
    let rows = sweep::sweep(&a.out_dir, &s, &out).unwrap();
    assert_eq!(rows.len(), 1 + 3 * 2);
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 1 + 7, "{csv}");
    let head: Vec<&str> = lines[0].split(',').collect();
    assert!(head.contains(&"maxilla_translate_y") && head.contains(&"face_p90_mm"));
    assert!(head.contains(&"nose_mean_mm"));
    assert!(lines[1].starts_with("1,\"advance, 5\","));
    // The grid's first plan moves nothing: the face stays exactly.
    assert_eq!(rows[1].face.max, 0.0);
    // Rows follow the grid (last axis fastest): row 3 is translate_y = 0, rotate_x = 4.
    let o = &rows[2].plan.osteotomy[0];
    assert_eq!((o.translate[1], o.rotate_deg[0]), (0.0, 4.0));
    // Each row's statistics are those of the replanned face for that plan.
    for r in &rows {
        assert!(r.face.max >= r.face.p90 && r.face.p90 >= 0.0 && r.face.max >= r.face.mean);
    }
    // The chart is the caller's (crates/facesim-lab sweep_chart): the library draws none.
    assert!(!out.join("sweep.svg").exists());
}

/// A directory holding the basis run's plan basis (and skull) and, when given, `report` as its
/// report.json.
fn run_dir_with_report(name: &str, report: Option<&[u8]>) -> PathBuf {
    let a = basis_run();
    let d = common::kept_dir("facesim-replan-report").join(name);
    std::fs::create_dir_all(&d).unwrap();
    for f in [file::FILE_NAME, "skull_pre.ply"] {
        std::fs::copy(a.out_dir.join(f), d.join(f)).unwrap();
    }
    if let Some(r) = report {
        std::fs::write(d.join("report.json"), r).unwrap();
    }
    d
}

#[test]
fn a_missing_or_corrupt_report_is_refused_by_replan_and_sweep_naming_it() {
    let tmp = common::kept_dir("facesim-replan-report-inputs");
    let plan = tmp.join("plan.toml");
    write_plan(&plan, &plan_b());
    let sweep_file = tmp.join("sweep.toml");
    std::fs::write(
        &sweep_file,
        "[[plan]]\n[[plan.move]]\nsegment = \"mandible\"\ntranslate = [0, -5, 0]\n",
    )
    .unwrap();
    let good = std::fs::read(basis_run().out_dir.join("report.json")).unwrap();
    let cases: [(&str, Option<&[u8]>, &str); 3] = [
        ("missing", None, "not found"),
        ("cut", Some(&good[..good.len() / 2]), "line"),
        ("not-a-report", Some(b"{\"name\": 3}"), "line"),
    ];
    for (name, bytes, says) in cases {
        let d = run_dir_with_report(name, bytes);
        let report = d.join("report.json");
        let (dir, p) = (d.clone(), plan.clone());
        refused(
            move |out| replan::replan(&dir, &p, Some(out)).map(|_| ()),
            &report,
            &format!("replan, {name} report"),
        );
        let (dir, s) = (d.clone(), sweep_file.clone());
        refused(
            move |out| sweep::sweep(&dir, &s, out).map(|_| ()),
            &report,
            &format!("sweep, {name} report"),
        );
        let e = Report::read(&report).unwrap_err().to_string();
        assert!(e.contains(says), "{name}: '{e}' does not say '{says}'");
    }
}

#[test]
fn a_runs_and_a_replans_report_json_read_back_and_written_again_are_the_same_json() {
    let a = basis_run();
    let tmp = common::kept_dir("facesim-replan-roundtrip");
    let b_file = tmp.join("b.toml");
    write_plan(&b_file, &plan_b());
    let r = replan::replan(&a.out_dir, &b_file, Some(&tmp.join("b"))).unwrap();
    for dir in [&a.out_dir, &r.out_dir] {
        let path = dir.join("report.json");
        let typed = Report::read(&path).unwrap();
        assert_eq!(
            serde_json::to_value(&typed).unwrap(),
            report_json(dir),
            "{}",
            path.display()
        );
        // Field order too: written again, the bytes are the file's.
        let again = serde_json::to_string_pretty(&typed).unwrap();
        assert_eq!(
            again.as_bytes(),
            std::fs::read(&path).unwrap(),
            "{}",
            path.display()
        );
    }
}

/// report.json of a run or replan in `dir`.
fn report_json(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap()
}

/// The largest difference between the `post` of each landmark both reports have (and the
/// number compared); every landmark must be present in both or missing in both.
fn landmark_gap(a: &serde_json::Value, b: &serde_json::Value) -> (f64, usize) {
    let (a, b) = (a.as_object().unwrap(), b.as_object().unwrap());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    let mut worst = 0.0f64;
    let mut n = 0;
    for (label, la) in a {
        let pa = la["post"].as_array();
        let pb = b[label]["post"].as_array();
        assert_eq!(pa.is_some(), pb.is_some(), "{label}");
        if let (Some(pa), Some(pb)) = (pa, pb) {
            for (x, y) in pa.iter().zip(pb) {
                worst = worst.max((x.as_f64().unwrap() - y.as_f64().unwrap()).abs());
            }
            n += 1;
        }
    }
    (worst, n)
}

/// The largest difference of mean, p90 and max over the regions present in `b` (each present
/// in `a` with the same vertex count).
fn region_gap(a: &serde_json::Value, b: &serde_json::Value) -> (f64, usize) {
    let mut worst = 0.0f64;
    let mut n = 0;
    for (name, rb) in b.as_object().unwrap() {
        if rb["vertices"].as_u64().unwrap_or(0) == 0 {
            continue;
        }
        let ra = &a[name];
        assert_eq!(ra["vertices"], rb["vertices"], "{name}");
        for k in ["mean", "p90", "max"] {
            worst = worst.max((ra[k].as_f64().unwrap() - rb[k].as_f64().unwrap()).abs());
        }
        n += 1;
    }
    (worst, n)
}

#[test]
fn replanning_carries_the_runs_landmarks_and_regions_as_a_full_run_finds_them() {
    let a = basis_run();
    let tmp = common::kept_dir("facesim-replan-landmarks");
    let b_file = tmp.join("b.toml");
    write_plan(&b_file, &plan_b());
    let r = replan::replan(&a.out_dir, &b_file, Some(&tmp.join("b"))).unwrap();
    let got = report_json(&r.out_dir);
    let full = report_json(&plan_b_run().out_dir);
    let (gap, n) = landmark_gap(&got["landmarks"], &full["landmarks"]);
    println!("replan vs full run: {n} landmarks within {gap:.2e} mm");
    assert!(n >= 8, "too few landmarks compared: {n}");
    assert!(gap < 1e-6, "landmarks {gap} mm apart");
    let (gap, regions) = region_gap(&got["regions"], &full["regions"]);
    assert!(regions >= 3 && gap < 1e-6, "{regions} regions, {gap} mm");
    for (name, m) in full["measurements"].as_object().unwrap() {
        if let Some(after) = m["after"].as_f64() {
            let mine = got["measurements"][name]["after"].as_f64().unwrap();
            assert!((mine - after).abs() < 1e-6, "{name}: {mine} vs {after}");
        }
    }
    // Slicer markups of the carried landmarks, as run writes them.
    for f in ["landmarks_pre.mrk.json", "landmarks_post.mrk.json"] {
        assert!(r.out_dir.join(f).is_file(), "{f}");
    }
}

/// Plan B as the page takes it: moves about the run's pivots (the origin), so the translation
/// absorbs the pivot: R (x − p) + p + t = R x + (t + p − R p).
fn plan_b_for_page() -> serde_json::Value {
    let mut plan = serde_json::Map::new();
    for o in plan_b() {
        let r = facesim::osteotomy::rotation(o.rotate_deg);
        let t: Vec<f64> = (0..3)
            .map(|i| {
                o.translate[i] + o.pivot[i] - (0..3).map(|k| r[i][k] * o.pivot[k]).sum::<f64>()
            })
            .collect();
        plan.insert(
            o.name.clone(),
            serde_json::json!({"translate": t, "rotate_deg": o.rotate_deg}),
        );
    }
    serde_json::Value::Object(plan)
}

#[test]
fn the_runs_page_re_plans_face_landmarks_and_regions_as_a_full_run() {
    let a = basis_run();
    assert!(basis_run_plan().iter().all(|o| o.pivot == [0.0; 3]));
    let page = common::kept_dir("facesim-replan-page").join("report.html");
    std::fs::copy(a.out_dir.join("report.html"), &page).unwrap();
    let r = browser::drive(
        &page,
        &serde_json::json!([plan_b_for_page()]),
        "report-jaws-plan-b.png",
    );
    let full = plan_b_run();
    let face = browser::max_diff(&browser::flat(&r["vertices"][0]), &full.face_post.vertices);
    let json = report_json(&full.out_dir);
    // The page's landmarks() as report.json's: label → {post}.
    let page_landmarks: serde_json::Map<String, serde_json::Value> = json["landmarks"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, _)| {
            let post = r["landmarks"][0].get(k).cloned().unwrap_or_default();
            (k.clone(), serde_json::json!({ "post": post }))
        })
        .collect();
    let (lm, n) = landmark_gap(
        &serde_json::Value::Object(page_landmarks),
        &json["landmarks"],
    );
    let (rg, regions) = region_gap(&r["regions"][0], &json["regions"]);
    println!(
        "page vs full run of plan B: face {face:.2e} mm, {n} landmarks {lm:.2e} mm, {regions} regions {rg:.2e} mm"
    );
    assert!(face < 1e-3, "face {face} mm");
    assert!(n >= 8 && lm < 1e-3, "{n} landmarks, {lm} mm");
    assert!(regions >= 3 && rg < 1e-3, "{regions} regions, {rg} mm");
}

#[test]
fn a_sweep_reports_each_plans_landmarks_and_regions_as_a_full_run() {
    let a = basis_run();
    let tmp = common::kept_dir("facesim-sweep-landmarks");
    let s = tmp.join("sweep.toml");
    let mut text = String::from("[[plan]]\nlabel = \"B\"\n");
    for o in plan_b() {
        text += &format!(
            "[[plan.move]]\nsegment = \"{}\"\ntranslate = {:?}\nrotate_deg = {:?}\npivot = {:?}\n",
            o.name, o.translate, o.rotate_deg, o.pivot
        );
    }
    std::fs::write(&s, text).unwrap();
    let rows = sweep::sweep(&a.out_dir, &s, &tmp.join("out")).unwrap();
    let json = report_json(&plan_b_run().out_dir);
    let row = &rows[0];
    assert!(row.landmarks.len() >= 8, "{:?}", row.landmarks);
    for (label, d) in &row.landmarks {
        let want = json["landmarks"][label]["change_mm"].as_f64().unwrap();
        assert!((d - want).abs() < 1e-6, "{label}: {d} vs {want}");
    }
    for (name, stats) in sweep::REGION_NAMES.iter().zip(&row.regions) {
        let want = &json["regions"][name];
        match stats {
            Some(st) => {
                for (k, v) in [("mean", st.mean), ("p90", st.p90), ("max", st.max)] {
                    let w = want[k].as_f64().unwrap();
                    assert!((v - w).abs() < 1e-6, "{name} {k}: {v} vs {w}");
                }
            }
            None => assert_eq!(want["vertices"].as_u64().unwrap_or(0), 0, "{name}"),
        }
    }
    let csv = std::fs::read_to_string(tmp.join("out/sweep.csv")).unwrap();
    let head = csv.lines().next().unwrap();
    assert!(
        head.contains("Prn_move_mm") && head.contains("nasolabial"),
        "{head}"
    );
}

/// Plan B with the maxilla cut by a closed surface (a segment as Slicer exports it, .stl) and
/// the mandible by a mask (.nii.gz), named relative to the plan's folder: re-planned from a
/// basis run with the same regions, the face and the skull equal a full run of plan B.
#[test]
fn replanning_with_surface_and_mask_regions_moves_the_skull_as_a_full_run() {
    use facesim::case::Region;
    let dir = common::kept_dir("facesim-replan-files");
    let maxilla = facesim::mesh::Mesh::cuboid([-90.0, -120.0, -24.0], [90.0, -11.0, 3.0]);
    facesim::mesh::stl::write(&maxilla, &dir.join("maxilla.stl"), "SPACE=LPS").unwrap();
    // The mandible's box on a 1 mm grid (its voxels' centres span the box).
    let (min, max) = ([-90.0, -120.0, -110.0], [90.0, -11.0, -26.0]);
    let dims = [0, 1, 2].map(|a| (max[a] - min[a]) as usize + 1);
    let mask = facesim::volume::Volume {
        dims,
        spacing: [1.0; 3],
        origin: min,
        direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        data: vec![1.0; dims[0] * dims[1] * dims[2]],
    };
    facesim::volume::nifti_io::write(&mask, &dir.join("mandible.nii.gz")).unwrap();
    let with_files = |mut plan: Vec<Osteotomy>| {
        plan[0].region = Region::Surface(dir.join("maxilla.stl").into());
        plan[1].region = Region::Mask(dir.join("mandible.nii.gz").into());
        plan
    };
    let plan_a = two_segments([
        ([0.0, -4.0, 0.0], [0.0; 3], [0.0; 3]),
        ([0.0, -5.0, 0.0], [0.0; 3], [0.0; 3]),
    ]);
    let basis = run_plan(with_files(plan_a), "facesim-replan-files-a");
    let full = run_plan(with_files(plan_b()), "facesim-replan-files-b");

    // PLAN.toml as a user writes it beside the files: relative names.
    let mut text = String::new();
    for (o, file) in plan_b()
        .iter()
        .zip(["surface = \"maxilla.stl\"", "mask = \"mandible.nii.gz\""])
    {
        text += &format!(
            "[[osteotomy]]\nname = \"{}\"\nregion = {{ {file} }}\ntranslate = {:?}\nrotate_deg = {:?}\npivot = {:?}\n\n",
            o.name, o.translate, o.rotate_deg, o.pivot
        );
    }
    let plan_file = dir.join("plan_b.toml");
    std::fs::write(&plan_file, text).unwrap();
    let r = replan::replan(&basis.out_dir, &plan_file, Some(&dir.join("replanned"))).unwrap();
    let face = max_distance(&r.face_post, &full.face_post.vertices);
    let skull = facesim::mesh::read_mesh(&r.out_dir.join("skull_post.ply")).unwrap();
    let full_skull = facesim::mesh::read_mesh(&full.out_dir.join("skull_post.ply")).unwrap();
    let bone = max_distance(&skull.vertices, &full_skull.vertices);
    let pre = facesim::mesh::read_mesh(&basis.out_dir.join("skull_pre.ply")).unwrap();
    let moved = max_distance(&skull.vertices, &pre.vertices);
    println!(
        "surface + mask regions: face {face:.2e} mm, skull {bone:.2e} mm (bone moves {moved:.1} mm)"
    );
    assert!(face < 1e-6, "face {face}");
    assert!(bone < 1e-9 && moved > 3.0, "skull {bone}, moved {moved}");
}

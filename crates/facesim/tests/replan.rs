//! The plan basis (docs/plan-basis.md) on the phantom with jaws and the volumetric model: a
//! replanned face equals a full `run` of the same plan (two segments, translation and rotation),
//! the run's own plan comes back, bad plans and bad basis files are refused naming the file with
//! nothing written, and a sweep writes one row per plan.

mod common;

use facesim::case::{Case, Osteotomy, SolveModel};
use facesim::observe::Quiet;
use facesim::phantom::PhantomOptions;
use facesim::phantom_jaws::{self, JawsOptions};
use facesim::pipeline::{self, Outcome};
use facesim::plan::{file, replan, sweep};
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
    pipeline::run_case(case, &common::kept_dir(prefix), &Quiet).unwrap()
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
        .map(|(p, q)| facesim::mesh::norm(facesim::mesh::sub(*p, *q)))
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
    let full = run_plan(plan_b(), "facesim-replan-b");
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
    let svg = std::fs::read_to_string(out.join("sweep.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("face max"));
}

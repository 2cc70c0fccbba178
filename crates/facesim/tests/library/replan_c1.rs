//! The plan basis of the C1 models (docs/design/plan-basis.md, "C1 models"): their linearisation at
//! the pre-operative state. Against full nonlinear solves of the same plans on the phantom, its
//! error shrinks with the square of the move (the basis is the solve's derivative at rest: a
//! wrong derivative would leave an error of first order), it is exact for no move, and a C1 run's
//! basis re-plans end to end, saying it is not exact.

use crate::common;

use facesim::case::{Case, Osteotomy, SolveModel};
use facesim::commands;
use facesim::commands::replan;
use facesim::observe::Quiet;
use facesim::pipeline::{self, Recorder, Scene, inputs::CaseFiles};
use facesim::plan::{PlanBasis, file};
use facesim_validate::phantom::PhantomOptions;
use std::path::PathBuf;
use std::sync::OnceLock;

/// The phantom case (2 mm voxels, a 4 mm face scan: small, for speed) with the given C1 model.
fn phantom_case(model: SolveModel) -> Case {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    let dir = DIR.get_or_init(|| {
        let d = common::kept_dir("facesim-replan-c1-phantom");
        let opts = PhantomOptions {
            spacing: [2.0; 3],
            scan_step_mm: 4.0,
            ..PhantomOptions::default()
        };
        facesim_validate::phantom::write_case(&d, &opts).unwrap();
        d
    });
    let (mut case, _) = Case::load(&dir.join("case.toml")).unwrap();
    case.solve.model = model;
    case
}

/// The face (face_pre's vertices, moved) of a full solve of `plan`, and the plan basis.
fn solve(scene: &mut Scene, plan: Vec<Osteotomy>) -> (Vec<[f64; 3]>, Option<PlanBasis>) {
    scene.case.osteotomy = plan;
    scene.model.plan = facesim::osteotomy::Plan::new(&scene.case.osteotomy);
    let case = scene.case.clone();
    let mut rec = Recorder::new(&Quiet);
    let p = facesim::model::predict(scene, &case, &CaseFiles::in_memory(&case), &mut rec).unwrap();
    (p.face_post.vertices, p.basis)
}

fn max_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| facesim::vec3::norm(facesim::vec3::sub(*p, *q)))
        .fold(0.0, f64::max)
}

/// The phantom's segment moved by `h` × (forward 1 mm, up 0.3 mm; 0.5° about x, 0.25° about z),
/// about a pivot at the chin: translation and rotation entries of M all take part.
fn scaled_move(base: &Osteotomy, h: f64) -> Vec<Osteotomy> {
    vec![Osteotomy {
        translate: [0.0, -h, 0.3 * h],
        rotate_deg: [0.5 * h, 0.0, 0.25 * h],
        pivot: [0.0, -70.0, -60.0],
        ..base.clone()
    }]
}

/// Observed orders of the linearisation's error over moves h = 0.5, 1, 2 of `model`, and
/// the checks at no move.
fn orders(model: SolveModel, coarse_triangles: usize) -> Vec<f64> {
    let mut case = phantom_case(model);
    case.solve.coarse_triangles = coarse_triangles;
    let mut scene = pipeline::prepare_case(&case, &Quiet).unwrap();
    assert_eq!(scene.face.fine.is_some(), coarse_triangles > 0);
    let pre = scene
        .face
        .fine
        .as_ref()
        .unwrap_or(&scene.face.skin)
        .vertices
        .clone();
    let base = case.osteotomy[0].clone();
    let (_, basis) = solve(&mut scene, case.osteotomy.clone());
    let basis = basis.expect("a C1 run builds a plan basis");
    assert!(!basis.exact);
    assert_eq!(
        basis.model,
        match model {
            SolveModel::Koch1996 => "koch1996-linearised",
            _ => "c1-linearised",
        }
    );
    // No move: the full solve stays at the pre-operative face, and so does the basis.
    let still = scaled_move(&base, 0.0);
    let (full, _) = solve(&mut scene, still.clone());
    assert!(max_distance(&full, &pre) < 1e-9);
    let err0 = max_distance(&basis.predict(&still).unwrap(), &full);
    assert!(err0 < 1e-9, "{model:?}: no move, error {err0:e} mm");
    // Newton's tolerance tight, so the full solves' own error stays far below the
    // linearisation's at the smallest move.
    scene.model.params.tolerance = 1e-11;
    let errors: Vec<(f64, f64)> = [0.5, 1.0, 2.0]
        .iter()
        .map(|&h| {
            let plan = scaled_move(&base, h);
            let (full, _) = solve(&mut scene, plan.clone());
            let moved = max_distance(&full, &pre);
            assert!(
                moved > 0.3 * h,
                "{model:?} h = {h}: the face moves {moved} mm"
            );
            (h, max_distance(&basis.predict(&plan).unwrap(), &full))
        })
        .collect();
    println!("{model:?}: (h, linearisation error mm) {errors:?}");
    errors
        .windows(2)
        .map(|w| (w[1].1 / w[0].1).log2() / (w[1].0 / w[0].0).log2())
        .collect()
}

#[test]
fn the_linearisation_error_is_of_second_order_in_the_move_and_zero_for_no_move() {
    let eq = orders(SolveModel::Equilibrium, 0);
    println!("equilibrium: observed orders {eq:?}");
    assert!(eq.iter().all(|p| (1.8..2.3).contains(p)), "{eq:?}");
    // koch1996: its increments are linear systems, but the spring forces in them are not
    // linear in the plan: the basis is its linearisation too, of second-order error.
    let koch = orders(SolveModel::Koch1996, 0);
    println!("koch1996: observed orders {koch:?}");
    assert!(koch.iter().all(|p| (1.8..2.3).contains(p)), "{koch:?}");
}

#[test]
fn on_a_coarse_skin_the_carried_face_is_linearised_too() {
    // The shell embedding that carries the fine face is not linear in the coarse solve (its
    // offset follows the triangles' normals and areas): the basis takes its derivative.
    let eq = orders(SolveModel::Equilibrium, 1000);
    println!("equilibrium, coarse skin: observed orders {eq:?}");
    assert!(eq.iter().all(|p| (1.8..2.3).contains(p)), "{eq:?}");
}

#[test]
fn a_c1_run_replans_end_to_end_as_a_linear_preview() {
    let case = phantom_case(SolveModel::Equilibrium);
    let out = common::out_dir("facesim-replan-c1");
    let run = commands::run_case(case.clone(), &out, &Quiet).unwrap();
    let report = run.report.plan_basis.as_ref().unwrap();
    assert_eq!(report.model, "c1-linearised");
    assert!(!report.exact);
    assert!(report.warnings.iter().any(|w| w.contains("linear preview")));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["plan_basis"]["exact"], false);
    let stored = file::read(&out.join(file::FILE_NAME)).unwrap();
    // The run's own plan from the stored basis: the error report.json states.
    let own = stored.predict(&case.osteotomy).unwrap();
    let err = max_distance(&own, &run.face_post.vertices);
    assert!(
        (err - report.run_plan_error_mm).abs() < 1e-9 && err > 0.0,
        "{err} vs {}",
        report.run_plan_error_mm
    );
    // A 1 mm advance, re-planned from the run's directory, against a full run of that plan.
    let plan = vec![Osteotomy {
        translate: [0.0, -1.0, 0.0],
        ..case.osteotomy[0].clone()
    }];
    let plan_file = out.join("plan.toml");
    #[derive(serde::Serialize)]
    struct P<'a> {
        osteotomy: &'a [Osteotomy],
    }
    std::fs::write(
        &plan_file,
        toml::to_string(&P { osteotomy: &plan }).unwrap(),
    )
    .unwrap();
    let r = replan::replan(&out, &plan_file, None).unwrap();
    let mut full_case = case;
    full_case.osteotomy = plan;
    let full = commands::run_case(
        full_case,
        &common::out_dir("facesim-replan-c1-full"),
        &Quiet,
    )
    .unwrap();
    let err = max_distance(&r.face_post, &full.face_post.vertices);
    let moved = max_distance(&full.face_post.vertices, &full.skin.vertices);
    println!("1 mm advance: replan vs full run {err:.3e} mm (face moves {moved:.3} mm)");
    assert!(moved > 0.9);
    assert!(err > 1e-6 && err < 0.1 * moved, "{err} mm");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(r.out_dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["replan"]["basis_model"], "c1-linearised");
    assert_eq!(json["replan"]["exact"], false);
    assert!(
        json["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("linear preview"))
    );
}

//! `facesim-lab bench linearisation`: the C1 models' plan basis (their linearisation at the
//! pre-operative state, docs/design/plan-basis.md "C1 models") against full nonlinear solves of the
//! same plans, as a function of the move's size: the first segment translated 1, 2, 5, 10 mm
//! along its planned translation (or −y, forward in LPS, when it has none) and rotated 1, 2, 5°
//! about x (the sagittal plane) about its pivot; the other segments still.

use facesim::case::{Case, Osteotomy, SolveModel};
use facesim::error::{Error, Result};
use facesim::observe::Quiet;
use facesim::pipeline::{self, Recorder, inputs::CaseFiles};
use std::path::Path;

/// One move's row.
pub struct Row {
    pub model: &'static str,
    /// "translate 5 mm", "rotate 2°".
    pub mv: String,
    /// The full solve's largest face displacement (mm).
    pub max_displacement_mm: f64,
    /// Largest and mean distance between the basis's face and the full solve's (mm).
    pub max_error_mm: f64,
    pub mean_error_mm: f64,
}

/// The rows for `case_toml` under each model in `models` (equilibrium, koch1996). A full solve
/// that fails (koch1996 diverges on stiff springs) is reported as a row with NaN errors.
pub fn run(case_toml: &Path, models: &[SolveModel]) -> Result<Vec<Row>> {
    let (case, _) = Case::load(case_toml)?;
    let Some(first) = case.osteotomy.first().cloned() else {
        return Err(Error::config(
            "bench linearisation: the case has no [[osteotomy]]",
        ));
    };
    let t = first.translate;
    let tn = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    let dir = if tn > 0.0 {
        t.map(|x| x / tn)
    } else {
        [0.0, -1.0, 0.0]
    };
    let still = |o: &Osteotomy| Osteotomy {
        translate: [0.0; 3],
        rotate_deg: [0.0; 3],
        ..o.clone()
    };
    let mut moves: Vec<(String, Osteotomy)> = [1.0, 2.0, 5.0, 10.0]
        .map(|d| {
            let mut o = still(&first);
            o.translate = dir.map(|x| x * d);
            (format!("translate {d} mm"), o)
        })
        .to_vec();
    for a in [1.0, 2.0, 5.0] {
        let mut o = still(&first);
        o.rotate_deg = [a, 0.0, 0.0];
        moves.push((format!("rotate {a}° about x"), o));
    }
    let mut rows = Vec::new();
    for &model in models {
        let name = model.name();
        let mut c = case.clone();
        c.solve.model = model;
        let mut scene = pipeline::prepare_case(&c, &Quiet)?;
        let files = CaseFiles::in_memory(&c);
        let with_plan = |scene: &mut pipeline::Scene, plan: Vec<Osteotomy>| {
            scene.case.osteotomy = plan;
            scene.model.plan = facesim::osteotomy::Plan::new(&scene.case.osteotomy);
            let mut rec = Recorder::new(&Quiet);
            let case = scene.case.clone();
            facesim::model::predict(scene, &case, &files, &mut rec)
        };
        // The basis does not depend on the plan (the linearisation at rest): build it once.
        let basis = with_plan(&mut scene, case.osteotomy.clone())?
            .basis
            .ok_or_else(|| Error::config("bench linearisation: the run built no plan basis"))?;
        for (label, o) in &moves {
            let mut plan: Vec<Osteotomy> = case.osteotomy.iter().map(still).collect();
            plan[0] = o.clone();
            let row = match with_plan(&mut scene, plan.clone()) {
                Ok(p) => {
                    let lin = basis.predict(&plan)?;
                    let err: Vec<f64> = lin
                        .iter()
                        .zip(&p.face_post.vertices)
                        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*a, *b)))
                        .collect();
                    Row {
                        model: name,
                        mv: label.clone(),
                        max_displacement_mm: p
                            .skin
                            .vertices
                            .iter()
                            .zip(&p.face_post.vertices)
                            .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*a, *b)))
                            .fold(0.0, f64::max),
                        max_error_mm: err.iter().cloned().fold(0.0, f64::max),
                        mean_error_mm: err.iter().sum::<f64>() / err.len().max(1) as f64,
                    }
                }
                Err(_) => Row {
                    model: name,
                    mv: label.clone(),
                    max_displacement_mm: f64::NAN,
                    max_error_mm: f64::NAN,
                    mean_error_mm: f64::NAN,
                },
            };
            rows.push(row);
        }
    }
    Ok(rows)
}

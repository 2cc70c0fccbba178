//! `facesim replan OUT_DIR PLAN.toml [--out DIR]` (docs/case.md): the face outputs of `run` for
//! a new plan, from the plan basis a run stored in OUT_DIR, without re-solving.

use super::outputs;
use crate::case::{Osteotomy, Region};
use crate::error::{Error, Result};
use crate::mesh::{self, Mesh};
use crate::plan::{PlanBasis, file};
use crate::report::{self, ReplanReport, Report};
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PlanFile {
    #[serde(default)]
    osteotomy: Vec<Osteotomy>,
}

/// The `[[osteotomy]]` list of a PLAN.toml (case.toml's form; nothing else in the file).
pub fn read_plan(path: &Path) -> Result<Vec<Osteotomy>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::input(path, e))?;
    plan_from_text(&text, path)
}

/// The `[[osteotomy]]` list of PLAN.toml text as if read from `path` (relative file names in it
/// resolve against `path`'s directory; errors name `path`).
pub fn plan_from_text(text: &str, path: &Path) -> Result<Vec<Osteotomy>> {
    let mut table: toml::Table = toml::from_str(text).map_err(|e| Error::input(path, e))?;
    let dir = path.parent().unwrap_or(Path::new(""));
    crate::slicer::resolve_plan_files(&mut table, dir, path)?;
    let mut plan: PlanFile = toml::Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| Error::input(path, e.message()))?;
    // Mask and surface files, like case.toml's, are relative to the file that names them.
    for o in &mut plan.osteotomy {
        let p = match &mut o.region {
            Region::Mask(m) => &mut m.path,
            Region::Surface(s) => &mut s.path,
            _ => continue,
        };
        if p.is_relative() {
            *p = dir.join(&*p);
        }
    }
    Ok(plan.osteotomy)
}

/// The basis's prediction for `plan`, a bad plan named as `plan_file`'s error.
pub(crate) fn predict_plan(
    basis: &PlanBasis,
    plan: &[Osteotomy],
    plan_file: &Path,
) -> Result<Vec<[f64; 3]>> {
    basis.predict(plan).map_err(|e| match e {
        Error::Config(msg) => Error::input(plan_file, msg),
        other => other,
    })
}

/// What `replan` wrote.
pub struct Replanned {
    pub out_dir: PathBuf,
    pub face_post: Vec<[f64; 3]>,
    pub report: Report,
}

/// Read the basis in `run_dir`, predict `plan_file`'s plan and write face_post.obj/.ply,
/// face_displacement.ply, displacement.csv, skull_post.ply (when the run's skull_pre.ply is
/// there), the run's landmarks carried with the new plan
/// (landmarks_pre/post.mrk.json; report.json `landmarks`, `measurements`, `regions`) and
/// report.json into `dest` (default `run_dir/replan`).
/// Everything is read and computed before the first file is written.
pub fn replan(run_dir: &Path, plan_file: &Path, dest: Option<&Path>) -> Result<Replanned> {
    let basis = file::read(&run_dir.join(file::FILE_NAME))?;
    let plan = read_plan(plan_file)?;
    replan_with(run_dir, &basis, &plan, plan_file, dest)
}

/// [`replan`] for a plan already read (`plan_file` names it in errors and the report) and the
/// run's basis already read from `run_dir`. The run's report.json must be there (its name, case
/// and landmarks carry over): missing or unreadable, it is an error naming it.
pub fn replan_with(
    run_dir: &Path,
    basis: &PlanBasis,
    plan: &[Osteotomy],
    plan_file: &Path,
    dest: Option<&Path>,
) -> Result<Replanned> {
    let face_post = predict_plan(basis, plan, plan_file)?;
    let out_dir = dest
        .map(Path::to_path_buf)
        .unwrap_or_else(|| run_dir.join("replan"));
    let skin = Mesh::new(basis.face_pre.clone(), basis.triangles.clone());
    let mut post = skin.clone();
    post.vertices = face_post.clone();
    let skull_pre = run_dir.join("skull_pre.ply");
    let skull_post = if skull_pre.exists() {
        // The bone each segment moves: mask and surface regions read as the run read them.
        let mut plan = plan.to_vec();
        crate::pipeline::inputs::read_region_files(plan.iter_mut().map(|o| &mut o.region))?;
        let mut s = mesh::read_mesh(&skull_pre)?;
        s.vertices = crate::osteotomy::Plan::new(&plan).apply(&s.vertices, 1.0).0;
        Some(s)
    } else {
        None
    };
    let dist = outputs::displacement(&skin, &post);
    let run_report = Report::read(&run_dir.join("report.json"))?;
    // The run's landmarks (as it found them, not detected again) carried with the new plan.
    let analysis = run_report.located_landmarks().map(|(frame, lms)| {
        crate::landmarks::analyse_located(
            &skin,
            &post,
            frame,
            lms,
            &crate::osteotomy::Plan::new(plan),
        )
    });
    let mut warnings = basis.warnings.clone();
    if skull_post.is_none() {
        warnings.push("skull_post.ply not written (no skull_pre.ply in the run's outputs)".into());
    }
    // Tissue lifted off the bone is a contact state the run's plan chose: the basis is exact
    // for plans in that state, and one that lifts off other tissue needs a full run.
    if let Some(lifted) = run_report
        .tet
        .as_ref()
        .map(|t| t.lifted_off)
        .filter(|n| *n > 0)
    {
        warnings.push(format!(
            "the run lifted {lifted} tissue nodes off the bone at the saw lines: the basis is exact for plans that lift off the same tissue; check a plan far from the run's with a full `facesim run`"
        ));
    }
    let replanned = ReplanReport {
        from: run_dir.display().to_string(),
        plan: plan_file.display().to_string(),
        basis_model: basis.model.clone(),
        exact: basis.exact,
        osteotomy: plan.to_vec(),
    };
    let report = report::assemble(
        run_report.name,
        run_report.case,
        None,
        &dist,
        analysis.as_ref(),
        Some(replanned),
        warnings,
    );
    // The writes, as one unit swapped in for `out_dir` (`output::RunDir`).
    let unit = crate::output::RunDir::create(&out_dir)?;
    let o = unit.path();
    mesh::write_mesh(&post, &o.join("face_post.obj"))?;
    mesh::write_mesh(&post, &o.join("face_post.ply"))?;
    mesh::write_mesh(
        &outputs::coloured_face(&post, &dist),
        &o.join("face_displacement.ply"),
    )?;
    outputs::displacement_csv(&o.join("displacement.csv"), &skin, &post, &dist)?;
    if let Some(s) = &skull_post {
        mesh::write_mesh(s, &o.join("skull_post.ply"))?;
    }
    if let Some(a) = &analysis {
        crate::landmarks::markups::write_pre_post(o, &a.carried)?;
    }
    outputs::write_report(o, &report)?;
    Ok(Replanned {
        out_dir: unit.commit()?,
        face_post,
        report,
    })
}

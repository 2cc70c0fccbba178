//! `facesim replan OUT_DIR PLAN.toml [--out DIR]` (docs/reference/case.md): the face outputs of `run` for
//! a new plan, from the plan basis a run stored in OUT_DIR, without re-solving; or, with `[tet]`
//! tissue parameters in PLAN.toml, for new tissues at the run's plan from the reduced model it
//! stored (docs/design/reduced.md "Re-solving from the stored model").

use super::outputs;
use crate::case::uncertainty::Method;
use crate::case::{Case, Osteotomy, Region, SolveModel, TissueElastic, Uncertainty};
use crate::error::{Error, Result};
use crate::mesh::{self, Mesh};
use crate::model::reduced::file::{self as stored, StoredReduced};
use crate::plan::{PlanBasis, file};
use crate::report::{self, ReplanReport, Report, TissueReplan};
use serde::Deserialize;
use std::borrow::Cow;
use std::path::{Path, PathBuf};

/// A PLAN.toml: the `[[osteotomy]]` list (case.toml's form) and, optionally, new tissue
/// parameters (`[tet]`: `sliding` and `[tet.skin]` … with `youngs_kpa` / `poisson`, any subset)
/// and a band (`[uncertainty]`, case.toml's form) from the run's stored reduced model.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NewPlan {
    #[serde(default)]
    pub osteotomy: Vec<Osteotomy>,
    /// `[[surgery]]` entries (docs/guide/planning.md): read in the run's clinical frame, about its
    /// landmarks, over the segments the run cut; they lead the plan, as in a run.
    #[serde(default)]
    pub surgery: Vec<crate::case::Surgery>,
    pub tet: Option<TissueChange>,
    pub uncertainty: Option<Uncertainty>,
}

/// PLAN.toml's `[tet]`: what changes from the run's tissue parameters.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TissueChange {
    pub sliding: Option<bool>,
    pub skin: Option<MaterialChange>,
    pub muscle: Option<MaterialChange>,
    pub fat_dark: Option<MaterialChange>,
    pub fat_bright: Option<MaterialChange>,
}

#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialChange {
    pub youngs_kpa: Option<f64>,
    pub poisson: Option<f64>,
}

impl TissueChange {
    /// `run`'s materials (`Tet::tissues` order) and sliding with these changes.
    pub fn apply(&self, run: [TissueElastic; 4], sliding: bool) -> ([TissueElastic; 4], bool) {
        let mut t = run;
        for (m, c) in t
            .iter_mut()
            .zip([&self.skin, &self.muscle, &self.fat_dark, &self.fat_bright])
        {
            if let Some(c) = c {
                m.youngs_kpa = c.youngs_kpa.unwrap_or(m.youngs_kpa);
                m.poisson = c.poisson.unwrap_or(m.poisson);
            }
        }
        (t, self.sliding.unwrap_or(sliding))
    }
}

/// PLAN.toml's `[[surgery]]` entries as osteotomies over the run's segments, read in the run's
/// clinical frame about the landmarks it found (report.json `clinical_frame` and `plan`),
/// followed by its `[[osteotomy]]` entries.
fn surgery_plan(
    run_dir: &Path,
    basis: &PlanBasis,
    new: &NewPlan,
    plan_file: &Path,
) -> Result<Vec<Osteotomy>> {
    let report = Report::read(&run_dir.join("report.json"))?;
    let (Some(frame), Some(found)) = (&report.clinical_frame, &report.plan) else {
        return Err(Error::input(
            plan_file,
            "[[surgery]]: the run's report.json has no clinical frame or plan (a run of a CT without a face, or an older facesim); use [[osteotomy]] or run the case again",
        ));
    };
    let landmarks: Vec<crate::landmarks::Landmark> = found
        .landmarks
        .0
        .iter()
        .map(|(label, m)| crate::landmarks::Landmark {
            label: label.clone(),
            kind: crate::landmarks::Kind::Bone,
            position: m.pre,
            source: crate::landmarks::Source::Detected,
            missing: m.missing.clone(),
        })
        .collect();
    let moves = crate::anatomy::surgery::moves_of(
        &new.surgery,
        &crate::anatomy::cuts::Found {
            landmarks: &landmarks,
        },
        &frame.frame(),
    )
    .map_err(|e| Error::input(plan_file, e))?;
    let mut plan = Vec::new();
    for m in &moves {
        let Some(run) = basis.run_plan.iter().find(|o| o.name == m.name) else {
            let names: Vec<&str> = basis.run_plan.iter().map(|o| o.name.as_str()).collect();
            return Err(Error::input(
                plan_file,
                format!(
                    "[[surgery]] {}: its segment '{}' was not cut by the run (its segments: {}); a new cut needs a new run",
                    m.what,
                    m.name,
                    names.join(", ")
                ),
            ));
        };
        plan.push(m.osteotomy_over(run.region.clone()));
    }
    plan.extend(new.osteotomy.iter().cloned());
    Ok(plan)
}

/// A PLAN.toml.
pub fn read_plan(path: &Path) -> Result<NewPlan> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::input(path, e))?;
    plan_from_text(&text, path)
}

/// PLAN.toml text as if read from `path` (relative file names in it resolve against `path`'s
/// directory; errors name `path`).
pub fn plan_from_text(text: &str, path: &Path) -> Result<NewPlan> {
    let mut table: toml::Table = toml::from_str(text).map_err(|e| Error::input(path, e))?;
    let dir = path.parent().unwrap_or(Path::new(""));
    crate::slicer::resolve_plan_files(&mut table, dir, path)?;
    let mut plan: NewPlan = toml::Value::Table(table)
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
    if let Some(t) = &plan.tet {
        let bad = [&t.skin, &t.muscle, &t.fat_dark, &t.fat_bright]
            .into_iter()
            .zip(crate::case::Tet::TISSUES)
            .find_map(|(m, name)| {
                let m = (*m)?;
                if m.youngs_kpa.is_some_and(|e| !(e > 0.0 && e.is_finite())) {
                    Some(format!("[tet.{name}] youngs_kpa must be positive"))
                } else if m.poisson.is_some_and(|nu| !(0.0..0.5).contains(&nu)) {
                    Some(format!("[tet.{name}] poisson must be in [0, 0.5)"))
                } else {
                    None
                }
            });
        if let Some(msg) = bad {
            return Err(Error::input(path, msg));
        }
    }
    if let Some(u) = &plan.uncertainty {
        if u.method == Method::Full {
            return Err(Error::input(
                path,
                "[uncertainty] method = \"full\": replan samples the run's stored reduced model; full solves need `facesim run`",
            ));
        }
        u.validate(SolveModel::Tet, true, path)?;
    }
    Ok(plan)
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

/// The face for PLAN.toml's tissue change at the run's plan, from the run's reduced_model.bin,
/// and what report.json says of it. A θ outside the trained box or another plan is refused: it
/// needs a full run.
fn tissue_face(
    models: &StoredReduced,
    basis: &PlanBasis,
    change: &TissueChange,
    plan_file: &Path,
) -> Result<(Vec<[f64; 3]>, TissueReplan)> {
    let (tissues, sliding) = change.apply(models.tissues, models.sliding);
    let f = models.face(&tissues, sliding).map_err(|e| {
        Error::input(
            plan_file,
            format!("{e}: not answered by the reduced model (no extrapolation); run the case with these values instead"),
        )
    })?;
    let face = crate::vec3::displaced(&basis.face_pre, &f.displacement);
    let named = |i: usize| crate::case::Tet::TISSUES[i].to_string();
    Ok((
        face,
        TissueReplan {
            materials: (0..4).map(|i| (named(i), tissues[i])).collect(),
            sliding,
            bound_mm: f.bound_mm,
            relative_energy_bound: f.relative_energy_bound,
        },
    ))
}

/// The run's stored reduced models, for PLAN.toml's `[tet]` or `[uncertainty]` (`what`): they
/// are the run's plan's, so another plan is refused.
fn stored_at_run_plan(
    run_dir: &Path,
    basis: &PlanBasis,
    plan: &NewPlan,
    plan_file: &Path,
    what: &str,
) -> Result<StoredReduced> {
    let same = |a: &[Osteotomy], b: &[Osteotomy]| {
        serde_json::to_value(a)
            .ok()
            .is_some_and(|x| Some(x) == serde_json::to_value(b).ok())
    };
    if !plan.osteotomy.is_empty() && !same(&plan.osteotomy, &basis.run_plan) {
        return Err(Error::input(
            plan_file,
            format!(
                "{what} is answered at the run's plan only (the reduced model was built for it): leave out [[osteotomy]] or give the run's plan unchanged; with a new plan it needs `facesim run`"
            ),
        ));
    }
    stored::read(&run_dir.join(stored::FILE_NAME), &basis.face_pre)
}

/// The band of `uncertainty` (PLAN.toml's) about the tissues the face `post` is at (the run's,
/// or `change`'s), sampled on the stored reduced models with the run's landmarks; a sample
/// outside the trained box is refused naming `plan_file`.
fn stored_band(
    models: &StoredReduced,
    (change, uncertainty): (Option<&TissueChange>, &Uncertainty),
    run_report: &Report,
    (skin, post): (&Mesh, &Mesh),
    plan: &crate::osteotomy::Plan,
    plan_file: &Path,
) -> Result<crate::uncertainty::Sampled> {
    let (tissues, sliding) = change.map_or((models.tissues, models.sliding), |c| {
        c.apply(models.tissues, models.sliding)
    });
    let nominal = crate::uncertainty::Nominal {
        skin,
        face_post: &post.vertices,
        moves: post.vertices != skin.vertices,
        sliding_matters: models.sliding_matters,
        // The stored models answer every sample: no full solve.
        solves_at_once: 1,
    };
    let mut case: Case = run_report.parameters.clone().ok_or_else(|| {
        Error::input(
            plan_file,
            "[uncertainty]: the run's report.json has no parameters (written by an older facesim); run the case again",
        )
    })?;
    for (m, t) in case.tet.tissues_mut().into_iter().zip(tissues) {
        *m = t;
    }
    case.tet.sliding = sliding;
    case.uncertainty = uncertainty.clone();
    // The run's order: the stored models bound the soft landmarks in it.
    let (frame, lms) = run_report.located_in_run_order().ok_or_else(|| {
        Error::input(
            plan_file,
            "[uncertainty]: the run found no landmarks, which the band is measured at",
        )
    })?;
    let analysis = crate::landmarks::analyse_located(skin, post, frame, lms, plan);
    crate::uncertainty::reduced::sample_stored(&nominal, models, &analysis, &case, &crate::observe::Quiet)
        .map_err(|e| match e {
            Error::Config(msg) => Error::input(
                plan_file,
                format!("[uncertainty]: {msg} (the stored model answers inside the box the run trained it on, its own [uncertainty] box; a wider box needs `facesim run`)"),
            ),
            other => other,
        })
}

/// [`replan`] for a plan already read (`plan_file` names it in errors and the report) and the
/// run's basis already read from `run_dir`. The run's report.json must be there (its name, case
/// and landmarks carry over): missing or unreadable, it is an error naming it.
pub fn replan_with(
    run_dir: &Path,
    basis: &PlanBasis,
    new: &NewPlan,
    plan_file: &Path,
    dest: Option<&Path>,
) -> Result<Replanned> {
    let new = with_surgeries(run_dir, basis, new, plan_file)?;
    let new: &NewPlan = &new;
    let wants_band = new.uncertainty.as_ref().is_some_and(|u| u.samples > 0);
    let what = if new.tet.is_some() {
        "[tet]"
    } else {
        "[uncertainty]"
    };
    let models = (new.tet.is_some() || wants_band)
        .then(|| stored_at_run_plan(run_dir, basis, new, plan_file, what))
        .transpose()?;
    let NewFace {
        face_post,
        tissue,
        plan,
    } = new_face(basis, new, models.as_ref(), plan_file)?;
    let plan = plan.as_slice();
    let out_dir = dest
        .map(Path::to_path_buf)
        .unwrap_or_else(|| run_dir.join("replan"));
    let skin = Mesh::new(basis.face_pre.clone(), basis.triangles.clone());
    let mut post = skin.clone();
    post.vertices = face_post.clone();
    let skull_post = skull_post(run_dir, plan)?;
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
    let warnings = replan_warnings(basis, &run_report, skull_post.is_some());
    // The band before any file is written (a sample outside the trained box is refused).
    let band = match (&new.uncertainty, &models) {
        (Some(u), Some(m)) if wants_band => Some(stored_band(
            m,
            (new.tet.as_ref(), u),
            &run_report,
            (&skin, &post),
            &crate::osteotomy::Plan::new(plan),
            plan_file,
        )?),
        _ => None,
    };
    let replanned = ReplanReport {
        from: run_dir.display().to_string(),
        plan: plan_file.display().to_string(),
        basis_model: basis.model.clone(),
        exact: basis.exact,
        osteotomy: plan.to_vec(),
        tissue,
    };
    let mut report = report::assemble(
        run_report.name,
        run_report.case,
        None,
        &dist,
        analysis.as_ref(),
        Some(replanned),
        warnings,
    );
    report.uncertainty = band.as_ref().map(|b| b.report.clone());
    let out_dir = write_replan(
        &out_dir,
        &ReplanFiles {
            skin: &skin,
            post: &post,
            dist: &dist,
            skull_post: skull_post.as_ref(),
            analysis: analysis.as_ref(),
            band: band.as_ref(),
            report: &report,
        },
    )?;
    Ok(Replanned {
        out_dir,
        face_post,
        report,
    })
}

/// PLAN.toml with its `[[surgery]]` entries turned into osteotomies over the run's segments,
/// leading its `[[osteotomy]]` entries (`surgery_plan`); as it is without any.
fn with_surgeries<'a>(
    run_dir: &Path,
    basis: &PlanBasis,
    new: &'a NewPlan,
    plan_file: &Path,
) -> Result<Cow<'a, NewPlan>> {
    if new.surgery.is_empty() {
        return Ok(Cow::Borrowed(new));
    }
    Ok(Cow::Owned(NewPlan {
        osteotomy: surgery_plan(run_dir, basis, new, plan_file)?,
        surgery: Vec::new(),
        ..new.clone()
    }))
}

/// The replanned face, what report.json says of a tissue change, and the plan it is at.
struct NewFace {
    face_post: Vec<[f64; 3]>,
    tissue: Option<TissueReplan>,
    plan: Vec<Osteotomy>,
}

/// The face for PLAN.toml `new`: with `models` (the run's stored reduced models, read for
/// `[tet]` or a band) at the run's plan, for `[tet]`'s tissues from them, else from the basis;
/// without, the basis's prediction for its `[[osteotomy]]` plan.
fn new_face(
    basis: &PlanBasis,
    new: &NewPlan,
    models: Option<&StoredReduced>,
    plan_file: &Path,
) -> Result<NewFace> {
    let (face_post, tissue, plan) = match (&new.tet, models) {
        (Some(change), Some(models)) => {
            let (face, t) = tissue_face(models, basis, change, plan_file)?;
            (face, Some(t), basis.run_plan.clone())
        }
        (None, Some(_)) => (
            predict_plan(basis, &basis.run_plan, plan_file)?,
            None,
            basis.run_plan.clone(),
        ),
        (_, None) => (
            predict_plan(basis, &new.osteotomy, plan_file)?,
            None,
            new.osteotomy.clone(),
        ),
    };
    Ok(NewFace {
        face_post,
        tissue,
        plan,
    })
}

/// The run's skull_pre.ply moved by `plan`; None when the run wrote no skull_pre.ply.
fn skull_post(run_dir: &Path, plan: &[Osteotomy]) -> Result<Option<Mesh>> {
    let skull_pre = run_dir.join("skull_pre.ply");
    if !skull_pre.exists() {
        return Ok(None);
    }
    // The bone each segment moves: mask and surface regions read as the run read them, the
    // segments the run cut from its own output.
    let mut plan = plan.to_vec();
    for o in &mut plan {
        if let Region::Mask(m) = &mut o.region
            && m.path.is_relative()
            && m.path.to_string_lossy().starts_with("segment_")
            && run_dir.join(&m.path).is_file()
        {
            m.path = run_dir.join(&m.path);
            m.found = true;
        }
    }
    crate::pipeline::inputs::read_region_files(plan.iter_mut().map(|o| &mut o.region))?;
    let mut s = mesh::read_mesh(&skull_pre)?;
    s.vertices = crate::osteotomy::Plan::new(&plan).apply(&s.vertices, 1.0).0;
    Ok(Some(s))
}

/// The replan's warnings: the basis's, a skull not written (`skull_written` false), and the
/// run's tissue states the basis is exact for only.
fn replan_warnings(basis: &PlanBasis, run_report: &Report, skull_written: bool) -> Vec<String> {
    let mut warnings = basis.warnings.clone();
    if !skull_written {
        warnings.push("skull_post.ply not written (no skull_pre.ply in the run's outputs)".into());
    }
    // Tissue lifted off the bone, or torn in the gap, is a state the run's plan chose: the
    // basis is exact for plans in that state, and one that changes it needs a full run.
    if let Some(t) = &run_report.tet {
        if t.lifted_off > 0 {
            warnings.push(format!(
                "the run lifted {} tissue nodes off the bone ({} of them raised by the approach, where the bone pulled it): the basis is exact for plans that lift off the same tissue; check a plan far from the run's with a full `facesim run`",
                t.lifted_off, t.lifted_in_tension
            ));
        }
        if t.torn_elements > 0 {
            warnings.push(format!(
                "the run's move tore {} tetrahedra of gap tissue ([tet] tear_gap): the basis is exact for plans that tear the same tissue; a plan that would invert other tissue needs a full `facesim run`",
                t.torn_elements
            ));
        }
    }
    warnings
}

/// What a replan writes.
struct ReplanFiles<'a> {
    skin: &'a Mesh,
    post: &'a Mesh,
    /// Per face vertex, its displacement's length (mm).
    dist: &'a [f64],
    skull_post: Option<&'a Mesh>,
    analysis: Option<&'a crate::landmarks::Analysis>,
    band: Option<&'a crate::uncertainty::Sampled>,
    report: &'a Report,
}

/// Write `files` into `out_dir`, as one unit swapped in for it (`output::RunDir`); the
/// directory they are in.
fn write_replan(out_dir: &Path, files: &ReplanFiles) -> Result<PathBuf> {
    let ReplanFiles {
        skin,
        post,
        dist,
        skull_post,
        analysis,
        band,
        report,
    } = *files;
    // The writes, as one unit swapped in for `out_dir` (`output::RunDir`).
    let unit = crate::output::RunDir::create(out_dir)?;
    let o = unit.path();
    mesh::write_mesh(post, &o.join("face_post.obj"))?;
    mesh::write_mesh(post, &o.join("face_post.ply"))?;
    mesh::write_mesh(
        &outputs::coloured_face(post, dist),
        &o.join("face_displacement.ply"),
    )?;
    outputs::displacement_csv(&o.join("displacement.csv"), skin, post, dist)?;
    if let Some(s) = skull_post {
        mesh::write_mesh(s, &o.join("skull_post.ply"))?;
    }
    if let Some(a) = analysis {
        crate::landmarks::markups::write_pre_post(o, &a.carried)?;
    }
    if let Some(b) = band {
        crate::uncertainty::write_band(o, post, b)?;
    }
    outputs::write_report(o, report)?;
    unit.commit()
}

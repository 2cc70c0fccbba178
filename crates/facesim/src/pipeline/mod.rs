//! The pipeline as typed stages (docs/architecture.md):
//!
//! ```text
//! case.toml ─ inputs::read ─▶ Inputs { case, ct, scan }              (the only file reads)
//!   ct ─ tissues ─▶ Segmentation ─ surfaces::extract ─▶ Surfaces { skin, skull, (u, v) axis }
//!   Surfaces + scan ─ face::place ─▶ Face { skin the model is built on, fine skin if coarsened }
//!   Face + tissues ─ model::build ─▶ Model { springs, plan, rigid skin, solver parameters }
//!   Model ─ predict::predict ─▶ Prediction { face_post, the C1 solution, embedding }
//!   everything ─ outputs::write ─▶ the output directory (the only file writes) and report.json,
//!                                 written as one unit (`output::RunDir`)
//! ```
//!
//! Each stage is a function from typed inputs to typed outputs; progress and per-stage cost go
//! through one [`Recorder`] (the caller's [`Observer`] plus the report's cost table and warnings).
//! `facesim run`, the study (crates/facesim-lab) and the tests call these same functions.

pub mod face;
pub mod inputs;
pub mod model;
pub mod outputs;
pub mod predict;
pub mod surfaces;
pub mod volumetric;

use crate::case::Case;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::meter::Meter;
use crate::observe::Observer;
use crate::report::{Costs, Report, Skipped, Stage};
use crate::segment::Segmentation;
use crate::volume::Volume;
use std::path::{Path, PathBuf};

/// What stages report besides their outputs: progress and cost (to the observer and the cost
/// table), warnings, and the optional stages that did not run.
pub struct Recorder<'a> {
    pub obs: &'a dyn Observer,
    pub costs: Costs,
    pub warnings: Vec<String>,
    pub skipped: Vec<Skipped>,
}

impl<'a> Recorder<'a> {
    pub fn new(obs: &'a dyn Observer) -> Self {
        Recorder {
            obs,
            costs: Costs::default(),
            warnings: Vec::new(),
            skipped: Vec::new(),
        }
    }

    /// Run `f` as `stage`, announced as `what` on the observer, and record its cost.
    pub fn time<T>(
        &mut self,
        stage: Stage,
        what: &str,
        f: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        if !what.is_empty() {
            self.obs.started(what);
        }
        let m = Meter::start(self.obs.heap());
        let r = f()?;
        let c = m.stop();
        self.obs.finished(stage.key(), &c);
        self.costs.0.push((stage, c));
        Ok(r)
    }

    pub fn warn(&mut self, w: impl Into<String>) {
        self.warnings.push(w.into());
    }

    pub fn skip(&mut self, stage: Stage, reason: impl Into<String>) {
        self.skipped.push(Skipped {
            stage: stage.key(),
            reason: reason.into(),
        });
    }
}

/// Tissues from the CT (Koch §2.3; docs/pipeline.md §1).
pub fn tissues(ct: &Volume, case: &Case, rec: &mut Recorder) -> Result<Segmentation> {
    rec.time(Stage::Segment, "segmenting tissues", || {
        crate::segment::segment(ct, &case.tissue, &case.ct.path)
    })
}

/// Everything the models need before any solve: the CT and its tissues, the skin (extracted or
/// the placed scan) and skull, the springs, the plan, the rigid skin and the solver parameters.
/// `run` and the study share it.
pub struct Scene {
    /// The case, its mask regions read.
    pub case: Case,
    pub vol: Volume,
    pub seg: Segmentation,
    pub face: face::Face,
    pub model: model::Model,
}

/// Stages 1–4 on a case whose files are read: tissues, surfaces, face, model.
pub fn prepare(inputs: inputs::Inputs, rec: &mut Recorder) -> Result<Scene> {
    let inputs::Inputs { case, ct, scan } = inputs;
    let seg = tissues(&ct, &case, rec)?;
    rec.warnings.extend(seg.report.warnings.iter().cloned());
    // The cleaned bone field serves the skull surface and the spring tracer.
    let bone_field = seg.bone_field(&ct);
    let surf = surfaces::extract(&ct, &seg, &bone_field, &case, rec)?;
    let face = face::place(surf, scan, &ct, &case, rec)?;
    let model = model::build(&face, &ct, &seg, &bone_field, &case, rec)?;
    drop(bone_field);
    Ok(Scene {
        case,
        vol: ct,
        seg,
        face,
        model,
    })
}

/// Read what an in-memory case names and run stages 1–4 (the study's and tests' entry).
pub fn prepare_case(case: &Case, obs: &dyn Observer) -> Result<Scene> {
    let mut rec = Recorder::new(obs);
    let inputs = inputs::read_case(case.clone(), &mut rec)?;
    prepare(inputs, &mut rec)
}

/// Everything a run produced, kept in memory for callers (tests, the study, bindings).
pub struct Outcome {
    pub report: Report,
    /// The predicted skin, same vertex order as `skin`.
    pub face_post: Mesh,
    pub volume: Volume,
    pub segmentation: Segmentation,
    pub skin: Mesh,
    pub skull: Mesh,
    pub out_dir: PathBuf,
}

/// `facesim run`: read the case, run every stage, write every output into `out` (default
/// `CASE_DIR/out`).
pub fn run(case_path: &Path, out: Option<&Path>, obs: &dyn Observer) -> Result<Outcome> {
    run_with(case_path, out, &toml::Table::new(), obs)
}

/// `run` with `overrides` (`case::overrides_table`, the CLI's `--set`) laid over the case file.
pub fn run_with(
    case_path: &Path,
    out: Option<&Path>,
    overrides: &toml::Table,
    obs: &dyn Observer,
) -> Result<Outcome> {
    let total = Meter::start(obs.heap());
    let mut rec = Recorder::new(obs);
    let (inputs, files) = inputs::read_with(case_path, overrides, &mut rec)?;
    let out_dir = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| files.dir.join("out"));
    finish(inputs, &files, &out_dir, total, rec)
}

/// Run a case built in memory (`Case { ct, ..Case::default() }`; paths absolute or relative to
/// the working directory) and write its outputs into `out_dir`.
pub fn run_case(case: Case, out_dir: &Path, obs: &dyn Observer) -> Result<Outcome> {
    let total = Meter::start(obs.heap());
    let mut rec = Recorder::new(obs);
    let files = inputs::CaseFiles::in_memory(&case);
    let inputs = inputs::read_case(case, &mut rec)?;
    finish(inputs, &files, out_dir, total, rec)
}

/// Run a case parsed from text ([`Case::from_text`]; the Python package's case given as a
/// dict): `case_file` names it in errors, `dir` is its directory; outputs go into `out_dir`.
pub fn run_parsed(
    case: Case,
    case_file: &Path,
    dir: &Path,
    out_dir: &Path,
    obs: &dyn Observer,
) -> Result<Outcome> {
    let total = Meter::start(obs.heap());
    let mut rec = Recorder::new(obs);
    let files = inputs::CaseFiles {
        dir: dir.to_path_buf(),
        case_file: case_file.to_path_buf(),
        ..inputs::CaseFiles::in_memory(&case)
    };
    let inputs = inputs::read_case(case, &mut rec)?;
    finish(inputs, &files, out_dir, total, rec)
}

/// Stages 2–5, the outputs and report.json, for read inputs.
fn finish(
    inputs: inputs::Inputs,
    files: &inputs::CaseFiles,
    out_dir: &Path,
    total: Meter,
    mut rec: Recorder,
) -> Result<Outcome> {
    let obs = rec.obs;
    // The outputs are one unit (docs/case.md "Outputs"): written into `unit.path()` and
    // swapped in for `out_dir` at the end; an error before then leaves `out_dir` as it was.
    let unit = crate::output::RunDir::create(out_dir)?;
    let dir = unit.path();
    let mut report = Report {
        name: inputs.case.name.clone().unwrap_or_else(|| {
            files
                .dir
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default()
        }),
        case: files.dir.display().to_string(),
        facesim_version: env!("CARGO_PKG_VERSION").into(),
        ..Default::default()
    };
    let scene = prepare(inputs, &mut rec)?;
    let case = &scene.case;
    let prediction = predict::predict(&scene, case, files, &mut rec)?;
    let dist = outputs::displacement(&prediction);
    // Landmarks before any file is written: a user landmark off the face is bad input.
    let analysis = rec.time(Stage::Landmarks, "finding landmarks", || {
        crate::landmarks::analyse(
            &prediction.skin,
            &prediction.face_post,
            Some(&scene.face.skull),
            &scene.model.plan,
            &inputs::user_landmarks(case)?,
            &files.case_file,
        )
    })?;
    // The band before any file is written: a failed sample leaves no outputs half-written.
    let band = crate::uncertainty::sample(&scene, &prediction, &analysis, case, &mut rec)?;
    outputs::write(dir, &scene, &prediction, &dist, case, &mut rec)?;
    if let Some(b) = &band {
        crate::uncertainty::write_band(dir, &prediction.face_post, b)?;
    }
    crate::landmarks::markups::write_pre_post(dir, &analysis.carried)?;
    rec.costs.0.push((
        Stage::Total,
        // Stage meters reset the heap high-water mark, so the whole run's peak is the
        // process's resident maximum (counts.max_rss_mb) instead.
        crate::meter::StageCost {
            peak_heap_mb: None,
            ..total.stop()
        },
    ));
    outputs::fill_report(&mut report, &scene, &prediction, &dist, case, rec);
    analysis.fill(&mut report);
    // The page colours the face by the band's width (p95 − p05) on request.
    let band_width: Option<Vec<f64>> = band
        .as_ref()
        .map(|b| b.bands.iter().map(|x| x.p95 - x.p05).collect());
    report.uncertainty = band.map(|b| b.report);
    let page_basis = outputs::page_basis(&prediction, case);
    outputs::write_page(
        dir,
        &scene,
        &prediction,
        &report,
        page_basis,
        &analysis,
        band_width.as_deref(),
    )?;
    outputs::write_report(dir, &report)?;
    let out_dir = unit.commit()?;
    obs.done();
    let Scene { vol, seg, face, .. } = scene;
    Ok(Outcome {
        report,
        face_post: prediction.face_post,
        volume: vol,
        segmentation: seg,
        skin: prediction.skin,
        skull: face.skull,
        out_dir,
    })
}

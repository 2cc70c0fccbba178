//! `facesim run` (docs/reference/case.md): read the case, run the stages (`crate::pipeline`), predict the
//! face with the case's model (`crate::model`), find the landmarks, sample the tissue parameters
//! when asked, and write every output as one unit (`outputs`, `crate::output::RunDir`) with
//! report.json assembled once (`crate::report`).

use super::outputs;
use crate::case::Case;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::meter::Meter;
use crate::observe::Observer;
use crate::pipeline::{Recorder, Scene, Stage, inputs, prepare};
use crate::report::{self, Counts, Report, RunSections};
use crate::segment::Segmentation;
use crate::volume::Volume;
use std::path::{Path, PathBuf};

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
    // The outputs are one unit (docs/reference/case.md "Outputs"): written into `unit.path()` and
    // swapped in for `out_dir` at the end; an error before then leaves `out_dir` as it was.
    let unit = crate::output::RunDir::create(out_dir)?;
    let dir = unit.path();
    let name = run_name(&inputs, files);
    let scene = prepare(inputs, &mut rec)?;
    let case = &scene.case;
    // The discretisation-error estimate's coarse solve needs the scene alone. On a CT of up to
    // BESIDE_MAX_VOXELS it runs beside the run's own solve, whose factorisation is sequential at
    // a head's size (fem/cholesky.rs), so it costs little wall time; on a larger CT it runs
    // after, since its mesher's two whole-volume fields (8 bytes a voxel) would otherwise add to
    // the run's peak (docs/lab/performance.md "Against CalculiX"). Nor beside the 10-node
    // element's: its symbolic analysis (the direct factor's size, 3.8 GB on the real CT) and
    // the coarse 10-node factor together took the real CT's peak to 4.6 GB.
    let coarse_face = || {
        let started = std::time::Instant::now();
        case.tet
            .error_estimate
            .then(|| crate::model::coarse_face(&scene, case))
            .flatten()
            .map(|c| (c, started.elapsed().as_secs_f64()))
    };
    let beside = scene.vol.data.len() <= BESIDE_MAX_VOXELS
        && case.tet.element != crate::case::TetElement::Quadratic;
    let (prediction, coarse) = if beside {
        rayon::join(
            || crate::model::predict(&scene, case, files, &mut rec),
            coarse_face,
        )
    } else {
        let prediction = crate::model::predict(&scene, case, files, &mut rec);
        let coarse = prediction
            .as_ref()
            .is_ok_and(|p| p.solved_by_tet() && case.tet.error_estimate)
            .then(|| {
                rec.obs.started("estimating the discretisation error");
                coarse_face()
            })
            .flatten();
        (prediction, coarse)
    };
    let prediction = prediction?;
    let dist = outputs::displacement(&prediction.skin, &prediction.face_post);
    let mut analysis = locate_landmarks(&scene, &prediction, files, &mut rec)?;
    let (band, reduced) = sample_band(&scene, &prediction, &analysis, &mut rec)?;
    // Stored beside plan_basis.bin (docs/design/reduced.md "The stored model").
    let reduced = reduced.map(|m| crate::model::reduced::file::StoredReduced {
        face_checksum: crate::mesh::checksum(&prediction.skin.vertices),
        tissues: case.tet.tissues(),
        sliding: case.tet.sliding,
        sliding_matters: m.sliding_matters,
        models: m.models,
    });
    let (discretisation, coarse) = discretisation_error(&prediction, coarse, &analysis, &mut rec);
    band_published(
        &scene,
        &prediction,
        &mut analysis,
        band.as_ref(),
        coarse.as_deref(),
    );
    outputs::write(dir, &scene, &prediction, &dist, case, &mut rec)?;
    if let Some(r) = &reduced {
        crate::model::reduced::file::write(&dir.join(crate::model::reduced::file::FILE_NAME), r)?;
    }
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
    // The page colours the face by the band's width (p95 − p05) on request.
    let band_width: Option<Vec<f64>> = band
        .as_ref()
        .map(|b| b.bands.iter().map(|x| x.p95 - x.p05).collect());
    let (sections, warnings) = run_sections(&scene, &prediction, rec, band.map(|b| b.report));
    let mut report = report::assemble(
        name,
        files.dir.display().to_string(),
        Some(sections),
        &dist,
        Some(&analysis),
        None,
        warnings,
    );
    complete_report(&mut report, &scene, &prediction, &analysis, discretisation);
    report.displacement.largest_jump =
        crate::skin_jump::largest(&prediction.skin, &prediction.face_post.vertices);
    // Elements turned inside out make the prediction no valid solution: a reported numerical
    // result (the outputs are written for inspection), not a success, unless asked for.
    let inverted = prediction.inverted_elements();
    let page_basis = outputs::page_basis(&prediction, case);
    outputs::write_page(
        dir,
        &scene,
        &prediction,
        &report,
        page_basis,
        &analysis,
        band_width.as_deref(),
        reduced.as_ref(),
    )?;
    outputs::write_report(dir, &report)?;
    let out_dir = unit.commit()?;
    obs.done();
    if inverted > 0 && !case.tet.accept_inverted {
        report.warnings.iter().for_each(|w| obs.warn(w));
        return Err(inverted_error(inverted, &out_dir));
    }
    Ok(outcome(scene, prediction, report, out_dir))
}

/// The run's name: the case's `name`, else its directory's.
fn run_name(inputs: &inputs::Inputs, files: &inputs::CaseFiles) -> String {
    inputs.case.name.clone().unwrap_or_else(|| {
        files
            .dir
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default()
    })
}

/// The landmarks of the face before and after, and the plan's published ratios.
fn locate_landmarks(
    scene: &Scene,
    prediction: &crate::model::Prediction,
    files: &inputs::CaseFiles,
    rec: &mut Recorder,
) -> Result<crate::landmarks::Analysis> {
    // Landmarks before any file is written: a user landmark off the face is bad input.
    // Located once: the tet model's region may have needed them already.
    let analysis = rec.time(Stage::Landmarks, "finding landmarks", || {
        let (frame, lms) = scene.landmarks_pre(&prediction.skin, &files.case_file)?;
        Ok(crate::landmarks::analyse_located(
            &prediction.skin,
            &prediction.face_post,
            frame,
            lms,
            &scene.model.plan,
        ))
    })?;
    let mut analysis = analysis;
    analysis.clinic = clinic_of(scene, analysis.frame.as_ref(), &analysis.carried);
    Ok(analysis)
}

/// The plan's published ratios as `carried` gives them. A plan in clinical terms: its surgery
/// type from its entries' kinds, its moves in the clinical frame; else read from its segments'
/// names in the head frame (none without one).
fn clinic_of(
    scene: &Scene,
    frame: Option<&crate::landmarks::HeadFrame>,
    carried: &[crate::landmarks::Carried],
) -> Option<crate::landmarks::clinic::Clinic> {
    use crate::landmarks::clinic;
    let segments = scene.model.plan.segments();
    if let Some(a) = scene.anatomy.as_ref().filter(|a| !a.planned.is_empty()) {
        let kinds: Vec<(String, &str)> =
            a.planned.iter().map(|p| (p.name.clone(), p.what)).collect();
        return Some(clinic::against_published_planned(
            segments,
            carried,
            &a.anatomy.frame.frame,
            &kinds,
        ));
    }
    frame.map(|f| clinic::against_published(segments, carried, f))
}

/// The bands of report.json `published_ratios`: each row's ratio on every sampled tissue's face
/// and on the coarse mesh's face, where the run has them.
fn band_published(
    scene: &Scene,
    prediction: &crate::model::Prediction,
    analysis: &mut crate::landmarks::Analysis,
    band: Option<&crate::uncertainty::Sampled>,
    coarse: Option<&[[f64; 3]]>,
) {
    use rayon::prelude::*;
    if analysis.clinic.is_none() || (band.is_none() && coarse.is_none()) {
        return;
    }
    // The run's landmarks with each soft one moved to `at(label)` (the bony ones move with
    // their segments whatever the tissue).
    let carried_at = |at: &dyn Fn(usize, &str) -> Option<[f64; 3]>| {
        let mut c = analysis.carried.clone();
        for (i, l) in c.iter_mut().enumerate() {
            if let (crate::landmarks::Kind::Soft, Some(pre), Some(p)) =
                (l.kind, l.pre, at(i, &l.label))
            {
                l.post = Some(p);
                l.change_mm = Some(crate::vec3::norm(crate::vec3::sub(p, pre)));
            }
        }
        c
    };
    let frame = analysis.frame.as_ref();
    let samples: Vec<crate::landmarks::clinic::Clinic> = band
        .map(|b| {
            let n = b.soft_positions.first().map_or(0, |(_, p)| p.len());
            // Per carried landmark, its column of the samples' positions (looked up once).
            let column: Vec<Option<&Vec<[f64; 3]>>> = analysis
                .carried
                .iter()
                .map(|c| {
                    let (_, p) = b.soft_positions.iter().find(|(l, _)| *l == c.label)?;
                    Some(p)
                })
                .collect();
            (0..n)
                .into_par_iter()
                .filter_map(|s| {
                    let at = |i: usize, _: &str| Some(column[i]?[s]);
                    clinic_of(scene, frame, &carried_at(&at))
                })
                .collect()
        })
        .unwrap_or_default();
    let coarse = coarse.and_then(|face| {
        let at = |i: usize, _: &str| {
            let a = analysis.anchors.get(i).copied().flatten()?;
            Some(a.place(&prediction.skin.triangles, face))
        };
        clinic_of(scene, frame, &carried_at(&at))
    });
    if let Some(c) = analysis.clinic.as_mut() {
        let p05_p95 = |v: &[f64]| {
            let b = crate::uncertainty::Band::of(v);
            [b.p05, b.p95]
        };
        crate::landmarks::clinic::with_bands(c, &samples, coarse.as_ref(), &p05_p95);
    }
}

/// The band of the sampled tissue parameters, and the certified reduced models it was sampled
/// on when the case asks for them; none without `[uncertainty] samples`.
fn sample_band(
    scene: &Scene,
    prediction: &crate::model::Prediction,
    analysis: &crate::landmarks::Analysis,
    rec: &mut Recorder,
) -> Result<(
    Option<crate::uncertainty::Sampled>,
    Option<crate::model::reduced::ReducedModels>,
)> {
    let (obs, case) = (rec.obs, &scene.case);
    // The band before any file is written: a failed sample leaves no outputs half-written.
    if case.uncertainty.samples == 0 {
        return Ok((None, None));
    }
    let nominal = crate::uncertainty::Nominal {
        skin: &prediction.skin,
        face_post: &prediction.face_post.vertices,
        moves: prediction.moves(),
        sliding_matters: prediction.sliding_matters(),
        solves_at_once: prediction.solves_at_once(),
    };
    let resolve = |c: &Case| prediction.resolve(scene, c);
    let (band, reduced) = rec.time(Stage::Uncertainty, "sampling tissue parameters", || {
        // The certified reduced model when the case asks for it (docs/design/reduced.md).
        let progress = |m: &str| obs.started(m);
        let outputs = crate::uncertainty::reduced::landmark_outputs(analysis, &prediction.skin);
        let reduced = if case.uncertainty.reduced(case.reduced_form()) {
            let train = crate::uncertainty::run::training(case);
            prediction
                .reduced(scene, case, &train, &outputs, &progress)
                .transpose()?
        } else {
            None
        };
        let band = match &reduced {
            Some(m) => {
                let solve = |c: &Case| m.solve(c);
                let r = crate::uncertainty::reduced::Reduced {
                    faces: m.models.iter().map(|x| &x.face).collect(),
                    solve: &solve,
                    reports: m.models.iter().map(|x| x.report()).collect(),
                };
                crate::uncertainty::reduced::sample_reduced(&nominal, &r, analysis, case, obs)
            }
            None => crate::uncertainty::sample(&nominal, &resolve, analysis, case, obs),
        }?;
        Ok((band, reduced))
    })?;
    Ok((Some(band), reduced))
}

/// The largest CT (voxels) whose coarse solve runs beside the run's own: its mesher's fields, 0.26
/// GB here, stay below the run's peak (the 106 M-voxel phantom's 0.85 GB raised it 1.75 → 2.57 GB).
const BESIDE_MAX_VOXELS: usize = 32 << 20;

/// The discretisation error: the case again at twice the element size (Richardson), with the
/// coarse mesh's face; none unless `[tet] error_estimate`, a failed coarse solve a warning.
fn discretisation_error(
    prediction: &crate::model::Prediction,
    coarse: Option<(Result<crate::model::CoarseFace>, f64)>,
    analysis: &crate::landmarks::Analysis,
    rec: &mut Recorder,
) -> (
    Option<crate::model::discretisation::DiscretisationError>,
    Option<Vec<[f64; 3]>>,
) {
    if !prediction.solved_by_tet() {
        return (None, None);
    }
    match coarse {
        Some((Ok((size, coarse)), seconds)) => (
            Some(crate::model::discretisation::estimate(
                &prediction.skin.vertices,
                &prediction.face_post.vertices,
                &coarse,
                &analysis.region_of,
                size,
                seconds,
            )),
            Some(coarse),
        ),
        Some((Err(e), _)) => {
            rec.warn(format!(
                "no discretisation-error estimate: the solve at twice the element size failed ({e})"
            ));
            (None, None)
        }
        None => (None, None),
    }
}

/// report.json's clinical frame and plan (with an anatomy), its discretisation error and the
/// neo-Hookean model's difference from the linear one.
fn complete_report(
    report: &mut Report,
    scene: &Scene,
    prediction: &crate::model::Prediction,
    analysis: &crate::landmarks::Analysis,
    discretisation: Option<crate::model::discretisation::DiscretisationError>,
) {
    if let Some(a) = &scene.anatomy {
        report.clinical_frame = Some(crate::anatomy::readback::FrameReport::of(&a.anatomy));
        report.plan = Some(crate::anatomy::readback::plan_report(
            &a.anatomy,
            &a.planned,
            &scene.model.plan,
        ));
    }
    report.discretisation_error = discretisation;
    report.nonlinear_vs_linear = prediction.linear_face().map(|linear| {
        crate::model::discretisation::nonlinear_vs_linear(
            &prediction.skin.vertices,
            &prediction.face_post.vertices,
            linear,
            &analysis.region_of,
        )
    });
}

/// The error of a prediction that turns `inverted` tetrahedra inside out, its outputs in
/// `out_dir`.
fn inverted_error(inverted: usize, out_dir: &Path) -> crate::error::Error {
    crate::error::Error::numerical(
        crate::error::NumericalKind::DegenerateElement,
        format!(
            "the solved displacement turns {inverted} {} inside out: not a valid prediction (the outputs in {} are written for inspection; [tet] accept_inverted = true accepts them)",
            if inverted == 1 {
                "tetrahedron"
            } else {
                "tetrahedra"
            },
            out_dir.display()
        ),
    )
}

/// What the run keeps in memory for its caller.
fn outcome(
    scene: Scene,
    prediction: crate::model::Prediction,
    report: Report,
    out_dir: PathBuf,
) -> Outcome {
    let Scene { vol, seg, face, .. } = scene;
    Outcome {
        report,
        face_post: prediction.face_post,
        volume: vol,
        segmentation: seg,
        skin: prediction.skin,
        skull: face.skull,
        out_dir,
    }
}

/// The report sections of a run's stages, and its warnings (the stages', then the dropped
/// pieces of the segmentation, then the plan basis's).
fn run_sections(
    scene: &Scene,
    p: &crate::model::Prediction,
    rec: Recorder,
    uncertainty: Option<crate::uncertainty::UncertaintyReport>,
) -> (RunSections, Vec<String>) {
    let (case, seg, skull) = (&scene.case, &scene.seg, &scene.face.skull);
    let model = p.report(scene);
    let counts = Counts {
        voxels: scene.vol.len(),
        dims: scene.vol.dims,
        skin_vertices: p.skin.vertices.len(),
        skin_triangles: p.skin.triangles.len(),
        skull_vertices: skull.vertices.len(),
        skull_triangles: skull.triangles.len(),
        springs_main: scene.model.spring_report.main,
        springs_strut: scene.model.spring_report.struts,
        unknowns: model.unknowns,
        solved_vertices: model.solved_vertices,
        max_rss_mb: crate::meter::max_rss_mb(),
    };
    let mut surfaces = scene.face.report.clone();
    surfaces.embedding = model.embedding;
    let Recorder {
        costs,
        mut warnings,
        skipped,
        ..
    } = rec;
    if seg.report.removed_components > 0 {
        warnings.push(format!(
            "{} pieces above the head threshold ({} voxels) are not the head and were dropped (CT table, head rest)",
            seg.report.removed_components, seg.report.removed_voxels
        ));
    }
    if let Some(b) = &p.basis {
        warnings.extend(b.warnings.iter().cloned());
    }
    let sections = RunSections {
        costs,
        counts,
        segmentation: seg.report.clone(),
        surfaces,
        registration: scene.face.registration.clone(),
        parameters: case.clone(),
        springs: model.springs,
        solve: model.solve,
        tet: model.tet,
        plan_basis: p.basis.as_ref().map(report::BasisReport::of),
        uncertainty,
        stages_not_run: skipped,
    };
    (sections, warnings)
}

//! The soft-tissue models behind one type (docs/design/architecture.md "The model seam").
//!
//! A case names its model in `[solve] model`: Koch's C1 surface model on tissue springs, solved
//! to equilibrium (`equilibrium`) or by Koch's eq. 20–23 (`koch1996`) — [`c1`]; or the volumetric
//! tetrahedral model of the tissue between skin and bone (`tet`, the default) — [`volumetric`].
//! Whatever the model, [`predict`] builds it on the scene and solves the plan, and the
//! [`Prediction`] it returns does the rest: the face before and after, the plan basis
//! ([`Prediction::basis`]), a re-solve with other tissue parameters on the same mesh and face
//! embedding ([`Prediction::resolve`]), the model's own files and report sections. Nothing outside
//! this module branches on the model.

pub mod c1;
mod degloved;
pub mod discretisation;
pub mod predicted;
pub mod reduced;
pub mod volumetric;

use crate::case::Case;
use crate::embed::EmbeddingReport;
use crate::error::{Error, Result};
use crate::pipeline::inputs::CaseFiles;
use crate::pipeline::{Recorder, Scene};
use std::path::Path;

pub use predicted::Predicted;
pub use volumetric::{NewtonStep, TetReport, Volumetric};

/// A solved model, kept for its files, its report sections and re-solves.
pub enum Solved {
    // Both boxed: each is a kilobyte and more, and their sizes differ by a few fields.
    C1(Box<c1::C1Solved>),
    /// None when the plan moves no bone (no tissue is meshed).
    Tet(Option<Box<Volumetric>>),
}

/// What report.json says of the model: `counts.unknowns` and `counts.solved_vertices`,
/// `surfaces.embedding` (a coarse C1 model carried the full skin), `springs` and `solve` (C1),
/// `tet` (the volumetric model).
pub struct ModelReport {
    pub unknowns: usize,
    pub solved_vertices: usize,
    pub embedding: Option<EmbeddingReport>,
    pub springs: Option<crate::springs::SpringReport>,
    pub solve: Option<Vec<crate::solve::StepRecord>>,
    pub tet: Option<TetReport>,
}

/// The greedy's stopping rule (docs/design/reduced.md "Measured"): a relative energy bound of 5e-3 over
/// the training box, or 16 vectors (on the real CT the worst vertex's true error is
/// then 4e-3 to 2e-2 mm). Batches of 8 were tried: offline 9.1 → 8.0 s on the real
/// CT, the greedy's last relative bound 8.5e-3 → 9.6e-3; not kept.
const REDUCED_TOLERANCE: f64 = 5e-3;
const REDUCED_MAX_SIZE: usize = 16;
/// Snapshots per greedy step: their conjugate-gradient solves share the preconditioner's
/// solves, which cost about a quarter per column in a block of four (docs/design/reduced.md).
const REDUCED_BATCH: usize = 4;

/// The landmarks' dual greedy (docs/design/reduced.md "Primal–dual output bounds") for
/// `[uncertainty] landmark_dual_rounds` rounds (0: none): each round adds the three adjoints at
/// the training point of the largest relative dual bound, their conjugate gradients stopped at
/// 1e-2 of the reduced dual bound there (the snapshot shapes the space; the bound is computed
/// from the full dual residual whatever it is), and stops early below a relative dual bound of
/// 1e-2.
fn dual_greedy(rounds: usize) -> Option<crate::reduced::dual::DualGreedy> {
    (rounds > 0).then_some(crate::reduced::dual::DualGreedy {
        tolerance: 1e-2,
        rounds,
        snapshot_accuracy: 1e-2,
    })
}

/// The predicted face and the model that predicted it.
pub type Prediction = Predicted<Solved>;

/// How [`Prediction::solve_at`] answered.
#[derive(Clone, Debug, PartialEq)]
pub enum Answer {
    /// By the reduced model, within this certified bound (mm) of the full model's face.
    Reduced { bound_mm: f64 },
    /// By a full solve, and why the reduced model did not answer.
    Full { why: String },
}

/// Build the case's model on the scene, solve its plan and carry the answer to the face.
pub fn predict(
    scene: &Scene,
    case: &Case,
    files: &CaseFiles,
    rec: &mut Recorder,
) -> Result<Prediction> {
    match crate::solve::Method::of(case.solve.model) {
        Some(_) => Ok(c1::predict(scene, case, files, rec)?.map(|c| Solved::C1(Box::new(c)))),
        None => {
            Ok(volumetric::predict_face(scene, case, rec)?.map(|v| Solved::Tet(v.map(Box::new))))
        }
    }
}

/// The element size of the discretisation-error estimate's coarse solve and its face.
pub(crate) type CoarseFace = (f64, Vec<[f64; 3]>);

/// The face solved again at twice the element size, for the discretisation-error estimate
/// ([`discretisation`]), with its element size; None for the C1 models (their surface is the
/// skin's own mesh). It needs the scene alone, so a run solves it beside its own solve and keeps
/// it when that solve moved the face ([`Prediction::solved_by_tet`]). Inverted elements in the
/// coarse solve are accepted: it is a yardstick.
pub(crate) fn coarse_face(scene: &Scene, case: &Case) -> Option<Result<CoarseFace>> {
    if crate::solve::Method::of(case.solve.model).is_some() {
        return None;
    }
    let skin = volumetric::face_mesh(scene);
    let mut coarse = case.clone();
    coarse.tet.skin_size_mm *= 2.0;
    coarse.tet.deep_size_mm *= 2.0;
    coarse.tet.accept_inverted = true;
    coarse.uncertainty.samples = 0;
    let mut rec = Recorder::new(&crate::observe::Quiet);
    Some(
        volumetric::predict_for(
            scene,
            &coarse,
            skin,
            volumetric::Purpose::FaceOnly,
            &mut rec,
        )
        .map(|o| {
            let face = o.map_or_else(|| skin.vertices.clone(), |(_, post)| post);
            (coarse.tet.skin_size_mm, face)
        }),
    )
}

impl Prediction {
    /// The face (face_post's vertex order) predicted with `case`'s tissue parameters (moduli,
    /// Poisson ratios, sliding; the C1 spring constants) on what this prediction built: the
    /// volumetric model's mesh, node roles, mucosa and face embedding, or the C1 model's springs
    /// and shell. The plan and the mesh settings must be this run's.
    pub fn resolve(&self, scene: &Scene, case: &Case) -> Result<Vec<[f64; 3]>> {
        if !self.moves() {
            return Ok(self.face_post.vertices.clone());
        }
        match &self.solved {
            Solved::C1(c) => c.resolve(scene, case, &self.skin),
            Solved::Tet(Some(v)) => v.resolve(scene, case, &self.skin),
            Solved::Tet(None) => Ok(self.face_post.vertices.clone()),
        }
    }

    /// The face with `case`'s tissue parameters (as [`Prediction::resolve`]; the plan and mesh
    /// settings must be this run's): from `reduced` when its θ is inside the trained box and the
    /// certified bound is within `tolerance_mm`, else by a full solve, with the reason
    /// (docs/design/reduced.md "Solve at θ"). Never extrapolated.
    pub fn solve_at(
        &self,
        scene: &Scene,
        case: &Case,
        reduced: Option<&reduced::ReducedModels>,
        tolerance_mm: f64,
    ) -> Result<(Vec<[f64; 3]>, Answer)> {
        let why = match reduced.map(|r| {
            r.model(case.tet.sliding)
                .and_then(|m| m.face_of(&case.tet.tissues()))
        }) {
            None => "no reduced model".to_string(),
            Some(Err(e)) => e.to_string(),
            Some(Ok(f)) if f.bound_mm <= tolerance_mm => {
                return Ok((
                    crate::vec3::displaced(&self.skin.vertices, &f.displacement),
                    Answer::Reduced {
                        bound_mm: f.bound_mm,
                    },
                ));
            }
            Some(Ok(f)) => format!(
                "the certified bound {:.3} mm exceeds the tolerance {tolerance_mm} mm",
                f.bound_mm
            ),
        };
        Ok((self.resolve(scene, case)?, Answer::Full { why }))
    }

    /// The certified reduced models of this prediction for `case`'s tissue-parameter ranges
    /// (docs/design/reduced.md): one per sliding state `[uncertainty]` draws (both when it samples
    /// sliding and the mesh has nodes to slide), trained on `train` draws of its box, with a
    /// bound for each of `outputs` (weights on face vertices: the landmarks). None when
    /// the model has no reduced form (the C1 models, the neo-Hookean material, the 10-node
    /// element) or nothing moves.
    pub fn reduced(
        &self,
        scene: &Scene,
        case: &Case,
        train: &[Case],
        outputs: &[Vec<(usize, f64)>],
        progress: &(dyn Fn(&str) + Sync),
    ) -> Option<Result<reduced::ReducedModels>> {
        let Solved::Tet(Some(v)) = &self.solved else {
            return None;
        };
        if !case.reduced_form() {
            return None;
        }
        // The sliding states the samples can draw (one when sliding holds no node).
        let states: Vec<bool> = if self.sliding_matters() {
            let p = case.uncertainty.sliding_probability();
            [true, false]
                .into_iter()
                .filter(|s| if *s { p > 0.0 } else { p < 1.0 })
                .collect()
        } else {
            vec![case.tet.sliding]
        };
        let greedy = crate::reduced::Greedy {
            tolerance: REDUCED_TOLERANCE,
            max_size: REDUCED_MAX_SIZE,
            batch: REDUCED_BATCH,
        };
        let one = |s: bool, progress: &dyn Fn(&str)| {
            let mut c = case.clone();
            c.tet.sliding = s;
            let t: Vec<Case> = train
                .iter()
                .map(|x| {
                    let mut x = x.clone();
                    x.tet.sliding = s;
                    x
                })
                .collect();
            let training = reduced::Training {
                cases: &t,
                greedy,
                outputs,
                dual: dual_greedy(case.uncertainty.landmark_dual_rounds),
            };
            v.reduced(scene, &c, &training, progress)
        };
        // The sliding states are independent builds, each mostly sequential work (the
        // factorisation, the snapshots' preconditioner solves): the second one runs beside the
        // first, reporting no progress of its own.
        let build = || -> Result<reduced::ReducedModels> {
            let Some((first, others)) = states.split_first() else {
                return Err(Error::config(
                    "the reduced model: no sliding state to build",
                ));
            };
            // Each build in a thread pool of its share of the cores: the builds' parallel
            // products and matrix-vector passes otherwise share one pool, whose waiting workers
            // take the core the other build needs (real CT, 10 000 samples on 2 cores: the band
            // stage 7.6 s with one shared pool, 7.2 s with a pool of one thread per build).
            let threads = (rayon::current_num_threads() / states.len()).max(1);
            let pooled = |s: bool, progress: &(dyn Fn(&str) + Sync)| {
                if states.len() == 1 {
                    return one(s, progress);
                }
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .map_err(|e| {
                        Error::config(format!(
                            "the reduced model: no thread pool for a build ({e})"
                        ))
                    })?
                    .install(|| one(s, progress))
            };
            let pooled = &pooled;
            let models = std::thread::scope(|scope| {
                let rest: Vec<_> = others
                    .iter()
                    .map(|s| scope.spawn(move || pooled(*s, &|_: &str| {})))
                    .collect();
                let mut models = vec![pooled(*first, progress)];
                models.extend(
                    rest.into_iter()
                        .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e))),
                );
                models.into_iter().collect::<Result<Vec<_>>>()
            })?;
            Ok(reduced::ReducedModels {
                models,
                sliding_matters: self.sliding_matters(),
            })
        };
        Some(build())
    }

    /// Whether the volumetric model solved and moved the face (what the discretisation-error
    /// estimate compares against; [`coarse_face`]).
    pub(crate) fn solved_by_tet(&self) -> bool {
        matches!(self.solved, Solved::Tet(Some(_)))
    }

    /// The hyperelastic run's linear face under the same holds (None for linear models).
    pub(crate) fn linear_face(&self) -> Option<&[[f64; 3]]> {
        match &self.solved {
            Solved::Tet(Some(v)) => v.linear_face.as_deref(),
            _ => None,
        }
    }

    /// Whether the model moved anything (else every re-solve is the pre-operative face).
    pub fn moves(&self) -> bool {
        match &self.solved {
            Solved::C1(c) => c.solution.is_some(),
            Solved::Tet(v) => v.is_some(),
        }
    }

    /// How many full re-solves (`resolve`) to run side by side (the uncertainty samples): the
    /// tet model's says `Volumetric::solves_at_once`; the C1 models' sparse factors are below
    /// the parallel size, so one per core.
    pub(crate) fn solves_at_once(&self) -> usize {
        match &self.solved {
            Solved::Tet(Some(v)) => v.solves_at_once(),
            _ => crate::fem::cholesky::factorisations_at_once(0),
        }
    }

    /// Whether `[tet] sliding` can change the answer: the mesh has mucosa or lip–tooth contact
    /// nodes to slide, or bone nodes released at the saw lines (which slide with it and are
    /// free without it; counting only the first two let one reduced model answer both states on
    /// the large phantom, 12 mm off for sliding off: found by `facesim bench reduced`).
    pub(crate) fn sliding_matters(&self) -> bool {
        matches!(&self.solved, Solved::Tet(Some(v))
            if v.report.mucosa_nodes + v.report.contact_nodes + v.report.released_at_cuts > 0)
    }

    /// The model's own files beside the face outputs: the springs (C1; springs.ply), the
    /// C1 surface sampled finer (face_post_fine.ply) and the coarse mesh's answer
    /// (face_post_coarse.ply), or the tetrahedral mesh (tets.vtu).
    pub(crate) fn write_model_files(&self, dir: &Path, scene: &Scene, case: &Case) -> Result<()> {
        match &self.solved {
            Solved::C1(c) => c.write_files(dir, scene, case, &self.skin),
            Solved::Tet(Some(v)) => v.write_vtu(&dir.join("tets.vtu")),
            Solved::Tet(None) => Ok(()),
        }
    }

    /// report.json's model sections (docs/reference/case.md).
    pub fn report(&self, scene: &Scene) -> ModelReport {
        match &self.solved {
            Solved::C1(c) => ModelReport {
                unknowns: c.solution.as_ref().map_or(0, |s| s.unknowns),
                solved_vertices: c.solution.as_ref().map_or(0, |s| s.solved_vertices),
                embedding: c.embedding.clone(),
                springs: Some(scene.model.spring_report.clone()),
                solve: c.solution.as_ref().map(|s| s.history.clone()),
                tet: None,
            },
            Solved::Tet(v) => ModelReport {
                unknowns: v.as_ref().map_or(0, |v| v.report.free_dofs),
                solved_vertices: 0,
                embedding: None,
                springs: None,
                solve: None,
                tet: v.as_ref().map(|v| v.report.clone()),
            },
        }
    }

    /// Tetrahedra the solved displacement turns inside out (0 for the C1 models).
    pub fn inverted_elements(&self) -> usize {
        match &self.solved {
            Solved::Tet(Some(v)) => v.report.inverted_elements,
            _ => 0,
        }
    }

    /// The shell embedding's report, when a coarse C1 model carried the full skin.
    pub fn embedding(&self) -> Option<&EmbeddingReport> {
        match &self.solved {
            Solved::C1(c) => c.embedding.as_ref(),
            Solved::Tet(_) => None,
        }
    }
}

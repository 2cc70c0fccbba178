//! The predicted face — the C1 solve of the model (docs/pipeline.md §5) and, when the
//! model ran on a coarse copy of the skin, the full skin carried along by shell embedding.

use super::inputs::CaseFiles;
use super::model::rigid_mask;
use super::volumetric::{self, Volumetric};
use super::{Recorder, Scene};
use crate::case::{Case, SolveModel};
use crate::embed::Shell;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::plan::c1::{self, C1Basis};
use crate::report::{EmbeddingReport, Stage};
use crate::solve::{Responses, Solution};

pub struct Prediction {
    /// The skin of face_pre: the full skin (the scan as given, or the extracted skin).
    pub skin: Mesh,
    /// The predicted face, same vertices in the same order as `skin`, without colours.
    pub face_post: Mesh,
    /// The C1 solution (None when the plan moves nothing).
    pub solution: Option<Solution>,
    /// The coarse skin that was solved, when it differs from `skin`.
    pub coarse: Option<Mesh>,
    pub embedding: Option<EmbeddingReport>,
    /// The volumetric model's mesh and solution (`[solve] model = "tet"`).
    pub volumetric: Option<Volumetric>,
    /// The plan basis (docs/plan-basis.md), when the model built one.
    pub basis: Option<crate::plan::PlanBasis>,
}

pub fn predict(
    scene: &Scene,
    case: &Case,
    files: &CaseFiles,
    rec: &mut Recorder,
) -> Result<Prediction> {
    if case.solve.model == SolveModel::Tet {
        return predict_volumetric(scene, case, rec);
    }
    let (face, model) = (&scene.face, &scene.model);
    // The plan basis's unit moves of the spring attachments, answered by the solve's own factor.
    let moves = crate::plan::c1::attachment_moves(&case.osteotomy, &model.springs.attachments);
    let solved = rec.time(Stage::Solve, "solving", || {
        solve(scene, files, &moves.columns)
    })?;
    let (solution, responses) = match solved {
        Some((s, r)) => (Some(s), Some(r)),
        None => (None, None),
    };
    if solution.is_none() {
        rec.warn("no [[osteotomy]] in the case: the predicted face is the pre-operative face");
        rec.skip(Stage::Solve, "no [[osteotomy]]: nothing moves");
    }
    let mut face_post = face.skin.clone();
    if let Some(sol) = &solution {
        face_post.vertices = sol.positions.clone();
    }
    face_post.colors = None;
    let model_name = match case.solve.model {
        SolveModel::Koch1996 => "koch1996-linearised",
        _ => "c1-linearised",
    };
    let Some(fine) = &face.fine else {
        rec.skip(Stage::Embed, "the skin was solved as given");
        let basis = match responses {
            Some(r) => {
                let wall = r.wall_s;
                let displacement = displacement_of(&face.skin.vertices, &face_post.vertices);
                let b = rec.time(Stage::PlanBasis, "building the plan basis", || {
                    c1::basis(
                        C1Basis {
                            model: model_name,
                            skin: &face.skin,
                            columns: r.columns,
                            offset: None,
                            overlapping_segments: &moves.overlapping_segments,
                            run_face_displacement: &displacement,
                        },
                        &case.osteotomy,
                    )
                })?;
                move_cost(rec, wall);
                Some(b)
            }
            None => None,
        };
        return Ok(Prediction {
            skin: face.skin.clone(),
            face_post,
            solution,
            coarse: None,
            embedding: None,
            volumetric: None,
            basis,
        });
    };
    let inward = -crate::springs::outward_sign(&face.skin, &scene.vol, &scene.seg.labels);
    let rigid_fine = rigid_mask(case, &fine.vertices);
    // The coarse model's answer carried to the full skin (paper 002).
    let (post, embedding, shell) =
        rec.time(Stage::Embed, "carrying the full skin along", || {
            let shell = Shell::new(
                &face.skin,
                case.solve.shell_mm,
                inward,
                case.solve.shell_poisson,
                &model.rigid,
            )?;
            let e = shell.embed(&fine.vertices);
            let carried = shell.carry(&e, &shell.deform(&face_post.vertices));
            // Fine vertices outside [surface] movable are rigid, exactly as in a full solve.
            let mut post = fine.clone();
            for ((p, c), r) in post.vertices.iter_mut().zip(carried).zip(&rigid_fine) {
                if !r {
                    *p = c;
                }
            }
            post.colors = None;
            let report = EmbeddingReport {
                shell_mm: case.solve.shell_mm,
                poisson: case.solve.shell_poisson,
                fine_to_coarse_mm: crate::compare::stats(&e.distance),
            };
            Ok((post, report, (shell, e)))
        })?;
    let basis = match responses {
        Some(r) => {
            let wall = r.wall_s;
            let (shell, e) = &shell;
            let displacement = displacement_of(&fine.vertices, &post.vertices);
            let b = rec.time(Stage::PlanBasis, "building the plan basis", || {
                // The carry linearised at rest, rigid fine vertices still (as in the run).
                let still = |mut d: Vec<[f64; 3]>| {
                    for (d, r) in d.iter_mut().zip(&rigid_fine) {
                        if *r {
                            *d = [0.0; 3];
                        }
                    }
                    d
                };
                let columns = r
                    .columns
                    .iter()
                    .map(|c| still(shell.carry_derivative(e, &face.skin.vertices, c)))
                    .collect();
                let at_rest = shell.carry(e, &shell.deform(&face.skin.vertices));
                let offset = still(displacement_of(&fine.vertices, &at_rest));
                let offset = offset
                    .iter()
                    .any(|d| crate::vec3::norm(*d) > 1e-9)
                    .then_some(offset);
                c1::basis(
                    C1Basis {
                        model: model_name,
                        skin: fine,
                        columns,
                        offset,
                        overlapping_segments: &moves.overlapping_segments,
                        run_face_displacement: &displacement,
                    },
                    &case.osteotomy,
                )
            })?;
            move_cost(rec, wall);
            Some(b)
        }
        None => None,
    };
    Ok(Prediction {
        skin: fine.clone(),
        face_post: post,
        solution,
        coarse: Some(face.skin.clone()),
        embedding: Some(embedding),
        volumetric: None,
        basis,
    })
}

/// `after − before` per vertex.
fn displacement_of(before: &[[f64; 3]], after: &[[f64; 3]]) -> Vec<[f64; 3]> {
    before
        .iter()
        .zip(after)
        .map(|(b, a)| crate::vec3::sub(*a, *b))
        .collect()
}

/// The basis's tangent solves ran inside the solve stage (on its factor): their wall time is
/// moved from `solve` to `plan_basis` in the cost table.
fn move_cost(rec: &mut Recorder, wall_s: f64) {
    for (stage, cost) in rec.costs.0.iter_mut() {
        match stage {
            Stage::Solve => cost.wall_s -= wall_s,
            Stage::PlanBasis => cost.wall_s += wall_s,
            _ => {}
        }
    }
}

/// The volumetric model carries the skin at full resolution (a dense scan needs no coarse copy).
fn predict_volumetric(scene: &Scene, case: &Case, rec: &mut Recorder) -> Result<Prediction> {
    let skin = scene.face.fine.as_ref().unwrap_or(&scene.face.skin).clone();
    let mut face_post = skin.clone();
    face_post.colors = None;
    let mut basis = None;
    let volumetric = match volumetric::predict(scene, case, &skin, rec)? {
        Some((mut v, post)) => {
            face_post.vertices = post;
            basis = v.basis.take();
            Some(v)
        }
        None => {
            rec.warn("the plan moves no bone: the predicted face is the pre-operative face");
            rec.skip(Stage::TetMesh, "no bone moves: no tissue to mesh");
            rec.skip(Stage::Solve, "no bone moves: nothing to solve");
            rec.skip(Stage::Embed, "no bone moves: the face stays");
            rec.skip(
                Stage::PlanBasis,
                "no bone moves: no plan basis to re-plan from",
            );
            None
        }
    };
    Ok(Prediction {
        skin,
        face_post,
        solution: None,
        coarse: None,
        embedding: None,
        volumetric,
        basis,
    })
}

/// The C1 solve and its linearised responses to the attachment `moves`; None when there is
/// nothing to move: the preloaded skin is an equilibrium by construction (F_init = K a_init), so
/// the prediction is the pre-operative face.
fn solve(
    scene: &Scene,
    files: &CaseFiles,
    moves: &[Vec<[f64; 3]>],
) -> Result<Option<(Solution, Responses)>> {
    let (face, model) = (&scene.face, &scene.model);
    if model.plan.is_empty() {
        return Ok(None);
    }
    crate::solve::solve_linearised(
        &face.skin,
        &model.springs,
        &model.plan,
        &model.rigid,
        &model.params,
        moves,
    )
    .map(Some)
    // An impossible plan is the case file's fault, a surface the model cannot use is its
    // source's: name them.
    .map_err(|e| match e {
        Error::ImpossiblePlan { .. } => e.in_file(&files.case_file),
        other => other.in_file(&files.skin_source),
    })
}

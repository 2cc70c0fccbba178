//! Koch's C1 surface models (`[solve] model = "equilibrium"` or `"koch1996"`; docs/design/pipeline.md
//! §5): the skin on tissue springs, solved by `crate::solve`, and — when the model ran on a coarse
//! copy of the skin — the full skin carried along by shell embedding (paper 002).

use super::predicted::Predicted;
use crate::case::Case;
use crate::embed::{Embedding, EmbeddingReport, Shell};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::pipeline::inputs::CaseFiles;
use crate::pipeline::model::rigid_mask;
use crate::pipeline::stage::Stage;
use crate::pipeline::{Recorder, Scene};
use crate::plan::c1::{self, C1Basis};
use crate::solve::{Responses, Solution};
use std::path::Path;

/// The solved C1 model: what the outputs, the report and re-solves need of it.
pub struct C1Solved {
    /// The C1 solution (None when the plan moves nothing).
    pub solution: Option<Solution>,
    /// The coarse skin that was solved, when it differs from the face.
    pub coarse: Option<Mesh>,
    pub embedding: Option<EmbeddingReport>,
    /// The shell that carried the full skin along the coarse answer, its embedding of the full
    /// skin and the full skin's rigid vertices: built once, reused by re-solves.
    carry: Option<(Shell, Embedding, Vec<bool>)>,
}

pub fn predict(
    scene: &Scene,
    case: &Case,
    files: &CaseFiles,
    rec: &mut Recorder,
) -> Result<Predicted<C1Solved>> {
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
    let model_name = match model.params.model {
        crate::solve::Method::Koch1996 => "koch1996-linearised",
        crate::solve::Method::Equilibrium => "c1-linearised",
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
        return Ok(Predicted {
            skin: face.skin.clone(),
            face_post,
            basis,
            solved: C1Solved {
                solution,
                coarse: None,
                embedding: None,
                carry: None,
            },
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
    let (shell, e) = shell;
    Ok(Predicted {
        skin: fine.clone(),
        face_post: post,
        basis,
        solved: C1Solved {
            solution,
            coarse: Some(face.skin.clone()),
            embedding: Some(embedding),
            carry: Some((shell, e, rigid_fine)),
        },
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

impl C1Solved {
    /// The face (the run's face's vertex order) solved again with `case`'s spring constants on
    /// the run's skin, springs and shell (docs/guide/uncertainty.md).
    pub(super) fn resolve(&self, scene: &Scene, case: &Case, skin: &Mesh) -> Result<Vec<[f64; 3]>> {
        let (face, model) = (&scene.face, &scene.model);
        let params = crate::pipeline::model::solve_params(case);
        let sol = crate::solve::solve(
            &face.skin,
            &model.springs,
            &model.plan,
            &model.rigid,
            &params,
        )?;
        Ok(match &self.carry {
            None => sol.positions,
            Some((shell, e, rigid)) => {
                let carried = shell.carry(e, &shell.deform(&sol.positions));
                skin.vertices
                    .iter()
                    .zip(carried)
                    .zip(rigid)
                    .map(|((x, c), r)| if *r { *x } else { c })
                    .collect()
            }
        })
    }

    /// springs.ply (on the mesh that was solved), face_post_fine.ply (the C1 surface sampled
    /// `[output] subdivide` times finer, when the skin was solved as given) and
    /// face_post_coarse.ply (the coarse mesh's answer, when there was one).
    pub(super) fn write_files(
        &self,
        dir: &Path,
        scene: &Scene,
        case: &Case,
        skin: &Mesh,
    ) -> Result<()> {
        use crate::mesh;
        let solved_skin = self.coarse.as_ref().unwrap_or(skin);
        mesh::ply::write(
            &scene.model.springs.to_mesh(solved_skin),
            &dir.join("springs.ply"),
            mesh::ply::Encoding::BinaryLittleEndian,
        )?;
        let Some(sol) = &self.solution else {
            return Ok(());
        };
        match &self.coarse {
            None if case.output.subdivide > 1 => {
                let fine = crate::fem::preload::sample(&sol.fem, &sol.a, case.output.subdivide);
                mesh::write_mesh(&fine, &dir.join("face_post_fine.ply"))
            }
            None => Ok(()),
            Some(coarse) => {
                let mut m = coarse.clone();
                m.vertices = sol.positions.clone();
                mesh::write_mesh(&m, &dir.join("face_post_coarse.ply"))
            }
        }
    }
}

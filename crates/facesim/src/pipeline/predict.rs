//! The predicted face — the C1 solve of the model (docs/pipeline.md §5) and, when the
//! model ran on a coarse copy of the skin, the full skin carried along by shell embedding.

use super::inputs::CaseFiles;
use super::model::rigid_mask;
use super::volumetric::{self, Volumetric};
use super::{Recorder, Scene};
use crate::case::{Case, SolveModel};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::report::{EmbeddingReport, Stage};
use crate::solve::Solution;

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
    let solution = rec.time(Stage::Solve, "solving", || solve(scene, files))?;
    if solution.is_none() {
        rec.warn("no [[osteotomy]] in the case: the predicted face is the pre-operative face");
        rec.skip(Stage::Solve, "no [[osteotomy]]: nothing moves");
    }
    let mut face_post = face.skin.clone();
    if let Some(sol) = &solution {
        face_post.vertices = sol.positions.clone();
    }
    face_post.colors = None;
    let Some(fine) = &face.fine else {
        rec.skip(Stage::Embed, "the skin was solved as given");
        return Ok(Prediction {
            skin: face.skin.clone(),
            face_post,
            solution,
            coarse: None,
            embedding: None,
            volumetric: None,
            basis: None,
        });
    };
    // The coarse model's answer carried to the full skin (paper 002).
    let (post, embedding) = rec.time(Stage::Embed, "carrying the full skin along", || {
        let (carried, e) = crate::embed::Shell::carry_skin(
            &face.skin,
            &face_post.vertices,
            &fine.vertices,
            (&scene.vol, &scene.seg.labels),
            &case.solve,
            &model.rigid,
        )?;
        // Fine vertices outside [surface] movable are rigid, exactly as in a full solve.
        let mut post = fine.clone();
        for ((p, c), r) in post
            .vertices
            .iter_mut()
            .zip(carried)
            .zip(rigid_mask(case, &fine.vertices))
        {
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
        Ok((post, report))
    })?;
    Ok(Prediction {
        skin: fine.clone(),
        face_post: post,
        solution,
        coarse: Some(face.skin.clone()),
        embedding: Some(embedding),
        volumetric: None,
        basis: None,
    })
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

/// The C1 solve; None when there is nothing to move: the preloaded skin is an equilibrium by
/// construction (F_init = K a_init), so the prediction is the pre-operative face.
fn solve(scene: &Scene, files: &CaseFiles) -> Result<Option<Solution>> {
    let (face, model) = (&scene.face, &scene.model);
    if model.plan.is_empty() {
        return Ok(None);
    }
    crate::solve::solve(
        &face.skin,
        &model.springs,
        &model.plan,
        &model.rigid,
        &model.params,
    )
    .map(Some)
    // An impossible plan is the case file's fault, a surface the model cannot use is its
    // source's: name them.
    .map_err(|e| match e {
        Error::ImpossiblePlan { .. } => e.in_file(&files.case_file),
        other => other.in_file(&files.skin_source),
    })
}

//! The pipeline as typed stages (docs/design/architecture.md):
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
//! through one [`Recorder`] (the caller's [`Observer`] plus the report's cost table and warnings;
//! `stage`), and report.json is assembled once at the end (`report`).
//! `facesim run`, the study (crates/facesim-lab) and the tests call these same functions.

pub mod anatomy;
pub mod bone_overlap;
pub mod face;
pub mod inputs;
pub mod model;
pub mod stage;
pub mod surfaces;

use crate::case::Case;
use crate::error::Result;
use crate::landmarks::{HeadFrame, Landmark};
use crate::mesh::Mesh;
use crate::observe::Observer;
use crate::segment::Segmentation;
use crate::volume::Volume;
pub use stage::{Recorder, Stage};
use std::path::Path;

/// Tissues from the CT (Koch §2.3; docs/design/pipeline.md §1).
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
    /// The clinical frame, the bony landmarks and the planned surgeries (None: no midsagittal
    /// frame, and no `[[surgery]]`).
    pub anatomy: Option<anatomy::Anatomical>,
    /// The pre-operative landmarks, located once ([`Scene::landmarks_pre`]).
    located: std::sync::OnceLock<Option<Located>>,
}

/// Landmarks located on one skin, with the checksum of its vertices.
struct Located {
    key: u64,
    frame: Option<HeadFrame>,
    landmarks: Vec<Landmark>,
}

impl Scene {
    /// The head frame and landmarks of `skin` (the pre-operative face a prediction moves) with the
    /// case's own landmarks over the detected ones, located on the first call and kept: the tet
    /// model's region, its nose option and the landmark stage all need them (0.13 s on the real
    /// CT). A call with another skin, or after the first failed, locates again, so that a user
    /// landmark that is not valid is an error naming `case_file`.
    pub(crate) fn landmarks_pre(
        &self,
        skin: &Mesh,
        case_file: &Path,
    ) -> Result<(Option<HeadFrame>, Vec<Landmark>)> {
        let locate = || {
            let user = inputs::user_landmarks(&self.case)?;
            crate::landmarks::locate(skin, Some(&self.face.skull), &user, case_file)
        };
        let key = crate::mesh::checksum(&skin.vertices);
        let kept = self.located.get_or_init(|| {
            locate().ok().map(|(frame, landmarks)| Located {
                key,
                frame,
                landmarks,
            })
        });
        match kept {
            Some(k) if k.key == key => Ok((k.frame, k.landmarks.clone())),
            _ => locate(),
        }
    }
}

/// Stages 1–4 on a case whose files are read: tissues, surfaces, face, model.
pub(crate) fn prepare(inputs: inputs::Inputs, rec: &mut Recorder) -> Result<Scene> {
    let inputs::Inputs { mut case, ct, scan } = inputs;
    let seg = tissues(&ct, &case, rec)?;
    rec.warnings.extend(seg.report.warnings.iter().cloned());
    // The cleaned bone field serves the skull surface and the spring tracer.
    let bone_field = seg.bone_field(&ct);
    let surf = surfaces::extract(&ct, &seg, &bone_field, &case, rec)?;
    let face = face::place(surf, scan, &ct, &case, rec)?;
    // The pre-operative landmarks (the anatomy's midsagittal frame and soft landmarks), located
    // once and kept for the landmark stage (`Scene::landmarks_pre`). A case that did not ask for
    // the anatomy runs on when they cannot be located: the landmark stage locates again and
    // reports why, naming the case file.
    let user = inputs::user_landmarks(&case)?;
    let located = match crate::landmarks::locate(
        &face.skin,
        Some(&face.skull),
        &user,
        Path::new("case.toml"),
    ) {
        Ok(l) => Some(l),
        Err(e) if anatomy::wanted(&case) => return Err(e),
        Err(_) => None,
    };
    let anatomy = anatomy::find(&mut case, &ct, &seg, located.as_ref(), rec)?;
    let model = model::build(&face, &ct, &seg, &bone_field, &case, rec)?;
    drop(bone_field);
    let kept = std::sync::OnceLock::new();
    if let Some((frame, landmarks)) = located {
        let _ = kept.set(Some(Located {
            key: crate::mesh::checksum(&face.skin.vertices),
            frame,
            landmarks,
        }));
    }
    Ok(Scene {
        case,
        vol: ct,
        seg,
        face,
        model,
        anatomy,
        located: kept,
    })
}

/// Read what an in-memory case names and run stages 1–4 (the study's and tests' entry).
pub fn prepare_case(case: &Case, obs: &dyn Observer) -> Result<Scene> {
    let mut rec = Recorder::new(obs);
    let inputs = inputs::read_case(case.clone(), &mut rec)?;
    prepare(inputs, &mut rec)
}

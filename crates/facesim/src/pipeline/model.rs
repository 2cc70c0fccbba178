//! The model on the skin — which skin is rigid (`[surface] movable`), the tissue springs
//! to the skull (Koch §2.5–2.6; docs/design/pipeline.md §3), the bone-move plan, and the parameters of
//! the C1 solve.

use super::face::Face;
use super::stage::Recorder;
use crate::case::Case;
use crate::error::{Error, Result};
use crate::osteotomy::Plan;
use crate::pipeline::stage::Stage;
use crate::segment::Segmentation;
use crate::springs::{SpringReport, SpringSet};
use crate::volume::Volume;

pub struct Model {
    pub springs: SpringSet,
    pub spring_report: SpringReport,
    pub plan: Plan,
    /// Per skin vertex: outside `[surface] movable` (its position and derivatives fixed).
    pub rigid: Vec<bool>,
    pub params: crate::solve::Params,
}

/// Per vertex: true when it lies outside `[surface] movable` (rigid skin); all false without a
/// movable region.
pub fn rigid_mask(case: &Case, vertices: &[[f64; 3]]) -> Vec<bool> {
    vertices
        .iter()
        .map(|p| {
            case.surface
                .movable
                .as_ref()
                .is_some_and(|r| !r.contains(*p))
        })
        .collect()
}

/// The C1 solve's parameters from the case.
pub(crate) fn solve_params(case: &Case) -> crate::solve::Params {
    // The volumetric model has no C1 solve; a C1 study of its case solves to equilibrium.
    let method =
        crate::solve::Method::of(case.solve.model).unwrap_or(crate::solve::Method::Equilibrium);
    crate::solve::Params {
        model: method,
        steps: case.solve.steps,
        alpha: case.surface.alpha,
        beta: case.surface.beta,
        regions: case.surface.regions.clone(),
        k_c: method.k_c(&case.solve),
        tolerance: 1e-6,
        max_iterations: 30,
        restrict: case.solve.restrict,
    }
}

pub fn build(
    face: &Face,
    ct: &Volume,
    seg: &Segmentation,
    bone_field: &[f32],
    case: &Case,
    rec: &mut Recorder,
) -> Result<Model> {
    let skin = &face.skin;
    let rigid = rigid_mask(case, &skin.vertices);
    if case.surface.movable.is_some() && rigid.iter().all(|r| *r) {
        // Every skin vertex outside the movable region: nothing can move, and the springs
        // (traced only under movable skin) would all be missing.
        return Err(Error::config(format!(
            "case.toml: [surface] movable contains none of the {} skin vertices: nothing could move; check the region (LPS mm) or its mask",
            skin.vertices.len()
        )));
    }
    // Bone driven into bone that stays: said for either model (docs/design/pipeline.md "Large moves").
    let plan = Plan::new(&case.osteotomy);
    for o in super::bone_overlap::bone_overlap(&plan, &face.skull, ct, &seg.labels) {
        rec.warn(super::bone_overlap::warning(&o));
    }
    if !case.solve.model.on_springs() {
        return volumetric_model(face, rigid, case);
    }
    let want = crate::springs::wanted(&rigid, case.solve.restrict);
    let springs = rec.time(Stage::Springs, "tracing springs", || {
        Ok(crate::springs::trace(
            skin,
            ct,
            seg,
            bone_field,
            &case.springs,
            &case.tissue.stiffness,
            want.as_deref(),
        ))
    })?;
    let spring_report = springs.report(skin);
    if springs.attachments.is_empty() {
        return Err(Error::input(
            &case.ct.path,
            format!(
                "no skin vertex found bone within {} mm along its inward normal: raise [springs] max_length_mm or check the [tissue] bone window",
                case.springs.max_length_mm
            ),
        ));
    }
    if spring_report.misses > 0 {
        rec.warn(miss_warning(&spring_report, case));
    }
    let plan = Plan::new(&case.osteotomy);
    plan.check_selects(
        &springs.attachments,
        if want.is_some() {
            "spring attachments under the movable skin ([surface] movable)"
        } else {
            "spring attachments"
        },
    )?;
    Ok(Model {
        springs,
        spring_report,
        plan,
        rigid,
        params: solve_params(case),
    })
}

/// The volumetric model needs no springs: its tissue is meshed in the solve stage
/// (`crate::model::volumetric`), and the plan must move some of the skull.
fn volumetric_model(face: &Face, rigid: Vec<bool>, case: &Case) -> Result<Model> {
    let plan = Plan::new(&case.osteotomy);
    plan.check_selects(&face.skull.vertices, "skull surface vertices")?;
    let springs = SpringSet::none(face.skin.vertices.len());
    Ok(Model {
        spring_report: springs.report(&face.skin),
        springs,
        plan,
        rigid,
        params: solve_params(case),
    })
}

fn miss_warning(r: &SpringReport, case: &Case) -> String {
    let places: Vec<String> = r
        .miss_regions
        .iter()
        .take(3)
        .map(|m| {
            format!(
                "{} around ({:.0}, {:.0}, {:.0})",
                m.vertices, m.centroid[0], m.centroid[1], m.centroid[2]
            )
        })
        .collect();
    format!(
        "{} skin vertices found no bone within {} mm (no spring); largest patches (LPS mm): {}",
        r.misses,
        case.springs.max_length_mm,
        places.join("; ")
    )
}

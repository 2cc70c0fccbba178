//! Skin and skull surfaces from the tissues (Koch §2.4; docs/design/pipeline.md §2) — the
//! cylindrical range scan with its (u, v) grid, or marching tetrahedra — then islands dropped,
//! optional smoothing and decimation, and the (u, v) parameterisation the C1 model needs.

use super::stage::Recorder;
use super::stage::Stage;
use crate::case::{Case, ExtractMethod, Parameterization};
use crate::compare::DistanceStats;
use crate::embed::EmbeddingReport;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::segment::Segmentation;
use crate::surface::{self, marching, rangescan};
use crate::volume::Volume;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The extracted skin and skull, with the cylinder (axis (x, y), radius) of the (u, v) map.
pub struct Surfaces {
    pub skin: Mesh,
    pub skull: Mesh,
    pub axis: [f64; 2],
    pub r0: f64,
    pub report: SurfaceReport,
}

/// `bone_field` is the segmentation's cleaned bone field (`Segmentation::bone_field`), made once
/// for this stage and the spring tracer.
pub fn extract(
    ct: &Volume,
    seg: &Segmentation,
    bone_field: &[f32],
    case: &Case,
    rec: &mut Recorder,
) -> Result<Surfaces> {
    let mut report = SurfaceReport::default();
    let mut notes = Vec::new();
    let (mut skin, mut skull, axis, r0) =
        rec.time(Stage::Surfaces, "extracting surfaces", || {
            Ok(match case.extract.method {
                ExtractMethod::Rangescan => range_scan(ct, seg, bone_field, case, &mut report),
                ExtractMethod::Marching => march(ct, seg, bone_field, &mut report, &mut notes),
            })
        })?;
    if let Some(w) = range_scan_warning(&report, case) {
        rec.warn(w);
    }
    notes.into_iter().for_each(|w| rec.warn(w));
    report.skin_islands_dropped = drop_small_components(&mut skin, 0.01);
    report.skull_islands_dropped = drop_small_components(&mut skull, 0.01);
    let warnings = rec.time(Stage::SmoothDecimate, "", || {
        Ok(smooth_and_decimate(
            &mut skin,
            &mut skull,
            case,
            &mut report,
        ))
    })?;
    warnings.into_iter().for_each(|w| rec.warn(w));
    if case.surface.parameterization == Parameterization::Planar {
        surface::planar_uv(&mut skin);
    }
    skin.check(Path::new("extracted skin surface"))?;
    if skull.triangles.is_empty() {
        return Err(Error::input(
            &case.ct.path,
            format!(
                "no skull surface: no bone found within {} mm of the skin; raise [springs] max_length_mm or check the [tissue] bone window",
                case.springs.max_length_mm
            ),
        ));
    }
    skull.check(Path::new("extracted skull surface"))?;
    report.extracted_skin_components = skin.components().1;
    report.skull_components = skull.components().1;
    Ok(Surfaces {
        skin,
        skull,
        axis,
        r0,
        report,
    })
}

/// The paper's simulated cylindrical range scan, with the cleaned bone field for the skull.
fn range_scan(
    ct: &Volume,
    seg: &Segmentation,
    bone_field: &[f32],
    case: &Case,
    report: &mut SurfaceReport,
) -> (Mesh, Mesh, [f64; 2], f64) {
    let z_step = if case.extract.z_step_mm > 0.0 {
        case.extract.z_step_mm
    } else {
        ct.spacing[2]
    };
    let r = rangescan::scan(
        ct,
        &seg.skin_field(ct),
        bone_field,
        &seg.head,
        &rangescan::ScanParams {
            angle_step_deg: case.extract.angle_step_deg,
            z_step,
            skin_iso: seg.windows.head_threshold as f32,
            bone_iso: seg.windows.bone as f32,
            max_skull_depth: case.springs.max_length_mm,
        },
    );
    report.method = "rangescan".into();
    report.rays = Some(r.rays);
    report.skin_misses = Some(r.skin_misses);
    report.skull_misses = Some(r.skull_misses);
    report.axis_xy = Some(r.axis);
    report.r0 = Some(r.r0);
    (r.skin, r.skull, r.axis, r.r0)
}

/// Rays with no bone within the springs' reach leave the C1 models' skin unsupported there; the
/// volumetric model meshes the tissue from the CT and has no such limit, so it is not warned.
fn range_scan_warning(report: &SurfaceReport, case: &Case) -> Option<String> {
    if !case.solve.model.on_springs() {
        return None;
    }
    let misses = report.skull_misses.filter(|m| *m > 0)?;
    Some(format!(
        "{misses} range-scan rays found skin but no bone within {} mm (bone defect, thin bone, or the scan's edge)",
        case.springs.max_length_mm
    ))
}

/// Marching tetrahedra on the cleaned fields; (u, v) about the volume's vertical mid-axis.
/// The skin's pieces besides the largest are dropped here (with a warning).
fn march(
    ct: &Volume,
    seg: &Segmentation,
    bone_field: &[f32],
    report: &mut SurfaceReport,
    warnings: &mut Vec<String>,
) -> (Mesh, Mesh, [f64; 2], f64) {
    let mut skin = marching::extract(ct, &seg.skin_field(ct), seg.windows.head_threshold as f32);
    let mut skull = marching::extract(ct, bone_field, seg.windows.bone as f32);
    // The skin is one surface; skull pieces above 1% are kept (a separate mandible is a real
    // piece).
    let dropped = drop_small_components(&mut skin, 1.0);
    if dropped > 0 {
        warnings.push(format!(
            "skin iso-surface: dropped {dropped} pieces besides the largest"
        ));
    }
    let (lo, hi) = ct.bounds();
    let axis = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let r0 = 0.25 * ((hi[0] - lo[0]) + (hi[1] - lo[1]));
    surface::cylindrical_uv(&mut skin, axis, r0);
    surface::cylindrical_uv(&mut skull, axis, r0);
    report.method = "marching".into();
    (skin, skull, axis, r0)
}

/// Taubin smoothing and decimation of both surfaces; returns warnings.
fn smooth_and_decimate(
    skin: &mut Mesh,
    skull: &mut Mesh,
    case: &Case,
    report: &mut SurfaceReport,
) -> Vec<String> {
    let mut warnings = Vec::new();
    for (m, name) in [(skin, "skin"), (skull, "skull")] {
        surface::taubin_smooth(m, case.extract.smooth_iterations);
        if case.extract.decimate_target == 0 {
            continue;
        }
        let before = m.clone();
        let err = surface::decimate(
            m,
            case.extract.decimate_target,
            case.extract.decimate_max_error_mm,
        );
        // Edge collapse is not guaranteed to keep a mesh manifold (thin iso-surface features
        // can pinch); a broken result is not used.
        if let Err(e) = m.check(Path::new(name)) {
            warnings.push(format!("decimation of the {name} was undone: {e}"));
            *m = before;
        } else if name == "skin" {
            report.skin_decimation_error_mm = Some(err);
        } else {
            report.skull_decimation_error_mm = Some(err);
        }
    }
    warnings
}

/// Drop connected pieces with fewer than `min_fraction` of the triangles (range-scan islands
/// at the edge of the field of view, stray iso-surface bits); every piece tied for largest is
/// kept. Returns how many were dropped.
pub(crate) fn drop_small_components(m: &mut Mesh, min_fraction: f64) -> usize {
    let (comp, n) = m.components();
    if n <= 1 {
        return 0;
    }
    let mut sizes = vec![0usize; n];
    for &c in &comp {
        sizes[c as usize] += 1;
    }
    let largest = sizes.iter().copied().max().unwrap_or(0);
    let keep: Vec<bool> = sizes
        .iter()
        .map(|&s| s == largest || s as f64 >= min_fraction * m.triangles.len() as f64)
        .collect();
    let tris = std::mem::take(&mut m.triangles);
    m.triangles = tris
        .into_iter()
        .zip(&comp)
        .filter(|(_, c)| keep[**c as usize])
        .map(|(t, _)| t)
        .collect();
    m.compact();
    keep.iter().filter(|k| !**k).count()
}

/// How the skin and skull were made, and what was dropped or changed on the way.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SurfaceReport {
    /// "rangescan" or "marching".
    pub method: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rays: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skin_misses: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skull_misses: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub axis_xy: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub r0: Option<f64>,
    pub skin_islands_dropped: usize,
    pub skull_islands_dropped: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skin_decimation_error_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skull_decimation_error_mm: Option<f64>,
    pub extracted_skin_components: usize,
    pub skull_components: usize,
    /// A given face scan's distance to the CT's skin.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scan_to_ct_skin_mm: Option<DistanceStats>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coarse: Option<CoarseReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub embedding: Option<EmbeddingReport>,
    /// A given skin that was not a clean face (another program's iso-surface): what keeping
    /// its outer face dropped (surface::outer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub foreign_skin: Option<crate::surface::outer::OuterReport>,
}

/// The coarse copy a dense skin was solved on (`[solve] coarse_triangles`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CoarseReport {
    pub triangles: usize,
    pub vertices: usize,
    pub fine_triangles: usize,
    pub fine_vertices: usize,
}

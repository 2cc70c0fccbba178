//! The skin the model is built on: the extracted skin, or a given face scan registered into the
//! CT frame, checked against the CT's skin and parameterised like it; a dense skin is solved on a
//! coarse (u, v)-grid copy and carried along afterwards (docs/design/pipeline.md §5, paper 002).

use super::stage::Recorder;
use super::stage::Stage;
use super::surfaces::{CoarseReport, SurfaceReport, Surfaces};
use crate::case::{Case, Parameterization};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::surface::outer::{self, OuterReport};
use crate::surface::{self, register};
use crate::volume::Volume;
use std::path::Path;

pub struct Face {
    /// The skin the model is built on (the coarse copy when `fine` is set).
    pub skin: Mesh,
    pub skull: Mesh,
    /// The skin as given, when the model runs on a coarse copy of it.
    pub fine: Option<Mesh>,
    /// Cylinder axis (x, y) and radius of the (u, v) parameterisation.
    pub axis: [f64; 2],
    pub r0: f64,
    pub registration: Option<register::Transform>,
    pub report: SurfaceReport,
}

pub fn place(
    surfaces: Surfaces,
    scan: Option<Mesh>,
    ct: &Volume,
    case: &Case,
    rec: &mut Recorder,
) -> Result<Face> {
    let Surfaces {
        skin: extracted,
        skull,
        axis,
        r0,
        mut report,
    } = surfaces;
    // The C1 models' resolution for a skin cut from another program: see `coarsen`.
    let mut c1_target = None;
    let (skin, registration) = match scan {
        None => (extracted, None),
        Some(scan) => {
            let (m, t, outer) = rec.time(Stage::PlaceScan, "placing the face scan", || {
                place_scan(scan, ct, case, axis, r0)
            })?;
            if let Some(o) = outer {
                rec.warn(o.summary(scan_path(case)));
                report.foreign_skin = Some(o);
            }
            let st =
                crate::compare::stats(&crate::compare::point_to_surface(&m.vertices, &extracted));
            if st.p90 > 3.0 {
                rec.warn(format!(
                    "face scan is {:.1} mm (90th percentile) from the CT skin: check the registration",
                    st.p90
                ));
            }
            report.scan_to_ct_skin_mm = Some(st);
            if report.foreign_skin.is_some() && case.solve.model.on_springs() {
                c1_target = Some(extracted.triangles.len());
            }
            (m, t)
        }
    };
    let (skin, fine) = coarsen(skin, case, c1_target, &mut report, rec)?;
    Ok(Face {
        skin,
        skull,
        fine,
        axis,
        r0,
        registration,
        report,
    })
}

fn scan_path(case: &Case) -> &Path {
    case.skin
        .as_ref()
        .map_or(Path::new("face scan"), |s| &s.path)
}

/// The fewest triangles the outer face cut from another program's skin may keep.
const MIN_CUT_FACE_TRIANGLES: usize = 100;

/// A face scan into the CT frame (`[registration]` landmarks), cut to its outer face when it is
/// another program's whole iso-surface rather than a clean face (surface::outer), checked to
/// overlap the CT, with the (u, v) coordinates of the case's parameterisation.
fn place_scan(
    mut m: Mesh,
    ct: &Volume,
    case: &Case,
    axis: [f64; 2],
    r0: f64,
) -> Result<(Mesh, Option<register::Transform>, Option<OuterReport>)> {
    let mut registration = None;
    if let Some(reg) = &case.registration {
        let t = register::fit(&reg.scan, &reg.ct, reg.scale)?;
        for v in &mut m.vertices {
            *v = t.apply(*v);
        }
        registration = Some(t);
    }
    let mut outer_report = None;
    if !outer::is_clean_face(&m) {
        let (kept, rep) = outer::outer_face(&m, axis, scan_path(case))?;
        // What is left of a broken file must still be a face, not a few stray triangles.
        if kept.triangles.len() < MIN_CUT_FACE_TRIANGLES {
            return Err(Error::input(
                scan_path(case),
                format!(
                    "not usable as a face scan: {}; {} triangles are too few (at least {MIN_CUT_FACE_TRIANGLES})",
                    rep.summary(scan_path(case)),
                    kept.triangles.len()
                ),
            ));
        }
        m = kept;
        outer_report = Some(rep);
    }
    m.check(scan_path(case))?;
    let (lo, hi) = ct.bounds();
    let inside = m
        .vertices
        .iter()
        .filter(|v| (0..3).all(|a| v[a] >= lo[a] && v[a] <= hi[a]))
        .count();
    if (inside as f64) < 0.5 * m.vertices.len() as f64 {
        return Err(Error::input(
            scan_path(case),
            format!(
                "face scan does not overlap the CT: only {inside} of {} vertices lie inside the CT's field of view (missing or wrong [registration]?)",
                m.vertices.len()
            ),
        ));
    }
    match case.surface.parameterization {
        Parameterization::Cylindrical => surface::cylindrical_uv(&mut m, axis, r0),
        Parameterization::Planar => surface::planar_uv(&mut m),
    }
    Ok((m, registration, outer_report))
}

/// A skin with more than twice `[solve] coarse_triangles` triangles is solved on a (u, v)-grid
/// resampling of it; returns (the skin to model, the full skin when coarsened).
///
/// `c1_target`: a C1 model on a skin cut from another program's iso-surface, with
/// `coarse_triangles` unset, is solved at the resolution of the skin facesim makes from the CT
/// itself (its triangle count). The C1 models are defined on that range-scan grid: Koch's struts
/// stiffen tangential motion in proportion to the mesh, and on a voxel-fine iso-surface (0.5 mm
/// edges, ragged rims) the equilibrium Newton solve does not converge (docs/design/pipeline.md "A skin
/// from another program").
fn coarsen(
    skin: Mesh,
    case: &Case,
    c1_target: Option<usize>,
    report: &mut SurfaceReport,
    rec: &mut Recorder,
) -> Result<(Mesh, Option<Mesh>)> {
    let target = match (case.solve.coarse_triangles, c1_target) {
        (0, Some(n)) if skin.triangles.len() > 2 * n => {
            rec.warn(format!(
                "the {} model is solved on a {n}-triangle (u, v) resampling of the cut skin (the resolution of the skin facesim scans from the CT) and the whole cut skin is carried along; set [solve] coarse_triangles to choose another",
                case.solve.model.name()
            ));
            n
        }
        (n, _) => n,
    };
    if target == 0 || skin.triangles.len() <= 2 * target {
        rec.skip(
            Stage::Coarsen,
            if target == 0 {
                "[solve] coarse_triangles = 0".to_string()
            } else {
                format!(
                    "the skin has {} triangles, not more than twice [solve] coarse_triangles",
                    skin.triangles.len()
                )
            },
        );
        return Ok((skin, None));
    }
    let coarse = rec.time(Stage::Coarsen, "coarsening the skin", || {
        Ok(surface::resample_uv(&skin, target)
            .filter(|m| m.check(Path::new("coarse skin")).is_ok() && surface::uv_folds(m) == 0))
    })?;
    match coarse {
        Some(c) => {
            report.coarse = Some(CoarseReport {
                triangles: c.triangles.len(),
                vertices: c.vertices.len(),
                fine_triangles: skin.triangles.len(),
                fine_vertices: skin.vertices.len(),
            });
            Ok((c, Some(skin)))
        }
        None => {
            rec.warn(format!(
                "[solve] coarse_triangles = {target}: could not resample the {}-triangle skin on a (u, v) grid; solved on the full skin",
                skin.triangles.len()
            ));
            Ok((skin, None))
        }
    }
}

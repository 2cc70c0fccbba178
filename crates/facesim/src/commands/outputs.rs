//! The one module that writes a run's files (docs/reference/case.md "Outputs"): each to a temporary name and
//! renamed, independent files in parallel, report.json last.

use crate::case::Case;
use crate::error::{Error, Result};
use crate::mesh::{self, Mesh};
use crate::model::Prediction;
use crate::output::write_bytes_atomic;
use crate::pipeline::stage::Stage;
use crate::pipeline::{Recorder, Scene};
use crate::report::Report;
use crate::volume;
use std::path::Path;

/// Viridis colour map (matplotlib's, 9 control points, linear in between) at t ∈ [0, 1].
pub(crate) fn viridis(t: f64) -> [u8; 3] {
    const C: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [71.0, 44.0, 122.0],
        [59.0, 81.0, 139.0],
        [44.0, 113.0, 142.0],
        [33.0, 144.0, 141.0],
        [39.0, 173.0, 129.0],
        [92.0, 200.0, 99.0],
        [170.0, 220.0, 50.0],
        [253.0, 231.0, 37.0],
    ];
    let x = t.clamp(0.0, 1.0) * 8.0;
    let i = (x.floor() as usize).min(7);
    let f = x - i as f64;
    [0, 1, 2].map(|k| (C[i][k] + f * (C[i + 1][k] - C[i][k])).round() as u8)
}

/// |x_post − x_pre| per vertex of the skin `pre` and the predicted face `post` (mm).
pub fn displacement(pre: &Mesh, post: &Mesh) -> Vec<f64> {
    pre.vertices
        .iter()
        .zip(&post.vertices)
        .map(|(a, b)| crate::vec3::norm(crate::vec3::sub(*a, *b)))
        .collect()
}

fn max_of(d: &[f64]) -> f64 {
    d.iter().cloned().fold(0.0, f64::max)
}

/// The predicted face `post` coloured by its displacement (viridis, 0 → max) with a
/// `displacement` vertex column.
pub fn coloured_face(post: &Mesh, dist: &[f64]) -> Mesh {
    let dmax = max_of(dist);
    let mut m = post.clone();
    m.colors = Some(
        dist.iter()
            .map(|d| viridis(if dmax > 0.0 { d / dmax } else { 0.0 }))
            .collect(),
    );
    m.vertex_columns.push(mesh::Column {
        name: "displacement".into(),
        values: dist.to_vec(),
    });
    m
}

/// displacement.csv: per vertex of the skin `pre`, its place before and on `post`, and `dist`.
pub(crate) fn displacement_csv(dest: &Path, pre: &Mesh, post: &Mesh, dist: &[f64]) -> Result<()> {
    write_bytes_atomic(dest, |w| {
        writeln!(w, "vertex,x_pre,y_pre,z_pre,x_post,y_post,z_post,dist")?;
        for (i, (a, b)) in pre.vertices.iter().zip(&post.vertices).enumerate() {
            writeln!(
                w,
                "{i},{},{},{},{},{},{},{}",
                a[0], a[1], a[2], b[0], b[1], b[2], dist[i]
            )?;
        }
        Ok(())
    })
}

/// The predicted face as VTK XML PolyData: point data `displacement_mm` (x_post − x_pre, 3
/// components, LPS mm) and `displacement_magnitude_mm` (its length).
pub(crate) fn write_face_vtp(p: &Prediction, dist: &[f64], path: &Path) -> Result<()> {
    let vector = p
        .skin
        .vertices
        .iter()
        .zip(&p.face_post.vertices)
        .flat_map(|(a, b)| crate::vec3::sub(*b, *a))
        .collect();
    let arrays = [
        mesh::vtk::PointArray {
            name: "displacement_mm".into(),
            components: 3,
            values: vector,
        },
        mesh::vtk::PointArray {
            name: "displacement_magnitude_mm".into(),
            components: 1,
            values: dist.to_vec(),
        },
    ];
    mesh::vtp::write_vtp(&p.face_post, &arrays, path)
}

/// Every output file but report.json, into `dir` (created if needed); `dist` is
/// [`displacement`] of `p`.
pub fn write(
    dir: &Path,
    scene: &Scene,
    p: &Prediction,
    dist: &[f64],
    case: &Case,
    rec: &mut Recorder,
) -> Result<()> {
    rec.time(Stage::Write, "writing outputs", || {
        write_files(dir, scene, p, dist, case)
    })
}

fn write_files(dir: &Path, scene: &Scene, p: &Prediction, dist: &[f64], case: &Case) -> Result<()> {
    crate::output::create_dir_guarded(dir)?;
    let coloured = coloured_face(&p.face_post, dist);
    let skull = &scene.face.skull;
    let mut skull_post = skull.clone();
    skull_post.vertices = scene.model.plan.apply(&skull.vertices, 1.0).0;
    // The files are independent (each written to a temporary name and renamed), so they are
    // written in parallel; the first error is reported.
    type Job<'a> = Box<dyn FnOnce() -> Result<()> + Send + Sync + 'a>;
    let o = dir;
    let jobs: Vec<Job> = vec![
        Box::new(|| mesh::write_mesh(&p.face_post, &o.join("face_post.obj"))),
        Box::new(|| mesh::write_mesh(&p.face_post, &o.join("face_post.ply"))),
        // For 3D Slicer and other VTK programs: VTK PolyData with the displacement, and STL.
        Box::new(|| write_face_vtp(p, dist, &o.join("face_post.vtp"))),
        Box::new(|| {
            mesh::stl::write(
                &p.face_post,
                &o.join("face_post.stl"),
                "facesim face_post SPACE=LPS",
            )
        }),
        Box::new(|| mesh::write_mesh(&coloured, &o.join("face_displacement.ply"))),
        Box::new(|| mesh::write_mesh(&skull_post, &o.join("skull_post.ply"))),
        // The model's own files: springs (C1) or the tetrahedral mesh.
        Box::new(|| p.write_model_files(o, scene, case)),
        Box::new(|| displacement_csv(&o.join("displacement.csv"), &p.skin, &p.face_post, dist)),
        Box::new(|| match &p.basis {
            Some(b) => crate::plan::file::write(&o.join(crate::plan::file::FILE_NAME), b),
            None => Ok(()),
        }),
        Box::new(|| mesh::write_mesh(&p.skin, &o.join("face_pre.obj"))),
        Box::new(|| mesh::write_mesh(&p.skin, &o.join("face_pre.ply"))),
        Box::new(|| mesh::write_mesh(skull, &o.join("skull_pre.ply"))),
        Box::new(|| {
            volume::nifti_io::write_labels(&scene.vol, &scene.seg.labels, &o.join("labels.nii.gz"))
        }),
    ];
    let mut jobs = jobs;
    // The segments `[[surgery]]` cut: each as the skull surface it moves and as a voxel mask.
    for planned in scene.anatomy.iter().flat_map(|a| &a.planned) {
        jobs.push(Box::new(move || {
            let region = planned.segment.region("");
            let keep: Vec<bool> = skull.vertices.iter().map(|v| region.contains(*v)).collect();
            let mut part = skull.sub_mesh(&keep);
            // One colour per kind, so that the segments tell apart in a viewer.
            let colour = match planned.what {
                "le-fort-i" => [230, 140, 40],
                "genioplasty" => [60, 170, 90],
                _ => [60, 120, 220],
            };
            part.colors = Some(vec![colour; part.vertices.len()]);
            mesh::write_mesh(&part, &o.join(format!("segment_{}.ply", planned.name)))
        }));
        jobs.push(Box::new(move || {
            volume::nifti_io::write(
                &planned.segment.mask,
                &o.join(format!("segment_{}.nii.gz", planned.name)),
            )
        }));
    }
    use rayon::prelude::*;
    jobs.into_par_iter()
        .map(|j| j())
        .collect::<Result<Vec<()>>>()?;
    Ok(())
}

/// The page's re-planning data from the run's plan basis; None (sliders hidden, the page says
/// why) without a basis or when the basis has a constant term the page does not carry.
pub(crate) fn page_basis(p: &Prediction, case: &Case) -> Option<crate::report_page::PageBasis> {
    let b = p.basis.as_ref()?;
    if b.offset.is_some() {
        return None;
    }
    let segments = b
        .segments
        .iter()
        .map(|s| {
            let o = case.osteotomy.iter().find(|o| o.name == s.name)?;
            Some(crate::report_page::PageSegment {
                name: s.name.clone(),
                pivot: s.pivot,
                translate: o.translate,
                rotate_deg: o.rotate_deg,
                columns: s.columns.clone(),
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some(crate::report_page::PageBasis {
        label: if b.exact { "exact" } else { "linear preview" }.into(),
        segments,
    })
}

/// report.html (docs/guide/report-page.md): the face and skull before and after, report.json's key
/// figures and warnings; re-planning sliders once the run has a plan basis.
#[allow(clippy::too_many_arguments)]
pub(crate) fn write_page(
    dir: &Path,
    scene: &Scene,
    p: &Prediction,
    report: &Report,
    basis: Option<crate::report_page::PageBasis>,
    analysis: &crate::landmarks::Analysis,
    band_width: Option<&[f64]>,
    reduced: Option<&crate::model::reduced::file::StoredReduced>,
) -> Result<()> {
    let case = &scene.case;
    let skull = &scene.face.skull;
    let skull_post = scene.model.plan.apply(&skull.vertices, 1.0).0;
    // The segment that moves each skull vertex (the last whose region holds it; 255: none).
    let skull_segment = skull
        .vertices
        .iter()
        .map(|v| {
            case.osteotomy
                .iter()
                .rposition(|o| o.region.contains(*v))
                .map_or(255, |i| i.min(254) as u8)
        })
        .collect();
    let model = serde_json::to_value(case.solve.model)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default();
    let c = &report.counts;
    let d = &report.displacement;
    let mut figures = vec![
        ("model".to_string(), model.clone()),
        ("face displacement max".into(), format!("{:.2} mm", d.max)),
        ("face displacement mean".into(), format!("{:.2} mm", d.mean)),
        (
            "skin vertices / triangles".into(),
            format!("{} / {}", c.skin_vertices, c.skin_triangles),
        ),
        (
            "skull vertices / triangles".into(),
            format!("{} / {}", c.skull_vertices, c.skull_triangles),
        ),
        ("CT voxels".into(), format!("{:?}", c.dims)),
        ("unknowns".into(), c.unknowns.to_string()),
    ];
    if let Some(e) = &report.discretisation_error {
        figures.push((
            "discretisation error (estimate)".into(),
            face_stats_line(&e.moving_face, &e.regions),
        ));
    }
    if let Some(e) = &report.nonlinear_vs_linear {
        figures.push((
            "neo-Hookean vs linear".into(),
            face_stats_line(&e.moving_face, &e.regions),
        ));
    }
    let clinical_frame: Option<crate::report_page::PageClinicalFrame> =
        report.clinical_frame.as_ref().map(Into::into);
    for o in &case.osteotomy {
        let text = match &report.clinical_frame {
            Some(c) => {
                let m = crate::anatomy::moves::read_back(
                    &c.frame(),
                    crate::osteotomy::rotation(o.rotate_deg),
                    o.translate,
                );
                format!(
                    "advance {:.1}, up {:.1}, left {:.1} mm; pitch {:.1}, roll {:.1}, yaw {:.1}°",
                    m.advance_mm, m.up_mm, m.left_mm, m.pitch_deg, m.roll_deg, m.yaw_deg
                )
            }
            None => format!("translate {:?} mm, rotate {:?}°", o.translate, o.rotate_deg),
        };
        figures.push((format!("plan: {}", o.name), text));
    }
    for (stage, cost) in &report.costs.0 {
        figures.push((
            format!("time: {}", stage.key()),
            format!("{:.2} s", cost.wall_s),
        ));
    }
    let data = crate::report_page::PageData {
        title: report.name.clone(),
        model,
        face_pre: &p.skin.vertices,
        face_post: &p.face_post.vertices,
        face_triangles: &p.skin.triangles,
        skull_pre: &skull.vertices,
        skull_post: &skull_post,
        skull_triangles: &skull.triangles,
        segments: case.osteotomy.iter().map(|o| o.name.clone()).collect(),
        skull_segment,
        colour_scale_mm: d.colour_scale_mm,
        figures,
        warnings: report.warnings.clone(),
        basis,
        landmarks: page_landmarks(analysis, case),
        missing_landmarks: analysis
            .landmarks
            .iter()
            .filter_map(|l| l.missing.clone().map(|m| (l.label.clone(), m)))
            .collect(),
        region_names: crate::landmarks::face_regions::NAMES
            .iter()
            .map(|s| s.to_string())
            .collect(),
        region_of: analysis.region_of.clone(),
        measurements: serde_json::to_value(&report.measurements).unwrap_or_default(),
        ratios: serde_json::to_value(&report.soft_hard_ratios).unwrap_or_default(),
        published: serde_json::to_value(&report.published_ratios).unwrap_or_default(),
        band_width: band_width.map(<[f64]>::to_vec),
        uncertainty: serde_json::to_value(&report.uncertainty).unwrap_or_default(),
        no_basis_reason: "No plan basis was stored with this run, so the page cannot re-plan: \
                          run `facesim replan` for other plans."
            .into(),
        head_frame: analysis.frame.as_ref().map(Into::into),
        clinical_frame,
        tissue: reduced.map(|r| page_tissue(r, analysis, case)),
    };
    crate::report_page::write_report_html(dir, &data)
}

/// The tissue sliders' data from the run's reduced models (docs/guide/report-page.md "Tissue
/// sliders"): the models, the run's materials and the `[uncertainty]` ranges they were trained
/// on (the sliders' ranges), and the soft landmarks their output gains belong to.
fn page_tissue<'a>(
    r: &'a crate::model::reduced::file::StoredReduced,
    analysis: &crate::landmarks::Analysis,
    case: &Case,
) -> crate::report_page::PageTissue<'a> {
    let parameters: serde_json::Map<String, serde_json::Value> = case
        .uncertainty
        .parameters(case.solve.model)
        .into_iter()
        .map(|(p, d)| {
            (
                p.key().to_string(),
                serde_json::to_value(d).unwrap_or_default(),
            )
        })
        .collect();
    crate::report_page::PageTissue {
        tissues: r.tissues,
        sliding: r.sliding,
        sliding_matters: r.sliding_matters,
        parameters: parameters.into(),
        landmarks: crate::uncertainty::reduced::landmark_output_labels(analysis),
        models: r
            .models
            .iter()
            .map(|m| crate::report_page::PageReduced {
                sliding: m.sliding,
                form: &m.form,
                terms: &m.terms,
                theta_box: &m.theta_box,
                face_bound: &m.face_bound,
                output_bounds: &m.output_bounds,
                duals: &m.duals,
                face: &m.face,
            })
            .collect(),
    }
}

/// The page's landmarks: soft ones with their anchor on face_pre, bony ones with the segment
/// that moves them (the last whose region holds them, as for the skull's vertices).
fn page_landmarks(
    a: &crate::landmarks::Analysis,
    case: &Case,
) -> Vec<crate::report_page::PageLandmark> {
    a.landmarks
        .iter()
        .zip(&a.anchors)
        .zip(&a.carried)
        .filter_map(|((l, anchor), c)| {
            let pre = l.position?;
            Some(crate::report_page::PageLandmark {
                label: l.label.clone(),
                pre,
                post: c.post?,
                anchor: *anchor,
                segment: case
                    .osteotomy
                    .iter()
                    .rposition(|o| o.region.contains(pre))
                    .map_or(255, |i| i.min(254) as u8),
            })
        })
        .collect()
}

pub(crate) fn write_report(dir: &Path, report: &Report) -> Result<()> {
    let text = serde_json::to_string_pretty(report).map_err(|e| Error::output(dir, e))?;
    write_bytes_atomic(&dir.join("report.json"), |w| w.write_all(text.as_bytes()))
}

/// "mean … mm, p90 … mm on the moving face; per region (mean, mm): …" for a per-face-vertex
/// distance in mm (the discretisation estimate, the nonlinear-vs-linear difference).
fn face_stats_line(
    moving: &crate::landmarks::face_regions::RegionStats,
    regions: &crate::landmarks::Ordered<crate::landmarks::face_regions::RegionStats>,
) -> String {
    let mm = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.2}"));
    let per: Vec<String> = regions
        .0
        .iter()
        .filter(|(_, r)| r.mean.is_some())
        .map(|(n, r)| format!("{n} {}", mm(r.mean)))
        .collect();
    format!(
        "mean {} mm, p90 {} mm on the moving face; per region (mean, mm): {}",
        mm(moving.mean),
        mm(moving.p90),
        if per.is_empty() {
            "none found".into()
        } else {
            per.join(", ")
        }
    )
}

//! `facesim run`: the pipeline stages in order, with timings and a report.
//!
//! Implemented stages: read CT → segment → surfaces (or a registered face scan) → write.
//! Springs, the C1 FEM and the solve are the next stages (issues 3–4); the report says so.

use crate::case::{Case, ExtractMethod, Region};
use crate::error::{Error, Result};
use crate::mesh::{self, Mesh};
use crate::observe::Observer;
use crate::segment::{self, Segmentation};
use crate::surface::{self, marching, rangescan, register};
use crate::volume::{self, Volume};
use serde::Serialize;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

#[derive(Default, Serialize)]
pub struct Report {
    pub name: String,
    pub case: String,
    pub facesim_version: String,
    /// Stage → wall time (s), in pipeline order.
    pub timings: serde_json::Map<String, Value>,
    /// Stage → wall time, CPU time (all threads) and peak heap above the stage's start.
    pub stage_costs: serde_json::Map<String, Value>,
    pub counts: serde_json::Map<String, Value>,
    pub segmentation: Option<segment::SegmentReport>,
    pub surfaces: serde_json::Map<String, Value>,
    pub registration: Option<register::Transform>,
    pub parameters: Option<Case>,
    pub springs: Option<crate::springs::SpringReport>,
    pub solve: Option<Vec<crate::solve::StepRecord>>,
    /// Displacement |x_post − x_pre| over the skin (mm): max, mean, and the colour scale of
    /// face_displacement.ply (viridis, 0 → max).
    pub displacement: serde_json::Map<String, Value>,
    pub warnings: Vec<String>,
    pub stages_not_run: Vec<String>,
}

impl Report {
    fn record(&mut self, stage: &str, c: crate::meter::StageCost) {
        self.timings.insert(stage.into(), json!(c.wall_s));
        self.stage_costs
            .insert(stage.into(), serde_json::to_value(c).unwrap_or(Value::Null));
    }
}

/// Everything the pipeline produced so far (kept in memory for tests and later stages).
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

struct Timer<'a> {
    report: &'a mut Report,
    obs: &'a dyn Observer,
}

impl Timer<'_> {
    fn time<T>(&mut self, stage: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let m = crate::meter::Meter::start(self.obs.heap());
        let r = f()?;
        let c = m.stop();
        self.obs.finished(stage, &c);
        self.report.record(stage, c);
        Ok(r)
    }
}

/// Viridis colour map (matplotlib's, 9 control points, linear in between) at t ∈ [0, 1].
pub fn viridis(t: f64) -> [u8; 3] {
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

/// Drop connected pieces with fewer than `min_fraction` of the triangles (range-scan islands
/// at the edge of the field of view, stray iso-surface bits). Returns how many were dropped.
fn drop_small_components(m: &mut Mesh, min_fraction: f64) -> usize {
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

fn check_regions_masks(case: &Case) -> Result<()> {
    let masks = case
        .surface
        .movable
        .iter()
        .chain(case.osteotomy.iter().map(|o| &o.region));
    for r in masks {
        if let Region::Mask(p) = r
            && !p.is_file()
        {
            return Err(Error::input(p, "region mask file not found"));
        }
    }
    Ok(())
}

/// Per vertex: true when it lies outside `[surface] movable` (rigid skin); all false without a
/// movable region.
pub fn rigid_mask(case: &Case, vertices: &[[f64; 3]]) -> Vec<bool> {
    vertices
        .iter()
        .map(|p| match &case.surface.movable {
            Some(r) => !crate::osteotomy::inside(r, None, *p),
            None => false,
        })
        .collect()
}

/// Everything the models need, before any solve: the CT, its tissues, the skin (extracted or
/// the registered scan) and skull, the springs, the bone-move plan, the rigid skin vertices and
/// the solver parameters. `run` and `facesim study` share it.
pub struct Scene {
    pub vol: Volume,
    pub seg: Segmentation,
    pub skin: Mesh,
    pub skull: Mesh,
    pub springs: crate::springs::SpringSet,
    pub spring_report: crate::springs::SpringReport,
    pub plan: crate::osteotomy::Plan,
    pub rigid: Vec<bool>,
    pub params: crate::solve::Params,
    /// Cylinder axis (x, y) and radius of the (u, v) parameterisation.
    pub axis: [f64; 2],
    pub r0: f64,
    /// The skin as given, when the models run on a coarse copy of it (`skin`) and it is carried
    /// along by shell embedding ([solve] coarse_triangles).
    pub fine: Option<Mesh>,
}

/// Stages 1–4 (read, segment, extract, springs) and the plan; timings, surface facts and
/// warnings go into `report`.
pub fn prepare(case: &Case, obs: &dyn Observer, report: &mut Report) -> Result<Scene> {
    check_regions_masks(case)?;
    if let Some(skin) = &case.skin
        && !skin.path.is_file()
    {
        return Err(Error::input(&skin.path, "face scan not found"));
    }
    let mut timer = Timer { report, obs };
    obs.started("reading CT");
    let vol = timer.time("read_ct", || volume::read_volume(&case.ct.path))?;
    obs.started("segmenting tissues");
    let seg = timer.time("segment", || {
        segment::segment(&vol, &case.tissue, &case.ct.path)
    })?;

    obs.started("extracting surfaces");
    let mut warnings = seg.report.warnings.clone();
    let mut surf = serde_json::Map::new();
    // The cleaned bone field serves the skull surface and, later, the spring tracer.
    let bone_field = seg.bone_field(&vol);
    let (mut skin, mut skull, axis, r0) = timer.time("surfaces", || {
        let skin_field = seg.skin_field(&vol);
        let iso_skin = seg.windows.head_threshold as f32;
        let iso_bone = seg.windows.bone as f32;
        match case.extract.method {
            ExtractMethod::Rangescan => {
                let z_step = if case.extract.z_step_mm > 0.0 { case.extract.z_step_mm } else { vol.spacing[2] };
                let r = rangescan::scan(
                    &vol,
                    &skin_field,
                    &bone_field,
                    &seg.head,
                    &rangescan::ScanParams {
                        angle_step_deg: case.extract.angle_step_deg,
                        z_step,
                        skin_iso: iso_skin,
                        bone_iso: iso_bone,
                        max_skull_depth: case.springs.max_length_mm,
                    },
                );
                surf.insert("method".into(), json!("rangescan"));
                surf.insert("rays".into(), json!(r.rays));
                surf.insert("skin_misses".into(), json!(r.skin_misses));
                surf.insert("skull_misses".into(), json!(r.skull_misses));
                surf.insert("axis_xy".into(), json!(r.axis));
                surf.insert("r0".into(), json!(r.r0));
                if r.skull_misses > 0 {
                    warnings.push(format!(
                        "{} range-scan rays found skin but no bone within {} mm (bone defect, thin bone, or the scan's edge)",
                        r.skull_misses, case.springs.max_length_mm
                    ));
                }
                Ok((r.skin, r.skull, r.axis, r.r0))
            }
            ExtractMethod::Marching => {
                let mut skin = marching::extract(&vol, &skin_field, iso_skin);
                let mut skull = marching::extract(&vol, &bone_field, iso_bone);
                // The skin is one surface; skull pieces above 1% are kept (a separate mandible
                // is a real piece).
                let dropped = drop_small_components(&mut skin, 1.0);
                if dropped > 0 {
                    warnings.push(format!("skin iso-surface: dropped {dropped} pieces besides the largest"));
                }
                let (lo, hi) = vol.bounds();
                let axis = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
                let r0 = 0.25 * ((hi[0] - lo[0]) + (hi[1] - lo[1]));
                surface::cylindrical_uv(&mut skin, axis, r0);
                surface::cylindrical_uv(&mut skull, axis, r0);
                surf.insert("method".into(), json!("marching"));
                Ok((skin, skull, axis, r0))
            }
        }
    })?;
    for (m, name) in [(&mut skin, "skin"), (&mut skull, "skull")] {
        let dropped = drop_small_components(m, 0.01);
        surf.insert(format!("{name}_islands_dropped"), json!(dropped));
    }
    timer.time("smooth_decimate", || {
        for (m, name) in [(&mut skin, "skin"), (&mut skull, "skull")] {
            surface::taubin_smooth(m, case.extract.smooth_iterations);
            if case.extract.decimate_target > 0 {
                let before = m.clone();
                let err = surface::decimate(
                    m,
                    case.extract.decimate_target,
                    case.extract.decimate_max_error_mm,
                );
                // Edge collapse is not guaranteed to keep a mesh manifold (thin iso-surface
                // features can pinch); a broken result is not used.
                if let Err(e) = m.check(Path::new(name)) {
                    warnings.push(format!("decimation of the {name} was undone: {e}"));
                    *m = before;
                } else {
                    surf.insert(format!("{name}_decimation_error_mm"), json!(err));
                }
            }
        }
        Ok(())
    })?;
    if case.surface.parameterization == crate::case::Parameterization::Planar {
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
    surf.insert(
        "extracted_skin_components".into(),
        json!(skin.components().1),
    );
    surf.insert("skull_components".into(), json!(skull.components().1));

    // A given face scan replaces the extracted skin (after registration).
    let mut registration = None;
    if let Some(scan) = &case.skin {
        obs.started("reading face scan");
        let extracted = skin.clone();
        skin = timer.time("read_scan", || {
            let mut m = mesh::read_mesh(&scan.path)?;
            if let Some(reg) = &case.registration {
                let t = register::fit(&reg.scan, &reg.ct, reg.scale)?;
                for v in &mut m.vertices {
                    *v = t.apply(*v);
                }
                registration = Some(t);
            }
            let (lo, hi) = vol.bounds();
            let inside = m.vertices.iter().filter(|v| (0..3).all(|a| v[a] >= lo[a] && v[a] <= hi[a])).count();
            if (inside as f64) < 0.5 * m.vertices.len() as f64 {
                return Err(Error::input(
                    &scan.path,
                    format!(
                        "face scan does not overlap the CT: only {inside} of {} vertices lie inside the CT's field of view (missing or wrong [registration]?)",
                        m.vertices.len()
                    ),
                ));
            }
            match case.surface.parameterization {
                crate::case::Parameterization::Cylindrical => surface::cylindrical_uv(&mut m, axis, r0),
                crate::case::Parameterization::Planar => surface::planar_uv(&mut m),
            }
            Ok(m)
        })?;
        let d = crate::compare::point_to_surface(&skin.vertices, &extracted);
        let st = crate::compare::stats(&d);
        if st.p90 > 3.0 {
            warnings.push(format!(
                "face scan is {:.1} mm (90th percentile) from the CT skin: check the registration",
                st.p90
            ));
        }
        surf.insert(
            "scan_to_ct_skin_mm".into(),
            serde_json::to_value(st).unwrap_or(Value::Null),
        );
    }
    timer.report.registration = registration;

    // A dense skin is solved on a coarse copy and carried along afterwards (issue 6).
    let target = case.solve.coarse_triangles;
    let mut fine = None;
    if target > 0 && skin.triangles.len() > 2 * target {
        obs.started("coarsening the skin");
        let coarse = timer.time("coarsen", || {
            Ok(surface::resample_uv(&skin, target)
                .filter(|m| m.check(Path::new("coarse skin")).is_ok() && surface::uv_folds(m) == 0))
        })?;
        match coarse {
            Some(c) => {
                surf.insert(
                    "coarse".into(),
                    json!({"triangles": c.triangles.len(), "vertices": c.vertices.len(),
                           "fine_triangles": skin.triangles.len(), "fine_vertices": skin.vertices.len()}),
                );
                fine = Some(std::mem::replace(&mut skin, c));
            }
            None => warnings.push(format!(
                "[solve] coarse_triangles = {target}: could not resample the {}-triangle skin on a (u, v) grid; solved on the full skin",
                skin.triangles.len()
            )),
        }
    }
    let rigid = rigid_mask(case, &skin.vertices);
    obs.started("tracing springs");
    let meter = crate::meter::Meter::start(obs.heap());
    let want = crate::springs::wanted(&rigid, case.solve.restrict);
    let springs = crate::springs::trace(
        &skin,
        &vol,
        &seg,
        &bone_field,
        &case.springs,
        &case.tissue.stiffness,
        want.as_deref(),
    );
    drop(bone_field);
    timer.report.record("springs", meter.stop());
    let spring_report = springs.report(&skin);
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
        let places: Vec<String> = spring_report
            .miss_regions
            .iter()
            .take(3)
            .map(|r| {
                format!(
                    "{} around ({:.0}, {:.0}, {:.0})",
                    r.vertices, r.centroid[0], r.centroid[1], r.centroid[2]
                )
            })
            .collect();
        warnings.push(format!(
            "{} skin vertices found no bone within {} mm (no spring); largest patches (LPS mm): {}",
            spring_report.misses,
            case.springs.max_length_mm,
            places.join("; ")
        ));
    }
    let plan = crate::osteotomy::Plan::new(&case.osteotomy)?;
    plan.check_selects(
        &springs.attachments,
        if want.is_some() {
            "spring attachments under the movable skin ([surface] movable)"
        } else {
            "spring attachments"
        },
    )?;
    let params = crate::solve::Params {
        model: case.solve.model,
        steps: case.solve.steps,
        alpha: case.surface.alpha,
        beta: case.surface.beta,
        regions: case.surface.regions.clone(),
        k_c: if case.solve.model == crate::case::SolveModel::Koch1996 {
            case.solve.koch_k_c
        } else {
            case.solve.k_c
        },
        tolerance: 1e-6,
        max_iterations: 30,
        restrict: case.solve.restrict,
    };
    timer.report.surfaces = surf;
    timer.report.warnings = warnings;
    Ok(Scene {
        vol,
        seg,
        skin,
        skull,
        springs,
        spring_report,
        plan,
        rigid,
        params,
        axis,
        r0,
        fine,
    })
}

pub fn run(case_path: &Path, out: Option<&Path>, obs: &dyn Observer) -> Result<Outcome> {
    let total = crate::meter::Meter::start(obs.heap());
    let (case, dir) = Case::load(case_path)?;
    let out_dir = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| dir.join("out"));
    let mut report = Report {
        name: case.name.clone().unwrap_or_else(|| {
            dir.file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default()
        }),
        case: dir.display().to_string(),
        facesim_version: env!("CARGO_PKG_VERSION").into(),
        ..Default::default()
    };
    let Scene {
        vol,
        seg,
        skin,
        skull,
        springs,
        spring_report,
        plan,
        rigid,
        params,
        fine,
        ..
    } = prepare(&case, obs, &mut report)?;
    let mut warnings = std::mem::take(&mut report.warnings);
    obs.started("solving");
    let meter = crate::meter::Meter::start(obs.heap());
    // No bone moves: the preloaded skin is an equilibrium by construction (F_init = K a_init),
    // so the prediction is the pre-operative face; skip the factorisation.
    let sol = if plan.is_empty() {
        warnings.push(
            "no [[osteotomy]] in the case: the predicted face is the pre-operative face".into(),
        );
        None
    } else {
        // An impossible plan is the case file's fault, a surface the model cannot use is its
        // source's: name them.
        let case_file = if case_path.is_dir() {
            case_path.join("case.toml")
        } else {
            case_path.to_path_buf()
        };
        let skin_source = case.skin.as_ref().map_or(&case.ct.path, |s| &s.path);
        Some(
            crate::solve::solve(&skin, &springs, &plan, &rigid, &params).map_err(|e| match e {
                Error::ImpossiblePlan { .. } => e.in_file(&case_file),
                other => other.in_file(skin_source),
            })?,
        )
    };
    report.record("solve", meter.stop());
    let mut face_post = skin.clone();
    if let Some(sol) = &sol {
        face_post.vertices = sol.positions.clone();
    }
    // The coarse model's answer carried to the full skin (paper 002); from here on `skin` is
    // the full skin again and `coarse` the mesh that was solved, if it differs.
    let (skin, coarse) = match fine {
        None => (skin, None),
        Some(fine) => {
            obs.started("carrying the full skin along");
            let meter = crate::meter::Meter::start(obs.heap());
            let (carried, e) = crate::embed::Shell::carry_skin(
                &skin,
                &face_post.vertices,
                &fine.vertices,
                (&vol, &seg.labels),
                &case.solve,
                &rigid,
            )?;
            // Fine vertices outside [surface] movable are rigid, exactly as in a full solve.
            let mut post = fine.clone();
            for ((p, c), r) in post
                .vertices
                .iter_mut()
                .zip(carried)
                .zip(rigid_mask(&case, &fine.vertices))
            {
                if !r {
                    *p = c;
                }
            }
            let st = crate::compare::stats(&e.distance);
            report.surfaces.insert(
                "embedding".into(),
                json!({"shell_mm": case.solve.shell_mm, "poisson": case.solve.shell_poisson,
                       "fine_to_coarse_mm": st}),
            );
            face_post = post;
            report.record("embed", meter.stop());
            (fine, Some(skin))
        }
    };
    let embedded = coarse.is_some();
    let solved_skin = coarse.as_ref().unwrap_or(&skin);
    face_post.colors = None;
    let dist: Vec<f64> = skin
        .vertices
        .iter()
        .zip(&face_post.vertices)
        .map(|(a, b)| mesh::norm(mesh::sub(*a, *b)))
        .collect();
    let dmax = dist.iter().cloned().fold(0.0, f64::max);
    let dmean = dist.iter().sum::<f64>() / dist.len().max(1) as f64;
    report.displacement.insert("max".into(), json!(dmax));
    report.displacement.insert("mean".into(), json!(dmean));
    report
        .displacement
        .insert("colour_scale_mm".into(), json!([0.0, dmax]));
    report
        .displacement
        .insert("colour_map".into(), json!("viridis"));
    report
        .counts
        .insert("springs_main".into(), json!(spring_report.main));
    report
        .counts
        .insert("springs_strut".into(), json!(spring_report.struts));
    report.counts.insert(
        "unknowns".into(),
        json!(sol.as_ref().map_or(0, |s| s.unknowns)),
    );
    report.counts.insert(
        "solved_vertices".into(),
        json!(sol.as_ref().map_or(0, |s| s.solved_vertices)),
    );
    report.springs = Some(spring_report);
    report.solve = sol.as_ref().map(|s| s.history.clone());

    obs.started("writing outputs");
    let meter = crate::meter::Meter::start(obs.heap());
    std::fs::create_dir_all(&out_dir).map_err(|e| Error::output(&out_dir, e))?;
    let mut coloured = face_post.clone();
    coloured.colors = Some(
        dist.iter()
            .map(|d| viridis(if dmax > 0.0 { d / dmax } else { 0.0 }))
            .collect(),
    );
    coloured.vertex_columns.push(mesh::Column {
        name: "displacement".into(),
        values: dist.clone(),
    });
    let mut skull_post = skull.clone();
    skull_post.vertices = plan.apply(&skull.vertices, 1.0).0;
    // The files are independent (each written to a temporary name and renamed), so they are
    // written in parallel; the first error is reported.
    type Job<'a> = Box<dyn FnOnce() -> Result<()> + Send + Sync + 'a>;
    let o = &out_dir;
    let jobs: Vec<Job> = vec![
        Box::new(|| mesh::write_mesh(&face_post, &o.join("face_post.obj"))),
        Box::new(|| mesh::write_mesh(&face_post, &o.join("face_post.ply"))),
        // The C1 surface sampled finer than the solved mesh; with a coarse model the carried
        // full skin is the fine output instead.
        Box::new(|| match (&sol, case.output.subdivide > 1 && !embedded) {
            (Some(sol), true) => {
                let fine = crate::fem::preload::sample(&sol.fem, &sol.a, case.output.subdivide);
                mesh::write_mesh(&fine, &o.join("face_post_fine.ply"))
            }
            _ => Ok(()),
        }),
        Box::new(|| mesh::write_mesh(&coloured, &o.join("face_displacement.ply"))),
        // With a coarse model, the mesh that was solved (pre-operative skin → its answer).
        Box::new(|| match (&sol, embedded) {
            (Some(sol), true) => {
                let mut m = solved_skin.clone();
                m.vertices = sol.positions.clone();
                mesh::write_mesh(&m, &o.join("face_post_coarse.ply"))
            }
            _ => Ok(()),
        }),
        Box::new(|| mesh::write_mesh(&skull_post, &o.join("skull_post.ply"))),
        Box::new(|| {
            mesh::ply::write(
                &springs.to_mesh(solved_skin),
                &o.join("springs.ply"),
                mesh::ply::Encoding::BinaryLittleEndian,
            )
        }),
        Box::new(|| {
            crate::output::write_bytes_atomic(&o.join("displacement.csv"), |w| {
                writeln!(w, "vertex,x_pre,y_pre,z_pre,x_post,y_post,z_post,dist")?;
                for (i, (p, q)) in skin.vertices.iter().zip(&face_post.vertices).enumerate() {
                    writeln!(
                        w,
                        "{i},{},{},{},{},{},{},{}",
                        p[0], p[1], p[2], q[0], q[1], q[2], dist[i]
                    )?;
                }
                Ok(())
            })
        }),
        Box::new(|| mesh::write_mesh(&skin, &o.join("face_pre.obj"))),
        Box::new(|| mesh::write_mesh(&skin, &o.join("face_pre.ply"))),
        Box::new(|| mesh::write_mesh(&skull, &o.join("skull_pre.ply"))),
        Box::new(|| volume::nifti_io::write_labels(&vol, &seg.labels, &o.join("labels.nii.gz"))),
    ];
    {
        use rayon::prelude::*;
        jobs.into_par_iter()
            .map(|j| j())
            .collect::<Result<Vec<()>>>()?;
    }
    report.record("write", meter.stop());
    // Stage meters reset the heap high-water mark, so the whole run's peak is the process's
    // resident maximum instead.
    report.record(
        "total",
        crate::meter::StageCost {
            peak_heap_mb: None,
            ..total.stop()
        },
    );
    report
        .counts
        .insert("max_rss_mb".into(), json!(crate::meter::max_rss_mb()));

    report.counts.insert("voxels".into(), json!(vol.len()));
    report.counts.insert("dims".into(), json!(vol.dims));
    report
        .counts
        .insert("skin_vertices".into(), json!(skin.vertices.len()));
    report
        .counts
        .insert("skin_triangles".into(), json!(skin.triangles.len()));
    report
        .counts
        .insert("skull_vertices".into(), json!(skull.vertices.len()));
    report
        .counts
        .insert("skull_triangles".into(), json!(skull.triangles.len()));
    if seg.report.removed_components > 0 {
        warnings.push(format!(
            "{} pieces above the head threshold ({} voxels) are not the head and were dropped (CT table, head rest)",
            seg.report.removed_components, seg.report.removed_voxels
        ));
    }
    report.segmentation = Some(seg.report.clone());
    report.parameters = Some(case.clone());
    report.warnings = warnings;
    report.stages_not_run = Vec::new();
    let text = serde_json::to_string_pretty(&report).map_err(|e| Error::output(&out_dir, e))?;
    crate::output::write_bytes_atomic(&out_dir.join("report.json"), |w| {
        w.write_all(text.as_bytes())
    })?;
    obs.done();
    Ok(Outcome {
        report,
        face_post,
        volume: vol,
        segmentation: seg,
        skin,
        skull,
        out_dir,
    })
}

//! Baselines on a face case (issue 5 §5): the C1 model at several skin resolutions under both
//! solve models, the surface mass-spring (Punak), the voxel-lattice mass-spring and a linear
//! tetrahedral FEM, each timed (wall, peak heap) and compared with the reference.
//!
//! Reference: the equilibrium C1 solution on the finest skin mesh. There is no post-operative
//! scan of these cases, so "error" here is distance to the converged answer of the product's own
//! model: the C1 discretisation converges under refinement (docs/fem.md: clamped plates 1.16 →
//! 0.33 → 0.023 %), and the equilibrium model converges in Newton to 1e-6 where koch1996 is a
//! fixed-point iteration with its own bias. The other families solve different physics; their
//! distance to the reference is model disagreement, not error against the patient.
//!
//! Distances are taken on the reference's movable vertices (outside `[surface] movable` every
//! model keeps the skin fixed): each is projected to the closest point of a
//! method's pre-operative skin, the method's displacement is interpolated there (barycentric),
//! and |d_method − d_ref| is the vertex's distance (mm). Volumetric methods are interpolated at
//! the vertices directly.

use super::mass_spring;
use super::volumetric::{self, Kind};
use facesim::case::{Case, Parameterization, SolveModel};
use facesim::compare::{DistanceStats, SurfaceIndex, barycentric, stats};
use facesim::error::{Error, NumericalKind, Result};
use facesim::mesh::{Mesh, sub};
use facesim::observe::Observer;
use facesim::pipeline::{Scene, prepare_case};
use facesim::surface;
use serde::Serialize;
use std::path::Path;

#[derive(Clone, Debug, Serialize)]
pub struct FaceRow {
    pub case: String,
    pub method: String,
    pub family: String,
    /// Skin triangles (surface models) or lattice spacing (volumetric).
    pub resolution: String,
    pub unknowns: usize,
    pub wall_s: f64,
    /// Peak heap above the shared anatomy (MB); None without the counting allocator.
    pub peak_mb: Option<f64>,
    /// Distances to the reference on its vertices (mm); None for a failed method.
    pub distance: Option<DistanceStats>,
    pub is_reference: bool,
    /// Mean |displacement| (mm) the method predicts over the reference's movable vertices (a
    /// method that predicted no change would be this far from a method that did).
    pub mean_displacement_mm: Option<f64>,
    /// What went wrong (diverged, did not converge), or a remark.
    pub note: Option<String>,
}

/// A method's answer: its pre-operative skin and the displacement of each of its vertices, or
/// displacements at the reference vertices directly.
enum Answer {
    OnMesh(Mesh, Vec<[f64; 3]>),
    AtReference(Vec<[f64; 3]>),
}

fn midpoint_subdivide(m: &Mesh) -> Mesh {
    let mut vertices = m.vertices.clone();
    let mut mid: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    let mut tris = Vec::with_capacity(4 * m.triangles.len());
    for t in &m.triangles {
        let mut e = [0u32; 3];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            e[k] = *mid.entry(key).or_insert_with(|| {
                let (p, q) = (m.vertices[a as usize], m.vertices[b as usize]);
                vertices.push([0, 1, 2].map(|c| 0.5 * (p[c] + q[c])));
                (vertices.len() - 1) as u32
            });
        }
        tris.push([t[0], e[0], e[2]]);
        tris.push([t[1], e[1], e[0]]);
        tris.push([t[2], e[2], e[1]]);
        tris.push([e[0], e[1], e[2]]);
    }
    Mesh::new(vertices, tris)
}

struct Level {
    label: String,
    skin: Mesh,
}

fn with_uv(mut m: Mesh, case: &Case, scene: &Scene) -> Mesh {
    match case.surface.parameterization {
        Parameterization::Cylindrical => {
            surface::cylindrical_uv(&mut m, scene.face.axis, scene.face.r0)
        }
        Parameterization::Planar => surface::planar_uv(&mut m),
    }
    m
}

/// (result, wall seconds, peak heap MB) of `f`, by the same meter as the pipeline's stages.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64, Option<f64>) {
    let m = facesim::meter::Meter::start(crate::memory::Probe::if_installed());
    let r = f();
    let c = m.stop();
    (r, c.wall_s, c.peak_heap_mb)
}

/// Run every method on the case at `case_path`.
pub fn study_case(case_path: &Path, quick: bool, progress: &dyn Observer) -> Result<Vec<FaceRow>> {
    let (case, dir) = Case::load(case_path)?;
    let name = case
        .name
        .clone()
        .unwrap_or_else(|| dir.display().to_string());
    let scene = prepare_case(&case, &facesim::observe::Quiet)?;
    let case = scene.case.clone();
    if scene.model.plan.is_empty() {
        return Err(Error::config(format!(
            "{}: the study needs a case with at least one [[osteotomy]]",
            dir.display()
        )));
    }
    let native = scene.face.skin.clone();
    let nt = native.triangles.len();
    // Resolutions, finest first (the reference).
    let mut levels: Vec<Level> = Vec::new();
    if !quick && nt < 30_000 {
        levels.push(Level {
            label: format!("{} tri (midpoint ×4)", 4 * nt),
            skin: with_uv(midpoint_subdivide(&native), &case, &scene),
        });
    }
    levels.push(Level {
        label: format!("{nt} tri"),
        skin: native.clone(),
    });
    if case.skin.is_none() && case.extract.method == facesim::case::ExtractMethod::Rangescan {
        // An extracted skin is coarsened the way a user would: a coarser range scan (angle and
        // slice steps × f). Its (θ, z) grid cannot fold in (u, v), unlike a decimation of it.
        let factors: &[f64] = if quick { &[2.0] } else { &[1.5, 2.0, 3.0] };
        for &f in factors {
            let mut c = case.clone();
            c.extract.angle_step_deg *= f;
            let z = if case.extract.z_step_mm > 0.0 {
                case.extract.z_step_mm
            } else {
                scene.vol.spacing[2]
            };
            c.extract.z_step_mm = z * f;
            let coarse = prepare_case(&c, &facesim::observe::Quiet)?;
            levels.push(Level {
                label: format!("{} tri", coarse.face.skin.triangles.len()),
                skin: coarse.face.skin,
            });
        }
    } else {
        let divisors: &[usize] = if quick { &[2, 4] } else { &[2, 4, 8] };
        for &dv in divisors {
            if let Some(m) = surface::decimate_unfolded(&native, nt / dv, |m| {
                *m = with_uv(std::mem::take(m), &case, &scene)
            }) {
                levels.push(Level {
                    label: format!("{} tri", m.triangles.len()),
                    skin: m,
                });
            }
        }
    }
    let bone_field = scene.seg.bone_field(&scene.vol);
    let rigid_of = |m: &Mesh| facesim::pipeline::model::rigid_mask(&case, &m.vertices);
    let mut rows: Vec<FaceRow> = Vec::new();
    let mut answers: Vec<(usize, Answer)> = Vec::new();
    let mut reference: Option<(Mesh, Vec<[f64; 3]>)> = None;
    let mut native_springs = None;
    for (li, level) in levels.iter().enumerate() {
        let rigid = rigid_of(&level.skin);
        let (springs, t_springs, m_springs) = timed(|| {
            facesim::springs::trace(
                &level.skin,
                &scene.vol,
                &scene.seg,
                &bone_field,
                &case.springs,
                &case.tissue.stiffness,
                facesim::springs::wanted(&rigid, case.solve.restrict).as_deref(),
            )
        });
        for model in [SolveModel::Equilibrium, SolveModel::Koch1996] {
            progress.started(&format!("study {name}: C1 {model:?} at {}", level.label));
            let params = facesim::solve::Params {
                model,
                k_c: match model {
                    SolveModel::Koch1996 => case.solve.koch_k_c,
                    SolveModel::Equilibrium => case.solve.k_c,
                },
                regions: scene.model.params.regions.clone(),
                ..scene.model.params
            };
            let (sol, wall, peak) = timed(|| {
                facesim::solve::solve(&level.skin, &springs, &scene.model.plan, &rigid, &params)
            });
            let mut row = FaceRow {
                case: name.clone(),
                method: format!("C1 {}", model_name(model)),
                family: "C1 surface FEM".into(),
                resolution: level.label.clone(),
                unknowns: 0,
                wall_s: wall + t_springs,
                peak_mb: peak.zip(m_springs).map(|(a, b)| a.max(b)),
                distance: None,
                is_reference: li == 0 && model == SolveModel::Equilibrium,
                mean_displacement_mm: None,
                note: None,
            };
            // A coarse level's equilibrium answer carried to the reference skin by the shell
            // embedding the product uses for dense scans ([solve] coarse_triangles, paper 002).
            let embedded_row = match (&sol, li > 0 && model == SolveModel::Equilibrium) {
                (Ok(sol), true) => {
                    let (carried, t_embed, m_embed) = timed(|| {
                        facesim::embed::Shell::carry_skin(
                            &level.skin,
                            &sol.positions,
                            &levels[0].skin.vertices,
                            (&scene.vol, &scene.seg.labels),
                            &case.solve,
                            &rigid,
                        )
                        .map(|(c, _)| c)
                    });
                    let mut r = FaceRow {
                        method: "C1 equilibrium + shell embedding".into(),
                        wall_s: wall + t_springs + t_embed,
                        peak_mb: peak.zip(m_embed).map(|(a, b)| a.max(b)),
                        is_reference: false,
                        unknowns: sol.unknowns,
                        ..row.clone()
                    };
                    match carried {
                        Ok(c) => {
                            let ref_rigid = rigid_of(&levels[0].skin);
                            let d: Vec<[f64; 3]> = c
                                .iter()
                                .zip(&levels[0].skin.vertices)
                                .zip(&ref_rigid)
                                .map(|((p, q), r)| if *r { [0.0; 3] } else { sub(*p, *q) })
                                .collect();
                            Some((r, Some(Answer::AtReference(d))))
                        }
                        Err(e) => {
                            r.note = Some(e.to_string());
                            Some((r, None))
                        }
                    }
                }
                _ => None,
            };
            match sol {
                Ok(sol) => {
                    row.unknowns = sol.unknowns;
                    let d: Vec<[f64; 3]> = sol
                        .positions
                        .iter()
                        .zip(&level.skin.vertices)
                        .map(|(p, q)| sub(*p, *q))
                        .collect();
                    if row.is_reference {
                        reference = Some((level.skin.clone(), d));
                    } else {
                        answers.push((rows.len(), Answer::OnMesh(level.skin.clone(), d)));
                    }
                }
                Err(e) => {
                    if row.is_reference {
                        return Err(e);
                    }
                    row.note = Some(e.to_string());
                }
            }
            rows.push(row);
            if let Some((r, answer)) = embedded_row {
                if let Some(a) = answer {
                    answers.push((rows.len(), a));
                }
                rows.push(r);
            }
        }
        // Punak's mass-spring on the native mesh and the coarsest one.
        if li + 1 == levels.len() || level.skin.triangles.len() == nt {
            progress.started(&format!("study {name}: mass-spring at {}", level.label));
            let (r, wall, peak) = timed(|| {
                mass_spring::relax(
                    &level.skin,
                    &springs,
                    &scene.model.plan,
                    &rigid,
                    case.surface.alpha,
                    case.surface.beta,
                    case.solve.k_c,
                    1e-5,
                    if quick { 60_000 } else { 200_000 },
                )
            });
            let d: Vec<[f64; 3]> = r
                .positions
                .iter()
                .zip(&level.skin.vertices)
                .map(|(p, q)| sub(*p, *q))
                .collect();
            let note = Some(if r.converged {
                format!("damped Verlet converged in {} steps", r.iterations)
            } else {
                format!(
                    "damped Verlet did not converge: residual {:.1e} after {} steps",
                    r.residual, r.iterations
                )
            });
            answers.push((rows.len(), Answer::OnMesh(level.skin.clone(), d)));
            rows.push(FaceRow {
                case: name.clone(),
                method: "mass-spring (Punak)".into(),
                family: "surface mass-spring".into(),
                resolution: level.label.clone(),
                unknowns: 3 * rigid.iter().filter(|r| !**r).count(),
                wall_s: wall + t_springs,
                peak_mb: peak,
                distance: None,
                is_reference: false,
                mean_displacement_mm: None,
                note,
            });
        }
        if level.skin.triangles.len() == nt {
            native_springs = Some(springs);
        }
    }
    // Depth of the facial soft tissue: the 99th percentile of the main springs' lengths.
    let depth = native_springs
        .as_ref()
        .map(|sp: &facesim::springs::SpringSet| {
            let mut l: Vec<f64> = sp
                .springs
                .iter()
                .filter(|s| s.kind == facesim::springs::Kind::Main)
                .map(|s| s.rest)
                .collect();
            l.sort_by(f64::total_cmp);
            l.get((0.99 * l.len() as f64) as usize)
                .copied()
                .unwrap_or(case.springs.max_length_mm)
        })
        .unwrap_or(case.springs.max_length_mm);
    drop(native_springs);
    let Some((ref_mesh, ref_d)) = reference else {
        return Err(Error::numerical(
            NumericalKind::NotConverged,
            "the reference solve produced nothing",
        ));
    };
    // Volumetric models.
    let spacings: &[f64] = if quick { &[4.0] } else { &[4.0, 6.0, 8.0] };
    for &s in spacings {
        for (kind, method, family) in [
            (
                Kind::Lattice,
                "voxel lattice mass-spring",
                "volumetric mass-spring",
            ),
            (
                Kind::Tetrahedra,
                "linear tetrahedral FEM (ν 0.45)",
                "volumetric FEM",
            ),
        ] {
            progress.started(&format!("study {name}: {method} at {s} mm"));
            let (r, wall, peak) = timed(|| {
                volumetric::predict(
                    &scene.vol,
                    &scene.seg,
                    &case.tissue.stiffness,
                    &scene.model.plan,
                    &ref_mesh.vertices,
                    volumetric::Options {
                        spacing: s,
                        max_depth_mm: depth + s,
                        kind,
                        nu: 0.45,
                    },
                )
            });
            let mut row = FaceRow {
                case: name.clone(),
                method: method.into(),
                family: family.into(),
                resolution: format!("{s} mm lattice"),
                unknowns: 0,
                wall_s: wall,
                peak_mb: peak,
                distance: None,
                is_reference: false,
                mean_displacement_mm: None,
                note: None,
            };
            match r {
                Ok(p) => {
                    row.unknowns = p.unknowns;
                    // Rigid skin stays rigid in every model: the same boundary condition.
                    let rigid = rigid_of(&ref_mesh);
                    let d = p
                        .displacement
                        .iter()
                        .zip(&rigid)
                        .map(|(d, r)| if *r { [0.0; 3] } else { *d })
                        .collect();
                    answers.push((rows.len(), Answer::AtReference(d)));
                }
                Err(e) => row.note = Some(e.to_string()),
            }
            rows.push(row);
        }
    }
    // Distances on the reference vertices the plan can move (rigid skin is identical in every
    // model by construction and would only dilute the statistics).
    let ref_rigid = rigid_of(&ref_mesh);
    for (row, answer) in answers {
        let d_at_ref: Vec<[f64; 3]> = match answer {
            Answer::AtReference(d) => d,
            Answer::OnMesh(mesh, d) => {
                let idx = SurfaceIndex::new(&mesh);
                ref_mesh
                    .vertices
                    .iter()
                    .map(|&p| {
                        let (_, q, t) = idx.closest_triangle(p);
                        let tri = mesh.triangles[t].map(|v| v as usize);
                        let w = barycentric(
                            q,
                            mesh.vertices[tri[0]],
                            mesh.vertices[tri[1]],
                            mesh.vertices[tri[2]],
                        );
                        [0, 1, 2].map(|c| (0..3).map(|k| w[k] * d[tri[k]][c]).sum::<f64>())
                    })
                    .collect()
            }
        };
        let dist: Vec<f64> = d_at_ref
            .iter()
            .zip(&ref_d)
            .zip(&ref_rigid)
            .filter(|(_, r)| !**r)
            .map(|((a, b), _)| facesim::mesh::norm(sub(*a, *b)))
            .collect();
        rows[row].distance = Some(stats(&dist));
        rows[row].mean_displacement_mm = Some(mean_norm(&d_at_ref, &ref_rigid));
    }
    for row in rows.iter_mut().filter(|r| r.is_reference) {
        row.distance = Some(stats(&[0.0]));
        row.mean_displacement_mm = Some(mean_norm(&ref_d, &ref_rigid));
    }
    Ok(rows)
}

fn mean_norm(d: &[[f64; 3]], rigid: &[bool]) -> f64 {
    let v: Vec<f64> = d
        .iter()
        .zip(rigid)
        .filter(|(_, r)| !**r)
        .map(|(d, _)| facesim::mesh::norm(*d))
        .collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn model_name(m: SolveModel) -> &'static str {
    match m {
        SolveModel::Equilibrium => "equilibrium",
        SolveModel::Koch1996 => "koch1996",
    }
}

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
use facesim::springs::SpringSet;
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
    let mut study = Study::new(case_path, quick, progress)?;
    let levels = study.levels()?;
    let native_springs = study.surface_rows(&levels)?;
    let depth = soft_tissue_depth(native_springs.as_ref(), &study.case);
    // The springs are not needed past here; free them before the volumetric lattices.
    drop(native_springs);
    let Some((ref_mesh, ref_d)) = study.reference.take() else {
        return Err(Error::numerical(
            NumericalKind::NotConverged,
            "the reference solve produced nothing",
        ));
    };
    study.volumetric_rows(&ref_mesh, depth);
    Ok(study.distances(&ref_mesh, &ref_d))
}

/// The state shared by the methods of one case: rows in the order they are reported, and the
/// answers still to be compared with the reference once it exists.
struct Study<'a> {
    name: String,
    case: Case,
    scene: Scene,
    quick: bool,
    progress: &'a dyn Observer,
    rows: Vec<FaceRow>,
    /// (index in `rows`, answer) of every non-reference method that produced one.
    answers: Vec<(usize, Answer)>,
    /// The reference skin and its displacements (equilibrium C1 on the finest level).
    reference: Option<(Mesh, Vec<[f64; 3]>)>,
}

/// A level's skin with its rigid mask and traced springs; the tracing cost is charged to every
/// surface method that solves on them.
struct Traced<'l> {
    level: &'l Level,
    rigid: Vec<bool>,
    springs: SpringSet,
    wall_s: f64,
    peak_mb: Option<f64>,
}

impl<'a> Study<'a> {
    fn new(case_path: &Path, quick: bool, progress: &'a dyn Observer) -> Result<Self> {
        let (case, dir) = Case::load(case_path)?;
        let name = case
            .name
            .clone()
            .unwrap_or_else(|| dir.display().to_string());
        let scene = prepare_case(&case, &facesim::observe::Quiet)?;
        if scene.model.plan.is_empty() {
            return Err(Error::config(format!(
                "{}: the study needs a case with at least one [[osteotomy]]",
                dir.display()
            )));
        }
        Ok(Study {
            name,
            // The scene's copy: its mask regions carry their voxels (rigid_mask needs them).
            case: scene.case.clone(),
            scene,
            quick,
            progress,
            rows: Vec::new(),
            answers: Vec::new(),
            reference: None,
        })
    }

    fn rigid_of(&self, m: &Mesh) -> Vec<bool> {
        facesim::pipeline::model::rigid_mask(&self.case, &m.vertices)
    }

    /// A row of this case with no answer yet.
    fn row(
        &self,
        method: impl Into<String>,
        family: &str,
        resolution: String,
        wall_s: f64,
        peak_mb: Option<f64>,
    ) -> FaceRow {
        FaceRow {
            case: self.name.clone(),
            method: method.into(),
            family: family.into(),
            resolution,
            unknowns: 0,
            wall_s,
            peak_mb,
            distance: None,
            is_reference: false,
            mean_displacement_mm: None,
            note: None,
        }
    }

    /// Skin resolutions, finest first (the reference).
    fn levels(&self) -> Result<Vec<Level>> {
        let native = &self.scene.face.skin;
        let nt = native.triangles.len();
        let mut levels: Vec<Level> = Vec::new();
        if !self.quick && nt < 30_000 {
            levels.push(Level {
                label: format!("{} tri (midpoint ×4)", 4 * nt),
                skin: with_uv(midpoint_subdivide(native), &self.case, &self.scene),
            });
        }
        levels.push(Level {
            label: format!("{nt} tri"),
            skin: native.clone(),
        });
        if self.case.skin.is_none()
            && self.case.extract.method == facesim::case::ExtractMethod::Rangescan
        {
            levels.extend(self.coarser_scans()?);
        } else {
            let divisors: &[usize] = if self.quick { &[2, 4] } else { &[2, 4, 8] };
            for &dv in divisors {
                if let Some(m) = surface::decimate_unfolded(native, nt / dv, |m| {
                    *m = with_uv(std::mem::take(m), &self.case, &self.scene)
                }) {
                    levels.push(Level {
                        label: format!("{} tri", m.triangles.len()),
                        skin: m,
                    });
                }
            }
        }
        Ok(levels)
    }

    /// An extracted skin is coarsened the way a user would: a coarser range scan (angle and
    /// slice steps × f). Its (θ, z) grid cannot fold in (u, v), unlike a decimation of it.
    fn coarser_scans(&self) -> Result<Vec<Level>> {
        let factors: &[f64] = if self.quick { &[2.0] } else { &[1.5, 2.0, 3.0] };
        let mut levels = Vec::new();
        for &f in factors {
            let mut c = self.case.clone();
            c.extract.angle_step_deg *= f;
            let z = if self.case.extract.z_step_mm > 0.0 {
                self.case.extract.z_step_mm
            } else {
                self.scene.vol.spacing[2]
            };
            c.extract.z_step_mm = z * f;
            let coarse = prepare_case(&c, &facesim::observe::Quiet)?;
            levels.push(Level {
                label: format!("{} tri", coarse.face.skin.triangles.len()),
                skin: coarse.face.skin,
            });
        }
        Ok(levels)
    }

    /// The surface models at every level; returns the native skin's springs (their depth bounds
    /// the volumetric models).
    fn surface_rows(&mut self, levels: &[Level]) -> Result<Option<SpringSet>> {
        let bone_field = self.scene.seg.bone_field(&self.scene.vol);
        let nt = self.scene.face.skin.triangles.len();
        let mut native_springs = None;
        for (li, level) in levels.iter().enumerate() {
            let traced = self.trace(level, &bone_field);
            for model in [SolveModel::Equilibrium, SolveModel::Koch1996] {
                self.c1_rows(li, &traced, &levels[0].skin, model)?;
            }
            // Punak's mass-spring on the native mesh and the coarsest one.
            if li + 1 == levels.len() || level.skin.triangles.len() == nt {
                self.mass_spring_row(&traced);
            }
            if level.skin.triangles.len() == nt {
                native_springs = Some(traced.springs);
            }
        }
        Ok(native_springs)
    }

    fn trace<'l>(&self, level: &'l Level, bone_field: &[f32]) -> Traced<'l> {
        let (case, scene) = (&self.case, &self.scene);
        let rigid = self.rigid_of(&level.skin);
        let (springs, wall_s, peak_mb) = timed(|| {
            facesim::springs::trace(
                &level.skin,
                &scene.vol,
                &scene.seg,
                bone_field,
                &case.springs,
                &case.tissue.stiffness,
                facesim::springs::wanted(&rigid, case.solve.restrict).as_deref(),
            )
        });
        Traced {
            level,
            rigid,
            springs,
            wall_s,
            peak_mb,
        }
    }

    /// The C1 row of level `li` under `model`, followed on coarse levels under equilibrium by
    /// the shell-embedding row. The finest equilibrium solve is the reference: its failure
    /// fails the study.
    fn c1_rows(&mut self, li: usize, t: &Traced, ref_skin: &Mesh, model: SolveModel) -> Result<()> {
        let level = t.level;
        let what = format!("study {}: C1 {model:?} at {}", self.name, level.label);
        self.progress.started(&what);
        let params = facesim::solve::Params {
            model,
            k_c: match model {
                SolveModel::Koch1996 => self.case.solve.koch_k_c,
                SolveModel::Equilibrium | SolveModel::Tet => self.case.solve.k_c,
            },
            regions: self.scene.model.params.regions.clone(),
            ..self.scene.model.params
        };
        let plan = &self.scene.model.plan;
        let (sol, wall, peak) =
            timed(|| facesim::solve::solve(&level.skin, &t.springs, plan, &t.rigid, &params));
        let method = format!("C1 {}", model_name(model));
        let peak_mb = peak.zip(t.peak_mb).map(|(a, b)| a.max(b));
        let mut row = FaceRow {
            is_reference: li == 0 && model == SolveModel::Equilibrium,
            ..self.row(
                method,
                "C1 surface FEM",
                level.label.clone(),
                wall + t.wall_s,
                peak_mb,
            )
        };
        let embedded = match (&sol, li > 0 && model == SolveModel::Equilibrium) {
            (Ok(sol), true) => Some(self.embedded_row(t, sol, ref_skin, &row, wall, peak)),
            _ => None,
        };
        match sol {
            Ok(sol) => {
                row.unknowns = sol.unknowns;
                let d = displacement(&sol.positions, &level.skin);
                if row.is_reference {
                    self.reference = Some((level.skin.clone(), d));
                } else {
                    let answer = Answer::OnMesh(level.skin.clone(), d);
                    self.answers.push((self.rows.len(), answer));
                }
            }
            Err(e) if row.is_reference => return Err(e),
            Err(e) => row.note = Some(e.to_string()),
        }
        self.rows.push(row);
        if let Some((r, answer)) = embedded {
            if let Some(a) = answer {
                self.answers.push((self.rows.len(), a));
            }
            self.rows.push(r);
        }
        Ok(())
    }

    /// A coarse level's equilibrium answer carried to the reference skin by the shell embedding
    /// the product uses for dense scans ([solve] coarse_triangles, paper 002). `c1` is the
    /// level's C1 row, whose solve took `wall` s and `peak` MB.
    fn embedded_row(
        &self,
        t: &Traced,
        sol: &facesim::solve::Solution,
        ref_skin: &Mesh,
        c1: &FaceRow,
        wall: f64,
        peak: Option<f64>,
    ) -> (FaceRow, Option<Answer>) {
        let (carried, t_embed, m_embed) = timed(|| {
            facesim::embed::Shell::carry_skin(
                &t.level.skin,
                &sol.positions,
                &ref_skin.vertices,
                (&self.scene.vol, &self.scene.seg.labels),
                &self.case.solve,
                &t.rigid,
            )
            .map(|(c, _)| c)
        });
        let mut r = FaceRow {
            method: "C1 equilibrium + shell embedding".into(),
            wall_s: wall + t.wall_s + t_embed,
            peak_mb: peak.zip(m_embed).map(|(a, b)| a.max(b)),
            is_reference: false,
            unknowns: sol.unknowns,
            ..c1.clone()
        };
        match carried {
            Ok(c) => {
                let ref_rigid = self.rigid_of(ref_skin);
                let d: Vec<[f64; 3]> = c
                    .iter()
                    .zip(&ref_skin.vertices)
                    .zip(&ref_rigid)
                    .map(|((p, q), r)| if *r { [0.0; 3] } else { sub(*p, *q) })
                    .collect();
                (r, Some(Answer::AtReference(d)))
            }
            Err(e) => {
                r.note = Some(e.to_string());
                (r, None)
            }
        }
    }

    fn mass_spring_row(&mut self, t: &Traced) {
        let (level, case) = (t.level, &self.case);
        let what = format!("study {}: mass-spring at {}", self.name, level.label);
        self.progress.started(&what);
        let (r, wall, peak) = timed(|| {
            mass_spring::relax(
                &level.skin,
                &t.springs,
                &self.scene.model.plan,
                &t.rigid,
                case.surface.alpha,
                case.surface.beta,
                case.solve.k_c,
                1e-5,
                if self.quick { 60_000 } else { 200_000 },
            )
        });
        let d = displacement(&r.positions, &level.skin);
        let note = Some(if r.converged {
            format!("damped Verlet converged in {} steps", r.iterations)
        } else {
            format!(
                "damped Verlet did not converge: residual {:.1e} after {} steps",
                r.residual, r.iterations
            )
        });
        let row = FaceRow {
            unknowns: 3 * t.rigid.iter().filter(|r| !**r).count(),
            note,
            ..self.row(
                "mass-spring (Punak)",
                "surface mass-spring",
                level.label.clone(),
                wall + t.wall_s,
                peak,
            )
        };
        self.answers
            .push((self.rows.len(), Answer::OnMesh(level.skin.clone(), d)));
        self.rows.push(row);
    }

    /// The voxel-lattice mass-spring and the tetrahedral FEM at each lattice spacing, down to
    /// `depth` (mm) under the skin.
    fn volumetric_rows(&mut self, ref_mesh: &Mesh, depth: f64) {
        let spacings: &[f64] = if self.quick { &[4.0] } else { &[4.0, 6.0, 8.0] };
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
                self.volumetric_row(ref_mesh, depth, s, kind, method, family);
            }
        }
    }

    fn volumetric_row(
        &mut self,
        ref_mesh: &Mesh,
        depth: f64,
        s: f64,
        kind: Kind,
        method: &str,
        family: &str,
    ) {
        self.progress
            .started(&format!("study {}: {method} at {s} mm", self.name));
        let scene = &self.scene;
        let (r, wall, peak) = timed(|| {
            volumetric::predict(
                &scene.vol,
                &scene.seg,
                &self.case.tissue.stiffness,
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
        let mut row = self.row(method, family, format!("{s} mm lattice"), wall, peak);
        match r {
            Ok(p) => {
                row.unknowns = p.unknowns;
                // Rigid skin stays rigid in every model: the same boundary condition.
                let rigid = self.rigid_of(ref_mesh);
                let d = p
                    .displacement
                    .iter()
                    .zip(&rigid)
                    .map(|(d, r)| if *r { [0.0; 3] } else { *d })
                    .collect();
                self.answers.push((self.rows.len(), Answer::AtReference(d)));
            }
            Err(e) => row.note = Some(e.to_string()),
        }
        self.rows.push(row);
    }

    /// The rows with their distances to the reference, taken on the reference vertices the plan
    /// can move (rigid skin is identical in every model by construction and would only dilute
    /// the statistics).
    fn distances(mut self, ref_mesh: &Mesh, ref_d: &[[f64; 3]]) -> Vec<FaceRow> {
        let ref_rigid = self.rigid_of(ref_mesh);
        for (row, answer) in std::mem::take(&mut self.answers) {
            let d_at_ref = at_reference(answer, ref_mesh);
            let dist: Vec<f64> = d_at_ref
                .iter()
                .zip(ref_d)
                .zip(&ref_rigid)
                .filter(|(_, r)| !**r)
                .map(|((a, b), _)| facesim::mesh::norm(sub(*a, *b)))
                .collect();
            self.rows[row].distance = Some(stats(&dist));
            self.rows[row].mean_displacement_mm = Some(mean_norm(&d_at_ref, &ref_rigid));
        }
        for row in self.rows.iter_mut().filter(|r| r.is_reference) {
            row.distance = Some(stats(&[0.0]));
            row.mean_displacement_mm = Some(mean_norm(ref_d, &ref_rigid));
        }
        self.rows
    }
}

/// Depth of the facial soft tissue: the 99th percentile of the main springs' lengths.
fn soft_tissue_depth(native_springs: Option<&SpringSet>, case: &Case) -> f64 {
    native_springs
        .map(|sp| {
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
        .unwrap_or(case.springs.max_length_mm)
}

/// Displacement of each vertex of `skin` to `positions`.
fn displacement(positions: &[[f64; 3]], skin: &Mesh) -> Vec<[f64; 3]> {
    positions
        .iter()
        .zip(&skin.vertices)
        .map(|(p, q)| sub(*p, *q))
        .collect()
}

/// An answer's displacements at the reference vertices: on another mesh, interpolated
/// (barycentric) at each reference vertex's closest point of it.
fn at_reference(answer: Answer, ref_mesh: &Mesh) -> Vec<[f64; 3]> {
    let (mesh, d) = match answer {
        Answer::AtReference(d) => return d,
        Answer::OnMesh(mesh, d) => (mesh, d),
    };
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
        SolveModel::Tet => "tet",
    }
}

//! Every model on a face case, measured against the volumetric reference: the
//! product's tetrahedral model (`[solve] model = "tet"`, `facesim::model::volumetric::predict`) at the
//! finest affordable skin element size, with the case's `[tet]` material and element. Rows: that
//! model at coarser sizes (its own convergence), neo-Hookean against linear material and
//! quadratic against linear elements; the C1 model at several skin resolutions under both solve
//! models, with the shell embedding on coarse levels, and with its spring scale k_c (and struts)
//! calibrated against the reference (`calibrate`); the surface mass-spring (Punak); the lab's
//! voxel lattice and Kuhn-lattice tetrahedra. Each is timed (wall, peak heap).
//!
//! There is no post-operative scan of these cases: "error" is distance to the most complete
//! model of the tissue facesim has (a continuum, bone moving it through the whole tissue depth,
//! converging under refinement), not to the patient. The old reference — the finest C1
//! equilibrium solve — is kept as a second distance column (`distance_c1`).
//!
//! Distances are taken on the face's movable vertices (outside `[surface] movable` every model
//! keeps the skin fixed): the reference carries the case's skin mesh; a surface model's answer
//! on another mesh is interpolated (barycentric) at each reference vertex's closest point of it;
//! volumetric answers are evaluated at the vertices directly. |d_method − d_ref| per vertex,
//! summarised over the face and per facial region (`regions`).

use super::mass_spring;
use super::regions::{self, Regions};
use super::volumetric::{self, Kind};
use facesim::case::{Case, Parameterization, SolveModel, TetElement, TetMaterial};
use facesim::compare::{DistanceStats, SurfaceIndex, barycentric, stats};
use facesim::error::{Error, NumericalKind, Result};
use facesim::mesh::Mesh;
use facesim::observe::Observer;
use facesim::pipeline::{Scene, prepare_case};
use facesim::springs::SpringSet;
use facesim::surface;
use facesim::vec3::sub;
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
    /// Tetrahedra (the product's volumetric rows).
    pub elements: Option<usize>,
    /// Distances to the reference per facial region (present regions only).
    pub regions: Vec<RegionStats>,
    /// Distances to the finest C1 equilibrium solve (the study's former reference).
    pub distance_c1: Option<DistanceStats>,
    /// What went wrong (diverged, did not converge), or a remark.
    pub note: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct RegionStats {
    pub region: String,
    /// Movable vertices of the region.
    pub vertices: usize,
    pub distance: DistanceStats,
}

/// One evaluation of the C1 calibration: the mean distance to the reference at (k_c, struts).
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationPoint {
    pub k_c: f64,
    pub struts: bool,
    /// None when the solve failed.
    pub mean_mm: Option<f64>,
}

/// `[solve] k_c` (and `[springs] struts`) of the C1 equilibrium model fitted to the volumetric
/// reference on the case's own skin mesh: the mean distance over the movable face minimised.
#[derive(Clone, Debug, Serialize)]
pub struct Calibration {
    pub case: String,
    pub k_c_default: f64,
    pub struts_default: bool,
    pub mean_default_mm: f64,
    pub k_c: f64,
    pub struts: bool,
    pub mean_mm: f64,
    /// Every evaluation, in order.
    pub evaluations: Vec<CalibrationPoint>,
}

/// One case's results.
#[derive(Clone, Debug, Serialize)]
pub struct CaseStudy {
    pub case: String,
    pub rows: Vec<FaceRow>,
    /// The facial regions (landmarks, vertex counts, which are absent and why).
    pub regions: Option<Regions>,
    /// C1 fitted on this case.
    pub calibration: Option<Calibration>,
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
    let m = facesim::meter::Meter::start(facesim::meter::counted_heap());
    let r = f();
    let c = m.stop();
    (r, c.wall_s, c.peak_heap_mb)
}

/// The volumetric model's rows: (skin element size mm, material, element). The first is the
/// product's default (the case's `[tet]` material and element at 4 mm); the 4-node linear rows
/// at 5–10 mm show its convergence in size, and the neo-Hookean and 10-node rows at sizes whose
/// Newton iterations or 10-node systems stay affordable compare material and element with the
/// 4-node linear row of the same size. Quick: sizes that solve in seconds.
fn tet_ladder(quick: bool, case: &Case) -> Vec<(f64, TetMaterial, TetElement)> {
    use TetElement::{Linear as C3D4, Quadratic};
    use TetMaterial::{Linear, NeoHookean};
    let (m, e) = (case.tet.material, case.tet.element);
    if quick {
        vec![
            (6.0, m, e),
            (8.0, Linear, C3D4),
            (12.0, Linear, C3D4),
            (12.0, NeoHookean, C3D4),
        ]
    } else {
        vec![
            (4.0, m, e),
            (5.0, Linear, C3D4),
            (6.0, Linear, C3D4),
            (8.0, Linear, C3D4),
            (10.0, Linear, C3D4),
            (8.0, NeoHookean, C3D4),
            (10.0, Linear, Quadratic),
        ]
    }
}

/// The full study's reference (converged in size and element order) is the
/// 10-node model at the finest of these sizes whose 4-node mesh has at most [`REFERENCE_TETS`]
/// tetrahedra. Chosen when the 10-node model was factored directly (the real CT at 4 mm,
/// 212 856 tetrahedra: 9.8 GB; the phantom at 5 mm, 213 403: more than 17 GB). Solved
/// iteratively, the finer meshes now fit (the real CT at 3 mm 4.9 GB and 236 s, the phantom at
/// 4 mm 3.6 GB and 170 s: docs/lab/study.md "A finer reference, now affordable"); the ladder
/// stays until their inverted elements (11 and 4) are looked at. The quick study's reference is
/// its first row.
const REFERENCE_SIZES: [f64; 2] = [4.0, 6.0];
const REFERENCE_TETS: usize = 250_000;

/// Run every method on the case at `case_path`; `transfer` is a calibration from another case
/// (the phantom) whose k_c and struts are applied here as one more row.
pub fn study_case(
    case_path: &Path,
    quick: bool,
    transfer: Option<&Calibration>,
    progress: &dyn Observer,
) -> Result<CaseStudy> {
    let mut study = Study::new(case_path, quick, progress)?;
    let ref_mesh = study.scene.face.skin.clone();
    study.tet_rows(&ref_mesh)?;
    let levels = study.levels()?;
    let native_springs = study.surface_rows(&levels)?;
    let depth = soft_tissue_depth(native_springs.as_ref(), &study.case);
    // The springs are not needed past here; free them before the volumetric lattices.
    drop(native_springs);
    study.volumetric_rows(&ref_mesh, depth);
    let Some(ref_d) = study.reference.take() else {
        return Err(Error::numerical(
            NumericalKind::NotConverged,
            "the volumetric reference produced nothing",
        ));
    };
    let calibration = study.calibrate(&ref_mesh, &ref_d)?;
    if let Some(t) = transfer {
        study.c1_fixed_row(
            &ref_mesh,
            t.k_c,
            t.struts,
            format!("C1 equilibrium, k_c from {}", t.case),
        )?;
    }
    let regions = regions::regions(&ref_mesh.vertices);
    let name = study.name.clone();
    let rows = study.distances(&ref_mesh, &ref_d, regions.as_ref());
    Ok(CaseStudy {
        case: name,
        rows,
        regions,
        calibration: Some(calibration),
    })
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
    /// The reference's displacement at each vertex of the case's skin (the volumetric model).
    reference: Option<Vec<[f64; 3]>>,
    /// The finest C1 equilibrium answer (the former reference).
    c1_finest: Option<Answer>,
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
        let (mut case, dir) = Case::load(case_path)?;
        // The scene carries the C1 model's springs, which the surface rows need (the default
        // model, "tet", traces none); the volumetric rows mesh their own tissue.
        if case.solve.model == SolveModel::Tet {
            case.solve.model = SolveModel::Equilibrium;
        }
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
            c1_finest: None,
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
            elements: None,
            regions: Vec::new(),
            distance_c1: None,
            note: None,
        }
    }

    /// The product's volumetric model at each size of the ladder, carrying `ref_mesh`, and the
    /// reference: the quick study's first row, the full study's 10-node model at the finest size
    /// its memory allows ([`REFERENCE_TETS`]). The reference's failure fails the study.
    fn tet_rows(&mut self, ref_mesh: &Mesh) -> Result<()> {
        let mut finest_affordable: Option<f64> = None;
        for (i, (size, material, element)) in
            tet_ladder(self.quick, &self.case).into_iter().enumerate()
        {
            let reference = self.quick && i == 0;
            let tets = self.tet_row(ref_mesh, size, material, element, reference)?;
            let four_node = element == TetElement::Linear && material == TetMaterial::Linear;
            if four_node
                && REFERENCE_SIZES.contains(&size)
                && tets.is_some_and(|t| t <= REFERENCE_TETS)
            {
                finest_affordable = Some(finest_affordable.map_or(size, |f: f64| f.min(size)));
            }
        }
        if self.quick {
            return Ok(());
        }
        let Some(size) = finest_affordable else {
            return Err(Error::config(format!(
                "study {}: no reference size ({REFERENCE_SIZES:?} mm) meshes with at most {REFERENCE_TETS} tetrahedra for the 10-node reference",
                self.name
            )));
        };
        self.tet_row(
            ref_mesh,
            size,
            self.case.tet.material,
            TetElement::Quadratic,
            true,
        )?;
        Ok(())
    }

    /// One volumetric row (the reference when `reference`: its failure is the study's); the
    /// number of tetrahedra when it solved.
    fn tet_row(
        &mut self,
        ref_mesh: &Mesh,
        size: f64,
        material: TetMaterial,
        element: TetElement,
        reference: bool,
    ) -> Result<Option<usize>> {
        let mut case = self.case.clone();
        case.tet.skin_size_mm = size;
        case.tet.material = material;
        case.tet.element = element;
        let method = format!(
            "tet {}, {}",
            match material {
                TetMaterial::Linear => "linear",
                TetMaterial::NeoHookean => "neo-Hookean",
            },
            match element {
                TetElement::Linear => "4-node",
                TetElement::Quadratic => "10-node",
            }
        );
        self.progress
            .started(&format!("study {}: {method} at {size} mm", self.name));
        let mut rec = facesim::pipeline::Recorder::new(&facesim::observe::Quiet);
        let (r, wall, peak) =
            timed(|| facesim::model::volumetric::predict(&self.scene, &case, ref_mesh, &mut rec));
        let mut row = FaceRow {
            is_reference: reference,
            ..self.row(
                method,
                "volumetric FEM (product)",
                format!("{size} mm skin"),
                wall,
                peak,
            )
        };
        let mut tets = None;
        match r {
            Ok(Some((v, post))) => {
                row.unknowns = v.report.free_dofs;
                row.elements = Some(v.report.tets);
                tets = Some(v.report.tets);
                row.resolution = format!("{size} mm skin, {} tets", v.report.tets);
                if v.report.inverted_elements > 0 {
                    row.note = Some(format!("{} inverted elements", v.report.inverted_elements));
                }
                if let Some(n) = &v.report.newton {
                    let it: usize = n.iter().map(|s| s.iterations).sum();
                    row.note = Some(format!("{} load steps, {it} Newton iterations", n.len()));
                }
                let d = displacement(&post, ref_mesh);
                if reference {
                    self.reference = Some(d);
                } else {
                    self.answers.push((self.rows.len(), Answer::AtReference(d)));
                }
            }
            Ok(None) => {
                return Err(Error::config("the study's plan moves no bone"));
            }
            Err(e) if reference => return Err(e),
            Err(e) => row.note = Some(e.to_string()),
        }
        self.rows.push(row);
        Ok(tets)
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
            let native = &self.scene.face.skin.clone();
            for model in [SolveModel::Equilibrium, SolveModel::Koch1996] {
                self.c1_rows(li, &traced, native, model)?;
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

    /// The C1 row of level `li` under `model`, followed on levels coarser than `ref_skin` under
    /// equilibrium by the shell-embedding row. The finest equilibrium answer is also kept as
    /// the former reference.
    fn c1_rows(&mut self, li: usize, t: &Traced, ref_skin: &Mesh, model: SolveModel) -> Result<()> {
        let level = t.level;
        let what = format!("study {}: C1 {model:?} at {}", self.name, level.label);
        self.progress.started(&what);
        let method =
            facesim::solve::Method::of(model).unwrap_or(facesim::solve::Method::Equilibrium);
        let params = facesim::solve::Params {
            model: method,
            k_c: method.k_c(&self.case.solve),
            regions: self.scene.model.params.regions.clone(),
            ..self.scene.model.params
        };
        let plan = &self.scene.model.plan;
        let (sol, wall, peak) =
            timed(|| facesim::solve::solve(&level.skin, &t.springs, plan, &t.rigid, &params));
        let method = format!("C1 {}", model.name());
        let peak_mb = peak.zip(t.peak_mb).map(|(a, b)| a.max(b));
        let finest = li == 0 && model == SolveModel::Equilibrium;
        let mut row = FaceRow {
            ..self.row(
                method,
                "C1 surface FEM",
                level.label.clone(),
                wall + t.wall_s,
                peak_mb,
            )
        };
        let coarse = level.skin.triangles.len() < ref_skin.triangles.len();
        let embedded = match (&sol, coarse && model == SolveModel::Equilibrium) {
            (Ok(sol), true) => Some(self.embedded_row(t, sol, ref_skin, &row, wall, peak)),
            _ => None,
        };
        match sol {
            Ok(sol) => {
                row.unknowns = sol.unknowns;
                let d = displacement(&sol.positions, &level.skin);
                if finest {
                    self.c1_finest = Some(Answer::OnMesh(level.skin.clone(), d.clone()));
                }
                let answer = Answer::OnMesh(level.skin.clone(), d);
                self.answers.push((self.rows.len(), answer));
            }
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

    /// The rows with their distances to the reference (over the face and per region) and to the
    /// finest C1 solve, taken on the reference vertices the plan can move (rigid skin is
    /// identical in every model by construction and would only dilute the statistics).
    fn distances(
        mut self,
        ref_mesh: &Mesh,
        ref_d: &[[f64; 3]],
        regions: Option<&Regions>,
    ) -> Vec<FaceRow> {
        let ref_rigid = self.rigid_of(ref_mesh);
        let c1 = self.c1_finest.take().map(|a| at_reference(a, ref_mesh));
        let movable = |v: &[f64]| -> Vec<f64> {
            v.iter()
                .zip(&ref_rigid)
                .filter(|(_, r)| !**r)
                .map(|(d, _)| *d)
                .collect()
        };
        let per_region = |dist: &[f64]| -> Vec<RegionStats> {
            let Some(r) = regions else {
                return Vec::new();
            };
            r.members
                .iter()
                .zip(regions::NAMES)
                .filter_map(|(m, name)| {
                    let m = m.as_ref()?;
                    let v: Vec<f64> = dist
                        .iter()
                        .zip(m)
                        .zip(&ref_rigid)
                        .filter(|((_, inside), rigid)| **inside && !**rigid)
                        .map(|((d, _), _)| *d)
                        .collect();
                    (!v.is_empty()).then(|| RegionStats {
                        region: name.into(),
                        vertices: v.len(),
                        distance: stats(&v),
                    })
                })
                .collect()
        };
        let to = |a: &[[f64; 3]], b: &[[f64; 3]]| -> Vec<f64> {
            a.iter()
                .zip(b)
                .map(|(a, b)| facesim::vec3::norm(sub(*a, *b)))
                .collect()
        };
        for (row, answer) in std::mem::take(&mut self.answers) {
            let d_at_ref = at_reference(answer, ref_mesh);
            let dist = to(&d_at_ref, ref_d);
            let r = &mut self.rows[row];
            r.distance = Some(stats(&movable(&dist)));
            r.regions = per_region(&dist);
            r.distance_c1 = c1.as_ref().map(|c| stats(&movable(&to(&d_at_ref, c))));
            r.mean_displacement_mm = Some(mean_norm(&d_at_ref, &ref_rigid));
        }
        let zero = vec![0.0; ref_d.len()];
        for row in self.rows.iter_mut().filter(|r| r.is_reference) {
            row.distance = Some(stats(&[0.0]));
            row.regions = per_region(&zero);
            row.distance_c1 = c1.as_ref().map(|c| stats(&movable(&to(ref_d, c))));
            row.mean_displacement_mm = Some(mean_norm(ref_d, &ref_rigid));
        }
        self.rows
    }

    /// The C1 equilibrium model on the case's skin with spring scale `k_c` and struts on or off:
    /// its displacement at each vertex, or None when the solve fails.
    fn c1_answer(
        &self,
        skin: &Mesh,
        k_c: f64,
        struts: bool,
    ) -> (Option<Vec<[f64; 3]>>, f64, Option<f64>, usize) {
        let bone_field = self.scene.seg.bone_field(&self.scene.vol);
        let rigid = self.rigid_of(skin);
        let mut sp = self.case.springs.clone();
        sp.struts = struts;
        let params = facesim::solve::Params {
            model: facesim::solve::Method::Equilibrium,
            k_c,
            regions: self.scene.model.params.regions.clone(),
            ..self.scene.model.params
        };
        let ((sol, unknowns), wall, peak) = timed(|| {
            let springs = facesim::springs::trace(
                skin,
                &self.scene.vol,
                &self.scene.seg,
                &bone_field,
                &sp,
                &self.case.tissue.stiffness,
                facesim::springs::wanted(&rigid, self.case.solve.restrict).as_deref(),
            );
            match facesim::solve::solve(skin, &springs, &self.scene.model.plan, &rigid, &params) {
                Ok(s) => (Some(displacement(&s.positions, skin)), s.unknowns),
                Err(_) => (None, 0),
            }
        });
        (sol, wall, peak, unknowns)
    }

    /// A C1 equilibrium row on the case's skin at (k_c, struts), measured like every other.
    fn c1_fixed_row(&mut self, skin: &Mesh, k_c: f64, struts: bool, method: String) -> Result<()> {
        self.progress
            .started(&format!("study {}: {method}", self.name));
        let (d, wall, peak, unknowns) = self.c1_answer(skin, k_c, struts);
        let mut row = FaceRow {
            unknowns,
            note: Some(format!(
                "k_c {k_c:.3e}, struts {}",
                if struts { "on" } else { "off" }
            )),
            ..self.row(
                method,
                "C1 surface FEM",
                format!("{} tri", skin.triangles.len()),
                wall,
                peak,
            )
        };
        match d {
            Some(d) => self.answers.push((self.rows.len(), Answer::AtReference(d))),
            None => row.note = Some(format!("k_c {k_c:.3e}: the solve failed")),
        }
        self.rows.push(row);
        Ok(())
    }

    /// Fit k_c (log scale) and struts on/off of the C1 equilibrium model on the case's skin to
    /// the reference: a sweep by factors of 2 (quick: 4) over [k_c/16, 16 k_c] around the
    /// default, then golden-section search (Kiefer 1953) in log k_c inside the best point's
    /// bracket to a factor 1.03. The best evaluation is kept, so the result is never worse
    /// than the default, which is evaluated first. Adds the calibrated row.
    fn calibrate(&mut self, skin: &Mesh, ref_d: &[[f64; 3]]) -> Result<Calibration> {
        self.progress.started(&format!(
            "study {}: calibrating C1 k_c against the reference",
            self.name
        ));
        let rigid = self.rigid_of(skin);
        let k0 = self.case.solve.k_c;
        let s0 = self.case.springs.struts;
        let mut evals: Vec<CalibrationPoint> = Vec::new();
        let mean_at = |k: f64, struts: bool, evals: &mut Vec<CalibrationPoint>| -> f64 {
            let (d, ..) = self.c1_answer(skin, k, struts);
            let m = d.map(|d| {
                let v: Vec<f64> = d
                    .iter()
                    .zip(ref_d)
                    .zip(&rigid)
                    .filter(|(_, r)| !**r)
                    .map(|((a, b), _)| facesim::vec3::norm(sub(*a, *b)))
                    .collect();
                v.iter().sum::<f64>() / v.len().max(1) as f64
            });
            evals.push(CalibrationPoint {
                k_c: k,
                struts,
                mean_mm: m,
            });
            m.unwrap_or(f64::INFINITY)
        };
        let mean_default = mean_at(k0, s0, &mut evals);
        if !mean_default.is_finite() {
            return Err(Error::numerical(
                NumericalKind::NotConverged,
                "calibration: the C1 solve at the default k_c failed",
            ));
        }
        let step: f64 = if self.quick { 4.0 } else { 2.0 };
        let mut best = (k0, s0, mean_default);
        for struts in [s0, !s0] {
            // Sweep: exponents of `step` from 1/16 to 16.
            let n = (16f64.ln() / step.ln()).round() as i32;
            let mut sweep: Vec<(f64, f64)> = Vec::new();
            for e in -n..=n {
                let k = k0 * step.powi(e);
                let m = if e == 0 && struts == s0 {
                    mean_default
                } else {
                    mean_at(k, struts, &mut evals)
                };
                sweep.push((k.ln(), m));
            }
            let Some(ib) = (0..sweep.len()).min_by(|a, b| sweep[*a].1.total_cmp(&sweep[*b].1))
            else {
                continue;
            };
            // Golden section over the bracket [x_{ib−1}, x_{ib+1}] (clamped at the sweep's ends).
            let (mut a, mut b) = (
                sweep[ib.saturating_sub(1)].0,
                sweep[(ib + 1).min(sweep.len() - 1)].0,
            );
            let g = 0.5 * (5f64.sqrt() - 1.0);
            let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
            let (mut fc, mut fd) = (
                mean_at(c.exp(), struts, &mut evals),
                mean_at(d.exp(), struts, &mut evals),
            );
            while b - a > 1.03f64.ln() {
                if fc < fd {
                    (b, d, fd) = (d, c, fc);
                    c = b - g * (b - a);
                    fc = mean_at(c.exp(), struts, &mut evals);
                } else {
                    (a, c, fc) = (c, d, fd);
                    d = a + g * (b - a);
                    fd = mean_at(d.exp(), struts, &mut evals);
                }
            }
        }
        for e in &evals {
            if let Some(m) = e.mean_mm
                && m < best.2
            {
                best = (e.k_c, e.struts, m);
            }
        }
        let cal = Calibration {
            case: self.name.clone(),
            k_c_default: k0,
            struts_default: s0,
            mean_default_mm: mean_default,
            k_c: best.0,
            struts: best.1,
            mean_mm: best.2,
            evaluations: evals,
        };
        self.c1_fixed_row(
            skin,
            cal.k_c,
            cal.struts,
            "C1 equilibrium, k_c calibrated here".into(),
        )?;
        Ok(cal)
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
        .map(|(d, _)| facesim::vec3::norm(*d))
        .collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

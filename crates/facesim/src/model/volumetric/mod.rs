//! The volumetric model (`[solve] model = "tet"`; docs/design/pipeline.md "Volumetric soft tissue"):
//! the soft tissue between skin and bone is meshed with tetrahedra inside the region the plan
//! reaches, bone nodes follow their segment rigidly, the region's cut faces are held, the skin is
//! free; the solved displacement carries the face (the extracted skin or the given scan, at full
//! resolution).
//!
//! [`predict`] runs it in stages, one module each: the mesh ([`mesh`]: the region, the tissue
//! mesh), the anatomy the holds read ([`roles`]: mucosa, contact, degloved bone, the face's
//! skin), the holds ([`holds`]), the solve ([`solve`], with the holds that read the solution in
//! [`rounds`]), the face carried ([`face`]), the plan basis ([`basis`]) and the report
//! ([`report`]). A run's re-solves with other tissue parameters are in [`resolve`] and its
//! certified reduced model in [`reduce`].
//!
//! **Where a new hold goes:** a hold fixed before the solve is a type implementing
//! `holds::Condition`, added to `holds::conditions` at its place in the order (its geometry in
//! `tet::conditions`); a hold that reads the solved displacement and solves again is a
//! `rounds::Round`, run from `solve::solve`.

mod basis;
mod face;
mod holds;
mod mesh;
mod reduce;
mod report;
mod resolve;
mod roles;
mod rounds;
mod solve;
mod state;

pub(crate) use mesh::system_size;
pub use report::{NewtonStep, ScanEnd, TetReport};

use super::predicted::Predicted;
use crate::case::{Case, TetMaterial};
use crate::compare::stats;
use crate::error::Result;
use crate::fem::cholesky::{MeshAnalyses, Ordering};
use crate::mesh::Mesh;
use crate::pipeline::stage::Stage;
use crate::pipeline::{Recorder, Scene};
use crate::plan::PlanBasis;
use crate::tet::conditions::Mucosa;
use crate::tet::embed::SkinEmbedding;
use crate::tet::from_ct::{NodeKind, SoftTissueMesh};
use crate::tet::holds::SolverUsed;
use crate::tet::quadratic::Tet10Mesh;
use crate::tet::vtu::{FIXED, FREE, MOVED, SLIDING};
use crate::tet::{Constrained, Hold, TissueElastic};
use std::path::Path;

/// The solved volumetric model, kept for the outputs (tets.vtu) and the report.
pub struct Volumetric {
    pub mesh: SoftTissueMesh,
    /// The 10-node mesh that was solved (`[tet] element = "quadratic"`).
    pub quadratic: Option<Tet10Mesh>,
    /// Per solved node (the corners, then the midpoints when quadratic): FREE, FIXED or MOVED.
    pub constraint: Vec<u8>,
    /// Per tetrahedron.
    pub material: Vec<TissueElastic>,
    /// Per solved node (mm).
    pub displacement: Vec<[f64; 3]>,
    pub report: TetReport,
    /// The plan basis of this solve (docs/design/plan-basis.md).
    pub basis: Option<PlanBasis>,
    /// What a solve with other tissue parameters reuses ([`Volumetric::resolve`]).
    pub reuse: Reuse,
    /// The nonlinear material: the linear model's face under the same holds (the Newton
    /// start), to report how far the two differ per region.
    pub linear_face: Option<Vec<[f64; 3]>>,
}

/// The parts of a run that do not depend on the tissue parameters: the node roles, the mucosa
/// and its bone, the face's embedding in the mesh (docs/guide/uncertainty.md).
pub struct Reuse {
    kind: Vec<NodeKind>,
    mucosa: Vec<Option<Mucosa>>,
    embedding: SkinEmbedding,
    /// Per face vertex: at rest whatever the solve (`face::still`).
    face_still: Vec<bool>,
    /// Per solved node: a skin node on the face (`tet::conditions::on_face`).
    on_face: Vec<bool>,
    /// Per tetrahedron: torn by the run's move (`[tet] tear_gap`); a re-solve keeps it torn.
    torn: Vec<bool>,
    /// The solved nodes the run's move lifted off the bone (freed): a re-solve with sliding keeps
    /// them free, so that at the run's own parameters it is the run's face (with sliding off
    /// the tissue stays bonded and nothing lifts off, as in a run).
    lifted: Vec<usize>,
    linear_solve: bool,
    /// The linear mesh's node ordering and symbolic analyses for its factors
    /// (`fem::cholesky::MeshAnalyses`), made by the run; None for the 10-node element (its own
    /// nodes) or a mesh METIS could not order.
    order: Option<MeshAnalyses>,
    /// Nonzeros of the run's factor (0 when it kept none): whether a re-solve's factorisation
    /// runs on one core (`Volumetric::solves_at_once`).
    factor_nonzeros: usize,
    /// The run's system was solved iteratively (`Constrained::quadratic`): its re-solves run
    /// one at a time (each holds a 10-node operator, not a small factor).
    iterative: bool,
}

impl Reuse {
    fn ordering(&self) -> Ordering<'_> {
        mesh::ordering(&self.order)
    }

    /// `hold` with the run's lifted-off nodes freed when `case` slides (the state they lifted
    /// off in; the run's lift-off rounds).
    fn lift_off(&self, mut hold: Vec<Hold>, case: &Case) -> Vec<Hold> {
        if case.tet.sliding && case.tet.release_cuts {
            for &n in &self.lifted {
                hold[n] = Hold::Free;
            }
        }
        hold
    }
}

impl Volumetric {
    /// How many re-solves (`resolve`) to run side by side (`fem::cholesky::
    /// factorisations_at_once` of the run's factor; the real CT's: 8 samples in 6.4 s two at a
    /// time, 12.0 s one at a time).
    pub(crate) fn solves_at_once(&self) -> usize {
        if self.reuse.iterative {
            return 1;
        }
        crate::fem::cholesky::factorisations_at_once(self.reuse.factor_nonzeros)
    }

    /// The solved nodes (corners, then midpoints when quadratic).
    pub fn nodes(&self) -> &[[f64; 3]] {
        self.quadratic
            .as_ref()
            .map_or(&self.mesh.nodes, |q| &q.nodes)
    }

    /// Write tets.vtu (docs/reference/case.md): the solved mesh, displacement, constraint codes, cell
    /// materials and tissue labels.
    pub(crate) fn write_vtu(&self, path: &std::path::Path) -> Result<()> {
        use crate::tet::vtu::{Cells, TetsVtu};
        let youngs: Vec<f64> = self.material.iter().map(|m| m.youngs_kpa).collect();
        let poisson: Vec<f64> = self.material.iter().map(|m| m.poisson).collect();
        let cells = match &self.quadratic {
            Some(q) => Cells::Quadratic(&q.tets),
            None => Cells::Linear(&self.mesh.tets),
        };
        crate::tet::vtu::write(
            path,
            &TetsVtu {
                nodes: self.nodes(),
                cells,
                displacement: &self.displacement,
                constraint: &self.constraint,
                youngs_kpa: &youngs,
                poisson: &poisson,
                tissue: &self.mesh.tissue,
            },
        )
    }
}

/// The volumetric model's prediction: it carries the skin at full resolution (a dense scan
/// needs no coarse copy).
pub(super) fn predict_face(
    scene: &Scene,
    case: &Case,
    rec: &mut Recorder,
) -> Result<Predicted<Option<Volumetric>>> {
    let skin = face_mesh(scene).clone();
    let mut face_post = skin.clone();
    face_post.colors = None;
    let mut basis = None;
    let volumetric = match predict(scene, case, &skin, rec)? {
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
    Ok(Predicted {
        skin,
        face_post,
        basis,
        solved: volumetric,
    })
}

/// The face the volumetric model carries: the fine face when the case asks for one.
pub(super) fn face_mesh(scene: &Scene) -> &Mesh {
    scene.face.fine.as_ref().unwrap_or(&scene.face.skin)
}

/// What a volumetric solve is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Purpose {
    /// A run: the face, and the plan basis on the run's factor.
    Run,
    /// The face alone (the discretisation estimate's coarse solve, `model::coarse_face`): no
    /// plan basis, and a 10-node system iterates even where its factor would fit, since one
    /// solve does not repay a factorisation.
    FaceOnly,
}

/// Mesh, hold, solve and carry the face, and build the plan basis; None when the plan moves no
/// bone.
pub fn predict(
    scene: &Scene,
    case: &Case,
    skin: &Mesh,
    rec: &mut Recorder,
) -> Result<Option<(Volumetric, Vec<[f64; 3]>)>> {
    predict_for(scene, case, skin, Purpose::Run, rec)
}

/// [`predict`] for `purpose`.
pub(crate) fn predict_for(
    scene: &Scene,
    case: &Case,
    skin: &Mesh,
    purpose: Purpose,
    rec: &mut Recorder,
) -> Result<Option<(Volumetric, Vec<[f64; 3]>)>> {
    let t = &case.tet;
    // The landmarks the region needs (the nose tip), located in the landmark stage's time;
    // the run's landmark stage reads them back from the scene.
    rec.time(Stage::Landmarks, "locating landmarks", || {
        Ok(scene.landmarks_pre(skin, Path::new("case.toml")).ok())
    })?;
    let Some(meshed) = mesh::build(scene, case, skin, rec)? else {
        return Ok(None);
    };
    let bone = roles::bone(scene, case);
    let anatomy = roles::find(scene, case, skin, &meshed, &bone, rec)?;
    let mesh::Meshed {
        roi,
        nose_tip,
        mesh,
        material,
        linear,
        quadratic,
        kind,
    } = meshed;
    let linear_solve = quadratic.is_some() || t.material == TetMaterial::Linear;
    let roles = roles::Roles {
        kind: &kind,
        mucosa: &anatomy.mucosa,
        on_face: &anatomy.on_face,
        scan: scene.vol.bounds(),
    };
    let (holds, held) =
        holds::hold_tissue(&mesh, quadratic.as_ref(), roles, &bone, case, linear_solve);
    let overlapping_segments = holds.overlapping_segments();
    // Not a warning: the bundled jaws phantom and both real CTs end in tissue within 3 mm of
    // moved bone (docs/design/pipeline.md "Region").
    let scan_end = report::scan_end(
        &mesh.nodes,
        &holds.constraint,
        scene.vol.bounds(),
        held.on_scan_end,
    );
    let largest = holds::largest_move(&holds);
    holds::check(&held, largest, &mesh, roi, case, rec)?;
    let embedding = rec.time(Stage::Embed, "embedding the face in the mesh", || {
        let on_skin = |f: [u32; 3]| f.iter().all(|n| mesh.kind[*n as usize] == NodeKind::Skin);
        let reach = (1.5 * t.skin_size_mm).max(3.0);
        Ok(SkinEmbedding::new(
            &mesh.nodes,
            &mesh.tets,
            on_skin,
            &skin.vertices,
            reach,
            roi,
        ))
    })?;
    // The tetrahedra that carry a face vertex: the face itself, which never tears.
    let mut carries_face = vec![false; mesh.tets.len()];
    for e in embedding.tet.iter().flatten() {
        carries_face[*e as usize] = true;
    }
    let inputs = solve::Inputs {
        quadratic: quadratic.as_ref(),
        kind: &kind,
        material: &material,
        raised: &anatomy.raised,
        carries_face: &carries_face,
        linear_solve,
        face_only: purpose == Purpose::FaceOnly,
        tears: t.tear_gap && quadratic.is_none() && largest <= holds::LARGE_MOVE_MM,
    };
    let solved = rec.time(Stage::Solve, "solving the volumetric model", || {
        solve::solve(&inputs, linear, holds, t)
    })?;
    if let Some(w) = &solved.fallback {
        rec.warn(w);
    }
    let one_sided = &solved.one_sided;
    if !one_sided.settled {
        rec.warn(format!(
            "[tet] degloved_maxilla/degloved_chin: the raised tissue's one-sided contact did not settle in {} rounds ({} nodes lifted off, the deepest {:.3} mm inside its bone's move)",
            rounds::ONE_SIDED_ROUNDS,
            one_sided.lifted_in_tension,
            one_sided.penetration_mm
        ));
    }
    let inverted = match &quadratic {
        Some(q) => q.inverted_after(&solved.displacement),
        None => solved.linear.inverted_after(&solved.displacement),
    };
    let damage = report::damage(
        inverted,
        &solved.torn,
        &mesh,
        &solved.constraint,
        &carries_face,
        (t.tear_gap, largest),
        rec,
    );
    let run = Run {
        roi,
        nose_tip,
        mesh,
        quadratic,
        kind,
        anatomy,
        held,
        scan_end,
        overlapping_segments,
        embedding,
        damage,
        linear_solve,
    };
    finish(run, solved, case, skin, purpose, rec).map(Some)
}

/// What the stages before the face hand on to it.
struct Run {
    roi: mesh::Box3,
    nose_tip: Option<[f64; 3]>,
    mesh: SoftTissueMesh,
    quadratic: Option<Tet10Mesh>,
    kind: Vec<NodeKind>,
    anatomy: roles::Anatomy,
    held: holds::Held,
    scan_end: Option<ScanEnd>,
    overlapping_segments: Vec<usize>,
    embedding: SkinEmbedding,
    damage: report::Damage,
    linear_solve: bool,
}

/// Carry the face, build the plan basis on the run's factor, and assemble the report and what
/// re-solves reuse.
fn finish(
    run: Run,
    mut solved: solve::Solution,
    case: &Case,
    skin: &Mesh,
    purpose: Purpose,
    rec: &mut Recorder,
) -> Result<(Volumetric, Vec<[f64; 3]>)> {
    let face_still = face::still(&face::Stillness {
        roi: run.roi,
        mesh_box: run.mesh.lattice_box,
        face: &skin.vertices,
        face_rigid: &crate::pipeline::model::rigid_mask(case, &skin.vertices),
        carried_by: &run.embedding.tet,
        tets: &run.mesh.tets,
        on_face: &run.anatomy.on_face,
        node_rigid: &crate::pipeline::model::rigid_mask(case, &run.mesh.nodes),
    });
    let carrier = face::Carrier {
        embedding: &run.embedding,
        quadratic: run.quadratic.as_ref(),
        tets: &run.mesh.tets,
        still: &face_still,
    };
    let carried = rec.time(Stage::Embed, "carrying the face", || {
        Ok(carrier.carry(&solved.displacement))
    })?;
    let factor_nonzeros = solved.factor.as_ref().map_or(0, Constrained::factor_nnz);
    let solver = solved
        .factor
        .as_ref()
        .map_or(SolverUsed::Direct, Constrained::solver_used);
    let run_factor = solved.factor.take();
    let basis = if purpose == Purpose::FaceOnly {
        None
    } else {
        Some(rec.time(Stage::PlanBasis, "building the plan basis", || {
            // The nonlinear material slides on the moved bone's normals: where a rotation turned
            // them, the basis (the linear model at rest) needs its own factor.
            let rest: Vec<Hold> = solved.linear_hold.iter().map(|l| l.hold(&[])).collect();
            let factor = match run_factor {
                Some(c) if c.takes(&rest) => c,
                run_factor => {
                    // The run's factor goes before the basis's is made: two at once would set
                    // the run's peak memory.
                    drop(run_factor);
                    let k = state::stiffness(run.quadratic.as_ref(), &solved.linear)?;
                    state::constrain(
                        run.quadratic.as_ref(),
                        &k,
                        &rest,
                        mesh::ordering(&solved.order),
                        false,
                    )?
                }
            };
            let inputs = basis::BasisInputs {
                factor: &factor,
                linear_hold: &solved.linear_hold,
                overlapping_segments: &run.overlapping_segments,
                nonlinear: !run.linear_solve,
                skin,
                run_face_displacement: &carried,
            };
            basis::plan_basis(&inputs, case, |u| carrier.carry(u))
        })?)
    };
    let report = tet_report(&run, &solved, case, factor_nonzeros, solver);
    let face_post = face::displaced(skin, &carried);
    let linear_face = solved
        .linear_start
        .as_ref()
        .map(|u| face::displaced(skin, &carrier.carry(u)));
    let Run {
        mesh,
        quadratic,
        kind,
        anatomy,
        embedding,
        linear_solve,
        ..
    } = run;
    Ok((
        Volumetric {
            linear_face,
            mesh,
            quadratic,
            constraint: solved.constraint,
            material: solved.linear.material,
            displacement: solved.displacement,
            report,
            basis,
            reuse: Reuse {
                kind,
                mucosa: anatomy.mucosa,
                embedding,
                face_still,
                on_face: anatomy.on_face,
                torn: solved.torn,
                lifted: solved.lifted,
                linear_solve,
                order: solved.order,
                factor_nonzeros,
                iterative: solver != SolverUsed::Direct,
            },
        },
        face_post,
    ))
}

/// report.json's `tet` section of a run.
fn tet_report(
    run: &Run,
    solved: &solve::Solution,
    case: &Case,
    factor_nonzeros: usize,
    solver: SolverUsed,
) -> TetReport {
    let t = &case.tet;
    let (e, constraint, a) = (&run.embedding, &solved.constraint, &run.anatomy);
    let reached: Vec<f64> = (0..e.distance.len())
        .filter(|i| e.reached(*i))
        .map(|i| e.distance[i])
        .collect();
    let counted = report::counted;
    let nodes = run.kind.len();
    TetReport {
        material: t.material,
        element: t.element,
        region: run.roi,
        mesh_box: Some(run.mesh.lattice_box),
        region_grown_for_nose_tip: run.nose_tip,
        nodes,
        tets: run.mesh.tets.len(),
        dofs: 3 * nodes,
        free_dofs: 3 * counted(constraint, FREE),
        factor_nonzeros,
        solver: report::SolverReport::of(solver),
        skin_nodes: run.kind.iter().filter(|k| **k == NodeKind::Skin).count(),
        mucosa_nodes: a.mucosa_nodes,
        sliding_nodes: counted(constraint, SLIDING),
        contact_nodes: a.contact_nodes,
        contact_sliding_nodes: (0..run.mesh.nodes.len())
            .filter(|n| a.covered[*n].is_some_and(|c| c.tooth))
            .filter(|n| constraint[*n] == SLIDING)
            .count(),
        moved_nodes: counted(constraint, MOVED),
        fixed_nodes: counted(constraint, FIXED),
        quality: run.mesh.quality.clone(),
        inverted_elements: run.damage.inverted,
        inverted_between_moved_and_held_bone: run.damage.at_cuts,
        released_at_cuts: run.held.released_at_cuts,
        lifted_off: solved.lifted.len(),
        torn_elements: run.damage.torn_elements,
        torn_volume_mm3: run.damage.torn_volume_mm3,
        degloved_nodes: a.deglove.nodes,
        lifted_in_tension: solved.one_sided.lifted_in_tension,
        lifted_penetration_mm: solved.one_sided.penetration_mm,
        degloved_settled: solved.one_sided.settled,
        degloved_not_applied: a.deglove.not_applied.clone(),
        degloved_chin_nodes: a.deglove.chin_nodes,
        degloved_chin_not_applied: a.deglove.chin_not_applied.clone(),
        floating_pieces: run.held.pieces,
        scan_end: run.scan_end,
        newton: solved.newton.clone(),
        face_vertices_unreached: e.unreached(),
        face_to_mesh_mm: stats(&reached),
    }
}

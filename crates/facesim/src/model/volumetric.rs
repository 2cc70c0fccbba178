//! The volumetric model (`[solve] model = "tet"`; docs/pipeline.md "Volumetric
//! soft tissue"): the soft tissue between skin and bone is meshed with tetrahedra inside the
//! region the plan reaches, bone nodes follow their segment rigidly, the region's cut faces are
//! held, the skin is free; the solved displacement carries the face (the extracted skin or the
//! given scan, at full resolution).

use super::degloved::{self, Approach};
use super::predicted::Predicted;
use crate::case::{Case, Degloved, ScanEndHold, TetElement, TetMaterial};
use crate::compare::{DistanceStats, stats};
use crate::error::{Error, Result};
use crate::fem::cholesky::{MeshAnalyses, Ordering};
use crate::fem::ordering::NodeOrder;
use crate::mesh::Mesh;
use crate::pipeline::stage::Stage;
use crate::pipeline::{Recorder, Scene};
use crate::plan::{PlanBasis, SegmentBasis};
use crate::tet::conditions::{
    Bone, Holds, Mucosa, covered_bone, follow_bone, hold_floating_pieces, holds, materials,
    midpoint_kinds, mucosa, on_face, release_at_cuts,
};
use crate::tet::embed::SkinEmbedding;
use crate::tet::from_ct::{MeshParams, NodeKind, SoftTissueMesh};
use crate::tet::newton_krylov;
use crate::tet::nonlinear::{self, Newton};
use crate::tet::plan_holds::LinearHold;
use crate::tet::quadratic::{Rule, Tet10Mesh};
use crate::tet::quality::Quality;
use crate::tet::vtu::{FIXED, FREE, MOVED, SLIDING};
use crate::tet::{Constrained, Hold, Loads, TetMesh, TissueElastic};
use serde::{Deserialize, Serialize};
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
    /// The plan basis of this solve (docs/plan-basis.md).
    pub basis: Option<PlanBasis>,
    /// What a solve with other tissue parameters reuses ([`Volumetric::resolve`]).
    pub reuse: Reuse,
    /// The nonlinear material: the linear model's face under the same holds (the Newton
    /// start), to report how far the two differ per region.
    pub linear_face: Option<Vec<[f64; 3]>>,
}

/// The parts of a run that do not depend on the tissue parameters: the node roles, the mucosa
/// and its bone, the face's embedding in the mesh (docs/uncertainty.md).
pub struct Reuse {
    kind: Vec<NodeKind>,
    mucosa: Vec<Option<Mucosa>>,
    embedding: SkinEmbedding,
    face_rigid: Vec<bool>,
    /// Per solved node: a skin node on the face (`tet::conditions::on_face`).
    on_face: Vec<bool>,
    /// Per tetrahedron: in the external nose (`[tet] nose_youngs_kpa`; `model::nose`).
    nose: Option<Vec<bool>>,
    /// Per tetrahedron: torn by the run's move (`[tet] tear_gap`); a re-solve keeps it torn.
    torn: Vec<bool>,
    /// The solved nodes the run's move lifted off the bone (freed): a re-solve with sliding keeps
    /// them free, so that at the run's own parameters it is the run's face (with sliding off
    /// the tissue stays bonded and nothing lifts off, as in a run).
    lifted: Vec<usize>,
    /// The nodes `[tet] septum_detached` holds still (empty without it); a re-solve holds them
    /// alike.
    still: Vec<bool>,
    roi: ([f64; 3], [f64; 3]),
    linear_solve: bool,
    /// The linear mesh's node ordering and symbolic analyses for its factors
    /// (`fem::cholesky::MeshAnalyses`), made by the run; None for the 10-node element (its own
    /// nodes) or a mesh METIS could not order.
    order: Option<MeshAnalyses>,
    /// Nonzeros of the run's factor (0 when it kept none): whether a re-solve's factorisation
    /// runs on one core (`Volumetric::solves_at_once`).
    factor_nonzeros: usize,
}

impl Reuse {
    fn ordering(&self) -> Ordering<'_> {
        ordering(&self.order)
    }

    /// `hold` with the run's lifted-off nodes freed when `case` slides (the state they lifted
    /// off in; `Volumetric::predict`'s lift-off rounds).
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
        crate::fem::cholesky::factorisations_at_once(self.reuse.factor_nonzeros)
    }

    /// The solved nodes (corners, then midpoints when quadratic).
    pub fn nodes(&self) -> &[[f64; 3]] {
        self.quadratic
            .as_ref()
            .map_or(&self.mesh.nodes, |q| &q.nodes)
    }

    /// The face positions (per vertex of `skin`, the run's face) with other tissue
    /// parameters (`case.tet`'s moduli, Poisson ratios and sliding; the plan and mesh settings
    /// must be the run's): the stiffness is assembled and factored again, the mesh, node roles,
    /// mucosa and face embedding are the run's.
    pub fn resolve(&self, scene: &Scene, case: &Case, skin: &Mesh) -> Result<Vec<[f64; 3]>> {
        let r = &self.reuse;
        let nodes = self.nodes();
        let (Holds { hold, .. }, _) = hold_tissue(
            &self.mesh,
            self.quadratic.as_ref(),
            Roles {
                kind: &r.kind,
                mucosa: &r.mucosa,
                on_face: &r.on_face,
                still: &r.still,
                scan: scene.vol.bounds(),
            },
            &bone(scene, case),
            case,
            r.linear_solve,
        );
        let hold = r.lift_off(hold, case);
        let linear = TetMesh {
            nodes: self.mesh.nodes.clone(),
            tets: self.mesh.tets.clone(),
            material: torn_trace(
                with_nose(
                    materials(&self.mesh.tissue, &case.tet),
                    r.nose.as_deref(),
                    case.tet.nose_youngs_kpa,
                ),
                &r.torn,
            ),
        };
        let quadratic = self
            .quadratic
            .as_ref()
            .map(|_| Tet10Mesh::from_linear(&linear, Rule::Full));
        let u = if r.linear_solve {
            let k = match &quadratic {
                Some(q) => q.assemble()?,
                None => linear.assemble()?,
            };
            let c = Constrained::ordered(&k, &hold, nodes.len(), r.ordering())?;
            let f = Loads::none().nodal_vector(nodes.len())?;
            c.solve(&[(&hold, &f)])?.remove(0)
        } else {
            // As the run: Newton from the linear answer, preconditioned by its factor.
            let c = Constrained::ordered(&linear.assemble()?, &hold, nodes.len(), r.ordering())?;
            let f = Loads::none().nodal_vector(nodes.len())?;
            let start = c.solve(&[(&hold, &f)])?.remove(0);
            newton_krylov::solve(&linear, &c, &start, &newton_krylov::Options::default())?
                .displacements
        };
        let carried = carry_face(
            &r.embedding,
            quadratic.as_ref(),
            &self.mesh.tets,
            &u,
            skin,
            &r.face_rigid,
            r.roi,
        );
        Ok(displaced(skin, &carried))
    }

    /// The certified reduced model of this linear model for `case`'s sliding state
    /// (docs/reduced.md): the stiffness split by tissue and Lamé parameter on the run's mesh,
    /// node roles, mucosa and face embedding; a greedy over `train` (cases differing in tissue
    /// parameters only) from the reference `case`. The linear element and material only: the
    /// neo-Hookean tangent is not affine in the parameters, the 10-node element is not yet split.
    pub fn reduced(
        &self,
        scene: &Scene,
        case: &Case,
        skin: &Mesh,
        training: &super::reduced::Training,
        progress: &dyn Fn(&str),
    ) -> Result<super::reduced::ReducedTet> {
        use super::reduced::{FaceMap, ReducedTet};
        let (train, greedy) = (training.cases, training.greedy);
        use crate::reduced::{Affine, Basis, affine::solve_columns, norm::largest_eigenvalue};
        let start = std::time::Instant::now();
        let r = &self.reuse;
        if !r.linear_solve || self.quadratic.is_some() {
            return Err(Error::config(
                "the reduced model needs [tet] material = \"linear\" and element = \"linear\"",
            ));
        }
        let c = case;
        let sliding = c.tet.sliding;
        let (Holds { hold, .. }, _) = hold_tissue(
            &self.mesh,
            None,
            Roles {
                kind: &r.kind,
                mucosa: &r.mucosa,
                on_face: &r.on_face,
                still: &r.still,
                scan: scene.vol.bounds(),
            },
            &bone(scene, c),
            c,
            true,
        );
        let hold = r.lift_off(hold, c);
        // The external nose's tetrahedra are their own terms (`[tet] nose_youngs_kpa`): the
        // stiffness stays affine, the nose's θ fixed by its modulus and its tissue's ν.
        let slot: Vec<usize> = self
            .mesh
            .tissue
            .iter()
            .enumerate()
            .map(|(t, l)| {
                let s = crate::case::Tet::slot(*l);
                match &r.nose {
                    Some(nose) if nose[t] => super::reduced::NOSE_SLOTS + s,
                    _ => s,
                }
            })
            .collect();
        let scale: Vec<f64> = r
            .torn
            .iter()
            .map(|t| if *t { TORN_STIFFNESS } else { 1.0 })
            .collect();
        let terms = crate::tet::lame_term_list(&slot);
        let lame = crate::tet::LameTerms::new(&self.mesh.nodes, &self.mesh.tets, &slot, &scale);
        let affine = Affine::new(&lame, &terms, &hold, r.ordering())?;
        drop(lame);
        let theta = |t: &crate::case::Tet| {
            super::reduced::theta_of(&terms, &t.tissues(), t.nose_youngs_kpa)
        };
        let train: Vec<Vec<f64>> = train.iter().map(|t| theta(&t.tet)).collect();
        let theta_bar = theta(&c.tet);
        let mut theta_box = [theta_bar.clone(), theta_bar.clone()];
        for t in &train {
            for (q, v) in t.iter().enumerate() {
                theta_box[0][q] = theta_box[0][q].min(*v);
                theta_box[1][q] = theta_box[1][q].max(*v);
            }
        }
        let (mut basis, x) = Basis::build(&affine, &theta_bar, &train, greedy, progress)?;
        let face_map = FaceMap {
            tets: self.mesh.tets.clone(),
            cell: r.embedding.tet.clone(),
            weights: r.embedding.weights.clone(),
            still: still(&r.face_rigid, r.roi, &skin.vertices),
        };
        let zero = vec![0.0; affine.unknowns()];
        // The face of free values (held values zero): a basis vector, a Riesz vector, an error.
        let carry = |v: &[f64]| face_map.carry(&affine.expand(v, false));
        let face = crate::reduced::LinearFace::new(
            face_map.carry(&affine.expand(&zero, true)),
            basis.vectors.iter().map(|v| carry(v)).collect(),
        );
        progress("reduced model: the face's gain");
        let nodes = self.mesh.nodes.len();
        let nv = face_map.cell.len();
        let lanczos = std::cell::Cell::new(0usize);
        let gain2 = largest_eigenvalue(3 * nv, 40, &|y: &[f64]| {
            lanczos.set(lanczos.get() + 1);
            let y3: Vec<[f64; 3]> = y.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
            let b = affine.restrict(&face_map.carry_transpose(&y3, nodes));
            let z = solve_columns(&x, &[b]).remove(0);
            carry(&z).into_iter().flatten().collect()
        });
        // Each output's gain: its 3×3 block of L X⁻¹ Lᵀ, the outputs' columns solved in blocks
        // (a block of columns costs a fraction of as many single solves).
        let mut rhs: Vec<Vec<f64>> = Vec::with_capacity(3 * training.outputs.len());
        for w in training.outputs {
            for k in 0..3 {
                let mut y = vec![[0.0; 3]; nv];
                for (v, a) in w {
                    y[*v][k] += a;
                }
                rhs.push(affine.restrict(&face_map.carry_transpose(&y, nodes)));
            }
        }
        // Four outputs' columns a solve: the blocks' cost, with no 3 × outputs columns held
        // three times over at once (the two states build side by side).
        let z: Vec<Vec<f64>> = rhs.chunks(12).flat_map(|b| solve_columns(&x, b)).collect();
        let output_gains: Vec<f64> = rhs
            .chunks(3)
            .zip(z.chunks(3))
            .map(|(rhs, z)| {
                let g =
                    nalgebra::Matrix3::from_fn(|i, j| crate::reduced::basis::dot(&rhs[i], &z[j]));
                let g = (g + g.transpose()) * 0.5;
                g.symmetric_eigenvalues().max().max(0.0).sqrt()
            })
            .collect();
        drop((rhs, z));
        let face_gain = gain2.max(0.0).sqrt();
        // The face's and each output's images of the Riesz space's vectors, for the bounds
        // through the Riesz representer (`reduced::OutputBound`); then the space is dropped.
        progress("reduced model: the bounds' images");
        let faces: Vec<Vec<[f64; 3]>> = std::mem::take(&mut basis.riesz_space)
            .into_iter()
            .map(|e| carry(&e))
            .collect();
        let output_bounds = training
            .outputs
            .iter()
            .zip(output_gains)
            .map(|(w, g)| {
                let images: Vec<Vec<f64>> = faces
                    .iter()
                    .map(|f| {
                        let mut y = vec![0.0; 3];
                        for (v, a) in w {
                            for k in 0..3 {
                                y[k] += a * f[*v][k];
                            }
                        }
                        y
                    })
                    .collect();
                crate::reduced::OutputBound::new(g, &images)
            })
            .collect();
        // The face's Gram matrix over the vertices the tissue can move only (1 015 of 19 260
        // on the real CT): the others' images are zero, and summing them was most of this stage.
        let moves: Vec<usize> = (0..nv)
            .filter(|v| face_map.cell[*v].is_some() && !face_map.still[*v])
            .collect();
        let face_bound = crate::reduced::OutputBound::new(
            face_gain,
            &faces
                .into_iter()
                .map(|f| moves.iter().flat_map(|v| f[*v]).collect())
                .collect::<Vec<Vec<f64>>>(),
        );
        Ok(ReducedTet {
            sliding,
            build: crate::reduced::ReducedReport {
                sliding,
                basis_size: basis.size(),
                full_factorisations: basis.full_factorisations,
                reference_solves: basis.riesz_solves + lanczos.get() + 3 * training.outputs.len(),
                cg_iterations: basis.cg_iterations,
                offline_seconds: start.elapsed().as_secs_f64(),
                face_gain,
                greedy: basis.history,
            },
            form: basis.form,
            terms,
            nose_youngs_kpa: if r.nose.is_some() {
                c.tet.nose_youngs_kpa
            } else {
                0.0
            },
            theta_box,
            face,
            face_bound,
            output_bounds,
        })
    }

    /// Write tets.vtu (docs/case.md): the solved mesh, displacement, constraint codes, cell materials
    /// and tissue labels.
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

/// One converged Newton load step of the nonlinear material.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct NewtonStep {
    pub load: f64,
    pub iterations: usize,
    pub residual: f64,
    /// Conjugate-gradient iterations of the step's Newton systems (0: factored).
    #[serde(default)]
    pub krylov_iterations: usize,
}

/// report.json's `tet` section.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TetReport {
    pub material: TetMaterial,
    pub element: TetElement,
    /// The face region (LPS mm): the box around the moved bone grown by `[tet] margin_mm`,
    /// within the CT, and grown further to hold the nose tip when the nose's base is inside.
    /// The face inside it is carried by the tissue mesh; the face beyond it stays.
    pub region: ([f64; 3], [f64; 3]),
    /// The tissue mesh's box (LPS mm): `region` grown by `[tet] margin_mm` once more, its upper
    /// corner rounded up to whole lattice cells (`tet::from_ct::SoftTissueMesh::lattice_box`).
    /// Its faces are held; where the scan ends inside it the tissue ends in a free surface.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh_box: Option<([f64; 3], [f64; 3])>,
    /// Pronasale (LPS mm) when the region was grown to hold it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region_grown_for_nose_tip: Option<[f64; 3]>,
    pub nodes: usize,
    pub tets: usize,
    pub dofs: usize,
    pub free_dofs: usize,
    /// Nonzeros of the Cholesky factor of the solved system: 8 bytes each, what sets the run's
    /// peak memory (`facesim estimate` predicts it before the run).
    #[serde(default)]
    pub factor_nonzeros: usize,
    /// Nodes per role: skin (free), bone moved with a segment, bone or cut faces held.
    pub skin_nodes: usize,
    /// Skin-kind nodes facing a cavity within `[tet] mucosa_gap_mm` of the skull, and those
    /// of them that slide (`[tet] sliding`; otherwise they move with the bone).
    pub mucosa_nodes: usize,
    pub sliding_nodes: usize,
    /// Bone-kind nodes where lip or cheek rests on a tooth with no air between
    /// (`tet::conditions::contact`: the tooth by its HU, the lip or cheek by the face's air
    /// reached through soft tissue), and those of them sliding in the solve (`[tet] sliding`, not
    /// lifted off); otherwise they stay attached to their bone.
    #[serde(default)]
    pub contact_nodes: usize,
    #[serde(default)]
    pub contact_sliding_nodes: usize,
    pub moved_nodes: usize,
    pub fixed_nodes: usize,
    pub quality: Quality,
    /// Linear material: elements the solved displacement turns inside out (the move is too
    /// large for small-strain elasticity; the nonlinear material handles it).
    pub inverted_elements: usize,
    /// Of those, the ones with nodes on both moved and held bone (the osteotomy's gap).
    pub inverted_between_moved_and_held_bone: usize,
    /// Bone nodes at the saw lines left unattached (`[tet] cut_release_mm`).
    #[serde(default)]
    pub released_at_cuts: usize,
    /// Bone and sliding nodes of elements a solve turned inside out, freed (the tissue lifts
    /// off the bone there) before solving again.
    #[serde(default)]
    pub lifted_off: usize,
    /// Tetrahedra off the face torn because the move still turned them inside out after lift-off
    /// (`[tet] tear_gap`), and their volume at rest (mm³).
    #[serde(default)]
    pub torn_elements: usize,
    #[serde(default)]
    pub torn_volume_mm3: f64,
    /// Tetrahedra of the external nose given `[tet] nose_youngs_kpa` (0 without it).
    #[serde(default)]
    pub nose_elements: usize,
    /// Nodes on the maxilla's nasal floor held still with the skull base (`[tet]
    /// septum_detached`; 0 without it).
    #[serde(default)]
    pub septum_nodes: usize,
    /// `[tet] degloved_maxilla` and `degloved_chin`: bone nodes of the raised regions (sliding,
    /// one-sided), those lifted off where the bone pulled them, and the deepest a lifted node
    /// lies inside its bone's move when the rounds end (mm; 0 when every lifted node is clear of
    /// it).
    #[serde(default)]
    pub degloved_nodes: usize,
    #[serde(default)]
    pub lifted_in_tension: usize,
    #[serde(default)]
    pub lifted_penetration_mm: f64,
    /// Whether the one-sided rounds settled: every raised node still on its bone pushed by it,
    /// every lifted one clear of it (false: a warning says how far from it they ended).
    #[serde(default)]
    pub degloved_settled: bool,
    /// Why `[tet] degloved_maxilla = "auto"` stepped aside on a plan that moves the upper teeth
    /// (absent when it served, was off, or had nothing to raise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degloved_not_applied: Option<String>,
    /// `[tet] degloved_chin`: of `degloved_nodes`, those the genioplasty's approach raised, and
    /// why `"auto"` stepped aside on a plan that moves a chin (absent when it did not).
    #[serde(default)]
    pub degloved_chin_nodes: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degloved_chin_not_applied: Option<String>,
    /// Pieces of the mesh held by fewer than three nodes, moved rigidly with their bone.
    #[serde(default)]
    pub floating_pieces: usize,
    /// Where the scan ends inside the tissue mesh's box: the free tissue nodes past the CT's
    /// outermost voxel centres (the surface the tissue ends in there) and how near bone the plan
    /// moves they come. None: the scan ends nowhere in the tissue, or no bone moves.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_end: Option<ScanEnd>,
    /// Nonlinear material: the load steps.
    pub newton: Option<Vec<NewtonStep>>,
    /// Face vertices farther from the mesh's skin than the reach (carried by extrapolation).
    pub face_vertices_unreached: usize,
    /// Distance from each carried face vertex to the mesh's skin boundary (mm).
    pub face_to_mesh_mm: DistanceStats,
}

/// The bone of the scene, moved by the case's plan; its normals where tissue slides on it at the
/// scale the mesh resolves there (`tet::bone_normal`).
fn bone<'a>(scene: &'a Scene, case: &'a Case) -> Bone<'a> {
    Bone::new(
        &scene.face.skull,
        &scene.model.plan,
        &case.osteotomy,
        case.tet.skin_size_mm,
    )
}

/// Per solved node: its kind, the mucosa or contact it slides on, whether it is the face's skin.
#[derive(Clone, Copy)]
struct Roles<'a> {
    kind: &'a [NodeKind],
    mucosa: &'a [Option<Mucosa>],
    on_face: &'a [bool],
    /// Nodes held still whatever their bone does (`[tet] septum_detached`; empty: none).
    still: &'a [bool],
    /// The CT's outermost voxel centres (`Volume::bounds`): where the scan ends.
    scan: ([f64; 3], [f64; 3]),
}

/// How `hold_tissue` held what the tissue's roles leave open.
struct Held {
    /// Bone nodes at the saw lines that slide instead (`[tet] release_cuts`).
    released_at_cuts: usize,
    /// Pieces of the mesh held by too few nodes, held rigidly, and their nodes.
    pieces: usize,
    piece_nodes: usize,
    /// Free nodes where the scan ends that slide on its end plane (`[tet] scan_end`).
    on_scan_end: usize,
}

/// Every solved node's hold (`tet::conditions::holds`; the nodes are the corners, then the
/// midpoints when `quadratic`), then the pieces of the mesh too loosely held to solve held still;
/// with how many pieces and nodes were so held. The run and its re-solves hold the tissue alike.
fn hold_tissue(
    mesh: &SoftTissueMesh,
    quadratic: Option<&Tet10Mesh>,
    roles: Roles,
    bone: &Bone,
    case: &Case,
    rest_normals: bool,
) -> (Holds, Held) {
    let Roles {
        kind,
        mucosa,
        on_face,
        still,
        scan,
    } = roles;
    let nodes = quadratic.map_or(&mesh.nodes, |q| &q.nodes);
    // `[surface] movable` holds the face outside it, not the walls of cavities.
    let rigid: Vec<bool> = crate::pipeline::model::rigid_mask(case, nodes)
        .into_iter()
        .zip(on_face)
        .map(|(r, f)| r && *f)
        .collect();
    let mut h = holds(
        nodes,
        kind,
        mucosa,
        &rigid,
        bone,
        case.tet.sliding,
        rest_normals,
    );
    // The solved cells: a 10-node mesh's midpoints are nodes of its cells, not of the corners'.
    let ms: Vec<_> = case
        .osteotomy
        .iter()
        .map(crate::plan::basis::matrix)
        .collect();
    let follow = follow_bone(bone, nodes);
    // Release the saw lines, then hold what floats; generic over the 4- and 10-node cells.
    fn condition<C: AsRef<[u32]>>(
        cells: &[C],
        nodes: &[[f64; 3]],
        kind: &[NodeKind],
        h: &mut Holds,
        tet: &crate::case::Tet,
        follow: &dyn Fn(&[usize]) -> Option<usize>,
        ms: &[[f64; crate::plan::basis::COLUMNS]],
    ) -> (usize, (usize, usize)) {
        let released = if tet.release_cuts {
            release_at_cuts(cells, nodes, kind, h, tet.cut_release_mm, tet.sliding)
        } else {
            0
        };
        (released, hold_floating_pieces(cells, nodes, h, follow, ms))
    }
    let (released, held) = match quadratic {
        Some(q) => condition(&q.tets, nodes, kind, &mut h, &case.tet, &follow, &ms),
        None => condition(&mesh.tets, nodes, kind, &mut h, &case.tet, &follow, &ms),
    };
    // After the floating pieces: a piece held by the scan's end plane alone could still slide
    // along it, so it is held with its bone as before.
    let on_scan_end = match case.tet.scan_end {
        ScanEndHold::Slides => crate::tet::conditions::slide_on_scan_end(&mut h, nodes, kind, scan),
        ScanEndHold::Free => 0,
    };
    hold_still(&mut h, still);
    (
        h,
        Held {
            released_at_cuts: released,
            pieces: held.0,
            piece_nodes: held.1,
            on_scan_end,
        },
    )
}

/// Hold `still`'s nodes where they are, in the run and in the plan basis.
fn hold_still(h: &mut Holds, still: &[bool]) {
    for (n, _) in still.iter().enumerate().filter(|(_, s)| **s) {
        h.constraint[n] = FIXED;
        h.hold[n] = Hold::Fixed([0.0; 3]);
        h.linear[n] = LinearHold::Still;
    }
}

/// `[tet] septum_detached`: the tissue on the nasal surface of the segment that carries the
/// upper teeth (`model::septum`), from the run's holds: a sliding node on that segment's bone
/// (its own position, or 2 mm into the bone along its normal) with the normal it slides on, a
/// bonded one with the bone surface's normal on its tissue's side. Empty when no segment carries
/// the upper teeth; Err says why the region was not found.
fn septum_nodes(
    mesh: &SoftTissueMesh,
    found: &(
        Option<crate::landmarks::HeadFrame>,
        Vec<crate::landmarks::Landmark>,
    ),
    covered: &[Option<crate::tet::conditions::Covered>],
    holds: &Holds,
    bone: &Bone,
    case: &Case,
) -> std::result::Result<Vec<bool>, String> {
    let Some(frame) = found.0.as_ref() else {
        return Err("needs the pre-operative landmarks' head frame, which was not found".into());
    };
    let Some(maxilla) = degloved::upper_teeth_segment(frame, &mesh.nodes, covered) else {
        return Ok(Vec::new());
    };
    let Some(sn) = found
        .1
        .iter()
        .find(|l| l.label == "Sn")
        .and_then(|l| l.position)
    else {
        return Err("needs subnasale (Sn), which was not found".into());
    };
    let on =
        |p: [f64; 3]| crate::tet::plan_holds::segment_at(&case.osteotomy, p).0 == Some(maxilla);
    let inward = crate::tet::conditions::into_tissue(&mesh.nodes, &mesh.tets, &mesh.kind);
    let on_maxilla: Vec<Option<[f64; 3]>> = (0..mesh.nodes.len())
        .map(|n| {
            let p = mesh.nodes[n];
            match holds.hold[n] {
                Hold::Slide { normal, .. } => {
                    let deep = [0, 1, 2].map(|c| p[c] - 2.0 * normal[c]);
                    (on(p) || on(deep)).then_some(normal)
                }
                Hold::Fixed(_)
                    if holds.constraint[n] == MOVED && mesh.kind[n] == NodeKind::Bone && on(p) =>
                {
                    bone.normals().at(p, inward[n])
                }
                _ => None,
            }
        })
        .collect();
    Ok(super::septum::held_still(
        frame,
        sn,
        &mesh.nodes,
        &on_maxilla,
    ))
}

/// Where the scan ends in the tissue (report.json `tet.scan_end`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct ScanEnd {
    /// The tissue's free surface there.
    pub free_nodes: usize,
    /// Nodes there sliding on the scan's end plane (`[tet] scan_end = "slides"`; 0 with
    /// `"free"`). Defaulted when absent: a report.json written before session 63 had none.
    #[serde(default)]
    pub sliding_nodes: usize,
    /// From the nearest of them to a node on bone the plan moves (mm).
    pub nearest_moved_bone_mm: f64,
}

/// The tissue past the CT's outermost voxel centres (`bounds`), where the scan ends (beyond the
/// CT the fields read air, docs/pipeline.md "Region"): its free nodes, the `sliding` nodes
/// `[tet] scan_end` slides on the end plane, and the distance from the nearest free or sliding
/// node there to moved bone; None when there are none or nothing moves.
fn scan_end(
    nodes: &[[f64; 3]],
    constraint: &[u8],
    bounds: ([f64; 3], [f64; 3]),
    sliding: usize,
) -> Option<ScanEnd> {
    let (end, free_nodes) = nodes
        .iter()
        .zip(constraint)
        .filter(|(p, c)| {
            (**c == FREE || (sliding > 0 && **c == SLIDING))
                && crate::volume::past_scan_end(bounds, **p)
        })
        .fold((Vec::new(), 0), |(mut end, free), (p, c)| {
            end.push(*p);
            (end, free + usize::from(*c == FREE))
        });
    let moved: Vec<[f64; 3]> = nodes
        .iter()
        .zip(constraint)
        .filter(|(_, c)| **c == MOVED)
        .map(|(p, _)| *p)
        .collect();
    let nearest = end
        .iter()
        .flat_map(|a| {
            moved
                .iter()
                .map(move |b| crate::vec3::norm(crate::vec3::sub(*a, *b)))
        })
        .fold(f64::INFINITY, f64::min);
    (!end.is_empty() && nearest.is_finite()).then_some(ScanEnd {
        free_nodes,
        sliding_nodes: sliding,
        nearest_moved_bone_mm: nearest,
    })
}

/// The face region (LPS mm): the box around the skull points the plan moves, grown by `margin`
/// and kept inside the CT's voxel centres, then grown to take in the nose ([`take_in_nose`]), with
/// the nose tip when it grew; None when the plan moves no bone. The face inside it is carried by
/// the mesh; the mesh itself fills this box grown by `margin` once more ([`MeshParams`]), whose
/// faces are held. That second margin reaches past the CT wherever the first was clipped, so
/// where the scan ends the tissue ends in a free surface, not a held one: the anatomy beyond the
/// scan is not modelled, and holding the scan's end instead pinned the real CT's upper lip, cut
/// by the scan 4.5 mm below labrale superius (docs/pipeline.md "Region").
fn region(scene: &Scene, skin: &Mesh, margin: f64) -> Option<(Box3, Option<[f64; 3]>)> {
    let skull = &scene.face.skull.vertices;
    let (_, moved) = scene.model.plan.apply(skull, 1.0);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (p, _) in skull.iter().zip(&moved).filter(|(_, m)| **m) {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c] - margin);
            hi[c] = hi[c].max(p[c] + margin);
        }
    }
    let (vlo, vhi) = scene.vol.bounds();
    for c in 0..3 {
        lo[c] = lo[c].max(vlo[c]);
        hi[c] = hi[c].min(vhi[c]);
    }
    (lo[0] <= hi[0]).then(|| take_in_nose((lo, hi), scene, skin, &moved))
}

/// An axis-aligned box (LPS mm): lowest and highest corner.
type Box3 = ([f64; 3], [f64; 3]);

/// Room kept about the nose tip when the region is grown to take in the nose (mm): as near as
/// `facesim validate` lets a landmark come to a held face before it says the hold may set its move.
const NOSE_ROOM_MM: f64 = 10.0;

/// `roi` grown to hold pronasale with [`NOSE_ROOM_MM`] about it when the nose's base (subnasale)
/// is inside it and its nearest bone moves, within the CT; the nose tip's position when it grew.
/// The region's cut faces are held, and the nose is a cantilever whose tip follows its base: a
/// face cutting through it holds the tip still (the jaws phantoms with 2–4 mm more tissue:
/// pronasale 4.6 mm outside the box of a 5 mm Le Fort I at `margin_mm` 30, not moving at all).
/// The landmarks are the pre-operative skin's (`Scene::landmarks_pre`, kept for the landmark
/// stage); without them, or with the tip already inside, `roi` is kept.
fn take_in_nose(roi: Box3, scene: &Scene, skin: &Mesh, moved: &[bool]) -> (Box3, Option<[f64; 3]>) {
    let Ok((_, lms)) = scene.landmarks_pre(skin, Path::new("case.toml")) else {
        return (roi, None);
    };
    let at = |label: &str| {
        lms.iter()
            .find(|l| l.label == label)
            .and_then(|l| l.position)
    };
    let inside =
        |p: [f64; 3], room: f64| (0..3).all(|c| p[c] >= roi.0[c] + room && p[c] <= roi.1[c] - room);
    let (Some(sn), Some(prn)) = (at("Sn"), at("Prn")) else {
        return (roi, None);
    };
    // The nose rests on the bone nearest its base: grown only when that bone moves (a Le Fort
    // I, not a mandibular move, whose region may hold subnasale while the nose stays).
    let skull = &scene.face.skull.vertices;
    let d2 = |p: &[f64; 3]| (0..3).map(|c| (p[c] - sn[c]).powi(2)).sum::<f64>();
    let nearest = (0..skull.len()).min_by(|a, b| d2(&skull[*a]).total_cmp(&d2(&skull[*b])));
    let on_moved_bone = nearest.is_some_and(|i| moved[i]);
    if !on_moved_bone || !inside(sn, 0.0) || inside(prn, NOSE_ROOM_MM) {
        return (roi, None);
    }
    let (vlo, vhi) = scene.vol.bounds();
    let grown = (
        std::array::from_fn(|c| roi.0[c].min(prn[c] - NOSE_ROOM_MM).max(vlo[c])),
        std::array::from_fn(|c| roi.1[c].max(prn[c] + NOSE_ROOM_MM).min(vhi[c])),
    );
    (grown, (grown != roi).then_some(prn))
}

fn counted(a: &[u8], c: u8) -> usize {
    a.iter().filter(|k| **k == c).count()
}

/// Node displacements `u` to face displacements; beyond the region's cut faces the tissue is
/// held: face vertices there stay (the extrapolation from the last tetrahedron would move them).
/// Face vertices outside [surface] movable (`face_rigid`) are rigid, as in the C1 model:
/// interpolation between held and free skin nodes would move them by a little.
fn carry_face(
    e: &SkinEmbedding,
    quadratic: Option<&Tet10Mesh>,
    tets: &[[u32; 4]],
    u: &[[f64; 3]],
    skin: &Mesh,
    face_rigid: &[bool],
    roi: ([f64; 3], [f64; 3]),
) -> Vec<[f64; 3]> {
    let mut carried = match quadratic {
        Some(q) => e.carry_quadratic(&q.tets, u),
        None => e.carry(tets, u),
    };
    for (d, still) in carried
        .iter_mut()
        .zip(still(face_rigid, roi, &skin.vertices))
    {
        if still {
            *d = [0.0; 3];
        }
    }
    carried
}

/// The face's positions moved by the carried displacement `d`, as face_post is written.
fn displaced(skin: &Mesh, d: &[[f64; 3]]) -> Vec<[f64; 3]> {
    crate::vec3::displaced(&skin.vertices, d)
}

/// Face vertices that stay (`carry_face`'s rule): rigid skin, or outside the region.
fn still(rigid: &[bool], roi: ([f64; 3], [f64; 3]), face: &[[f64; 3]]) -> Vec<bool> {
    rigid
        .iter()
        .zip(face)
        .map(|(r, p)| *r || (0..3).any(|c| p[c] < roi.0[c] || p[c] > roi.1[c]))
        .collect()
}

/// The tissues' materials with the nose's tetrahedra (`nose`) at `youngs_kpa`
/// ([`super::nose::material`]).
fn with_nose(
    mut material: Vec<TissueElastic>,
    nose: Option<&[bool]>,
    youngs_kpa: f64,
) -> Vec<TissueElastic> {
    if let Some(nose) = nose {
        for (m, _) in material.iter_mut().zip(nose).filter(|(_, n)| **n) {
            *m = super::nose::material(*m, youngs_kpa);
        }
    }
    material
}

/// `material` with the torn tetrahedra's stiffness a trace ([`TORN_STIFFNESS`]).
fn torn_trace(mut material: Vec<TissueElastic>, torn: &[bool]) -> Vec<TissueElastic> {
    for (m, _) in material.iter_mut().zip(torn).filter(|(_, t)| **t) {
        m.youngs_kpa *= TORN_STIFFNESS;
    }
    material
}

/// Rounds of freeing the bone and sliding nodes of inverted elements and solving again.
const RELEASE_ROUNDS: usize = 6;
/// Rounds of the degloved maxilla's one-sided contact (`model::degloved`), and how far (mm) a
/// lifted node may lie inside its bone's move before it rests on the bone again (the solve's
/// round-off is far below; a tenth of a voxel is far above it).
const ONE_SIDED_ROUNDS: usize = 8;
const PENETRATION_MM: f64 = 0.01;

/// A node of the degloved maxilla on its bone (`predict`'s one-sided rounds): its sliding hold
/// n · u = value with n the unit normal into the tissue, and its holds to rest it again.
struct OneSided {
    node: usize,
    normal: [f64; 3],
    value: f64,
    rest: (Hold, LinearHold),
}

impl OneSided {
    /// How far the node lies off its bone along the normal at displacement `u` (mm; negative:
    /// inside the bone's move).
    fn gap(&self, u: [f64; 3]) -> f64 {
        crate::vec3::dot(self.normal, u) - self.value
    }
}

/// (K u) on the rows of the `watched` nodes only (zero elsewhere), from K's lower triangle in one
/// pass: the one-sided contact's hold forces. (`fem::sparse::multiply` sorts K into rows first,
/// about 0.5 s a round on the real CT.)
fn rows_times(k: &[(usize, usize, f64)], watched: &[bool], u: &[[f64; 3]]) -> Vec<f64> {
    let u = u.as_flattened();
    let mut ku = vec![0.0; u.len()];
    for &(r, c, v) in k {
        if watched[r / 3] {
            ku[r] += v * u[c];
        }
        if r != c && watched[c / 3] {
            ku[c] += v * u[r];
        }
    }
    ku
}

/// Rounds of tearing the gap tissue a move inverts (after lift-off) and solving again.
const TEAR_ROUNDS: usize = 8;
/// A tearing round that inverts up to this many elements has not spread, whatever the first
/// round inverted: on a coarse phantom's impaction one torn gap element leaves two neighbours
/// inverted, which tear in the next round; tissue sheared by a 25 mm move inverts tens.
const SPREAD_FLOOR: usize = 8;

/// A torn element's stiffness, as a fraction of its tissue's: a trace, so that a node left only
/// in torn elements still has a definite (if meaningless) displacement.
const TORN_STIFFNESS: f64 = 1e-4;

/// Bone moves beyond this (mm) are warned about: orthognathic advancements and setbacks stay
/// within about 15 mm, distraction of the maxilla reaches ~20.
const LARGE_MOVE_MM: f64 = 25.0;

/// The volumetric model's prediction: it carries the skin at full resolution (a dense scan
/// needs no coarse copy).
pub(super) fn predict_face(
    scene: &Scene,
    case: &Case,
    rec: &mut Recorder,
) -> Result<Predicted<Option<Volumetric>>> {
    let skin = scene.face.fine.as_ref().unwrap_or(&scene.face.skin).clone();
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

/// The tissue mesh's sizes from `[tet]`.
fn mesh_params(t: &crate::case::Tet) -> MeshParams {
    MeshParams {
        skin_size_mm: t.skin_size_mm,
        deep_size_mm: t.deep_size_mm,
        margin_mm: t.margin_mm,
    }
}

/// The size of the system a run of the volumetric model factors, for `facesim estimate`: the
/// run's own mesh, and its stiffness restricted to the nodes the plan leaves to solve (bone the
/// plan does not move is held; moved, sliding and soft nodes are counted as solved, so the
/// factor is the run's or a little larger), analysed symbolically in the run's ordering.
pub(crate) struct SystemSize {
    pub nodes: usize,
    pub elements: usize,
    pub unknowns: usize,
    pub factor_nonzeros: usize,
    pub factor_flops: f64,
}

/// [`SystemSize`] of `case` on `scene`; None when the plan moves no bone.
pub(crate) fn system_size(scene: &Scene, case: &Case) -> Result<Option<SystemSize>> {
    let t = &case.tet;
    let skin = scene.face.fine.as_ref().unwrap_or(&scene.face.skin);
    let Some((roi, _)) = region(scene, skin, t.margin_mm) else {
        return Ok(None);
    };
    let params = mesh_params(t);
    let mesh = crate::tet::from_ct::soft_tissue(&scene.vol, &scene.seg, roi, &params)?;
    let (_, moved) = scene.model.plan.apply(&mesh.nodes, 1.0);
    let corner_solved: Vec<bool> = (mesh.kind.iter().zip(&moved))
        .map(|(k, m)| *k != NodeKind::Bone || *m)
        .collect();
    let failed = |e| {
        Error::numerical(
            crate::error::NumericalKind::Singular,
            format!("symbolic Cholesky: {e:?}"),
        )
    };
    let (nodes, elements, pattern) = if t.element == TetElement::Quadratic {
        let linear = TetMesh {
            nodes: mesh.nodes.clone(),
            tets: mesh.tets.clone(),
            material: materials(&mesh.tissue, t),
        };
        let q = Tet10Mesh::from_linear(&linear, Rule::Full);
        // A midpoint is solved when either end is.
        let mut solved = corner_solved.clone();
        solved.extend(
            q.edges
                .iter()
                .map(|[a, b]| corner_solved[*a as usize] || corner_solved[*b as usize]),
        );
        let pattern = crate::fem::cholesky::pattern_of_elements(
            &solved,
            q.tets.iter().map(|t| &t[..]),
            Ordering::NestedDissection,
        )
        .map_err(failed)?;
        (q.nodes.len(), q.tets.len(), pattern)
    } else {
        let order = NodeOrder::of_tets(&corner_solved, &mesh.tets).map(MeshAnalyses::new);
        let pattern = crate::fem::cholesky::pattern_of_elements(
            &corner_solved,
            mesh.tets.iter().map(|t| &t[..]),
            ordering(&order),
        )
        .map_err(failed)?;
        (mesh.nodes.len(), mesh.tets.len(), pattern)
    };
    Ok(Some(SystemSize {
        nodes,
        elements,
        unknowns: pattern.columns(),
        factor_nonzeros: pattern.factor_nnz(),
        factor_flops: pattern.factor_flops(),
    }))
}

/// Mesh, solve and carry the face; None when the plan moves no bone.
pub fn predict(
    scene: &Scene,
    case: &Case,
    skin: &Mesh,
    rec: &mut Recorder,
) -> Result<Option<(Volumetric, Vec<[f64; 3]>)>> {
    let t = &case.tet;
    // The landmarks the region needs (the nose tip), located in the landmark stage's time;
    // the run's landmark stage reads them back from the scene.
    rec.time(Stage::Landmarks, "locating landmarks", || {
        Ok(scene.landmarks_pre(skin, Path::new("case.toml")).ok())
    })?;
    let Some((roi, nose_tip)) = region(scene, skin, t.margin_mm) else {
        return Ok(None);
    };
    let params = mesh_params(t);
    let mesh = rec.time(Stage::TetMesh, "meshing the soft tissue", || {
        crate::tet::from_ct::soft_tissue(&scene.vol, &scene.seg, roi, &params)
    })?;
    // The external nose as one framework, found from the pre-operative landmarks.
    let nose = if t.nose_youngs_kpa > 0.0 {
        // The bone the plan moves, on the mesh: the framework is not bonded to it.
        let (_, moved) = scene.model.plan.apply(&mesh.nodes, 1.0);
        let moved_bone: Vec<bool> = (mesh.kind.iter().zip(&moved))
            .map(|(k, m)| *k == NodeKind::Bone && *m)
            .collect();
        Some(super::nose::nose_tets(
            scene.landmarks_pre(skin, Path::new("case.toml"))?,
            t.nose_base_above_sn_mm,
            &mesh.nodes,
            &mesh.tets,
            &moved_bone,
        )?)
    } else {
        None
    };
    let nose_elements = nose
        .as_ref()
        .map_or(0, |n| n.iter().filter(|b| **b).count());
    let material = with_nose(
        materials(&mesh.tissue, &case.tet),
        nose.as_deref(),
        t.nose_youngs_kpa,
    );
    let mut linear = TetMesh {
        nodes: mesh.nodes.clone(),
        tets: mesh.tets.clone(),
        material: material.clone(),
    };
    let quadratic =
        (t.element == TetElement::Quadratic).then(|| Tet10Mesh::from_linear(&linear, Rule::Full));
    let (nodes, kind) = match &quadratic {
        Some(q) => {
            let mut kind = mesh.kind.clone();
            kind.extend(midpoint_kinds(q, &mesh.tets, &mesh.kind));
            (&q.nodes, kind)
        }
        None => (&mesh.nodes, mesh.kind.clone()),
    };
    let bone = bone(scene, case);
    let mucosa = mucosa(
        &mesh.nodes,
        &mesh.kind,
        &bone,
        &scene.vol,
        &scene.seg.outside,
        t.mucosa_gap_mm,
    );
    // Lip and cheek on the teeth (bone-kind nodes; the mucosa above is skin-kind): one list.
    let covered = covered_bone(
        &mesh.nodes,
        &mesh.tets,
        &mesh.kind,
        &bone,
        &scene.vol,
        &scene.seg,
        &|p| !crate::pipeline::model::rigid_mask(case, &[p])[0],
    );
    // With `[tet] degloved_maxilla` and `degloved_chin`, the bone a Le Fort I's or a
    // genioplasty's approach raises slides too, and (with the teeth it covers) rests on its bone
    // one-sidedly: the one-sided rounds below. "auto" (the default) steps aside where `true` is
    // refused or fails, with a warning and report.json's reason (`model::degloved::applied`).
    let found = if t.degloved_maxilla == Degloved::Off
        && t.degloved_chin == Degloved::Off
        && !t.septum_detached
    {
        (None, Vec::new())
    } else {
        match scene.landmarks_pre(skin, Path::new("case.toml")) {
            Ok(found) => found,
            // The landmark stage reports why (`commands::run`).
            Err(_) if !(t.degloved_maxilla.required() || t.degloved_chin.required()) => {
                (None, Vec::new())
            }
            Err(e) => return Err(e),
        }
    };
    // The segment of a bone node: where a segment's bone ends tells a chin (`degloved`).
    let bone_segment = |n: usize| {
        (mesh.kind[n] == NodeKind::Bone)
            .then(|| crate::tet::plan_holds::segment_at(&case.osteotomy, mesh.nodes[n]).0)
            .flatten()
    };
    let mut not_applied = [None, None];
    let mut raised: Option<Vec<bool>> = None;
    let mut degloved_chin_nodes = 0;
    for (k, approach) in [Approach::Maxilla, Approach::Chin].into_iter().enumerate() {
        if approach.asked(t) == Degloved::Off {
            continue;
        }
        let region = match approach {
            Approach::Maxilla => {
                degloved::raised((found.0.as_ref(), &found.1), &mesh.nodes, &covered)
            }
            Approach::Chin => degloved::raised_chin(
                (found.0.as_ref(), &found.1),
                &mesh.nodes,
                &covered,
                &bone_segment,
            ),
        };
        let (r, why) = degloved::applied(t, approach, region)?;
        if let Some(why) = &why {
            rec.warn(format!(
                "[tet] {} = \"auto\" stepped aside: {why}; the tissue over the {} stays attached to its bone",
                approach.option(),
                approach.over()
            ));
        }
        not_applied[k] = why;
        if let Some(r) = r {
            if approach == Approach::Chin {
                degloved_chin_nodes = r.iter().filter(|b| **b).count();
            }
            raised = Some(match raised {
                Some(q) => q.iter().zip(&r).map(|(a, b)| *a || *b).collect(),
                None => r,
            });
        }
    }
    let [degloved_not_applied, degloved_chin_not_applied] = not_applied;
    let raised = raised.unwrap_or_else(|| vec![false; mesh.nodes.len()]);
    let contact: Vec<Option<Mucosa>> = covered
        .iter()
        .zip(&raised)
        .map(|(c, r)| c.filter(|c| c.tooth || *r).map(|c| c.mucosa))
        .collect();
    let contact_nodes = covered.iter().flatten().filter(|c| c.tooth).count();
    let degloved_nodes = raised.iter().filter(|r| **r).count();
    let mucosa_nodes = mucosa.iter().filter(|m| m.is_some()).count();
    let mucosa: Vec<Option<Mucosa>> = mucosa
        .into_iter()
        .zip(contact)
        .map(|(m, c)| m.or(c))
        .collect();
    let on_face = on_face(nodes, &kind, &scene.vol, &scene.seg.outside);
    // The linear models (any quadratic element, or the linear material) solve K u = f once.
    let linear_solve = quadratic.is_some() || t.material == TetMaterial::Linear;
    let (
        mut holds,
        Held {
            released_at_cuts,
            pieces,
            piece_nodes: held_still,
            on_scan_end,
        },
    ) = hold_tissue(
        &mesh,
        quadratic.as_ref(),
        Roles {
            kind: &kind,
            mucosa: &mucosa,
            on_face: &on_face,
            still: &[],
            scan: scene.vol.bounds(),
        },
        &bone,
        case,
        linear_solve,
    );
    // `[tet] septum_detached`: found on the run's holds, then held by every re-solve alike.
    let septum = match (t.septum_detached, quadratic.is_some()) {
        (false, _) => Ok(Vec::new()),
        (true, true) => Err("needs the 4-node element".to_string()),
        (true, false) => septum_nodes(&mesh, &found, &covered, &holds, &bone, case),
    };
    let septum = septum.unwrap_or_else(|why| {
        rec.warn(format!(
            "[tet] septum_detached stepped aside: {why}; the tissue on the maxilla's nasal floor moves with it"
        ));
        Vec::new()
    });
    hold_still(&mut holds, &septum);
    let septum_nodes = septum.iter().filter(|s| **s).count();
    let Holds {
        constraint,
        hold,
        linear: linear_hold,
        overlapping_segments,
        ..
    } = holds;
    // Not a warning: the bundled jaws phantom and both real CTs end in tissue within 3 mm of
    // moved bone (docs/pipeline.md "Region").
    let scan_end = scan_end(&mesh.nodes, &constraint, scene.vol.bounds(), on_scan_end);
    if pieces > 0 {
        rec.warn(format!(
            "{pieces} pieces of the tissue mesh ({held_still} nodes) are held by fewer than three bone or region-face nodes: each moves rigidly with the bone it lies on (thin tissue the mesh separated or hinged; a smaller [tet] skin_size_mm resolves it)"
        ));
    }
    // The tissue follows its bone, so a move no skin could follow (centimetres typed as
    // millimetres) is no error here as it is in the C1 model's spring check; say it instead.
    let largest = hold
        .iter()
        .zip(&constraint)
        .filter(|(_, c)| **c == MOVED)
        .filter_map(|(h, _)| match h {
            Hold::Fixed(u) => Some((u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()),
            _ => None,
        })
        .fold(0.0, f64::max);
    if largest > LARGE_MOVE_MM {
        rec.warn(format!(
            "the plan moves bone up to {largest:.0} mm, beyond the {LARGE_MOVE_MM:.0} mm of the largest orthognathic moves: check the osteotomy's translate (mm) and rotate_deg (degrees); the small-strain model is not valid there"
        ));
    }
    // Each segment must carry tissue: a segment whose bone touches no node of the mesh moves
    // nothing, and the plan is surely not what was meant.
    for o in &case.osteotomy {
        let carried = mesh
            .nodes
            .iter()
            .zip(&mesh.kind)
            .any(|(p, k)| *k == NodeKind::Bone && o.region.contains(*p));
        if !carried {
            return Err(Error::config(format!(
                "case.toml: osteotomy '{}': no node of the soft-tissue mesh lies on its bone (modelled region {:.0?} to {:.0?} mm): the segment carries no tissue; check its region",
                o.name, roi.0, roi.1
            )));
        }
    }
    let stiffness = |linear: &TetMesh| match &quadratic {
        Some(q) => q.assemble(),
        None => linear.assemble(),
    };
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
    // The linear models keep their factor for the plan basis (no second factorisation).
    let (mut constraint, mut hold, mut linear_hold) = (constraint, hold, linear_hold);
    let mut lifted: Vec<usize> = Vec::new();
    let (mut lifted_in_tension, mut lifted_penetration_mm) = (0, 0.0);
    let mut degloved_settled = true;
    let mut torn = vec![false; mesh.tets.len()];
    let mut fallback = None;
    let (displacement, newton, factor, linear_start, order) =
        rec.time(Stage::Solve, "solving the volumetric model", || {
            // The linear mesh's node ordering, once for every factor of this run and its
            // re-solves (the 10-node element orders its own DOFs).
            let order = match quadratic {
                None => {
                    let solved: Vec<bool> =
                        hold.iter().map(|h| !matches!(h, Hold::Fixed(_))).collect();
                    NodeOrder::of_tets(&solved, &mesh.tets).map(MeshAnalyses::new)
                }
                Some(_) => None,
            };
            {
                let k = stiffness(&linear)?;
                let f = Loads::none().nodal_vector(nodes.len())?;
                let mut c = Constrained::ordered(&k, &hold, nodes.len(), ordering(&order))?;
                let mut u = c.solve(&[(&hold, &f)])?.remove(0);
                // The degloved maxilla (`model::degloved`): its sliding nodes rest on the bone one
                // way only. Where the hold's force n · (K u) points into the bone (the bone pulls
                // the tissue after it) the node lifts off; a lifted node the bone would pass into
                // (n · u below the bone's normal move) rests on it again. Rounds until the set
                // settles, none factoring anew (below).
                let one_sided: Vec<OneSided> = (0..mesh.nodes.len())
                    .filter(|n| raised[*n] && constraint[*n] == SLIDING)
                    .filter_map(|n| match hold[n] {
                        Hold::Slide { normal, value } => Some(OneSided {
                            node: n,
                            normal: crate::vec3::scale(normal, 1.0 / crate::vec3::norm(normal)),
                            value,
                            rest: (hold[n], linear_hold[n]),
                        }),
                        _ => None,
                    })
                    .collect();
                degloved_settled = one_sided.is_empty();
                let rounds = if one_sided.is_empty() { 0 } else { ONE_SIDED_ROUNDS + 1 };
                let mut watched = vec![false; nodes.len()];
                one_sided.iter().for_each(|o| watched[o.node] = true);
                // K's entries on the watched rows, once: each round's hold forces pass over
                // them only (a twentieth of K on the real CT).
                let k_watched: Vec<(usize, usize, f64)> = k
                    .iter()
                    .filter(|(r, c, _)| watched[r / 3] || watched[c / 3])
                    .copied()
                    .collect();
                for round in 0..rounds {
                    let ku = rows_times(&k_watched, &watched, &u);
                    let mut freed = Vec::new();
                    let mut rests = Vec::new();
                    for o in &one_sided {
                        let n = o.node;
                        if hold[n] == Hold::Free {
                            if o.gap(u[n]) < -PENETRATION_MM {
                                rests.push(n);
                            }
                        } else if crate::vec3::dot(o.normal, [0, 1, 2].map(|c| ku[3 * n + c])) < 0.0
                        {
                            freed.push(n);
                        }
                    }
                    if freed.is_empty() && rests.is_empty() {
                        degloved_settled = true;
                        break;
                    }
                    if round == ONE_SIDED_ROUNDS {
                        break;
                    }
                    for &n in &freed {
                        constraint[n] = FREE;
                        hold[n] = Hold::Free;
                        linear_hold[n] = LinearHold::Free;
                    }
                    lifted.extend(&freed);
                    let mut rested = Vec::with_capacity(rests.len());
                    for o in one_sided.iter().filter(|o| rests.contains(&o.node)) {
                        constraint[o.node] = SLIDING;
                        (hold[o.node], linear_hold[o.node]) = o.rest;
                        rested.push((o.node, o.rest.0));
                    }
                    lifted.retain(|n| !rests.contains(n));
                    // The factor is bordered by the normal components of the nodes lifted so
                    // far (one solve each, the first time), and a node that rests again is held
                    // on the border: no round factors anew.
                    if !freed.is_empty() {
                        c.free_nodes(&freed)?;
                    }
                    if !rested.is_empty() {
                        c.rest_nodes(&rested)?;
                    }
                    u = c.solve(&[(&hold, &f)])?.remove(0);
                }
                lifted_in_tension = lifted.len();
                lifted_penetration_mm = one_sided
                    .iter()
                    .filter(|o| hold[o.node] == Hold::Free)
                    .map(|o| -o.gap(u[o.node]))
                    .fold(0.0, f64::max);
                // Where the solution turns an element next to bone inside out, the bone would
                // drag that tissue through itself or through the bone of another piece (the
                // tissue behind an advanced segment, or between it and the skull it slides
                // past): the tissue there lifts off (the element's nodes that move with a
                // segment, are held on bone or slide are freed) and the model is solved again,
                // a few rounds at most. The region's cut faces and held skin stay held. Lift-off
                // is contact, as sliding is: with `sliding = false` the tissue stays bonded (and a
                // plan basis exact for every plan, with no contact state to choose).
                let rounds = if t.release_cuts && t.sliding {
                    RELEASE_ROUNDS
                } else {
                    0
                };
                for _ in 0..rounds {
                    let inverted = match &quadratic {
                        Some(q) => q.inverted_after(&u),
                        None => linear.inverted_after(&u),
                    };
                    let mut freed = Vec::new();
                    for e in inverted {
                        let cell: Vec<u32> = match &quadratic {
                            Some(q) => q.tets[e].to_vec(),
                            None => mesh.tets[e].to_vec(),
                        };
                        for n in cell {
                            let n = n as usize;
                            let lifts = constraint[n] == SLIDING
                                || constraint[n] == MOVED
                                || (constraint[n] == FIXED && kind[n] == NodeKind::Bone);
                            if lifts {
                                constraint[n] = FREE;
                                hold[n] = Hold::Free;
                                linear_hold[n] = LinearHold::Free;
                                freed.push(n);
                            }
                        }
                    }
                    if freed.is_empty() {
                        break;
                    }
                    lifted.extend(&freed);
                    // The factor bordered by the freed components: no second factorisation.
                    c.free_nodes(&freed)?;
                    u = c.solve(&[(&hold, &f)])?.remove(0);
                }
                // What lift-off leaves inverted is tissue in the osteotomy gap that the move
                // stretches or squeezes beyond what a continuum can follow: the mobilisation
                // tears it (docs/pipeline.md "Large moves"). It is released: its stiffness falls
                // to a trace, the model is factored and solved again, a few rounds at most. Tissue
                // on the face never tears: an inverted element there stays a failure.
                // A round that inverts more than the first, and more than [`SPREAD_FLOOR`],
                // spreads instead of settling (tissue sheared against a held face, or lips the
                // scan fused): it stops there. (A torn element's few neighbours may invert in
                // the next round as the gap settles.)
                // Beyond orthognathic size (centimetres typed as millimetres?) nothing tears: the
                // inverted elements then refuse the plan.
                let tears = t.tear_gap && quadratic.is_none() && largest <= LARGE_MOVE_MM;
                let mut first: Option<usize> = None;
                for _ in 0..if tears { TEAR_ROUNDS } else { 0 } {
                    let inverted: Vec<usize> = linear
                        .inverted_after(&u)
                        .into_iter()
                        .filter(|e| !torn[*e])
                        .collect();
                    let on_the_face = |e: &usize| carries_face[*e];
                    if inverted.is_empty()
                        || first.is_some_and(|n| inverted.len() > n.max(SPREAD_FLOOR))
                        || inverted.iter().any(on_the_face)
                    {
                        break;
                    }
                    first.get_or_insert(inverted.len());
                    for e in inverted {
                        torn[e] = true;
                    }
                    linear.material = torn_trace(material.clone(), &torn);
                    // The old factor goes before the new one is made: two at once set the
                    // run's peak (a rotation on a 2.5 mm phantom: 3.3 GB against 2.0 GB).
                    drop(c);
                    c = Constrained::ordered(
                        &stiffness(&linear)?,
                        &hold,
                        nodes.len(),
                        ordering(&order),
                    )?;
                    u = c.solve(&[(&hold, &f)])?.remove(0);
                }
                if linear_solve {
                    return Ok((u, None, Some(c), None, order));
                }
                // The hyperelastic model: Newton from the linear answer, the linear factor
                // preconditioning each Newton system (tet::newton_krylov).
                let s = match newton_krylov::solve(
                    &linear,
                    &c,
                    &u,
                    &newton_krylov::Options::default(),
                ) {
                    Ok(s) => s,
                    // Too far from the linear answer for Newton to start there: load steps,
                    // each Newton system factored (slower, more robust).
                    Err(e) => {
                        fallback = Some(format!(
                            "the nonlinear solve from the linear answer failed ({e}); solved again in {} load steps",
                            t.load_steps
                        ));
                        let opts = Newton {
                            load_steps: t.load_steps,
                            ..Newton::default()
                        };
                        nonlinear::solve(&linear, &hold, &Loads::none(), &opts)?
                    }
                };
                let steps = s
                    .steps
                    .iter()
                    .map(|s| NewtonStep {
                        load: s.load,
                        iterations: s.iterations,
                        residual: s.residuals.last().copied().unwrap_or(0.0),
                        krylov_iterations: s.krylov_iterations,
                    })
                    .collect();
                Ok((s.displacements, Some(steps), Some(c), Some(u), order))
            }
        })?;
    if let Some(w) = fallback {
        rec.warn(w);
    }
    if !degloved_settled {
        rec.warn(format!(
            "[tet] degloved_maxilla/degloved_chin: the raised tissue's one-sided contact did not settle in {ONE_SIDED_ROUNDS} rounds ({lifted_in_tension} nodes lifted off, the deepest {lifted_penetration_mm:.3} mm inside its bone's move)"
        ));
    }
    let inverted_tets = match &quadratic {
        Some(q) => q.inverted_after(&displacement),
        None => linear.inverted_after(&displacement),
    };
    let inverted_tets: Vec<usize> = inverted_tets.into_iter().filter(|e| !torn[*e]).collect();
    let torn_elements = torn.iter().filter(|b| **b).count();
    let torn_volume_mm3: f64 = (0..mesh.tets.len())
        .filter(|e| torn[*e])
        .filter_map(|e| crate::tet::gradients(mesh.tets[e].map(|n| mesh.nodes[n as usize])))
        .map(|(v, _)| v)
        // From +0: an empty f64 sum is −0, which report.json would print as "-0.0".
        .fold(0.0, |a, v| a + v);
    if torn_elements > 0 {
        rec.warn(format!(
            "the move tears {torn_elements} tetrahedra ({torn_volume_mm3:.0} mm³) of tissue off the face that it would turn inside out (the osteotomy gap): their stiffness is a trace of their tissue's ([tet] tear_gap; docs/pipeline.md \"Large moves\")"
        ));
    }
    // Tetrahedra spanning moved and held bone (the osteotomy's gap, where the plan shears the
    // tissue between bone pieces) are told apart from those a large move inverts elsewhere.
    let at_cuts = inverted_tets
        .iter()
        .filter(|t| {
            let c = mesh.tets[**t].map(|n| constraint[n as usize]);
            c.contains(&MOVED) && c.contains(&FIXED)
        })
        .count();
    let inverted = inverted_tets.len();
    if inverted > 0 {
        let on_the_face = inverted_tets.iter().filter(|e| carries_face[**e]).count();
        let why = if !t.tear_gap {
            "[tet] tear_gap = true tears such tissue off the face".to_string()
        } else if largest > LARGE_MOVE_MM {
            format!("nothing tears for a move beyond {LARGE_MOVE_MM:.0} mm")
        } else if on_the_face > 0 {
            format!(
                "{on_the_face} of them carry the face, which does not tear: the bone moves further than the face can follow (teeth or bone of two segments colliding, skin held outside [surface] movable, or tissue squeezed against the CT's edge?)"
            )
        } else {
            "the tearing stopped without leaving every element valid".to_string()
        };
        rec.warn(format!(
            "the predicted move turns {inverted} of {} tetrahedra inside out ({at_cuts} of them span moved and held bone, where the osteotomy shears the tissue between bone pieces); {why}",
            mesh.tets.len()
        ));
    }
    let face_rigid = crate::pipeline::model::rigid_mask(case, &skin.vertices);
    let carry = |e: &SkinEmbedding, u: &[[f64; 3]]| {
        carry_face(e, quadratic.as_ref(), &mesh.tets, u, skin, &face_rigid, roi)
    };
    let carried = rec.time(Stage::Embed, "carrying the face", || {
        Ok(carry(&embedding, &displacement))
    })?;
    let factor_nonzeros = factor.as_ref().map_or(0, Constrained::factor_nnz);
    let basis = rec.time(Stage::PlanBasis, "building the plan basis", || {
        // The nonlinear material slides on the moved bone's normals: where a rotation turned
        // them, the basis (the linear model at rest) needs its own factor.
        let rest: Vec<Hold> = linear_hold.iter().map(|l| l.hold(&[])).collect();
        let factor = match factor {
            Some(c) if c.takes(&rest) => c,
            run_factor => {
                // The run's factor goes before the basis's is made: two at once would set the
                // run's peak memory.
                drop(run_factor);
                Constrained::ordered(&stiffness(&linear)?, &rest, nodes.len(), ordering(&order))?
            }
        };
        let inputs = BasisInputs {
            factor: &factor,
            linear_hold: &linear_hold,
            overlapping_segments: &overlapping_segments,
            nonlinear: !linear_solve,
            skin,
            run_face_displacement: &carried,
        };
        plan_basis(&inputs, case, |u| carry(&embedding, u))
    })?;
    let reached: Vec<f64> = (0..embedding.distance.len())
        .filter(|i| embedding.reached(*i))
        .map(|i| embedding.distance[i])
        .collect();
    let report = TetReport {
        material: t.material,
        element: t.element,
        region: roi,
        mesh_box: Some(mesh.lattice_box),
        region_grown_for_nose_tip: nose_tip,
        nodes: nodes.len(),
        tets: mesh.tets.len(),
        dofs: 3 * nodes.len(),
        free_dofs: 3 * counted(&constraint, FREE),
        factor_nonzeros,
        skin_nodes: kind.iter().filter(|k| **k == NodeKind::Skin).count(),
        mucosa_nodes,
        sliding_nodes: counted(&constraint, SLIDING),
        contact_nodes,
        contact_sliding_nodes: (0..mesh.nodes.len())
            .filter(|n| covered[*n].is_some_and(|c| c.tooth))
            .filter(|n| constraint[*n] == SLIDING)
            .count(),
        moved_nodes: counted(&constraint, MOVED),
        fixed_nodes: counted(&constraint, FIXED),
        quality: mesh.quality.clone(),
        inverted_elements: inverted,
        inverted_between_moved_and_held_bone: at_cuts,
        released_at_cuts,
        lifted_off: lifted.len(),
        torn_elements,
        torn_volume_mm3,
        nose_elements,
        septum_nodes,
        degloved_nodes,
        lifted_in_tension,
        lifted_penetration_mm,
        degloved_settled,
        degloved_not_applied,
        degloved_chin_nodes,
        degloved_chin_not_applied,
        floating_pieces: pieces,
        scan_end,
        newton,
        face_vertices_unreached: embedding.unreached(),
        face_to_mesh_mm: stats(&reached),
    };
    let face_post = displaced(skin, &carried);
    let linear_face = linear_start.map(|u| displaced(skin, &carry(&embedding, &u)));
    Ok(Some((
        Volumetric {
            linear_face,
            mesh,
            quadratic,
            constraint,
            material: linear.material,
            displacement,
            report,
            basis: Some(basis),
            reuse: Reuse {
                kind,
                mucosa,
                embedding,
                face_rigid,
                on_face,
                nose,
                torn,
                lifted,
                still: septum,
                roi,
                linear_solve,
                order,
                factor_nonzeros,
            },
        },
        face_post,
    )))
}

/// The ordering of a factor of the linear mesh: its node ordering (and the analyses made in
/// it) when made, else its free DOFs' own.
fn ordering(order: &Option<MeshAnalyses>) -> Ordering<'_> {
    order
        .as_ref()
        .map_or(Ordering::NestedDissection, Ordering::Nodes)
}

/// What the plan basis is built from.
struct BasisInputs<'a> {
    factor: &'a Constrained,
    linear_hold: &'a [LinearHold],
    overlapping_segments: &'a [usize],
    /// The run solved the nonlinear material: the basis is its linearisation at rest.
    nonlinear: bool,
    skin: &'a Mesh,
    /// The run's own face displacement, to check the basis against.
    run_face_displacement: &'a [[f64; 3]],
}

/// 12 solves per segment on the run's factor (only the held values change: segment s's bone
/// moved by E_k·[x; 1], the rest held still), each carried to the face like the run's own.
fn plan_basis(
    b: &BasisInputs,
    case: &Case,
    carry: impl Fn(&[[f64; 3]]) -> Vec<[f64; 3]>,
) -> Result<PlanBasis> {
    use crate::plan::basis::{COLUMNS, unit};
    let ns = case.osteotomy.len();
    let n = b.linear_hold.len();
    let zero = vec![0.0; 3 * n];
    let unit_holds: Vec<Vec<Hold>> = (0..ns * COLUMNS)
        .map(|sk| {
            let mut ms = vec![[0.0; COLUMNS]; ns];
            ms[sk / COLUMNS] = unit(sk % COLUMNS);
            b.linear_hold.iter().map(|l| l.hold(&ms)).collect()
        })
        .collect();
    let cases: Vec<(&[Hold], &[f64])> = unit_holds
        .iter()
        .map(|h| (h.as_slice(), zero.as_slice()))
        .collect();
    let mut solved = b.factor.solve(&cases)?.into_iter();
    let segments = case
        .osteotomy
        .iter()
        .map(|o| SegmentBasis {
            name: o.name.clone(),
            region: o.region.clone(),
            pivot: o.pivot,
            columns: solved.by_ref().take(COLUMNS).map(|u| carry(&u)).collect(),
        })
        .collect();
    let mut basis = PlanBasis {
        model: if b.nonlinear {
            "tet-neo-hookean-linearised"
        } else {
            "tet-linear"
        }
        .into(),
        exact: !b.nonlinear,
        warnings: Vec::new(),
        segments,
        face_pre: b.skin.vertices.clone(),
        triangles: b.skin.triangles.clone(),
        run_plan: case.osteotomy.clone(),
        offset: None,
        facesim_version: env!("CARGO_PKG_VERSION").into(),
        run_plan_error_mm: 0.0,
    };
    if b.nonlinear {
        basis.warnings.push(
            "linear preview: the basis is the linear model at rest, the run solved the neo-Hookean material".into(),
        );
    }
    if !b.overlapping_segments.is_empty() {
        let names: Vec<String> = b
            .overlapping_segments
            .iter()
            .map(|s| format!("'{}'", case.osteotomy[*s].name))
            .collect();
        basis.exact = false;
        basis.warnings.push(format!(
            "osteotomies {} share bone nodes (their moves compose, which is not linear): the plan basis is not exact",
            names.join(", ")
        ));
    }
    // The basis must give the run's own face back: the same linear system, summed.
    let ms = basis.matrices(&case.osteotomy)?;
    let again = basis.displacement_of(&ms);
    basis.run_plan_error_mm = again
        .iter()
        .zip(b.run_face_displacement)
        .map(|(a, r)| crate::vec3::norm(crate::vec3::sub(*a, *r)))
        .fold(0.0, f64::max);
    if basis.exact && !(basis.run_plan_error_mm <= 1e-6) {
        basis.exact = false;
        basis.warnings.push(format!(
            "the plan basis differs from the run's own face by up to {:.3e} mm (a segment moves bone into another's region): not exact",
            basis.run_plan_error_mm
        ));
    }
    Ok(basis)
}

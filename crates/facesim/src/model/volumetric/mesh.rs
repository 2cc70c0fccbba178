//! The mesh stage: the face region the plan reaches, the soft-tissue mesh inside it (4-node, or
//! 10-node with `[tet] element = "quadratic"`) with each solved node's kind, and the size of the
//! system a run factors (`facesim estimate`).

use crate::case::{Case, TetElement};
use crate::error::{Error, Result};
use crate::fem::cholesky::{MeshAnalyses, Ordering};
use crate::fem::ordering::NodeOrder;
use crate::mesh::Mesh;
use crate::pipeline::stage::Stage;
use crate::pipeline::{Recorder, Scene};
use crate::tet::conditions::{materials, midpoint_kinds};
use crate::tet::from_ct::{MeshParams, NodeKind, SoftTissueMesh};
use crate::tet::quadratic::{Rule, Tet10Mesh};
use crate::tet::{TetMesh, TissueElastic};
use std::path::Path;

/// An axis-aligned box (LPS mm): lowest and highest corner.
pub(super) type Box3 = ([f64; 3], [f64; 3]);

/// The mesh stage's result.
pub(super) struct Meshed {
    /// The face region ([`region`]) and pronasale when it was grown to hold it.
    pub(super) roi: Box3,
    pub(super) nose_tip: Option<[f64; 3]>,
    pub(super) mesh: SoftTissueMesh,
    /// Per tetrahedron, its tissue's material (`[tet]`), before any tearing.
    pub(super) material: Vec<TissueElastic>,
    /// The 4-node mesh with those materials (what the rounds re-assemble).
    pub(super) linear: TetMesh,
    /// The 10-node mesh solved instead (`[tet] element = "quadratic"`).
    pub(super) quadratic: Option<Tet10Mesh>,
    /// Per solved node (the corners, then the midpoints when quadratic): its kind.
    pub(super) kind: Vec<NodeKind>,
}

impl Meshed {
    /// The solved nodes: the corners, then the midpoints when quadratic.
    pub(super) fn nodes(&self) -> &[[f64; 3]] {
        self.quadratic
            .as_ref()
            .map_or(&self.mesh.nodes, |q| &q.nodes)
    }
}

/// Mesh the soft tissue inside the region the plan reaches (timed as the tet-mesh stage); None
/// when the plan moves no bone.
pub(super) fn build(
    scene: &Scene,
    case: &Case,
    skin: &Mesh,
    rec: &mut Recorder,
) -> Result<Option<Meshed>> {
    let t = &case.tet;
    let Some((roi, nose_tip)) = region(scene, skin, t.margin_mm) else {
        return Ok(None);
    };
    let params = mesh_params(t);
    let mesh = rec.time(Stage::TetMesh, "meshing the soft tissue", || {
        crate::tet::from_ct::soft_tissue(&scene.vol, &scene.seg, roi, &params)
    })?;
    let material = materials(&mesh.tissue, t);
    let linear = TetMesh {
        nodes: mesh.nodes.clone(),
        tets: mesh.tets.clone(),
        material: material.clone(),
    };
    let quadratic =
        (t.element == TetElement::Quadratic).then(|| Tet10Mesh::from_linear(&linear, Rule::Full));
    let mut kind = mesh.kind.clone();
    if let Some(q) = &quadratic {
        kind.extend(midpoint_kinds(q, &mesh.tets, &mesh.kind));
    }
    Ok(Some(Meshed {
        roi,
        nose_tip,
        mesh,
        material,
        linear,
        quadratic,
        kind,
    }))
}

/// The face region (LPS mm): the box around the skull points the plan moves, grown by `margin`
/// and kept inside the CT's voxel centres, then grown to take in the nose ([`take_in_nose`]), with
/// the nose tip when it grew; None when the plan moves no bone. The face inside it is carried by
/// the mesh; the mesh itself fills this box grown by `margin` once more ([`MeshParams`]), whose
/// faces are held. That second margin reaches past the CT wherever the first was clipped, so
/// where the scan ends the tissue ends in a free surface, not a held one: the anatomy beyond the
/// scan is not modelled, and holding the scan's end instead pinned the real CT's upper lip, cut
/// by the scan 4.5 mm below labrale superius (docs/design/pipeline.md "Region").
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

/// The tissue mesh's sizes from `[tet]`.
fn mesh_params(t: &crate::case::Tet) -> MeshParams {
    MeshParams {
        skin_size_mm: t.skin_size_mm,
        deep_size_mm: t.deep_size_mm,
        margin_mm: t.margin_mm,
    }
}

/// The ordering of a factor of the linear mesh: its node ordering (and the analyses made in
/// it) when made, else its free DOFs' own.
pub(super) fn ordering(order: &Option<MeshAnalyses>) -> Ordering<'_> {
    order
        .as_ref()
        .map_or(Ordering::NestedDissection, Ordering::Nodes)
}

/// The size of the system a run of the volumetric model factors, for `facesim estimate`: the
/// run's own mesh, and its stiffness restricted to the nodes the plan leaves to solve (bone the
/// plan does not move is held; moved, sliding and soft nodes are counted as solved, so the
/// factor is the run's or a little larger), analysed symbolically in the run's ordering.
pub(crate) struct SystemSize {
    pub(crate) nodes: usize,
    pub(crate) elements: usize,
    pub(crate) unknowns: usize,
    /// The factor's nonzeros and operations: the run's factor, or with the 10-node element
    /// solved iteratively its coarse level's (the 4-node mesh's).
    pub(crate) factor_nonzeros: usize,
    pub(crate) factor_flops: f64,
    /// The 10-node system solved iteratively: its operator's 3 × 3 lower blocks.
    pub(crate) iterative_blocks: Option<usize>,
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
    // The 4-node mesh's factor: the run's own with the linear element, the coarse level's
    // with the 10-node element solved iteratively.
    let linear_pattern = || {
        let order = NodeOrder::of_tets(&corner_solved, &mesh.tets).map(MeshAnalyses::new);
        crate::fem::cholesky::pattern_of_elements(
            &corner_solved,
            mesh.tets.iter().map(|t| &t[..]),
            ordering(&order),
        )
        .map_err(failed)
    };
    if t.element != TetElement::Quadratic {
        let pattern = linear_pattern()?;
        return Ok(Some(SystemSize {
            nodes: mesh.nodes.len(),
            elements: mesh.tets.len(),
            unknowns: pattern.columns(),
            factor_nonzeros: pattern.factor_nnz(),
            factor_flops: pattern.factor_flops(),
            iterative_blocks: None,
        }));
    }
    let linear = TetMesh {
        nodes: mesh.nodes.clone(),
        tets: mesh.tets.clone(),
        material: materials(&mesh.tissue, t),
    };
    let q = Tet10Mesh::from_linear(&linear, Rule::Full);
    let solved = q.solved_nodes(&corner_solved);
    let elements = || q.tets.iter().map(|t| &t[..]);
    // As the run decides (`tet::Constrained::quadratic`): the node graph first.
    let graph = crate::fem::cholesky::node_graph_size(&solved, elements()).map_err(failed)?;
    let unknowns = 3 * solved.iter().filter(|s| **s).count();
    if !crate::tet::holds::quadratic_factor_fits(graph.factor_nnz) {
        let coarse = linear_pattern()?;
        return Ok(Some(SystemSize {
            nodes: q.nodes.len(),
            elements: q.tets.len(),
            unknowns,
            factor_nonzeros: coarse.factor_nnz(),
            factor_flops: coarse.factor_flops(),
            iterative_blocks: Some(graph.lower_blocks),
        }));
    }
    let pattern =
        crate::fem::cholesky::pattern_of_elements(&solved, elements(), Ordering::NestedDissection)
            .map_err(failed)?;
    Ok(Some(SystemSize {
        nodes: q.nodes.len(),
        elements: q.tets.len(),
        unknowns: pattern.columns(),
        factor_nonzeros: pattern.factor_nnz(),
        factor_flops: pattern.factor_flops(),
        iterative_blocks: None,
    }))
}

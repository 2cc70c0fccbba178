//! The volumetric model (`[solve] model = "tet"`, MODEL.md §9; docs/pipeline.md "Volumetric
//! soft tissue"): the soft tissue between skin and bone is meshed with tetrahedra inside the
//! region the plan reaches, bone nodes follow their segment rigidly, the region's cut faces are
//! held, the skin is free; the solved displacement carries the face (the extracted skin or the
//! given scan, at full resolution).

use super::{Recorder, Scene};
use crate::case::{Case, TetMaterial};
use crate::compare::{DistanceStats, stats};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::report::Stage;
use crate::tet::embed::SkinEmbedding;
use crate::tet::from_ct::{MeshParams, NodeKind, SoftTissueMesh};
use crate::tet::quality::Quality;
use crate::tet::{Elastic, TetMesh};
use serde::Serialize;

/// tets.vtu's `constraint` codes (CASE.md).
pub const FREE: u8 = 0;
pub const FIXED: u8 = 1;
pub const MOVED: u8 = 2;

/// The solved volumetric model, kept for the outputs (tets.vtu) and the report.
pub struct Volumetric {
    pub mesh: SoftTissueMesh,
    /// Per node: FREE, FIXED or MOVED.
    pub constraint: Vec<u8>,
    /// Per tetrahedron.
    pub material: Vec<Elastic>,
    /// Per node (mm).
    pub displacement: Vec<[f64; 3]>,
    pub report: TetReport,
}

/// report.json's `tet` section.
#[derive(Clone, Debug, Serialize)]
pub struct TetReport {
    pub material: TetMaterial,
    /// The modelled region (LPS mm): the box around the moved bone grown by `[tet] margin_mm`.
    pub region: ([f64; 3], [f64; 3]),
    pub nodes: usize,
    pub tets: usize,
    pub dofs: usize,
    pub free_dofs: usize,
    /// Nodes per role: skin (free), bone moved with a segment, bone or cut faces held.
    pub skin_nodes: usize,
    pub moved_nodes: usize,
    pub fixed_nodes: usize,
    pub quality: Quality,
    /// Face vertices farther from the mesh's skin than the reach (they stay at rest).
    pub face_vertices_unreached: usize,
    /// Distance from each carried face vertex to the mesh's skin boundary (mm).
    pub face_to_mesh_mm: DistanceStats,
}

/// The box (LPS mm) around the skull points the plan moves, grown by `margin` and kept inside
/// the CT's voxel centres (where the scan ends, the tissue is cut and held like the region's other
/// cut faces, not left as a free surface); None when the plan moves none.
fn region(scene: &Scene, margin: f64) -> Option<([f64; 3], [f64; 3])> {
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
    (lo[0] <= hi[0]).then_some((lo, hi))
}

/// The role of each node and the displacement held on it: bone nodes inside a segment move
/// with it (any rotation, exactly), other bone and the cut faces stay, skin outside
/// `[surface] movable` stays, the rest is free.
fn holds(mesh: &SoftTissueMesh, scene: &Scene, case: &Case) -> (Vec<u8>, Vec<Option<[f64; 3]>>) {
    let (moved_to, moved) = scene.model.plan.apply(&mesh.nodes, 1.0);
    let rigid = super::model::rigid_mask(case, &mesh.nodes);
    mesh.kind
        .iter()
        .enumerate()
        .map(|(n, k)| match k {
            NodeKind::Bone if moved[n] => (
                MOVED,
                Some([0, 1, 2].map(|c| moved_to[n][c] - mesh.nodes[n][c])),
            ),
            NodeKind::Bone | NodeKind::Cut => (FIXED, Some([0.0; 3])),
            NodeKind::Skin if rigid[n] => (FIXED, Some([0.0; 3])),
            NodeKind::Skin | NodeKind::Interior => (FREE, None),
        })
        .unzip()
}

/// Mesh, solve and carry the face; None when the plan moves no bone.
pub fn predict(
    scene: &Scene,
    case: &Case,
    skin: &Mesh,
    rec: &mut Recorder,
) -> Result<Option<(Volumetric, Vec<[f64; 3]>)>> {
    let t = &case.tet;
    let Some(roi) = region(scene, t.margin_mm) else {
        return Ok(None);
    };
    let params = MeshParams {
        skin_size_mm: t.skin_size_mm,
        deep_size_mm: t.deep_size_mm,
        margin_mm: t.margin_mm,
    };
    let mesh = rec.time(Stage::TetMesh, "meshing the soft tissue", || {
        crate::tet::from_ct::soft_tissue(&scene.vol, &scene.seg, roi, &params)
    })?;
    let material: Vec<Elastic> = mesh
        .tissue
        .iter()
        .map(|l| {
            let m = t.elastic(*l);
            Elastic {
                youngs_kpa: m.youngs_kpa,
                poisson: m.poisson,
            }
        })
        .collect();
    let (constraint, prescribed) = holds(&mesh, scene, case);
    if !constraint.contains(&MOVED) {
        return Err(Error::config(format!(
            "case.toml: the plan moves bone, but no node of the tissue mesh lies on moved bone (region {:?}–{:?} mm): the moved bone touches no soft tissue",
            roi.0, roi.1
        )));
    }
    let displacement = rec.time(Stage::Solve, "solving the volumetric model", || {
        let tm = TetMesh {
            nodes: mesh.nodes.clone(),
            tets: mesh.tets.clone(),
            material: material.clone(),
        };
        tm.solve_linear(&prescribed)
    })?;
    let (carried, embedding) = rec.time(Stage::Embed, "carrying the face", || {
        let on_skin = |f: [u32; 3]| f.iter().all(|n| mesh.kind[*n as usize] == NodeKind::Skin);
        let reach = (1.5 * t.skin_size_mm).max(3.0);
        let e = SkinEmbedding::new(&mesh.nodes, &mesh.tets, on_skin, &skin.vertices, reach);
        Ok((e.carry(&mesh.tets, &displacement), e))
    })?;
    let count = |c: u8| constraint.iter().filter(|k| **k == c).count();
    let reached: Vec<f64> = embedding
        .distance
        .iter()
        .zip(&embedding.tet)
        .filter(|(_, t)| t.is_some())
        .map(|(d, _)| *d)
        .collect();
    let report = TetReport {
        material: t.material,
        region: roi,
        nodes: mesh.nodes.len(),
        tets: mesh.tets.len(),
        dofs: 3 * mesh.nodes.len(),
        free_dofs: 3 * count(FREE),
        skin_nodes: mesh.kind.iter().filter(|k| **k == NodeKind::Skin).count(),
        moved_nodes: count(MOVED),
        fixed_nodes: count(FIXED),
        quality: mesh.quality.clone(),
        face_vertices_unreached: embedding.unreached(),
        face_to_mesh_mm: stats(&reached),
    };
    let face_post = skin
        .vertices
        .iter()
        .zip(&carried)
        .map(|(p, d)| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
        .collect();
    Ok(Some((
        Volumetric {
            mesh,
            constraint,
            material,
            displacement,
            report,
        },
        face_post,
    )))
}

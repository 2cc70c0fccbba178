//! The volumetric model's boundary conditions (docs/pipeline.md "Volumetric soft tissue"):
//! which node moves with which bone, which is held, which mucosa node slides on the bone it faces
//! (`[tet] sliding`), the pieces of the mesh too loosely held to solve, and each element's
//! material. Everything here is a function of the mesh, the bone and the plan; the model stage
//! (`crate::model::volumetric`) calls it.

use super::embed::boundary_faces;
use super::from_ct::NodeKind;
use super::plan_holds::{LinearHold, segment_at};
use super::quadratic::Tet10Mesh;
use super::vtu::{FIXED, FREE, MOVED, SLIDING};
use super::{Hold, TissueElastic};
use crate::case::{Osteotomy, Tet};
use crate::mesh::Mesh;
use crate::osteotomy::Plan;
use crate::segment::runs::Runs;
use crate::volume::Volume;

/// The role of each node (`kind`, at `nodes`) and its hold: bone nodes inside a segment move
/// with it (any rotation, exactly: the displacement is p' − p of the plan's rigid move), other
/// bone and the cut faces stay, skin outside `[surface] movable` stays, mucosa slides along or
/// moves with the bone it faces (`mucosa`), the rest is free. With `rest_normals` (the linear
/// models) mucosa slides along the bone's normal at rest, the small-strain form of the condition,
/// which keeps the factor independent of the plan (the plan basis). Also returns each hold as a
/// linear function of the segments' matrices (docs/plan-basis.md) and the nodes that lie in more
/// than one segment (their moves compose).
pub(crate) fn holds(
    nodes: &[[f64; 3]],
    kind: &[NodeKind],
    mucosa: &[Option<Mucosa>],
    rigid: &[bool],
    bone: &Bone,
    sliding: bool,
    rest_normals: bool,
) -> Holds {
    let (moved_to, moved) = bone.plan.apply(nodes, 1.0);
    let mut overlaps = Vec::new();
    let mut out = Holds::default();
    for (n, k) in kind.iter().enumerate() {
        let (c, h, l) = match (k, mucosa.get(n).copied().flatten()) {
            (NodeKind::Bone, _) if moved[n] => {
                let (s, over) = segment_at(bone.osteotomy, nodes[n]);
                overlaps.extend(over);
                (
                    MOVED,
                    Hold::Fixed([0, 1, 2].map(|c| moved_to[n][c] - nodes[n][c])),
                    s.map_or(LinearHold::Still, |segment| LinearHold::Moves {
                        segment,
                        at: nodes[n],
                    }),
                )
            }
            (NodeKind::Bone | NodeKind::Cut, _) => {
                (FIXED, Hold::Fixed([0.0; 3]), LinearHold::Still)
            }
            (NodeKind::Skin, _) if rigid[n] => (FIXED, Hold::Fixed([0.0; 3]), LinearHold::Still),
            (NodeKind::Skin, Some(m)) if sliding => {
                let normal = if rest_normals {
                    m.rest_normal
                } else {
                    m.normal
                };
                (
                    SLIDING,
                    Hold::Slide {
                        normal,
                        value: (0..3).map(|c| normal[c] * m.bone_move[c]).sum(),
                    },
                    LinearHold::Slides {
                        normal: m.rest_normal,
                        segment: m.segment,
                        at: m.bone_at,
                    },
                )
            }
            (NodeKind::Skin, Some(m)) => (
                if m.bone_move == [0.0; 3] {
                    FIXED
                } else {
                    MOVED
                },
                Hold::Fixed(m.bone_move),
                m.segment
                    .map_or(LinearHold::Still, |segment| LinearHold::Moves {
                        segment,
                        at: m.bone_at,
                    }),
            ),
            (NodeKind::Skin | NodeKind::Interior, _) => (FREE, Hold::Free, LinearHold::Free),
        };
        out.constraint.push(c);
        out.hold.push(h);
        out.linear.push(l);
    }
    overlaps.sort_unstable();
    overlaps.dedup();
    out.overlapping_segments = overlaps;
    out
}

/// Per node: the constraint code, the hold, the hold as a function of the plan; and the segments
/// some node lies in together.
#[derive(Default)]
pub(crate) struct Holds {
    pub constraint: Vec<u8>,
    pub hold: Vec<Hold>,
    pub linear: Vec<LinearHold>,
    pub overlapping_segments: Vec<usize>,
}

/// The bone that holds the tissue: the skull surface at rest, the plan's rigid moves and its
/// segments (`[[osteotomy]]`, in the plan's order).
pub(crate) struct Bone<'a> {
    pub skull: &'a Mesh,
    pub plan: &'a Plan,
    pub osteotomy: &'a [Osteotomy],
}

/// A mucosa node: the bone surface's unit normal at the nearest skull point (after the move)
/// and that point's displacement.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Mucosa {
    normal: [f64; 3],
    bone_move: [f64; 3],
    /// The bone surface's normal at rest, the nearest skull point and its segment (at rest).
    rest_normal: [f64; 3],
    bone_at: [f64; 3],
    segment: Option<usize>,
}

/// Skin-kind nodes that face a cavity (no outside air within a voxel of them) and lie within
/// `[tet] mucosa_gap_mm` of the skull surface: the inner lips and cheeks across the vestibule,
/// the nasal floor.
pub(crate) fn mucosa(
    nodes: &[[f64; 3]],
    kind: &[NodeKind],
    bone: &Bone,
    vol: &Volume,
    outside: &Runs,
    gap_mm: f64,
) -> Vec<Option<Mucosa>> {
    use rayon::prelude::*;
    let skull = bone.skull;
    let index = crate::compare::SurfaceIndex::new(skull);
    let faces_cavity = |p: [f64; 3]| {
        let c = vol.to_voxel(p).map(|v| v.round() as i64);
        !(-1..=1).any(|dk| {
            (-1..=1).any(|dj| {
                (-1..=1).any(|di| {
                    let (i, j, k) = (c[0] + di, c[1] + dj, c[2] + dk);
                    i >= 0
                        && j >= 0
                        && k >= 0
                        && outside.contains(i as usize, j as usize, k as usize)
                })
            })
        })
    };
    let plan = bone.plan;
    nodes
        .par_iter()
        .zip(kind)
        .map(|(p, k)| {
            if *k != NodeKind::Skin || !faces_cavity(*p) {
                return None;
            }
            let (d, q, t) = index.closest_triangle(*p);
            if !(d <= gap_mm) {
                return None;
            }
            let tri = skull.triangles[t].map(|v| skull.vertices[v as usize]);
            let n = crate::vec3::cross(
                crate::vec3::sub(tri[1], tri[0]),
                crate::vec3::sub(tri[2], tri[0]),
            );
            let len = crate::vec3::norm(n);
            if !(len > 0.0) {
                return None;
            }
            let n = n.map(|v| v / len);
            // The normal carried by the bone's move: the image of q + εn minus that of q.
            let eps = 1e-3;
            let (moved, which) = plan.apply(&[q, [0, 1, 2].map(|c| q[c] + eps * n[c])], 1.0);
            let bone_move = [0, 1, 2].map(|c| moved[0][c] - q[c]);
            let normal = if which[0] == which[1] {
                let m = [0, 1, 2].map(|c| (moved[1][c] - moved[0][c]) / eps);
                let l = crate::vec3::norm(m);
                m.map(|v| v / l)
            } else {
                n
            };
            Some(Mucosa {
                normal,
                bone_move,
                rest_normal: n,
                bone_at: q,
                segment: segment_at(bone.osteotomy, q).0,
            })
        })
        .collect()
}

/// The role of each midpoint of a 10-node mesh: a midpoint on a boundary face whose corners
/// are all held (bone, cut) takes the role of that surface; every other midpoint is interior or
/// skin, free.
pub(crate) fn midpoint_kinds(q: &Tet10Mesh, tets: &[[u32; 4]], kind: &[NodeKind]) -> Vec<NodeKind> {
    let mut mid = vec![NodeKind::Interior; q.edges.len()];
    let held = |k: NodeKind| matches!(k, NodeKind::Bone | NodeKind::Cut);
    for (_, f) in boundary_faces(tets) {
        let ks = f.map(|n| kind[n as usize]);
        let role = if ks.iter().all(|k| *k == NodeKind::Bone) {
            NodeKind::Bone
        } else if ks.iter().all(|k| held(*k)) {
            NodeKind::Cut
        } else {
            continue;
        };
        for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
            if let Some(m) = q.midpoint(a, b) {
                let e = m as usize - q.corners;
                if mid[e] != NodeKind::Bone {
                    mid[e] = role;
                }
            }
        }
    }
    mid
}

/// Pieces of the mesh (tetrahedra joined through shared faces; a piece hanging on by a node
/// or an edge is a hinge) held by fewer than three nodes would float or turn: a singular
/// system. Their nodes are held still. `cells` are the solved elements (4-node, or 10-node
/// with the corners first): a node no cell uses carries no stiffness and is held too. Returns
/// the pieces and nodes so held.
pub(crate) fn hold_floating_pieces<C: AsRef<[u32]>>(
    cells: &[C],
    constraint: &mut [u8],
    hold: &mut [Hold],
    linear: &mut [LinearHold],
) -> (usize, usize) {
    let mut faces: Vec<([u32; 3], u32)> = cells
        .iter()
        .enumerate()
        .flat_map(|(t, q)| {
            let q = q.as_ref();
            [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]].map(|f| {
                let mut k = f.map(|i| q[i]);
                k.sort_unstable();
                (k, t as u32)
            })
        })
        .collect();
    faces.sort_unstable();
    let mut uf = crate::union_find::UnionFind::new(cells.len());
    for w in faces.windows(2) {
        if w[0].0 == w[1].0 {
            uf.union(w[0].1 as usize, w[1].1 as usize);
        }
    }
    let (label, count) = uf.labels();
    // A piece is anchored by three or more held nodes (one or two let it turn about them).
    let mut held_nodes: Vec<Vec<u32>> = vec![Vec::new(); count];
    for (t, q) in cells.iter().enumerate() {
        for n in q.as_ref() {
            if matches!(constraint[*n as usize], FIXED | MOVED) {
                held_nodes[label[t] as usize].push(*n);
            }
        }
    }
    let anchored: Vec<bool> = held_nodes
        .iter_mut()
        .map(|h| {
            h.sort_unstable();
            h.dedup();
            h.len() >= 3
        })
        .collect();
    // A node no tetrahedron uses (one of a flattened sliver left out of the mesh) carries no
    // stiffness: hold it.
    let mut used = vec![false; constraint.len()];
    cells
        .iter()
        .flat_map(|q| q.as_ref())
        .for_each(|n| used[*n as usize] = true);
    for (n, u) in used.iter().enumerate() {
        if !u && n < hold.len() {
            constraint[n] = FIXED;
            hold[n] = Hold::Fixed([0.0; 3]);
            linear[n] = LinearHold::Still;
        }
    }
    let mut pieces = vec![false; count];
    let mut nodes = 0;
    for (t, q) in cells.iter().enumerate() {
        let l = label[t] as usize;
        if anchored[l] {
            continue;
        }
        pieces[l] = true;
        for n in q.as_ref() {
            let n = *n as usize;
            if constraint[n] != FIXED {
                constraint[n] = FIXED;
                hold[n] = Hold::Fixed([0.0; 3]);
                linear[n] = LinearHold::Still;
                nodes += 1;
            }
        }
    }
    (pieces.iter().filter(|p| **p).count(), nodes)
}

/// Per tetrahedron, the material of its tissue label (`[tet]`).
pub(crate) fn materials(tissue: &[u8], tet: &Tet) -> Vec<TissueElastic> {
    tissue.iter().map(|l| tet.elastic(*l)).collect()
}

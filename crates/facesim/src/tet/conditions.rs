//! The volumetric model's boundary conditions (docs/design/pipeline.md "Volumetric soft tissue"):
//! which node moves with which bone, which is held, which mucosa node slides on the bone it faces
//! (`[tet] sliding`), the pieces of the mesh too loosely held to solve, and each element's
//! material. Everything here is a function of the mesh, the bone and the plan; the model stage
//! (`crate::model::volumetric`) calls it.

use super::bone_normal::BoneNormals;
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
use std::sync::OnceLock;

/// The role of each node (`kind`, at `nodes`) and its hold, the tissue bonded to its bone: bone
/// nodes inside a segment move with it (any rotation, exactly: the displacement is p' − p of the
/// plan's rigid move), other bone and the cut faces stay, skin outside `[surface] movable`
/// (`rigid`) stays, mucosa moves with the bone it faces (`mucosa`), the rest is free. Also each
/// hold as a linear function of the segments' matrices (docs/design/plan-basis.md) and, per moved bone
/// node, the segments it lies in together with its own (their moves compose). [`slide_on_bone`]
/// then lets mucosa and contact slide.
pub(crate) fn bone_moves(
    nodes: &[[f64; 3]],
    kind: &[NodeKind],
    mucosa: &[Option<Mucosa>],
    rigid: &[bool],
    bone: &Bone,
) -> Holds {
    let (moved_to, moved) = bone.plan.apply(nodes, 1.0);
    let mut out = Holds::default();
    for (n, k) in kind.iter().enumerate() {
        let (c, h, l) = match (k, mucosa.get(n).copied().flatten()) {
            (NodeKind::Bone, _) if moved[n] => {
                let (s, over) = segment_at(bone.osteotomy, nodes[n]);
                out.overlaps.extend(over.into_iter().map(|s| (n, s)));
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
            (NodeKind::Skin, Some(m)) => (
                if m.node_move == [0.0; 3] {
                    FIXED
                } else {
                    MOVED
                },
                Hold::Fixed(m.node_move),
                m.segment
                    .map_or(LinearHold::Still, |segment| LinearHold::Moves {
                        segment,
                        at: m.at,
                    }),
            ),
            (NodeKind::Skin | NodeKind::Interior, _) => (FREE, Hold::Free, LinearHold::Free),
        };
        out.constraint.push(c);
        out.hold.push(h);
        out.linear.push(l);
    }
    out
}

/// `[tet] sliding`: the mucosa and the bone lip or cheek rests on (`mucosa`; bone-kind nodes on
/// the teeth or raised by a degloving approach) slide along the bone they face instead of moving
/// with it: n · u = n · u_bone, tangential free. Skin held by `[surface] movable` (`rigid`) stays
/// held. With `rest_normals` (the linear models) along the bone's normal at rest, the
/// small-strain form of the condition, which keeps the factor independent of the plan (the plan
/// basis). A bone node that slides no longer composes its segments' moves. How many nodes slide.
pub(crate) fn slide_on_bone(
    h: &mut Holds,
    kind: &[NodeKind],
    mucosa: &[Option<Mucosa>],
    rigid: &[bool],
    rest_normals: bool,
) -> usize {
    let mut slid = vec![false; kind.len()];
    for (n, k) in kind.iter().enumerate() {
        let Some(m) = mucosa.get(n).copied().flatten() else {
            continue;
        };
        if !(*k == NodeKind::Bone || (*k == NodeKind::Skin && !rigid[n])) {
            continue;
        }
        let normal = if rest_normals {
            m.rest_normal
        } else {
            m.normal
        };
        h.constraint[n] = SLIDING;
        h.hold[n] = Hold::Slide {
            normal,
            value: (0..3).map(|c| normal[c] * m.node_move[c]).sum(),
        };
        h.linear[n] = LinearHold::Slides {
            normal: m.rest_normal,
            segment: m.segment,
            at: m.at,
        };
        slid[n] = true;
    }
    h.overlaps.retain(|(n, _)| !slid[*n]);
    slid.iter().filter(|s| **s).count()
}

/// Per node: the constraint code, the hold, the hold as a function of the plan; and, per moved
/// bone node, the other segments it lies in.
#[derive(Default)]
pub(crate) struct Holds {
    pub constraint: Vec<u8>,
    pub hold: Vec<Hold>,
    pub linear: Vec<LinearHold>,
    /// (node, segment): a bone node moved with its segment lies in this one too.
    pub overlaps: Vec<(usize, usize)>,
}

impl Holds {
    /// The segments some moved bone node lies in together with another (ascending).
    pub(crate) fn overlapping_segments(&self) -> Vec<usize> {
        let mut s: Vec<usize> = self.overlaps.iter().map(|(_, s)| *s).collect();
        s.sort_unstable();
        s.dedup();
        s
    }
}

/// `[tet] scan_end = "slides"`: every free node past the CT's outermost voxel centres `bounds`
/// (the tissue's surface where the scan ends, `volume::past_scan_end`) slides on the plane the
/// scan ends in: n · u = 0 with n that plane's outward normal, the motion along it free. Tissue
/// that goes on past a plane and is moved mirror-symmetrically about it moves so; a free surface
/// instead lets the cut lip or neck swing as if nothing lay beyond (docs/lab/validation-notes.md
/// "Where the scan ends: a truncation study"). A node past two planes (an edge of the field of
/// view) slides on the one it lies furthest past. The plane is held by the rest of the head, the
/// bone the plan leaves in place: a plan that moves every bone node of the mesh (the whole head
/// moved rigidly) leaves nothing to hold it, and the end stays free. How many nodes now slide
/// there.
pub(crate) fn slide_on_scan_end(
    h: &mut Holds,
    nodes: &[[f64; 3]],
    kind: &[NodeKind],
    bounds: ([f64; 3], [f64; 3]),
) -> usize {
    let rest_of_head = kind
        .iter()
        .zip(&h.linear)
        .any(|(k, l)| *k == NodeKind::Bone && *l == LinearHold::Still);
    if !rest_of_head {
        return 0;
    }
    let mut n_sliding = 0;
    for (n, p) in nodes.iter().enumerate() {
        if h.constraint[n] != FREE || !crate::volume::past_scan_end(bounds, *p) {
            continue;
        }
        let (mut axis, mut past, mut sign) = (0, f64::NEG_INFINITY, 1.0);
        for k in 0..3 {
            for (d, s) in [(bounds.0[k] - p[k], -1.0), (p[k] - bounds.1[k], 1.0)] {
                if d > past {
                    (axis, past, sign) = (k, d, s);
                }
            }
        }
        let mut normal = [0.0; 3];
        normal[axis] = sign;
        h.constraint[n] = SLIDING;
        h.hold[n] = Hold::Slide { normal, value: 0.0 };
        h.linear[n] = LinearHold::Slides {
            normal,
            segment: None,
            at: *p,
        };
        n_sliding += 1;
    }
    n_sliding
}

/// The bone that holds the tissue: the skull surface at rest, the plan's rigid moves and its
/// segments (`[[osteotomy]]`, in the plan's order), and the surface's normals where tissue slides
/// on it ([`Bone::normals`]).
pub(crate) struct Bone<'a> {
    pub skull: &'a Mesh,
    pub plan: &'a Plan,
    pub osteotomy: &'a [Osteotomy],
    /// The radius (mm) the normals average over (`tet::bone_normal`).
    normal_radius: f64,
    normals: OnceLock<BoneNormals>,
}

impl<'a> Bone<'a> {
    /// The bone of `skull` moved by `plan`, its normals averaged within `normal_radius` (mm).
    pub(crate) fn new(
        skull: &'a Mesh,
        plan: &'a Plan,
        osteotomy: &'a [Osteotomy],
        normal_radius: f64,
    ) -> Bone<'a> {
        Bone {
            skull,
            plan,
            osteotomy,
            normal_radius,
            normals: OnceLock::new(),
        }
    }

    /// The skull surface's normals where tissue slides on it, bucketed on first use: the
    /// re-solves (`Volumetric::resolve`, the reduced model's assembly) take the holds from the
    /// run and never ask.
    pub(crate) fn normals(&self) -> &BoneNormals {
        self.normals
            .get_or_init(|| BoneNormals::new(self.skull, self.normal_radius))
    }
}

/// A mucosa node: the bone surface's unit normal about the nearest skull point (after the move;
/// `tet::bone_normal`)
/// and the node's displacement as that bone point's segment carries it (not the bone point's
/// own displacement: under a rotation the two differ by the turn of the gap between them).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Mucosa {
    normal: [f64; 3],
    node_move: [f64; 3],
    /// The bone surface's normal at rest, the node at rest and the segment of its nearest skull
    /// point.
    rest_normal: [f64; 3],
    at: [f64; 3],
    segment: Option<usize>,
}

/// Whether the air outside the head lies within a voxel of `p` (a skin node on the face, not on
/// a cavity's wall: the airway, the mouth, the nose's passages).
fn touches_outside(vol: &Volume, outside: &Runs, p: [f64; 3]) -> bool {
    let c = vol.to_voxel(p).map(|v| v.round() as i64);
    (-1..=1).any(|dk| {
        (-1..=1).any(|dj| {
            (-1..=1).any(|di| {
                let (i, j, k) = (c[0] + di, c[1] + dj, c[2] + dk);
                i >= 0 && j >= 0 && k >= 0 && outside.contains(i as usize, j as usize, k as usize)
            })
        })
    })
}

/// Per node: a skin-kind node on the face (the outside air within a voxel). `[surface]
/// movable` holds only these: it says where the face may move, and a cavity's wall outside it
/// (the pharynx behind an advanced maxilla) is tissue like any other, free. Held, it pinned
/// the airway's wall 4 mm from a 15 mm advanced maxilla and turned an element inside out.
pub(crate) fn on_face(
    nodes: &[[f64; 3]],
    kind: &[NodeKind],
    vol: &Volume,
    outside: &Runs,
) -> Vec<bool> {
    use rayon::prelude::*;
    nodes
        .par_iter()
        .zip(kind)
        .map(|(p, k)| *k == NodeKind::Skin && touches_outside(vol, outside, *p))
        .collect()
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
    let faces_cavity = |p: [f64; 3]| !touches_outside(vol, outside, p);
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
            // The bone's surface about q, not its one nearest facet (`tet::bone_normal`).
            let n = bone.normals().at(q, n).unwrap_or(n);
            // The node and the normal carried by the bone's move at q: the image of q + εn
            // minus that of q.
            let eps = 1e-3;
            let (moved, _) =
                plan.carry(&[*p, q, [0, 1, 2].map(|c| q[c] + eps * n[c])], &[q; 3], 1.0);
            let normal = [0, 1, 2].map(|c| (moved[2][c] - moved[1][c]) / eps);
            let l = crate::vec3::norm(normal);
            Some(Mucosa {
                normal: normal.map(|v| v / l),
                node_move: [0, 1, 2].map(|c| moved[0][c] - p[c]),
                rest_normal: n,
                at: *p,
                segment: segment_at(bone.osteotomy, q).0,
            })
        })
        .collect()
}

/// Tooth: the median HU at [`TOOTH_DEPTHS_MM`] under a bone node (into the bone) at or above
/// this. Enamel and dentine are the brightest tissue of a head CT (dentine ≈ 1600–2400 HU, enamel
/// above 2500, metal saturated; the real CT's crowns 1650–2150 at a node), the alveolar and basal
/// bone below it (the maxilla's thin cortex over cancellous bone); the jaws phantom's teeth are
/// 1500. The median ignores one bright metal streak or one dark beam-hardening band.
pub(crate) const TOOTH_HU: f64 = 1450.0;

/// Depths (mm) into the bone where [`TOOTH_HU`] is tested: the median needs three of the five,
/// so the bone must be that dense at 3 mm or deeper. A crown is dense right through (5–10 mm
/// labio-lingually above its edge); the skull's cortex is a 1.5–3 mm table over cancellous bone
/// or diploë (300–800 HU) (the real CT's occipital and mastoid cortex reaches 1590 HU 1–3 mm
/// deep).
pub(crate) const TOOTH_DEPTHS_MM: [f64; 5] = [1.5, 2.25, 3.0, 3.75, 4.5];

/// How far (mm) into the tissue the face's outside air must be reached from a tooth's surface for
/// lip or cheek to lie on it: the upper lip is 11–17 mm thick at the incisors, the cheek 15–30 mm
/// at the molars.
pub(crate) const LIP_REACH_MM: f64 = 35.0;

/// The lip–tooth and cheek–tooth contact: `Bone`-kind nodes where lip or cheek
/// rests on the crowns with no air between (the vestibule is a potential space: the lip is not
/// attached to the teeth). A bone node is in contact when (1) it lies on a tooth: the median HU
/// at [`TOOTH_DEPTHS_MM`] into the bone, along the normal, is at least [`TOOTH_HU`]; and (2) lip or cheek
/// covers it: from the node into the tissue (the normal: the mean direction to its elements'
/// centroids; the node then slides on the bone surface's own normal, `tet::bone_normal`) the
/// air outside the head is reached within [`LIP_REACH_MM`] through soft tissue
/// alone (no bone on the way), at the face (`face`: the skin `[surface] movable` lets move, not
/// the scalp): the labial and buccal faces of the dental arch, not the lingual, palatal or
/// occlusal ones (tongue, the other jaw). Everything here is the anatomy at rest, not
/// the plan, so the set keeps the model linear in the plan. The rest of the bone (gingiva and
/// periosteum on the alveolar process and elsewhere) stays attached.
///
/// Returns every bone node that lip or cheek covers (criterion (2)), each with whether it lies on
/// a tooth (criterion (1)): the contact nodes are those on a tooth; `[tet] degloved_maxilla`
/// and `degloved_chin` take the others over the anterior maxilla and the chin too
/// (`model::degloved`).
pub(crate) fn covered_bone(
    nodes: &[[f64; 3]],
    tets: &[[u32; 4]],
    kind: &[NodeKind],
    bone: &Bone,
    vol: &Volume,
    seg: &crate::segment::Segmentation,
    face: &(dyn Fn([f64; 3]) -> bool + Sync),
) -> Vec<Option<Covered>> {
    use rayon::prelude::*;
    let inward = into_tissue(nodes, tets, kind);
    let step = 0.5 * vol.spacing.iter().copied().fold(f64::INFINITY, f64::min);
    let voxel = |p: [f64; 3]| {
        let c = vol.to_voxel(p).map(|v| v.round() as i64);
        (c.iter()
            .zip(vol.dims)
            .all(|(c, d)| *c >= 0 && (*c as usize) < d))
        .then(|| c.map(|v| v as usize))
    };
    // From p along n: true at the outside air; false at bone or beyond the reach.
    let reaches_outside = |p: [f64; 3], n: [f64; 3]| {
        let mut d = step;
        while d <= LIP_REACH_MM {
            let q = [0, 1, 2].map(|c| p[c] + d * n[c]);
            let Some([i, j, k]) = voxel(q) else {
                return false;
            };
            if seg.outside.contains(i, j, k) {
                return face(q);
            }
            // Past the first millimetre (the node's own bone surface, partial volume).
            if d > 1.0 && seg.labels[vol.idx(i, j, k)] == crate::segment::BONE {
                return false;
            }
            d += step;
        }
        false
    };
    let plan = bone.plan;
    let rows: Vec<Option<(f64, bool)>> = nodes
        .par_iter()
        .zip(kind)
        .zip(&inward)
        .map(|((p, k), w)| {
            let len = crate::vec3::norm(*w);
            if *k != NodeKind::Bone || !(len > 0.0) {
                return None;
            }
            let n = w.map(|c| c / len);
            let mut hu = TOOTH_DEPTHS_MM
                .map(|d| vol.sample([0, 1, 2].map(|c| p[c] - d * n[c]), -1000.0) as f64);
            hu.sort_by(f64::total_cmp);
            Some((hu[hu.len() / 2], reaches_outside(*p, n)))
        })
        .collect();
    nodes
        .iter()
        .zip(&rows)
        .zip(&inward)
        .map(|((p, r), w)| {
            let (hu, out) = (*r)?;
            if !out {
                return None;
            }
            // The direction into the tissue tells the ray where to look; the bone's own
            // surface tells how the tissue slides on it.
            let into = w.map(|c| c / crate::vec3::norm(*w));
            let n = bone.normals().at(*p, into).unwrap_or(into);
            // The normal carried by the bone's move: the image of p + εn minus that of p.
            let eps = 1e-3;
            let (moved, which) = plan.apply(&[*p, [0, 1, 2].map(|c| p[c] + eps * n[c])], 1.0);
            let node_move = [0, 1, 2].map(|c| moved[0][c] - p[c]);
            let normal = if which[0] == which[1] {
                let m = [0, 1, 2].map(|c| (moved[1][c] - moved[0][c]) / eps);
                let l = crate::vec3::norm(m);
                m.map(|v| v / l)
            } else {
                n
            };
            Some(Covered {
                mucosa: Mucosa {
                    normal,
                    node_move,
                    rest_normal: n,
                    at: *p,
                    segment: segment_at(bone.osteotomy, *p).0,
                },
                tooth: hu >= TOOTH_HU,
            })
        })
        .collect()
}

/// Per node: for a bone node, the sum of the directions from it to its elements' centroids, the
/// side its tissue lies on (zero for other nodes).
pub(crate) fn into_tissue(
    nodes: &[[f64; 3]],
    tets: &[[u32; 4]],
    kind: &[NodeKind],
) -> Vec<[f64; 3]> {
    let mut inward = vec![[0.0; 3]; nodes.len()];
    for q in tets {
        let c: [f64; 3] =
            std::array::from_fn(|k| q.iter().map(|n| nodes[*n as usize][k]).sum::<f64>() / 4.0);
        for n in q {
            let n = *n as usize;
            if kind[n] == NodeKind::Bone {
                inward[n] = crate::vec3::add(inward[n], crate::vec3::sub(c, nodes[n]));
            }
        }
    }
    inward
}

/// A bone node that lip or cheek covers ([`covered_bone`]): how it slides, and whether it lies
/// on a tooth (a contact node).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Covered {
    pub mucosa: Mucosa,
    pub tooth: bool,
}

impl Covered {
    /// The node's segment (None: bone left in place).
    pub(crate) fn segment(&self) -> Option<usize> {
        self.mucosa.segment
    }

    /// A covered node on `segment`, at rest, for tests of what reads the covered bone.
    #[cfg(test)]
    pub(crate) fn at_rest(segment: Option<usize>, tooth: bool) -> Covered {
        Covered {
            mucosa: Mucosa {
                normal: [1.0, 0.0, 0.0],
                node_move: [0.0; 3],
                rest_normal: [1.0, 0.0, 0.0],
                at: [0.0; 3],
                segment,
            },
            tooth,
        }
    }
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
/// system. Each such piece moves rigidly with what holds it already (the bone of its one or two
/// held nodes, most of them), else with the bone it lies on (`follow`, given the piece's nodes:
/// the segment most of its nodes are nearest to, or still): in a head whose bone all
/// moves, nothing is held still (36 pieces held still made a rigid move of the whole
/// skull 24 % non-rigid). `cells` are the solved elements (4-node, or 10-node with the corners
/// first): a node no cell uses carries no stiffness and follows its bone too. Returns the pieces
/// and nodes so held.
pub(crate) fn hold_floating_pieces<C: AsRef<[u32]>>(
    cells: &[C],
    at: &[[f64; 3]],
    h: &mut Holds,
    follow: &dyn Fn(&[usize]) -> Option<usize>,
    ms: &[[f64; crate::plan::basis::COLUMNS]],
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
            if matches!(h.constraint[*n as usize], FIXED | MOVED) {
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
    let hold_with = |nodes: &[usize], h: &mut Holds| {
        // The piece follows what already holds it (a hinge node's bone), else its nearest bone.
        let mut votes: Vec<(Option<usize>, usize)> = Vec::new();
        for p in nodes.iter().filter_map(|n| held_piece(h, *n)) {
            match votes.iter_mut().find(|(q, _)| *q == p) {
                Some((_, c)) => *c += 1,
                None => votes.push((p, 1)),
            }
        }
        // Most votes; a tie goes to the bone the piece lies on when that is one of them.
        let most = votes.iter().map(|(_, c)| *c).max();
        let tied: Vec<Option<usize>> = votes
            .iter()
            .filter(|(_, c)| Some(*c) == most)
            .map(|(p, _)| *p)
            .collect();
        let segment = match tied.as_slice() {
            [] => follow(nodes),
            [one] => *one,
            _ => Some(follow(nodes))
                .filter(|s| tied.contains(s))
                .unwrap_or(tied[0]),
        };
        let mut count = 0;
        for &n in nodes {
            // A node held by another piece's bone (a piece hinged on both sides of a cut) moves
            // with the piece too: a rigid sliver cannot follow two bones.
            if held_piece(h, n) != Some(segment) {
                // Each node moves as the piece's bone carries its own position.
                h.linear[n] = segment.map_or(LinearHold::Still, |segment| LinearHold::Moves {
                    segment,
                    at: at[n],
                });
                h.hold[n] = h.linear[n].hold(ms);
                h.constraint[n] = if segment.is_some() { MOVED } else { FIXED };
                count += 1;
            }
        }
        count
    };
    // A node no tetrahedron uses (one of a flattened sliver left out of the mesh) carries no
    // stiffness: it follows its bone.
    let mut used = vec![false; h.constraint.len()];
    cells
        .iter()
        .flat_map(|q| q.as_ref())
        .for_each(|n| used[*n as usize] = true);
    for n in 0..used.len().min(h.hold.len()) {
        if !used[n] {
            hold_with(&[n], h);
        }
    }
    // A node an anchored piece shares (the hinge) is solved with that piece: holding it with
    // the floating one would join two bones in the anchored piece's elements (a released saw-line
    // node re-held with the other bone turns them inside out).
    let mut in_anchored = vec![false; h.constraint.len()];
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (t, q) in cells.iter().enumerate() {
        let l = label[t] as usize;
        if anchored[l] {
            q.as_ref()
                .iter()
                .for_each(|n| in_anchored[*n as usize] = true);
        } else {
            members[l].extend(q.as_ref().iter().map(|n| *n as usize));
        }
    }
    members
        .iter_mut()
        .for_each(|m| m.retain(|n| !in_anchored[*n]));
    let mut pieces = 0;
    let mut nodes = 0;
    for mut m in members.into_iter().filter(|m| !m.is_empty()) {
        m.sort_unstable();
        m.dedup();
        pieces += 1;
        nodes += hold_with(&m, h);
    }
    (pieces, nodes)
}

/// For [`hold_floating_pieces`]: the bone a piece of tissue with nodes at `nodes` (indices
/// into `at`) lies on: the segment most of its nodes' nearest bone points lie in, or None (still)
/// when that is bone no segment moves.
pub(crate) fn follow_bone<'a>(
    bone: &'a Bone<'a>,
    at: &'a [[f64; 3]],
) -> impl Fn(&[usize]) -> Option<usize> + 'a {
    let index = crate::compare::SurfaceIndex::new(bone.skull);
    move |nodes: &[usize]| {
        let mut votes = vec![0usize; bone.osteotomy.len() + 1];
        for &n in nodes {
            let (_, q, _) = index.closest_triangle(at[n]);
            let s = segment_at(bone.osteotomy, q).0;
            votes[s.map_or(0, |s| s + 1)] += 1;
        }
        let best = (0..votes.len()).max_by_key(|i| votes[*i]).unwrap_or(0);
        best.checked_sub(1)
    }
}

/// The piece of bone a held node moves with: Some(Some(s)) segment s, Some(None) still (bone
/// left in place, held skin, the region's cut faces), None not held (free or sliding).
fn held_piece(h: &Holds, n: usize) -> Option<Option<usize>> {
    match (h.constraint[n], h.linear[n]) {
        (MOVED, LinearHold::Moves { segment, .. }) => Some(Some(segment)),
        (FIXED, _) => Some(None),
        _ => None,
    }
}

/// The saw line: the tissue is not one continuum through an osteotomy. Where
/// pieces held differently meet (a segment's bone and the bone left in place, two segments, or a
/// segment and held skin or the region's cut faces), the surgeon has raised the periosteum and
/// the tissue over the cut is not attached: the held nodes of every element joining two pieces,
/// and every held bone node nearer than `band_mm` to a held node of another piece, are released.
/// So no element joins two pieces: the tissue bridges the step instead of one element being
/// sheared inside out.
///
/// A released bone node slides on its own bone (n · u = n · u_bone, tangential free): the tissue
/// stays on the bone it covers, as it does after the periosteum is closed, but is not dragged
/// along it. n is the direction from the node into the tissue around it (the mean of its
/// elements' centroids), so the bone mesh's orientation does not matter. A released node that is
/// not bone (held skin, the region's cut faces), or any released node with `slide` false (`[tet]
/// sliding = false`: nothing slides), is free. The set depends on the segments and the geometry,
/// not on how far the plan moves them, so the face stays linear in the move and the plan basis
/// exact. Returns the released nodes.
pub(crate) fn release_at_cuts<C: AsRef<[u32]>>(
    cells: &[C],
    at: &[[f64; 3]],
    kind: &[NodeKind],
    h: &mut Holds,
    band_mm: f64,
    slide: bool,
) -> usize {
    let piece: Vec<Option<Option<usize>>> =
        (0..h.constraint.len()).map(|n| held_piece(h, n)).collect();
    let is_bone = |n: usize| matches!(kind.get(n), Some(NodeKind::Bone));
    let mut release = vec![false; piece.len()];
    for q in cells {
        let q = q.as_ref();
        let first = q.iter().find_map(|n| piece[*n as usize]);
        if q.iter()
            .any(|n| piece[*n as usize].is_some_and(|p| Some(p) != first))
        {
            q.iter()
                .filter(|n| piece[**n as usize].is_some())
                .for_each(|n| release[*n as usize] = true);
        }
    }
    // Held nodes of other pieces within the band, on a grid of cells as wide as the band.
    let held: Vec<usize> = (0..piece.len()).filter(|n| piece[*n].is_some()).collect();
    let cell = band_mm.max(1e-6);
    let key = |p: [f64; 3]| p.map(|c| (c / cell).floor() as i64);
    let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> = Default::default();
    for &n in &held {
        grid.entry(key(at[n])).or_default().push(n);
    }
    let near_other = |n: usize| {
        let k = key(at[n]);
        (-1..=1).any(|a| {
            (-1..=1).any(|b| {
                (-1..=1).any(|c| {
                    grid.get(&[k[0] + a, k[1] + b, k[2] + c])
                        .is_some_and(|others| {
                            others.iter().any(|m| {
                                piece[*m] != piece[n]
                                    && crate::vec3::norm(crate::vec3::sub(at[n], at[*m])) < band_mm
                            })
                        })
                })
            })
        })
    };
    for &n in &held {
        if is_bone(n) && !release[n] && near_other(n) {
            release[n] = true;
        }
    }
    // Into the tissue from each node: the mean of its elements' centroids.
    let mut inward = vec![[0.0; 3]; piece.len()];
    for q in cells {
        let q = q.as_ref();
        let corners = &q[..4];
        let centroid: [f64; 3] =
            std::array::from_fn(|c| corners.iter().map(|n| at[*n as usize][c]).sum::<f64>() / 4.0);
        for n in q {
            let n = *n as usize;
            if release[n] {
                let d = crate::vec3::sub(centroid, at[n]);
                inward[n] = crate::vec3::add(inward[n], d);
            }
        }
    }
    let mut count = 0;
    for n in (0..release.len()).filter(|n| release[*n]) {
        count += 1;
        let len = crate::vec3::norm(inward[n]);
        if slide && len > 0.0 && is_bone(n) {
            let normal = inward[n].map(|c| c / len);
            let own = match h.hold[n] {
                Hold::Fixed(u) => u,
                _ => [0.0; 3],
            };
            let segment = match h.linear[n] {
                LinearHold::Moves { segment, .. } => Some(segment),
                _ => None,
            };
            h.constraint[n] = SLIDING;
            h.hold[n] = Hold::Slide {
                normal,
                value: crate::vec3::dot(normal, own),
            };
            h.linear[n] = LinearHold::Slides {
                normal,
                segment,
                at: at[n],
            };
        } else {
            h.constraint[n] = FREE;
            h.hold[n] = Hold::Free;
            h.linear[n] = LinearHold::Free;
        }
    }
    count
}

/// Per tetrahedron, the material of its tissue label (`[tet]`).
pub(crate) fn materials(tissue: &[u8], tet: &Tet) -> Vec<TissueElastic> {
    tissue.iter().map(|l| tet.elastic(*l)).collect()
}

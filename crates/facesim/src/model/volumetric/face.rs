//! Carrying the face: the solved node displacements to the face's vertices through its embedding
//! in the mesh (`tet::embed`), the face outside the region, and outside `[surface] movable` where
//! the mesh holds the face around it, kept still.

use super::mesh::Box3;
use crate::mesh::Mesh;
use crate::tet::embed::SkinEmbedding;
use crate::tet::quadratic::Tet10Mesh;

/// How the run's face is carried: its embedding and the face vertices that stay ([`still`]).
pub(super) struct Carrier<'a> {
    pub(super) embedding: &'a SkinEmbedding,
    pub(super) quadratic: Option<&'a Tet10Mesh>,
    pub(super) tets: &'a [[u32; 4]],
    pub(super) still: &'a [bool],
}

impl Carrier<'_> {
    /// Node displacements `u` to face displacements ([`carry_face`]).
    pub(super) fn carry(&self, u: &[[f64; 3]]) -> Vec<[f64; 3]> {
        carry_face(self.embedding, self.quadratic, self.tets, u, self.still)
    }
}

/// Node displacements `u` to face displacements, the vertices `still` at rest.
pub(super) fn carry_face(
    e: &SkinEmbedding,
    quadratic: Option<&Tet10Mesh>,
    tets: &[[u32; 4]],
    u: &[[f64; 3]],
    still: &[bool],
) -> Vec<[f64; 3]> {
    let mut carried = match quadratic {
        Some(q) => e.carry_quadratic(&q.tets, u),
        None => e.carry(tets, u),
    };
    for (d, still) in carried.iter_mut().zip(still) {
        if *still {
            *d = [0.0; 3];
        }
    }
    carried
}

/// The face's positions moved by the carried displacement `d`, as face_post is written.
pub(super) fn displaced(skin: &Mesh, d: &[[f64; 3]]) -> Vec<[f64; 3]> {
    crate::vec3::displaced(&skin.vertices, d)
}

/// What decides which face vertices stay.
pub(super) struct Stillness<'a> {
    /// The face region, and the tissue mesh's box around it (report.json `tet.region`,
    /// `tet.mesh_box`).
    pub(super) roi: Box3,
    pub(super) mesh_box: Box3,
    pub(super) face: &'a [[f64; 3]],
    /// Per face vertex: outside `[surface] movable`.
    pub(super) face_rigid: &'a [bool],
    /// Per face vertex: the tetrahedron carrying it (the face's embedding, `tet::embed`).
    pub(super) carried_by: &'a [Option<u32>],
    pub(super) tets: &'a [[u32; 4]],
    /// Per mesh node: a skin node on the face, and outside `[surface] movable` (held if both).
    pub(super) on_face: &'a [bool],
    pub(super) node_rigid: &'a [bool],
}

/// Face vertices that stay: beyond the mesh's box, where the tissue is held (the extrapolation
/// from the last tetrahedron would move them); and, outside the face region or outside
/// `[surface] movable`, unless the tetrahedron carrying the vertex has a face node the mesh
/// leaves free — there the mesh models the skin, and the vertex follows it so that the face
/// fades with the mesh's field instead of stepping to rest. (Holding every face vertex outside
/// `[surface] movable` tore the skin at its edge: on the real-mandible CT's BSSO advance 114
/// edges had a vertex moving beside one held exactly, the worst 1.30 mm beside 0 over 1.85 mm,
/// 0.93 mm per mm across the edge. Holding every one outside the face region did the same at
/// the region's edge: 0.54–0.55 per mm on three phantoms' bimaxillary advance, a still vertex
/// beside one moving 1.3–1.4 mm; docs/lab/skin-continuity.md.)
pub(super) fn still(s: &Stillness) -> Vec<bool> {
    let outside = |(lo, hi): Box3, p: &[f64; 3]| (0..3).any(|c| p[c] < lo[c] || p[c] > hi[c]);
    s.face
        .iter()
        .enumerate()
        .map(|(v, p)| {
            if outside(s.mesh_box, p) {
                return true;
            }
            if !outside(s.roi, p) && !s.face_rigid[v] {
                return false;
            }
            match s.carried_by[v] {
                None => true,
                Some(t) => s.tets[t as usize].iter().all(|&n| {
                    let n = n as usize;
                    !s.on_face[n] || s.node_rigid[n]
                }),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One tetrahedron, its first corner a free skin node on the face: a face vertex in it
    /// follows the mesh inside the face region and outside it within the mesh's box, and stays
    /// beyond the box; a vertex in a tetrahedron without a free face node stays outside the
    /// region.
    #[test]
    fn the_face_follows_the_mesh_past_the_region_and_stays_past_the_mesh() {
        let tets = [[0, 1, 2, 3], [4, 5, 6, 7]];
        let on_face = [true, false, false, false, false, false, false, false];
        let node_rigid = [false; 8];
        let roi: Box3 = ([0.0; 3], [10.0; 3]);
        let mesh_box: Box3 = ([-30.0; 3], [40.0; 3]);
        let face = [
            [5.0, 5.0, 5.0],  // inside the region
            [15.0, 5.0, 5.0], // past the region, in the mesh's box
            [45.0, 5.0, 5.0], // past the mesh's box
            [15.0, 5.0, 5.0], // past the region, carried by a tetrahedron without a face node
        ];
        let carried_by = [Some(0), Some(0), Some(0), Some(1)];
        let still = still(&Stillness {
            roi,
            mesh_box,
            face: &face,
            face_rigid: &[false; 4],
            carried_by: &carried_by,
            tets: &tets,
            on_face: &on_face,
            node_rigid: &node_rigid,
        });
        assert_eq!(still, [false, false, true, true]);
    }
}

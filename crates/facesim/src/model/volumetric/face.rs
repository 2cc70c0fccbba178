//! Carrying the face: the solved node displacements to the face's vertices through its embedding
//! in the mesh (`tet::embed`), the face outside the region kept still.

use super::mesh::Box3;
use crate::mesh::Mesh;
use crate::tet::embed::SkinEmbedding;
use crate::tet::quadratic::Tet10Mesh;

/// How the run's face is carried: its embedding and the region.
pub(super) struct Carrier<'a> {
    pub(super) embedding: &'a SkinEmbedding,
    pub(super) quadratic: Option<&'a Tet10Mesh>,
    pub(super) tets: &'a [[u32; 4]],
    pub(super) skin: &'a Mesh,
    pub(super) roi: Box3,
}

impl Carrier<'_> {
    /// Node displacements `u` to face displacements ([`carry_face`]).
    pub(super) fn carry(&self, u: &[[f64; 3]]) -> Vec<[f64; 3]> {
        carry_face(
            self.embedding,
            self.quadratic,
            self.tets,
            u,
            self.skin,
            self.roi,
        )
    }
}

/// Node displacements `u` to face displacements; beyond the region's cut faces the tissue is
/// held: face vertices there stay (the extrapolation from the last tetrahedron would move them).
/// The face outside `[surface] movable` is carried like the rest: the mesh's skin nodes there are
/// held, so the field is zero beyond one element of the region's edge and continuous across it.
/// (Holding those face vertices still as well tore the skin at the edge: on the real-mandible
/// CT's BSSO advance a vertex just inside moved 1.30 mm beside one just outside, 1.85 mm away.)
pub(super) fn carry_face(
    e: &SkinEmbedding,
    quadratic: Option<&Tet10Mesh>,
    tets: &[[u32; 4]],
    u: &[[f64; 3]],
    skin: &Mesh,
    roi: Box3,
) -> Vec<[f64; 3]> {
    let mut carried = match quadratic {
        Some(q) => e.carry_quadratic(&q.tets, u),
        None => e.carry(tets, u),
    };
    for (d, still) in carried.iter_mut().zip(still(roi, &skin.vertices)) {
        if still {
            *d = [0.0; 3];
        }
    }
    carried
}

/// The face's positions moved by the carried displacement `d`, as face_post is written.
pub(super) fn displaced(skin: &Mesh, d: &[[f64; 3]]) -> Vec<[f64; 3]> {
    crate::vec3::displaced(&skin.vertices, d)
}

/// Face vertices that stay (`carry_face`'s rule): those outside the region.
pub(super) fn still(roi: Box3, face: &[[f64; 3]]) -> Vec<bool> {
    face.iter()
        .map(|p| (0..3).any(|c| p[c] < roi.0[c] || p[c] > roi.1[c]))
        .collect()
}

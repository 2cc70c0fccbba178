//! Carrying the face: the solved node displacements to the face's vertices through its embedding
//! in the mesh (`tet::embed`), the face outside the region and outside `[surface] movable` kept
//! still.

use super::mesh::Box3;
use crate::mesh::Mesh;
use crate::tet::embed::SkinEmbedding;
use crate::tet::quadratic::Tet10Mesh;

/// How the run's face is carried: its embedding, the rigid skin and the region.
pub(super) struct Carrier<'a> {
    pub(super) embedding: &'a SkinEmbedding,
    pub(super) quadratic: Option<&'a Tet10Mesh>,
    pub(super) tets: &'a [[u32; 4]],
    pub(super) skin: &'a Mesh,
    pub(super) face_rigid: &'a [bool],
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
            self.face_rigid,
            self.roi,
        )
    }
}

/// Node displacements `u` to face displacements; beyond the region's cut faces the tissue is
/// held: face vertices there stay (the extrapolation from the last tetrahedron would move them).
/// Face vertices outside [surface] movable (`face_rigid`) are rigid, as in the C1 model:
/// interpolation between held and free skin nodes would move them by a little.
pub(super) fn carry_face(
    e: &SkinEmbedding,
    quadratic: Option<&Tet10Mesh>,
    tets: &[[u32; 4]],
    u: &[[f64; 3]],
    skin: &Mesh,
    face_rigid: &[bool],
    roi: Box3,
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
pub(super) fn displaced(skin: &Mesh, d: &[[f64; 3]]) -> Vec<[f64; 3]> {
    crate::vec3::displaced(&skin.vertices, d)
}

/// Face vertices that stay (`carry_face`'s rule): rigid skin, or outside the region.
pub(super) fn still(rigid: &[bool], roi: Box3, face: &[[f64; 3]]) -> Vec<bool> {
    rigid
        .iter()
        .zip(face)
        .map(|(r, p)| *r || (0..3).any(|c| p[c] < roi.0[c] || p[c] > roi.1[c]))
        .collect()
}

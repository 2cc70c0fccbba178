//! The face carried by the volume mesh: each face vertex (the extracted skin or a given scan)
//! takes the displacement of the tetrahedron under its nearest point on the mesh's skin
//! boundary, interpolated with that tetrahedron's linear shape functions — extrapolated a little
//! when the vertex lies just outside (the face and the mesh's skin are two discretisations of the
//! same iso-surface, up to half a voxel apart). An affine displacement field (a rigid move, a
//! uniform strain) is therefore carried exactly, inside or out.
//! Face vertices farther than `reach` from the skin boundary (beyond the modelled region, or
//! where a coarse mesh does not reach the scan's edge) are "unreached": they take the linear
//! extrapolation of their nearest skin tetrahedron's corners — at rest when that tetrahedron is
//! held still (the region's cut faces), moving with the head when everything moves (a
//! face vertex must never stay still in a moving head), still exact for affine fields.

use crate::compare::SurfaceIndex;
use crate::mesh::Mesh;
use rayon::prelude::*;

/// The faces of `tets` used by exactly one tetrahedron, each with that tetrahedron and wound
/// so its normal points out of it.
pub(crate) fn boundary_faces(tets: &[[u32; 4]]) -> Vec<(usize, [u32; 3])> {
    // Each face of a positively oriented tet [a, b, c, d], wound outward.
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
    let mut all: Vec<([u32; 3], usize, [u32; 3])> = tets
        .iter()
        .enumerate()
        .flat_map(|(t, tet)| {
            FACES.iter().map(move |f| {
                let face = f.map(|i| tet[i]);
                let mut key = face;
                key.sort_unstable();
                (key, t, face)
            })
        })
        .collect();
    all.par_sort_unstable_by_key(|e| e.0);
    let mut out = Vec::new();
    let mut i = 0;
    while i < all.len() {
        let mut j = i + 1;
        while j < all.len() && all[j].0 == all[i].0 {
            j += 1;
        }
        if j - i == 1 {
            out.push((all[i].1, all[i].2));
        }
        i = j;
    }
    out
}

/// Where each face vertex sits: its tetrahedron and barycentric weights, or None (not searched:
/// at rest).
pub(crate) struct SkinEmbedding {
    pub tet: Vec<Option<u32>>,
    pub weights: Vec<[f64; 4]>,
    /// Distance (mm) from each face vertex to the mesh's skin boundary.
    pub distance: Vec<f64>,
    /// Beyond this distance a vertex is carried by its tetrahedron's corners only.
    reach: f64,
}

/// Barycentric coordinates of `p` in the tetrahedron `x` (Σ λ = 1; negative outside).
pub fn barycentric(x: [[f64; 3]; 4], p: [f64; 3]) -> Option<[f64; 4]> {
    let (_, g) = super::gradients(x)?;
    // λ_a = N_a(p) = ∇N_a · (p − x_3) for a < 3, since N_a(x_3) = 0.
    let d = [0, 1, 2].map(|c| p[c] - x[3][c]);
    let l = [0, 1, 2].map(|a| (0..3).map(|c| g[a][c] * d[c]).sum::<f64>());
    Some([l[0], l[1], l[2], 1.0 - l[0] - l[1] - l[2]])
}

impl SkinEmbedding {
    /// Embed `points` on the boundary faces of the mesh that `on_skin` accepts (faces whose
    /// three nodes lie on the skin); points outside the box `near` (the mesh's region grown by
    /// the reach) are not searched for: they stay.
    pub fn new(
        nodes: &[[f64; 3]],
        tets: &[[u32; 4]],
        on_skin: impl Fn([u32; 3]) -> bool,
        points: &[[f64; 3]],
        reach: f64,
        near: ([f64; 3], [f64; 3]),
    ) -> SkinEmbedding {
        let faces: Vec<(usize, [u32; 3])> = boundary_faces(tets)
            .into_iter()
            .filter(|(_, f)| on_skin(*f))
            .collect();
        let none = || SkinEmbedding {
            tet: vec![None; points.len()],
            weights: vec![[0.0; 4]; points.len()],
            distance: vec![f64::INFINITY; points.len()],
            reach,
        };
        if faces.is_empty() {
            return none();
        }
        let skin = Mesh::new(nodes.to_vec(), faces.iter().map(|f| f.1).collect());
        let index = SurfaceIndex::new(&skin);
        let found: Vec<(Option<u32>, [f64; 4], f64)> = points
            .par_iter()
            .map(|&p| {
                if (0..3).any(|c| p[c] < near.0[c] - reach || p[c] > near.1[c] + reach) {
                    return (None, [0.0; 4], f64::INFINITY);
                }
                let (d, _, f) = index.closest_triangle(p);
                let t = faces[f].0;
                match barycentric(tets[t].map(|n| nodes[n as usize]), p) {
                    Some(w) => (Some(t as u32), w, d),
                    None => (None, [0.0; 4], d),
                }
            })
            .collect();
        SkinEmbedding {
            tet: found.iter().map(|f| f.0).collect(),
            weights: found.iter().map(|f| f.1).collect(),
            distance: found.iter().map(|f| f.2).collect(),
            reach,
        }
    }

    /// Whether vertex `i` lies within reach of the mesh's skin.
    pub(crate) fn reached(&self, i: usize) -> bool {
        self.tet[i].is_some() && self.distance[i] <= self.reach
    }

    /// The displacement at each face vertex for node displacements `u`.
    pub fn carry(&self, tets: &[[u32; 4]], u: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.tet
            .iter()
            .zip(&self.weights)
            .map(|(t, w)| match t {
                None => [0.0; 3],
                Some(t) => weighted(&tets[*t as usize], w, u),
            })
            .collect()
    }

    /// The same for 10-node tetrahedra (`tets10[t]` extends linear tetrahedron t with its edge
    /// midpoints in `quadratic::EDGES` order): N_a = λ_a (2λ_a − 1) at the corners and
    /// 4 λ_a λ_b at the midpoints, so quadratic fields are carried exactly too.
    /// An unreached vertex takes the corners' linear extrapolation: the quadratic shape
    /// functions grow with the square of the distance outside the element.
    pub(crate) fn carry_quadratic(&self, tets10: &[[u32; 10]], u: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.tet
            .iter()
            .zip(&self.weights)
            .enumerate()
            .map(|(i, (t, l))| match t {
                None => [0.0; 3],
                Some(t) if !self.reached(i) => weighted(&tets10[*t as usize][..4], l, u),
                Some(t) => {
                    let tet = tets10[*t as usize];
                    let mut n = [0.0; 10];
                    for a in 0..4 {
                        n[a] = l[a] * (2.0 * l[a] - 1.0);
                    }
                    for (e, [a, b]) in super::quadratic::EDGES.iter().enumerate() {
                        n[4 + e] = 4.0 * l[*a] * l[*b];
                    }
                    weighted(&tet, &n, u)
                }
            })
            .collect()
    }

    /// Face vertices outside the reach of the mesh (carried by extrapolation, or at rest).
    pub(crate) fn unreached(&self) -> usize {
        (0..self.tet.len()).filter(|i| !self.reached(*i)).count()
    }
}

/// Σ_k n_k u[nodes_k]: the displacement interpolated with shape-function values `n`.
fn weighted(nodes: &[u32], n: &[f64], u: &[[f64; 3]]) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        nodes
            .iter()
            .zip(n)
            .map(|(v, w)| w * u[*v as usize][c])
            .sum()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two tetrahedra sharing the face (1, 2, 3).
    fn pair() -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
        let nodes = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ];
        (nodes, vec![[0, 1, 2, 3], [1, 4, 2, 3]])
    }

    #[test]
    fn boundary_faces_are_the_unshared_ones_wound_outwards() {
        let (nodes, tets) = pair();
        assert!(
            tets.iter()
                .all(|t| super::super::gradients(t.map(|n| nodes[n as usize])).is_some())
        );
        let b = boundary_faces(&tets);
        assert_eq!(b.len(), 6);
        for (t, f) in &b {
            let mut s = *f;
            s.sort_unstable();
            assert_ne!(s, [1, 2, 3], "the shared face is interior");
            // Outward: the tet's fourth node lies behind the face.
            let other = tets[*t].iter().find(|n| !f.contains(n)).unwrap();
            let [a, b, c] = f.map(|n| nodes[n as usize]);
            let nrm = crate::vec3::cross(crate::vec3::sub(b, a), crate::vec3::sub(c, a));
            let d = crate::vec3::dot(nrm, crate::vec3::sub(nodes[*other as usize], a));
            assert!(d < 0.0);
        }
    }

    #[test]
    fn affine_fields_are_carried_exactly_inside_and_outside() {
        let (nodes, tets) = pair();
        let affine = |p: [f64; 3]| {
            [
                0.3 + 0.1 * p[0] - 0.2 * p[1] + 0.05 * p[2],
                -0.7 + 0.02 * p[0] + 0.3 * p[2],
                1.1 - 0.4 * p[1],
            ]
        };
        let u: Vec<[f64; 3]> = nodes.iter().map(|p| affine(*p)).collect();
        // Points near the boundary, inside and a little outside.
        let points = [
            [0.2, 0.2, -0.1],
            [0.6, 0.6, 0.6],
            [1.05, 1.0, 1.1],
            [0.1, 0.1, 0.1],
        ];
        let e = SkinEmbedding::new(&nodes, &tets, |_| true, &points, 1.0, ([0.0; 3], [1.0; 3]));
        assert_eq!(e.unreached(), 0);
        for (p, v) in points.iter().zip(e.carry(&tets, &u)) {
            let want = affine(*p);
            for c in 0..3 {
                assert!((v[c] - want[c]).abs() < 1e-12, "{p:?}: {v:?} vs {want:?}");
            }
        }
        // Beyond reach: unreached, carried by extrapolation (exact for an affine field); beyond
        // the searched box: at rest.
        let far = SkinEmbedding::new(
            &nodes,
            &tets,
            |_| true,
            &[[5.0, 5.0, 5.0], [50.0, 5.0, 5.0]],
            1.0,
            ([-9.0; 3], [9.0; 3]),
        );
        assert_eq!(far.unreached(), 2);
        let v = far.carry(&tets, &u);
        let want = affine([5.0, 5.0, 5.0]);
        assert!(
            (0..3).all(|c| (v[0][c] - want[c]).abs() < 1e-12),
            "{v:?} vs {want:?}"
        );
        assert_eq!(v[1], [0.0; 3]);
    }
}

//! The bone surface's normal where tissue slides on it (`conditions::covered_bone`,
//! `conditions::mucosa`): the area-weighted mean of the skull surface's facet normals within a
//! radius, not one facet's or one node's elements'.
//!
//! Why: a sliding node holds only n · u, so an error in n turns a tangential move into a push.
//! The skull surface is a marching iso-surface of the CT at voxel size, faceted in steps; the
//! mean direction from a bone node to its elements' centroids follows the mesh's stencils. Over
//! the bone that lip and cheek cover in the Le Fort I impaction of the real CTs the two differ by
//! a median 17° (ProMED 0051) and 9° (headsq), by more than 40° at a tenth of the nodes, and a
//! 4 mm impaction, tangential to the maxilla's front, pushed the lip and nose up through the
//! tilted ones (docs/lab/validation-notes.md "The bone's normal where tissue slides"). Over a
//! surface that is flat within the radius the mean of the facets' area vectors is exactly its
//! normal (the facets' area vectors sum to the area vector of the patch they tile).

use crate::mesh::Mesh;
use crate::vec3::{add, cross, dot, norm, scale, sub};
use std::collections::HashMap;

/// A facet's centroid and area vector (the cross product of two edges: twice the area, along
/// the normal; wound outwards, out of the bone).
struct Facet {
    centroid: [f64; 3],
    area: [f64; 3],
}

/// The skull surface's facets, bucketed by cells of the radius for the queries.
pub(crate) struct BoneNormals {
    radius: f64,
    cells: HashMap<[i64; 3], Vec<Facet>>,
}

impl BoneNormals {
    /// `surface`'s facets (wound outwards) for normals averaged within `radius` (mm).
    pub(crate) fn new(surface: &Mesh, radius: f64) -> BoneNormals {
        let radius = radius.max(1e-6);
        let mut cells: HashMap<[i64; 3], Vec<Facet>> = HashMap::new();
        for t in &surface.triangles {
            let v = t.map(|i| surface.vertices[i as usize]);
            let c = scale(add(add(v[0], v[1]), v[2]), 1.0 / 3.0);
            let a = cross(sub(v[1], v[0]), sub(v[2], v[0]));
            cells.entry(cell(c, radius)).or_default().push(Facet {
                centroid: c,
                area: a,
            });
        }
        BoneNormals { radius, cells }
    }

    /// The unit mean normal at `p` of the facets within the radius that face the side `toward`
    /// points to (a thin plate's other face, within the radius too, faces away and is left
    /// out). None when no facet does.
    pub(crate) fn at(&self, p: [f64; 3], toward: [f64; 3]) -> Option<[f64; 3]> {
        let g = cell(p, self.radius);
        let mut sum = [0.0; 3];
        for d in 0..27 {
            let key = [g[0] + d % 3 - 1, g[1] + (d / 3) % 3 - 1, g[2] + d / 9 - 1];
            for f in self.cells.get(&key).into_iter().flatten() {
                if norm(sub(f.centroid, p)) <= self.radius && dot(f.area, toward) > 0.0 {
                    sum = add(sum, f.area);
                }
            }
        }
        let l = norm(sum);
        (l > 0.0).then(|| scale(sum, 1.0 / l))
    }
}

fn cell(p: [f64; 3], r: f64) -> [i64; 3] {
    p.map(|x| (x / r).floor() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A staircase of steps 1 mm deep and `rise` high over x ∈ [0, 40] (the voxel facets of a
    /// tilted face, as a marching surface of a CT makes them), in 1 mm tiles: the bone lies
    /// below the treads (facing +z) and behind the risers (facing −y).
    fn staircase(rise: f64) -> Mesh {
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        let mut quad = |q: [[f64; 3]; 4]| {
            let i = vertices.len() as u32;
            vertices.extend(q);
            triangles.push([i, i + 1, i + 2]);
            triangles.push([i, i + 2, i + 3]);
        };
        for s in 0..40 {
            let (y, z) = (s as f64, s as f64 * rise);
            for x in 0..40 {
                let (x0, x1) = (x as f64, x as f64 + 1.0);
                let h = z + rise;
                quad([[x0, y, h], [x1, y, h], [x1, y + 1.0, h], [x0, y + 1.0, h]]);
                quad([[x0, y, z], [x1, y, z], [x1, y, h], [x0, y, h]]);
            }
        }
        Mesh::new(vertices, triangles)
    }

    fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
        (dot(a, b) / (norm(a) * norm(b)))
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }

    #[test]
    fn the_mean_normal_of_a_staircase_is_its_face_and_no_single_facet_is() {
        let rise = 2.0;
        let m = staircase(rise);
        // Treads face +z, risers −y: the face rises 2 mm per mm in +y, so its outward normal is
        // (0, −rise, 1)/|·|.
        let face = scale([0.0, -rise, 1.0], 1.0 / (1.0 + rise * rise).sqrt());
        for t in &m.triangles {
            let v = t.map(|i| m.vertices[i as usize]);
            let a = cross(sub(v[1], v[0]), sub(v[2], v[0]));
            assert!(dot(a, face) > 0.0, "a facet winds inwards");
            assert!(angle_deg(a, face) > 25.0, "a facet is the face");
        }
        let n = BoneNormals::new(&m, 6.0);
        for s in [10, 20, 30] {
            let p = [20.0, s as f64 + 0.5, s as f64 * rise + 1.0];
            let got = n.at(p, face).expect("facets in reach");
            assert!(
                angle_deg(got, face) < 3.0,
                "at step {s}: {got:?}, {:.1}° off the face",
                angle_deg(got, face)
            );
        }
    }

    #[test]
    fn a_thin_plates_other_face_is_left_out() {
        // Two planes 2 mm apart, wound away from each other: bone between them.
        let quad = |z: f64, up: bool| {
            let v = vec![
                [0.0, 0.0, z],
                [10.0, 0.0, z],
                [10.0, 10.0, z],
                [0.0, 10.0, z],
            ];
            let t = if up {
                vec![[0, 1, 2], [0, 2, 3]]
            } else {
                vec![[0, 2, 1], [0, 3, 2]]
            };
            (v, t)
        };
        let (mut v, mut t) = quad(1.0, true);
        let (v2, t2) = quad(-1.0, false);
        t.extend(t2.iter().map(|f| f.map(|i| i + 4)));
        v.extend(v2);
        let n = BoneNormals::new(&Mesh::new(v, t), 4.0);
        let up = n.at([5.0, 5.0, 1.0], [0.0, 0.0, 1.0]).unwrap();
        let down = n.at([5.0, 5.0, -1.0], [0.0, 0.0, -1.0]).unwrap();
        assert!(angle_deg(up, [0.0, 0.0, 1.0]) < 1e-9, "{up:?}");
        assert!(angle_deg(down, [0.0, 0.0, -1.0]) < 1e-9, "{down:?}");
        assert!(n.at([50.0, 50.0, 0.0], [0.0, 0.0, 1.0]).is_none());
    }
}

//! Marching tetrahedra: the marching-cubes family's general iso-surface extractor, used when a
//! surface is not a cylindrical range image. Each cube is split into the six tetrahedra of the
//! Kuhn decomposition around its main diagonal; that split is the same in every cube, so
//! faces match and the surface is watertight and manifold without marching cubes' ambiguous
//! cases or its 256-entry tables. Vertices on shared edges are welded through an edge map.

use crate::mesh::Mesh;
use crate::vec3::{cross, dot, sub};
use crate::volume::Volume;
use std::collections::HashMap;

/// Cube corner offsets, bit 0 = +i, bit 1 = +j, bit 2 = +k.
const CORNER: [[usize; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [0, 1, 0],
    [1, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [0, 1, 1],
    [1, 1, 1],
];
/// Kuhn tetrahedra: paths 0 → 7 through the cube's corners (corner bit 0 = +i, 1 = +j, 2 = +k;
/// also the volumetric FEM's split in `study::volumetric`).
pub const TETS: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 1, 5, 7],
    [0, 2, 3, 7],
    [0, 2, 6, 7],
    [0, 4, 5, 7],
    [0, 4, 6, 7],
];

/// Iso-surface {field = iso} enclosing the region field > iso, triangles wound outwards.
pub fn extract(vol: &Volume, field: &[f32], iso: f32) -> Mesh {
    let [nx, ny, nz] = vol.dims;
    let id = |c: [usize; 3]| c[0] + nx * (c[1] + ny * c[2]);
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    let mut verts: Vec<[f64; 3]> = Vec::new();
    let mut tris: Vec<[u32; 3]> = Vec::new();
    let mut vertex_on = |a: usize, b: usize, verts: &mut Vec<[f64; 3]>| -> u32 {
        let key = (a.min(b), a.max(b));
        *edge_vertex.entry(key).or_insert_with(|| {
            let (fa, fb) = (field[a], field[b]);
            // Clamp away from the corners so no two edge vertices coincide (no zero-area faces).
            let t = (((iso - fa) / (fb - fa)) as f64).clamp(1e-3, 1.0 - 1e-3);
            let pa = vol.to_world(vol.ijk(a).map(|x| x as f64));
            let pb = vol.to_world(vol.ijk(b).map(|x| x as f64));
            verts.push([
                pa[0] + t * (pb[0] - pa[0]),
                pa[1] + t * (pb[1] - pa[1]),
                pa[2] + t * (pb[2] - pa[2]),
            ]);
            (verts.len() - 1) as u32
        })
    };
    for k in 0..nz.saturating_sub(1) {
        for j in 0..ny.saturating_sub(1) {
            for i in 0..nx.saturating_sub(1) {
                let c: [usize; 8] = CORNER.map(|o| id([i + o[0], j + o[1], k + o[2]]));
                let inside = c.map(|x| field[x] > iso);
                if inside.iter().all(|&b| b) || inside.iter().all(|&b| !b) {
                    continue;
                }
                for tet in TETS {
                    let v = tet.map(|t| c[t]);
                    let ins: Vec<usize> = v.iter().cloned().filter(|&x| field[x] > iso).collect();
                    let out: Vec<usize> = v.iter().cloned().filter(|&x| field[x] <= iso).collect();
                    let emit = |a: u32,
                                b: u32,
                                cc: u32,
                                from: usize,
                                to: usize,
                                verts: &mut Vec<[f64; 3]>,
                                tris: &mut Vec<[u32; 3]>| {
                        // Orient the triangle's normal from inside (`from`) to outside (`to`).
                        let (pa, pb, pc) =
                            (verts[a as usize], verts[b as usize], verts[cc as usize]);
                        let n = cross(sub(pb, pa), sub(pc, pa));
                        let g = sub(
                            vol.to_world(vol.ijk(to).map(|x| x as f64)),
                            vol.to_world(vol.ijk(from).map(|x| x as f64)),
                        );
                        if dot(n, g) >= 0.0 {
                            tris.push([a, b, cc])
                        } else {
                            tris.push([a, cc, b])
                        }
                    };
                    match ins.len() {
                        1 | 3 => {
                            let (apex, others, from, to) = if ins.len() == 1 {
                                (ins[0], out.clone(), ins[0], out[0])
                            } else {
                                (out[0], ins.clone(), ins[0], out[0])
                            };
                            let e: Vec<u32> = others
                                .iter()
                                .map(|&o| vertex_on(apex, o, &mut verts))
                                .collect();
                            emit(e[0], e[1], e[2], from, to, &mut verts, &mut tris);
                        }
                        2 => {
                            let (a, b, cc, d) = (
                                vertex_on(ins[0], out[0], &mut verts),
                                vertex_on(ins[0], out[1], &mut verts),
                                vertex_on(ins[1], out[1], &mut verts),
                                vertex_on(ins[1], out[0], &mut verts),
                            );
                            emit(a, b, cc, ins[0], out[0], &mut verts, &mut tris);
                            emit(a, cc, d, ins[0], out[0], &mut verts, &mut tris);
                        }
                        _ => {}
                    }
                }
            }
        }
    }
    Mesh::new(verts, tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_is_closed_manifold_with_right_area() {
        let n = 40;
        let vol = Volume {
            dims: [n, n, n],
            spacing: [1.0; 3],
            origin: [-19.5; 3],
            direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            data: vec![0.0; n * n * n],
        };
        let r = 12.0;
        let field: Vec<f32> = (0..n * n * n)
            .map(|a| {
                let p = vol.to_world(vol.ijk(a).map(|x| x as f64));
                (r - (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()) as f32
            })
            .collect();
        let m = extract(&vol, &field, 0.0);
        let stats = m.check(std::path::Path::new("sphere")).unwrap();
        assert_eq!(stats.boundary_edges, 0, "closed surface");
        let area = m.area();
        let exact = 4.0 * std::f64::consts::PI * r * r;
        assert!((area / exact - 1.0).abs() < 0.08, "area {area} vs {exact}");
        // Outward orientation: the signed volume is positive.
        let vol6: f64 = m
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.vertices[i as usize]);
                dot(a, cross(b, c))
            })
            .sum();
        assert!((vol6 / 6.0 / (4.0 / 3.0 * std::f64::consts::PI * r.powi(3)) - 1.0).abs() < 0.03);
    }
}

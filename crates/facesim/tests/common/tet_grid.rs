//! Structured tetrahedral meshes for tests (tet_linear here; the lab's CalculiX cross-check
//! includes this file by `#[path]`): Kuhn tetrahedra on grids, a sheared two-material cube.
#![allow(dead_code)]

use facesim::tet::{TetMesh, TissueElastic};

/// The six Kuhn tetrahedra of the grid cell whose lowest corner has indices `c` (the paths from
/// that corner to the opposite one along the three axes in each order), each with positive
/// volume; `id` numbers grid nodes. Neighbouring cells share their face diagonals: conforming.
pub fn kuhn_cell(
    c: [usize; 3],
    id: &dyn Fn(usize, usize, usize) -> u32,
    nodes: &[[f64; 3]],
) -> Vec<[u32; 4]> {
    const PATHS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    PATHS
        .iter()
        .map(|p| {
            let mut at = c;
            let mut t = [id(c[0], c[1], c[2]); 4];
            for (s, axis) in p.iter().enumerate() {
                at[*axis] += 1;
                t[s + 1] = id(at[0], at[1], at[2]);
            }
            if facesim::tet::gradients(t.map(|v| nodes[v as usize])).is_none() {
                t.swap(2, 3);
            }
            t
        })
        .collect()
}

/// An n×n×n grid of cubes of side h, each split into the six Kuhn tetrahedra around its main
/// diagonal; materials alternate between two tissues by cube (a checkerboard).
pub fn cube(n: usize, h: f64, soft: TissueElastic, stiff: TissueElastic) -> TetMesh {
    let id = |i: usize, j: usize, k: usize| ((k * (n + 1) + j) * (n + 1) + i) as u32;
    let mut nodes = Vec::new();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                // A gentle shear of the grid, so no element is axis-aligned.
                let (x, y, z) = (i as f64 * h, j as f64 * h, k as f64 * h);
                nodes.push([x + 0.1 * y, y + 0.05 * z, z]);
            }
        }
    }
    let mut tets = Vec::new();
    let mut material = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                for t in kuhn_cell([i, j, k], &id, &nodes) {
                    tets.push(t);
                    material.push(if (i + j + k) % 2 == 0 { soft } else { stiff });
                }
            }
        }
    }
    TetMesh {
        nodes,
        tets,
        material,
    }
}

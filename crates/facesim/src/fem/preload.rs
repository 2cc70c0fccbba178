//! Preloading (Koch §4.3; docs/design/fem.md, "Preloading") and sampling the C1 surface (Koch Fig. 12).
//!
//! a_init: corner values are the mesh vertices; corner gradients and edge cross-boundary
//! derivatives come from least-squares quadratic fits in (u, v) over the neighbourhood, so a
//! planar or quadratic surface is reproduced exactly (the paper's eq. 18 gives only unit
//! directions). F_init = K a_init (eq. 17) makes the pre-operative face an equilibrium.

use super::assembly::FemMesh;
use super::element::edge_normal;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::collections::HashMap;

/// Least-squares fit of c0 + c1 du + c2 dv + c3 du² + c4 du dv + c5 dv² (du, dv from `at`,
/// scaled by h) to the values `ys[f][i]` of each field f at the points `uv[i]`; with `value`
/// given (one per field), c0 is fixed to it. One solve with the design matrix serves every field.
/// Returns (value, ∂u, ∂v) at `at` per field, or None when the points cannot determine a
/// quadratic.
fn fit(
    uv: &[[f64; 2]],
    ys: &[Vec<f64>],
    at: [f64; 2],
    value: Option<&[f64]>,
) -> Option<Vec<[f64; 3]>> {
    let h = uv
        .iter()
        .map(|p| ((p[0] - at[0]).powi(2) + (p[1] - at[1]).powi(2)).sqrt())
        .fold(0.0, f64::max);
    if h == 0.0 {
        return None;
    }
    let cols = if value.is_some() { 5 } else { 6 };
    if uv.len() < cols {
        return None;
    }
    let nf = ys.len();
    let skip = usize::from(value.is_some());
    let row = |r: usize| {
        let p = uv[r];
        let (x1, x2) = ((p[0] - at[0]) / h, (p[1] - at[1]) / h);
        [1.0, x1, x2, x1 * x1, x1 * x2, x2 * x2]
    };
    let rhs = |r: usize, f: usize| ys[f][r] - value.map_or(0.0, |v| v[f]);
    let c = normal_equations(uv.len(), cols, skip, nf, &row, &rhs).or_else(|| {
        // Poorly conditioned neighbourhoods: the SVD, which also tells a rank-deficient one.
        let mut a = DMatrix::<f64>::zeros(uv.len(), cols);
        let mut b = DMatrix::<f64>::zeros(uv.len(), nf);
        for r in 0..uv.len() {
            let w = row(r);
            for c in 0..cols {
                a[(r, c)] = w[c + skip];
            }
            for f in 0..nf {
                b[(r, f)] = rhs(r, f);
            }
        }
        let svd = a.svd(true, true);
        let sv = &svd.singular_values;
        if sv.min() <= 1e-9 * sv.max() {
            return None;
        }
        let c = svd.solve(&b, 1e-12).ok()?;
        Some((0..nf).map(|f| [c[(0, f)], c[(1, f)], c[(2, f)]]).collect())
    })?;
    Some(
        (0..nf)
            .map(|f| match value {
                Some(v) => [v[f], c[f][0] / h, c[f][1] / h],
                None => [c[f][0], c[f][1] / h, c[f][2] / h],
            })
            .collect(),
    )
}

/// The first three least-squares coefficients per field from the normal equations AᵀA c = Aᵀb
/// (A: rows `row(r)[skip..skip + cols]`), on the stack: most fits are well conditioned, and
/// this avoids the SVD's heap matrices. None when AᵀA's condition number exceeds 1e6 (A's
/// exceeds 1e3, where squaring it would cost accuracy): the caller then uses the SVD.
fn normal_equations(
    rows: usize,
    cols: usize,
    skip: usize,
    nf: usize,
    row: &dyn Fn(usize) -> [f64; 6],
    rhs: &dyn Fn(usize, usize) -> f64,
) -> Option<Vec<[f64; 3]>> {
    if nf > 3 {
        return None;
    }
    let mut m = nalgebra::Matrix6::<f64>::zeros();
    let mut b = nalgebra::Matrix6x3::<f64>::zeros();
    for r in 0..rows {
        let w = row(r);
        for i in 0..cols {
            for j in 0..=i {
                m[(i, j)] += w[i + skip] * w[j + skip];
            }
            for f in 0..nf {
                b[(i, f)] += w[i + skip] * rhs(r, f);
            }
        }
    }
    // An unused sixth unknown (value given) gets an identity row so the 6×6 system stays
    // regular.
    for i in cols..6 {
        m[(i, i)] = 1.0;
    }
    for i in 0..6 {
        for j in 0..i {
            m[(j, i)] = m[(i, j)];
        }
    }
    // (The identity row adds the eigenvalue 1, inside the used block's range: its largest
    // eigenvalue is at least ½ since the farthest point has x1² + x2² = 1.)
    let ev = nalgebra::SymmetricEigen::new(m).eigenvalues;
    let (lo, hi) = ev.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &x| {
        (a.min(x), b.max(x.abs()))
    });
    if !(lo > 1e-6 * hi) {
        return None;
    }
    let c = m.cholesky()?.solve(&b);
    Some((0..nf).map(|f| [c[(0, f)], c[(1, f)], c[(2, f)]]).collect())
}

/// Initial DOFs for one coordinate field given at the vertices.
pub fn initial_dofs(mesh: &FemMesh, values: &[f64]) -> Result<Vec<f64>> {
    Ok(initial_dofs_fields(mesh, &[values])?.remove(0))
}

/// Initial DOFs for several fields over the same mesh (x, y, z of the skin): the fits share
/// their neighbourhoods and design matrices, so three fields cost one least-squares solve per fit.
pub(crate) fn initial_dofs_fields(mesh: &FemMesh, fields: &[&[f64]]) -> Result<Vec<Vec<f64>>> {
    let nb = crate::mesh::one_rings(mesh.uv.len(), &mesh.tris);
    let nv = mesh.uv.len();
    let nf = fields.len();
    // Neighbourhood: the 1-ring, widened ring by ring (up to the 3-ring) while it cannot fix a
    // quadratic (decimated meshes have low-valence vertices whose 1-ring is degenerate in (u, v)).
    let hood = |seed: &[u32], rings: usize| -> Vec<u32> {
        let mut s: Vec<u32> = seed.to_vec();
        for _ in 0..rings {
            let frontier = s.clone();
            for &v in &frontier {
                s.extend(&nb[v as usize]);
            }
            s.sort_unstable();
            s.dedup();
        }
        s
    };
    let gradient = |seed: &[u32], at: [f64; 2], value: Option<&[f64]>| -> Option<Vec<[f64; 3]>> {
        for rings in 1..=3 {
            let h = hood(seed, rings);
            let uv: Vec<[f64; 2]> = h.iter().map(|&v| mesh.uv[v as usize]).collect();
            let ys: Vec<Vec<f64>> = fields
                .iter()
                .map(|f| h.iter().map(|&v| f[v as usize]).collect())
                .collect();
            if let Some(g) = fit(&uv, &ys, at, value) {
                return Some(g);
            }
        }
        None
    };
    // Every fit is independent: in parallel (results land by index, so they are the same for
    // any thread count).
    let corner: Vec<Vec<[f64; 3]>> = (0..nv)
        .into_par_iter()
        .map(|v| {
            let vals: Vec<f64> = fields.iter().map(|f| f[v]).collect();
            gradient(&[v as u32], mesh.uv[v], Some(&vals)).ok_or_else(|| {
                Error::surface(format!(
                    "preloading: vertex {v} has too few neighbours to fit its tangent plane"
                ))
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let cross: Vec<Vec<f64>> = mesh
        .edges
        .par_iter()
        .enumerate()
        .map(|(e, ed)| {
            let (p, q) = (mesh.uv[ed[0] as usize], mesh.uv[ed[1] as usize]);
            let mid = [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])];
            let g = gradient(&[ed[0], ed[1]], mid, None).ok_or_else(|| {
                Error::surface(format!(
                    "preloading: edge {e} has too few neighbours for a fit"
                ))
            })?;
            let n = edge_normal(p, q);
            Ok(g.iter().map(|g| g[1] * n[0] + g[2] * n[1]).collect())
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((0..nf)
        .map(|f| {
            let dofs = mesh.dofs();
            let mut a = vec![0.0; dofs.ndof()];
            for (v, g) in corner.iter().enumerate() {
                a[dofs.vertex(v)].copy_from_slice(&[fields[f][v], g[f][1], g[f][2]]);
            }
            for (e, c) in cross.iter().enumerate() {
                a[dofs.edge(e)] = c[f];
            }
            a
        })
        .collect())
}

/// Sample the C1 surface (DOFs for x, y, z) on each triangle split into `level`² triangles,
/// sharing vertices along edges (Koch Fig. 12). `level` = 1 gives the input mesh's vertices.
pub fn sample(mesh: &FemMesh, a: &[Vec<f64>; 3], level: usize) -> Mesh {
    let level = level.max(1);
    // Vertex key: corner (vertex id), edge point (edge id, steps from its lower vertex), or
    // interior (triangle, i, j).
    #[derive(Hash, PartialEq, Eq)]
    enum Key {
        Corner(u32),
        Edge(u32, usize),
        Inner(usize, usize, usize),
    }
    let mut ids: HashMap<Key, u32> = HashMap::new();
    let mut verts: Vec<[f64; 3]> = Vec::new();
    let mut tris = Vec::new();
    for (t, tri) in mesh.tris.iter().enumerate() {
        let mut local = vec![vec![0u32; level + 1]; level + 1];
        for j in 0..=level {
            for i in 0..=(level - j) {
                let k = level - i - j; // weight of corner 0
                let key = if i == 0 && j == 0 {
                    Key::Corner(tri[0])
                } else if i == level {
                    Key::Corner(tri[1])
                } else if j == level {
                    Key::Corner(tri[2])
                } else if j == 0 {
                    edge_key(mesh, t, 0, i, level)
                } else if k == 0 {
                    edge_key(mesh, t, 1, j, level)
                } else if i == 0 {
                    edge_key(mesh, t, 2, k, level)
                } else {
                    Key::Inner(t, i, j)
                };
                let id = *ids.entry(key).or_insert_with(|| {
                    let (xi, eta) = (i as f64 / level as f64, j as f64 / level as f64);
                    let p = [0, 1, 2].map(|c| mesh.eval(&a[c], t, xi, eta)[0]);
                    verts.push(p);
                    (verts.len() - 1) as u32
                });
                local[j][i] = id;
            }
        }
        for j in 0..level {
            for i in 0..(level - j) {
                tris.push([local[j][i], local[j][i + 1], local[j + 1][i]]);
                if i + j + 1 < level {
                    tris.push([local[j][i + 1], local[j + 1][i + 1], local[j + 1][i]]);
                }
            }
        }
    }
    fn edge_key(mesh: &FemMesh, t: usize, e: usize, step: usize, level: usize) -> Key {
        // `step` counts from local corner e towards corner e+1; re-count from the edge's lower vertex.
        let tri = mesh.tris[t];
        let id = mesh.tri_edges[t][e];
        let from_low = if tri[e] < tri[(e + 1) % 3] {
            step
        } else {
            level - step
        };
        Key::Edge(id, from_low)
    }
    Mesh::new(verts, tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Least squares by SVD, the reference for the normal-equation path.
    fn svd_coefficients(rows: &[[f64; 6]], cols: usize, skip: usize, b: &[f64]) -> Vec<f64> {
        let a = DMatrix::from_fn(rows.len(), cols, |r, c| rows[r][c + skip]);
        let b = DMatrix::from_fn(rows.len(), 1, |r, _| b[r]);
        let c = a.svd(true, true).solve(&b, 1e-14).unwrap();
        (0..3).map(|i| c[(i, 0)]).collect()
    }

    #[test]
    fn normal_equations_agree_with_the_svd_and_refuse_degenerate_points() {
        // A ring of 9 points around the origin (scaled to the unit disc), noisy values.
        let pts: Vec<[f64; 2]> = (0..9)
            .map(|i| {
                let t = i as f64 * 0.7 + 0.3;
                let r = 0.4 + 0.6 * ((i * 5 % 9) as f64 / 8.0);
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        let row = |p: [f64; 2]| [1.0, p[0], p[1], p[0] * p[0], p[0] * p[1], p[1] * p[1]];
        let rows: Vec<[f64; 6]> = pts.iter().map(|&p| row(p)).collect();
        let b: Vec<f64> = (0..9).map(|i| ((i * 7 % 5) as f64 - 2.0) * 0.3).collect();
        for (cols, skip) in [(6, 0), (5, 1)] {
            let c = normal_equations(9, cols, skip, 1, &|r| rows[r], &|r, _| b[r]).unwrap();
            let reference = svd_coefficients(&rows, cols, skip, &b);
            for i in 0..3 {
                assert!(
                    (c[0][i] - reference[i]).abs() < 1e-10,
                    "{cols}: {c:?} vs {reference:?}"
                );
            }
        }
        // Points on a line cannot fix a quadratic in two variables.
        let line: Vec<[f64; 6]> = (0..9)
            .map(|i| row([i as f64 / 8.0, 0.5 * i as f64 / 8.0]))
            .collect();
        assert!(normal_equations(9, 6, 0, 1, &|r| line[r], &|r, _| b[r]).is_none());
    }
}

//! Skin and skull surfaces (docs/design/pipeline.md §2): the range scan (with its (u, v)
//! parameterisation) or marching tetrahedra, then optional Taubin smoothing and adaptive
//! decimation; a given face scan replaces the extracted skin after landmark registration.

pub mod marching;
pub mod outer;
pub mod rangescan;
pub(crate) mod register;

use crate::mesh::{Column, Mesh};
use rayon::prelude::*;

/// Taubin λ|μ low-pass smoothing (Taubin 1995): a shrink step λ = 0.5 and an inflate step
/// μ = −0.53 per iteration, umbrella Laplacian; boundary vertices stay fixed.
pub(crate) fn taubin_smooth(mesh: &mut Mesh, iterations: usize) {
    if iterations == 0 {
        return;
    }
    let nb = mesh.neighbours();
    let mut on_boundary = vec![false; mesh.vertices.len()];
    let mut edge_count: std::collections::HashMap<(u32, u32), u32> =
        std::collections::HashMap::new();
    for t in &mesh.triangles {
        for e in 0..3 {
            let (a, b) = (t[e].min(t[(e + 1) % 3]), t[e].max(t[(e + 1) % 3]));
            *edge_count.entry((a, b)).or_default() += 1;
        }
    }
    for ((a, b), n) in edge_count {
        if n == 1 {
            on_boundary[a as usize] = true;
            on_boundary[b as usize] = true;
        }
    }
    for _ in 0..iterations {
        for f in [0.5, -0.53] {
            let old = mesh.vertices.clone();
            for (i, v) in mesh.vertices.iter_mut().enumerate() {
                if on_boundary[i] || nb[i].is_empty() {
                    continue;
                }
                let mut c = [0.0; 3];
                for &j in &nb[i] {
                    for a in 0..3 {
                        c[a] += old[j as usize][a];
                    }
                }
                for a in 0..3 {
                    v[a] += f * (c[a] / nb[i].len() as f64 - old[i][a]);
                }
            }
        }
    }
}

/// Adaptive decimation by quadric edge collapse (meshoptimizer's simplifier), to at most
/// `target` triangles while the geometric error stays below `max_error` mm. Borders are locked
/// so the mesh keeps its outline. Returns the error reached (mm).
pub(crate) fn decimate(mesh: &mut Mesh, target: usize, max_error: f64) -> f64 {
    if target == 0 || mesh.triangles.len() <= target {
        return 0.0;
    }
    let pos: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| v.map(|x| x as f32)).collect();
    let bytes: &[u8] = bytemuck::cast_slice(&pos);
    let Ok(adapter) = meshopt::VertexDataAdapter::new(bytes, 12, 0) else {
        return 0.0;
    };
    let idx: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let mut err = 0f32;
    let out = meshopt::simplify(
        &idx,
        &adapter,
        target * 3,
        max_error as f32,
        meshopt::SimplifyOptions::LockBorder | meshopt::SimplifyOptions::ErrorAbsolute,
        Some(&mut err),
    );
    mesh.triangles = out.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    mesh.compact();
    flip_slivers(mesh);
    err as f64
}

/// Triangles whose (u, v) orientation disagrees with the majority (a fold of the map).
pub(crate) fn uv_folds(m: &Mesh) -> usize {
    let (Some(u), Some(v)) = (m.column("u"), m.column("v")) else {
        return 0;
    };
    let pos = m
        .triangles
        .iter()
        .filter(|t| {
            let [a, b, c] = t.map(|i| i as usize);
            (u[b] - u[a]) * (v[c] - v[a]) - (u[c] - u[a]) * (v[b] - v[a]) > 0.0
        })
        .count();
    pos.min(m.triangles.len() - pos)
}

/// A copy of `mesh` decimated to about `target` triangles that the C1 FEM can use: manifold,
/// and with an unfolded (u, v) map (set by `uv`). Edge collapse can fold the map at a few
/// triangles, so the target backs off (×5/4, up to 6 times) until it does not. None when no
/// attempt succeeds (dense scans fold at every target; `resample_uv` cannot fold).
pub fn decimate_unfolded(mesh: &Mesh, target: usize, uv: impl Fn(&mut Mesh)) -> Option<Mesh> {
    let mut target = target;
    for _ in 0..6 {
        let mut m = mesh.clone();
        decimate(&mut m, target, 5.0);
        uv(&mut m);
        if m.check(std::path::Path::new("decimated skin")).is_ok() && uv_folds(&m) == 0 {
            return Some(m);
        }
        target = target * 5 / 4;
    }
    None
}

/// A coarse copy of a skin with (u, v) columns: a regular grid in (u, v) of about `target`
/// triangles, each node placed on the skin by barycentric interpolation in the skin triangle
/// containing it in (u, v). Edge-collapse decimation folds the (u, v) map of dense scans (a
/// 158 k-triangle phantom scan folded at 33–91 triangles for every target from 20 k to 61 k); a
/// grid in the parameter domain cannot fold. Cells with a node outside the skin's (u, v) domain
/// are dropped, and only the largest connected piece is kept. None without u, v columns or when
/// nothing is left.
pub(crate) fn resample_uv(mesh: &Mesh, target: usize) -> Option<Mesh> {
    let (u, v) = (mesh.column("u")?, mesh.column("v")?);
    let uv = |i: u32| [u[i as usize], v[i as usize]];
    let signed = |t: &[u32; 3]| {
        let [a, b, c] = t.map(uv);
        0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
    };
    let total: f64 = mesh.triangles.iter().map(&signed).sum();
    let area: f64 = mesh.triangles.iter().map(|t| signed(t).abs()).sum();
    if area <= 0.0 || target == 0 {
        return None;
    }
    let grid = UvGrid::new(u, v, (2.0 * area / target as f64).sqrt());
    let buckets = grid.buckets(mesh, u, v);
    let nodes = grid.place_nodes(mesh, u, v, &buckets);
    // Same (u, v) orientation as the skin, hence the same 3-D orientation.
    let tris = grid.triangles(&nodes, !(total >= 0.0));
    let vertices: Vec<[f64; 3]> = nodes.iter().map(|p| p.unwrap_or([0.0; 3])).collect();
    let mut m = Mesh::new(vertices, tris);
    let count = grid.n[0] * grid.n[1];
    set_uv(
        &mut m,
        (0..count).map(|k| grid.node(k)[0]).collect(),
        (0..count).map(|k| grid.node(k)[1]).collect(),
    );
    keep_largest_piece(&mut m);
    m.compact();
    (!m.triangles.is_empty()).then_some(m)
}

/// The regular grid of `resample_uv`: nodes lo + (i, j)·step, n[0] × n[1] of them, numbered
/// k = j·n[0] + i.
struct UvGrid {
    lo: [f64; 2],
    step: f64,
    n: [usize; 2],
}

impl UvGrid {
    /// The grid over the (u, v) bounding box.
    fn new(u: &[f64], v: &[f64], step: f64) -> UvGrid {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for i in 0..u.len() {
            for (a, x) in [u[i], v[i]].into_iter().enumerate() {
                lo[a] = lo[a].min(x);
                hi[a] = hi[a].max(x);
            }
        }
        let n = [0, 1].map(|a| ((hi[a] - lo[a]) / step).floor() as usize + 1);
        UvGrid { lo, step, n }
    }

    /// The (u, v) of node k.
    fn node(&self, k: usize) -> [f64; 2] {
        [
            self.lo[0] + (k % self.n[0]) as f64 * self.step,
            self.lo[1] + (k / self.n[0]) as f64 * self.step,
        ]
    }

    /// The cell holding `p`, clamped to the grid.
    fn cell(&self, p: [f64; 2]) -> [usize; 2] {
        [0, 1].map(|a| {
            (((p[a] - self.lo[a]) / self.step).floor().max(0.0) as usize).min(self.n[a] - 1)
        })
    }

    /// The skin's triangles by the grid cells their (u, v) boxes overlap.
    fn buckets(&self, mesh: &Mesh, u: &[f64], v: &[f64]) -> Vec<Vec<u32>> {
        let uv = |i: u32| [u[i as usize], v[i as usize]];
        let n = self.n;
        let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); n[0] * n[1]];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let p = tri.map(uv);
            let a = self.cell([
                p[0][0].min(p[1][0]).min(p[2][0]),
                p[0][1].min(p[1][1]).min(p[2][1]),
            ]);
            let b = self.cell([
                p[0][0].max(p[1][0]).max(p[2][0]),
                p[0][1].max(p[1][1]).max(p[2][1]),
            ]);
            for j in a[1]..=b[1] {
                for i in a[0]..=b[0] {
                    buckets[j * n[0] + i].push(t as u32);
                }
            }
        }
        buckets
    }

    /// Each grid node placed on the skin by barycentric interpolation in the first skin
    /// triangle of its cell that contains it in (u, v); None outside the skin's domain.
    fn place_nodes(
        &self,
        mesh: &Mesh,
        u: &[f64],
        v: &[f64],
        buckets: &[Vec<u32>],
    ) -> Vec<Option<[f64; 3]>> {
        let uv = |i: u32| [u[i as usize], v[i as usize]];
        let n = self.n;
        (0..n[0] * n[1])
            .into_par_iter()
            .map(|k| {
                let q = self.node(k);
                let c = self.cell(q);
                buckets[c[1] * n[0] + c[0]].iter().find_map(|&t| {
                    let tri = mesh.triangles[t as usize];
                    let [a, b, cc] = tri.map(uv);
                    let det = (b[0] - a[0]) * (cc[1] - a[1]) - (cc[0] - a[0]) * (b[1] - a[1]);
                    if det == 0.0 {
                        return None;
                    }
                    let l1 =
                        ((q[0] - a[0]) * (cc[1] - a[1]) - (cc[0] - a[0]) * (q[1] - a[1])) / det;
                    let l2 = ((b[0] - a[0]) * (q[1] - a[1]) - (q[0] - a[0]) * (b[1] - a[1])) / det;
                    let l0 = 1.0 - l1 - l2;
                    let eps = -1e-9;
                    (l0 >= eps && l1 >= eps && l2 >= eps).then(|| {
                        let [x, y, z] = tri.map(|i| mesh.vertices[i as usize]);
                        [0, 1, 2].map(|c| l0 * x[c] + l1 * y[c] + l2 * z[c])
                    })
                })
            })
            .collect()
    }

    /// Two triangles per cell, each kept when its three nodes are placed; wound (a, b, c), or
    /// (a, c, b) when `flip`.
    fn triangles(&self, nodes: &[Option<[f64; 3]>], flip: bool) -> Vec<[u32; 3]> {
        let n = self.n;
        let id = |i: usize, j: usize| (j * n[0] + i) as u32;
        let mut tris = Vec::new();
        for j in 0..n[1].saturating_sub(1) {
            for i in 0..n[0] - 1 {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                for t in [[a, b, c], [a, c, d]] {
                    if t.iter().all(|&k| nodes[k as usize].is_some()) {
                        tris.push(if flip { [t[0], t[2], t[1]] } else { t });
                    }
                }
            }
        }
        tris
    }
}

/// Keep only the triangles of the mesh's largest connected piece (of equal pieces the last in
/// `Mesh::components` order).
fn keep_largest_piece(m: &mut Mesh) {
    let (comp, count) = m.components();
    if count > 1 {
        let mut size = vec![0usize; count];
        for &c in &comp {
            size[c as usize] += 1;
        }
        let best = (0..count).max_by_key(|&c| size[c]).unwrap_or(0) as u32;
        let tris = std::mem::take(&mut m.triangles);
        m.triangles = tris
            .into_iter()
            .zip(&comp)
            .filter(|(_, c)| **c == best)
            .map(|(t, _)| t)
            .collect();
    }
}

/// Remove zero-area slivers (the collapse can leave a vertex on its neighbour's edge) by
/// flipping each sliver's longest edge: for sliver (a, b, c) with c on ab and neighbour
/// (b, a, d), the quad a→d→b→c becomes (a, d, c) and (d, b, c). Returns the flips made.
pub(crate) fn flip_slivers(mesh: &mut Mesh) -> usize {
    use crate::vec3::{cross, norm, sub};
    let diag = mesh.diagonal();
    let tiny = 1e-12 * diag * diag; // the same bound as Mesh::check
    let mut flips = 0;
    for _pass in 0..4 {
        let mut edge_owner: std::collections::HashMap<(u32, u32), usize> =
            std::collections::HashMap::new();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for e in 0..3 {
                edge_owner.insert((tri[e], tri[(e + 1) % 3]), t);
            }
        }
        let mut changed = false;
        for t in 0..mesh.triangles.len() {
            let tri = mesh.triangles[t];
            let p = tri.map(|i| mesh.vertices[i as usize]);
            if norm(cross(sub(p[1], p[0]), sub(p[2], p[0]))) > tiny {
                continue;
            }
            // Longest edge (a → b), opposite vertex c.
            let e = (0..3)
                .max_by(|&i, &j| {
                    norm(sub(p[(i + 1) % 3], p[i])).total_cmp(&norm(sub(p[(j + 1) % 3], p[j])))
                })
                .unwrap_or(0);
            let (a, b, c) = (tri[e], tri[(e + 1) % 3], tri[(e + 2) % 3]);
            let Some(&n) = edge_owner.get(&(b, a)) else {
                continue;
            };
            let nt = mesh.triangles[n];
            let Some(&d) = nt.iter().find(|&&v| v != a && v != b) else {
                continue;
            };
            if d == c || edge_owner.contains_key(&(c, d)) || edge_owner.contains_key(&(d, c)) {
                continue;
            }
            mesh.triangles[t] = [a, d, c];
            mesh.triangles[n] = [d, b, c];
            for (tt, tri) in [(t, [a, d, c]), (n, [d, b, c])] {
                for k in 0..3 {
                    edge_owner.insert((tri[k], tri[(k + 1) % 3]), tt);
                }
            }
            edge_owner.remove(&(a, b));
            edge_owner.remove(&(b, a));
            flips += 1;
            changed = true;
        }
        if !changed {
            break;
        }
    }
    flips
}

/// Replace the mesh's `u`, `v` vertex columns (the FEM's parameter coordinates).
fn set_uv(mesh: &mut Mesh, u: Vec<f64>, v: Vec<f64>) {
    mesh.vertex_columns
        .retain(|c| c.name != "u" && c.name != "v");
    mesh.vertex_columns.push(Column {
        name: "u".into(),
        values: u,
    });
    mesh.vertex_columns.push(Column {
        name: "v".into(),
        values: v,
    });
}

/// Cylindrical (u, v) = (R0·φ, z) about the vertical axis through `axis`, φ from −y towards +x
/// (the parameterisation a given face scan gets, docs/design/pipeline.md §2).
pub fn cylindrical_uv(mesh: &mut Mesh, axis: [f64; 2], r0: f64) {
    let (mut u, mut v) = (Vec::new(), Vec::new());
    for p in &mesh.vertices {
        u.push(r0 * (p[0] - axis[0]).atan2(-(p[1] - axis[1])));
        v.push(p[2]);
    }
    set_uv(mesh, u, v);
}

/// Planar (u, v): orthogonal projection on the least-squares plane of the vertices (for
/// patch-like surfaces, docs/reference/case.md `parameterization = "planar"`). u runs along the direction of
/// largest spread, v completes a right-handed frame with the plane normal pointing to the side
/// the triangles face on average.
pub fn planar_uv(mesh: &mut Mesh) {
    use nalgebra::{Matrix3, SymmetricEigen, Vector3};
    let n = mesh.vertices.len().max(1) as f64;
    let c = mesh
        .vertices
        .iter()
        .fold(Vector3::zeros(), |a, p| a + Vector3::new(p[0], p[1], p[2]))
        / n;
    let mut cov = Matrix3::zeros();
    for p in &mesh.vertices {
        let d = Vector3::new(p[0], p[1], p[2]) - c;
        cov += d * d.transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let e1: Vector3<f64> = eig.eigenvectors.column(order[0]).into();
    let mut normal: Vector3<f64> = eig.eigenvectors.column(order[2]).into();
    let facing = (0..mesh.triangles.len()).fold(Vector3::zeros(), |a, t| {
        let f = mesh.face_normal(t);
        a + Vector3::new(f[0], f[1], f[2])
    });
    if normal.dot(&facing) < 0.0 {
        normal = -normal;
    }
    let e2 = normal.cross(&e1);
    let (mut u, mut v) = (Vec::new(), Vec::new());
    for p in &mesh.vertices {
        let d = Vector3::new(p[0], p[1], p[2]) - c;
        u.push(d.dot(&e1));
        v.push(d.dot(&e2));
    }
    set_uv(mesh, u, v);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sheet whose inner vertices zig-zag ±bump/2 (a checkerboard), its border flat.
    fn grid(n: usize, bump: f64) -> Mesh {
        let last = (n - 1) as f64;
        crate::mesh::sheet(n, |x, y| {
            if x > 0.0 && y > 0.0 && x < last && y < last {
                bump * (((x + y) as usize % 2) as f64 - 0.5)
            } else {
                0.0
            }
        })
    }

    #[test]
    fn taubin_removes_high_frequency_noise_and_keeps_border() {
        let mut m = grid(12, 1.0);
        let rough = |m: &Mesh| m.vertices.iter().map(|v| v[2].abs()).fold(0.0, f64::max);
        let before = rough(&m);
        taubin_smooth(&mut m, 10);
        assert!(rough(&m) < 0.1 * before, "{} vs {before}", rough(&m));
        assert_eq!(m.vertices[0], [0.0, 0.0, 0.0]);
    }

    #[test]
    fn planar_parameterisation_of_a_tilted_plane_is_an_isometry() {
        let mut m = grid(6, 0.0);
        // Tilt the plane: rotate about x by 30°, then shift.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        for p in &mut m.vertices {
            *p = [
                p[0] + 5.0,
                c * p[1] - s * p[2] - 2.0,
                s * p[1] + c * p[2] + 1.0,
            ];
        }
        planar_uv(&mut m);
        let (u, v) = (m.column("u").unwrap(), m.column("v").unwrap());
        for t in &m.triangles {
            for e in 0..3 {
                let (a, b) = (t[e] as usize, t[(e + 1) % 3] as usize);
                let d3 = crate::vec3::norm(crate::vec3::sub(m.vertices[a], m.vertices[b]));
                let d2 = ((u[a] - u[b]).powi(2) + (v[a] - v[b]).powi(2)).sqrt();
                assert!((d3 - d2).abs() < 1e-12);
            }
        }
        // Orientation kept: (u, v) triangles wind like the mesh (positive area).
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| i as usize);
            let area = (u[b] - u[a]) * (v[c] - v[a]) - (u[c] - u[a]) * (v[b] - v[a]);
            assert!(area > 0.0);
        }
    }

    #[test]
    fn a_sliver_is_flipped_away() {
        // c = (1, 0) lies on edge ab of triangle (a, b, c); d is above.
        let mut m = Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [1.0, -1.0, 0.0],
            ],
            vec![[0, 1, 2], [1, 0, 3], [0, 2, 4], [2, 1, 4]],
        );
        assert!(m.check(std::path::Path::new("s")).is_err());
        assert_eq!(flip_slivers(&mut m), 1);
        m.check(std::path::Path::new("s")).unwrap();
        assert!((m.area() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn decimation_of_a_plane_is_exact_and_reaches_target() {
        let mut m = grid(30, 0.0);
        let err = decimate(&mut m, 200, 0.01);
        assert!(m.triangles.len() <= 200, "{}", m.triangles.len());
        assert!(err <= 0.01, "{err}");
        assert!(m.vertices.iter().all(|v| v[2] == 0.0));
        m.check(std::path::Path::new("plane")).unwrap();
        assert!((m.area() - 29.0 * 29.0).abs() < 1e-6);
    }
}

//! Mesh-to-mesh distances (docs/lab/study.md, docs/reference/case.md `facesim compare`): every vertex of one mesh
//! to the closest point on the other's surface, both directions; with equal vertex counts also
//! the per-vertex (same index) distances.

use crate::mesh::Mesh;
use crate::vec3::{add, dot, norm, scale, sub};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Closest point to p on triangle (a, b, c) (Ericson, Real-Time Collision Detection §5.1.5).
pub(crate) fn closest_on_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return add(a, scale(ab, d1 / (d1 - d3)));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return add(a, scale(ac, d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return add(b, scale(sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = 1.0 / (va + vb + vc);
    add(a, add(scale(ab, vb * denom), scale(ac, vc * denom)))
}

/// Barycentric coordinates of p (on or near the triangle's plane) in triangle abc.
pub fn barycentric(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let (v0, v1, v2) = (sub(b, a), sub(c, a), sub(p, a));
    let (d00, d01, d11) = (dot(v0, v0), dot(v0, v1), dot(v1, v1));
    let (d20, d21) = (dot(v2, v0), dot(v2, v1));
    let den = d00 * d11 - d01 * d01;
    if den.abs() < 1e-300 {
        return [1.0, 0.0, 0.0];
    }
    let v = (d11 * d20 - d01 * d21) / den;
    let w = (d00 * d21 - d01 * d20) / den;
    [1.0 - v - w, v, w]
}

/// A uniform grid of triangle buckets for closest-point queries.
pub struct SurfaceIndex<'a> {
    mesh: &'a Mesh,
    cell: f64,
    origin: [f64; 3],
    cells: HashMap<[i64; 3], Vec<u32>>,
    span: i64,
    /// The highest cell index per axis (the lowest is 0).
    last: [i64; 3],
}

/// A point more cells than this outside the index's grid is answered by every triangle once:
/// the shells between it and the grid hold nothing, and there are (distance / cell)³ of them.
const FAR_CELLS: i64 = 8;

impl<'a> SurfaceIndex<'a> {
    pub fn new(mesh: &'a Mesh) -> Self {
        let (lo, hi) = mesh.bounds();
        // Cell ≈ mean edge length × 2: a few triangles per cell.
        let mean_edge = if mesh.triangles.is_empty() {
            1.0
        } else {
            let s: f64 = mesh
                .triangles
                .iter()
                .map(|t| {
                    norm(sub(
                        mesh.vertices[t[1] as usize],
                        mesh.vertices[t[0] as usize],
                    ))
                })
                .sum();
            s / mesh.triangles.len() as f64
        };
        let cell = (2.0 * mean_edge).max(1e-6);
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        let key = |p: [f64; 3]| [0, 1, 2].map(|a| ((p[a] - lo[a]) / cell).floor() as i64);
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let pts = tri.map(|i| mesh.vertices[i as usize]);
            let mut tlo = pts[0];
            let mut thi = pts[0];
            for p in &pts[1..] {
                for a in 0..3 {
                    tlo[a] = tlo[a].min(p[a]);
                    thi[a] = thi[a].max(p[a]);
                }
            }
            let (k0, k1) = (key(tlo), key(thi));
            for x in k0[0]..=k1[0] {
                for y in k0[1]..=k1[1] {
                    for z in k0[2]..=k1[2] {
                        cells.entry([x, y, z]).or_default().push(t as u32);
                    }
                }
            }
        }
        let span = [0, 1, 2]
            .map(|a| ((hi[a] - lo[a]) / cell).ceil() as i64 + 1)
            .into_iter()
            .max()
            .unwrap_or(1);
        SurfaceIndex {
            mesh,
            cell,
            origin: lo,
            cells,
            span,
            last: [0, 1, 2].map(|a| ((hi[a] - lo[a]) / cell).floor().max(0.0) as i64),
        }
    }

    /// Each point's distance to the surface (mm).
    pub(crate) fn distances(&self, points: &[[f64; 3]]) -> Vec<f64> {
        points.par_iter().map(|p| self.closest(*p).0).collect()
    }

    /// Distance from p to the surface and the closest point.
    pub fn closest(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let (d, q, _) = self.closest_triangle(p);
        (d, q)
    }

    /// Distance, closest point and the triangle it lies on.
    pub fn closest_triangle(&self, p: [f64; 3]) -> (f64, [f64; 3], usize) {
        let c = [0, 1, 2].map(|a| ((p[a] - self.origin[a]) / self.cell).floor() as i64);
        let mut best = (f64::INFINITY, p, 0);
        let try_triangle = |t: usize, best: &mut (f64, [f64; 3], usize)| {
            let tri = self.mesh.triangles[t].map(|i| self.mesh.vertices[i as usize]);
            let q = closest_on_triangle(p, tri[0], tri[1], tri[2]);
            let d = norm(sub(p, q));
            if d < best.0 {
                *best = (d, q, t);
            }
        };
        // How many cells p lies outside the grid: the shells nearer than that are empty.
        let gap = (0..3)
            .map(|a| (-c[a]).max(c[a] - self.last[a]).max(0))
            .max()
            .unwrap_or(0);
        if gap > FAR_CELLS {
            (0..self.mesh.triangles.len()).for_each(|t| try_triangle(t, &mut best));
            return best;
        }
        // Search shells of cells within the grid; once a hit is closer than the shell's inner
        // distance, stop.
        let far = [0, 1, 2].map(|a| c[a].abs()).into_iter().max().unwrap_or(0) + self.span;
        let within = |a: usize, r: i64| (c[a] - r).max(0)..=(c[a] + r).min(self.last[a]);
        for r in gap..=far {
            for x in within(0, r) {
                for y in within(1, r) {
                    for z in within(2, r) {
                        let on_shell =
                            (x - c[0]).abs() == r || (y - c[1]).abs() == r || (z - c[2]).abs() == r;
                        if !on_shell {
                            continue;
                        }
                        if let Some(list) = self.cells.get(&[x, y, z]) {
                            for &t in list {
                                try_triangle(t as usize, &mut best);
                            }
                        }
                    }
                }
            }
            if best.0 <= r as f64 * self.cell {
                break;
            }
        }
        best
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct DistanceStats {
    pub mean: f64,
    pub rms: f64,
    pub max: f64,
    pub p90: f64,
    pub pct_within_1mm: f64,
    pub pct_within_2mm: f64,
}

pub fn stats(d: &[f64]) -> DistanceStats {
    if d.is_empty() {
        return DistanceStats {
            mean: 0.0,
            rms: 0.0,
            max: 0.0,
            p90: 0.0,
            pct_within_1mm: 100.0,
            pct_within_2mm: 100.0,
        };
    }
    let n = d.len() as f64;
    let mut s = d.to_vec();
    s.sort_by(f64::total_cmp);
    DistanceStats {
        mean: d.iter().sum::<f64>() / n,
        rms: (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
        max: s[s.len() - 1],
        p90: s[((0.9 * (s.len() - 1) as f64).round()) as usize],
        pct_within_1mm: 100.0 * d.iter().filter(|&&x| x <= 1.0).count() as f64 / n,
        pct_within_2mm: 100.0 * d.iter().filter(|&&x| x <= 2.0).count() as f64 / n,
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// Both directions pooled (docs/reference/case.md: mean, rms, max = Hausdorff, % within 1 / 2 mm).
    pub mean: f64,
    pub rms: f64,
    pub max: f64,
    pub pct_within_1mm: f64,
    pub pct_within_2mm: f64,
    pub a_to_b: DistanceStats,
    pub b_to_a: DistanceStats,
    /// Per-vertex distance |a_i − b_i| when the vertex counts match.
    pub vertex_mean: Option<f64>,
    pub vertex_max: Option<f64>,
}

pub(crate) fn point_to_surface(points: &[[f64; 3]], surface: &Mesh) -> Vec<f64> {
    SurfaceIndex::new(surface).distances(points)
}

pub fn compare(a: &Mesh, b: &Mesh) -> Comparison {
    let ab = point_to_surface(&a.vertices, b);
    let ba = point_to_surface(&b.vertices, a);
    let both: Vec<f64> = ab.iter().chain(&ba).copied().collect();
    let all = stats(&both);
    let (vertex_mean, vertex_max) = if a.vertices.len() == b.vertices.len() {
        let d: Vec<f64> = a
            .vertices
            .iter()
            .zip(&b.vertices)
            .map(|(p, q)| norm(sub(*p, *q)))
            .collect();
        (
            Some(d.iter().sum::<f64>() / d.len().max(1) as f64),
            Some(d.iter().cloned().fold(0.0, f64::max)),
        )
    } else {
        (None, None)
    };
    Comparison {
        mean: all.mean,
        rms: all.rms,
        max: all.max,
        pct_within_1mm: all.pct_within_1mm,
        pct_within_2mm: all.pct_within_2mm,
        a_to_b: stats(&ab),
        b_to_a: stats(&ba),
        vertex_mean,
        vertex_max,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_point_regions() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let q = closest_on_triangle([0.2, 0.2, 5.0], a, b, c);
        assert!((q[0] - 0.2).abs() < 1e-15 && (q[1] - 0.2).abs() < 1e-15 && q[2] == 0.0);
        assert_eq!(closest_on_triangle([-1.0, -1.0, 0.0], a, b, c), a);
        assert_eq!(
            closest_on_triangle([0.5, -2.0, 0.0], a, b, c),
            [0.5, 0.0, 0.0]
        );
        let q = closest_on_triangle([1.0, 1.0, 0.0], a, b, c);
        assert!((q[0] - 0.5).abs() < 1e-15 && (q[1] - 0.5).abs() < 1e-15);
    }

    use crate::mesh::sheet;

    #[test]
    fn parallel_planes_are_their_gap_apart() {
        let c = compare(&sheet(10, |_, _| 0.0), &sheet(10, |_, _| 1.5));
        assert!((c.mean - 1.5).abs() < 1e-12 && (c.max - 1.5).abs() < 1e-12);
        assert_eq!(c.pct_within_1mm, 0.0);
        assert_eq!(c.pct_within_2mm, 100.0);
        assert!((c.vertex_mean.unwrap() - 1.5).abs() < 1e-12);
    }

    /// The index against every triangle, for points inside its grid, just outside it and far
    /// away (a user landmark typed in metres, 9 000 mm off: the shell search used to walk every
    /// empty shell between, (distance / cell)³ cells, and a run hung).
    #[test]
    fn the_index_finds_what_every_triangle_finds_near_and_far() {
        // A bumpy 12 × 12 sheet, 1 mm spacing.
        let mesh = sheet(12, |i, j| 0.3 * (0.7 * i).sin() * (0.5 * j).cos());
        let index = SurfaceIndex::new(&mesh);
        let every = |p: [f64; 3]| {
            mesh.triangles
                .iter()
                .map(|tri| {
                    let [a, b, c] = tri.map(|i| mesh.vertices[i as usize]);
                    norm(sub(p, closest_on_triangle(p, a, b, c)))
                })
                .fold(f64::INFINITY, f64::min)
        };
        let points = [
            [5.3, 4.1, 0.7],
            [-0.5, 11.5, -0.2],
            [13.0, -2.0, 3.0],
            [30.0, 5.0, 1.0],
            [9000.0, 0.0, 0.0],
            [-4.0e4, 2.0e4, -7.0e3],
        ];
        for p in points {
            let (d, q, tri) = index.closest_triangle(p);
            let want = every(p);
            assert!(
                (d - want).abs() <= 1e-9 * want.max(1.0),
                "{p:?}: {d} against {want}"
            );
            let [a, b, c] = mesh.triangles[tri].map(|i| mesh.vertices[i as usize]);
            assert!(
                norm(sub(closest_on_triangle(p, a, b, c), q)) < 1e-12,
                "{p:?}"
            );
        }
    }
}

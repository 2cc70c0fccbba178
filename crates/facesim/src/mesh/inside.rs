//! Inside a closed surface (a bone segment exported from Slicer as STL, PLY, OBJ or VTK): ray
//! parity along +z, with the triangles binned in an xy grid so a query costs a few triangles.
//!
//! A point is inside when a ray from it towards +z crosses the surface an odd number of times.
//! Parity needs no consistent orientation (STL exports often have none) and is exact for any
//! closed surface, also one with several pieces. The 2-D point-in-triangle test uses a
//! tie-breaking rule on the projected edges (an edge belongs to the triangle on its one side
//! only), so a ray through a shared edge or vertex is counted once, not twice or never.

use super::surface::Mesh;
use crate::error::{Error, Result};
use std::collections::HashMap;
use std::path::Path;

pub struct ClosedSurface {
    vertices: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    lo: [f64; 3],
    hi: [f64; 3],
    cells: [usize; 2],
    cell_size: [f64; 2],
    /// Triangle indices per grid cell (row-major in x, then y).
    bins: Vec<Vec<u32>>,
}

impl ClosedSurface {
    /// Check that `mesh` is closed (every edge shared by an even number of triangles, after
    /// merging coincident vertices) and index it; errors name `path`.
    pub fn new(mesh: &Mesh, path: &Path) -> Result<ClosedSurface> {
        let mesh = weld(mesh);
        if mesh.triangles.is_empty() {
            return Err(Error::input(path, "region surface has no triangles"));
        }
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let open = edges.values().filter(|c| *c % 2 == 1).count();
        if open > 0 {
            return Err(Error::input(
                path,
                format!(
                    "region surface is not closed ({open} edges border a hole): export the segment as a closed surface"
                ),
            ));
        }
        let (lo, hi) = mesh.bounds();
        let n = ((mesh.triangles.len() as f64).sqrt() as usize).clamp(1, 512);
        let cell_size = [0, 1].map(|a| ((hi[a] - lo[a]) / n as f64).max(1e-9));
        let mut bins = vec![Vec::new(); n * n];
        let cell = |x: f64, a: usize| (((x - lo[a]) / cell_size[a]) as usize).min(n - 1);
        for (i, t) in mesh.triangles.iter().enumerate() {
            let p = t.map(|v| mesh.vertices[v as usize]);
            let (x0, x1) = minmax([p[0][0], p[1][0], p[2][0]]);
            let (y0, y1) = minmax([p[0][1], p[1][1], p[2][1]]);
            for cy in cell(y0, 1)..=cell(y1, 1) {
                for cx in cell(x0, 0)..=cell(x1, 0) {
                    bins[cy * n + cx].push(i as u32);
                }
            }
        }
        Ok(ClosedSurface {
            vertices: mesh.vertices,
            triangles: mesh.triangles,
            lo,
            hi,
            cells: [n, n],
            cell_size,
            bins,
        })
    }

    pub fn contains(&self, p: [f64; 3]) -> bool {
        if (0..3).any(|a| p[a] < self.lo[a] || p[a] > self.hi[a]) {
            return false;
        }
        let c = [0, 1]
            .map(|a| (((p[a] - self.lo[a]) / self.cell_size[a]) as usize).min(self.cells[a] - 1));
        let mut crossings = 0usize;
        for &t in &self.bins[c[1] * self.cells[0] + c[0]] {
            let tri = self.triangles[t as usize].map(|v| self.vertices[v as usize]);
            if let Some(z) = ray_hit_z(&tri, p[0], p[1])
                && z > p[2]
            {
                crossings += 1;
            }
        }
        crossings % 2 == 1
    }
}

fn minmax(v: [f64; 3]) -> (f64, f64) {
    (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]))
}

/// The edge a → b (projected, of a counter-clockwise triangle) owns the points on it when it
/// points "up" or, horizontal, "left": the reverse edge of the neighbour then does not.
fn owns(a: [f64; 3], b: [f64; 3]) -> bool {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    dy > 0.0 || (dy == 0.0 && dx < 0.0)
}

/// Where the vertical line through (x, y) meets the triangle, if its projection holds (x, y).
fn ray_hit_z(t: &[[f64; 3]; 3], x: f64, y: f64) -> Option<f64> {
    let area =
        (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]);
    if area == 0.0 {
        return None; // seen edge-on: its neighbours carry the crossing
    }
    let v = if area > 0.0 { *t } else { [t[0], t[2], t[1]] };
    let mut w = [0.0; 3];
    for k in 0..3 {
        let (a, b) = (v[k], v[(k + 1) % 3]);
        let e = (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]);
        if e < 0.0 || (e == 0.0 && !owns(a, b)) {
            return None;
        }
        // Barycentric weight of the vertex opposite this edge.
        w[(k + 2) % 3] = e;
    }
    let s = w[0] + w[1] + w[2];
    if s <= 0.0 {
        return None;
    }
    Some((w[0] * v[0][2] + w[1] * v[1][2] + w[2] * v[2][2]) / s)
}

/// Merge vertices with identical coordinates (STL stores each triangle's corners apart).
fn weld(mesh: &Mesh) -> Mesh {
    let mut index: HashMap<[u64; 3], u32> = HashMap::new();
    let mut vertices = Vec::new();
    let remap: Vec<u32> = mesh
        .vertices
        .iter()
        .map(|v| {
            *index
                .entry(v.map(|c| (c + 0.0).to_bits()))
                .or_insert_with(|| {
                    vertices.push(*v);
                    (vertices.len() - 1) as u32
                })
        })
        .collect();
    let triangles = mesh
        .triangles
        .iter()
        .map(|t| t.map(|v| remap[v as usize]))
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect();
    Mesh::new(vertices, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis-aligned box [0,2]×[0,3]×[0,4] as 12 triangles.
    fn cube() -> Mesh {
        Mesh::cuboid([0.0; 3], [2.0, 3.0, 4.0])
    }

    #[test]
    fn box_inside_outside_and_through_shared_edges() {
        let s = ClosedSurface::new(&cube(), Path::new("box.stl")).unwrap();
        assert!(s.contains([1.0, 1.5, 2.0]));
        assert!(!s.contains([1.0, 1.5, 4.5]));
        assert!(!s.contains([2.5, 1.5, 2.0]));
        // The +z ray through (1, 1.5) hits the diagonal the top and bottom quads share
        // (x/2 = y/3): counted once, not twice.
        assert!(s.contains([1.0, 1.5, 0.5]));
        // A grid of points: inside exactly when strictly within the box.
        for i in 0..20 {
            for j in 0..20 {
                let p = [-0.43 + 0.15 * i as f64, -0.45 + 0.2 * j as f64, 1.0];
                let inside = p[0] > 0.0 && p[0] < 2.0 && p[1] > 0.0 && p[1] < 3.0;
                assert_eq!(s.contains(p), inside, "{p:?}");
            }
        }
    }

    #[test]
    fn flipped_triangles_do_not_matter_and_holes_are_refused() {
        let mut m = cube();
        m.triangles[3] = [m.triangles[3][0], m.triangles[3][2], m.triangles[3][1]];
        let s = ClosedSurface::new(&m, Path::new("box.stl")).unwrap();
        assert!(s.contains([0.3, 0.4, 0.5]));
        let mut m = cube();
        m.triangles.pop();
        let e = ClosedSurface::new(&m, Path::new("box.stl")).err().unwrap();
        assert!(e.to_string().contains("box.stl") && e.to_string().contains("not closed"));
    }
}

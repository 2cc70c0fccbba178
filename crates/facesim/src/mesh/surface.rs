//! The triangle mesh itself: vertices (LPS mm), triangles, optional per-vertex columns, and its
//! checks, cleaning and measures. The format readers and writers beside it build and read this
//! type; `mod.rs` only dispatches by file extension.

use crate::error::{Error, Result};
use crate::union_find::UnionFind;
use crate::vec3::{add, cross, norm, scale, sub};
use std::collections::HashMap;
use std::path::Path;

/// A per-element scalar column of a PLY file beyond the standard ones.
#[derive(Clone, Debug, PartialEq)]
pub struct Column {
    pub name: String,
    pub values: Vec<f64>,
}

/// Optional `element edge` of a PLY file: vertex pairs with extra scalar columns
/// (springs.ply uses `stiffness` and `kind`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Edges {
    pub pairs: Vec<[u32; 2]>,
    pub columns: Vec<Column>,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Optional per-vertex RGB colours.
    pub colors: Option<Vec<[u8; 3]>>,
    /// Extra per-vertex scalar properties (PLY only).
    pub vertex_columns: Vec<Column>,
    /// Optional edges (PLY only).
    pub edges: Option<Edges>,
}

/// What [`Mesh::check`] found that is worth a warning but not an error.
#[derive(Clone, Debug, Default)]
pub struct MeshStats {
    pub unreferenced_vertices: usize,
    pub boundary_edges: usize,
}

/// An n × n sheet of unit spacing at height z(i, j), two triangles per square: the tests' grid.
#[cfg(test)]
pub(crate) fn sheet(n: usize, z: impl Fn(f64, f64) -> f64) -> Mesh {
    let mut v = Vec::new();
    for j in 0..n {
        for i in 0..n {
            v.push([i as f64, j as f64, z(i as f64, j as f64)]);
        }
    }
    let mut t = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            t.push([a, a + 1, a + n as u32]);
            t.push([a + 1, a + n as u32 + 1, a + n as u32]);
        }
    }
    Mesh::new(v, t)
}

/// The six Kuhn tetrahedra of the grid cube whose lowest corner has indices `c`: the paths
/// from that corner to the opposite one along the three axes in each order (`id` numbers the
/// grid's nodes). Neighbouring cubes share their face diagonals, so the mesh conforms; the
/// orientation is the caller's to fix where volumes must be positive. The tests' tetrahedra.
#[cfg(test)]
pub(crate) fn kuhn_cell(c: [usize; 3], id: impl Fn(usize, usize, usize) -> u32) -> [[u32; 4]; 6] {
    const PATHS: [[usize; 3]; 6] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    PATHS.map(|p| {
        let mut at = c;
        let mut t = [id(c[0], c[1], c[2]); 4];
        for (s, axis) in p.iter().enumerate() {
            at[*axis] += 1;
            t[s + 1] = id(at[0], at[1], at[2]);
        }
        t
    })
}

/// The tetrahedra of an m³ grid of nodes, node `(x, y, z)` numbered `(x·m + y)·m + z`: six Kuhn
/// tetrahedra per cube ([`kuhn_cell`]), orientation not fixed.
#[cfg(test)]
pub(crate) fn kuhn_grid(m: usize) -> Vec<[u32; 4]> {
    let id = |x: usize, y: usize, z: usize| ((x * m + y) * m + z) as u32;
    let mut t = Vec::new();
    for x in 0..m - 1 {
        for y in 0..m - 1 {
            for z in 0..m - 1 {
                t.extend(kuhn_cell([x, y, z], id));
            }
        }
    }
    t
}

/// Two triangles over four points with fractional coordinates: the file-format tests' mesh.
#[cfg(test)]
pub(crate) fn two_triangles() -> Mesh {
    Mesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.5, 0.0, 0.0],
            [0.0, 2.25, -1.0],
            [1.0, 1.0, 1.0],
        ],
        vec![[0, 1, 2], [1, 3, 2]],
    )
}

impl Mesh {
    /// The closed axis-aligned box [min, max] as 12 triangles wound outwards (a region, a test
    /// body).
    /// The triangles whose three vertices are kept, with only the vertices they use.
    pub(crate) fn sub_mesh(&self, keep: &[bool]) -> Mesh {
        let mut index = vec![u32::MAX; self.vertices.len()];
        let mut vertices = Vec::new();
        let mut triangles = Vec::new();
        for t in &self.triangles {
            if !t.iter().all(|&v| keep[v as usize]) {
                continue;
            }
            triangles.push(t.map(|v| {
                let v = v as usize;
                if index[v] == u32::MAX {
                    index[v] = vertices.len() as u32;
                    vertices.push(self.vertices[v]);
                }
                index[v]
            }));
        }
        Mesh::new(vertices, triangles)
    }

    pub fn cuboid(min: [f64; 3], max: [f64; 3]) -> Self {
        // Corner i has max[a] where bit a of i is set.
        let v = (0..8)
            .map(|i| [0, 1, 2].map(|a| if (i >> a) & 1 == 1 { max[a] } else { min[a] }))
            .collect();
        let quads: [[u32; 4]; 6] = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let t = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Mesh::new(v, t)
    }

    pub fn new(vertices: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Self {
        Mesh {
            vertices,
            triangles,
            ..Default::default()
        }
    }

    /// The values of the vertex column `name` (e.g. the (u, v) parameter coordinates).
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.vertex_columns
            .iter()
            .find(|c| c.name == name)
            .map(|c| c.values.as_slice())
    }

    /// Twice-area normal of triangle t (not normalised).
    pub(crate) fn face_normal(&self, t: usize) -> [f64; 3] {
        let [a, b, c] = self.triangles[t].map(|i| self.vertices[i as usize]);
        cross(sub(b, a), sub(c, a))
    }

    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| 0.5 * norm(self.face_normal(t)))
            .sum()
    }

    /// Area-weighted vertex normals (docs/design/pipeline.md §4), unit length; zero for isolated vertices.
    pub fn vertex_normals(&self) -> Vec<[f64; 3]> {
        let mut n = vec![[0.0; 3]; self.vertices.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            let f = self.face_normal(t);
            for &v in tri {
                n[v as usize] = add(n[v as usize], f);
            }
        }
        for v in &mut n {
            let l = norm(*v);
            if l > 0.0 {
                *v = scale(*v, 1.0 / l);
            }
        }
        n
    }

    /// Characteristic size: the bounding-box diagonal.
    pub fn diagonal(&self) -> f64 {
        let (lo, hi) = self.bounds();
        norm(sub(hi, lo))
    }

    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in &self.vertices {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        (lo, hi)
    }

    /// Reject what the model cannot use: no triangles, non-finite coordinates, indices out of
    /// range, degenerate triangles, edges shared by more than two triangles, and neighbouring
    /// triangles with opposite orientation. `path` names the source in the error.
    pub fn check(&self, path: &Path) -> Result<MeshStats> {
        if self.vertices.is_empty() || self.triangles.is_empty() {
            return Err(Error::input(
                path,
                format!(
                    "empty mesh ({} vertices, {} triangles)",
                    self.vertices.len(),
                    self.triangles.len()
                ),
            ));
        }
        if let Some(i) = self
            .vertices
            .iter()
            .position(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(Error::input(
                path,
                format!("vertex {i} has a non-finite coordinate"),
            ));
        }
        let nv = self.vertices.len();
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(&bad) = tri.iter().find(|&&i| i as usize >= nv) {
                return Err(Error::input(
                    path,
                    format!("triangle {t} uses vertex index {bad}, but there are {nv} vertices"),
                ));
            }
        }
        let diag = self.diagonal();
        let tiny = (1e-12 * diag * diag).max(f64::MIN_POSITIVE);
        let degenerate: Vec<usize> = (0..self.triangles.len())
            .filter(|&t| {
                let [a, b, c] = self.triangles[t];
                a == b || b == c || a == c || norm(self.face_normal(t)) <= tiny
            })
            .collect();
        if let Some(&first) = degenerate.first() {
            return Err(Error::input(
                path,
                format!(
                    "{} degenerate (zero-area) triangles, the first is triangle {first}",
                    degenerate.len()
                ),
            ));
        }
        // Directed edge → count; undirected edge → count.
        let mut directed: HashMap<(u32, u32), u32> =
            HashMap::with_capacity(self.triangles.len() * 3);
        let mut undirected: HashMap<(u32, u32), u32> =
            HashMap::with_capacity(self.triangles.len() * 3);
        for tri in &self.triangles {
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                *directed.entry((a, b)).or_default() += 1;
                *undirected.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        if let Some((&(a, b), &n)) = undirected.iter().filter(|(_, n)| **n > 2).min() {
            let count = undirected.values().filter(|n| **n > 2).count();
            return Err(Error::input(
                path,
                format!(
                    "non-manifold: {count} edges shared by more than two triangles (edge {a}-{b} by {n})"
                ),
            ));
        }
        if let Some((&(a, b), _)) = directed.iter().filter(|(_, n)| **n > 1).min() {
            return Err(Error::input(
                path,
                format!(
                    "inconsistent triangle orientation at edge {a}-{b} (neighbouring triangles wind the same way)"
                ),
            ));
        }
        let mut used = vec![false; nv];
        for tri in &self.triangles {
            for &v in tri {
                used[v as usize] = true;
            }
        }
        Ok(MeshStats {
            unreferenced_vertices: used.iter().filter(|u| !**u).count(),
            boundary_edges: undirected.values().filter(|n| **n == 1).count(),
        })
    }

    /// Vertex → neighbouring vertices (one ring), sorted.
    pub fn neighbours(&self) -> Vec<Vec<u32>> {
        one_rings(self.vertices.len(), &self.triangles)
    }

    /// Drop vertices no triangle uses (keeping the order of the rest).
    pub fn compact(&mut self) {
        let mut map = vec![u32::MAX; self.vertices.len()];
        for tri in &self.triangles {
            for &v in tri {
                map[v as usize] = 0;
            }
        }
        let mut next = 0u32;
        let mut keep = Vec::new();
        for (i, m) in map.iter_mut().enumerate() {
            if *m == 0 {
                *m = next;
                next += 1;
                keep.push(i);
            }
        }
        self.vertices = keep.iter().map(|&i| self.vertices[i]).collect();
        if let Some(c) = &self.colors {
            self.colors = Some(keep.iter().map(|&i| c[i]).collect());
        }
        for col in &mut self.vertex_columns {
            col.values = keep.iter().map(|&i| col.values[i]).collect();
        }
        for tri in &mut self.triangles {
            *tri = tri.map(|v| map[v as usize]);
        }
    }

    /// Connected components by shared vertices: component id per triangle, and the count.
    pub fn components(&self) -> (Vec<u32>, usize) {
        let mut sets = UnionFind::new(self.vertices.len());
        for tri in &self.triangles {
            for &v in &tri[1..] {
                sets.union(tri[0] as usize, v as usize);
            }
        }
        // Components numbered in the order of their first triangle.
        let mut id = vec![u32::MAX; self.vertices.len()];
        let mut count = 0;
        let comp: Vec<u32> = self
            .triangles
            .iter()
            .map(|tri| {
                let r = sets.find(tri[0] as usize);
                if id[r] == u32::MAX {
                    id[r] = count;
                    count += 1;
                }
                id[r]
            })
            .collect();
        (comp, count as usize)
    }
}

/// Vertex → neighbouring vertices (one ring, sorted) of `n` vertices joined by `triangles`.
pub(crate) fn one_rings(n: usize, triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let mut nb = vec![Vec::new(); n];
    for tri in triangles {
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            nb[a as usize].push(b);
            nb[b as usize].push(a);
        }
    }
    for l in &mut nb {
        l.sort_unstable();
        l.dedup();
    }
    nb
}

/// Read a mesh in any format a run writes or 3D Slicer saves (OBJ, PLY, STL, legacy VTK,
/// VTP; by extension) into LPS, then check it. The one reader of `facesim compare`, `render` and
/// the read-backs; `facesim run`'s inputs use its first half, [`model_file::read_model`], and
/// check what each needs. A run's .vtp and .stl say SPACE=LPS, so they read back to face_post's
/// coordinates (the STL's rounded to f32, its vertices welded in the order triangles use them).
/// FNV-1a (64 bit) over vertex coordinates' bits: which face a stored reduced model belongs to,
/// which skin landmarks were located on.
pub fn checksum(vertices: &[[f64; 3]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in vertices
        .iter()
        .flatten()
        .flat_map(|x| x.to_bits().to_le_bytes())
    {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

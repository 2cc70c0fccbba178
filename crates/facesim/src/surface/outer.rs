//! The outer face of a skin exported by another program (docs/design/pipeline.md
//! "A skin from another program").
//!
//! An iso-surface of a CT made elsewhere (3D Slicer, a segmentation program) is the whole
//! air/tissue boundary: the face joined through the nostrils and mouth to the airway and
//! sinuses, closed internal surfaces, floating islands (the head rest), non-manifold edges and,
//! from STL, every vertex repeated per triangle. The model needs the face a range scanner
//! would see, so this keeps exactly that:
//!
//! 1. vertices at bit-identical positions are merged (an STL's repeated corners), degenerate
//!    and repeated triangles dropped;
//! 2. only the largest vertex-connected piece is scanned (a scanner sees the patient, not the
//!    table; closed internal surfaces are separate pieces);
//! 3. the cylindrical range scan of the product's own skin (docs/design/pipeline.md §2) is cast at the
//!    mesh: horizontal rays (constant LPS z) from outside towards the vertical axis, one every
//!    half median edge length in z and along the outermost circumference; the first triangle
//!    each ray meets is seen;
//! 4. pinholes the rays passed between (a triangle with two or three seen edge-neighbours) are
//!    closed, then the largest piece joined through manifold edges (shared by exactly two kept
//!    triangles) is kept: a fin on a non-manifold edge, a cavity wall reached only through one,
//!    and islands fall away;
//! 5. the piece is wound consistently with its normals pointing away from the axis.

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::union_find::UnionFind;
use crate::vec3::{cross, norm, sub};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::f64::consts::PI;
use std::path::Path;

/// What [`outer_face`] found and dropped (report.json `surfaces.foreign_skin`).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct OuterReport {
    /// Triangles in the file as read.
    pub triangles_in: usize,
    pub vertices_in: usize,
    /// Vertices merged with an identical one (an STL repeats each corner per triangle).
    pub duplicate_vertices_merged: usize,
    /// Zero-area or repeated triangles dropped.
    pub degenerate_triangles_dropped: usize,
    /// Edges shared by more than two triangles in the file.
    pub non_manifold_edges: usize,
    /// Vertex-connected pieces in the file.
    pub pieces: usize,
    /// Triangles in pieces other than the largest (islands, closed internal surfaces).
    pub island_triangles_dropped: usize,
    /// Triangles of the largest piece no ray from outside reached (airway, sinuses, the inside
    /// of the nostrils and mouth), or cut off from the face by a non-manifold edge.
    pub hidden_triangles_dropped: usize,
    pub triangles_kept: usize,
    pub rays: usize,
}

impl OuterReport {
    /// One line for report.json's warnings.
    pub fn summary(&self, file: &Path) -> String {
        format!(
            "skin {}: kept its outer face, {} of {} triangles; dropped {} hidden from outside (airway, sinuses, internal surfaces), {} in {} islands besides the largest piece, {} degenerate; {} non-manifold edges and {} duplicate vertices in the file",
            file.display(),
            self.triangles_kept,
            self.triangles_in,
            self.hidden_triangles_dropped,
            self.island_triangles_dropped,
            self.pieces.saturating_sub(1),
            self.degenerate_triangles_dropped,
            self.non_manifold_edges,
            self.duplicate_vertices_merged,
        )
    }
}

/// Whether a mesh is usable as given: manifold, consistently wound, one piece, with a boundary
/// (a face scan is open; a closed surface is a whole head, internals and all).
pub(crate) fn is_clean_face(m: &Mesh) -> bool {
    match m.check(Path::new("")) {
        Ok(stats) => stats.boundary_edges > 0 && m.components().1 == 1,
        Err(_) => false,
    }
}

/// The outer face of `m` as seen by a cylindrical range scan about the vertical axis through
/// `axis` (x, y) in LPS mm. `file` names the source in errors.
pub fn outer_face(m: &Mesh, axis: [f64; 2], file: &Path) -> Result<(Mesh, OuterReport)> {
    let mut rep = OuterReport {
        triangles_in: m.triangles.len(),
        vertices_in: m.vertices.len(),
        ..Default::default()
    };
    let (vertices, triangles) = weld(m, &mut rep);
    rep.non_manifold_edges = edge_triangles(&triangles)
        .values()
        .filter(|t| t.len() > 2)
        .count();
    let largest = largest_piece(vertices.len(), &triangles, &mut rep);
    let tris: Vec<[u32; 3]> = largest.iter().map(|&t| triangles[t]).collect();
    let (seen, rays) = scan(&vertices, &tris, axis);
    rep.rays = rays;
    let kept = close_and_keep_largest(&tris, seen, true);
    let mut out: Vec<[u32; 3]> = kept.iter().map(|&t| tris[t]).collect();
    orient_outward(&vertices, &mut out, axis);
    // A scanner sees a surface from its front only, and its sheet is open at the back (the seam
    // φ = ±π of the product's own scan): what faces the axis or crosses the seam goes, and the
    // largest piece of the rest stays. The (u, v) map of what is left cannot fold.
    let front = front_facing(&vertices, &out, axis);
    let sheet = close_and_keep_largest(&out, front, false);
    out = sheet.iter().map(|&t| out[t]).collect();
    rep.hidden_triangles_dropped = tris.len() - out.len();
    rep.triangles_kept = out.len();
    if out.is_empty() {
        return Err(Error::input(
            file,
            "no triangle of the skin is seen from outside along the range-scan rays",
        ));
    }
    let mut mesh = Mesh::new(vertices, out);
    mesh.compact();
    Ok((mesh, rep))
}

/// Merge bit-identical vertices; drop degenerate and repeated triangles.
fn weld(m: &Mesh, rep: &mut OuterReport) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    // +0.0 and -0.0 are one position.
    let key = |v: [f64; 3]| v.map(|x| (x + 0.0).to_bits());
    let mut index: HashMap<[u64; 3], u32> = HashMap::with_capacity(m.vertices.len());
    let mut vertices = Vec::new();
    let map: Vec<u32> = m
        .vertices
        .iter()
        .map(|&v| {
            *index.entry(key(v)).or_insert_with(|| {
                vertices.push(v);
                (vertices.len() - 1) as u32
            })
        })
        .collect();
    rep.duplicate_vertices_merged = m.vertices.len() - vertices.len();
    let diag = Mesh::new(vertices.clone(), Vec::new()).diagonal();
    let tiny = (1e-12 * diag * diag).max(f64::MIN_POSITIVE);
    let mut seen_tri = std::collections::HashSet::with_capacity(m.triangles.len());
    let mut triangles = Vec::with_capacity(m.triangles.len());
    for t in &m.triangles {
        let t = t.map(|i| map[i as usize]);
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        let mut sorted = t;
        sorted.sort_unstable();
        let degenerate = t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
        if degenerate || norm(cross(sub(b, a), sub(c, a))) <= tiny || !seen_tri.insert(sorted) {
            rep.degenerate_triangles_dropped += 1;
        } else {
            triangles.push(t);
        }
    }
    (vertices, triangles)
}

/// Undirected edge → the triangles using it.
fn edge_triangles(tris: &[[u32; 3]]) -> HashMap<(u32, u32), Vec<u32>> {
    let mut e: HashMap<(u32, u32), Vec<u32>> = HashMap::with_capacity(tris.len() * 2);
    for (i, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            e.entry((a.min(b), a.max(b))).or_default().push(i as u32);
        }
    }
    e
}

/// The triangles (indices) of the largest vertex-connected piece.
fn largest_piece(nv: usize, tris: &[[u32; 3]], rep: &mut OuterReport) -> Vec<usize> {
    let mut uf = UnionFind::new(nv);
    for t in tris {
        uf.union(t[0] as usize, t[1] as usize);
        uf.union(t[0] as usize, t[2] as usize);
    }
    let mut size: HashMap<usize, usize> = HashMap::new();
    let roots: Vec<usize> = tris.iter().map(|t| uf.find(t[0] as usize)).collect();
    for &r in &roots {
        *size.entry(r).or_default() += 1;
    }
    rep.pieces = size.len();
    let Some((&big, _)) = size
        .iter()
        .max_by_key(|(r, s)| (**s, std::cmp::Reverse(**r)))
    else {
        return Vec::new();
    };
    let keep: Vec<usize> = (0..tris.len()).filter(|&t| roots[t] == big).collect();
    rep.island_triangles_dropped = tris.len() - keep.len();
    keep
}

/// Cast the cylindrical range scan at the triangles: per triangle, whether some ray met it
/// first; and the number of rays.
fn scan(v: &[[f64; 3]], tris: &[[u32; 3]], axis: [f64; 2]) -> (Vec<bool>, usize) {
    if tris.is_empty() {
        return (Vec::new(), 0);
    }
    // Per triangle its shortest edge: a long thin triangle is met only by rays closer than that.
    let mut edges: Vec<f64> = tris
        .iter()
        .map(|t| {
            (0..3)
                .map(|k| norm(sub(v[t[(k + 1) % 3] as usize], v[t[k] as usize])))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let mid = edges.len() / 2;
    let h = *edges.select_nth_unstable_by(mid, f64::total_cmp).1;
    let (mut zlo, mut zhi, mut rmax) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    for t in tris {
        for &i in t {
            let p = v[i as usize];
            zlo = zlo.min(p[2]);
            zhi = zhi.max(p[2]);
            rmax = rmax.max((p[0] - axis[0]).hypot(p[1] - axis[1]));
        }
    }
    // Half the typical shortest edge between rays, so nearly every outer triangle is met; capped so a
    // very fine mesh costs at most 4096 × 8192 rays.
    let step = (0.5 * h).max(1e-3);
    let rows = (((zhi - zlo) / step).ceil() as usize).clamp(1, 4096);
    let dz = (zhi - zlo) / rows as f64;
    let nphi = ((2.0 * PI * rmax / step).ceil() as usize).clamp(64, 8192);
    let dphi = 2.0 * PI / nphi as f64;
    // Triangles by the rows their z range crosses.
    let row_of = |z: f64| ((z - zlo) / dz - 0.5).max(-1.0);
    let mut by_row: Vec<Vec<u32>> = vec![Vec::new(); rows];
    for (ti, t) in tris.iter().enumerate() {
        let zs = t.map(|i| v[i as usize][2]);
        let lo = row_of(zs.iter().cloned().fold(f64::INFINITY, f64::min)).ceil() as usize;
        let hi = row_of(zs.iter().cloned().fold(f64::NEG_INFINITY, f64::max)).floor();
        if hi < 0.0 {
            continue;
        }
        for row in by_row.iter_mut().take(hi as usize + 1).skip(lo) {
            row.push(ti as u32);
        }
    }
    let hits: Vec<Vec<u32>> = by_row
        .par_iter()
        .enumerate()
        .map(|(r, list)| {
            let z = zlo + (r as f64 + 0.5) * dz;
            row_hits(v, tris, list, z, axis, nphi, dphi)
        })
        .collect();
    let mut seen = vec![false; tris.len()];
    for t in hits.into_iter().flatten() {
        seen[t as usize] = true;
    }
    (seen, rows * nphi)
}

/// One row of rays at height `z`: each triangle's cut by the plane is a segment; per ray angle
/// the segment met furthest from the axis (first from outside) wins. Returns the winners.
fn row_hits(
    v: &[[f64; 3]],
    tris: &[[u32; 3]],
    list: &[u32],
    z: f64,
    axis: [f64; 2],
    nphi: usize,
    dphi: f64,
) -> Vec<u32> {
    let mut best = vec![(f64::NEG_INFINITY, u32::MAX); nphi];
    // Angle from the anterior direction (−y) towards +x, as the product's scan measures it.
    let angle = |p: [f64; 2]| p[0].atan2(-p[1]);
    for &ti in list {
        let Some((p, q)) = cut(tris[ti as usize].map(|i| v[i as usize]), z, axis) else {
            continue;
        };
        let (a, mut b) = (angle(p), angle(q));
        if (b - a).abs() > PI {
            b += if b < a { 2.0 * PI } else { -2.0 * PI };
        }
        let (lo, hi) = (a.min(b), a.max(b));
        let e = [q[0] - p[0], q[1] - p[1]];
        let cpe = p[0] * e[1] - p[1] * e[0];
        // Ray k at φ_k = −π + (k + ½)Δφ; the bins whose φ lies in [lo, hi].
        let k0 = ((lo + PI) / dphi - 0.5).ceil() as i64;
        let k1 = ((hi + PI) / dphi - 0.5).floor() as i64;
        for k in k0..=k1 {
            let phi = -PI + (k as f64 + 0.5) * dphi;
            let d = [phi.sin(), -phi.cos()];
            let den = d[0] * e[1] - d[1] * e[0];
            if den.abs() < 1e-300 {
                continue;
            }
            let r = cpe / den;
            let bin = k.rem_euclid(nphi as i64) as usize;
            if r > best[bin].0 {
                best[bin] = (r, ti);
            }
        }
    }
    let mut out: Vec<u32> = best
        .into_iter()
        .filter(|b| b.1 != u32::MAX)
        .map(|b| b.1)
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// The segment where the plane at height `z` cuts a triangle, relative to the axis; `None`
/// when it does not (or only touches a corner).
fn cut(t: [[f64; 3]; 3], z: f64, axis: [f64; 2]) -> Option<([f64; 2], [f64; 2])> {
    let mut pts = Vec::with_capacity(2);
    for k in 0..3 {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        let (da, db) = (a[2] - z, b[2] - z);
        if (da < 0.0) != (db < 0.0) {
            let s = da / (da - db);
            pts.push([
                a[0] + s * (b[0] - a[0]) - axis[0],
                a[1] + s * (b[1] - a[1]) - axis[1],
            ]);
        }
    }
    (pts.len() == 2).then(|| (pts[0], pts[1]))
}

/// Close the pinholes between seen triangles (when `close`), then keep the largest piece joined
/// through manifold edges. Returns the kept triangle indices.
fn close_and_keep_largest(tris: &[[u32; 3]], mut kept: Vec<bool>, close: bool) -> Vec<usize> {
    let edges = edge_triangles(tris);
    // Per triangle, its neighbours across manifold edges.
    let mut nb: Vec<Vec<u32>> = vec![Vec::new(); tris.len()];
    for ts in edges.values() {
        if ts.len() == 2 {
            nb[ts[0] as usize].push(ts[1]);
            nb[ts[1] as usize].push(ts[0]);
        }
    }
    for _ in 0..if close { 4 } else { 0 } {
        let add: Vec<usize> = (0..tris.len())
            .filter(|&t| !kept[t] && nb[t].iter().filter(|&&n| kept[n as usize]).count() >= 2)
            .collect();
        if add.is_empty() {
            break;
        }
        add.into_iter().for_each(|t| kept[t] = true);
    }
    // Edges shared by exactly two kept triangles join pieces.
    let mut uf = UnionFind::new(tris.len());
    for ts in edges.values() {
        let k: Vec<u32> = ts.iter().copied().filter(|&t| kept[t as usize]).collect();
        if k.len() == 2 {
            uf.union(k[0] as usize, k[1] as usize);
        }
    }
    let mut size: HashMap<usize, usize> = HashMap::new();
    for t in (0..tris.len()).filter(|&t| kept[t]) {
        *size.entry(uf.find(t)).or_default() += 1;
    }
    let Some((&big, _)) = size
        .iter()
        .max_by_key(|(r, s)| (**s, std::cmp::Reverse(**r)))
    else {
        return Vec::new();
    };
    let mut keep: Vec<usize> = (0..tris.len())
        .filter(|&t| kept[t] && uf.find(t) == big)
        .collect();
    // Three or more kept sheets on one edge, each joined to the piece elsewhere: drop them all.
    let in_piece: std::collections::HashSet<usize> = keep.iter().copied().collect();
    let mut bad = std::collections::HashSet::new();
    for ts in edges.values() {
        let k: Vec<u32> = ts
            .iter()
            .copied()
            .filter(|&t| in_piece.contains(&(t as usize)))
            .collect();
        if k.len() > 2 {
            bad.extend(k.into_iter().map(|t| t as usize));
        }
    }
    keep.retain(|t| !bad.contains(t));
    keep
}

/// Per triangle: faces away from the axis (positive area in (φ, z)) and does not cross the
/// seam φ = ±π.
fn front_facing(v: &[[f64; 3]], tris: &[[u32; 3]], axis: [f64; 2]) -> Vec<bool> {
    tris.iter()
        .map(|t| {
            let p = t.map(|i| {
                let q = v[i as usize];
                [(q[0] - axis[0]).atan2(-(q[1] - axis[1])), q[2]]
            });
            let span = [p[0][0], p[1][0], p[2][0]];
            let lo = span.iter().cloned().fold(f64::INFINITY, f64::min);
            let hi = span.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            let area = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
            hi - lo < PI && area > 0.0
        })
        .collect()
}

/// Wind the triangles consistently (breadth first across edges) and so that the area-weighted
/// normal points away from the vertical axis through `axis`.
fn orient_outward(v: &[[f64; 3]], tris: &mut [[u32; 3]], axis: [f64; 2]) {
    let edges = edge_triangles(tris);
    let mut done = vec![false; tris.len()];
    for seed in 0..tris.len() {
        if done[seed] {
            continue;
        }
        done[seed] = true;
        let mut queue = std::collections::VecDeque::from([seed]);
        let mut piece = vec![seed];
        while let Some(t) = queue.pop_front() {
            let tri = tris[t];
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                for &n in &edges[&(a.min(b), a.max(b))] {
                    let n = n as usize;
                    if done[n] {
                        continue;
                    }
                    // A consistent neighbour runs the shared edge the other way (b → a).
                    let m = tris[n];
                    let same_way = (0..3).any(|j| m[j] == a && m[(j + 1) % 3] == b);
                    if same_way {
                        tris[n] = [m[0], m[2], m[1]];
                    }
                    done[n] = true;
                    queue.push_back(n);
                    piece.push(n);
                }
            }
        }
        let outward: f64 = piece
            .iter()
            .map(|&t| {
                let [a, b, c] = tris[t].map(|i| v[i as usize]);
                let n = cross(sub(b, a), sub(c, a));
                let cen = [
                    (a[0] + b[0] + c[0]) / 3.0 - axis[0],
                    (a[1] + b[1] + c[1]) / 3.0 - axis[1],
                ];
                n[0] * cen[0] + n[1] * cen[1]
            })
            .sum();
        if outward < 0.0 {
            for &t in &piece {
                let m = tris[t];
                tris[t] = [m[0], m[2], m[1]];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An open cylinder of radius `r` about the z axis, `n` around, `m` high, wound outward
    /// when `outward`.
    fn cylinder(r: f64, n: usize, m: usize, outward: bool, base: u32) -> Mesh {
        let mut v = Vec::new();
        for j in 0..=m {
            for i in 0..n {
                let a = 2.0 * PI * i as f64 / n as f64;
                v.push([r * a.cos(), r * a.sin(), j as f64]);
            }
        }
        let id = |i: usize, j: usize| base + (j * n + i % n) as u32;
        let mut t = Vec::new();
        for j in 0..m {
            for i in 0..n {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if outward {
                    t.push([a, b, c]);
                    t.push([a, c, d]);
                } else {
                    t.push([a, c, b]);
                    t.push([a, d, c]);
                }
            }
        }
        Mesh::new(v, t)
    }

    fn join(a: &Mesh, b: &Mesh) -> Mesh {
        let off = a.vertices.len() as u32;
        let mut m = a.clone();
        m.vertices.extend(&b.vertices);
        m.triangles
            .extend(b.triangles.iter().map(|t| t.map(|i| i + off)));
        m
    }

    #[test]
    fn an_inner_cylinder_is_hidden_and_an_island_dropped() {
        let outer = cylinder(50.0, 120, 20, false, 0);
        // Inside the outer one (hidden) — joined by vertex to nothing, so a separate piece.
        let inner = cylinder(20.0, 60, 20, true, 0);
        let m = join(&outer, &inner);
        let (kept, rep) = outer_face(&m, [0.0, 0.0], Path::new("t.stl")).unwrap();
        // All but the column of quads across the seam at the back (φ = ±π, +y).
        assert_eq!(rep.triangles_kept, outer.triangles.len() - 2 * 20);
        assert_eq!(rep.island_triangles_dropped, inner.triangles.len());
        assert!(
            kept.vertices
                .iter()
                .all(|p| (p[0].hypot(p[1]) - 50.0).abs() < 1e-9)
        );
        // Wound outward although given inward.
        kept.check(Path::new("kept")).unwrap();
        let n = kept.face_normal(0);
        let [a, b, c] = kept.triangles[0].map(|i| kept.vertices[i as usize]);
        let cen = [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0];
        assert!(n[0] * cen[0] + n[1] * cen[1] > 0.0);
    }

    #[test]
    fn a_tube_joined_to_the_face_is_hidden_and_a_fin_cut_off() {
        // Outer and inner cylinders joined by a flat ring at the top: one piece, like the
        // airway joined to the face through a nostril.
        let n = 90;
        let outer = cylinder(50.0, n, 20, true, 0);
        let inner = cylinder(20.0, n, 20, false, 0);
        let mut m = join(&outer, &inner);
        let off = outer.vertices.len() as u32;
        let top = |i: usize| (20 * n + i % n) as u32;
        for i in 0..n {
            let (a, b) = (top(i), top(i + 1));
            m.triangles.push([a, off + b, b]);
            m.triangles.push([a, off + a, off + b]);
        }
        // A fin standing out of the outer wall on one of its edges (non-manifold).
        let fin = m.vertices.len() as u32;
        m.vertices.push([80.0, 0.5, 5.5]);
        m.triangles.push([(5 * n) as u32, (6 * n) as u32, fin]);
        let (kept, rep) = outer_face(&m, [0.0, 0.0], Path::new("t.stl")).unwrap();
        assert_eq!(rep.non_manifold_edges, 1);
        assert_eq!(rep.pieces, 1);
        let seam = 2 * 20;
        assert_eq!(rep.triangles_kept, outer.triangles.len() - seam);
        assert_eq!(
            rep.hidden_triangles_dropped,
            inner.triangles.len() + 2 * n + 1 + seam
        );
        assert!(
            kept.vertices
                .iter()
                .all(|p| (p[0].hypot(p[1]) - 50.0).abs() < 1e-9)
        );
        kept.check(Path::new("kept")).unwrap();
    }

    #[test]
    fn stl_corners_are_welded() {
        let c = cylinder(30.0, 40, 5, true, 0);
        let soup = Mesh::new(
            c.triangles
                .iter()
                .flat_map(|t| t.map(|i| c.vertices[i as usize]))
                .collect(),
            (0..c.triangles.len() as u32)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect(),
        );
        let (kept, rep) = outer_face(&soup, [0.0, 0.0], Path::new("t.stl")).unwrap();
        assert_eq!(
            rep.duplicate_vertices_merged,
            soup.vertices.len() - c.vertices.len()
        );
        // The seam column (a vertex lies on φ = π) is cut: the sheet opens there.
        assert_eq!(kept.triangles.len(), c.triangles.len() - 2 * 5);
        assert_eq!(kept.vertices.len(), c.vertices.len());
    }
}

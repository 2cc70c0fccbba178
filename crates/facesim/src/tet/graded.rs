//! Graded isosurface stuffing: the stencils and warping of `stuffing` on a graded background
//! mesh built from a 2:1-balanced octree (our construction, in the spirit of Labelle &
//! Shewchuk 2007 §4, not their exact lattice).
//!
//! Background mesh. Cubes of sizes h·2^l (l = 0..=levels) refined where `size` asks for less
//! than the cube's size; neighbours (across faces, edges and corners) differ by at most one
//! level. Each leaf cube is the cone from its centre over its boundary, triangulated per face:
//! - a face shared with a leaf of the same size: the BCC tetrahedra (centre, neighbour's
//!   centre, face edge), as in the uniform lattice;
//! - a face on a bigger neighbour or on the grid's border: triangles (face centre, face edge);
//! - a face on four smaller neighbours: the triangles of each of the four sub-faces.
//!
//! A face edge is halved at its midpoint exactly when a leaf smaller than the edge touches it
//! (then both sides see the midpoint); balance keeps it to one split. Every triangle is thus
//! decided by the face alone, so both sides agree: the mesh is conforming. In a uniform region
//! it is the BCC lattice.
//!
//! Stuffing on it: the same stencils; warping with α_long on axis-parallel edges and α_short
//! on the others, except at the points of transition tetrahedra (not whole BCC ones), which
//! never move: warping the flatter cones at a size change inverted elements on the real CT
//! (a big cube's centre and a small face's centre both pulled towards the face). The uniform
//! lattice's angle bounds are not proven there; `Quality` reports what was reached and
//! `crates/facesim/tests/library/tet_mesh.rs` checks it.

use super::stuffing::{
    ALPHA_LONG, ALPHA_SHORT, Filled, Implicit, NodeKind, Places, Ref, Stuffed, classify, compact,
    cut_on_edge, fill, orient,
};
use crate::error::{Error, Result};
use crate::vec3::sub;
use rayon::prelude::*;
use std::collections::HashMap;

/// Background lattices beyond this many fine cells are refused.
const MAX_FINE_CELLS: usize = 40_000_000;

/// A cube's wanted size (mm) from its LPS bounds: the smallest size asked for inside it.
pub(crate) type Sizing<'a> = &'a (dyn Fn([f64; 3], [f64; 3]) -> f64 + Sync);

/// The graded background: points in doubled fine coordinates (units of h/2 from `origin`),
/// positively oriented tetrahedra, the box in the same units.
pub struct Background {
    pub origin: [f64; 3],
    pub unit: f64,
    pub points: Vec<[i64; 3]>,
    pub tets: Vec<[u32; 4]>,
    /// Points of a tetrahedron that is not a whole BCC tetrahedron (at a size change or on the
    /// grid's border): never warped.
    pub transition: Vec<bool>,
    pub box_lo: [f64; 3],
    pub box_hi: [f64; 3],
}

impl Background {
    fn point(&self, d: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|a| self.origin[a] + self.unit * d[a])
    }
    fn g(&self, d: [f64; 3]) -> f64 {
        (0..3)
            .map(|a| (self.box_lo[a] - d[a]).max(d[a] - self.box_hi[a]))
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// The octree: the leaf level of every fine cell.
struct Octree {
    /// Fine cells per axis.
    n: [i64; 3],
    levels: u32,
    leaf: Vec<u8>,
}

impl Octree {
    fn level(&self, c: [i64; 3]) -> Option<u8> {
        if (0..3).any(|a| c[a] < 0 || c[a] >= self.n[a]) {
            return None;
        }
        Some(self.leaf[(c[0] + self.n[0] * (c[1] + self.n[1] * c[2])) as usize])
    }
    fn set(&mut self, o: [i64; 3], s: i64, l: u8) {
        for k in o[2]..o[2] + s {
            for j in o[1]..o[1] + s {
                for i in o[0]..o[0] + s {
                    self.leaf[(i + self.n[0] * (j + self.n[1] * k)) as usize] = l;
                }
            }
        }
    }
    /// Leaves at level l: origins (fine coordinates) of the aligned cubes whose cells are l.
    fn leaves(&self, l: u32) -> Vec<[i64; 3]> {
        let s = 1i64 << l;
        let mut out = Vec::new();
        for k in (0..self.n[2]).step_by(s as usize) {
            for j in (0..self.n[1]).step_by(s as usize) {
                for i in (0..self.n[0]).step_by(s as usize) {
                    if self.level([i, j, k]) == Some(l as u8) {
                        out.push([i, j, k]);
                    }
                }
            }
        }
        out
    }
    /// The smallest leaf level among the fine cells touching cube (o, s) from outside.
    fn min_around(&self, o: [i64; 3], s: i64) -> u8 {
        let mut m = u8::MAX;
        for k in o[2] - 1..=o[2] + s {
            for j in o[1] - 1..=o[1] + s {
                for i in o[0] - 1..=o[0] + s {
                    let inside = (o[0]..o[0] + s).contains(&i)
                        && (o[1]..o[1] + s).contains(&j)
                        && (o[2]..o[2] + s).contains(&k);
                    if let Some(l) = self.level([i, j, k]).filter(|_| !inside) {
                        m = m.min(l);
                    }
                }
            }
        }
        m
    }
    /// Whether the edge from fine point a along axis b, length 2^q, is halved: a leaf smaller
    /// than the edge touches it (such a leaf has a corner at the midpoint).
    fn split(&self, a: [i64; 3], axis: usize, q: u32) -> bool {
        if q == 0 {
            return false;
        }
        let mut m = a;
        m[axis] += 1 << (q - 1);
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for db in [-1, 0] {
            for du in [-1, 0] {
                for dv in [-1, 0] {
                    let mut c = m;
                    c[axis] += db;
                    c[u] += du;
                    c[v] += dv;
                    if self.level(c).is_some_and(|l| (l as u32) < q) {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Build the graded background over the box (lo, hi): finest size h, up to `levels` doublings,
/// the box rounded up to whole coarsest cubes, one coarsest cube of padding around it.
pub fn background(
    lo: [f64; 3],
    hi: [f64; 3],
    h: f64,
    levels: u32,
    size: Sizing,
) -> Result<Background> {
    if !(h.is_finite() && h > 0.0) || levels > 6 {
        return Err(Error::config(format!(
            "graded stuffing: need a positive size and at most 6 levels, got {h} mm and {levels}"
        )));
    }
    if (0..3).any(|a| !(lo[a].is_finite() && hi[a].is_finite() && hi[a] > lo[a])) {
        return Err(Error::config(format!(
            "graded stuffing: empty or invalid box {lo:?} .. {hi:?}"
        )));
    }
    let big = h * f64::from(1u32 << levels);
    let coarse = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / big - 1e-9).ceil().max(1.0) as i64 + 2);
    let s_top = 1i64 << levels;
    let n = coarse.map(|c| c * s_top);
    let cells: f64 = n.iter().map(|x| *x as f64).product();
    if cells > MAX_FINE_CELLS as f64 {
        return Err(Error::config(format!(
            "graded stuffing: a {h} mm lattice over {:?} mm has {cells:.0} cells, more than {MAX_FINE_CELLS}",
            [0, 1, 2].map(|a| hi[a] - lo[a])
        )));
    }
    let origin = [0, 1, 2].map(|a| lo[a] - big);
    let mut tree = Octree {
        n,
        levels,
        leaf: vec![levels as u8; n.iter().product::<i64>() as usize],
    };
    let mm = |c: [i64; 3]| [0, 1, 2].map(|a| origin[a] + h * c[a] as f64);
    // Refine top-down where the size asks for it, the padding too: a size change on the box's
    // faces would put transition tetrahedra where the surfaces cross the cut.
    for l in (1..=levels).rev() {
        let s = 1i64 << l;
        let split: Vec<[i64; 3]> = tree
            .leaves(l)
            .into_par_iter()
            .filter(|o| {
                let (a, b) = (mm(*o), mm([o[0] + s, o[1] + s, o[2] + s]));
                size(a, b) < h * s as f64 * (1.0 - 1e-9)
            })
            .collect();
        for o in split {
            tree.set(o, s, (l - 1) as u8);
        }
    }
    // 2:1 balance across faces, edges and corners.
    loop {
        let mut changed = false;
        for l in (2..=levels).rev() {
            let s = 1i64 << l;
            let split: Vec<[i64; 3]> = tree
                .leaves(l)
                .into_par_iter()
                .filter(|o| (tree.min_around(*o, s) as u32) + 1 < l)
                .collect();
            changed |= !split.is_empty();
            for o in split {
                tree.set(o, s, (l - 1) as u8);
            }
        }
        if !changed {
            break;
        }
    }
    let box_lo = [2.0 * s_top as f64; 3];
    let box_hi = coarse.map(|c| 2.0 * ((c - 1) * s_top) as f64);
    let (points, tets, transition) = tetrahedralise(&tree);
    Ok(Background {
        origin,
        unit: 0.5 * h,
        points,
        tets,
        transition,
        box_lo,
        box_hi,
    })
}

/// The cone tetrahedra of every leaf (see the module notes), in doubled fine coordinates.
type Tets = Vec<([[i64; 3]; 4], bool)>;

fn tetrahedralise(tree: &Octree) -> (Vec<[i64; 3]>, Vec<[u32; 4]>, Vec<bool>) {
    let per_leaf: Vec<Tets> = (0..=tree.levels)
        .flat_map(|l| tree.leaves(l).into_iter().map(move |o| (l, o)))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|(l, o)| leaf_tets(tree, l, o))
        .collect();
    let dims = tree.n.map(|x| 2 * x + 1);
    let mut id = vec![u32::MAX; (dims[0] * dims[1] * dims[2]) as usize];
    let mut points = Vec::new();
    let mut tets = Vec::new();
    let mut transition = Vec::new();
    for (t, bcc) in per_leaf.iter().flatten() {
        let mut r = [0u32; 4];
        for k in 0..4 {
            let p = t[k];
            let i = (p[0] + dims[0] * (p[1] + dims[1] * p[2])) as usize;
            if id[i] == u32::MAX {
                id[i] = points.len() as u32;
                points.push(p);
                transition.push(false);
            }
            r[k] = id[i];
            transition[id[i] as usize] |= !bcc;
        }
        tets.push(r);
    }
    (points, tets, transition)
}

/// The leaf's tetrahedra, each marked whether it is a whole BCC tetrahedron.
fn leaf_tets(tree: &Octree, l: u32, o: [i64; 3]) -> Tets {
    let s = 1i64 << l;
    let c: [i64; 3] = o.map(|x| 2 * x + s);
    let mut out = Vec::new();
    let mut push = |mut t: [[i64; 3]; 4], bcc: bool| {
        if orient(t.map(|p| p.map(|x| x as f64))) < 0.0 {
            t.swap(2, 3);
        }
        out.push((t, bcc));
    };
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0, 1] {
            // The face's lowest corner (fine) and the cell just across it.
            let mut f0 = o;
            f0[axis] += side * s;
            let mut across = o;
            across[axis] += if side == 0 { -1 } else { s };
            let neighbour = tree.level(across);
            match neighbour {
                Some(nl) if nl as u32 == l => {
                    if side == 1 {
                        let mut c2 = c;
                        c2[axis] += 2 * s;
                        let edges = face_edges(tree, f0, axis, l);
                        let whole = edges.len() == 4;
                        for (a, b) in edges {
                            push([c, c2, a, b], whole);
                        }
                    }
                }
                Some(nl) if (nl as u32) < l => {
                    let h2 = s / 2;
                    for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let mut q = f0;
                        q[u] += du * h2;
                        q[v] += dv * h2;
                        let fc = face_centre(q, axis, h2);
                        for (a, b) in face_edges(tree, q, axis, l - 1) {
                            push([c, fc, a, b], false);
                        }
                    }
                }
                _ => {
                    let fc = face_centre(f0, axis, s);
                    for (a, b) in face_edges(tree, f0, axis, l) {
                        push([c, fc, a, b], false);
                    }
                }
            }
        }
    }
    out
}

/// Centre (doubled) of the face with lowest fine corner q, normal `axis`, side s.
fn face_centre(q: [i64; 3], axis: usize, s: i64) -> [i64; 3] {
    let mut p = q.map(|x| 2 * x);
    p[(axis + 1) % 3] += s;
    p[(axis + 2) % 3] += s;
    p
}

/// The boundary segments (doubled coordinates) of the face with lowest fine corner q, normal
/// `axis`, side 2^q_level: its four edges, halved where `Octree::split` says so.
fn face_edges(tree: &Octree, q: [i64; 3], axis: usize, level: u32) -> Vec<([i64; 3], [i64; 3])> {
    let s = 1i64 << level;
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let at = |du: i64, dv: i64| {
        let mut p = q;
        p[u] += du;
        p[v] += dv;
        p
    };
    // Edges as (start corner, direction axis).
    let edges = [(at(0, 0), u), (at(0, s), u), (at(0, 0), v), (at(s, 0), v)];
    let mut out = Vec::with_capacity(8);
    for (a, dir) in edges {
        let mut b = a;
        b[dir] += s;
        let (da, db) = (a.map(|x| 2 * x), b.map(|x| 2 * x));
        if tree.split(a, dir, level) {
            let mut m = da;
            m[dir] += s;
            out.push((da, m));
            out.push((m, db));
        } else {
            out.push((da, db));
        }
    }
    out
}

struct Cut {
    neg: u32,
    pos: u32,
    t: f64,
    kind: NodeKind,
}

/// Stuff {f < 0} ∩ box on a graded background (see `background`).
pub fn stuff_graded(f: Implicit, bg: &Background) -> Result<Stuffed> {
    let np = bg.points.len();
    let pd = |i: u32| bg.points[i as usize].map(|x| x as f64);
    let values: Vec<(f64, f64)> = (0..np as u32)
        .into_par_iter()
        .map(|i| (f(bg.point(pd(i))), bg.g(pd(i))))
        .collect();
    if let Some(i) = values.iter().position(|(v, _)| !v.is_finite()) {
        return Err(Error::config(format!(
            "stuffing: the implicit function is not finite at {:?}",
            bg.point(pd(i as u32))
        )));
    }
    let mut sign: Vec<i8> = values.iter().map(|(a, b)| classify(*a, *b).0).collect();
    let mut kind: Vec<NodeKind> = values.iter().map(|(a, b)| classify(*a, *b).1).collect();
    let cuts = cuts_of(f, bg, &values, &sign);
    let (warped, alive) = warp(bg, &cuts, &mut sign, &mut kind);
    let cut_index: HashMap<(u32, u32), u32> = cuts
        .iter()
        .enumerate()
        .filter(|(i, _)| alive[*i])
        .map(|(i, c)| ((c.neg, c.pos), i as u32))
        .collect();
    let cut_point = |c: &Cut| {
        let (a, b) = (pd(c.neg), pd(c.pos));
        bg.point([0, 1, 2].map(|k| a[k] + c.t * (b[k] - a[k])))
    };
    let vertex_point = |v: usize| match warped[v] {
        Some(c) => cut_point(&cuts[c as usize]),
        None => bg.point(pd(v as u32)),
    };
    let position = |r: Ref| match r {
        Ref::Vertex(v) => vertex_point(v),
        Ref::Cut(c) => cut_point(&cuts[c]),
        Ref::Centre(_) => [f64::NAN; 3],
    };
    let reference = |r: Ref| match r {
        Ref::Vertex(v) => pd(v as u32),
        Ref::Cut(c) => {
            let (a, b) = (pd(cuts[c].neg), pd(cuts[c].pos));
            [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]))
        }
        Ref::Centre(_) => [f64::NAN; 3],
    };
    let dist2 = |a: Ref, b: Ref| {
        let d = sub(position(a), position(b));
        d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    };
    let filled: Vec<Filled> = bg
        .tets
        .par_chunks(4096)
        .map(|chunk| {
            let mut out = Filled::default();
            for t in chunk {
                let ids = t.map(|v| v as usize);
                let s = ids.map(|v| sign[v]);
                if s.iter().all(|x| *x >= 0) && s.iter().any(|x| *x > 0) {
                    continue;
                }
                let cut = |a: usize, b: usize| {
                    cut_index
                        .get(&(a as u32, b as u32))
                        .map(|c| Ref::Cut(*c as usize))
                };
                let _ = fill(&ids, &s, &cut, &dist2, &mut out);
            }
            out
        })
        .collect();
    compact(
        &filled,
        (np, cuts.len()),
        &|v| sign[v] == 0,
        &|c| {
            let d = [0, 1, 2].map(|a| (c[a] - bg.origin[a]) / bg.unit);
            f(c) < 0.0 && bg.g(d) < 0.0
        },
        &Places {
            position: &position,
            reference: &reference,
            vertex: &|v| (vertex_point(v), kind[v]),
            cut: &|c| (cut_point(&cuts[c]), cuts[c].kind),
        },
        (bg.point(bg.box_lo), bg.point(bg.box_hi)),
        "graded stuffing",
    )
}

/// The cut points of the edges with strictly opposite signs, from the tetrahedra that have both.
fn cuts_of(f: Implicit, bg: &Background, values: &[(f64, f64)], sign: &[i8]) -> Vec<Cut> {
    let pd = |i: u32| bg.points[i as usize].map(|x| x as f64);
    let mut pairs: Vec<(u32, u32)> = bg
        .tets
        .par_iter()
        .flat_map_iter(|t| {
            (0..4).flat_map(move |a| {
                (0..4).filter_map(move |b| {
                    (sign[t[a] as usize] < 0 && sign[t[b] as usize] > 0).then_some((t[a], t[b]))
                })
            })
        })
        .collect();
    pairs.par_sort_unstable();
    pairs.dedup();
    pairs
        .par_iter()
        .map(|&(u, w)| {
            let (t, kind) = cut_on_edge(
                pd(u),
                pd(w),
                (
                    values[u as usize].0,
                    values[w as usize].0,
                    values[w as usize].1,
                ),
                (bg.box_lo, bg.box_hi),
                |d| f(bg.point(d)),
            );
            Cut {
                neg: u,
                pos: w,
                t,
                kind,
            }
        })
        .collect()
}

/// Warping, vertex by vertex in index order (transition vertices stay): a vertex with a cut
/// point near it moves to the nearest, takes its sign (0) and kind, and its other cuts die. Per
/// vertex: the cut it moved to; per cut: whether it survives.
fn warp(
    bg: &Background,
    cuts: &[Cut],
    sign: &mut [i8],
    kind: &mut [NodeKind],
) -> (Vec<Option<u32>>, Vec<bool>) {
    let np = bg.points.len();
    let pd = |i: u32| bg.points[i as usize].map(|x| x as f64);
    let mut per_vertex: Vec<Vec<u32>> = vec![Vec::new(); np];
    for (i, c) in cuts.iter().enumerate() {
        per_vertex[c.neg as usize].push(i as u32);
        per_vertex[c.pos as usize].push(i as u32);
    }
    let mut alive = vec![true; cuts.len()];
    let mut warped: Vec<Option<u32>> = vec![None; np];
    for v in (0..np).filter(|v| !bg.transition[*v]) {
        let mut best: Option<(f64, u32)> = None;
        for &c in &per_vertex[v] {
            let cut = &cuts[c as usize];
            if !alive[c as usize] {
                continue;
            }
            let e = sub(pd(cut.pos), pd(cut.neg));
            let len = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
            let axis_parallel = e.iter().filter(|x| **x != 0.0).count() == 1;
            let alpha = if axis_parallel {
                ALPHA_LONG
            } else {
                ALPHA_SHORT
            };
            let frac = if cut.neg as usize == v {
                cut.t
            } else {
                1.0 - cut.t
            };
            if frac < alpha && best.is_none_or(|(d, _)| frac * len < d) {
                best = Some((frac * len, c));
            }
        }
        if let Some((_, c)) = best {
            warped[v] = Some(c);
            sign[v] = 0;
            kind[v] = cuts[c as usize].kind;
            for &c2 in &per_vertex[v] {
                alive[c2 as usize] = false;
            }
        }
    }
    (warped, alive)
}

//! Isosurface stuffing (Labelle & Shewchuk, "Isosurface stuffing: fast tetrahedral meshes with
//! good dihedral angles", SIGGRAPH 2007): a tetrahedral mesh of {p : f(p) < 0} inside a box,
//! from the body-centred cubic (BCC) lattice.
//!
//! 1. The BCC lattice: the corners of cubes of side h plus their centres. In *doubled* integer
//!    coordinates (units of h/2) the corners have all-even and the centres all-odd coordinates.
//!    Long edges (length h) join neighbours of one grid, short edges (√3 h/2) a corner and a
//!    centre. Each BCC tetrahedron has one corner-grid long edge, one centre-grid long edge
//!    perpendicular to it and four short edges; twelve per cube.
//! 2. The value at each lattice vertex is F = max(f, g) with g the box's distance function, so
//!    the box is a second iso-surface: with its faces on lattice planes, lattice vertices on
//!    them are exactly zero and the box's cut faces keep lattice quality (BCC tetrahedra halved
//!    by the plane; no warping happens there, since those cut points sit mid-edge).
//! 3. Cut points: on each edge whose ends have strictly opposite signs, the zero of f (bisection
//!    on f itself, then one secant step) or of g (exact, g is linear on the edge): `cut_on_edge`,
//!    shared with the graded stuffing.
//! 4. Warping (paper §3): a lattice vertex closer to a cut point on one of its edges than α times
//!    that edge's length (α_long = 0.24999, α_short = 0.41189) moves onto the nearest such cut
//!    point and becomes zero; the cut points on its edges disappear.
//! 5. Stencils: each BCC tetrahedron is filled by the signs of its four vertices (−, 0, +):
//!    no + → the whole tetrahedron; one − → one tetrahedron; two − with a zero → a pyramid
//!    (two); two − and two +, or three − and one + → a prism (three). A quadrilateral on a
//!    lattice face takes its shorter diagonal (ties to the lower lattice index): it depends on
//!    the face's four points alone, so the two tetrahedra sharing the face agree. Where a
//!    prism's three diagonals form a cycle (no vertex meets two of them; Dompierre et al. 1999,
//!    "How to subdivide pyramids, prisms and hexahedra into tetrahedra") it is split into
//!    eight around a centre point; the surface quadrilateral inside a 2–2 prism is chosen to
//!    avoid the cycle. (A fixed rank rule, the diagonal through the lower-index vertex, is
//!    cycle-free without centre points but gave 9.96° on the real CT at 2.5 mm.)
//! 6. A tetrahedron with all four corners warped onto the surface is kept when F < 0 at its
//!    centroid, unless the warp flattened it beyond the angle bounds: two opposite long edges
//!    can both be pulled (each by < α_long h) onto a surface lying between two lattice layers,
//!    leaving a sliver of the surface (5.9° on the real CT at 2 mm); leaving it out moves the
//!    boundary by its thickness and keeps the mesh conforming. `Stuffed::flattened` counts them.
//!
//! The paper proves dihedral angles within [10.7°, 164.8°] for these α with its own stencils.
//! Ours differ in the quadrilateral rule (5) and in leaving out flattened all-zero tetrahedra
//! (6), so here the bound is checked rather than proven: `crates/facesim/tests/library/tet_mesh.rs` asserts it on
//! spheres, shells, a cut shell, the phantom and the real CT. Orientation is decided on the
//! unwarped lattice (cut points at edge midpoints), where every stencil tetrahedron is non-degenerate; a tetrahedron
//! the warp flattened or inverted would be a reported numerical failure, never a silent one.

use crate::error::{Error, NumericalKind, Result};
use crate::vec3::{cross, sub};
use rayon::prelude::*;

/// Warping thresholds of the paper for the [10.7°, 164.8°] dihedral bounds.
pub(crate) const ALPHA_LONG: f64 = 0.24999;
pub(crate) const ALPHA_SHORT: f64 = 0.41189;
/// The proven dihedral angle bounds (degrees) of uniform stuffing with these α.
pub const MIN_DIHEDRAL_BOUND_DEG: f64 = 10.7;
pub const MAX_DIHEDRAL_BOUND_DEG: f64 = 164.8;

/// Lattices beyond this many vertices are refused (a size typo, not a mesh).
const MAX_LATTICE_VERTICES: usize = 60_000_000;

/// Where a node lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum NodeKind {
    Interior,
    /// On the iso-surface f = 0.
    Surface,
    /// On a face of the restricting box, not on f = 0.
    Cut,
}

/// A stuffed mesh: nodes, positively oriented tetrahedra, the kind of each node.
pub struct Stuffed {
    pub nodes: Vec<[f64; 3]>,
    pub tets: Vec<[u32; 4]>,
    pub kind: Vec<NodeKind>,
    /// Tetrahedra with all four corners warped onto the surface and flattened beyond the
    /// angle bounds, left out (see `stuff`).
    pub flattened: usize,
    /// The box the lattice filled (mm): from the asked box's lower corner, whole cells of the
    /// lattice's (coarsest) size up past its upper one. Its faces are where `Cut` nodes lie.
    pub bounds: ([f64; 3], [f64; 3]),
}

/// The implicit domain function: negative inside.
pub(crate) type Implicit<'a> = &'a (dyn Fn([f64; 3]) -> f64 + Sync);

/// The 14 lattice neighbours in doubled coordinates: 6 long, then 8 short.
const NEIGHBOURS: [[i64; 3]; 14] = [
    [2, 0, 0],
    [-2, 0, 0],
    [0, 2, 0],
    [0, -2, 0],
    [0, 0, 2],
    [0, 0, -2],
    [1, 1, 1],
    [1, 1, -1],
    [1, -1, 1],
    [1, -1, -1],
    [-1, 1, 1],
    [-1, 1, -1],
    [-1, -1, 1],
    [-1, -1, -1],
];

fn neighbour_slot(d: [i64; 3]) -> Option<usize> {
    NEIGHBOURS.iter().position(|n| *n == d)
}

/// The BCC lattice over a box: `n` cubes per axis with one padding cube around the box.
struct Lattice {
    origin: [f64; 3],
    h: f64,
    n: [i64; 3],
    /// The box in doubled coordinates.
    box_lo: [f64; 3],
    box_hi: [f64; 3],
}

impl Lattice {
    fn new(lo: [f64; 3], hi: [f64; 3], h: f64) -> Result<Lattice> {
        if !(h.is_finite() && h > 0.0) {
            return Err(Error::config(format!(
                "stuffing: the lattice spacing must be positive, got {h} mm"
            )));
        }
        if (0..3).any(|a| !(lo[a].is_finite() && hi[a].is_finite() && hi[a] > lo[a])) {
            return Err(Error::config(format!(
                "stuffing: empty or invalid box {lo:?} .. {hi:?}"
            )));
        }
        let cubes = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / h - 1e-9).ceil().max(1.0));
        let total: f64 = cubes.iter().map(|c| c + 3.0).product::<f64>() * 2.0;
        if total > MAX_LATTICE_VERTICES as f64 {
            return Err(Error::config(format!(
                "stuffing: a {h} mm lattice over {:?} mm has {total:.0} vertices, more than {MAX_LATTICE_VERTICES}",
                [0, 1, 2].map(|a| hi[a] - lo[a])
            )));
        }
        Ok(Lattice {
            origin: [0, 1, 2].map(|a| lo[a] - h),
            h,
            n: cubes.map(|c| c as i64 + 2),
            box_lo: [2.0; 3],
            box_hi: cubes.map(|c| 2.0 + 2.0 * c),
        })
    }

    fn corners(&self) -> usize {
        self.n.iter().map(|n| (n + 1) as usize).product()
    }
    fn vertices(&self) -> usize {
        self.corners() + self.n.iter().map(|n| *n as usize).product::<usize>()
    }

    fn coords(&self, v: usize) -> [i64; 3] {
        let np = self.corners();
        let (v, m, odd) = if v < np {
            (v as i64, self.n.map(|n| n + 1), 0)
        } else {
            ((v - np) as i64, self.n, 1)
        };
        [
            2 * (v % m[0]) + odd,
            2 * ((v / m[0]) % m[1]) + odd,
            2 * (v / (m[0] * m[1])) + odd,
        ]
    }

    fn id(&self, d: [i64; 3]) -> Option<usize> {
        let odd = d[0].rem_euclid(2);
        if d.iter().any(|x| x.rem_euclid(2) != odd) {
            return None;
        }
        let (m, base) = if odd == 0 {
            (self.n.map(|n| n + 1), 0)
        } else {
            (self.n, self.corners())
        };
        let i = d.map(|x| (x - odd) / 2);
        if (0..3).any(|a| i[a] < 0 || i[a] >= m[a]) {
            return None;
        }
        Some(base + (i[0] + m[0] * (i[1] + m[1] * i[2])) as usize)
    }

    fn point(&self, d: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|a| self.origin[a] + 0.5 * self.h * d[a])
    }

    /// The box's distance-like function in doubled coordinates (≤ 0 inside).
    fn g(&self, d: [f64; 3]) -> f64 {
        (0..3)
            .map(|a| (self.box_lo[a] - d[a]).max(d[a] - self.box_hi[a]))
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// Sign and kind of a lattice value pair (f at the point, g of the box).
pub(super) fn classify(f: f64, g: f64) -> (i8, NodeKind) {
    if g > 0.0 || f > 0.0 {
        (1, NodeKind::Interior)
    } else if f < 0.0 && g < 0.0 {
        (-1, NodeKind::Interior)
    } else if f == 0.0 {
        (0, NodeKind::Surface)
    } else {
        (0, NodeKind::Cut)
    }
}

struct Cut {
    /// The negative end and the slot of the edge towards the positive end.
    from: usize,
    slot: usize,
    /// Fraction of the edge from the negative end.
    t: f64,
    kind: NodeKind,
}

/// Where the edge from a negative point `a` to a positive point `b` (doubled lattice
/// coordinates, the uniform and the graded stuffing alike) leaves {F < 0}, as the fraction of the
/// edge from `a` (in [0, 1]) and the kind of the cut: `Surface` where f = 0 comes first, `Cut`
/// where a face of the box does. `ends` is (f(a), f(b), g(b)); `f_at` is f at a point in
/// doubled coordinates. f's zero: 12 bisections on f itself, then one secant step in the final
/// bracket (f is smooth at that scale). The box's: exact, g is linear along each of its planes;
/// the first plane crossed. `a` is strictly inside the box (it is negative), so only planes `b`
/// lies strictly beyond can be crossed.
pub(super) fn cut_on_edge(
    a: [f64; 3],
    b: [f64; 3],
    ends: (f64, f64, f64),
    (box_lo, box_hi): ([f64; 3], [f64; 3]),
    f_at: impl Fn([f64; 3]) -> f64,
) -> (f64, NodeKind) {
    let (mut f0, mut f1, gb) = ends;
    let mut tg = f64::INFINITY;
    if gb > 0.0 {
        for k in 0..3 {
            for plane in [box_lo[k], box_hi[k]] {
                let (ga, gb) = (a[k] - plane, b[k] - plane);
                let out = if plane == box_lo[k] {
                    ga > 0.0 && gb < 0.0
                } else {
                    ga < 0.0 && gb > 0.0
                };
                if out {
                    tg = tg.min(ga / (ga - gb));
                }
            }
        }
    }
    let mut tf = f64::INFINITY;
    if f1 > 0.0 {
        let at = |t: f64| [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
        let (mut t0, mut t1) = (0.0, 1.0);
        for _ in 0..12 {
            let tm = 0.5 * (t0 + t1);
            let fm = f_at(at(tm));
            if fm < 0.0 {
                (t0, f0) = (tm, fm);
            } else {
                (t1, f1) = (tm, fm);
            }
        }
        tf = if f1 > f0 {
            t0 + (t1 - t0) * (-f0 / (f1 - f0))
        } else {
            t1
        };
    }
    let (t, kind) = if tf <= tg {
        (tf, NodeKind::Surface)
    } else {
        (tg, NodeKind::Cut)
    };
    (t.clamp(0.0, 1.0), kind)
}

pub(super) fn orient(x: [[f64; 3]; 4]) -> f64 {
    let (a, b, c) = (sub(x[1], x[0]), sub(x[2], x[0]), sub(x[3], x[0]));
    let n = cross(a, b);
    n[0] * c[0] + n[1] * c[1] + n[2] * c[2]
}

/// The twelve BCC tetrahedra owned by a corner-grid vertex (offsets in doubled coordinates),
/// positively oriented: its long edge along +a and the centre-grid edges perpendicular to it.
fn bcc_patterns() -> Vec<[[i64; 3]; 4]> {
    let mut out = Vec::with_capacity(12);
    for a in 0..3 {
        for b in 0..3 {
            if b == a {
                continue;
            }
            let c = 3 - a - b;
            for s in [-1, 1] {
                let mut t = [[0i64; 3]; 4];
                t[1][a] = 2;
                for k in [2, 3] {
                    t[k][a] = 1;
                    t[k][c] = s;
                    t[k][b] = if k == 2 { -1 } else { 1 };
                }
                if orient(t.map(|v| v.map(|x| x as f64))) < 0.0 {
                    t.swap(2, 3);
                }
                out.push(t);
            }
        }
    }
    out
}

/// A node reference while stencils are filled: a lattice vertex, a cut point (by index) or a
/// prism's centre point.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Ref {
    Vertex(usize),
    Cut(usize),
    /// The k-th centre point of the current corner's prisms.
    Centre(usize),
}

/// Mesh {f < 0} ∩ box with BCC lattice spacing `h` (mm). The box faces are lattice planes
/// (its upper corner rounds up to a whole number of cubes).
pub fn stuff(f: Implicit, lo: [f64; 3], hi: [f64; 3], h: f64) -> Result<Stuffed> {
    let lat = Lattice::new(lo, hi, h)?;
    let nv = lat.vertices();
    let (values, mut sign, mut kind) = lattice_values(&lat, f)?;
    let cuts = cut_points(&lat, f, &sign, &values);
    let (warped, alive) = warp(&lat, &cuts, &mut sign, &mut kind);
    // The surviving cut point of each (negative vertex, slot).
    let mut cut_at = vec![u32::MAX; nv * 14];
    for (i, c) in cuts.iter().enumerate() {
        if alive[i] {
            cut_at[c.from * 14 + c.slot] = i as u32;
        }
    }

    // Positions: lattice vertices (possibly warped) and cut points.
    let cut_point = |c: &Cut| -> [f64; 3] {
        let a = lat.coords(c.from).map(|x| x as f64);
        let off = NEIGHBOURS[c.slot];
        lat.point([0, 1, 2].map(|k| a[k] + c.t * off[k] as f64))
    };
    let vertex_point = |v: usize| -> [f64; 3] {
        match warped[v] {
            Some(c) => cut_point(&cuts[c]),
            None => lat.point(lat.coords(v).map(|x| x as f64)),
        }
    };
    let position = |r: Ref| -> [f64; 3] {
        match r {
            Ref::Vertex(v) => vertex_point(v),
            Ref::Cut(c) => cut_point(&cuts[c]),
            Ref::Centre(_) => [f64::NAN; 3],
        }
    };
    // Reference positions (doubled coordinates, unwarped, cuts mid-edge) for orientation.
    let reference = |r: Ref| -> [f64; 3] {
        match r {
            Ref::Vertex(v) => lat.coords(v).map(|x| x as f64),
            Ref::Cut(c) => {
                let a = lat.coords(cuts[c].from);
                let off = NEIGHBOURS[cuts[c].slot];
                [0, 1, 2].map(|k| a[k] as f64 + 0.5 * off[k] as f64)
            }
            Ref::Centre(_) => [f64::NAN; 3],
        }
    };
    let dist2 = |a: Ref, b: Ref| {
        let d = sub(position(a), position(b));
        d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    };
    let filled = fill_stencils(&lat, &sign, &cut_at, &dist2);
    compact(
        &filled,
        (nv, cuts.len()),
        &|v| sign[v] == 0,
        &|c| {
            let d = [0, 1, 2].map(|a| (c[a] - lat.origin[a]) * 2.0 / lat.h);
            f(c) < 0.0 && lat.g(d) < 0.0
        },
        &Places {
            position: &position,
            reference: &reference,
            vertex: &|v| (vertex_point(v), kind[v]),
            cut: &|c| (cut_point(&cuts[c]), cuts[c].kind),
        },
        (lat.point(lat.box_lo), lat.point(lat.box_hi)),
        "stuffing",
    )
}

/// Per lattice vertex: the implicit function and the box's distance function there, and the
/// vertex's sign and kind (`classify`); an error where the function is not finite.
#[allow(clippy::type_complexity)]
fn lattice_values(lat: &Lattice, f: Implicit) -> Result<(Vec<(f64, f64)>, Vec<i8>, Vec<NodeKind>)> {
    let nv = lat.vertices();
    let values: Vec<(f64, f64)> = (0..nv)
        .into_par_iter()
        .map(|v| {
            let d = lat.coords(v).map(|x| x as f64);
            (f(lat.point(d)), lat.g(d))
        })
        .collect();
    if let Some(v) = values.iter().position(|(fv, _)| !fv.is_finite()) {
        let d = lat.coords(v).map(|x| x as f64);
        return Err(Error::config(format!(
            "stuffing: the implicit function is not finite at {:?}",
            lat.point(d)
        )));
    }
    let mut sign: Vec<i8> = Vec::with_capacity(nv);
    let mut kind: Vec<NodeKind> = Vec::with_capacity(nv);
    for (fv, g) in &values {
        let (s, k) = classify(*fv, *g);
        sign.push(s);
        kind.push(k);
    }
    Ok((values, sign, kind))
}

/// Cut points on the edges from each negative vertex to its positive neighbours.
fn cut_points(lat: &Lattice, f: Implicit, sign: &[i8], values: &[(f64, f64)]) -> Vec<Cut> {
    (0..lat.vertices())
        .into_par_iter()
        .filter(|v| sign[*v] < 0)
        .flat_map_iter(|u| {
            let du = lat.coords(u);
            NEIGHBOURS
                .iter()
                .enumerate()
                .filter_map(move |(slot, off)| {
                    let dw = [0, 1, 2].map(|a| du[a] + off[a]);
                    let w = lat.id(dw)?;
                    if sign[w] <= 0 {
                        return None;
                    }
                    let (t, kind) = cut_on_edge(
                        du.map(|x| x as f64),
                        dw.map(|x| x as f64),
                        (values[u].0, values[w].0, values[w].1),
                        (lat.box_lo, lat.box_hi),
                        |d| f(lat.point(d)),
                    );
                    Some(Cut {
                        from: u,
                        slot,
                        t,
                        kind,
                    })
                })
        })
        .collect()
}

/// Warping: a vertex with a cut point near it (within `ALPHA_LONG` or `ALPHA_SHORT` of the
/// edge) moves to the nearest, takes its sign (0) and kind, and its other cuts die. Per vertex:
/// the cut it moved to; per cut: whether it survives.
fn warp(
    lat: &Lattice,
    cuts: &[Cut],
    sign: &mut [i8],
    kind: &mut [NodeKind],
) -> (Vec<Option<usize>>, Vec<bool>) {
    let nv = lat.vertices();
    // Each vertex's cut edges (as the negative or the positive end).
    let mut per_vertex: Vec<Vec<(usize, bool)>> = vec![Vec::new(); nv];
    let to_of = |c: &Cut| -> usize {
        let d = lat.coords(c.from);
        let off = NEIGHBOURS[c.slot];
        lat.id([0, 1, 2].map(|a| d[a] + off[a]))
            .unwrap_or(usize::MAX)
    };
    let ends: Vec<(usize, usize)> = cuts.iter().map(|c| (c.from, to_of(c))).collect();
    for (i, (u, w)) in ends.iter().enumerate() {
        per_vertex[*u].push((i, true));
        if *w < nv {
            per_vertex[*w].push((i, false));
        }
    }
    let mut alive = vec![true; cuts.len()];
    let mut warped: Vec<Option<usize>> = vec![None; nv];
    let mut vertices_with_cuts: Vec<usize> =
        (0..nv).filter(|v| !per_vertex[*v].is_empty()).collect();
    vertices_with_cuts.sort_unstable();
    for v in vertices_with_cuts {
        let mut best: Option<(f64, usize)> = None;
        for &(c, neg_end) in &per_vertex[v] {
            if !alive[c] {
                continue;
            }
            let cut = &cuts[c];
            let (alpha, len) = if cut.slot < 6 {
                (ALPHA_LONG, 1.0)
            } else {
                (ALPHA_SHORT, 0.75f64.sqrt())
            };
            let frac = if neg_end { cut.t } else { 1.0 - cut.t };
            if frac < alpha {
                let dist = frac * len;
                if best.is_none_or(|(bd, _)| dist < bd) {
                    best = Some((dist, c));
                }
            }
        }
        if let Some((_, c)) = best {
            warped[v] = Some(c);
            sign[v] = 0;
            kind[v] = cuts[c].kind;
            for &(c2, _) in &per_vertex[v] {
                alive[c2] = false;
            }
        }
    }
    (warped, alive)
}

/// Per corner-grid vertex: its stencil tetrahedra and the prisms that needed a centre point
/// (`Ref::Centre(k)` is the k-th of that list). `cut_at`: the surviving cut point of each
/// (negative vertex, slot); `dist2`: squared distance between two references.
fn fill_stencils(
    lat: &Lattice,
    sign: &[i8],
    cut_at: &[u32],
    dist2: &(dyn Fn(Ref, Ref) -> f64 + Sync),
) -> Vec<Filled> {
    let patterns = bcc_patterns();
    let n = lat.n;
    (0..lat.corners())
        .into_par_iter()
        .map(|p| {
            let dp = lat.coords(p);
            let mut out = Filled::default();
            if dp.iter().zip(&n).any(|(d, n)| *d >= 2 * n) {
                return out;
            }
            for pat in &patterns {
                let mut ids = [0usize; 4];
                let mut inside = true;
                for k in 0..4 {
                    match lat.id([0, 1, 2].map(|a| dp[a] + pat[k][a])) {
                        Some(id) => ids[k] = id,
                        None => inside = false,
                    }
                }
                if !inside {
                    continue;
                }
                let s = ids.map(|v| sign[v]);
                if s.iter().all(|x| *x >= 0) && s.iter().any(|x| *x > 0) {
                    continue;
                }
                let cut = |a: usize, b: usize| -> Option<Ref> {
                    let da = lat.coords(a);
                    let db = lat.coords(b);
                    let slot = neighbour_slot([0, 1, 2].map(|k| db[k] - da[k]))?;
                    let c = cut_at[a * 14 + slot];
                    (c != u32::MAX).then_some(Ref::Cut(c as usize))
                };
                // Every mixed sign pattern has its cut points (they survive warping exactly
                // when both ends keep their signs), so a None here cannot happen.
                let _ = fill(&ids, &s, &cut, dist2, &mut out);
            }
            out
        })
        .collect()
}

/// Where the references of the filled stencils lie: their positions, their reference positions
/// (unwarped, for orientation) and, for lattice vertices and cut points, the node they become.
pub(super) struct Places<'a> {
    pub(super) position: &'a dyn Fn(Ref) -> [f64; 3],
    pub(super) reference: &'a dyn Fn(Ref) -> [f64; 3],
    pub(super) vertex: &'a dyn Fn(usize) -> ([f64; 3], NodeKind),
    pub(super) cut: &'a dyn Fn(usize) -> ([f64; 3], NodeKind),
}

/// The filled stencils as a mesh (the uniform and the graded stuffing share it): each used
/// lattice vertex, cut point and prism centre becomes one node; tetrahedra are oriented
/// positively by their reference positions. A tetrahedron whose four corners were all warped
/// onto the surface (`on_surface`) is kept when `inside` holds at its centroid, unless the warp
/// flattened it (two long edges pulled towards each other onto a surface lying between two
/// lattice layers): such a sliver is left out and counted — that moves the boundary by its
/// thickness, and any choice conforms (its faces are whole lattice faces).
/// The node a lattice vertex or cut point becomes: made at its first use.
fn node_of(
    slot: &mut u32,
    place: impl FnOnce() -> ([f64; 3], NodeKind),
    nodes: &mut Vec<[f64; 3]>,
    kinds: &mut Vec<NodeKind>,
) -> u32 {
    if *slot == u32::MAX {
        let (p, k) = place();
        *slot = nodes.len() as u32;
        nodes.push(p);
        kinds.push(k);
    }
    *slot
}

pub(super) fn compact(
    filled: &[Filled],
    (vertices, cuts): (usize, usize),
    on_surface: &dyn Fn(usize) -> bool,
    inside: &dyn Fn([f64; 3]) -> bool,
    at: &Places,
    bounds: ([f64; 3], [f64; 3]),
    what: &str,
) -> Result<Stuffed> {
    let mut vertex_node = vec![u32::MAX; vertices];
    let mut cut_node = vec![u32::MAX; cuts];
    let mut nodes: Vec<[f64; 3]> = Vec::new();
    let mut node_kind: Vec<NodeKind> = Vec::new();
    let mut tets: Vec<[u32; 4]> = Vec::new();
    let mut flattened = 0;
    for Filled {
        tets: local,
        centres,
    } in filled
    {
        // Centre points: one new interior node each, at the mean of its prism's corners.
        let mean = |x: [[f64; 3]; 6]| [0, 1, 2].map(|a| x.iter().map(|p| p[a]).sum::<f64>() / 6.0);
        let first_centre = nodes.len() as u32;
        for c in centres {
            nodes.push(mean(c.map(at.position)));
            node_kind.push(NodeKind::Interior);
        }
        let centre_ref: Vec<[f64; 3]> = centres.iter().map(|c| mean(c.map(at.reference))).collect();
        let refpos = |r: Ref| match r {
            Ref::Centre(k) => centre_ref[k],
            other => (at.reference)(other),
        };
        for t in local {
            let mut r = *t;
            if orient(r.map(refpos)) < 0.0 {
                r.swap(2, 3);
            }
            if t.iter()
                .all(|r| matches!(r, Ref::Vertex(v) if on_surface(*v)))
            {
                let x = t.map(at.position);
                let c = [0, 1, 2].map(|a| 0.25 * (x[0][a] + x[1][a] + x[2][a] + x[3][a]));
                if !inside(c) {
                    continue;
                }
                let within =
                    super::quality::tet_shape(r.map(at.position)).is_some_and(|(a, _, _)| {
                        a.iter()
                            .all(|x| (MIN_DIHEDRAL_BOUND_DEG..=MAX_DIHEDRAL_BOUND_DEG).contains(x))
                    });
                if !within {
                    flattened += 1;
                    continue;
                }
            }
            let mut tet = [0u32; 4];
            for k in 0..4 {
                tet[k] = match r[k] {
                    Ref::Vertex(v) => node_of(
                        &mut vertex_node[v],
                        || (at.vertex)(v),
                        &mut nodes,
                        &mut node_kind,
                    ),
                    Ref::Cut(c) => {
                        node_of(&mut cut_node[c], || (at.cut)(c), &mut nodes, &mut node_kind)
                    }
                    Ref::Centre(c) => first_centre + c as u32,
                };
            }
            tets.push(tet);
        }
    }
    if nodes.len() > u32::MAX as usize / 2 {
        return Err(Error::config(format!("{what}: too many nodes")));
    }
    let bad = tets
        .par_iter()
        .filter(|t| super::gradients(t.map(|v| nodes[v as usize])).is_none())
        .count();
    if bad > 0 {
        return Err(Error::numerical(
            NumericalKind::DegenerateElement,
            format!("{what} produced {bad} flat or inverted tetrahedra"),
        ));
    }
    Ok(Stuffed {
        nodes,
        tets,
        kind: node_kind,
        flattened,
        bounds,
    })
}

/// Tetrahedra of one corner's stencils, and the prisms among them split around a centre point.
#[derive(Default)]
pub(super) struct Filled {
    pub(super) tets: Vec<[Ref; 4]>,
    pub(super) centres: Vec<[Ref; 6]>,
}

/// The diagonal of quadrilateral (a, b, c_b, c_a) on a lattice face (a, b lattice vertices, c_a
/// and c_b the cut points on the edges from a and from b to the face's positive vertex): true
/// for a–c_b. The shorter one, which depends on the four points alone, so the two tetrahedra
/// sharing the face agree; ties go to the lower lattice index.
fn diagonal_through_a(
    a: (usize, Ref),
    b: (usize, Ref),
    ca: Ref,
    cb: Ref,
    dist2: &dyn Fn(Ref, Ref) -> f64,
) -> bool {
    let (da, db) = (dist2(a.1, cb), dist2(b.1, ca));
    if da != db { da < db } else { a.0 < b.0 }
}

/// Fill one BCC tetrahedron by the signs of its vertices; None when a needed cut is missing.
pub(super) fn fill(
    ids: &[usize; 4],
    s: &[i8; 4],
    cut: &dyn Fn(usize, usize) -> Option<Ref>,
    dist2: &dyn Fn(Ref, Ref) -> f64,
    out: &mut Filled,
) -> Option<()> {
    let v = |k: usize| Ref::Vertex(ids[k]);
    let neg: Vec<usize> = (0..4).filter(|k| s[*k] < 0).collect();
    let zero: Vec<usize> = (0..4).filter(|k| s[*k] == 0).collect();
    let pos: Vec<usize> = (0..4).filter(|k| s[*k] > 0).collect();
    if pos.is_empty() {
        // Whole tetrahedron (all-zero ones are decided later at their centroid).
        out.tets.push([v(0), v(1), v(2), v(3)]);
        return Some(());
    }
    let c = |a: usize, b: usize| cut(ids[a], ids[b]);
    let diag = |a: usize, b: usize, ca: Ref, cb: Ref| {
        diagonal_through_a((ids[a], v(a)), (ids[b], v(b)), ca, cb, dist2)
    };
    match (neg.len(), zero.len(), pos.len()) {
        (1, 0, 3) => {
            let a = neg[0];
            out.tets
                .push([v(a), c(a, pos[0])?, c(a, pos[1])?, c(a, pos[2])?]);
        }
        (1, 1, 2) => {
            let a = neg[0];
            out.tets
                .push([v(a), v(zero[0]), c(a, pos[0])?, c(a, pos[1])?]);
        }
        (1, 2, 1) => {
            let a = neg[0];
            out.tets.push([v(a), v(zero[0]), v(zero[1]), c(a, pos[0])?]);
        }
        (2, 1, 1) => {
            // Pyramid: apex z, base quadrilateral (a, b, c_bp, c_ap) on lattice face abp.
            let (a, b, z, p) = (neg[0], neg[1], zero[0], pos[0]);
            let (cap, cbp) = (c(a, p)?, c(b, p)?);
            if diag(a, b, cap, cbp) {
                out.tets.push([v(z), v(a), v(b), cbp]);
                out.tets.push([v(z), v(a), cbp, cap]);
            } else {
                out.tets.push([v(z), v(a), v(b), cap]);
                out.tets.push([v(z), v(b), cbp, cap]);
            }
        }
        (2, 0, 2) => {
            // Prism: ends (a, c_ap, c_aq) and (b, c_bp, c_bq).
            let (a, b, p, q) = (neg[0], neg[1], pos[0], pos[1]);
            let x = [v(a), c(a, p)?, c(a, q)?];
            let y = [v(b), c(b, p)?, c(b, q)?];
            // Quadrilateral 0 on face abp (true: a–c_bp), 2 on face abq (true: c_aq–b).
            let d0 = diag(a, b, x[1], y[1]);
            let d2 = !diag(a, b, x[2], y[2]);
            // Quadrilateral 1 is the surface inside this tetrahedron: its shorter diagonal,
            // unless that would close a cycle.
            let d1 = if d0 == d2 {
                !d0
            } else {
                dist2(x[1], y[2]) <= dist2(x[2], y[1])
            };
            prism(x, y, [d0, d1, d2], out);
        }
        (3, 0, 1) => {
            let p = pos[0];
            let x = [v(neg[0]), v(neg[1]), v(neg[2])];
            let y = [c(neg[0], p)?, c(neg[1], p)?, c(neg[2], p)?];
            let d = [0, 1, 2].map(|i| {
                let j = (i + 1) % 3;
                diag(neg[i], neg[j], y[i], y[j])
            });
            prism(x, y, d, out);
        }
        _ => return None,
    }
    Some(())
}

/// Split a prism with ends x and y (lateral edges x_i–y_i) into tetrahedra; `d[i]` picks the
/// diagonal of quadrilateral i (between lateral edges i and i + 1): x_i–y_{i+1} when true,
/// x_{i+1}–y_i when false. Three tetrahedra from a vertex where two diagonals meet; when the
/// three diagonals form a cycle no such vertex exists and the prism is split into eight
/// around a new centre point.
fn prism(x: [Ref; 3], y: [Ref; 3], d: [bool; 3], out: &mut Filled) {
    for i in 0..3 {
        let (prev, next) = ((i + 2) % 3, (i + 1) % 3);
        if d[i] && !d[prev] {
            // x_i sees y_prev, y_i, y_next: cut off that corner, then the pyramid x_i over
            // quadrilateral (x_next, x_prev, y_prev, y_next).
            out.tets.push([x[i], y[prev], y[i], y[next]]);
            if d[next] {
                out.tets.push([x[i], x[next], x[prev], y[prev]]);
                out.tets.push([x[i], x[next], y[prev], y[next]]);
            } else {
                out.tets.push([x[i], x[next], x[prev], y[next]]);
                out.tets.push([x[i], x[prev], y[prev], y[next]]);
            }
            return;
        }
        if !d[i] && d[prev] {
            out.tets.push([y[i], x[prev], x[i], x[next]]);
            if !d[next] {
                out.tets.push([y[i], y[next], y[prev], x[prev]]);
                out.tets.push([y[i], y[next], x[prev], x[next]]);
            } else {
                out.tets.push([y[i], y[next], y[prev], x[next]]);
                out.tets.push([y[i], y[prev], x[prev], x[next]]);
            }
            return;
        }
    }
    let m = Ref::Centre(out.centres.len());
    out.centres.push([x[0], x[1], x[2], y[0], y[1], y[2]]);
    out.tets.push([m, x[0], x[1], x[2]]);
    out.tets.push([m, y[0], y[1], y[2]]);
    for i in 0..3 {
        let j = (i + 1) % 3;
        if d[i] {
            out.tets.push([m, x[i], x[j], y[j]]);
            out.tets.push([m, x[i], y[j], y[i]]);
        } else {
            out.tets.push([m, x[i], x[j], y[i]]);
            out.tets.push([m, x[j], y[j], y[i]]);
        }
    }
}

//! Volumetric baselines on the CT grid, resampled to a lattice of spacing `s` mm (node = lattice
//! point; label = the CT label at that point):
//!
//! - **voxel lattice mass-spring**: springs between each soft-tissue node and its 26 neighbours,
//!   stiffness in series of the two nodes' tissue stiffness ([tissue.stiffness], harmonic mean)
//!   scaled by s/|d| (longer diagonals are softer), linearised about the rest state (k e eᵀ);
//! - **linear tetrahedral FEM**: each lattice cube whose 8 corners are tissue or bone split into
//!   six Kuhn tetrahedra, linear elasticity with E from the tissue stiffness and ν (default 0.45:
//!   near-incompressible soft tissue locks linear tets as ν → 0.5 — the study shows it).
//!
//! The model is the soft tissue between skin and skull: soft nodes reached from the air side
//! through soft tissue within the springs' depth (the brain behind the skull is dropped).
//! Bone nodes are Dirichlet nodes moved by the plan (the rigid motion of their segment, zero for
//! bone that stays); air has no nodes. The static equilibrium K_ff u_f = −K_fp u_p is solved with
//! faer's sparse Cholesky. Only the pieces of tissue connected to bone are kept (anything else
//! floats). Skin vertices take the displacement of the lattice by trilinear interpolation over
//! the cell's corners that carry nodes (weights renormalised; nearest node if none).

use facesim::case::Stiffness;
use facesim::error::{Error, NumericalKind, Result};
use facesim::fem::assembly::System;
use facesim::osteotomy::Plan;
use facesim::segment::{self, Segmentation};
use facesim::union_find::UnionFind;
use facesim::volume::Volume;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Lattice,
    Tetrahedra,
}

/// Lattice spacing (mm), depth of the facial tissue kept (mm), model and Poisson ratio (tets).
#[derive(Clone, Copy, Debug)]
pub struct Options {
    pub spacing: f64,
    pub max_depth_mm: f64,
    pub kind: Kind,
    pub nu: f64,
}

pub struct Prediction {
    /// Displacement (mm) per requested point.
    pub displacement: Vec<[f64; 3]>,
    pub nodes: usize,
    pub unknowns: usize,
}

/// The spring tracer's relative stiffness for soft tissue; 0 for air and bone (no node or a
/// Dirichlet node).
fn tissue_c(label: u8, s: &Stiffness) -> f64 {
    match label {
        0 | segment::BONE => 0.0,
        l => facesim::springs::tissue_c(l, s),
    }
}

struct Lattice {
    dims: [usize; 3],
    origin: [f64; 3],
    s: f64,
    /// Label per lattice point (0 = air / no node).
    label: Vec<u8>,
}

impl Lattice {
    fn new(vol: &Volume, seg: &Segmentation, s: f64) -> Lattice {
        let (lo, hi) = vol.bounds();
        let dims = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / s).floor() as usize + 1);
        let n = dims[0] * dims[1] * dims[2];
        let label = (0..n)
            .map(|i| {
                let p = [
                    lo[0] + (i % dims[0]) as f64 * s,
                    lo[1] + ((i / dims[0]) % dims[1]) as f64 * s,
                    lo[2] + (i / (dims[0] * dims[1])) as f64 * s,
                ];
                let c = vol.to_voxel(p);
                let v = [0, 1, 2].map(|a| c[a].round());
                if (0..3).all(|a| v[a] >= 0.0 && (v[a] as usize) < vol.dims[a]) {
                    let idx = vol.idx(v[0] as usize, v[1] as usize, v[2] as usize);
                    if seg.head[idx] { seg.labels[idx] } else { 0 }
                } else {
                    0
                }
            })
            .collect();
        Lattice {
            dims,
            origin: lo,
            s,
            label,
        }
    }

    fn pos(&self, i: usize) -> [f64; 3] {
        let d = self.dims;
        [
            self.origin[0] + (i % d[0]) as f64 * self.s,
            self.origin[1] + ((i / d[0]) % d[1]) as f64 * self.s,
            self.origin[2] + (i / (d[0] * d[1])) as f64 * self.s,
        ]
    }

    fn at(&self, x: usize, y: usize, z: usize) -> usize {
        (z * self.dims[1] + y) * self.dims[0] + x
    }

    /// Keep only the soft tissue between skin and skull: breadth-first from the soft nodes that
    /// touch air, through soft nodes, to a depth of `max_depth` (Chebyshev steps × s). The brain
    /// and other tissue behind bone are not part of the face model.
    fn keep_facial_tissue(&mut self, max_depth: f64) {
        let d = self.dims;
        let n = self.label.len();
        let soft = |l: u8| l != 0 && l != segment::BONE;
        let mut depth = vec![u32::MAX; n];
        let mut queue = std::collections::VecDeque::new();
        let neighbours = |i: usize, diag: bool| {
            let (x, y, z) = (
                (i % d[0]) as i64,
                ((i / d[0]) % d[1]) as i64,
                (i / (d[0] * d[1])) as i64,
            );
            let mut out = Vec::with_capacity(26);
            for dz in -1..=1i64 {
                for dy in -1..=1i64 {
                    for dx in -1..=1i64 {
                        let m = dx.abs() + dy.abs() + dz.abs();
                        if m == 0 || (!diag && m > 1) {
                            continue;
                        }
                        let q = [x + dx, y + dy, z + dz];
                        if (0..3).all(|a| q[a] >= 0 && q[a] < d[a] as i64) {
                            out.push((q[2] as usize * d[1] + q[1] as usize) * d[0] + q[0] as usize);
                        }
                    }
                }
            }
            out
        };
        for i in 0..n {
            if soft(self.label[i]) && neighbours(i, false).iter().any(|&j| self.label[j] == 0) {
                depth[i] = 0;
                queue.push_back(i);
            }
        }
        let limit = (max_depth / self.s).ceil() as u32;
        while let Some(i) = queue.pop_front() {
            if depth[i] >= limit {
                continue;
            }
            for j in neighbours(i, true) {
                if soft(self.label[j]) && depth[j] == u32::MAX {
                    depth[j] = depth[i] + 1;
                    queue.push_back(j);
                }
            }
        }
        for i in 0..n {
            if soft(self.label[i]) && depth[i] == u32::MAX {
                self.label[i] = 0;
            }
        }
    }
}

/// Lower-triangle triplets of k e eᵀ between nodes a and b (node indices into the unknowns).
fn spring(t: &mut Vec<(usize, usize, f64)>, a: usize, b: usize, k: f64, e: [f64; 3]) {
    for r in 0..3 {
        for c in 0..3 {
            let v = k * e[r] * e[c];
            for (i, j, sgn) in [(a, a, 1.0), (b, b, 1.0), (a, b, -1.0), (b, a, -1.0)] {
                let (gr, gc) = (3 * i + r, 3 * j + c);
                if gr >= gc {
                    t.push((gr, gc, sgn * v));
                }
            }
        }
    }
}

/// Element stiffness of a linear tetrahedron (constant strain), 12×12, lower triplets.
fn tetra(t: &mut Vec<(usize, usize, f64)>, nodes: [usize; 4], x: [[f64; 3]; 4], e: f64, nu: f64) {
    use nalgebra::{Matrix3, SMatrix};
    let m = Matrix3::from_fn(|r, c| x[c + 1][r] - x[0][r]);
    let det = m.determinant();
    let Some(inv) = m.try_inverse() else { return };
    let vol = det.abs() / 6.0;
    // Gradients of the barycentric shape functions.
    let mut g = [[0.0; 3]; 4];
    for a in 0..3 {
        for k in 0..3 {
            g[a + 1][k] = inv[(a, k)];
        }
    }
    for k in 0..3 {
        g[0][k] = -(g[1][k] + g[2][k] + g[3][k]);
    }
    let mut b = SMatrix::<f64, 6, 12>::zeros();
    for a in 0..4 {
        let ba = crate::dynamics::strain_rows_3d(g[a]);
        for r in 0..6 {
            for c in 0..3 {
                b[(r, 3 * a + c)] = ba[r][c];
            }
        }
    }
    let iso = crate::dynamics::isotropic_3d(e, nu);
    let d = SMatrix::<f64, 6, 6>::from_fn(|i, j| iso[i][j]);
    let k = b.transpose() * d * b * vol;
    for i in 0..12 {
        for j in 0..=i {
            let (gi, gj) = (3 * nodes[i / 3] + i % 3, 3 * nodes[j / 3] + j % 3);
            let (r, c) = if gi >= gj { (gi, gj) } else { (gj, gi) };
            t.push((r, c, k[(i, j)]));
        }
    }
}

/// Solve the volumetric model and return the displacement at `points` (the skin vertices).
pub fn predict(
    vol: &Volume,
    seg: &Segmentation,
    stiffness: &Stiffness,
    plan: &Plan,
    points: &[[f64; 3]],
    opts: Options,
) -> Result<Prediction> {
    let Options {
        spacing,
        max_depth_mm,
        kind,
        nu,
    } = opts;
    let mut lat = Lattice::new(vol, seg, spacing);
    lat.keep_facial_tissue(max_depth_mm);
    let (couple, cubes) = couplings(&lat, kind);
    let nodes = Nodes::anchored(&lat, &couple);
    if nodes.points.iter().all(|&i| lat.is_bone(i)) {
        return Err(Error::numerical(
            NumericalKind::Singular,
            "volumetric model: no soft tissue is connected to bone at this lattice spacing",
        ));
    }
    let mut t: Vec<(usize, usize, f64)> = Vec::new();
    match kind {
        Kind::Lattice => lattice_springs(&mut t, &lat, &nodes, &couple, stiffness),
        Kind::Tetrahedra => kuhn_tetrahedra(&mut t, &lat, &nodes, &cubes, stiffness, nu),
    }
    regularise(&mut t, &nodes, &couple);
    let nn = nodes.points.len();
    let (fixed, prescribed) = bone_motion(&lat, &nodes, plan);
    let sys = System::new(3 * nn, t, &fixed)
        .map_err(|e| Error::numerical(NumericalKind::Singular, format!("volumetric model: {e}")))?;
    let unknowns = sys.free.len();
    let u = sys.solve(&[vec![0.0; 3 * nn]], &[prescribed]).remove(0);
    if u.iter().any(|x| !x.is_finite()) {
        return Err(Error::numerical(
            NumericalKind::Diverged,
            "volumetric model: the solve returned non-finite displacements",
        ));
    }
    Ok(Prediction {
        displacement: points
            .iter()
            .map(|&p| interpolate(&lat, &nodes, &u, p))
            .collect(),
        nodes: nn,
        unknowns,
    })
}

impl Lattice {
    fn is_node(&self, i: usize) -> bool {
        self.label[i] != 0
    }

    fn is_bone(&self, i: usize) -> bool {
        self.label[i] == segment::BONE
    }

    /// Lattice point at integer coordinates `q`; None outside the lattice.
    fn at_checked(&self, q: [i64; 3]) -> Option<usize> {
        if (0..3).any(|a| q[a] < 0 || q[a] >= self.dims[a] as i64) {
            return None;
        }
        Some(self.at(q[0] as usize, q[1] as usize, q[2] as usize))
    }

    /// The 8 corners of the cell whose lowest corner is (x, y, z); bit 0 of the corner number
    /// steps x, bit 1 y, bit 2 z (the numbering of marching tetrahedra's Kuhn split).
    fn cube_corners(&self, x: usize, y: usize, z: usize) -> Vec<usize> {
        (0..8)
            .map(|c| self.at(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2)))
            .collect()
    }
}

/// Edges of the model (pairs of lattice points coupled by a spring or an element), in lattice
/// order, and for tetrahedra the lowest corner of every meshed cube.
fn couplings(lat: &Lattice, kind: Kind) -> (Vec<(usize, usize)>, Vec<usize>) {
    let d = lat.dims;
    let mut couple: Vec<(usize, usize)> = Vec::new();
    let mut cubes: Vec<usize> = Vec::new();
    let offsets: Vec<[i64; 3]> = (0..27)
        .map(|c| [c % 3 - 1, (c / 3) % 3 - 1, c / 9 - 1])
        .filter(|o| o.iter().any(|&x| x != 0))
        .map(|o| o.map(|x| x as i64))
        .collect();
    for z in 0..d[2] {
        for y in 0..d[1] {
            for x in 0..d[0] {
                let i = lat.at(x, y, z);
                if !lat.is_node(i) {
                    continue;
                }
                match kind {
                    Kind::Lattice => {
                        for o in &offsets {
                            let q = [x as i64 + o[0], y as i64 + o[1], z as i64 + o[2]];
                            let Some(j) = lat.at_checked(q) else { continue };
                            // Bone–bone springs would join two Dirichlet nodes: no energy.
                            if j > i && lat.is_node(j) && !(lat.is_bone(i) && lat.is_bone(j)) {
                                couple.push((i, j));
                            }
                        }
                    }
                    Kind::Tetrahedra => {
                        if x + 1 < d[0] && y + 1 < d[1] && z + 1 < d[2] {
                            let cs = lat.cube_corners(x, y, z);
                            if cs.iter().all(|&c| lat.is_node(c))
                                && !cs.iter().all(|&c| lat.is_bone(c))
                            {
                                cubes.push(i);
                                for a in 0..8 {
                                    for b in a + 1..8 {
                                        couple.push((cs[a], cs[b]));
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    (couple, cubes)
}

/// The nodes of the model: the coupled lattice points of the pieces of tissue connected to bone
/// (anything else floats).
struct Nodes {
    /// Node number per lattice point (usize::MAX: not a node).
    index: Vec<usize>,
    /// Lattice point per node.
    points: Vec<usize>,
    /// Rest position per node.
    pos: Vec<[f64; 3]>,
}

impl Nodes {
    /// Union–find over the couplings; a component is kept when it holds a coupled bone point.
    fn anchored(lat: &Lattice, couple: &[(usize, usize)]) -> Nodes {
        let n = lat.label.len();
        let mut sets = UnionFind::new(n);
        for &(a, b) in couple {
            sets.union(a, b);
        }
        let mut anchored = vec![false; n];
        let mut touched = vec![false; n];
        for &(a, b) in couple {
            touched[a] = true;
            touched[b] = true;
        }
        for i in 0..n {
            if touched[i] && lat.is_bone(i) {
                let r = sets.find(i);
                anchored[r] = true;
            }
        }
        let mut index = vec![usize::MAX; n];
        let mut points = Vec::new();
        for i in 0..n {
            if touched[i] && anchored[sets.find(i)] {
                index[i] = points.len();
                points.push(i);
            }
        }
        let pos = points.iter().map(|&i| lat.pos(i)).collect();
        Nodes { index, points, pos }
    }

    /// Node numbers of both ends of a coupling, None when either end is not a node.
    fn pair(&self, (a, b): (usize, usize)) -> Option<(usize, usize)> {
        let (ia, ib) = (self.index[a], self.index[b]);
        (ia != usize::MAX && ib != usize::MAX).then_some((ia, ib))
    }
}

/// Voxel-lattice mass-spring: one linearised spring per coupling.
fn lattice_springs(
    t: &mut Vec<(usize, usize, f64)>,
    lat: &Lattice,
    nodes: &Nodes,
    couple: &[(usize, usize)],
    stiffness: &Stiffness,
) {
    let c_of = |i: usize| tissue_c(lat.label[i], stiffness);
    let pos = &nodes.pos;
    for &(a, b) in couple {
        let Some((ia, ib)) = nodes.pair((a, b)) else {
            continue;
        };
        let (ca, cb) = (c_of(a), c_of(b));
        // Series stiffness of the two half-springs (a bone end is rigid).
        let c = match (ca > 0.0, cb > 0.0) {
            (true, true) => 2.0 * ca * cb / (ca + cb),
            (true, false) => ca,
            (false, true) => cb,
            _ => continue,
        };
        let dv = facesim::vec3::sub(pos[ib], pos[ia]);
        let l = facesim::vec3::norm(dv);
        spring(t, ia, ib, c * lat.s / l, dv.map(|x| x / l));
    }
}

/// Linear tetrahedra: the Kuhn split of every meshed cube whose corners are all nodes, E the
/// mean stiffness of the tetrahedron's soft corners.
fn kuhn_tetrahedra(
    t: &mut Vec<(usize, usize, f64)>,
    lat: &Lattice,
    nodes: &Nodes,
    cubes: &[usize],
    stiffness: &Stiffness,
    nu: f64,
) {
    // Kuhn split of the cube: six tetrahedra around the main diagonal 0–7 (the same
    // split marching tetrahedra uses).
    use facesim::surface::marching::TETS as KUHN;
    let d = lat.dims;
    let c_of = |i: usize| tissue_c(lat.label[i], stiffness);
    let (index, pos) = (&nodes.index, &nodes.pos);
    for &i in cubes {
        let (x, y, z) = (i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1]));
        let cs = lat.cube_corners(x, y, z);
        if cs.iter().any(|&c| index[c] == usize::MAX) {
            continue;
        }
        for tet in KUHN {
            let g = tet.map(|c| cs[c]);
            let soft: Vec<f64> = g.iter().map(|&c| c_of(c)).filter(|&c| c > 0.0).collect();
            if soft.is_empty() {
                continue;
            }
            let e = soft.iter().sum::<f64>() / soft.len() as f64;
            tetra(t, g.map(|c| index[c]), g.map(|c| pos[index[c]]), e, nu);
        }
    }
}

/// A weak isotropic coupling along every edge of the model (1e-9 of the largest diagonal)
/// removes the lattice's zero-energy modes at the tissue's edge; unlike a tie to the rest
/// position it stores no energy under a rigid translation, so it cannot bias one.
fn regularise(t: &mut Vec<(usize, usize, f64)>, nodes: &Nodes, couple: &[(usize, usize)]) {
    let mut diag_max = 0.0f64;
    for &(r, c, v) in t.iter() {
        if r == c {
            diag_max = diag_max.max(v);
        }
    }
    let eps = 1e-9 * diag_max;
    for &pair in couple {
        let Some((ia, ib)) = nodes.pair(pair) else {
            continue;
        };
        for e in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            spring(t, ia, ib, eps, e);
        }
    }
}

/// Dirichlet conditions: every bone node is fixed at the plan's motion of its rest position
/// (returns the fixed flags and prescribed displacements per unknown).
fn bone_motion(lat: &Lattice, nodes: &Nodes, plan: &Plan) -> (Vec<bool>, Vec<f64>) {
    let nn = nodes.points.len();
    let pos = &nodes.pos;
    let mut fixed = vec![false; 3 * nn];
    let mut prescribed = vec![0.0; 3 * nn];
    let bone_pts: Vec<[f64; 3]> = nodes
        .points
        .iter()
        .zip(pos)
        .filter(|(i, _)| lat.is_bone(**i))
        .map(|(_, p)| *p)
        .collect();
    let (moved, _) = plan.apply(&bone_pts, 1.0);
    let mut k = 0;
    for (a, &i) in nodes.points.iter().enumerate() {
        if lat.is_bone(i) {
            for c in 0..3 {
                fixed[3 * a + c] = true;
                prescribed[3 * a + c] = moved[k][c] - pos[a][c];
            }
            k += 1;
        }
    }
    (fixed, prescribed)
}

/// Displacement at `p`: trilinear over the corners of its cell that are nodes (weights
/// renormalised), else the nearest node nearby (`nearest_node`), else zero.
fn interpolate(lat: &Lattice, nodes: &Nodes, u: &[f64], p: [f64; 3]) -> [f64; 3] {
    let index = &nodes.index;
    let c = [0, 1, 2].map(|a| (p[a] - lat.origin[a]) / lat.s);
    let base = c.map(|x| x.floor() as i64);
    let f = [0, 1, 2].map(|a| c[a] - base[a] as f64);
    let mut acc = [0.0; 3];
    let mut wsum = 0.0;
    for corner in 0..8 {
        let o = [corner & 1, (corner >> 1) & 1, corner >> 2];
        let q = [0, 1, 2].map(|a| base[a] + o[a] as i64);
        let Some(gi) = lat.at_checked(q) else {
            continue;
        };
        if index[gi] == usize::MAX {
            continue;
        }
        // The floor keeps wsum > 0 whenever a corner is a node, even one of zero weight.
        let w: f64 = (0..3)
            .map(|a| if o[a] == 1 { f[a] } else { 1.0 - f[a] })
            .product::<f64>()
            .max(1e-12);
        for k in 0..3 {
            acc[k] += w * u[3 * index[gi] + k];
        }
        wsum += w;
    }
    if wsum > 0.0 {
        return acc.map(|x| x / wsum);
    }
    nearest_node(lat, nodes, u, base, p)
}

/// Displacement of the node nearest to `p` among the lattice points base − 2 … base + 3.
fn nearest_node(lat: &Lattice, nodes: &Nodes, u: &[f64], base: [i64; 3], p: [f64; 3]) -> [f64; 3] {
    let index = &nodes.index;
    let mut best = (f64::INFINITY, [0.0; 3]);
    for dz in -2..=3i64 {
        for dy in -2..=3i64 {
            for dx in -2..=3i64 {
                let q = [base[0] + dx, base[1] + dy, base[2] + dz];
                let Some(gi) = lat.at_checked(q) else {
                    continue;
                };
                if index[gi] == usize::MAX {
                    continue;
                }
                let dist = facesim::vec3::norm(facesim::vec3::sub(lat.pos(gi), p));
                if dist < best.0 {
                    best = (dist, [0, 1, 2].map(|k| u[3 * index[gi] + k]));
                }
            }
        }
    }
    best.1
}

//! Global C1 surface system (Koch eq. 6, 15–16): DOF numbering, parallel assembly of one scalar
//! K shared by x, y and z, Dirichlet conditions, and the system factored once (fem/cholesky.rs)
//! and solved for several right-hand sides.
//!
//! The DOF numbering is fem/dofs.rs's.

use super::cholesky::{Cholesky, Ordering, Pattern};
use super::dofs::{Dofs, Owner};
use super::element::{Element, Material, NDOF};
/// The symmetric product, re-exported where K's triplets come from.
pub use super::sparse::multiply;
use crate::error::{Error, NumericalKind, Result};
use crate::union_find::UnionFind;
use faer::sparse::linalg::LltError;
use faer::sparse::{SparseColMat, Triplet};
use rayon::prelude::*;
use std::collections::HashMap;

/// One element's global DOFs, stiffness and load.
type ElementSystem = ([usize; NDOF], [[f64; NDOF]; NDOF], [f64; NDOF]);

pub struct FemMesh {
    pub uv: Vec<[f64; 2]>,
    pub tris: Vec<[u32; 3]>,
    /// Edges as (low, high) vertex pairs.
    pub edges: Vec<[u32; 2]>,
    /// Per triangle, the global edge of its local edges (0: corners 0–1, 1: 1–2, 2: 2–0).
    pub tri_edges: Vec<[u32; 3]>,
    /// Triangles per edge (1 on the boundary, 2 inside).
    pub edge_tris: Vec<u8>,
    pub elements: Vec<Element>,
}

impl FemMesh {
    pub fn new(uv: Vec<[f64; 2]>, tris: Vec<[u32; 3]>) -> Result<FemMesh> {
        let mut index: HashMap<(u32, u32), u32> = HashMap::new();
        let mut edges = Vec::new();
        let mut edge_tris = Vec::new();
        let mut tri_edges = Vec::with_capacity(tris.len());
        for t in &tris {
            let mut te = [0u32; 3];
            for e in 0..3 {
                let (a, b) = (t[e].min(t[(e + 1) % 3]), t[e].max(t[(e + 1) % 3]));
                let id = *index.entry((a, b)).or_insert_with(|| {
                    edges.push([a, b]);
                    edge_tris.push(0u8);
                    (edges.len() - 1) as u32
                });
                edge_tris[id as usize] = edge_tris[id as usize].saturating_add(1);
                te[e] = id;
            }
            tri_edges.push(te);
        }
        // A (u, v) map that folds (some triangles flipped against the rest) gives overlapping
        // elements and an indefinite or meaningless system: say so rather than fail in the factor.
        let signed: Vec<f64> = tris
            .iter()
            .map(|t| {
                let [p, q, r] = t.map(|i| uv[i as usize]);
                (q[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (q[1] - p[1])
            })
            .collect();
        let positive = signed.iter().filter(|a| **a > 0.0).count();
        let flipped = if 2 * positive >= signed.len() {
            signed.len() - positive
        } else {
            positive
        };
        if flipped > 0 {
            let sign = if 2 * positive >= signed.len() {
                -1.0
            } else {
                1.0
            };
            let t = signed.iter().position(|a| a * sign >= 0.0).unwrap_or(0);
            let v = tris[t][0] as usize;
            return Err(Error::surface(format!(
                "the (u, v) parameterisation folds over at {flipped} of {} triangles (first: triangle {t}, at u = {:.1}, v = {:.1}): use [surface] parameterization = \"planar\", a finer or less decimated skin, or restrict [surface] movable",
                tris.len(),
                uv[v][0],
                uv[v][1]
            )));
        }
        let elements = tris
            .par_iter()
            .map(|t| Element::new(t.map(|i| uv[i as usize])))
            .collect::<Result<Vec<_>>>()?;
        Ok(FemMesh {
            uv,
            tris,
            edges,
            tri_edges,
            edge_tris,
            elements,
        })
    }

    /// The mesh's C1 DOF numbering.
    pub fn dofs(&self) -> Dofs {
        Dofs::new(self.uv.len(), self.edges.len())
    }

    pub fn ndof(&self) -> usize {
        self.dofs().ndof()
    }

    /// Global DOFs of triangle t in the element's local order.
    pub fn element_dofs(&self, t: usize) -> [usize; NDOF] {
        let tri = self.tris[t];
        let dofs = self.dofs();
        let e = self.tri_edges[t];
        let v = |k: usize| dofs.value(tri[k] as usize);
        [
            v(0),
            v(0) + 1,
            v(0) + 2,
            v(1),
            v(1) + 1,
            v(1) + 2,
            v(2),
            v(2) + 1,
            v(2) + 2,
            dofs.edge(e[0] as usize),
            dofs.edge(e[1] as usize),
            dofs.edge(e[2] as usize),
        ]
    }

    /// Evaluate the C1 field with global DOFs `a` in triangle t at local (ξ, η).
    pub fn eval(&self, a: &[f64], t: usize, xi: f64, eta: f64) -> [f64; 6] {
        let phi = self.elements[t].shape(xi, eta);
        let d = self.element_dofs(t);
        let mut w = [0.0; 6];
        for j in 0..NDOF {
            for k in 0..6 {
                w[k] += a[d[j]] * phi[j][k];
            }
        }
        w
    }

    /// Assemble K (its lower triangle) and F for a uniform load q, with per-element materials,
    /// in parallel, from the precomputed reference moments. Returns summed triplets and F.
    pub fn assemble(
        &self,
        material: &(dyn Fn(usize) -> Material + Sync),
        q: f64,
    ) -> (Vec<(usize, usize, f64)>, Vec<f64>) {
        let per: Vec<ElementSystem> = (0..self.tris.len())
            .into_par_iter()
            .map(|t| {
                let (k, f) = self.elements[t].stiffness_fast(&material(t), q);
                (self.element_dofs(t), k, f)
            })
            .collect();
        let mut f = vec![0.0; self.ndof()];
        for (d, _, fe) in &per {
            for i in 0..NDOF {
                f[d[i]] += fe[i];
            }
        }
        (self.gather_lower(&per), f)
    }

    /// K's lower triangle as triplets sorted by (column, row), each entry the sum of its
    /// element contributions in element order (the order a stable sort of all element triplets
    /// gives). Built column by column in parallel: a DOF's column only receives contributions
    /// from the triangles containing its vertex or edge, so no global sort of the ~78 triplets
    /// per element is needed.
    fn gather_lower(&self, per: &[ElementSystem]) -> Vec<(usize, usize, f64)> {
        let dofs = self.dofs();
        let nv = dofs.nv;
        // Triangles per vertex, ascending (counting sort).
        let mut start = vec![0usize; nv + 1];
        for t in &self.tris {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut vt = vec![0u32; start[nv]];
        for (t, tri) in self.tris.iter().enumerate() {
            for &v in tri {
                vt[fill[v as usize]] = t as u32;
                fill[v as usize] += 1;
            }
        }
        // Triangles per edge (at most two), ascending.
        let mut et = vec![[u32::MAX; 2]; self.edges.len()];
        for (t, es) in self.tri_edges.iter().enumerate() {
            for &e in es {
                let slot = &mut et[e as usize];
                if slot[0] == u32::MAX {
                    slot[0] = t as u32;
                } else {
                    slot[1] = t as u32;
                }
            }
        }
        let columns: Vec<Vec<(usize, usize, f64)>> = (0..dofs.ndof())
            .into_par_iter()
            .with_min_len(256)
            .map(|c| {
                let tris: &[u32] = match dofs.owner(c) {
                    Owner::Vertex(v) => &vt[start[v]..start[v + 1]],
                    Owner::Edge(e) => {
                        let e = &et[e];
                        if e[1] == u32::MAX { &e[..1] } else { &e[..] }
                    }
                };
                let mut col: Vec<(usize, f64)> = Vec::with_capacity(tris.len() * NDOF);
                for &t in tris {
                    let (d, k, _) = &per[t as usize];
                    let Some(j) = d.iter().position(|&x| x == c) else {
                        continue;
                    };
                    for i in 0..NDOF {
                        if d[i] >= c {
                            col.push((d[i], k[i][j]));
                        }
                    }
                }
                // Stable: repeated rows keep element order, so their sum is bit-identical
                // whatever the thread count.
                col.sort_by_key(|e| e.0);
                let mut out: Vec<(usize, usize, f64)> = Vec::with_capacity(col.len() / 2);
                for (r, v) in col {
                    match out.last_mut() {
                        Some(last) if last.0 == r => last.2 += v,
                        _ => out.push((r, c, v)),
                    }
                }
                out
            })
            .collect();
        columns.concat()
    }
}

impl FemMesh {
    /// Refuse constraints that leave K singular, before factoring (a Cholesky of a singular
    /// matrix in floating point may "succeed" with tiny pivots). Per connected piece of the
    /// mesh the null space of the energy is: nothing with a foundation; the constants when
    /// some element stretches (α ≠ 0); the linear fields for pure bending. They are removed by
    /// one fixed value, or by one vertex with value and gradient fixed, respectively.
    pub fn check_constraints(
        &self,
        material: &(dyn Fn(usize) -> Material + Sync),
        fixed: &[bool],
    ) -> Result<()> {
        let dofs = self.dofs();
        let nv = dofs.nv;
        let mut sets = UnionFind::new(nv);
        for t in &self.tris {
            for &v in &t[1..] {
                sets.union(t[0] as usize, v as usize);
            }
        }
        // Per piece: (has foundation, has stretching, has bending, a value fixed, a vertex fully fixed).
        let mut piece: HashMap<usize, [bool; 5]> = HashMap::new();
        for (t, tri) in self.tris.iter().enumerate() {
            let m = material(t);
            let e = piece.entry(sets.find(tri[0] as usize)).or_default();
            e[0] |= m.foundation > 0.0;
            e[1] |= m.alpha.iter().any(|a| *a != 0.0);
            e[2] |= m.beta.iter().any(|b| *b != 0.0);
        }
        for v in 0..nv {
            if let Some(e) = piece.get_mut(&sets.find(v)) {
                e[3] |= fixed[dofs.value(v)];
                e[4] |= dofs.vertex(v).all(|g| fixed[g]);
            }
        }
        for (root, [found, stretch, bend, value, full]) in piece {
            let ok = found
                || (stretch && bend && value)
                || (bend && full)
                || (stretch && !bend && value);
            if !ok {
                return Err(Error::numerical(
                    NumericalKind::Singular,
                    format!(
                        "the surface stiffness matrix is singular: the piece of the skin mesh containing vertex {root} has no rigid node \
                     (mark part of it rigid with [surface] movable, or give it α, β > 0)"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Sort by (column, row) and add up repeated entries (the reference for `gather_lower`).
#[cfg(test)]
fn sum_duplicates(mut t: Vec<(usize, usize, f64)>) -> Vec<(usize, usize, f64)> {
    // Stable: repeated entries are summed in element order, so results are bit-identical
    // from run to run whatever the thread count.
    t.par_sort_by_key(|&(r, c, _)| (c, r));
    let mut out: Vec<(usize, usize, f64)> = Vec::with_capacity(t.len() / 4);
    for (r, c, v) in t {
        match out.last_mut() {
            Some(last) if last.0 == r && last.1 == c => last.2 += v,
            _ => out.push((r, c, v)),
        }
    }
    out
}

/// The largest Cholesky factor a solve may allocate: a model that needs more is refused with
/// its size (before the allocation fails and aborts the process).
pub(crate) const MAX_FACTOR_BYTES: usize = 12 << 30;

/// K y = b on the free DOFs, with the fixed ones prescribed; factored once.
pub struct System {
    pub n: usize,
    /// Global DOF → free index (usize::MAX for fixed DOFs).
    pub free_index: Vec<usize>,
    pub free: Vec<usize>,
    /// K entries coupling a free row to a fixed column (free row index, global col, value).
    coupling: Vec<(usize, usize, f64)>,
    /// K's lower triangle (global triplets), kept for products such as F_init = K a_init.
    pub k: Vec<(usize, usize, f64)>,
    /// The factor; its symbolic analysis is reused when only values change.
    llt: Cholesky<f64>,
    pub nnz_lower: usize,
    /// DOFs fixed when factored and freed since ([`System::free_more`]).
    border: Option<Border>,
}

/// Fixed DOFs freed after factoring, solved by bordering the factor instead of refactoring.
/// With A = Pᵀ L Lᵀ P the factored free block, B = K[free, added] and C = K[added, added], the
/// added unknowns y solve the Schur complement S y = g − Gᵀ z, S = C − Gᵀ G (dense k × k),
/// where G = L⁻¹ P B and z = L⁻¹ P b; then x = Pᵀ L⁻ᵀ (z − G y). G is nonzero only on the
/// factor's reach of B's rows (`Cholesky::forward_from`), where it is kept: a bordered DOF
/// costs a forward sweep over that reach once, and a solve costs one solve of A and a product
/// with G (its two sweeps run apart, the border between them).
/// A bordered DOF may be held again at a prescribed value (`System::hold_border`): its y is
/// then given and only S's block on the others is factored (a contact node resting again).
struct Border {
    /// The bordered DOFs, in the order bordered (G's and S's columns).
    added: Vec<usize>,
    /// Of each, whether it is held again at its prescribed value.
    held: Vec<bool>,
    /// K between an added DOF and a DOF still fixed: (border index, global DOF, value).
    coupling: Vec<(usize, usize, f64)>,
    /// G on the factor positions `g_at` (its rows), zero on every other.
    g_at: Vec<usize>,
    g: faer::Mat<f64>,
    /// S over every bordered DOF.
    schur: nalgebra::DMatrix<f64>,
    /// The border indices not held, and S's Cholesky factor on them (None: all held).
    unknown: Vec<usize>,
    s: Option<nalgebra::linalg::Cholesky<f64, nalgebra::Dyn>>,
}

impl Border {
    /// Factor S on the bordered DOFs that are not held.
    fn factor_unknown(&mut self) -> Result<()> {
        self.unknown = (0..self.added.len()).filter(|e| !self.held[*e]).collect();
        let u = &self.unknown;
        self.s = if u.is_empty() {
            None
        } else {
            let s = nalgebra::DMatrix::from_fn(u.len(), u.len(), |i, j| self.schur[(u[i], u[j])]);
            Some(nalgebra::linalg::Cholesky::new(s).ok_or_else(|| {
                Error::numerical(
                    NumericalKind::Singular,
                    format!(
                        "freeing {} held components leaves the system singular",
                        u.len()
                    ),
                )
            })?)
        };
        Ok(())
    }
}

impl System {
    /// Factor K restricted to the DOFs not in `fixed`.
    pub fn new(n: usize, k: Vec<(usize, usize, f64)>, fixed: &[bool]) -> Result<System> {
        Self::with_ordering(n, k, fixed, Ordering::Amd)
    }

    /// As `new`, with the factor's fill-reducing ordering chosen.
    pub(crate) fn with_ordering(
        n: usize,
        k: Vec<(usize, usize, f64)>,
        fixed: &[bool],
        ordering: Ordering<'_>,
    ) -> Result<System> {
        Self::within(n, k, fixed, ordering, MAX_FACTOR_BYTES)
    }

    /// As `with_ordering`, refusing (`NumericalKind::TooLarge`) a factor of more than
    /// `max_bytes` before it is allocated.
    pub(crate) fn within(
        n: usize,
        k: Vec<(usize, usize, f64)>,
        fixed: &[bool],
        ordering: Ordering<'_>,
        max_bytes: usize,
    ) -> Result<System> {
        let (free_index, free) = free_dofs(&fixed[..n]);
        // faer runs sequentially (fem/cholesky.rs says why), its dense kernels too.
        faer::set_global_parallelism(faer::Par::Seq);
        let (mat, coupling) = split(&k, &free_index, free.len())?;
        let nnz_lower = mat.compute_nnz();
        let symbolic = Pattern::analyse_with(mat.symbolic(), ordering, &free).map_err(|e| {
            Error::numerical(NumericalKind::Singular, format!("symbolic Cholesky: {e:?}"))
        })?;
        let bytes = symbolic
            .factor_nnz()
            .saturating_mul(std::mem::size_of::<f64>());
        if bytes > max_bytes.min(MAX_FACTOR_BYTES) {
            return Err(Error::numerical(
                NumericalKind::TooLarge,
                format!(
                    "the system of {} unknowns would need a {:.1} GB Cholesky factor (limit {:.1} GB): use a coarser model",
                    free.len(),
                    bytes as f64 / 1e9,
                    max_bytes.min(MAX_FACTOR_BYTES) as f64 / f64::from(1u32 << 30)
                ),
            ));
        }
        let llt = Cholesky::factor(&symbolic, mat.as_ref()).map_err(|e| match e {
            LltError::Generic(g) => Error::numerical(
                NumericalKind::TooLarge,
                format!(
                    "the system of {} unknowns could not be factored ({g:?}; a {:.1} GB factor): use a coarser model",
                    free.len(),
                    bytes as f64 / 1e9
                ),
            ),
            LltError::Numeric(_) => Error::numerical(NumericalKind::Singular, format!(
                "the surface stiffness matrix is not positive definite ({e:?}): too few rigid nodes, or α = β = 0"
            )),
        })?;
        Ok(System {
            n,
            free_index,
            free,
            coupling,
            k,
            llt,
            nnz_lower,
            border: None,
        })
    }

    /// Free the fixed DOFs `dofs` (with those freed before) without refactoring: the system is
    /// bordered (see [`Border`]). The DOFs bordered for the first time cost a forward sweep
    /// over the factor's reach of their neighbours; one bordered before and held again since is
    /// an unknown again at no sweep.
    pub(crate) fn free_more(&mut self, dofs: &[usize]) -> Result<()> {
        let (mut added, mut held, before) = match self.border.take() {
            Some(b) => (b.added, b.held, Some((b.schur, b.g_at, b.g))),
            None => (Vec::new(), Vec::new(), None),
        };
        // Border index by global DOF (usize::MAX: not bordered); a lookup per K entry below.
        let mut pos = vec![usize::MAX; self.n];
        for (i, g) in added.iter().enumerate() {
            pos[*g] = i;
        }
        let k0 = added.len();
        for &g in dofs {
            match pos[g] {
                usize::MAX if self.free_index[g] == usize::MAX => {
                    pos[g] = added.len();
                    added.push(g);
                    held.push(false);
                }
                usize::MAX => {}
                e => held[e] = false,
            }
        }
        let k = added.len();
        let mut c = nalgebra::DMatrix::<f64>::zeros(k, k);
        let (mut b, mut coupling) = (Vec::new(), Vec::new());
        let mut off = |e: usize, other: usize, v: f64| match self.free_index[other] {
            usize::MAX => coupling.push((e, other, v)),
            f => b.push((f, e, v)),
        };
        const NO: usize = usize::MAX;
        for &(r, col, v) in &self.k {
            match (pos[r], pos[col]) {
                (NO, NO) => {}
                (a, NO) => off(a, col, v),
                (NO, d) => off(d, r, v),
                (a, d) => {
                    c[(a, d)] += v;
                    if a != d {
                        c[(d, a)] += v;
                    }
                }
            }
        }
        // A and the earlier columns of B are as they were: so are G's and S's between them.
        let (mut g_at, old_g) = match before {
            Some((schur, at, g)) => {
                c.view_mut((0, 0), (k0, k0)).copy_from(&schur);
                (at, g)
            }
            None => (Vec::new(), faer::Mat::zeros(0, 0)),
        };
        let mut g = old_g;
        if k > k0 {
            // G's new columns, L⁻¹ P B_new, on the reach of their own rows: the columns shared
            // among the cores (the factor's own sweeps are sequential; fem/cholesky.rs says why).
            let parts = rayon::current_num_threads().clamp(1, k - k0);
            let width = (k - k0).div_ceil(parts);
            let mut columns = vec![Vec::new(); parts];
            for &(f, e, v) in b.iter().filter(|t| t.1 >= k0) {
                let j = e - k0;
                columns[j / width].push((f, j % width, v));
            }
            let solved: Vec<(Vec<usize>, faer::Mat<f64>)> = columns
                .par_iter()
                .enumerate()
                .map(|(p, bp)| {
                    let ncols = (k - k0).saturating_sub(p * width).min(width);
                    self.llt.forward_from(bp, ncols)
                })
                .collect();
            // G's rows: the earlier ones, then the positions first reached now.
            let mut row_of = vec![usize::MAX; self.free.len()];
            for (i, p) in g_at.iter().enumerate() {
                row_of[*p] = i;
            }
            for (at, _) in &solved {
                for p in at {
                    if row_of[*p] == usize::MAX {
                        row_of[*p] = g_at.len();
                        g_at.push(*p);
                    }
                }
            }
            let mut grown = faer::Mat::<f64>::zeros(g_at.len(), k);
            grown
                .as_mut()
                .submatrix_mut(0, 0, g.nrows(), k0)
                .copy_from(g.as_ref());
            let mut first = k0;
            for (at, part) in &solved {
                for (i, p) in at.iter().enumerate() {
                    for j in 0..part.ncols() {
                        grown[(row_of[*p], first + j)] = part[(i, j)];
                    }
                }
                first += part.ncols();
            }
            g = grown;
            // S's new columns: C − Gᵀ G_new.
            let gtg = g.transpose() * g.as_ref().subcols(k0, k - k0);
            for j in k0..k {
                for e in 0..k {
                    c[(e, j)] -= gtg[(e, j - k0)];
                }
            }
            // S is symmetric: its new rows are its new columns (the new block made exactly so).
            for j in k0..k {
                for e in 0..k0 {
                    c[(j, e)] = c[(e, j)];
                }
                for e in k0..j {
                    let mean = 0.5 * (c[(e, j)] + c[(j, e)]);
                    c[(e, j)] = mean;
                    c[(j, e)] = mean;
                }
            }
        }
        let mut border = Border {
            added,
            held,
            coupling,
            g_at,
            g,
            schur: c,
            unknown: Vec::new(),
            s: None,
        };
        border.factor_unknown()?;
        self.border = Some(border);
        Ok(())
    }

    /// Hold the bordered DOFs `dofs` again, at the values a solve prescribes for them, without
    /// refactoring (a DOF that was never bordered is refused: it needs no hold).
    pub(crate) fn hold_border(&mut self, dofs: &[usize]) -> Result<()> {
        let Some(border) = self.border.as_mut() else {
            return Err(Error::config(
                "hold_border: no DOF has been freed by bordering",
            ));
        };
        for g in dofs {
            let e = border.added.iter().position(|a| a == g).ok_or_else(|| {
                Error::config(format!("hold_border: DOF {g} was not freed by bordering"))
            })?;
            border.held[e] = true;
        }
        border.factor_unknown()
    }

    /// The free DOFs (global indices, in the factor's column order) and the factor, for a
    /// caller that solves with zero prescribed values alone (a preconditioner's coarse level).
    pub(crate) fn into_factor(self) -> (Vec<usize>, Cholesky<f64>) {
        (self.free, self.llt)
    }

    /// Nonzeros of the Cholesky factor L (for reports).
    pub fn factor_nnz(&self) -> Result<usize> {
        Ok(self.llt.pattern().factor_nnz())
    }

    /// Refactor after K's values changed on the same pattern (new α/β, spring stiffness),
    /// reusing the symbolic analysis.
    pub fn refactor(&mut self, k: Vec<(usize, usize, f64)>) -> Result<()> {
        let (mat, coupling) = split(&k, &self.free_index, self.free.len())?;
        if mat.compute_nnz() != self.nnz_lower {
            return Err(Error::numerical(
                NumericalKind::Singular,
                "refactor: the sparsity pattern changed",
            ));
        }
        self.llt.refactor(mat.as_ref()).map_err(|e| {
            Error::numerical(
                NumericalKind::Singular,
                format!("the surface stiffness matrix is not positive definite ({e:?})"),
            )
        })?;
        self.coupling = coupling;
        self.k = k;
        Ok(())
    }

    /// Solve K a = f for each right-hand side, with a = `prescribed` on the fixed DOFs.
    pub fn solve(&self, rhs: &[Vec<f64>], prescribed: &[Vec<f64>]) -> Vec<Vec<f64>> {
        let nf = self.free.len();
        let m = rhs.len();
        // Freed DOFs are unknowns: no prescribed value of theirs enters the right-hand side
        // (a bordered DOF held again enters through W, below).
        let mut prescribed = prescribed.to_vec();
        let given: Vec<Vec<f64>> = match &self.border {
            Some(bd) => prescribed
                .iter_mut()
                .map(|p| {
                    bd.added
                        .iter()
                        .map(|g| std::mem::replace(&mut p[*g], 0.0))
                        .collect()
                })
                .collect(),
            None => Vec::new(),
        };
        let mut b = faer::Mat::<f64>::zeros(nf, m);
        for c in 0..m {
            for (i, &g) in self.free.iter().enumerate() {
                b[(i, c)] = rhs[c][g];
            }
            for &(fr, gc, v) in &self.coupling {
                b[(fr, c)] -= v * prescribed[c][gc];
            }
        }
        let x = match &self.border {
            None => {
                self.llt.solve_in_place(b.as_mut());
                b
            }
            Some(bd) => {
                let mut z = self.llt.forward(b.as_ref());
                let zg = faer::Mat::<f64>::from_fn(bd.g_at.len(), m, |i, c| z[(bd.g_at[i], c)]);
                let gtz = bd.g.transpose() * zg.as_ref();
                let k = bd.added.len();
                let mut ys = faer::Mat::<f64>::zeros(k, m);
                for c in 0..m {
                    let mut g = nalgebra::DVector::<f64>::from_iterator(
                        k,
                        bd.added
                            .iter()
                            .enumerate()
                            .map(|(e, a)| rhs[c][*a] - gtz[(e, c)]),
                    );
                    for &(e, col, v) in &bd.coupling {
                        g[e] -= v * prescribed[c][col];
                    }
                    // Held DOFs take their given values; the others solve S_uu y_u = g_u − S_uh y_h.
                    let mut y = nalgebra::DVector::<f64>::zeros(k);
                    for e in 0..k {
                        if bd.held[e] {
                            y[e] = given[c][e];
                        }
                    }
                    if let Some(s) = &bd.s {
                        let mut gu = nalgebra::DVector::<f64>::from_iterator(
                            bd.unknown.len(),
                            bd.unknown.iter().map(|e| g[*e]),
                        );
                        for (i, &e) in bd.unknown.iter().enumerate() {
                            for d in (0..k).filter(|d| bd.held[*d]) {
                                gu[i] -= bd.schur[(e, d)] * y[d];
                            }
                        }
                        let yu = s.solve(&gu);
                        for (i, &e) in bd.unknown.iter().enumerate() {
                            y[e] = yu[i];
                        }
                    }
                    for (e, a) in bd.added.iter().enumerate() {
                        ys[(e, c)] = y[e];
                        prescribed[c][*a] = y[e];
                    }
                }
                // z − G y, then the backward sweep, every case at once.
                let gy = bd.g.as_ref() * ys.as_ref();
                for c in 0..m {
                    for (i, p) in bd.g_at.iter().enumerate() {
                        z[(*p, c)] -= gy[(i, c)];
                    }
                }
                let mut x = faer::Mat::<f64>::zeros(nf, m);
                self.llt.backward(z, x.as_mut());
                x
            }
        };
        (0..m)
            .map(|c| {
                let mut a = prescribed[c].clone();
                for (i, &g) in self.free.iter().enumerate() {
                    a[g] = x[(i, c)];
                }
                a
            })
            .collect()
    }
}

/// Global DOF → free index (usize::MAX for fixed DOFs), and the free DOFs in increasing order.
pub fn free_dofs(fixed: &[bool]) -> (Vec<usize>, Vec<usize>) {
    let mut free_index = vec![usize::MAX; fixed.len()];
    let mut free = Vec::new();
    for (g, &f) in fixed.iter().enumerate() {
        if !f {
            free_index[g] = free.len();
            free.push(g);
        }
    }
    (free_index, free)
}

/// The free–free lower triangle as a sparse matrix, and the free-row/fixed-column couplings.
type Split = (SparseColMat<usize, f64>, Vec<(usize, usize, f64)>);

fn split(k: &[(usize, usize, f64)], free_index: &[usize], nf: usize) -> Result<Split> {
    let mut lower = Vec::new();
    let mut coupling = Vec::new();
    for &(r, c, v) in k {
        let (fr, fc) = (free_index[r], free_index[c]);
        match (fr != usize::MAX, fc != usize::MAX) {
            // Free indices increase with global ones, so r ≥ c gives fr ≥ fc.
            (true, true) => lower.push(Triplet::new(fr, fc, v)),
            (true, false) => coupling.push((fr, c, v)),
            (false, true) => coupling.push((fc, r, v)),
            (false, false) => {}
        }
    }
    let mat = SparseColMat::<usize, f64>::try_new_from_triplets(nf, nf, &lower)
        .map_err(|e| Error::numerical(NumericalKind::Singular, format!("sparse matrix: {e:?}")))?;
    Ok((mat, coupling))
}

/// Boundary conditions from rigid vertices (Koch §4.1): a rigid vertex has value and gradient
/// fixed; an edge's cross-boundary derivative is fixed when both its ends are rigid.
pub fn rigid_dofs(mesh: &FemMesh, rigid: &[bool]) -> Vec<bool> {
    let dofs = mesh.dofs();
    let mut fixed = vec![false; dofs.ndof()];
    for (v, &r) in rigid.iter().enumerate() {
        if r {
            fixed[dofs.vertex(v)].iter_mut().for_each(|f| *f = true);
        }
    }
    for (e, ed) in mesh.edges.iter().enumerate() {
        if rigid[ed[0] as usize] && rigid[ed[1] as usize] {
            fixed[dofs.edge(e)] = true;
        }
    }
    fixed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Column-wise gathering gives bit for bit what sorting all element triplets gives.
    #[test]
    fn gathered_columns_equal_the_sorted_element_triplets() {
        // A jittered 9×7 grid with per-element materials.
        let (nx, ny) = (9usize, 7usize);
        let mut uv = Vec::new();
        for j in 0..=ny {
            for i in 0..=nx {
                let w = ((i * 7 + j * 13) % 5) as f64 * 0.05;
                uv.push([i as f64 + w, j as f64 - w]);
            }
        }
        let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
        let mut tris = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let mesh = FemMesh::new(uv, tris).unwrap();
        let mat = |t: usize| Material::isotropic(0.01 * (1 + t % 3) as f64, 0.02);
        let (k, _) = mesh.assemble(&mat, 1.0);
        let mut all = Vec::new();
        for t in 0..mesh.tris.len() {
            let (ke, _) = mesh.elements[t].stiffness_fast(&mat(t), 1.0);
            let d = mesh.element_dofs(t);
            for i in 0..NDOF {
                for j in 0..NDOF {
                    if d[i] >= d[j] {
                        all.push((d[i], d[j], ke[i][j]));
                    }
                }
            }
        }
        let reference = sum_duplicates(all);
        assert_eq!(k.len(), reference.len());
        for (a, b) in k.iter().zip(&reference) {
            assert_eq!((a.0, a.1), (b.0, b.1));
            assert_eq!(a.2.to_bits(), b.2.to_bits(), "entry {:?}", (a.0, a.1));
        }
    }

    /// K's lower triangle, the fixed DOFs and a load.
    type Chain = (Vec<(usize, usize, f64)>, Vec<bool>, Vec<f64>);

    /// A 1-D chain of springs with ground springs, stiffness varying: SPD, fully coupled.
    fn chain() -> Chain {
        let n = 40;
        let mut k = Vec::new();
        for i in 0..n {
            k.push((i, i, 2.5 + (i % 7) as f64 * 0.3));
            if i > 0 {
                k.push((i, i - 1, -1.0 - (i % 3) as f64 * 0.2));
            }
            if i > 4 {
                k.push((i, i - 5, -0.1));
            }
        }
        let mut fixed = vec![false; n];
        for i in [0, 3, 4, 11, 12, 20, 27, 39] {
            fixed[i] = true;
        }
        let rhs: Vec<f64> = (0..n).map(|i| ((i * 13) % 5) as f64 - 2.0).collect();
        (k, fixed, rhs)
    }

    /// `bordered` solves (rhs, pre) as a fresh factorisation with `fixed` does, to 1e-12.
    fn assert_solves_as_factored(
        bordered: &System,
        k: &[(usize, usize, f64)],
        fixed: &[bool],
        rhs: &[f64],
        pre: &[f64],
        what: &str,
    ) {
        let fresh = System::new(fixed.len(), k.to_vec(), fixed).unwrap();
        let (rhs, pre) = (vec![rhs.to_vec()], vec![pre.to_vec()]);
        let a = &bordered.solve(&rhs, &pre)[0];
        let b = &fresh.solve(&rhs, &pre)[0];
        for i in 0..fixed.len() {
            assert!(
                (a[i] - b[i]).abs() < 1e-12 * (1.0 + b[i].abs()),
                "{what}: DOF {i}: {} {}",
                a[i],
                b[i]
            );
        }
    }

    /// A 7-point Laplacian on a 12³ grid with every 9th DOF fixed: a factor faer makes
    /// supernodal (the chain's is simplicial), whose forward sweep the border runs apart.
    fn grid() -> Chain {
        let m = 12;
        let k = crate::fem::cholesky::grid_laplacian(m);
        let n = m * m * m;
        let fixed: Vec<bool> = (0..n).map(|i| i % 9 == 0).collect();
        let rhs: Vec<f64> = (0..n).map(|i| ((i * 7) % 11) as f64 - 5.0).collect();
        (k, fixed, rhs)
    }

    /// Bordered DOFs held again (at their prescribed values), freed again and joined by new
    /// ones give what a factorisation with that set fixed gives: the contact rounds' sequence,
    /// on a simplicial factor (the chain) and a supernodal one (the grid).
    #[test]
    fn bordered_dofs_held_again_equal_factoring_with_them_fixed() {
        // (freed, held again) per round; the last frees a held one again and a new one.
        let chain_rounds: [(&[usize], &[usize]); 4] = [
            (&[11, 27, 4], &[]),
            (&[], &[27]),
            (&[12], &[11, 4]),
            (&[27, 39, 4], &[12]),
        ];
        let grid_rounds: [(&[usize], &[usize]); 4] = [
            (&[9, 900, 1503, 1719, 18, 27], &[]),
            (&[], &[900, 18]),
            (&[855, 450], &[9, 1503]),
            (&[900, 1503, 1017], &[855]),
        ];
        for ((k, mut fixed, rhs), rounds) in [(chain(), chain_rounds), (grid(), grid_rounds)] {
            let n = fixed.len();
            let pre: Vec<f64> = (0..n).map(|i| 0.1 * (i % 40) as f64 - 1.0).collect();
            let mut bordered = System::new(n, k.clone(), &fixed).unwrap();
            assert_eq!(bordered.llt.pattern().is_supernodal(), n > 1000);
            for (freed, held) in rounds {
                if !freed.is_empty() {
                    bordered.free_more(freed).unwrap();
                }
                if !held.is_empty() {
                    bordered.hold_border(held).unwrap();
                }
                freed.iter().for_each(|g| fixed[*g] = false);
                held.iter().for_each(|g| fixed[*g] = true);
                let what = format!("{n} DOFs: freed {freed:?}, held again {held:?}");
                assert_solves_as_factored(&bordered, &k, &fixed, &rhs, &pre, &what);
            }
            // A DOF never bordered cannot be held again.
            assert!(bordered.hold_border(&[5]).is_err());
        }
    }

    /// Freeing fixed DOFs by bordering the factor gives what a factorisation with them free
    /// gives, for loads and prescribed values alike, over two rounds of freeing.
    #[test]
    fn bordered_freeing_equals_factoring_with_the_dofs_free() {
        let (k, mut fixed, rhs) = chain();
        let n = fixed.len();
        let pre: Vec<f64> = (0..n)
            .map(|i| if fixed[i] { 0.1 * i as f64 } else { 0.0 })
            .collect();
        let mut bordered = System::new(n, k.clone(), &fixed).unwrap();
        for freed in [vec![11, 27], vec![4, 12, 39]] {
            bordered.free_more(&freed).unwrap();
            freed.iter().for_each(|g| fixed[*g] = false);
            let what = format!("freed {freed:?}");
            assert_solves_as_factored(&bordered, &k, &fixed, &rhs, &pre, &what);
        }
    }
}

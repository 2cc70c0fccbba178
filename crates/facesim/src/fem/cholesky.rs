//! The one sparse Cholesky wrapper over faer: a symbolic analysis (AMD ordering, elimination
//! tree) done once per sparsity pattern, numeric factors of any matrix on that pattern (in f64,
//! or f32 for the preconditioner), each solved for many right-hand sides.
//!
//! Sequential except for large factors: faer's own multithreading of the sparse factorisation
//! and triangular solves costs more than it gains on the surface models on 2 cores (40k
//! triangles: factor 0.48 s sequential vs 0.59–0.66 s threaded, three solves 0.05 s vs 0.15 s;
//! docs/design/fem.md), where rayon parallelises the element work instead; a volumetric head's factor
//! (tens of millions of nonzeros) is factored on all cores (`PARALLEL_FACTOR_NNZ`).

use super::ordering::NodeOrder;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::LltError;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::traits::ComplexField;
use faer::{Accum, Conj, Mat, MatMut, MatRef, Par, Side};
use std::sync::{Arc, Mutex};

pub use faer::sparse::FaerError;

/// The symbolic analysis of a lower-triangle sparsity pattern, shared by the factors on it.
#[derive(Clone)]
pub struct Pattern(Arc<SymbolicCholesky<usize>>);

/// The fill-reducing ordering of a factorisation (fem/ordering.rs says when each wins).
#[derive(Clone, Copy)]
pub enum Ordering<'a> {
    /// Approximate minimum degree (faer): the surface models.
    Amd,
    /// Nested dissection (METIS) on the DOF groups: the volumetric meshes; AMD if METIS fails.
    NestedDissection,
    /// A mesh's node ordering, computed once, expanded to the free DOFs (3 per node); nested
    /// dissection on the DOF groups if it does not cover them. A pattern analysed in it before
    /// is not analysed again.
    Nodes(&'a MeshAnalyses),
}

/// A mesh's node ordering and the symbolic analyses made in it, shared by every factor on the
/// mesh: the run's, its tearing rounds' and each uncertainty sample's. The pattern of a factor
/// is the mesh's connectivity restricted to the free DOFs (values do not enter it), so samples
/// with the same holds (the same sliding state) share one analysis: 0.1 s each on the real CT,
/// where the 8 samples of a band made 8. (Found by its pattern, matched exactly, not by the
/// holds: any analysis of a pattern is right for every matrix on it.)
pub struct MeshAnalyses {
    order: NodeOrder,
    /// The last few patterns analysed, each with a copy of its pattern to be matched exactly.
    done: Mutex<Vec<Analysed>>,
}

/// A pattern's column pointers and row indices (u32: 20 MB for the real CT's 84 k columns, half
/// of usize) and its analysis.
struct Analysed {
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    pattern: Pattern,
}

impl Analysed {
    fn of(lower: SymbolicSparseColMatRef<'_, usize>, pattern: &Pattern) -> Option<Analysed> {
        let narrow = |v: &[usize]| -> Option<Vec<u32>> {
            v.iter().map(|i| u32::try_from(*i).ok()).collect()
        };
        // A pattern with gaps in its columns (col_nnz) is not kept: it is not matched by its
        // pointers and rows alone.
        if lower.col_nnz().is_some() {
            return None;
        }
        Some(Analysed {
            col_ptr: narrow(lower.col_ptr())?,
            row_idx: narrow(lower.row_idx())?,
            pattern: pattern.clone(),
        })
    }

    fn matches(&self, lower: SymbolicSparseColMatRef<'_, usize>) -> bool {
        let same = |a: &[u32], b: &[usize]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| *x as usize == *y)
        };
        lower.col_nnz().is_none()
            && same(&self.col_ptr, lower.col_ptr())
            && same(&self.row_idx, lower.row_idx())
    }
}

/// Patterns `MeshAnalyses` keeps: the sliding states a band draws, the run's own, its
/// lifted-off variant.
const KEPT_ANALYSES: usize = 4;

impl MeshAnalyses {
    pub(crate) fn new(order: NodeOrder) -> MeshAnalyses {
        MeshAnalyses {
            order,
            done: Mutex::new(Vec::new()),
        }
    }

    /// The analysis of `lower` (its columns the free DOFs `dofs`), made once per pattern.
    fn analysed(
        &self,
        lower: SymbolicSparseColMatRef<'_, usize>,
        dofs: &[usize],
    ) -> Result<Pattern, FaerError> {
        // A poisoned lock only means another analysis panicked; the list is still whole.
        let done = || self.done.lock().unwrap_or_else(|p| p.into_inner());
        let found = done()
            .iter()
            .find(|a| a.matches(lower))
            .map(|a| a.pattern.clone());
        if let Some(p) = found {
            return Ok(p);
        }
        let nd = self
            .order
            .dofs(dofs)
            .or_else(|| super::ordering::nested_dissection(lower));
        let pattern = Pattern::analyse_in(lower, nd)?;
        if let Some(a) = Analysed::of(lower, &pattern) {
            let mut done = done();
            if done.len() >= KEPT_ANALYSES {
                done.remove(0);
            }
            done.push(a);
        }
        Ok(pattern)
    }
}

impl Pattern {
    pub(crate) fn analyse(lower: SymbolicSparseColMatRef<'_, usize>) -> Result<Pattern, FaerError> {
        Self::analyse_with(lower, Ordering::Amd, &[])
    }

    /// The analysis of `lower` in `ordering`; `dofs` gives each column's global DOF (3 node +
    /// component), which only `Ordering::Nodes` reads.
    pub(crate) fn analyse_with(
        lower: SymbolicSparseColMatRef<'_, usize>,
        ordering: Ordering<'_>,
        dofs: &[usize],
    ) -> Result<Pattern, FaerError> {
        let nd = match ordering {
            Ordering::Amd => None,
            Ordering::Nodes(mesh) if dofs.len() == lower.ncols() => {
                return mesh.analysed(lower, dofs);
            }
            Ordering::NestedDissection | Ordering::Nodes(_) => {
                super::ordering::nested_dissection(lower)
            }
        };
        Self::analyse_in(lower, nd)
    }

    /// The analysis of `lower` in the permutation `nd` (`(forward, inverse)`), AMD if none.
    fn analyse_in(
        lower: SymbolicSparseColMatRef<'_, usize>,
        nd: Option<(Vec<usize>, Vec<usize>)>,
    ) -> Result<Pattern, FaerError> {
        let order = match &nd {
            Some((fwd, inv)) => {
                SymmetricOrdering::Custom(PermRef::new_checked(fwd, inv, fwd.len()))
            }
            None => SymmetricOrdering::Amd,
        };
        let s = factorize_symbolic_cholesky(
            lower,
            Side::Lower,
            order,
            CholeskySymbolicParams::default(),
        )?;
        Ok(Pattern(Arc::new(s)))
    }

    /// Whether `other` is this very analysis (shared, not made again).
    #[cfg(test)]
    pub(crate) fn is(&self, other: &Pattern) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }

    /// Nonzeros of the factor L.
    pub fn factor_nnz(&self) -> usize {
        self.0.len_val()
    }

    /// The order of the analysed matrix.
    pub(crate) fn columns(&self) -> usize {
        self.0.ncols()
    }

    /// Floating-point operations of the numeric factorisation, Σ over the factor's columns of
    /// the squared column count (the dense update each column makes): what `facesim estimate`
    /// scales its time with.
    pub(crate) fn factor_flops(&self) -> f64 {
        match self.0.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => {
                let (begin, end) = (s.supernode_begin(), s.supernode_end());
                let rows = s.col_ptr_for_row_idx();
                (0..s.n_supernodes())
                    .map(|k| {
                        let width = (end[k] - begin[k]) as f64;
                        let below = (rows[k + 1] - rows[k]) as f64;
                        // Column j of the block has (width - j) + below entries.
                        (0..width as usize)
                            .map(|j| (width - j as f64 + below).powi(2))
                            .sum::<f64>()
                    })
                    .sum()
            }
            SymbolicCholeskyRaw::Simplicial(s) => {
                let ptr = s.col_ptr();
                ptr.windows(2).map(|w| ((w[1] - w[0]) as f64).powi(2)).sum()
            }
        }
    }

    /// Whether faer chose its supernodal factor (dense blocks) over the simplicial one.
    #[cfg(test)]
    pub(crate) fn is_supernodal(&self) -> bool {
        matches!(self.0.raw(), SymbolicCholeskyRaw::Supernodal(_))
    }
}

/// Factors with at least this many nonzeros are factored on all cores: their dense supernodes
/// are large enough for faer's parallel kernels to pay (a volumetric head of 142 k unknowns,
/// 98 M nonzeros: 9.9 s sequential, 8.2 s on 2 cores; one of 23 k unknowns, 7.4 M nonzeros:
/// 0.27 s sequential, 0.39 s on 2 cores; the surface models' largest, 41 M at 80 k triangles,
/// stays sequential as measured in docs/design/fem.md).
pub(crate) const PARALLEL_FACTOR_NNZ: usize = 50_000_000;

/// How many factorisations of `nnz` nonzeros to run side by side (full re-solves, the
/// uncertainty samples): a factor below `PARALLEL_FACTOR_NNZ` is factored on one core, so one
/// per core, at most 4 (each holds its own factor); a larger one already uses every core.
pub(crate) fn factorisations_at_once(nnz: usize) -> usize {
    if nnz >= PARALLEL_FACTOR_NNZ {
        1
    } else {
        rayon::current_num_threads().clamp(1, 4)
    }
}

fn factor_par(nnz: usize) -> Par {
    if nnz >= PARALLEL_FACTOR_NNZ {
        Par::rayon(0)
    } else {
        Par::Seq
    }
}

/// The numeric factor L Lᵀ of a symmetric positive definite matrix on a `Pattern`.
pub struct Cholesky<T> {
    pattern: Pattern,
    values: Vec<T>,
}

impl<T: ComplexField + Copy> Cholesky<T> {
    /// Factor `m` (its lower triangle) on `pattern`'s analysis; an error if `m` is not
    /// (numerically) positive definite.
    pub fn factor(pattern: &Pattern, m: SparseColMatRef<'_, usize, T>) -> Result<Self, LltError> {
        let symbolic = &pattern.0;
        let par = factor_par(symbolic.len_val());
        let mut values = vec![T::zero_impl(); symbolic.len_val()];
        let scratch = symbolic.factorize_numeric_llt_scratch::<T>(par, Default::default());
        let mut mem =
            MemBuffer::try_new(scratch).map_err(|_| LltError::Generic(FaerError::OutOfMemory))?;
        symbolic.factorize_numeric_llt(
            &mut values,
            m,
            Side::Lower,
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )?;
        Ok(Cholesky {
            pattern: pattern.clone(),
            values,
        })
    }

    /// Analyse `m`'s pattern and factor it.
    pub fn new(m: SparseColMatRef<'_, usize, T>) -> Result<Self, LltError> {
        let pattern = Pattern::analyse(m.symbolic()).map_err(LltError::Generic)?;
        Self::factor(&pattern, m)
    }

    /// Refactor for new values on the same pattern, reusing the symbolic analysis; on failure
    /// the previous factor is kept.
    pub fn refactor(&mut self, m: SparseColMatRef<'_, usize, T>) -> Result<(), LltError> {
        *self = Self::factor(&self.pattern, m)?;
        Ok(())
    }

    pub(crate) fn pattern(&self) -> &Pattern {
        &self.pattern
    }

    /// Overwrite each column of `b` with the solution of L Lᵀ x = b.
    pub fn solve_in_place(&self, b: MatMut<'_, T>) {
        let symbolic = &self.pattern.0;
        let mut mem = MemBuffer::new(symbolic.solve_in_place_scratch::<T>(b.ncols(), Par::Seq));
        LltRef::new(symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            b,
            Par::Seq,
            MemStack::new(&mut mem),
        );
    }
}

impl Cholesky<f64> {
    /// The factor with its entries rounded to f32: a preconditioner's coarse solve, which reads
    /// half the bytes (fem/pmultigrid.rs).
    pub(crate) fn to_f32(&self) -> Cholesky<f32> {
        Cholesky {
            pattern: self.pattern.clone(),
            values: self.values.iter().map(|v| *v as f32).collect(),
        }
    }
}

/// The factor's two triangular sweeps taken apart, A = Pᵀ L Lᵀ P: the forward sweep's
/// result L⁻¹ P b lives in the factor's own row order (its "positions"). A bordered system
/// needs them apart: its Schur complement is C − Gᵀ G with G = L⁻¹ P B, and a solve runs the
/// forward sweep, the border, then the backward sweep (fem/assembly.rs, `Border`).
impl Cholesky<f64> {
    /// L⁻¹ P b for each column of b.
    pub(crate) fn forward(&self, b: MatRef<'_, f64>) -> Mat<f64> {
        let (fwd, _) = self.perm();
        let mut x = Mat::from_fn(b.nrows(), b.ncols(), |i, j| b[(fwd[i], j)]);
        match self.pattern.0.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) => {
                let llt = SupernodalLltRef::new(sn, &self.values);
                let all = vec![true; sn.n_supernodes()];
                let identity: Vec<usize> = (0..x.nrows()).collect();
                forward_sweep(llt, &all, &identity, x.as_mut());
            }
            SymbolicCholeskyRaw::Simplicial(sym) => {
                let l = SparseColMatRef::new(sym.factor(), &self.values);
                faer::sparse::linalg::triangular_solve::solve_lower_triangular_in_place(
                    l,
                    Conj::No,
                    x.as_mut(),
                    Par::Seq,
                );
            }
        }
        x
    }

    /// L⁻¹ P B for a sparse B (`b`: row, column, value; `ncols` columns), computed only where
    /// it can be nonzero: on the positions of the supernodes on the elimination tree paths from
    /// B's rows to the root (the "reach", Gilbert & Peierls 1988). Returns those positions and
    /// L⁻¹ P B on them (zero on every other). The neighbours of the 263 nodes the real CT's
    /// degloved maxilla lifts first reach about a quarter of its factor's 27 M stored values,
    /// and nothing of the size of the whole system is made.
    pub(crate) fn forward_from(
        &self,
        b: &[(usize, usize, f64)],
        ncols: usize,
    ) -> (Vec<usize>, Mat<f64>) {
        let n = self.pattern.0.nrows();
        let SymbolicCholeskyRaw::Supernodal(sn) = self.pattern.0.raw() else {
            // A simplicial factor (a small system): every position, the whole sweep.
            let mut dense = Mat::<f64>::zeros(n, ncols);
            b.iter().for_each(|(r, c, v)| dense[(*r, *c)] += v);
            return ((0..n).collect(), self.forward(dense.as_ref()));
        };
        let (_, inv) = self.perm();
        let llt = SupernodalLltRef::new(sn, &self.values);
        let begin = sn.supernode_begin();
        let owner = |p: usize| begin.partition_point(|s| *s <= p) - 1;
        let mut reach = vec![false; sn.n_supernodes()];
        for &(r, _, _) in b {
            let mut s = owner(inv[r]);
            while !reach[s] {
                reach[s] = true;
                // The parent supernode holds the first row below the diagonal block.
                match llt.supernode(s).pattern().iter().min() {
                    Some(p) => s = owner(*p),
                    None => break,
                }
            }
        }
        // The reached positions, each supernode's together and in order (a path's ancestors
        // are reached too, so every row a reached supernode updates has a slot).
        let at: Vec<usize> = (0..reach.len())
            .filter(|s| reach[*s])
            .flat_map(|s| {
                let node = llt.supernode(s);
                node.start()..node.start() + node.val().ncols()
            })
            .collect();
        let mut slot = vec![usize::MAX; n];
        at.iter().enumerate().for_each(|(i, p)| slot[*p] = i);
        let mut x = Mat::<f64>::zeros(at.len(), ncols);
        b.iter().for_each(|(r, c, v)| x[(slot[inv[*r]], *c)] += v);
        forward_sweep(llt, &reach, &slot, x.as_mut());
        (at, x)
    }

    /// Pᵀ L⁻ᵀ z for each column of z (in the factor's order), written to `out`.
    pub(crate) fn backward(&self, mut z: Mat<f64>, mut out: MatMut<'_, f64>) {
        match self.pattern.0.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) => {
                let llt = SupernodalLltRef::new(sn, &self.values);
                let widest = (0..sn.n_supernodes())
                    .map(|s| llt.supernode(s).pattern().len())
                    .max()
                    .unwrap_or(0);
                let mut tmp = Mat::<f64>::zeros(widest, z.ncols());
                for s in (0..sn.n_supernodes()).rev() {
                    let node = llt.supernode(s);
                    let (top, bot) = node.val().split_at_row(node.val().ncols());
                    let pattern = node.pattern();
                    let mut t = tmp.as_mut().subrows_mut(0, pattern.len());
                    for j in 0..z.ncols() {
                        for (idx, i) in pattern.iter().enumerate() {
                            t[(idx, j)] = z[(*i, j)];
                        }
                    }
                    let mut zt = z.as_mut().subrows_mut(node.start(), top.ncols());
                    faer::linalg::matmul::matmul(
                        zt.rb_mut(),
                        Accum::Add,
                        bot.transpose(),
                        t.rb(),
                        -1.0,
                        Par::Seq,
                    );
                    faer::linalg::triangular_solve::solve_upper_triangular_in_place(
                        top.transpose(),
                        zt,
                        Par::Seq,
                    );
                }
            }
            SymbolicCholeskyRaw::Simplicial(sym) => {
                let l = SparseColMatRef::new(sym.factor(), &self.values);
                faer::sparse::linalg::triangular_solve::solve_lower_triangular_transpose_in_place(
                    l,
                    Conj::No,
                    z.as_mut(),
                    Par::Seq,
                );
            }
        }
        let (_, inv) = self.perm();
        for j in 0..z.ncols() {
            for (i, p) in inv.iter().enumerate() {
                out[(i, j)] = z[(*p, j)];
            }
        }
    }

    /// The factor's row order: (forward, inverse), position i holding the matrix's row
    /// forward[i] (the identity when faer chose none).
    fn perm(&self) -> (std::borrow::Cow<'_, [usize]>, std::borrow::Cow<'_, [usize]>) {
        match self.pattern.0.perm() {
            Some(p) => {
                let (f, i) = p.arrays();
                (f.into(), i.into())
            }
            None => {
                let id: Vec<usize> = (0..self.pattern.0.nrows()).collect();
                (id.clone().into(), id.into())
            }
        }
    }
}

/// L's forward sweep on the supernodes marked in `on`, in place (faer's own sweep with the
/// unmarked supernodes skipped: their rows must be zero, and stay so). x's rows are the factor
/// positions through `slot` (a supernode's positions in consecutive rows).
fn forward_sweep(
    llt: SupernodalLltRef<'_, usize, f64>,
    on: &[bool],
    slot: &[usize],
    mut x: MatMut<'_, f64>,
) {
    let widest = (0..on.len())
        .filter(|s| on[*s])
        .map(|s| llt.supernode(s).pattern().len())
        .max()
        .unwrap_or(0);
    let mut tmp = Mat::<f64>::zeros(widest, x.ncols());
    for s in (0..on.len()).filter(|s| on[*s]) {
        let node = llt.supernode(s);
        let (top, bot) = node.val().split_at_row(node.val().ncols());
        let pattern = node.pattern();
        let mut xt = x.rb_mut().subrows_mut(slot[node.start()], top.ncols());
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(top, xt.rb_mut(), Par::Seq);
        let mut t = tmp.as_mut().subrows_mut(0, pattern.len());
        faer::linalg::matmul::matmul(t.rb_mut(), Accum::Replace, bot, xt.rb(), 1.0, Par::Seq);
        for j in 0..x.ncols() {
            for (idx, i) in pattern.iter().enumerate() {
                x[(slot[*i], j)] -= t[(idx, j)];
            }
        }
    }
}

/// The factor of a stiffness matrix with three DOFs per node on `elements` (each a list of node
/// indices), restricted to the nodes `solved`, analysed in `ordering` without any value: what
/// `facesim estimate` reads the size of a run's factor from before any numeric work.
pub(crate) fn pattern_of_elements<'e>(
    solved: &[bool],
    elements: impl Iterator<Item = &'e [u32]> + Clone,
    ordering: Ordering<'_>,
) -> Result<Pattern, FaerError> {
    let (lower, dofs) = lower_pattern_of_elements(solved, elements, 3);
    Pattern::analyse_with(lower.as_ref(), ordering, &dofs)
}

/// [`pattern_of_elements`]'s system seen from its node graph (one unknown per solved node).
pub(crate) struct NodeGraphSize {
    /// The nonzeros of the DOF factor in nested dissection, estimated: the DOF ordering keeps a
    /// node's three DOFs together (METIS orders the graph of nodes either way), so each nonzero
    /// of the node factor stands for a 3 × 3 block. Nodes with a held component count whole, so
    /// the estimate errs high by their share.
    pub(crate) factor_nnz: usize,
    /// The 3 × 3 blocks of the stiffness's lower triangle (node pairs sharing an element, each
    /// node with itself): what the iterative solve stores.
    pub(crate) lower_blocks: usize,
}

/// [`NodeGraphSize`] of a stiffness on `elements` restricted to the nodes `solved`. Its pattern
/// has a ninth of the DOF pattern's entries, so the 10-node model decides whether its factor
/// fits without allocating the DOF-level analysis (on the jaws sample that analysis set the
/// run's peak: 4.5 GB against 2.9 GB without it).
pub(crate) fn node_graph_size<'e>(
    solved: &[bool],
    elements: impl Iterator<Item = &'e [u32]> + Clone,
) -> Result<NodeGraphSize, FaerError> {
    let (lower, _) = lower_pattern_of_elements(solved, elements, 1);
    let nodes = Pattern::analyse_with(lower.as_ref(), Ordering::NestedDissection, &[])?;
    Ok(NodeGraphSize {
        factor_nnz: 9 * nodes.factor_nnz(),
        lower_blocks: lower.compute_nnz(),
    })
}

/// The lower pattern of a matrix with `components` unknowns per node on `elements`, restricted
/// to the `solved` nodes, and each column's global DOF (`components` node + component).
fn lower_pattern_of_elements<'e>(
    solved: &[bool],
    elements: impl Iterator<Item = &'e [u32]> + Clone,
    components: usize,
) -> (faer::sparse::SymbolicSparseColMat<usize>, Vec<usize>) {
    let mut index = vec![usize::MAX; solved.len()];
    let mut count = 0;
    for (i, s) in index.iter_mut().zip(solved) {
        if *s {
            *i = count;
            count += 1;
        }
    }
    // Each solved node's solved neighbours at or after it, ascending (itself included).
    let mut after: Vec<Vec<u32>> = vec![Vec::new(); count];
    for e in elements {
        for &a in e {
            let ia = index[a as usize];
            if ia == usize::MAX {
                continue;
            }
            for &b in e {
                let ib = index[b as usize];
                if ib != usize::MAX && ib >= ia {
                    after[ia].push(ib as u32);
                }
            }
        }
    }
    let c = components;
    let mut col_ptr = Vec::with_capacity(c * count + 1);
    let mut row_idx = Vec::new();
    let mut dofs = Vec::with_capacity(c * count);
    col_ptr.push(0usize);
    let nodes: Vec<usize> = (0..solved.len()).filter(|n| solved[*n]).collect();
    for (ia, list) in after.iter_mut().enumerate() {
        list.sort_unstable();
        list.dedup();
        for j in 0..c {
            for &ib in list.iter() {
                let first = if ib as usize == ia { j } else { 0 };
                row_idx.extend((first..c).map(|i| c * ib as usize + i));
            }
            col_ptr.push(row_idx.len());
            dofs.push(c * nodes[ia] + j);
        }
        // The node's list is no longer needed: free it as the pattern grows.
        *list = Vec::new();
    }
    let n = c * count;
    (
        faer::sparse::SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx),
        dofs,
    )
}

#[cfg(test)]
/// The lower triangle of a 7-point Laplacian on an m³ grid with a varying diagonal shift: SPD,
/// and from m ≈ 10 large enough for faer to factor it supernodally (the tests here and the
/// bordered factor's in fem/assembly.rs).
pub(crate) fn grid_laplacian(m: usize) -> Vec<(usize, usize, f64)> {
    let id = |x: usize, y: usize, z: usize| x + m * (y + m * z);
    let mut t = Vec::new();
    for z in 0..m {
        for y in 0..m {
            for x in 0..m {
                let i = id(x, y, z);
                t.push((i, i, 6.1 + (i % 5) as f64 * 0.1));
                for (a, b, c) in [(x + 1, y, z), (x, y + 1, z), (x, y, z + 1)] {
                    if a < m && b < m && c < m {
                        t.push((id(a, b, c), i, -1.0));
                    }
                }
            }
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::{SparseColMat, Triplet};

    /// The grid Laplacian as a sparse matrix.
    fn grid(m: usize) -> SparseColMat<usize, f64> {
        let t: Vec<Triplet<usize, usize, f64>> = grid_laplacian(m)
            .into_iter()
            .map(|(r, c, v)| Triplet::new(r, c, v))
            .collect();
        SparseColMat::try_new_from_triplets(m * m * m, m * m * m, &t).unwrap()
    }

    /// The sweeps apart equal the whole solve, and the forward sweep from a sparse B equals the
    /// whole forward sweep of B on the positions it reports and is zero on every other: on a
    /// supernodal factor (the reach is then a strict part of it) and a simplicial one.
    #[test]
    fn sweeps_apart_and_from_a_sparse_b_equal_the_whole_solve() {
        for (m, supernodal) in [(14, true), (3, false)] {
            let a = grid(m);
            let n = a.nrows();
            let llt = Cholesky::new(a.as_ref()).unwrap();
            assert_eq!(llt.pattern().is_supernodal(), supernodal, "{m}³ grid");
            // Three columns: one node, two neighbours, a corner and the centre.
            let c = n / 2 + m / 2;
            let b: Vec<(usize, usize, f64)> = vec![
                (5, 0, 1.0),
                (c, 1, -2.0),
                (c + 1, 1, 0.5),
                (0, 2, 1.5),
                (n - 1, 2, 1.0),
            ];
            let mut dense = Mat::<f64>::zeros(n, 3);
            b.iter().for_each(|(r, j, v)| dense[(*r, *j)] += v);
            let whole = llt.forward(dense.as_ref());
            let (at, g) = llt.forward_from(&b, 3);
            let mut on = vec![false; n];
            for (i, p) in at.iter().enumerate() {
                on[*p] = true;
                for j in 0..3 {
                    assert!(
                        (g[(i, j)] - whole[(*p, j)]).abs() < 1e-13,
                        "{m}³: position {p}"
                    );
                }
            }
            for p in (0..n).filter(|p| !on[*p]) {
                for j in 0..3 {
                    assert_eq!(whole[(p, j)], 0.0, "{m}³: position {p} is not reached");
                }
            }
            if supernodal {
                assert!(at.len() < n, "the reach is the whole factor");
            }
            let mut apart = Mat::<f64>::zeros(n, 3);
            llt.backward(whole, apart.as_mut());
            let mut together = dense.clone();
            llt.solve_in_place(together.as_mut());
            for i in 0..n {
                for j in 0..3 {
                    assert!(
                        (apart[(i, j)] - together[(i, j)]).abs() < 1e-13,
                        "{m}³: row {i}"
                    );
                }
            }
        }
    }

    /// The factor analysed from the elements alone, for `facesim estimate`, is the very factor
    /// of the assembled stiffness with the same nodes held, in the same ordering.
    #[test]
    fn the_pattern_of_the_elements_is_the_assembled_stiffness_pattern() {
        use crate::tet::{Constrained, Hold, TetMesh, TissueElastic};
        let m = 7;
        let mut tets = crate::mesh::kuhn_grid(m);
        let nodes: Vec<[f64; 3]> = (0..m * m * m)
            .map(|n| [(n / (m * m)) as f64, ((n / m) % m) as f64, (n % m) as f64])
            .collect();
        // Kuhn's tetrahedra come in both orientations: each made positive.
        for t in &mut tets {
            let p = |i: usize| nodes[t[i] as usize];
            let d = |i: usize| crate::vec3::sub(p(i), p(0));
            if crate::vec3::dot(crate::vec3::cross(d(1), d(2)), d(3)) < 0.0 {
                t.swap(1, 2);
            }
        }
        let material = vec![
            TissueElastic {
                youngs_kpa: 3.0,
                poisson: 0.45
            };
            tets.len()
        ];
        let mesh = TetMesh {
            nodes,
            tets,
            material,
        };
        // The bottom layer and a column of nodes held.
        let solved: Vec<bool> = (0..mesh.nodes.len())
            .map(|n| n / (m * m) != 0 && n % (m + 2) != 0)
            .collect();
        let holds: Vec<Hold> = solved
            .iter()
            .map(|s| {
                if *s {
                    Hold::Free
                } else {
                    Hold::Fixed([0.0; 3])
                }
            })
            .collect();
        let order = || MeshAnalyses::new(NodeOrder::of_tets(&solved, &mesh.tets).unwrap());
        let (a, b) = (order(), order());
        let k = mesh.assemble().unwrap();
        let assembled = Constrained::ordered(&k, &holds, mesh.nodes.len(), Ordering::Nodes(&a))
            .unwrap()
            .factor_nnz();
        let p = pattern_of_elements(
            &solved,
            mesh.tets.iter().map(|t| &t[..]),
            Ordering::Nodes(&b),
        )
        .unwrap();
        assert_eq!(p.columns(), 3 * solved.iter().filter(|s| **s).count());
        assert_eq!(p.factor_nnz(), assembled);
        // Σ column count² is at least the nonzeros (every column holds its diagonal).
        assert!(p.factor_flops() >= p.factor_nnz() as f64);
    }

    /// The node graph's estimate of a 10-node factor is the DOF-level analysis's within a few
    /// per cent (both in nested dissection), and it errs high: the 10-node model decides from it
    /// whether to factor.
    #[test]
    fn the_node_graph_estimates_the_ten_node_factor() {
        use crate::tet::TetMesh;
        use crate::tet::quadratic::{Rule, Tet10Mesh};
        let m = 9;
        let nodes: Vec<[f64; 3]> = (0..m * m * m)
            .map(|n| [(n / (m * m)) as f64, ((n / m) % m) as f64, (n % m) as f64])
            .collect();
        let tets = crate::mesh::kuhn_grid(m);
        let material = vec![
            crate::tet::TissueElastic {
                youngs_kpa: 3.0,
                poisson: 0.45
            };
            tets.len()
        ];
        let q = Tet10Mesh::from_linear(
            &TetMesh {
                nodes,
                tets,
                material,
            },
            Rule::Full,
        );
        // The corners of the bottom layer held; a midpoint is solved when either end is.
        let corner_solved: Vec<bool> = (0..q.corners).map(|n| n / (m * m) != 0).collect();
        let solved = q.solved_nodes(&corner_solved);
        let elements = || q.tets.iter().map(|t| &t[..]);
        let exact = pattern_of_elements(&solved, elements(), Ordering::NestedDissection)
            .unwrap()
            .factor_nnz() as f64;
        let estimate = node_graph_size(&solved, elements()).unwrap().factor_nnz as f64;
        assert!(
            estimate >= exact && estimate <= 1.1 * exact,
            "estimate {estimate} against the DOF-level analysis's {exact}"
        );
    }
}

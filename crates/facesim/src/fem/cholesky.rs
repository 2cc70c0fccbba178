//! The one sparse Cholesky wrapper over faer: a symbolic analysis (AMD ordering, elimination
//! tree) done once per sparsity pattern, numeric factors of any matrix on that pattern (in f64,
//! or f32 for the preconditioner), each solved for many right-hand sides.
//!
//! Sequential except for large factors: faer's own multithreading of the sparse factorisation
//! and triangular solves costs more than it gains on the surface models on 2 cores (40k
//! triangles: factor 0.48 s sequential vs 0.59–0.66 s threaded, three solves 0.05 s vs 0.15 s;
//! docs/fem.md), where rayon parallelises the element work instead; a volumetric head's factor
//! (tens of millions of nonzeros) is factored on all cores (`PARALLEL_FACTOR_NNZ`).

use super::ordering::NodeOrder;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::linalg::LltError;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::traits::ComplexField;
use faer::{Conj, MatMut, Par, Side};
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
}

/// Factors with at least this many nonzeros are factored on all cores: their dense supernodes
/// are large enough for faer's parallel kernels to pay (a volumetric head of 142 k unknowns,
/// 98 M nonzeros: 9.9 s sequential, 8.2 s on 2 cores; one of 23 k unknowns, 7.4 M nonzeros:
/// 0.27 s sequential, 0.39 s on 2 cores; the surface models' largest, 41 M at 80 k triangles,
/// stays sequential as measured in docs/fem.md).
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

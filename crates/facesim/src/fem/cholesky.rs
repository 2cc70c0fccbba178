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
use std::sync::Arc;

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
    /// dissection on the DOF groups if it does not cover them.
    Nodes(&'a NodeOrder),
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
            Ordering::NestedDissection => super::ordering::nested_dissection(lower),
            Ordering::Nodes(order) if dofs.len() == lower.ncols() => order
                .dofs(dofs)
                .or_else(|| super::ordering::nested_dissection(lower)),
            Ordering::Nodes(_) => super::ordering::nested_dissection(lower),
        };
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

//! A scalar stiffness factored once in single precision, applied to several coordinate fields
//! at once: the preconditioner of the equilibrium solve's conjugate gradients (src/solve.rs).
//!
//! Why single precision: each CG iteration is one forward and one backward substitution with the
//! factor L, which streams all of L through memory (L of a 15 k-triangle piece holds 4.7 M
//! entries: 38 MB in f64, larger than the cache). A preconditioner only has to be close to the
//! operator, not exact, so f32 halves the bytes moved per iteration (measured: 24 → 14–19 ms per
//! three-field application) without changing what CG converges to (the products with the true
//! operator and the residual test stay in f64). If the f32 factorisation breaks down (a matrix too
//! ill-conditioned for 7 digits), the f64 factor is used instead.

use crate::error::{Error, NumericalKind, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, SparseColMatRef, Triplet};
use faer::{Conj, Par, Side};

enum Values {
    Single(Vec<f32>),
    Double(Vec<f64>),
}

pub struct Precond {
    n: usize,
    /// Free DOFs in increasing order (fixed DOFs get zero).
    free: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
    values: Values,
}

/// The numeric Cholesky factor of `m` on `symbolic`'s pattern, or None if `m` is not
/// (numerically) positive definite.
fn factor<T: faer::traits::ComplexField + Copy>(
    symbolic: &SymbolicCholesky<usize>,
    m: SparseColMatRef<'_, usize, T>,
) -> Option<Vec<T>> {
    let mut values = vec![T::zero_impl(); symbolic.len_val()];
    let mut mem =
        MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<T>(Par::Seq, Default::default()));
    symbolic
        .factorize_numeric_llt(
            &mut values,
            m,
            Side::Lower,
            Default::default(),
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .ok()?;
    Some(values)
}

impl Precond {
    /// Factor the free–free block of K + diag(d) (K as lower-triangle triplets, duplicates
    /// summed; d with one entry per DOF).
    pub fn new(n: usize, k: &[(usize, usize, f64)], d: &[f64], fixed: &[bool]) -> Result<Precond> {
        let (free_index, free) = super::assembly::free_dofs(&fixed[..n]);
        let nf = free.len();
        let triplets: Vec<(usize, usize, f64)> = k
            .iter()
            .filter_map(|&(r, c, v)| {
                let (fr, fc) = (free_index[r], free_index[c]);
                (fr != usize::MAX && fc != usize::MAX).then(|| (fr.max(fc), fr.min(fc), v))
            })
            .chain(free.iter().enumerate().map(|(i, &g)| (i, i, d[g])))
            .collect();
        let bad =
            |e: String| Error::numerical(NumericalKind::Singular, format!("preconditioner: {e}"));
        let single: Vec<Triplet<usize, usize, f32>> = triplets
            .iter()
            .map(|&(r, c, v)| Triplet::new(r, c, v as f32))
            .collect();
        let m32 = SparseColMat::<usize, f32>::try_new_from_triplets(nf, nf, &single)
            .map_err(|e| bad(format!("{e:?}")))?;
        let symbolic = factorize_symbolic_cholesky(
            m32.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| bad(format!("symbolic Cholesky: {e:?}")))?;
        let values = match factor(&symbolic, m32.as_ref()) {
            Some(v) => Values::Single(v),
            None => {
                let double: Vec<Triplet<usize, usize, f64>> = triplets
                    .iter()
                    .map(|&(r, c, v)| Triplet::new(r, c, v))
                    .collect();
                let m64 = SparseColMat::<usize, f64>::try_new_from_triplets(nf, nf, &double)
                    .map_err(|e| bad(format!("{e:?}")))?;
                Values::Double(
                    factor(&symbolic, m64.as_ref())
                        .ok_or_else(|| bad("the matrix is not positive definite".into()))?,
                )
            }
        };
        Ok(Precond {
            n,
            free,
            symbolic,
            values,
        })
    }

    /// z = (K + diag(d))⁻¹ v for `v` holding m fields of n DOFs stacked; zero on the fixed DOFs.
    pub fn apply(&self, v: &[f64]) -> Vec<f64> {
        match &self.values {
            Values::Single(x) => self.apply_with(x, v, |a| a as f32, |a| a as f64),
            Values::Double(x) => self.apply_with(x, v, |a| a, |a| a),
        }
    }

    fn apply_with<T: faer::traits::ComplexField + Copy>(
        &self,
        values: &[T],
        v: &[f64],
        to: impl Fn(f64) -> T,
        from: impl Fn(T) -> f64,
    ) -> Vec<f64> {
        let n = self.n;
        let m = v.len() / n;
        let mut b = faer::Mat::<T>::zeros(self.free.len(), m);
        for c in 0..m {
            for (i, &g) in self.free.iter().enumerate() {
                b[(i, c)] = to(v[c * n + g]);
            }
        }
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<T>(m, Par::Seq));
        LltRef::new(&self.symbolic, values).solve_in_place_with_conj(
            Conj::No,
            b.as_mut(),
            Par::Seq,
            MemStack::new(&mut mem),
        );
        let mut out = vec![0.0; v.len()];
        for c in 0..m {
            for (i, &g) in self.free.iter().enumerate() {
                out[c * n + g] = from(b[(i, c)]);
            }
        }
        out
    }
}

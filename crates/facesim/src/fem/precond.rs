//! A scalar stiffness factored once in single precision, applied to several coordinate fields
//! at once: the preconditioner of the equilibrium solve's conjugate gradients
//! (src/solve/equilibrium.rs).
//!
//! Why single precision: each CG iteration is one forward and one backward substitution with the
//! factor L, which streams all of L through memory (L of a 15 k-triangle piece holds 4.7 M
//! entries: 38 MB in f64, larger than the cache). A preconditioner only has to be close to the
//! operator, not exact, so f32 halves the bytes moved per iteration (measured: 24 → 14–19 ms per
//! three-field application) without changing what CG converges to (the products with the true
//! operator and the residual test stay in f64). If the f32 factorisation breaks down (a matrix too
//! ill-conditioned for 7 digits), the f64 factor is used instead.

use super::cholesky::{Cholesky, Pattern};
use crate::error::{Error, NumericalKind, Result};
use faer::sparse::{SparseColMat, Triplet};

enum Factor {
    Single(Cholesky<f32>),
    Double(Cholesky<f64>),
}

pub(crate) struct Precond {
    n: usize,
    /// Free DOFs in increasing order (fixed DOFs get zero).
    free: Vec<usize>,
    factor: Factor,
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
        let pattern = Pattern::analyse(m32.symbolic())
            .map_err(|e| bad(format!("symbolic Cholesky: {e:?}")))?;
        let factor = match Cholesky::factor(&pattern, m32.as_ref()) {
            Ok(f) => Factor::Single(f),
            Err(_) => {
                let double: Vec<Triplet<usize, usize, f64>> = triplets
                    .iter()
                    .map(|&(r, c, v)| Triplet::new(r, c, v))
                    .collect();
                let m64 = SparseColMat::<usize, f64>::try_new_from_triplets(nf, nf, &double)
                    .map_err(|e| bad(format!("{e:?}")))?;
                Factor::Double(
                    Cholesky::factor(&pattern, m64.as_ref())
                        .map_err(|_| bad("the matrix is not positive definite".into()))?,
                )
            }
        };
        Ok(Precond { n, free, factor })
    }

    /// z = (K + diag(d))⁻¹ v for `v` holding m fields of n DOFs stacked; zero on the fixed DOFs.
    pub fn apply(&self, v: &[f64]) -> Vec<f64> {
        match &self.factor {
            Factor::Single(f) => self.apply_with(f, v, |a| a as f32, |a| a as f64),
            Factor::Double(f) => self.apply_with(f, v, |a| a, |a| a),
        }
    }

    fn apply_with<T: faer::traits::ComplexField + Copy>(
        &self,
        factor: &Cholesky<T>,
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
        factor.solve_in_place(b.as_mut());
        let mut out = vec![0.0; v.len()];
        for c in 0..m {
            for (i, &g) in self.free.iter().enumerate() {
                out[c * n + g] = from(b[(i, c)]);
            }
        }
        out
    }
}

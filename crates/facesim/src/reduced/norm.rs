//! The gain from the energy norm to an output: for a linear output y = C e of the error e,
//! ‖C e‖₂ ≤ σ ‖e‖_X with σ² = λ_max(C X⁻¹ Cᵀ) (Cauchy–Schwarz in X). λ_max by Lanczos with full
//! reorthogonalisation (Golub & Van Loan 2013 §10.1); the returned value adds the top Ritz
//! pair's residual |β_k s_k| (an eigenvalue lies within it of the Ritz value, §10.1.4), so it
//! is an upper bound of λ_max once Lanczos has found the top of the spectrum.

use nalgebra::{DMatrix, SymmetricEigen};

/// An upper estimate of λ_max of the symmetric positive semi-definite operator `apply` on
/// vectors of length `n`, with at most `steps` Lanczos steps from a fixed start.
pub(crate) fn largest_eigenvalue(
    n: usize,
    steps: usize,
    apply: &dyn Fn(&[f64]) -> Vec<f64>,
) -> f64 {
    if n == 0 {
        return 0.0;
    }
    // A fixed, dense start (no zero component a structured operator could hide behind).
    let mut v: Vec<f64> = (0..n)
        .map(|i| 1.0 + ((i as f64 * 0.618_033_988_749_895).fract() - 0.5))
        .collect();
    normalise(&mut v);
    let mut basis: Vec<Vec<f64>> = vec![v];
    let (mut alpha, mut beta): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
    let mut best = 0.0;
    for k in 0..steps.min(n) {
        let mut w = apply(&basis[k]);
        let a = dot(&w, &basis[k]);
        alpha.push(a);
        for _ in 0..2 {
            for b in &basis {
                let p = dot(&w, b);
                w.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
            }
        }
        let b = dot(&w, &w).sqrt();
        let m = alpha.len();
        let t = DMatrix::from_fn(m, m, |i, j| {
            if i == j {
                alpha[i]
            } else if i + 1 == j {
                beta[i]
            } else if j + 1 == i {
                beta[j]
            } else {
                0.0
            }
        });
        let e = SymmetricEigen::new(t);
        let (top, val) =
            e.eigenvalues
                .iter()
                .enumerate()
                .fold(
                    (0, f64::NEG_INFINITY),
                    |a, (i, v)| if *v > a.1 { (i, *v) } else { a },
                );
        let residual = (b * e.eigenvectors[(m - 1, top)]).abs();
        best = val + residual;
        if residual <= 1e-8 * val.abs() || !(b > 1e-14 * val.abs()) {
            break;
        }
        beta.push(b);
        w.iter_mut().for_each(|x| *x /= b);
        basis.push(w);
    }
    best
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn normalise(v: &mut [f64]) {
    let n = dot(v, v).sqrt();
    v.iter_mut().for_each(|x| *x /= n);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_largest_eigenvalue_of_a_diagonal_operator() {
        let d: Vec<f64> = (0..200).map(|i| 1.0 + (i as f64).sqrt()).collect();
        let l = largest_eigenvalue(200, 80, &|x| x.iter().zip(&d).map(|(a, b)| a * b).collect());
        let top = 1.0 + 199f64.sqrt();
        assert!(
            l >= top * (1.0 - 1e-12) && l <= top * (1.0 + 1e-3),
            "{l} vs {top}"
        );
    }
}

//! Sobol sensitivity indices of the prediction to the tissue parameters (
//! docs/guide/uncertainty.md "Sensitivity"): which parameter a landmark's or a region's displacement
//! depends on, alone (first-order S_i) and with its interactions (total S_Ti).
//!
//! Estimators on two independent quasi-random matrices A and B (N rows, one column per sampled
//! parameter) and the d matrices A_B^i (A with column i from B): Saltelli et al. (2010, Comput.
//! Phys. Commun. 181, Table 2 (b) and (f)):
//! S_i = (1/N) Σ_j f(B)_j (f(A_B^i)_j − f(A)_j) / V and S_Ti = (1/2N) Σ_j (f(A)_j − f(A_B^i)_j)² / V
//! (Jansen 1999), V the variance of f over A and B, f centred on its mean over A and B first.
//! N (d + 2) evaluations: affordable with the reduced model only.

use super::sample::ScrambledHalton;
use crate::landmarks::Ordered;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// First-order and total Sobol index of one parameter for one output.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Index {
    pub first: f64,
    pub total: f64,
}

/// report.json `uncertainty.sensitivity`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Sensitivity {
    /// N, the rows of A and B; the model was evaluated N (d + 2) times.
    pub base_samples: usize,
    pub evaluations: usize,
    pub estimator: String,
    /// Landmark label → parameter → indices (outputs that do not vary are left out).
    pub landmarks: Ordered<Ordered<Index>>,
    /// Region → parameter → indices of the region's mean displacement magnitude.
    pub regions: Ordered<Ordered<Index>>,
}

/// Per output (the length of what `f` returns), per parameter, the indices of `f` on the unit
/// cube of `d` dimensions with `n` base rows from the scrambled Halton sequence (`seed`);
/// None for an output whose variance is zero.
pub fn indices(
    d: usize,
    n: usize,
    seed: u64,
    f: &(dyn Fn(&[f64]) -> Vec<f64> + Sync),
) -> Vec<Option<Vec<Index>>> {
    let seq = ScrambledHalton::new(2 * d, seed);
    let a: Vec<Vec<f64>> = (0..n as u64)
        .map(|j| (0..d).map(|i| seq.at(j, i)).collect())
        .collect();
    let b: Vec<Vec<f64>> = (0..n as u64)
        .map(|j| (0..d).map(|i| seq.at(j, d + i)).collect())
        .collect();
    let fa: Vec<Vec<f64>> = a.par_iter().map(|x| f(x)).collect();
    let fb: Vec<Vec<f64>> = b.par_iter().map(|x| f(x)).collect();
    let fab: Vec<Vec<Vec<f64>>> = (0..d)
        .map(|i| {
            (0..n)
                .into_par_iter()
                .map(|j| {
                    let mut x = a[j].clone();
                    x[i] = b[j][i];
                    f(&x)
                })
                .collect()
        })
        .collect();
    let outputs = fa.first().map_or(0, Vec::len);
    (0..outputs)
        .map(|o| {
            let all: Vec<f64> = fa.iter().chain(&fb).map(|v| v[o]).collect();
            let mean = all.iter().sum::<f64>() / all.len() as f64;
            let var = all.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / all.len() as f64;
            if !(var > 1e-18 * mean.abs().max(1e-9).powi(2)) {
                return None;
            }
            Some(
                (0..d)
                    .map(|i| {
                        let (mut s, mut t) = (0.0, 0.0);
                        for j in 0..n {
                            // Centred: the same expectation, far less variance when the output's
                            // mean is large against its spread (a lip that moves 3 ± 0.1 mm).
                            let (ya, yb, yab) =
                                (fa[j][o] - mean, fb[j][o] - mean, fab[i][j][o] - mean);
                            s += yb * (yab - ya);
                            t += (ya - yab) * (ya - yab);
                        }
                        Index {
                            first: s / n as f64 / var,
                            total: t / (2.0 * n as f64) / var,
                        }
                    })
                    .collect(),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The Ishigami function (a = 7, b = 0.1) on [−π, π]³, whose indices are known in closed
    /// form (Saltelli et al. 2008, Global Sensitivity Analysis, §4.5): S = (0.3139, 0.4424, 0),
    /// S_T = (0.5576, 0.4424, 0.2437).
    #[test]
    fn the_ishigami_function_gives_its_closed_form_indices() {
        let f = |x: &[f64]| {
            let x: Vec<f64> = x.iter().map(|u| PI * (2.0 * u - 1.0)).collect();
            vec![x[0].sin() + 7.0 * x[1].sin().powi(2) + 0.1 * x[2].powi(4) * x[0].sin()]
        };
        let got = indices(3, 8192, 1, &f).remove(0).unwrap();
        let (a, b) = (7.0, 0.1);
        let v = a * a / 8.0 + b * PI.powi(4) / 5.0 + b * b * PI.powi(8) / 18.0 + 0.5;
        let v1 = 0.5 * (1.0 + b * PI.powi(4) / 5.0).powi(2);
        let v2 = a * a / 8.0;
        let v13 = b * b * PI.powi(8) * (1.0 / 18.0 - 1.0 / 50.0);
        let want = [(v1 / v, (v1 + v13) / v), (v2 / v, v2 / v), (0.0, v13 / v)];
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            assert!(
                (g.first - w.0).abs() < 0.02 && (g.total - w.1).abs() < 0.02,
                "parameter {i}: {g:?} vs {w:?}"
            );
        }
        // A constant output has no indices.
        assert!(indices(2, 64, 1, &|_| vec![3.0])[0].is_none());
    }
}

//! Preconditioned conjugate gradients over vectors given only through products: to
//! convergence for the equilibrium solve's inexact Newton steps (src/solve/equilibrium.rs), and
//! truncated at negative curvature for the Newton–Krylov solve (src/tet/newton_krylov.rs).

/// Why the CG iteration stopped.
enum Stop {
    Converged,
    /// d · A d ≤ 0 (A not positive definite along d, the direction returned).
    NegativeCurvature(Vec<f64>),
    NotFinite,
    MaxIterations,
}

/// Preconditioned CG for A x = b from x = 0 until |r| ≤ tol |b| or a stop: the iterate, the
/// iterations taken and why it stopped.
fn cg(
    a: impl Fn(&[f64]) -> Vec<f64>,
    p: impl Fn(&[f64]) -> Vec<f64>,
    b: &[f64],
    tol: f64,
    max_it: usize,
) -> (Vec<f64>, usize, Stop) {
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>();
    let bn = dot(b, b).sqrt();
    let mut x = vec![0.0; b.len()];
    if bn == 0.0 {
        return (x, 0, Stop::Converged);
    }
    let mut r = b.to_vec();
    let mut z = p(&r);
    let mut d = z.clone();
    let mut rz = dot(&r, &z);
    for it in 1..=max_it {
        let ad = a(&d);
        let curv = dot(&d, &ad);
        if !(curv > 0.0) {
            return (x, it, Stop::NegativeCurvature(d));
        }
        let alpha = rz / curv;
        for i in 0..x.len() {
            x[i] += alpha * d[i];
            r[i] -= alpha * ad[i];
        }
        let rn = dot(&r, &r).sqrt();
        if !rn.is_finite() {
            return (x, it, Stop::NotFinite);
        }
        if rn <= tol * bn {
            return (x, it, Stop::Converged);
        }
        z = p(&r);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..d.len() {
            d[i] = z[i] + beta * d[i];
        }
    }
    (x, max_it, Stop::MaxIterations)
}

/// Preconditioned conjugate gradients for A x = b (A symmetric positive definite, given as a
/// product), from x = 0 to |r| ≤ tol |b|. Returns the solution and the iterations, or None on
/// negative curvature (A not positive definite), a non-finite value or no convergence in
/// `max_it` iterations.
pub(crate) fn pcg(
    a: impl Fn(&[f64]) -> Vec<f64>,
    p: impl Fn(&[f64]) -> Vec<f64>,
    b: &[f64],
    tol: f64,
    max_it: usize,
) -> Option<(Vec<f64>, usize)> {
    match cg(a, p, b, tol, max_it) {
        (x, it, Stop::Converged) => Some((x, it)),
        _ => None,
    }
}

/// The same truncated at non-positive curvature (Steihaug 1983): the iterate so far, or the
/// preconditioned right-hand side when that happens at once; at a non-finite residual or
/// `max_it`, the iterate so far. Returns the direction and the iterations taken.
pub(crate) fn truncated_pcg(
    a: impl Fn(&[f64]) -> Vec<f64>,
    p: impl Fn(&[f64]) -> Vec<f64>,
    b: &[f64],
    tol: f64,
    max_it: usize,
) -> (Vec<f64>, usize) {
    match cg(a, p, b, tol, max_it) {
        (_, 1, Stop::NegativeCurvature(d)) => (d, 1),
        (x, it, _) => (x, it),
    }
}

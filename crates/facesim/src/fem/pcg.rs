//! Preconditioned conjugate gradients over vectors given only through products (the
//! equilibrium solve's inexact Newton steps, src/solve/equilibrium.rs).

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
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>();
    let bn = dot(b, b).sqrt();
    let mut x = vec![0.0; b.len()];
    if bn == 0.0 {
        return Some((x, 0));
    }
    let mut r = b.to_vec();
    let mut z = p(&r);
    let mut d = z.clone();
    let mut rz = dot(&r, &z);
    for it in 1..=max_it {
        let ad = a(&d);
        let curv = dot(&d, &ad);
        if !(curv > 0.0) {
            return None;
        }
        let alpha = rz / curv;
        for i in 0..x.len() {
            x[i] += alpha * d[i];
            r[i] -= alpha * ad[i];
        }
        let rn = dot(&r, &r).sqrt();
        if !rn.is_finite() {
            return None;
        }
        if rn <= tol * bn {
            return Some((x, it));
        }
        z = p(&r);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..d.len() {
            d[i] = z[i] + beta * d[i];
        }
    }
    None
}

//! Quadrature on triangles for the C1 element's rational shape functions.
//!
//! The correction functions N10–N12 (Koch eq. 7) are rational with second derivatives that are
//! bounded but direction-dependent at the corners (homogeneous of degree 0 there), so a plain
//! Gauss rule converges slowly. The triangle is split into six sub-triangles, each touching one
//! corner, and each is mapped from the unit square by a Duffy transform collapsed at that corner:
//! a degree-0 homogeneous integrand then depends smoothly on the square's coordinates and the
//! tensor Gauss–Legendre rule converges exponentially (tested in `element.rs`).

/// Gauss–Legendre nodes and weights on [0, 1] (Newton on P_n, Golub–Welsch not needed).
pub(crate) fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 0 { 1.0 } else { p1 };
            let pm = if n == 0 { 0.0 } else { p0 };
            dp = n as f64 * (x * pn - pm) / (x * x - 1.0);
            let dx = pn / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (1.0 - x), 0.5 * w));
    }
    out
}

/// Points (ξ, η) in the reference triangle (0,0), (1,0), (0,1) with weights summing to ½
/// (its area), from six Duffy-collapsed sub-triangles, `n`×`n` points each.
pub(crate) fn triangle_rule(n: usize) -> Vec<([f64; 2], f64)> {
    let gl = gauss_legendre(n);
    let corners = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    let g = [1.0 / 3.0, 1.0 / 3.0];
    let mid = |a: [f64; 2], b: [f64; 2]| [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
    let mut subs = Vec::new();
    for k in 0..3 {
        let (a, b) = (corners[k], corners[(k + 1) % 3]);
        let m = mid(a, b);
        subs.push([a, m, g]); // collapsed at corner a
        subs.push([b, g, m]); // collapsed at corner b
    }
    let mut pts = Vec::with_capacity(6 * n * n);
    for [v0, v1, v2] in subs {
        let area2 = ((v1[0] - v0[0]) * (v2[1] - v0[1]) - (v2[0] - v0[0]) * (v1[1] - v0[1])).abs();
        for &(x, wx) in &gl {
            for &(y, wy) in &gl {
                // p = v0 + x (v1 − v0 + y (v2 − v1)); dA = x · area2 dx dy.
                let p = [
                    v0[0] + x * (v1[0] - v0[0] + y * (v2[0] - v1[0])),
                    v0[1] + x * (v1[1] - v0[1] + y * (v2[1] - v1[1])),
                ];
                pts.push((p, wx * wy * x * area2));
            }
        }
    }
    pts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_is_exact_to_degree_2n_minus_1() {
        let r = gauss_legendre(5);
        for d in 0..10 {
            let s: f64 = r.iter().map(|(x, w)| w * x.powi(d)).sum();
            assert!((s - 1.0 / (d + 1) as f64).abs() < 1e-14, "degree {d}");
        }
    }

    #[test]
    fn triangle_rule_integrates_monomials() {
        let r = triangle_rule(4);
        // ∫ ξ^a η^b over the reference triangle = a! b! / (a + b + 2)!
        let fact = |n: u32| (1..=n).map(|k| k as f64).product::<f64>();
        // The Duffy map raises the degree by one in x: n = 4 is exact to total degree 6.
        for a in 0..=6u32 {
            for b in 0..=(6 - a) {
                let s: f64 = r
                    .iter()
                    .map(|(p, w)| w * p[0].powi(a as i32) * p[1].powi(b as i32))
                    .sum();
                let exact = fact(a) * fact(b) / fact(a + b + 2);
                assert!((s - exact).abs() < 1e-14, "{a} {b}: {s} vs {exact}");
            }
        }
    }
}

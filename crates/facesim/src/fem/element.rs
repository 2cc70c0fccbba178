//! The globally C1 triangular surface element of Koch et al. 1996 §3.2 (after Celniker &
//! Gossard 1991 and Zienkiewicz): 12 scalar DOFs per triangle — value and (u, v) gradient at
//! each corner, and the cross-boundary derivative at each edge midpoint along the edge's
//! global normal (eq. 11).
//!
//! Shape space: the nine BCIZ cubics N1…N9 of eq. 7 and the three rational edge functions
//! N10…N12, in barycentrics (r, s, t). The printed eq. 8–9 (the corrected N̄ᵢ and the φᵢ built
//! from them) are garbled in the extracted text (e.g. φ6 has a sign that breaks the cyclic
//! pattern of φ3 and φ9). We do not transcribe them: the φᵢ are *defined* as the basis of
//! span{N1…N12} dual to the twelve DOFs, φ = N·D⁻¹ with Dₖⱼ = DOFₖ(Nⱼ), computed per element.
//! That is the same construction eq. 8–9 performs by hand (subtracting N10…N12 multiples so the
//! cross-boundary derivatives match, then rotating corner derivatives into u, v); docs/design/fem.md
//! derives why the resulting surface is C1:
//! - along an edge, every Nᵢ is a cubic whose end values and end tangential derivatives are
//!   DOFs of that edge (N10…N12 vanish on all edges), so the value along the edge is the cubic
//!   Hermite interpolant of the edge's DOFs — shared by both neighbours;
//! - the normal derivative along edge rs is quadratic (cubics differentiate to quadratics; N10
//!   contributes r·s, N11 and N12 nothing), fixed by its end values (corner gradients) and its
//!   midpoint value (the edge DOF) — again shared.
//!
//! Derivatives are exact (forward-mode jets, `jet.rs`); integrals use `quadrature.rs`.

use super::jet::Jet;
use super::quadrature::triangle_rule;
use crate::error::{Error, Result};
use nalgebra::SMatrix;

pub(crate) const NDOF: usize = 12;

/// Stretching tensor (α11, α12, α22), bending tensor (β11, β12, β22) (eq. 3–4) and an optional
/// elastic foundation c (energy ∫ c w²; the springs of the equilibrium model, and Winkler plates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub alpha: [f64; 3],
    pub beta: [f64; 3],
    pub foundation: f64,
}

impl Material {
    pub fn isotropic(alpha: f64, beta: f64) -> Material {
        Material {
            alpha: [alpha, 0.0, alpha],
            beta: [beta, beta, beta],
            foundation: 0.0,
        }
    }
}

/// Value and (u, v) derivatives of one shape function at one point: w, wu, wv, wuu, wuv, wvv.
pub(crate) type Derivs = [f64; 6];

/// The global normal of an edge from a to b (eq. 11): the unit normal with a positive v
/// component, or +u when the edge is parallel to v… i.e. normal to u = const lines.
pub fn edge_normal(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    let d = [b[0] - a[0], b[1] - a[1]];
    let l = (d[0] * d[0] + d[1] * d[1]).sqrt();
    let n = [-d[1] / l, d[0] / l];
    let tol = 1e-12;
    if n[1] > tol || (n[1].abs() <= tol && n[0] > 0.0) {
        n
    } else {
        [-n[0], -n[1]]
    }
}

/// N1…N12 of eq. 7 at local coordinates (ξ, η): r = 1 − ξ − η, s = ξ, t = η. At a corner the
/// rational N10…N12 are 0/0; their limits (value and gradient 0) are used.
fn basis(xi: Jet, eta: Jet) -> [Jet; NDOF] {
    let one = Jet::constant(1.0);
    let (r, s, t) = (one - xi - eta, xi, eta);
    let half = 0.5;
    let corner = |a: Jet, b: Jet, c: Jet| {
        // For corner a with neighbours b (next) and c (previous).
        let abc = a * b * c * half;
        [
            a + a * a * b + a * a * c - a * b * b - a * c * c,
            a * a * b + abc,
            a * a * c + abc,
        ]
    };
    let [n1, n2, n3] = corner(r, s, t);
    let [n4, n5, n6] = corner(s, t, r);
    let [n7, n8, n9] = corner(t, r, s);
    let edge = |a: Jet, b: Jet, c: Jet| {
        // a² b² c (1 + c) / ((a + c)(b + c)), the function of edge ab (c = 0 on it).
        let den = (a + c) * (b + c);
        if den.v.abs() < 1e-14 {
            Jet::constant(0.0)
        } else {
            a * a * b * b * c * (c + 1.0) / den
        }
    };
    [
        n1,
        n2,
        n3,
        n4,
        n5,
        n6,
        n7,
        n8,
        n9,
        edge(r, s, t),
        edge(s, t, r),
        edge(t, r, s),
    ]
}

/// Quadrature order (per sub-triangle, per axis) of the reference moments: 10 → 600 points,
/// element stiffness exact to ~1e-12 relative (the convergence test shows 8 → 1.6e-11).
pub(crate) const REFERENCE_ORDER: usize = 10;

/// Integrals over the reference triangle of products of the raw shape functions N1…N12 and
/// their (ξ, η) derivatives. The Nᵢ depend on barycentrics only, so these are the same for
/// every element: an element's stiffness is a geometry-weighted sum of them (no per-element
/// quadrature), K = Cᵀ (Σ G_ab M_ab) C.
struct Moments {
    /// ∫ Nᵢ Nⱼ, ∫ Nᵢ.
    m0: SMatrix<f64, NDOF, NDOF>,
    f0: SMatrix<f64, NDOF, 1>,
    /// ∫ ∂ₐNᵢ ∂_bNⱼ, a, b ∈ {ξ, η}.
    m1: [[SMatrix<f64, NDOF, NDOF>; 2]; 2],
    /// ∫ ∂ₐNᵢ ∂_bNⱼ, a, b ∈ {ξξ, ξη, ηη}.
    m2: [[SMatrix<f64, NDOF, NDOF>; 3]; 3],
}

fn moments() -> &'static Moments {
    static M: std::sync::OnceLock<Moments> = std::sync::OnceLock::new();
    M.get_or_init(|| {
        let z = SMatrix::<f64, NDOF, NDOF>::zeros();
        let mut m = Moments {
            m0: z,
            f0: SMatrix::zeros(),
            m1: [[z; 2]; 2],
            m2: [[z; 3]; 3],
        };
        for (pt, w) in triangle_rule(REFERENCE_ORDER) {
            let (x, y) = Jet::vars(pt[0], pt[1]);
            let n = basis(x, y);
            let d1 = |f: &Jet| [f.x, f.y];
            let d2 = |f: &Jet| [f.xx, f.xy, f.yy];
            for i in 0..NDOF {
                m.f0[i] += w * n[i].v;
                for j in 0..NDOF {
                    m.m0[(i, j)] += w * n[i].v * n[j].v;
                    let (gi, gj) = (d1(&n[i]), d1(&n[j]));
                    for a in 0..2 {
                        for b in 0..2 {
                            m.m1[a][b][(i, j)] += w * gi[a] * gj[b];
                        }
                    }
                    let (hi, hj) = (d2(&n[i]), d2(&n[j]));
                    for a in 0..3 {
                        for b in 0..3 {
                            m.m2[a][b][(i, j)] += w * hi[a] * hj[b];
                        }
                    }
                }
            }
        }
        m
    })
}

#[derive(Clone, Debug)]
pub struct Element {
    /// Corner (u, v) in the element's order r, s, t.
    pub p: [[f64; 2]; 3],
    /// J⁻ᵀ of the map (ξ, η) → (u, v): rows give ∂/∂u, ∂/∂v from ∂/∂ξ, ∂/∂η.
    a: [[f64; 2]; 2],
    /// |det J| = twice the area.
    pub det: f64,
    /// φ = N · coef (coef = D⁻¹).
    coef: SMatrix<f64, NDOF, NDOF>,
}

impl Element {
    pub fn new(p: [[f64; 2]; 3]) -> Result<Element> {
        let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1]];
        let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1]];
        let det = e1[0] * e2[1] - e2[0] * e1[1];
        let scale = (e1[0] * e1[0] + e1[1] * e1[1]).max(e2[0] * e2[0] + e2[1] * e2[1]);
        if !(det.abs() > 1e-12 * scale) {
            return Err(Error::surface(format!(
                "degenerate element in the (u, v) parameterisation: corners {p:?}"
            )));
        }
        let a = [[e2[1] / det, -e1[1] / det], [-e2[0] / det, e1[0] / det]];
        let mut el = Element {
            p,
            a,
            det: det.abs(),
            coef: SMatrix::identity(),
        };
        // D[k][j] = DOF_k(N_j).
        let mut d = SMatrix::<f64, NDOF, NDOF>::zeros();
        let local = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        for c in 0..3 {
            let n = el.raw(local[c][0], local[c][1]);
            for j in 0..NDOF {
                d[(3 * c, j)] = n[j][0];
                d[(3 * c + 1, j)] = n[j][1];
                d[(3 * c + 2, j)] = n[j][2];
            }
        }
        for e in 0..3 {
            let (i, k) = (e, (e + 1) % 3);
            let m = [
                0.5 * (local[i][0] + local[k][0]),
                0.5 * (local[i][1] + local[k][1]),
            ];
            let nrm = edge_normal(p[i], p[k]);
            let n = el.raw(m[0], m[1]);
            for j in 0..NDOF {
                d[(9 + e, j)] = n[j][1] * nrm[0] + n[j][2] * nrm[1];
            }
        }
        el.coef = d.try_inverse().ok_or_else(|| {
            Error::surface(format!(
                "C1 element DOF matrix is singular for corners {p:?}"
            ))
        })?;
        Ok(el)
    }

    /// N1…N12 with (u, v) derivatives at local (ξ, η).
    fn raw(&self, xi: f64, eta: f64) -> [Derivs; NDOF] {
        let (x, y) = Jet::vars(xi, eta);
        let n = basis(x, y);
        let a = self.a;
        n.map(|f| {
            let gu = a[0][0] * f.x + a[0][1] * f.y;
            let gv = a[1][0] * f.x + a[1][1] * f.y;
            // H_uv = A H_ξη Aᵀ.
            let h = [[f.xx, f.xy], [f.xy, f.yy]];
            let ah = |r: usize, c: usize| a[r][0] * h[0][c] + a[r][1] * h[1][c];
            let huv = |r: usize, c: usize| ah(r, 0) * a[c][0] + ah(r, 1) * a[c][1];
            [f.v, gu, gv, huv(0, 0), huv(0, 1), huv(1, 1)]
        })
    }

    /// φ1…φ12 with (u, v) derivatives at local (ξ, η).
    pub fn shape(&self, xi: f64, eta: f64) -> [Derivs; NDOF] {
        let n = self.raw(xi, eta);
        let mut phi = [[0.0; 6]; NDOF];
        for j in 0..NDOF {
            for i in 0..NDOF {
                let c = self.coef[(i, j)];
                if c != 0.0 {
                    for k in 0..6 {
                        phi[j][k] += c * n[i][k];
                    }
                }
            }
        }
        phi
    }

    /// (u, v) of local (ξ, η).
    pub fn point(&self, xi: f64, eta: f64) -> [f64; 2] {
        let p = self.p;
        [
            p[0][0] + xi * (p[1][0] - p[0][0]) + eta * (p[2][0] - p[0][0]),
            p[0][1] + xi * (p[1][1] - p[0][1]) + eta * (p[2][1] - p[0][1]),
        ]
    }

    // Only the unit tests use it (a reference the production path does not need).
    #[cfg(test)]
    /// Element stiffness (eq. 15) and load vector for a uniform load q (eq. 16), with an
    /// `n`×`n` Gauss rule on each of the six Duffy sub-triangles. E = aᵀKa − 2Fᵀa.
    pub(crate) fn stiffness_and_load(
        &self,
        m: &Material,
        q: f64,
        n: usize,
    ) -> ([[f64; NDOF]; NDOF], [f64; NDOF]) {
        self.integrate(m, q, &triangle_rule(n))
    }

    /// The same K and F from the precomputed reference moments (`REFERENCE_ORDER`): the fast
    /// path used by assembly. With A = J⁻ᵀ, (∂u, ∂v) = A (∂ξ, ∂η) and
    /// (∂uu, ∂uv, ∂vv) = T (∂ξξ, ∂ξη, ∂ηη), the stretching weights are G1 = Aᵀ S A with
    /// S = [[α11, α12/2], [α12/2, α22]], the bending weights G2 = Tᵀ diag(β11, 2β12, β22) T.
    pub(crate) fn stiffness_fast(
        &self,
        m: &Material,
        q: f64,
    ) -> ([[f64; NDOF]; NDOF], [f64; NDOF]) {
        let mo = moments();
        let a = self.a;
        let [a11, a12, a22] = m.alpha;
        let s = [[a11, 0.5 * a12], [0.5 * a12, a22]];
        let t = [
            [
                a[0][0] * a[0][0],
                2.0 * a[0][0] * a[0][1],
                a[0][1] * a[0][1],
            ],
            [
                a[0][0] * a[1][0],
                a[0][0] * a[1][1] + a[0][1] * a[1][0],
                a[0][1] * a[1][1],
            ],
            [
                a[1][0] * a[1][0],
                2.0 * a[1][0] * a[1][1],
                a[1][1] * a[1][1],
            ],
        ];
        let bd = [m.beta[0], 2.0 * m.beta[1], m.beta[2]];
        let mut kr = mo.m0 * m.foundation;
        for x in 0..2 {
            for y in 0..2 {
                let mut g = 0.0;
                for p in 0..2 {
                    for r in 0..2 {
                        g += a[p][x] * s[p][r] * a[r][y];
                    }
                }
                if g != 0.0 {
                    kr += mo.m1[x][y] * g;
                }
            }
        }
        for x in 0..3 {
            for y in 0..3 {
                let g: f64 = (0..3).map(|p| t[p][x] * bd[p] * t[p][y]).sum();
                if g != 0.0 {
                    kr += mo.m2[x][y] * g;
                }
            }
        }
        let k = self.coef.transpose() * kr * self.coef * self.det;
        let f = self.coef.transpose() * mo.f0 * (self.det * q);
        let mut ko = [[0.0; NDOF]; NDOF];
        let mut fo = [0.0; NDOF];
        for i in 0..NDOF {
            fo[i] = f[i];
            for j in 0..NDOF {
                ko[i][j] = 0.5 * (k[(i, j)] + k[(j, i)]);
            }
        }
        (ko, fo)
    }

    pub fn integrate(
        &self,
        m: &Material,
        q: f64,
        rule: &[([f64; 2], f64)],
    ) -> ([[f64; NDOF]; NDOF], [f64; NDOF]) {
        let mut k = [[0.0; NDOF]; NDOF];
        let mut f = [0.0; NDOF];
        let [a11, a12, a22] = m.alpha;
        let [b11, b12, b22] = m.beta;
        for &(pt, w) in rule {
            let wd = w * self.det;
            let phi = self.shape(pt[0], pt[1]);
            for i in 0..NDOF {
                let pi = phi[i];
                f[i] += wd * q * pi[0];
                for j in i..NDOF {
                    let pj = phi[j];
                    let e = a11 * pi[1] * pj[1]
                        + 0.5 * a12 * (pi[1] * pj[2] + pi[2] * pj[1])
                        + a22 * pi[2] * pj[2]
                        + b11 * pi[3] * pj[3]
                        + 2.0 * b12 * pi[4] * pj[4]
                        + b22 * pi[5] * pj[5]
                        + m.foundation * pi[0] * pj[0];
                    k[i][j] += wd * e;
                }
            }
        }
        for i in 0..NDOF {
            for j in 0..i {
                k[i][j] = k[j][i];
            }
        }
        (k, f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Element {
        Element::new([[0.3, -0.2], [2.1, 0.4], [0.7, 1.9]]).unwrap()
    }

    /// The DOFs of a field with value/gradient function g and Hessian at the element's nodes.
    fn dofs(el: &Element, f: &dyn Fn([f64; 2]) -> Derivs) -> [f64; NDOF] {
        let mut a = [0.0; NDOF];
        for c in 0..3 {
            let d = f(el.p[c]);
            a[3 * c] = d[0];
            a[3 * c + 1] = d[1];
            a[3 * c + 2] = d[2];
        }
        for e in 0..3 {
            let (p, q) = (el.p[e], el.p[(e + 1) % 3]);
            let m = [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])];
            let n = edge_normal(p, q);
            let d = f(m);
            a[9 + e] = d[1] * n[0] + d[2] * n[1];
        }
        a
    }

    fn interpolate(el: &Element, a: &[f64; NDOF], xi: f64, eta: f64) -> Derivs {
        let phi = el.shape(xi, eta);
        let mut w = [0.0; 6];
        for j in 0..NDOF {
            for k in 0..6 {
                w[k] += a[j] * phi[j][k];
            }
        }
        w
    }

    #[test]
    fn shape_functions_are_dual_to_the_dofs() {
        let el = tri();
        for j in 0..NDOF {
            let basis_j = |x: [f64; 2]| {
                // Evaluate φ_j at the (u, v) point x by inverting the affine map.
                let p = el.p;
                let (e1, e2) = (
                    [p[1][0] - p[0][0], p[1][1] - p[0][1]],
                    [p[2][0] - p[0][0], p[2][1] - p[0][1]],
                );
                let det = e1[0] * e2[1] - e2[0] * e1[1];
                let d = [x[0] - p[0][0], x[1] - p[0][1]];
                let xi = (d[0] * e2[1] - e2[0] * d[1]) / det;
                let eta = (e1[0] * d[1] - d[0] * e1[1]) / det;
                el.shape(xi, eta)[j]
            };
            let a = dofs(&el, &basis_j);
            for k in 0..NDOF {
                let expect = if k == j { 1.0 } else { 0.0 };
                assert!((a[k] - expect).abs() < 1e-11, "DOF {k} of φ{j} = {}", a[k]);
            }
        }
    }

    #[test]
    fn quadratics_are_reproduced_exactly() {
        let el = tri();
        let q = |x: [f64; 2]| {
            let (u, v) = (x[0], x[1]);
            [
                1.5 - 0.7 * u + 0.3 * v + 0.9 * u * u - 1.1 * u * v + 0.4 * v * v,
                -0.7 + 1.8 * u - 1.1 * v,
                0.3 - 1.1 * u + 0.8 * v,
                1.8,
                -1.1,
                0.8,
            ]
        };
        let a = dofs(&el, &q);
        for &(xi, eta) in &[(0.2, 0.3), (0.6, 0.1), (0.05, 0.9), (1.0 / 3.0, 1.0 / 3.0)] {
            let w = interpolate(&el, &a, xi, eta);
            let exact = q(el.point(xi, eta));
            for k in 0..6 {
                assert!(
                    (w[k] - exact[k]).abs() < 1e-10,
                    "component {k}: {} vs {}",
                    w[k],
                    exact[k]
                );
            }
        }
    }

    #[test]
    fn precomputed_moments_give_the_directly_integrated_stiffness() {
        let el = tri();
        let m = Material {
            alpha: [0.3, 0.1, 0.2],
            beta: [1.0, 0.5, 0.7],
            foundation: 2.5,
        };
        let (k1, f1) = el.stiffness_and_load(&m, 1.7, 16);
        let (k2, f2) = el.stiffness_fast(&m, 1.7);
        let scale = k1.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
        for i in 0..NDOF {
            assert!((f1[i] - f2[i]).abs() < 1e-12);
            for j in 0..NDOF {
                assert!(
                    (k1[i][j] - k2[i][j]).abs() < 1e-10 * scale,
                    "K[{i}][{j}]: {} vs {}",
                    k1[i][j],
                    k2[i][j]
                );
            }
        }
    }

    #[test]
    fn stiffness_quadrature_converges_to_1e_10() {
        let el = tri();
        let m = Material {
            alpha: [0.3, 0.1, 0.2],
            beta: [1.0, 0.5, 0.7],
            foundation: 0.0,
        };
        let norm = |k: &[[f64; NDOF]; NDOF]| k.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
        let diff = |a: &[[f64; NDOF]; NDOF], b: &[[f64; NDOF]; NDOF]| {
            a.iter()
                .flatten()
                .zip(b.iter().flatten())
                .map(|(x, y)| (x - y) * (x - y))
                .sum::<f64>()
                .sqrt()
        };
        let reference = el.stiffness_and_load(&m, 1.0, 24).0;
        let mut prev = f64::INFINITY;
        for n in [2, 3, 4, 6, 8] {
            let k = el.stiffness_and_load(&m, 1.0, n).0;
            let rel = diff(&k, &reference) / norm(&reference);
            println!("n = {n}: relative error {rel:.3e}");
            assert!(rel <= prev * 1.01 || rel < 1e-13, "not converging");
            prev = rel;
        }
        assert!(prev < 1e-10, "8×8×6 points: {prev:e}");
    }
}

//! The stable neo-Hookean material of Smith, de Goes & Kim (2018, "Stable Neo-Hookean Flesh
//! Simulation", ACM TOG 37(2):12), the default energy of `[tet] material = "neo-hookean"`.
//!
//! Their energy (eq. 14, with the log barrier on I_C that keeps the rest state stress-free),
//!   Ψ = μ/2 (I_C − 3) + λ/2 (J − α)² − μ/2 ln(I_C + 1),  α = 1 + 3μ/(4λ),
//! I_C = tr(FᵀF), J = det F, is finite and smooth for every F, inverted (J ≤ 0) or not: the
//! volume term pushes an inverted element back through J = 0 instead of being undefined there,
//! as the classical ln J or J^(−2/3) forms are. So a Newton iterate may pass through an inverted
//! state on its way to equilibrium; the converged answer is still checked for inverted elements.
//!
//! α makes F = I stress-free: P(I) = ¾ μ I + λ (1 − α) I = 0. Linearised at F = I the tangent is
//! (λ − ⅝ μ) δij δkl + ¾ μ (δik δjl + δil δjk), so the small-strain material of Lamé
//! constants (λ_L, μ_L) needs μ = 4/3 μ_L and λ = λ_L + 5/6 μ_L (their §3.4, "Lamé
//! reparametrisation", derived again here): the model agrees with the linear one for small moves.
//!
//! Derivatives, with g = ∂J/∂F = cof F and Ĩ = 1 − 1/(I_C + 1):
//!   P = μ Ĩ F + λ (J − α) g,
//!   ∂P_iJ/∂F_kL = μ Ĩ δik δJL + 2μ/(I_C + 1)² F_iJ F_kL + λ g_iJ g_kL + λ (J − α) ε_ikm ε_JLN F_mN
//! (the last: J's Hessian, from J = ⅙ ε_ikm ε_JLN F_iJ F_kL F_mN); tested against finite
//! differences of Ψ.

use super::TissueElastic;
use super::hyperelastic::{Hyperelastic, Tangent};
use nalgebra::Matrix3;

/// Stable neo-Hookean material: its own Lamé constants μ, λ (kPa) and rest offset α.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StableNeoHooke {
    pub mu: f64,
    pub lambda: f64,
    pub alpha: f64,
}

impl StableNeoHooke {
    /// The material with the small-strain behaviour of `m` (the reparametrisation above).
    pub fn from_elastic(m: TissueElastic) -> StableNeoHooke {
        let (lambda_l, mu_l) = m.lame();
        let mu = 4.0 / 3.0 * mu_l;
        let lambda = lambda_l + 5.0 / 6.0 * mu_l;
        StableNeoHooke {
            mu,
            lambda,
            alpha: 1.0 + 0.75 * mu / lambda,
        }
    }

    /// Ψ(I), subtracted so that the rest state stores no energy.
    fn rest(&self) -> f64 {
        0.5 * self.lambda * (1.0 - self.alpha).powi(2) - 0.5 * self.mu * 4f64.ln()
    }
}

/// cof F = ∂ det F / ∂F (columns: f₁ × f₂, f₂ × f₀, f₀ × f₁).
fn cofactor(f: &Matrix3<f64>) -> Matrix3<f64> {
    let (c0, c1, c2) = (f.column(0), f.column(1), f.column(2));
    Matrix3::from_columns(&[c1.cross(&c2), c2.cross(&c0), c0.cross(&c1)])
}

/// The Levi-Civita symbol.
fn eps(i: usize, j: usize, k: usize) -> f64 {
    match (i, j, k) {
        (0, 1, 2) | (1, 2, 0) | (2, 0, 1) => 1.0,
        (0, 2, 1) | (2, 1, 0) | (1, 0, 2) => -1.0,
        _ => 0.0,
    }
}

impl Hyperelastic for StableNeoHooke {
    fn energy(&self, f: &Matrix3<f64>) -> Option<f64> {
        let ic = f.norm_squared();
        let j = f.determinant();
        let w = 0.5 * self.mu * (ic - 3.0) + 0.5 * self.lambda * (j - self.alpha).powi(2)
            - 0.5 * self.mu * (ic + 1.0).ln()
            - self.rest();
        w.is_finite().then_some(w)
    }

    fn stress(&self, f: &Matrix3<f64>) -> Option<Matrix3<f64>> {
        let ic = f.norm_squared();
        let j = f.determinant();
        let p = f * (self.mu * (1.0 - 1.0 / (ic + 1.0)))
            + cofactor(f) * (self.lambda * (j - self.alpha));
        p.iter().all(|v| v.is_finite()).then_some(p)
    }

    fn stress_tangent(&self, f: &Matrix3<f64>) -> Option<(Matrix3<f64>, Tangent)> {
        let p = self.stress(f)?;
        let ic = f.norm_squared();
        let j = f.determinant();
        let g = cofactor(f);
        let a = self.mu * (1.0 - 1.0 / (ic + 1.0));
        let b = 2.0 * self.mu / (ic + 1.0).powi(2);
        let c = self.lambda * (j - self.alpha);
        let mut t = [[0.0; 9]; 9];
        for i in 0..3 {
            for jj in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        let d = if i == k && jj == l { a } else { 0.0 };
                        let mut h = 0.0;
                        for m in 0..3 {
                            let e1 = eps(i, k, m);
                            if e1 == 0.0 {
                                continue;
                            }
                            for n in 0..3 {
                                h += e1 * eps(jj, l, n) * f[(m, n)];
                            }
                        }
                        t[3 * i + jj][3 * k + l] = d
                            + b * f[(i, jj)] * f[(k, l)]
                            + self.lambda * g[(i, jj)] * g[(k, l)]
                            + c * h;
                    }
                }
            }
        }
        Some((p, t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material() -> (StableNeoHooke, TissueElastic) {
        let e = TissueElastic {
            youngs_kpa: 10.0,
            poisson: 0.45,
        };
        (StableNeoHooke::from_elastic(e), e)
    }

    #[test]
    fn stress_and_tangent_are_the_derivatives_of_the_energy_even_inverted() {
        let (m, _) = material();
        // An ordinary state and an inverted one (J < 0): the energy is defined for both.
        for f in [
            Matrix3::new(1.2, 0.3, -0.1, 0.05, 0.9, 0.2, -0.2, 0.1, 1.1),
            Matrix3::new(-0.8, 0.2, 0.1, 0.1, 0.7, -0.3, 0.2, 0.0, 0.9),
        ] {
            let (p, t) = m.stress_tangent(&f).unwrap();
            let h = 1e-6;
            for k in 0..3 {
                for l in 0..3 {
                    let (mut fp, mut fm) = (f, f);
                    fp[(k, l)] += h;
                    fm[(k, l)] -= h;
                    let dw = (m.energy(&fp).unwrap() - m.energy(&fm).unwrap()) / (2.0 * h);
                    assert!((dw - p[(k, l)]).abs() < 1e-6 * (1.0 + p.norm()), "P {k}{l}");
                    let dp = (m.stress(&fp).unwrap() - m.stress(&fm).unwrap()) / (2.0 * h);
                    for i in 0..3 {
                        for j in 0..3 {
                            let e = t[3 * i + j][3 * k + l];
                            assert!((dp[(i, j)] - e).abs() < 1e-5 * (1.0 + e.abs()), "A");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_rest_state_is_free_and_linearises_to_the_small_strain_material() {
        let (m, e) = material();
        let i = Matrix3::identity();
        assert!(m.energy(&i).unwrap().abs() < 1e-12);
        assert!(m.stress(&i).unwrap().norm() < 1e-12);
        let (lambda, mu) = e.lame();
        let (_, t0) = m.stress_tangent(&i).unwrap();
        let d = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        let want = lambda * d(i, j) * d(k, l)
                            + mu * (d(i, k) * d(j, l) + d(i, l) * d(j, k));
                        assert!((t0[3 * i + j][3 * k + l] - want).abs() < 1e-10 * lambda);
                    }
                }
            }
        }
        // A rigid rotation stores no energy and no stress.
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.5, 1.1).into_inner();
        assert!(m.energy(&r).unwrap().abs() < 1e-10);
        assert!(m.stress(&r).unwrap().norm() < 1e-10);
    }
}

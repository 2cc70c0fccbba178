//! The reduced basis: built by a greedy over a training set with the error bound as its
//! indicator, solved online in O(N³ + Q²N²) for any θ with a certified bound on the error in
//! the energy norm of the reference parameter θ̄ (Rozza, Huynh & Patera 2008 §4 and §6;
//! Quarteroni, Manzoni & Negri 2016 ch. 3 and 7).
//!
//! - X = A(θ̄), the inner product of the space; the basis is X-orthonormal.
//! - Online: A_N(θ) = Σ θ_q Vᵀ A_q V, f_N(θ) = Σ θ_q Vᵀ f_q, A_N c = f_N.
//! - The residual r(θ) = f(θ) − A(θ) V c has the dual norm ‖r‖_X' = ‖X⁻¹ r‖_X, and X⁻¹ r is a
//!   combination of the Riesz representers X⁻¹ f_q and X⁻¹ A_q v_n with weights (θ, −c θ)
//!   (Rozza et al. eq. 4.21–4.23). Those are kept in an X-orthonormal basis (Gram–Schmidt), so
//!   the norm is the Euclidean norm of T w: accurate to round-off in ‖r‖ itself, where the
//!   textbook quadratic form loses half the digits (Buhr, Engwer, Ohlberger & Rave 2014).
//! - Coercivity: every A_q is positive semi-definite and θ_q > 0, so
//!   vᵀ A(θ) v ≥ min_q (θ_q / θ̄_q) vᵀ X v: the min-θ lower bound α_LB(θ) (Rozza et al. §4.2.2).
//! - The bound: ‖u(θ) − V c‖_X ≤ Δ(θ) = ‖r(θ)‖_X' / α_LB(θ) (Rozza et al. Prop. 4.1).

use super::affine::{Affine, solve_columns};
use crate::error::{Error, NumericalKind, Result};
use crate::fem::cholesky::Cholesky;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// When the greedy stops: the largest relative bound Δ/‖u_N‖_X over the training set, or the
/// basis size.
#[derive(Clone, Copy, Debug)]
pub struct Greedy {
    pub tolerance: f64,
    pub max_size: usize,
}

/// One step of the greedy: the basis size and the largest relative bound over the training
/// set with that basis (before the next snapshot).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GreedyStep {
    pub size: usize,
    pub max_relative_bound: f64,
    /// The parameter of the next snapshot (the training point of the largest bound).
    pub worst: Vec<f64>,
}

/// The reduced model on an [`Affine`] system.
pub struct Basis {
    /// X-orthonormal basis vectors (free values).
    pub vectors: Vec<Vec<f64>>,
    /// Everything the online solve and its bound need (and all a stored model keeps).
    pub form: OnlineForm,
    pub history: Vec<GreedyStep>,
    /// Factorisations of the full model the build took (X and one per snapshot).
    pub full_factorisations: usize,
    /// Solves with the factor of X (Riesz representers and snapshots), the cheaper work.
    pub riesz_solves: usize,
}

/// The online data of a reduced model: N×N and N-sized arrays, independent of the mesh size
/// (docs/reduced.md "The stored model"). Serialised into `reduced_model.bin` and the page.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OnlineForm {
    /// θ̄: the reference parameters, X = A(θ̄).
    pub theta_bar: Vec<f64>,
    /// Per term q: Vᵀ A_q V (N×N, row-major) and Vᵀ f_q.
    pub matrices: Vec<Vec<f64>>,
    pub loads: Vec<Vec<f64>>,
    /// The residual's Riesz representers in an X-orthonormal basis: column j holds the
    /// coordinates of X⁻¹ f_q (j = q) or X⁻¹ A_q v_n (j = Q + n Q + q); shorter columns are
    /// zero beyond their length.
    pub riesz: Vec<Vec<f64>>,
    /// ‖ρ_j‖_X (for the round-off floor).
    pub riesz_norms: Vec<f64>,
    /// The full model's free unknowns (for the round-off floor).
    pub unknowns: usize,
}

/// The answer at one θ: the coefficients and the certified bound.
#[derive(Clone, Debug)]
pub struct Online {
    pub coefficients: DVector<f64>,
    /// Δ(θ): the bound on ‖u − u_N‖_X.
    pub energy_bound: f64,
    /// ‖u_N‖_X.
    pub energy_norm: f64,
    /// ‖r(θ)‖_X'.
    pub residual: f64,
    pub alpha: f64,
}

impl Basis {
    /// The greedy over `train` from the snapshot at θ̄; with the factor of X (which must be in the box the training
    /// set spans, every entry positive).
    pub fn build(
        sys: &Affine,
        theta_bar: &[f64],
        train: &[Vec<f64>],
        greedy: Greedy,
        progress: &dyn Fn(&str),
    ) -> Result<(Basis, Cholesky<f64>)> {
        let q = sys.terms();
        if theta_bar.len() != q || theta_bar.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(Error::config(
                "reduced model: the reference parameters must be positive, one per term",
            ));
        }
        let x = sys.factor(theta_bar)?;
        // X's values, so that X v is one pass over the pattern (Gram–Schmidt needs four).
        let x_values = sys.values_at(theta_bar);
        let loads: Vec<Vec<f64>> = (0..q).map(|k| sys.load(k).to_vec()).collect();
        let mut basis = Basis {
            vectors: Vec::new(),
            form: OnlineForm {
                theta_bar: theta_bar.to_vec(),
                matrices: vec![Vec::new(); q],
                loads: vec![Vec::new(); q],
                riesz: Vec::new(),
                riesz_norms: Vec::new(),
                unknowns: sys.unknowns(),
            },
            history: Vec::new(),
            full_factorisations: 1,
            riesz_solves: q,
        };
        // The X-orthonormal basis the Riesz coordinates refer to, needed only while the basis
        // grows (two vectors per term and basis vector: most of the build's memory).
        let mut space = RieszSpace::default();
        for (r, g) in solve_columns(&x, &loads).into_iter().zip(&loads) {
            basis.push_riesz(&mut space, r, g.clone());
        }
        // Riesz representers X⁻¹ A_q v_n, kept for the new vectors' inner products.
        let mut snapshot = solve_columns(&x, &[sys.rhs(theta_bar)]).remove(0);
        basis.riesz_solves += 1;
        loop {
            if !basis.add(sys, (&x, &x_values), &loads, &mut space, snapshot)? {
                break;
            }
            progress(&format!(
                "reduced model: basis of {} vectors",
                basis.vectors.len()
            ));
            let (worst, rel) = train
                .iter()
                .map(|t| {
                    let o = basis.solve(t);
                    let rel = o.as_ref().map_or(f64::INFINITY, |o| {
                        o.energy_bound / o.energy_norm.max(1e-300)
                    });
                    (t.as_slice(), rel)
                })
                .fold((theta_bar, f64::NEG_INFINITY), |a, b| {
                    if b.1 > a.1 { b } else { a }
                });
            basis.history.push(GreedyStep {
                size: basis.vectors.len(),
                max_relative_bound: rel,
                worst: worst.to_vec(),
            });
            if rel <= greedy.tolerance || basis.vectors.len() >= greedy.max_size {
                break;
            }
            let k = sys.factor(worst)?;
            basis.full_factorisations += 1;
            snapshot = solve_columns(&k, &[sys.rhs(worst)]).remove(0);
        }
        Ok((basis, x))
    }

    fn push_riesz(&mut self, space: &mut RieszSpace, rho: Vec<f64>, g: Vec<f64>) {
        let (coords, norm) = space.push(rho, g);
        self.form.riesz.push(coords);
        self.form.riesz_norms.push(norm);
    }

    /// Orthonormalise `u` against the basis in X (Gram–Schmidt twice) and add it with its
    /// reduced matrices and Riesz inner products; false when it adds nothing new.
    fn add(
        &mut self,
        sys: &Affine,
        (x, x_values): (&Cholesky<f64>, &[f64]),
        loads: &[Vec<f64>],
        space: &mut RieszSpace,
        mut u: Vec<f64>,
    ) -> Result<bool> {
        let q = sys.terms();
        let xu = |v: &[f64]| sys.apply_values(x_values, v);
        let norm0 = dot(&u, &xu(&u)).sqrt();
        for _ in 0..2 {
            let xv = xu(&u);
            for v in &self.vectors {
                let p = dot(v, &xv);
                for (a, b) in u.iter_mut().zip(v) {
                    *a -= p * b;
                }
            }
        }
        let norm = dot(&u, &xu(&u)).sqrt();
        if !(norm > 1e-10 * norm0) || !norm.is_finite() {
            return Ok(false);
        }
        u.iter_mut().for_each(|a| *a /= norm);
        let n = self.vectors.len();
        let av: Vec<Vec<f64>> = (0..q).map(|k| sys.apply(k, &u)).collect();
        let new_riesz = solve_columns(x, &av);
        self.riesz_solves += q;
        self.vectors.push(u);
        let m = n + 1;
        for (k, avk) in av.iter().enumerate() {
            let old = &self.form.matrices[k];
            let mut a = vec![0.0; m * m];
            for i in 0..n {
                a[i * m..i * m + n].copy_from_slice(&old[i * n..(i + 1) * n]);
            }
            for (j, v) in self.vectors.iter().enumerate() {
                let e = dot(v, avk);
                a[n * m + j] = e;
                a[j * m + n] = e;
            }
            self.form.matrices[k] = a;
            let f = dot(&self.vectors[n], &loads[k]);
            self.form.loads[k].push(f);
        }
        for (r, g) in new_riesz.into_iter().zip(av) {
            self.push_riesz(space, r, g);
        }
        Ok(true)
    }

    /// N.
    pub fn size(&self) -> usize {
        self.vectors.len()
    }

    /// The reduced solution at θ and its bound (θ positive, one per term).
    pub fn solve(&self, theta: &[f64]) -> Result<Online> {
        self.form.solve(theta)
    }

    /// The free values V c.
    pub fn expand(&self, c: &DVector<f64>) -> Vec<f64> {
        let mut u = vec![0.0; self.vectors.first().map_or(0, Vec::len)];
        for (v, w) in self.vectors.iter().zip(c.iter()) {
            for (a, b) in u.iter_mut().zip(v) {
                *a += w * b;
            }
        }
        u
    }
}

impl OnlineForm {
    /// N.
    pub fn size(&self) -> usize {
        self.loads.first().map_or(0, Vec::len)
    }

    /// Q.
    pub fn terms(&self) -> usize {
        self.theta_bar.len()
    }

    /// The reduced solution at θ and its bound (θ positive, one per term).
    pub fn solve(&self, theta: &[f64]) -> Result<Online> {
        let q = self.terms();
        let n = self.size();
        if theta.len() != q || theta.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(Error::config(format!(
                "reduced model: parameters {theta:?} are not {q} positive values"
            )));
        }
        let mut a = DMatrix::zeros(n, n);
        let mut f = DVector::zeros(n);
        for k in 0..q {
            a += DMatrix::from_row_slice(n, n, &self.matrices[k]) * theta[k];
            f += DVector::from_column_slice(&self.loads[k]) * theta[k];
        }
        let c = a
            .cholesky()
            .ok_or_else(|| {
                Error::numerical(
                    NumericalKind::Singular,
                    "the reduced system is not positive definite",
                )
            })?
            .solve(&f);
        // X⁻¹ r = Σ_j w_j ρ_j with w = (θ, −c_n θ_q).
        let w: Vec<f64> = theta
            .iter()
            .copied()
            .chain((0..n * q).map(|i| -c[i / q] * theta[i % q]))
            .collect();
        let residual = self.residual_norm(&w);
        let alpha = theta
            .iter()
            .zip(&self.theta_bar)
            .map(|(t, b)| t / b)
            .fold(f64::INFINITY, f64::min);
        Ok(Online {
            energy_norm: c.norm(),
            coefficients: c,
            residual,
            energy_bound: residual / alpha,
            alpha,
        })
    }

    /// ‖Σ_j w_j ρ_j‖_X plus its round-off: the coordinates carry ε ‖ρ_j‖ per unknown summed
    /// (Higham 2002 §3.1, γ_n), so the floor is n ε Σ |w_j| ‖ρ_j‖_X.
    fn residual_norm(&self, w: &[f64]) -> f64 {
        let rows = self.riesz.iter().map(Vec::len).max().unwrap_or(0);
        let mut y = vec![0.0; rows];
        for (wj, col) in w.iter().zip(&self.riesz) {
            for (a, b) in y.iter_mut().zip(col) {
                *a += wj * b;
            }
        }
        let floor: f64 = w
            .iter()
            .zip(&self.riesz_norms)
            .map(|(a, b)| a.abs() * b)
            .sum();
        dot(&y, &y).sqrt() + self.unknowns as f64 * f64::EPSILON * floor
    }

    /// Whether the arrays have the sizes N and Q imply (a stored model is checked on read).
    pub fn consistent(&self) -> bool {
        let (n, q) = (self.size(), self.terms());
        self.matrices.len() == q
            && self.loads.len() == q
            && self.matrices.iter().all(|m| m.len() == n * n)
            && self.loads.iter().all(|f| f.len() == n)
            && self.riesz.len() == q * (n + 1)
            && self.riesz_norms.len() == q * (n + 1)
            && self.riesz.iter().all(|c| c.len() <= q * (n + 1))
            && self.theta_bar.iter().all(|t| *t > 0.0 && t.is_finite())
    }
}

/// The X-orthonormal vectors e_i that Riesz representers ρ_j are kept in as coordinates
/// (ρ_j = Σ_i t_ij e_i), with X e_i to take inner products of new vectors without applying X.
#[derive(Default)]
struct RieszSpace {
    e: Vec<Vec<f64>>,
    xe: Vec<Vec<f64>>,
}

impl RieszSpace {
    /// Add ρ with X ρ = g (Gram–Schmidt twice; a direction already spanned adds no new e):
    /// its coordinates and ‖ρ‖_X.
    fn push(&mut self, mut rho: Vec<f64>, mut g: Vec<f64>) -> (Vec<f64>, f64) {
        let norm0 = dot(&rho, &g).max(0.0).sqrt();
        let mut coords = vec![0.0; self.e.len()];
        for _ in 0..2 {
            for (i, (e, xe)) in self.e.iter().zip(&self.xe).enumerate() {
                let p = dot(e, &g);
                coords[i] += p;
                rho.iter_mut().zip(e).for_each(|(a, b)| *a -= p * b);
                g.iter_mut().zip(xe).for_each(|(a, b)| *a -= p * b);
            }
        }
        let rest = dot(&rho, &g).max(0.0).sqrt();
        if rest > 1e-12 * norm0 {
            rho.iter_mut().for_each(|a| *a /= rest);
            g.iter_mut().for_each(|a| *a /= rest);
            self.e.push(rho);
            self.xe.push(g);
            coords.push(rest);
        }
        (coords, norm0)
    }
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

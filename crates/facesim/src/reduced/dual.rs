//! Primal–dual output bounds (Pierce & Giles 2000; Rozza, Huynh & Patera 2008 §4, the
//! bound for a non-compliant output; docs/design/reduced.md "Primal–dual output bounds"): for an output
//! s(θ) = lᵀ u(θ), a linear functional of the free unknowns, the adjoint problem
//! A(θ) ψ = l (A symmetric) has its own reduced basis W. With the primal residual
//! r(θ) = f(θ) − A(θ) u_N and the dual residual r_du(θ) = l − A(θ) ψ_N,
//!
//! ```text
//! s − lᵀu_N = ψᵀ r,      s_N = lᵀu_N + ψ_Nᵀ r,
//! |s − s_N| = |(ψ − ψ_N)ᵀ r| ≤ ‖r‖_X' ‖r_du‖_X' / α_LB(θ)
//! ```
//!
//! (A(θ)(ψ − ψ_N) = r_du and the coercivity bound give ‖ψ − ψ_N‖_X ≤ ‖r_du‖_X'/α_LB). The
//! corrected output's error is the product of the two residuals: with dual bounds of 1e-2 the
//! output is certified 100 times tighter than through the energy norm alone.
//!
//! A vector output (a landmark's displacement: three components) shares one dual space W for
//! its components: the adjoints of the three directions at the same θ lie close together.

use super::affine::{Affine, solve_columns};
use super::basis::{
    Basis, Online, Problem, RieszSpace, conjugate_gradients, dot, riesz_combination,
    solve_factorised,
};
use crate::error::{Error, NumericalKind, Result};
use crate::fem::cholesky::Cholesky;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// When a dual greedy stops: its largest relative bound ‖r_du‖_X' / (α_LB ‖ψ_N‖_X) over the
/// training set, or after `rounds` steps (each adds one snapshot per component).
#[derive(Clone, Copy, Debug)]
pub struct DualGreedy {
    pub tolerance: f64,
    pub rounds: usize,
    /// A snapshot's conjugate gradients stop at this fraction of the reduced dual bound at its
    /// point (the product uses the primal's, 1e-3).
    pub snapshot_accuracy: f64,
}

/// The online data of one output's dual reduced basis (C components, m = dim W, N = the
/// primal's basis size, Q terms): small arrays only, stored with the model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DualForm {
    /// Per term q: Wᵀ A_q W (m × m, row-major).
    pub matrices: Vec<Vec<f64>>,
    /// Per component j: Wᵀ l_j.
    pub outputs: Vec<Vec<f64>>,
    /// Per term q: Wᵀ f_q.
    pub loads: Vec<Vec<f64>>,
    /// Per term q: Wᵀ A_q V (m × N, row-major): the primal residual seen by the dual.
    pub coupling: Vec<Vec<f64>>,
    /// The dual residual's Riesz representers in an X-orthonormal basis: column j < C holds
    /// the coordinates of X⁻¹ l_j, column C + n Q + q those of X⁻¹ A_q w_n.
    pub riesz: Vec<Vec<f64>>,
    /// ‖ρ_j‖_X of those columns (for the round-off floor).
    pub riesz_norms: Vec<f64>,
    /// The full model's free unknowns (for the round-off floor).
    pub unknowns: usize,
    /// The greedy: its largest relative dual bound over the training set per size of W.
    pub greedy: Vec<(usize, f64)>,
}

/// One output's answer at θ: per component the correction ψ_Nᵀ r to add to lᵀ u_N, and the
/// bound on the corrected output's error.
#[derive(Clone, Debug, PartialEq)]
pub struct DualAnswer {
    pub correction: Vec<f64>,
    pub bound: Vec<f64>,
}

/// The dual reduced solution at θ: per component φ_j (ψ_N = W φ_j) and ‖r_du‖_X' with its
/// round-off floor.
struct DualSolution {
    phi: Vec<DVector<f64>>,
    residuals: Vec<f64>,
}

impl DualForm {
    /// m = dim W.
    pub fn size(&self) -> usize {
        self.outputs.first().map_or(0, Vec::len)
    }

    /// C, the output's components.
    pub fn components(&self) -> usize {
        self.outputs.len()
    }

    /// The corrected outputs' corrections and bounds at θ for the primal answer `primal` (the
    /// same θ). The bound: ‖r‖_X' ‖r_du‖_X' / α_LB, plus the round-off of the correction.
    pub fn answer(&self, theta: &[f64], primal: &Online) -> Result<DualAnswer> {
        let d = self.solve(theta)?;
        let c = primal.coefficients.as_slice();
        let n = c.len();
        let mut out = DualAnswer {
            correction: Vec::with_capacity(d.phi.len()),
            bound: Vec::with_capacity(d.phi.len()),
        };
        // W ᵀ r(θ) = Σ_q θ_q (Wᵀ f_q − Wᵀ A_q V c), and the sum of its terms' magnitudes.
        let m = self.size();
        let mut wr = vec![0.0; m];
        let mut wr_abs = vec![0.0; m];
        for (q, t) in theta.iter().enumerate() {
            for i in 0..m {
                let row = &self.coupling[q][i * n..(i + 1) * n];
                let avc = dot(row, c);
                let mag: f64 = row.iter().zip(c).map(|(a, b)| (a * b).abs()).sum();
                wr[i] += t * (self.loads[q][i] - avc);
                wr_abs[i] += t * (self.loads[q][i].abs() + mag);
            }
        }
        let eps = (self.unknowns + m + n) as f64 * f64::EPSILON;
        for (phi, res) in d.phi.iter().zip(&d.residuals) {
            out.correction.push(dot(phi.as_slice(), &wr));
            let floor = eps
                * phi
                    .iter()
                    .zip(&wr_abs)
                    .map(|(a, b)| a.abs() * b)
                    .sum::<f64>();
            out.bound.push(primal.residual * res / primal.alpha + floor);
        }
        Ok(out)
    }

    /// The dual reduced solution at θ: (Σ θ_q Wᵀ A_q W) φ_j = Wᵀ l_j, and the dual residual
    /// l_j − A(θ) W φ_j through its Riesz representer's coordinates.
    fn solve(&self, theta: &[f64]) -> Result<DualSolution> {
        let m = self.size();
        let q = theta.len();
        let mut a = DMatrix::zeros(m, m);
        for (k, t) in theta.iter().enumerate() {
            a += DMatrix::from_row_slice(m, m, &self.matrices[k]) * *t;
        }
        let chol = a.cholesky().ok_or_else(|| {
            Error::numerical(
                NumericalKind::Singular,
                "the dual reduced system is not positive definite",
            )
        })?;
        let cc = self.components();
        let mut phi = Vec::with_capacity(cc);
        let mut residuals = Vec::with_capacity(cc);
        for j in 0..cc {
            let p = chol.solve(&DVector::from_column_slice(&self.outputs[j]));
            // X⁻¹ r_du = ρ(l_j) − Σ_{n,q} φ_n θ_q ρ(A_q w_n).
            let mut w = vec![0.0; self.riesz.len()];
            w[j] = 1.0;
            for (nn, pn) in p.iter().enumerate() {
                for (k, t) in theta.iter().enumerate() {
                    w[cc + nn * q + k] = -pn * t;
                }
            }
            let (y, floor) = riesz_combination(&self.riesz, &self.riesz_norms, self.unknowns, &w);
            residuals.push(dot(&y, &y).sqrt() + floor);
            phi.push(p);
        }
        Ok(DualSolution { phi, residuals })
    }

    /// Whether the arrays have the sizes m, C, Q and N imply (a stored model is checked on
    /// read).
    pub fn consistent(&self, terms: usize, primal_size: usize) -> bool {
        let (m, c) = (self.size(), self.components());
        let columns = c + terms * m;
        self.matrices.len() == terms
            && self.loads.len() == terms
            && self.coupling.len() == terms
            && self.matrices.iter().all(|a| a.len() == m * m)
            && self.loads.iter().all(|f| f.len() == m)
            && self.coupling.iter().all(|a| a.len() == m * primal_size)
            && self.outputs.iter().all(|o| o.len() == m)
            && self.riesz.len() == columns
            && self.riesz_norms.len() == columns
            && self.riesz.iter().all(|r| r.len() <= columns)
            && self
                .matrices
                .iter()
                .chain(&self.loads)
                .chain(&self.coupling)
                .chain(&self.outputs)
                .chain(&self.riesz)
                .flatten()
                .chain(&self.riesz_norms)
                .all(|x| x.is_finite())
    }
}

/// α_LB(θ) = min_q θ_q / θ̄_q (Rozza et al. §4.2.2).
fn alpha_lb(theta: &[f64], theta_bar: &[f64]) -> f64 {
    theta
        .iter()
        .zip(theta_bar)
        .map(|(t, b)| t / b)
        .fold(f64::INFINITY, f64::min)
}

/// What the dual builds cost: conjugate-gradient iterations, solves with X's factor (one per
/// column) and factorisations of a snapshot that did not converge.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DualCost {
    pub cg_iterations: usize,
    pub reference_solves: usize,
    pub full_factorisations: usize,
}

/// The reference and the primal basis a dual build needs: the system, X's factor and values,
/// θ̄ and the primal's vectors V.
pub struct DualContext<'a> {
    pub sys: &'a Affine,
    pub x: &'a Cholesky<f64>,
    pub theta_bar: &'a [f64],
    pub primal: &'a Basis,
}

/// The dual reduced basis of one output of components `l` (free unknowns), whose adjoints at
/// θ̄, X⁻¹ l_j, are `adjoint`: W starts from them (the exact dual at θ̄), then the greedy over
/// `train` adds, each round, the adjoints of every component at the training point of the
/// largest relative dual bound, solved by conjugate gradients preconditioned with X.
pub fn build(
    ctx: &DualContext,
    l: &[Vec<f64>],
    adjoint: &[Vec<f64>],
    train: &[Vec<f64>],
    greedy: DualGreedy,
    cost: &mut DualCost,
) -> Result<DualForm> {
    let sys = ctx.sys;
    let q = sys.terms();
    let mut b = DualBuilder {
        ctx,
        x_values: sys.values_at(ctx.theta_bar),
        vectors: Vec::new(),
        x_vectors: Vec::new(),
        space: RieszSpace::new(sys.unknowns()),
        form: DualForm {
            matrices: vec![Vec::new(); q],
            outputs: vec![Vec::new(); l.len()],
            loads: vec![Vec::new(); q],
            coupling: vec![Vec::new(); q],
            riesz: Vec::new(),
            riesz_norms: Vec::new(),
            unknowns: sys.unknowns(),
            greedy: Vec::new(),
        },
    };
    // The Riesz representers of the outputs themselves are the adjoints at θ̄: no solve.
    b.push_riesz_solved(l, adjoint);
    b.add(l, adjoint.to_vec(), cost);
    for round in 0..=greedy.rounds {
        let bounds: Vec<f64> = train
            .iter()
            .map(|t| b.relative_bound(t))
            .collect::<Vec<_>>();
        let (worst, rel) = bounds
            .iter()
            .enumerate()
            .fold(
                (0, f64::NEG_INFINITY),
                |a, (i, r)| {
                    if *r > a.1 { (i, *r) } else { a }
                },
            );
        b.form.greedy.push((b.vectors.len(), rel));
        if rel <= greedy.tolerance || round == greedy.rounds || train.is_empty() {
            break;
        }
        let snapshots = b.snapshots(l, &train[worst], greedy.snapshot_accuracy, cost)?;
        if b.add(l, snapshots, cost) == 0 {
            break;
        }
    }
    Ok(b.form)
}

/// A dual basis while it grows: W (X-orthonormal) and the Riesz space of its residual.
struct DualBuilder<'a> {
    ctx: &'a DualContext<'a>,
    x_values: Vec<f64>,
    vectors: Vec<Vec<f64>>,
    /// X w for each w of W.
    x_vectors: Vec<Vec<f64>>,
    space: RieszSpace,
    form: DualForm,
}

impl DualBuilder<'_> {
    /// The largest relative dual bound ‖r_du‖_X' / (α_LB ‖ψ_N‖_X) over the components at θ
    /// (W is X-orthonormal, so ‖ψ_N‖_X = |φ|).
    fn relative_bound(&self, theta: &[f64]) -> f64 {
        let alpha = alpha_lb(theta, self.ctx.theta_bar);
        match self.form.solve(theta) {
            Ok(d) => d
                .phi
                .iter()
                .zip(&d.residuals)
                .map(|(p, r)| r / alpha / p.norm().max(1e-300))
                .fold(0.0, f64::max),
            Err(_) => f64::INFINITY,
        }
    }

    /// The adjoints A(θ) ψ_j = l_j at θ, by conjugate gradients from the reduced dual, each
    /// stopped at `accuracy` of its reduced bound (as the primal's snapshots); one not
    /// converged is factorised.
    fn snapshots(
        &mut self,
        l: &[Vec<f64>],
        theta: &[f64],
        accuracy: f64,
        cost: &mut DualCost,
    ) -> Result<Vec<Vec<f64>>> {
        let sys = self.ctx.sys;
        let d = self.form.solve(theta)?;
        let alpha = alpha_lb(theta, self.ctx.theta_bar);
        let problems = l
            .iter()
            .zip(d.phi.iter().zip(&d.residuals))
            .map(|(lj, (phi, res))| Problem {
                theta,
                rhs: lj.clone(),
                start: self.expand(phi),
                alpha,
                tolerance: accuracy * res / alpha,
            })
            .collect();
        let solved = conjugate_gradients(sys, self.ctx.x, problems);
        cost.cg_iterations += solved.iterations;
        cost.reference_solves += solved.preconditioner_solves;
        solved
            .solutions
            .into_iter()
            .zip(l)
            .map(|(u, lj)| match u {
                Some(u) => Ok(u),
                None => {
                    cost.full_factorisations += 1;
                    solve_factorised(sys, theta, lj)
                }
            })
            .collect()
    }

    /// W φ.
    fn expand(&self, phi: &DVector<f64>) -> Vec<f64> {
        let mut u = vec![0.0; self.ctx.sys.unknowns()];
        for (v, w) in self.vectors.iter().zip(phi.iter()) {
            for (a, b) in u.iter_mut().zip(v) {
                *a += w * b;
            }
        }
        u
    }

    /// Coordinates and norms of Riesz representers already solved (ρ = X⁻¹ g).
    fn push_riesz_solved(&mut self, g: &[Vec<f64>], rho: &[Vec<f64>]) {
        let n = self.ctx.sys.unknowns();
        let mut gm = faer::Mat::<f64>::zeros(n, g.len());
        let mut rm = faer::Mat::<f64>::zeros(n, g.len());
        for (j, (gj, rj)) in g.iter().zip(rho).enumerate() {
            gm.col_as_slice_mut(j).copy_from_slice(gj);
            rm.col_as_slice_mut(j).copy_from_slice(rj);
        }
        for (coords, norm) in self.space.push(rm, gm) {
            self.form.riesz.push(coords);
            self.form.riesz_norms.push(norm);
        }
    }

    /// Orthonormalise each new vector against W in X (Gram–Schmidt twice) and add it: its
    /// rows of Wᵀ A_q W, Wᵀ l_j, Wᵀ f_q and Wᵀ A_q V, and the Riesz representers of A_q w
    /// (Q solves with X's factor, all new vectors' in one block). How many were added.
    fn add(&mut self, l: &[Vec<f64>], new: Vec<Vec<f64>>, cost: &mut DualCost) -> usize {
        let sys = self.ctx.sys;
        let q = sys.terms();
        let first = self.vectors.len();
        for w in new {
            self.orthonormalise_in(w);
        }
        let fresh: Vec<&[f64]> = self.vectors[first..].iter().map(Vec::as_slice).collect();
        // Per term, its products with the new vectors in one pass over its entries.
        let mut by_term: Vec<Vec<Vec<f64>>> = (0..q).map(|k| sys.apply_many(k, &fresh)).collect();
        let mut images: Vec<Vec<f64>> = Vec::new();
        for (i, n) in (first..self.vectors.len()).enumerate() {
            let m = n + 1;
            let w = &self.vectors[n];
            for (k, terms) in by_term.iter().enumerate() {
                let awk = &terms[i];
                let old = &self.form.matrices[k];
                let mut a = vec![0.0; m * m];
                for r in 0..n {
                    a[r * m..r * m + n].copy_from_slice(&old[r * n..(r + 1) * n]);
                }
                for (j, v) in self.vectors[..m].iter().enumerate() {
                    let e = dot(v, awk);
                    a[n * m + j] = e;
                    a[j * m + n] = e;
                }
                self.form.matrices[k] = a;
                self.form.loads[k].push(dot(w, sys.load(k)));
                let primal = &self.ctx.primal.vectors;
                self.form.coupling[k].extend(primal.iter().map(|v| dot(awk, v)));
            }
            for (o, lj) in self.form.outputs.iter_mut().zip(l) {
                o.push(dot(w, lj));
            }
        }
        // The Riesz solves' right-hand sides, vector after vector, term after term.
        for i in 0..self.vectors.len() - first {
            images.extend(by_term.iter_mut().map(|t| std::mem::take(&mut t[i])));
        }
        let added = images.len() / q.max(1);
        if added > 0 {
            let rho = solve_columns(self.ctx.x, &images);
            cost.reference_solves += images.len();
            self.push_riesz_solved(&images, &rho);
        }
        added
    }

    /// Gram–Schmidt twice in X of `w` against W, then added to W unless nothing of it is left.
    /// X w is applied once and carried along (X(w − p v) = X w − p X v, with X v kept per
    /// vector), where applying X at each sweep cost three more products per vector.
    fn orthonormalise_in(&mut self, mut w: Vec<f64>) {
        let mut xw = self.ctx.sys.apply_values(&self.x_values, &w);
        let norm0 = dot(&w, &xw).sqrt();
        for _ in 0..2 {
            for (v, xv) in self.vectors.iter().zip(&self.x_vectors) {
                let p = dot(v, &xw);
                w.iter_mut().zip(v).for_each(|(a, b)| *a -= p * b);
                xw.iter_mut().zip(xv).for_each(|(a, b)| *a -= p * b);
            }
        }
        let norm = dot(&w, &xw).max(0.0).sqrt();
        if !(norm > 1e-10 * norm0 && norm.is_finite()) {
            return;
        }
        w.iter_mut().for_each(|a| *a /= norm);
        xw.iter_mut().for_each(|a| *a /= norm);
        self.vectors.push(w);
        self.x_vectors.push(xw);
    }
}

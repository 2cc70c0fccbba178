//! The nonlinear (hyperelastic) solve as `facesim run` does it: Newton's method from the linear
//! model's answer, each Newton system solved by conjugate gradients preconditioned with the
//! linear model's Cholesky factor (inexact Newton–Krylov; Knoll & Keyes 2004 review it). No
//! tangent is ever factored.
//!
//! Why it converges fast: for the moves of orthognathic surgery the tissue's strains are small
//! over most of the mesh, so the linear answer is already near equilibrium, and the tangent K_T
//! differs from the linear stiffness K₀ only where strains are large. With K₀⁻¹ as the
//! preconditioner, CG needs a few iterations per Newton step (the spectrum of K₀⁻¹ K_T clusters
//! at 1), each one triangular solve pair with the factor the linear model made anyway.
//!
//! The method (all vectors in the nodes' hold frames; held components are never changed, the
//! linear answer already meets every hold):
//! - residual r = f_int(u) on the free components (no external loads: the product's problems
//!   are prescribed displacements);
//! - direction: K_T d = −r by preconditioned CG to a relative tolerance η = min(0.1, ‖r‖/‖r₀‖)
//!   (the forcing term of Eisenstat & Walker 1996, choice giving quadratic convergence); if CG
//!   meets non-positive curvature (the stable neo-Hookean tangent is indefinite for strongly
//!   compressed or inverted elements) it stops there (Steihaug's truncation), or on its first
//!   iteration returns the preconditioned steepest-descent direction −K₀⁻¹ r, a descent
//!   direction because K₀ is positive definite;
//! - line search: the step is halved until the potential energy falls by the Armijo amount
//!   (with a round-off allowance); the energy is defined for every state (stable neo-Hookean);
//! - convergence: ‖r‖ / max(‖f_int‖, ‖r₀‖, f₀) ≤ tolerance (r₀: the linear answer's own
//!   out-of-balance force; f₀: that of a 10⁻⁴ strain, so a rigid move converges), or the
//!   correction's work |d · r| below 10⁻²⁰ of the first (the energy criterion of Bathe, Finite
//!   Element Procedures §8.4.4).
//!
//! A failure (no descent, no convergence in `max_iterations`) is a reported
//! [`NumericalKind::NotConverged`] with the residual history.

use super::TetMesh;
use super::holds::{Constrained, Frame, to_global, to_local};
use super::nonlinear::{ElementState, Energy, Solution, Step, element_state_of, scales};
use super::tangent::BlockMatrix;
use crate::error::{Error, NumericalKind, Result};
use crate::fem::pcg::truncated_pcg;
use rayon::prelude::*;

/// Settings of the Newton–Krylov solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    pub energy: Energy,
    pub max_iterations: usize,
    /// On the relative free residual.
    pub tolerance: f64,
    /// CG iterations per Newton step at most.
    pub max_krylov: usize,
    /// The increment criterion: the displacement error left estimated below this (mm).
    pub displacement_tolerance_mm: f64,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            energy: Energy::StableNeoHooke,
            max_iterations: 30,
            tolerance: 1e-10,
            max_krylov: 300,
            displacement_tolerance_mm: 1e-3,
        }
    }
}

const ENERGY_TOLERANCE: f64 = 1e-20;
/// The relative residual below which, after a full step, the exact tangent is used.
const EXACT_BELOW: f64 = 0.05;
/// The largest forcing term (relative tolerance of a Newton system's CG solve).
const ETA_MAX: f64 = 0.1;

/// Equilibrium of `mesh` with the holds `linear` was factored with, from `start` (the linear
/// model's answer under those holds: every held component at its value).
pub fn solve(
    mesh: &TetMesh,
    linear: &Constrained,
    start: &[[f64; 3]],
    opts: &Options,
) -> Result<Solution> {
    let frames = linear.frames();
    let n = mesh.nodes.len();
    if start.len() != n || frames.len() != n {
        return Err(Error::config(format!(
            "nonlinear volumetric model: {} start displacements and {} frames for {n} nodes",
            start.len(),
            frames.len()
        )));
    }
    let p = Problem::new(mesh, linear, opts);
    let mut tangent = BlockMatrix::new(n, &mesh.tets);
    let mut u = start.to_vec();
    let mut h = History::default();
    // The tangent is projected to positive semi-definite per element (globalisation: every
    // direction a descent direction) until Newton takes full steps near the solution, where the
    // exact tangent gives back quadratic convergence (the projected one converges linearly
    // where nearly incompressible elements are compressed at equilibrium).
    let mut project = true;
    for it in 0..=opts.max_iterations {
        let states = p.element_states(&u, project);
        let (energy, f_int) = p.internal_force(&states)?;
        let r = p.to_free_local(&f_int);
        let rn = norm(&r);
        let r0v = *h.r0.get_or_insert(rn);
        let rel = rn / norm(&f_int).max(r0v).max(p.f0);
        h.residuals.push(rel);
        if !rel.is_finite() {
            return Err(not_converged("the residual is not finite", &h.residuals));
        }
        if h.converged(rel, opts) {
            return Ok(done(u, it, h.residuals, h.krylov));
        }
        if it == opts.max_iterations {
            break;
        }
        tangent.assemble(&mesh.tets, frames, |e| {
            states[e].as_ref().and_then(|s| s.2.clone())
        });
        drop(states);
        let eta = h.forcing_term(rn);
        let (d, its) = p.direction(&tangent, &r, eta);
        h.krylov += its;
        let slope = dot(&r, &d);
        if !(slope < 0.0) {
            return Err(not_converged(
                "the Newton direction does not lower the energy",
                &h.residuals,
            ));
        }
        h.first_work.get_or_insert(slope.abs());
        let Some((trial, alpha)) = p.line_search(&u, &d, energy, slope) else {
            return Err(not_converged(
                "the line search found no step that lowers the energy",
                &h.residuals,
            ));
        };
        u = trial;
        h.last_work = Some((alpha * slope).abs());
        project = !(alpha == 1.0 && rel <= EXACT_BELOW);
        h.record_correction(alpha, &d);
    }
    Err(not_converged(
        &format!(
            "no convergence in {} Newton iterations",
            opts.max_iterations
        ),
        &h.residuals,
    ))
}

/// What the iterations solve: the mesh, the linear model (its factor and hold frames), which
/// components are held, the force and energy scales and the settings.
struct Problem<'a> {
    mesh: &'a TetMesh,
    linear: &'a Constrained,
    frames: &'a [Frame],
    /// Per component (3 per node): held.
    fixed: Vec<bool>,
    /// The out-of-balance force of a 10⁻⁴ strain, and the energy's round-off allowance.
    f0: f64,
    energy_noise: f64,
    opts: &'a Options,
}

impl<'a> Problem<'a> {
    fn new(mesh: &'a TetMesh, linear: &'a Constrained, opts: &'a Options) -> Problem<'a> {
        let frames = linear.frames();
        let fixed: Vec<bool> = frames
            .iter()
            .flat_map(|f| std::array::from_fn::<bool, 3, _>(|i| i < f.held))
            .collect();
        let (f0, energy_noise) = scales(mesh);
        Problem {
            mesh,
            linear,
            frames,
            fixed,
            f0,
            energy_noise,
            opts,
        }
    }

    /// The free components of a global vector, in the nodes' hold frames (held ones zero).
    fn to_free_local(&self, g: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; 3 * self.mesh.nodes.len()];
        for (v, f) in self.frames.iter().enumerate() {
            let l = to_local(&f.axes, [g[3 * v], g[3 * v + 1], g[3 * v + 2]]);
            for c in f.held..3 {
                out[3 * v + c] = l[c];
            }
        }
        out
    }

    /// The potential energy at `u`; None where an element has none or it is not finite.
    fn energy_at(&self, u: &[[f64; 3]]) -> Option<f64> {
        let (mesh, energy) = (self.mesh, self.opts.energy);
        (0..mesh.tets.len())
            .into_par_iter()
            .map(|e| element_state_of(mesh, e, u, false, false, energy).map(|s| s.0))
            .sum::<Option<f64>>()
            .filter(|e| e.is_finite())
    }

    /// Each element's energy, force and tangent (projected when `project`) at `u`.
    fn element_states(&self, u: &[[f64; 3]], project: bool) -> Vec<Option<ElementState>> {
        let (mesh, energy) = (self.mesh, self.opts.energy);
        (0..mesh.tets.len())
            .into_par_iter()
            .map(|e| element_state_of(mesh, e, u, true, project, energy))
            .collect()
    }

    /// The potential energy and the internal force f_int (global components) of the element
    /// states; an element without energy is a degenerate element.
    fn internal_force(&self, states: &[Option<ElementState>]) -> Result<(f64, Vec<f64>)> {
        let mesh = self.mesh;
        let mut energy = 0.0;
        let mut f_int = vec![0.0; 3 * mesh.nodes.len()];
        for (e, s) in states.iter().enumerate() {
            let (w, fe, _) = s.as_ref().ok_or_else(|| {
                Error::numerical(
                    NumericalKind::DegenerateElement,
                    format!(
                        "tetrahedron {e} (nodes {:?}) has no defined energy in the nonlinear solve",
                        mesh.tets[e]
                    ),
                )
            })?;
            energy += w;
            for a in 0..12 {
                f_int[3 * mesh.tets[e][a / 3] as usize + a % 3] += fe[a];
            }
        }
        Ok((energy, f_int))
    }

    /// The Newton direction: K_T d = −r by CG preconditioned with the linear factor, to the
    /// relative tolerance `eta`, held components kept at zero; and the CG iterations taken.
    fn direction(&self, tangent: &BlockMatrix, r: &[f64], eta: f64) -> (Vec<f64>, usize) {
        let apply = |x: &[f64]| -> Vec<f64> {
            let mut y = tangent.apply(x);
            for (v, h) in y.iter_mut().zip(&self.fixed) {
                if *h {
                    *v = 0.0;
                }
            }
            y
        };
        let precondition = |x: &[f64]| -> Vec<f64> {
            let mut y = self.linear.solve_local(x);
            for (v, h) in y.iter_mut().zip(&self.fixed) {
                if *h {
                    *v = 0.0;
                }
            }
            y
        };
        let b: Vec<f64> = r.iter().map(|v| -v).collect();
        truncated_pcg(apply, precondition, &b, eta, self.opts.max_krylov)
    }

    /// `u` moved by `alpha` times the direction `d` (in the hold frames).
    fn step(&self, u: &[[f64; 3]], d: &[f64], alpha: f64) -> Vec<[f64; 3]> {
        u.iter()
            .zip(self.frames)
            .enumerate()
            .map(|(v, (p, f))| {
                let g = to_global(&f.axes, [d[3 * v], d[3 * v + 1], d[3 * v + 2]]);
                [0, 1, 2].map(|c| p[c] + alpha * g[c])
            })
            .collect()
    }

    /// The line search along `d` from `u` (energy `energy`, slope `slope` = r · d): the step
    /// halved until the energy falls by the Armijo amount (with a round-off allowance); the
    /// state reached and its step length, or None in 30 halvings.
    fn line_search(
        &self,
        u: &[[f64; 3]],
        d: &[f64],
        energy: f64,
        slope: f64,
    ) -> Option<(Vec<[f64; 3]>, f64)> {
        let mut alpha = 1.0;
        for _ in 0..30 {
            let trial = self.step(u, d, alpha);
            if let Some(e) = self.energy_at(&trial)
                && e <= energy + 1e-4 * alpha * slope + self.energy_noise + 1e-13 * energy.abs()
            {
                return Some((trial, alpha));
            }
            alpha /= 2.0;
        }
        None
    }
}

/// What the iterations have seen so far.
#[derive(Default)]
struct History {
    /// The max nodal length of each accepted full correction (mm).
    corrections: Vec<f64>,
    /// The last residual norm and forcing term (None: no Newton step yet).
    last_rn: Option<f64>,
    last_eta: Option<f64>,
    /// The relative residual of each iterate.
    residuals: Vec<f64>,
    /// The first residual norm (the linear answer's own out-of-balance force).
    r0: Option<f64>,
    krylov: usize,
    /// The work |α d · r| of the first and of the last correction.
    first_work: Option<f64>,
    last_work: Option<f64>,
}

impl History {
    /// Whether the iterate of relative residual `rel` is converged: `rel` within the
    /// tolerance, the energy criterion or the increment criterion.
    fn converged(&self, rel: f64, opts: &Options) -> bool {
        let energy_converged = matches!((self.first_work, self.last_work), (Some(a), Some(b)) if b <= ENERGY_TOLERANCE * a);
        // The increment criterion: after two full Newton steps, the error left is about
        // |d_k| q / (1 − q) with q = |d_k| / |d_{k−1}| the observed contraction.
        let increment_converged = match self.corrections[..] {
            [.., a, b] if b < a => b * (b / a) / (1.0 - b / a) <= opts.displacement_tolerance_mm,
            _ => false,
        };
        rel <= opts.tolerance || energy_converged || increment_converged
    }

    /// The forcing term of the Newton system at residual norm `rn`, recorded for the next.
    fn forcing_term(&mut self, rn: f64) -> f64 {
        // Eisenstat & Walker's (1996) forcing term, choice 2 (γ = 0.9, exponent 2) with their
        // safeguard: accurate linear solves only as Newton closes in.
        let eta = match self.last_rn {
            None => ETA_MAX,
            Some(prev) => {
                let last_eta = self.last_eta.unwrap_or(ETA_MAX);
                let e = 0.9 * (rn / prev).powi(2);
                let guard = 0.9 * last_eta * last_eta;
                (if guard > 0.1 { e.max(guard) } else { e }).clamp(1e-12, ETA_MAX)
            }
        };
        self.last_rn = Some(rn);
        self.last_eta = Some(eta);
        eta
    }

    /// Record the correction `d` taken with step length `alpha`.
    fn record_correction(&mut self, alpha: f64, d: &[f64]) {
        // Only full steps show Newton's contraction; a damped one restarts the record.
        if alpha == 1.0 {
            let dmax = d
                .chunks(3)
                .map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
                .fold(0.0, f64::max);
            self.corrections.push(dmax);
        } else {
            self.corrections.clear();
        }
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|a| a * a).sum::<f64>().sqrt()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>()
}

fn done(u: Vec<[f64; 3]>, iterations: usize, residuals: Vec<f64>, krylov: usize) -> Solution {
    Solution {
        displacements: u,
        steps: vec![Step {
            load: 1.0,
            iterations,
            residuals,
            krylov_iterations: krylov,
        }],
        cuts: 0,
    }
}

fn not_converged(why: &str, residuals: &[f64]) -> Error {
    let history: Vec<String> = residuals.iter().map(|r| format!("{r:.3e}")).collect();
    Error::numerical(
        NumericalKind::NotConverged,
        format!(
            "the nonlinear (neo-Hookean) solve did not converge: {why}; relative residual history [{}]",
            history.join(", ")
        ),
    )
}

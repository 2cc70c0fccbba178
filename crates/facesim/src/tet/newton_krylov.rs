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
use super::holds::{Constrained, to_global, to_local};
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
    let fixed: Vec<bool> = frames
        .iter()
        .flat_map(|f| std::array::from_fn::<bool, 3, _>(|i| i < f.held))
        .collect();
    let (f0, energy_noise) = scales(mesh);
    let mut tangent = BlockMatrix::new(n, &mesh.tets);
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let to_free_local = |g: &[f64]| -> Vec<f64> {
        let mut out = vec![0.0; 3 * n];
        for (v, f) in frames.iter().enumerate() {
            let l = to_local(&f.axes, [g[3 * v], g[3 * v + 1], g[3 * v + 2]]);
            for c in f.held..3 {
                out[3 * v + c] = l[c];
            }
        }
        out
    };
    let energy_at = |u: &[[f64; 3]]| -> Option<f64> {
        (0..mesh.tets.len())
            .into_par_iter()
            .map(|e| element_state_of(mesh, e, u, false, false, opts.energy).map(|s| s.0))
            .sum::<Option<f64>>()
            .filter(|e| e.is_finite())
    };
    let mut u = start.to_vec();
    // The max nodal length of each accepted correction (mm), the last residual and forcing term.
    let mut corrections: Vec<f64> = Vec::new();
    let (mut last_rn, mut last_eta) = (None::<f64>, ETA_MAX);
    let mut residuals = Vec::new();
    let (mut r0, mut krylov) = (None::<f64>, 0);
    let (mut first_work, mut last_work) = (None::<f64>, None::<f64>);
    // The tangent is projected to positive semi-definite per element (globalisation: every
    // direction a descent direction) until Newton takes full steps near the solution, where the
    // exact tangent gives back quadratic convergence (the projected one converges linearly
    // where nearly incompressible elements are compressed at equilibrium).
    let mut project = true;
    for it in 0..=opts.max_iterations {
        let states: Vec<Option<ElementState>> = (0..mesh.tets.len())
            .into_par_iter()
            .map(|e| element_state_of(mesh, e, &u, true, project, opts.energy))
            .collect();
        let mut energy = 0.0;
        let mut f_int = vec![0.0; 3 * n];
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
        let r = to_free_local(&f_int);
        let rn = norm(&r);
        let r0v = *r0.get_or_insert(rn);
        let rel = rn / norm(&f_int).max(r0v).max(f0);
        residuals.push(rel);
        if !rel.is_finite() {
            return Err(not_converged("the residual is not finite", &residuals));
        }
        let energy_converged =
            matches!((first_work, last_work), (Some(a), Some(b)) if b <= ENERGY_TOLERANCE * a);
        // The increment criterion: after two full Newton steps, the error left is about
        // |d_k| q / (1 − q) with q = |d_k| / |d_{k−1}| the observed contraction.
        let increment_converged = match corrections[..] {
            [.., a, b] if b < a => b * (b / a) / (1.0 - b / a) <= opts.displacement_tolerance_mm,
            _ => false,
        };
        if rel <= opts.tolerance || energy_converged || increment_converged {
            return Ok(done(u, it, residuals, krylov));
        }
        if it == opts.max_iterations {
            break;
        }
        tangent.assemble(&mesh.tets, frames, |e| {
            states[e].as_ref().and_then(|s| s.2.clone())
        });
        drop(states);
        let apply = |x: &[f64]| -> Vec<f64> {
            let mut y = tangent.apply(x);
            for (v, h) in y.iter_mut().zip(&fixed) {
                if *h {
                    *v = 0.0;
                }
            }
            y
        };
        let precondition = |x: &[f64]| -> Vec<f64> {
            let mut y = linear.solve_local(x);
            for (v, h) in y.iter_mut().zip(&fixed) {
                if *h {
                    *v = 0.0;
                }
            }
            y
        };
        let b: Vec<f64> = r.iter().map(|v| -v).collect();
        // Eisenstat & Walker's (1996) forcing term, choice 2 (γ = 0.9, exponent 2) with their
        // safeguard: accurate linear solves only as Newton closes in.
        let eta = match last_rn {
            None => ETA_MAX,
            Some(prev) => {
                let e = 0.9 * (rn / prev).powi(2);
                let guard = 0.9 * last_eta * last_eta;
                (if guard > 0.1 { e.max(guard) } else { e }).clamp(1e-12, ETA_MAX)
            }
        };
        last_rn = Some(rn);
        last_eta = eta;
        let (d, its) = truncated_pcg(apply, precondition, &b, eta, opts.max_krylov);
        krylov += its;
        let slope = dot(&r, &d);
        if !(slope < 0.0) {
            return Err(not_converged(
                "the Newton direction does not lower the energy",
                &residuals,
            ));
        }
        first_work.get_or_insert(slope.abs());
        let step = |alpha: f64| -> Vec<[f64; 3]> {
            u.iter()
                .zip(frames)
                .enumerate()
                .map(|(v, (p, f))| {
                    let g = to_global(&f.axes, [d[3 * v], d[3 * v + 1], d[3 * v + 2]]);
                    [0, 1, 2].map(|c| p[c] + alpha * g[c])
                })
                .collect()
        };
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..30 {
            let trial = step(alpha);
            if let Some(e) = energy_at(&trial)
                && e <= energy + 1e-4 * alpha * slope + energy_noise + 1e-13 * energy.abs()
            {
                accepted = Some(trial);
                break;
            }
            alpha /= 2.0;
        }
        match accepted {
            Some(t) => u = t,
            None => {
                return Err(not_converged(
                    "the line search found no step that lowers the energy",
                    &residuals,
                ));
            }
        }
        last_work = Some((alpha * slope).abs());
        project = !(alpha == 1.0 && rel <= EXACT_BELOW);
        // Only full steps show Newton's contraction; a damped one restarts the record.
        if alpha == 1.0 {
            let dmax = d
                .chunks(3)
                .map(|c| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt())
                .fold(0.0, f64::max);
            corrections.push(dmax);
        } else {
            corrections.clear();
        }
    }
    Err(not_converged(
        &format!(
            "no convergence in {} Newton iterations",
            opts.max_iterations
        ),
        &residuals,
    ))
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

//! The `equilibrium` model: minimise
//! E(a) = ½ (a − a_init)ᵀ K (a − a_init) + Σ ½ k_c k_i c (|x_i − x_b'| − L0)²
//! over the three coordinate fields together, by Newton per increment. The spring Hessian
//! k c [n nᵀ + (1 − L0/L)(I − n nᵀ)] couples x, y, z at a vertex. The exact tangent is used when
//! it is positive definite; otherwise compressed springs' negative lateral part is dropped for
//! that iteration (a positive definite modified Newton step). Each Newton system is solved by
//! conjugate gradients (inexact Newton: to 1e-1 … 1e-3 of the residual, as far as the iteration
//! needs) preconditioned by one single-precision factorisation of the decoupled
//! K + diag(tr H₀ / 3) that serves x, y and z for the whole solve (the coupled tangent has 3× the
//! unknowns and 3×3 blocks: ~25× the factorisation cost); if they stall, the coupled tangent is
//! factored instead. Load increments start from a linear predictor. Converged when |r|/|r0| or
//! |Δa|/|a − a_init| falls below the tolerance — for the last increment; the energy is
//! conservative, so the equilibrium does not depend on the load path and earlier increments
//! stop at 1e-2 (they only keep Newton close to the path). Not converging within the iteration
//! limit is an error, never a silent result.
//!
//! Stacked unknowns: coordinate c of DOF g at c·nd + g.

use super::linearised::{DofResponses, RestSprings};
use super::problem::{Params, Problem, StepRecord};
use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::System;
use crate::fem::dofs::Dofs;
use crate::fem::pcg::pcg;
use crate::fem::precond::Precond;
use crate::fem::sparse::SymmetricCsr;
use crate::vec3::{norm, sub};
use std::collections::HashMap;

/// Relative residual at which load increments before the last stop.
const INTERMEDIATE_TOLERANCE: f64 = 1e-2;

/// The coupled factor is kept while it contracts the residual by this factor per iteration.
const RHO: f64 = 0.25;

/// Conjugate-gradient iterations before a Newton system counts as stalled.
const CG_MAX_ITERATIONS: usize = 400;

type Block = [[f64; 3]; 3];

/// Relative residual of the linearised (plan basis) solves by conjugate gradients (the fallback):
/// far below the linearisation's own error, so the basis is the tangent's response.
const LINEAR_TOLERANCE: f64 = 1e-11;

/// Conjugate-gradient iterations before a linearised solve falls back to the coupled factor.
const LINEAR_MAX_ITERATIONS: usize = 2000;

/// The DOFs of x, y, z after the last load increment, the per-increment records, and the
/// responses to `moves` of the tangent at rest (linearised.rs).
pub(super) fn solve(
    pr: &Problem,
    moves: &[Vec<[f64; 3]>],
) -> Result<([Vec<f64>; 3], Vec<StepRecord>, DofResponses)> {
    let p = pr.p;
    let mut newton = Newton::new(pr)?;
    let mut a = pr.a_init.clone();
    let mut history = Vec::new();
    let mut previous_step = a.clone();
    for step in 1..=p.steps {
        let (xb, _) = pr
            .plan
            .apply(&pr.springs.attachments, step as f64 / p.steps as f64);
        // Predictor: the load increments are equal, so start from the last state plus
        // the last increment's change (the response is close to linear per increment).
        let here = a.clone();
        if step > 1 {
            for c in 0..3 {
                for g in 0..newton.nd {
                    a[c][g] += a[c][g] - previous_step[c][g];
                }
            }
        }
        previous_step = here;
        history.push(newton.increment(&mut a, &xb, step)?);
    }
    let responses = if moves.is_empty() {
        DofResponses::none()
    } else {
        newton.responses(moves)?
    };
    Ok((a, history, responses))
}

/// The spring energy's gradient per coordinate field and its Hessian per spring vertex: exact,
/// and with compressed springs' negative lateral part dropped (`clamped`, positive definite).
struct Tangent {
    grad: [Vec<f64>; 3],
    hess: Vec<Block>,
    clamped: Vec<Block>,
}

/// The skin vertices carrying springs (sorted), each with one 3×3 Hessian block.
struct SpringBlocks {
    dofs: Dofs,
    vertices: Vec<usize>,
    slot: HashMap<usize, usize>,
}

impl SpringBlocks {
    fn new(pr: &Problem) -> SpringBlocks {
        let mut vertices: Vec<usize> = pr.springs.springs.iter().map(|s| s.skin).collect();
        vertices.sort_unstable();
        vertices.dedup();
        let slot = vertices.iter().enumerate().map(|(n, &i)| (i, n)).collect();
        SpringBlocks {
            dofs: pr.fem.dofs(),
            vertices,
            slot,
        }
    }

    /// Gradient and Hessians of the spring energy at `a`, attachments at `xb`.
    fn tangent(&self, pr: &Problem, a: &[Vec<f64>; 3], xb: &[[f64; 3]]) -> Tangent {
        let dofs = self.dofs;
        let nd = dofs.ndof();
        let mut grad = [vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]];
        let mut hess = vec![[[0.0; 3]; 3]; self.vertices.len()];
        let mut clamped = vec![[[0.0; 3]; 3]; self.vertices.len()];
        for (s, w) in pr.springs.springs.iter().zip(&pr.weight) {
            let g = dofs.value(s.skin);
            let xs = [0, 1, 2].map(|c| a[c][g]);
            let d = sub(xs, xb[s.bone]);
            let l = norm(d).max(1e-12);
            let n = d.map(|x| x / l);
            let geo = 1.0 - s.rest / l;
            let (h, hc) = (
                &mut hess[self.slot[&s.skin]],
                &mut clamped[self.slot[&s.skin]],
            );
            for r in 0..3 {
                grad[r][g] += w * (l - s.rest) * n[r];
                for c in 0..3 {
                    let id = if r == c { 1.0 } else { 0.0 };
                    h[r][c] += w * (n[r] * n[c] + geo * (id - n[r] * n[c]));
                    hc[r][c] += w * (n[r] * n[c] + geo.max(0.0) * (id - n[r] * n[c]));
                }
            }
        }
        Tangent {
            grad,
            hess,
            clamped,
        }
    }

    /// The coupled tangent I₃ ⊗ K + blocks `hess` as lower-triangle triplets of 3·nd unknowns.
    fn coupled(
        &self,
        k: &[(usize, usize, f64)],
        nd: usize,
        hess: &[Block],
    ) -> Vec<(usize, usize, f64)> {
        let mut t = Vec::with_capacity(3 * k.len() + 6 * self.vertices.len());
        for c in 0..3 {
            t.extend(
                k.iter()
                    .map(|&(r, col, val)| (c * nd + r, c * nd + col, val)),
            );
        }
        for (n, &i) in self.vertices.iter().enumerate() {
            let g = self.dofs.value(i);
            for r in 0..3 {
                for c in 0..=r {
                    t.push((r * nd + g, c * nd + g, hess[n][r][c]));
                }
            }
        }
        t
    }
}

/// The state the Newton iterations share over all load increments.
struct Newton<'a> {
    pr: &'a Problem<'a>,
    nd: usize,
    blocks: SpringBlocks,
    /// `fixed` for the stacked unknowns.
    fixed3: Vec<bool>,
    k_rows: SymmetricCsr,
    precond: Precond,
    /// The spring Hessian blocks at a_init (the coupled factor's first pattern).
    h0: Vec<Block>,
    /// The coupled tangent, factored only when conjugate gradients fail to converge.
    direct: Option<System>,
    /// Largest spring force scale, for the absolute floor of the residual test.
    scale: f64,
}

impl<'a> Newton<'a> {
    fn new(pr: &'a Problem<'a>) -> Result<Newton<'a>> {
        let nd = pr.fem.ndof();
        let fixed3: Vec<bool> = (0..3 * nd).map(|i| pr.fixed[i % nd]).collect();
        let blocks = SpringBlocks::new(pr);
        let Tangent { clamped: h0, .. } = blocks.tangent(pr, &pr.a_init, &pr.springs.attachments);
        // Preconditioner for the Newton systems: the coordinate fields decoupled, each spring
        // vertex's 3×3 stiffness replaced by its mean eigenvalue (trace / 3) times I. One
        // scalar factorisation of K + D (single precision, src/fem/precond.rs) serves x, y
        // and z and the whole solve, where the coupled tangent (3× the unknowns, 3×3 blocks)
        // costs ~25× more to factor. (Splitting each vertex's field into its normal and
        // tangential parts, with the spring stiffness along the normal only, was tried: CG
        // needed 2.3× more iterations, since K does not commute with the per-vertex frames.)
        let precond = {
            let mut d = vec![0.0; nd];
            for (n, &i) in blocks.vertices.iter().enumerate() {
                d[blocks.dofs.value(i)] = (h0[n][0][0] + h0[n][1][1] + h0[n][2][2]) / 3.0;
            }
            Precond::new(nd, &pr.k, &d, &pr.fixed).map_err(|e| {
                Error::numerical(
                    NumericalKind::Singular,
                    format!(
                        "{e} (equilibrium model: no rigid node and too few springs to hold the skin)"
                    ),
                )
            })?
        };
        let k_rows = SymmetricCsr::from_lower(nd, &pr.k);
        let scale = pr
            .springs
            .springs
            .iter()
            .zip(&pr.weight)
            .map(|(s, w)| w * s.rest)
            .fold(0.0, f64::max)
            .max(1e-300);
        Ok(Newton {
            pr,
            nd,
            blocks,
            fixed3,
            k_rows,
            precond,
            h0,
            direct: None,
            scale,
        })
    }

    /// The tangent (I₃ ⊗ K + spring blocks `h`) times the stacked `v`, zero on fixed DOFs.
    fn apply_tangent(&self, h: &[Block], v: &[f64]) -> Vec<f64> {
        let nd = self.nd;
        let mut y = self.k_rows.apply3(v, nd);
        for (n, &i) in self.blocks.vertices.iter().enumerate() {
            let g = self.blocks.dofs.value(i);
            for r in 0..3 {
                for c in 0..3 {
                    y[r * nd + g] += h[n][r][c] * v[c * nd + g];
                }
            }
        }
        for (i, f) in self.fixed3.iter().enumerate() {
            if *f {
                y[i] = 0.0;
            }
        }
        y
    }

    /// ∇E = K (a − a_init) + spring gradient, stacked, zero on fixed DOFs.
    fn residual(&self, a: &[Vec<f64>; 3], grad: &[Vec<f64>; 3]) -> Vec<f64> {
        let nd = self.nd;
        let da: Vec<f64> = (0..3)
            .flat_map(|c| a[c].iter().zip(&self.pr.a_init[c]).map(|(x, y)| x - y))
            .collect();
        let mut r = self.k_rows.apply3(&da, nd);
        for c in 0..3 {
            for g in 0..nd {
                r[c * nd + g] = if self.pr.fixed[g] {
                    0.0
                } else {
                    r[c * nd + g] + grad[c][g]
                };
            }
        }
        r
    }

    /// The Newton step for residual `r`: conjugate gradients on the tangent (exact when positive
    /// definite, else with compressed springs' negative lateral part dropped), preconditioned by
    /// the decoupled factor, to `cg_tol` of the residual (an inexact Newton step). If they stall,
    /// the coupled tangent is factored instead; that factor is kept (`stale` false) while it
    /// contracts the residual RHO× per iteration. Returns the step, the CG iterations and the
    /// factorisations it took.
    fn direction(
        &mut self,
        t: &Tangent,
        r: &[f64],
        stale: bool,
        cg_tol: f64,
    ) -> Result<(Vec<f64>, usize, usize)> {
        let neg: Vec<f64> = r.iter().map(|x| -x).collect();
        let refactor = self.direct.is_none() || stale;
        if refactor {
            let apply_p = |v: &[f64]| -> Vec<f64> { self.precond.apply(v) };
            let iterative = pcg(
                |v| self.apply_tangent(&t.hess, v),
                apply_p,
                &neg,
                cg_tol,
                CG_MAX_ITERATIONS,
            )
            .or_else(|| {
                pcg(
                    |v| self.apply_tangent(&t.clamped, v),
                    apply_p,
                    &neg,
                    cg_tol,
                    CG_MAX_ITERATIONS,
                )
            });
            if let Some((d, n)) = iterative {
                return Ok((d, n, 0));
            }
        }
        let (nd, k) = (self.nd, &self.pr.k);
        let sys = match self.direct.as_mut() {
            Some(s) => s,
            None => self.direct.insert(System::new(
                3 * nd,
                self.blocks.coupled(k, nd, &self.h0),
                &self.fixed3,
            )?),
        };
        // The exact tangent if it is positive definite, else the clamped one.
        if refactor && sys.refactor(self.blocks.coupled(k, nd, &t.hess)).is_err() {
            sys.refactor(self.blocks.coupled(k, nd, &t.clamped))?;
        }
        let zero = vec![0.0; 3 * nd];
        let d = sys.solve(&[neg], std::slice::from_ref(&zero)).remove(0);
        Ok((d, 0, usize::from(refactor)))
    }

    /// The linearisation at rest (linearised.rs): (I₃ ⊗ K + Σ H_s) δa = Σ H_s δx_b per move.
    /// The coupled tangent at rest is factored once and solves every move at once: on the real
    /// CT 0.16 s for 12 moves, where conjugate gradients on the run's preconditioner (no new
    /// factor, ~65 iterations per move to 1e-11) took 0.86 s (docs/design/plan-basis.md). Should that
    /// factorisation fail, conjugate gradients are the fallback.
    fn responses(&self, moves: &[Vec<[f64; 3]>]) -> Result<DofResponses> {
        let start = std::time::Instant::now();
        let (pr, nd) = (self.pr, self.nd);
        let rest = RestSprings::new(pr);
        let hess = self
            .blocks
            .tangent(pr, &pr.a_init, &pr.springs.attachments)
            .hess;
        let rhs: Vec<Vec<f64>> = moves
            .iter()
            .map(|m| rest.force(pr, m, 1.0, None).concat())
            .collect();
        let solved = match System::new(3 * nd, self.blocks.coupled(&pr.k, nd, &hess), &self.fixed3)
        {
            Ok(sys) => sys.solve(&rhs, &vec![vec![0.0; 3 * nd]; rhs.len()]),
            Err(factor_error) => rhs
                .iter()
                .map(|b| {
                    pcg(
                        |v| self.apply_tangent(&hess, v),
                        |v| self.precond.apply(v),
                        b,
                        LINEAR_TOLERANCE,
                        LINEAR_MAX_ITERATIONS,
                    )
                    .map(|(d, _)| d)
                    .ok_or_else(|| {
                        Error::numerical(
                            NumericalKind::NotConverged,
                            format!(
                                "plan basis: the equilibrium model's tangent at rest could not be factored ({factor_error}) and conjugate gradients did not converge"
                            ),
                        )
                    })
                })
                .collect::<Result<_>>()?,
        };
        let columns = solved
            .iter()
            .map(|d| [0, 1, 2].map(|c| d[c * nd..(c + 1) * nd].to_vec()))
            .collect();
        Ok(DofResponses {
            columns,
            wall_s: start.elapsed().as_secs_f64(),
        })
    }

    /// Newton iterations for load increment `step` (attachments at `xb`) from the predicted
    /// `a`, until the increment's tolerance holds.
    fn increment(
        &mut self,
        a: &mut [Vec<f64>; 3],
        xb: &[[f64; 3]],
        step: usize,
    ) -> Result<StepRecord> {
        let (p, nd) = (self.pr.p, self.nd);
        // The load increments only keep Newton near the equilibrium path: the energy is
        // conservative, so the final equilibrium does not depend on the path and only the last
        // increment needs the full tolerance.
        let tol_here = if step < p.steps {
            INTERMEDIATE_TOLERANCE.max(p.tolerance)
        } else {
            p.tolerance
        };
        let mut res_hist = Vec::new();
        let mut r0 = None;
        let (mut factorizations, mut cg_iterations) = (0, 0);
        let mut it = 0;
        let mut converged = false;
        while it < p.max_iterations {
            it += 1;
            let t = self.blocks.tangent(self.pr, a, xb);
            let r = self.residual(a, &t.grad);
            let rn = r.iter().map(|x| x * x).sum::<f64>().sqrt();
            let r0v = *r0.get_or_insert(rn);
            let previous = res_hist.last().copied();
            res_hist.push(rn);
            let target = tol_here * r0v.max(1e-12 * self.scale);
            if rn <= target {
                converged = true;
                break;
            }
            let stale = previous.is_some_and(|q| rn > RHO * q);
            // Inexact Newton (Eisenstat & Walker 1996): CG reduces the residual only as far as
            // this iteration needs to reach the target, between 1e-1 and 1e-3.
            let cg_tol = (target / rn).clamp(1e-3, 1e-1);
            let (d, cg, factored) = self.direction(&t, &r, stale, cg_tol)?;
            cg_iterations += cg;
            factorizations += factored;
            for c in 0..3 {
                for g in 0..nd {
                    a[c][g] += d[c * nd + g];
                }
            }
            let dn = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            let un = (0..3)
                .flat_map(|c| {
                    a[c].iter()
                        .zip(&self.pr.a_init[c])
                        .map(|(x, y)| (x - y) * (x - y))
                        .collect::<Vec<_>>()
                })
                .sum::<f64>()
                .sqrt();
            if !dn.is_finite() {
                return Err(Error::numerical(
                    NumericalKind::Diverged,
                    format!("equilibrium Newton diverged at step {step}, iteration {it}"),
                ));
            }
            // A step below the rounding of the positions themselves is as converged as the
            // arithmetic allows (a plan that moves nothing: the residual is rounding from the
            // start, and no relative test can be met).
            let an = a.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
            if dn <= tol_here * un.max(1e-12) || dn <= 16.0 * f64::EPSILON * an {
                converged = true;
                res_hist.push(rn);
                break;
            }
        }
        if !converged {
            return Err(not_converged(p, step, &res_hist, r0));
        }
        Ok(StepRecord {
            step,
            iterations: it,
            residual_history: res_hist,
            factorizations,
            cg_iterations,
            max_displacement_mm: self.pr.max_displacement(a),
        })
    }
}

/// Not converging within the iteration limit is an error, never a silent result.
fn not_converged(p: &Params, step: usize, res_hist: &[f64], r0: Option<f64>) -> Error {
    Error::numerical(
        NumericalKind::NotConverged,
        format!(
            "equilibrium Newton did not converge in {} iterations at load step {step}/{} (residual {:.2e} of {:.2e}; history {}); try more [solve] steps",
            p.max_iterations,
            p.steps,
            res_hist.last().copied().unwrap_or(f64::NAN),
            r0.unwrap_or(f64::NAN),
            res_hist
                .iter()
                .map(|x| format!("{x:.1e}"))
                .collect::<Vec<_>>()
                .join(" ")
        ),
    )
}

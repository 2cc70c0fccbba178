//! The geometrically nonlinear option of the volumetric model: compressible neo-Hookean tissue on
//! linear tetrahedra, total Lagrangian, solved by Newton's method with load steps.
//!
//! Material: the strain energy CalculiX uses for `*HYPERELASTIC, NEO HOOKE` (ccx manual, the
//! Neo-Hooke potential of *HYPERELASTIC),
//!   W = C10 (Ī₁ − 3) + (1/D1) (J − 1)²,  Ī₁ = J^(−2/3) tr(FᵀF),  J = det F,
//! with C10 = μ/2 and D1 = 2/K, K = λ + 2μ/3, so that it linearises to the small-strain material
//! of the same (E, ν) (an independent engine given C10 and D1 solves the same problem). Its first
//! Piola–Kirchhoff stress, with H = F⁻ᵀ and a = μ J^(−2/3):
//!   P = a (F − (I₁/3) H) + K (J − 1) J H,
//! and the consistent tangent ∂P_iJ/∂F_kL (tested against finite differences):
//!   A = −⅔ a H_kL (F_iJ − (I₁/3) H_iJ) + a (δ_ik δ_JL − ⅔ F_kL H_iJ + (I₁/3) H_iL H_kJ)
//!       + K (2J − 1) J H_iJ H_kL − K (J − 1) J H_iL H_kJ.
//! On a linear tetrahedron F = I + Σ_a u_a ⊗ g_a is constant; node a's internal force is
//! f_a = V P g_a and the tangent block K_ab,ik = V Σ_JL A_iJkL g_aJ g_bL.
//!
//! Holds are those of the linear model ([`Hold`]): Fixed values are the node's total
//! displacement (a rigidly moving bone node gets (R − I) x + t, exact for any rotation); a Slide
//! is the same linear constraint n · u = value, with the normal the caller gives (the moved
//! bone's). Loads are dead loads (fixed in the reference configuration).
//!
//! Solution: the held values and loads are applied in load steps s = 1/n, 2/n, …, 1. In each step
//! Newton's method solves K′ Δ′ = −r′ in the nodes' hold frames. The first iteration applies the
//! step's held increments whole (the held components of Δ′ are the gap to their target) with the
//! free nodes' linearised response; if that inverts an element the step is cut, never
//! shortened (a shortened step leaves part of the gap, and halving it again each iteration never
//! closes it). Later iterations keep the held values and search the line (halving while an element
//! inverts, J ≤ 0, or the potential energy does not decrease: Armijo). A step converges when the
//! held values are reached and either the relative free residual ‖r_free‖ / max(‖f_int‖, ‖f_ext‖,
//! ‖r₁‖, f₀) falls below the tolerance (‖r₁‖: the step's own out-of-balance force after its held
//! increments; f₀: the internal-force norm of a 10⁻⁴ strain, so a rigid move converges) or the
//! last correction's work |Δ·r| is below 10⁻²⁰ of the step's first (the energy criterion). A
//! step that does not converge in `max_iterations` is cut in half, up to `max_cuts` times in a
//! row, and then the solve fails with [`NumericalKind::NotConverged`] and the residual history; a
//! step that converges in a few iterations lets the next grow back (adaptive load steps).

use super::holds::{Frame, Hold, Loads, frames, rotate_lower, to_global, to_local};
pub use super::hyperelastic::{Hyperelastic, Tangent};
pub use super::stable_neo_hooke::StableNeoHooke;
use super::{TetMesh, TissueElastic, gradients};
use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::System;
use crate::fem::cholesky::Ordering;
use nalgebra::Matrix3;
use rayon::prelude::*;

/// Compressible neo-Hookean material (shear modulus μ, bulk modulus K, kPa).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeoHooke {
    pub mu: f64,
    pub kappa: f64,
}

/// Which strain energy the nonlinear solve uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Energy {
    /// CalculiX's `*HYPERELASTIC, NEO HOOKE` ([`NeoHooke`]): undefined for J ≤ 0, so every
    /// iterate must keep every element uninverted. Kept for the cross-check with CalculiX.
    CalculixNeoHooke,
    /// The stable neo-Hookean of Smith, de Goes & Kim 2018 ([`StableNeoHooke`]): defined for
    /// every F, the product's choice.
    StableNeoHooke,
}

impl NeoHooke {
    /// The neo-Hookean material with the small-strain behaviour of `m`.
    pub fn from_elastic(m: TissueElastic) -> NeoHooke {
        let (lambda, mu) = m.lame();
        NeoHooke {
            mu,
            kappa: lambda + 2.0 * mu / 3.0,
        }
    }

    /// CalculiX's C10 (kPa).
    pub fn c10(&self) -> f64 {
        self.mu / 2.0
    }

    /// CalculiX's D1 (1/kPa).
    pub fn d1(&self) -> f64 {
        2.0 / self.kappa
    }
}

impl Hyperelastic for NeoHooke {
    /// W(F); None when J ≤ 0.
    fn energy(&self, f: &Matrix3<f64>) -> Option<f64> {
        let j = f.determinant();
        if !(j > 0.0) {
            return None;
        }
        let i1 = f.norm_squared();
        Some(0.5 * self.mu * (j.powf(-2.0 / 3.0) * i1 - 3.0) + 0.5 * self.kappa * (j - 1.0).powi(2))
    }

    /// The first Piola–Kirchhoff stress P(F); None when J ≤ 0.
    fn stress(&self, f: &Matrix3<f64>) -> Option<Matrix3<f64>> {
        let j = f.determinant();
        if !(j > 0.0) {
            return None;
        }
        let h = f.try_inverse()?.transpose();
        let a = self.mu * j.powf(-2.0 / 3.0);
        let i1 = f.norm_squared();
        Some((f - h * (i1 / 3.0)) * a + h * (self.kappa * (j - 1.0) * j))
    }

    /// The stress and the consistent tangent ∂P/∂F; None when J ≤ 0.
    fn stress_tangent(&self, f: &Matrix3<f64>) -> Option<(Matrix3<f64>, Tangent)> {
        let j = f.determinant();
        if !(j > 0.0) {
            return None;
        }
        let h = f.try_inverse()?.transpose();
        let a = self.mu * j.powf(-2.0 / 3.0);
        let i1 = f.norm_squared();
        let p = (f - h * (i1 / 3.0)) * a + h * (self.kappa * (j - 1.0) * j);
        let (vol_a, vol_b) = (self.kappa * (2.0 * j - 1.0) * j, self.kappa * (j - 1.0) * j);
        let mut t = [[0.0; 9]; 9];
        for i in 0..3 {
            for jj in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        let d = if i == k && jj == l { 1.0 } else { 0.0 };
                        t[3 * i + jj][3 * k + l] =
                            -2.0 / 3.0 * a * h[(k, l)] * (f[(i, jj)] - i1 / 3.0 * h[(i, jj)])
                                + a * (d - 2.0 / 3.0 * f[(k, l)] * h[(i, jj)]
                                    + i1 / 3.0 * h[(i, l)] * h[(k, jj)])
                                + vol_a * h[(i, jj)] * h[(k, l)]
                                - vol_b * h[(i, l)] * h[(k, jj)];
                    }
                }
            }
        }
        Some((p, t))
    }
}

/// ∂P/∂F with its negative eigenvalues set to zero (projected Newton, Teran, Sifakis, Irving &
/// Fedkiw 2005): the element tangent V Gᵀ A G is then positive semi-definite, so the Newton
/// system stays a minimisation and its conjugate gradients meet no negative curvature. A
/// positive definite A (every element at small strain) is left as it is (one 9×9 Cholesky).
fn project_to_psd(t: &mut Tangent) {
    let a = nalgebra::SMatrix::<f64, 9, 9>::from_fn(|i, j| 0.5 * (t[i][j] + t[j][i]));
    if a.cholesky().is_some() {
        return;
    }
    let e = a.symmetric_eigen();
    let clamped = e.eigenvalues.map(|v| v.max(0.0));
    let p = e.eigenvectors
        * nalgebra::SMatrix::<f64, 9, 9>::from_diagonal(&clamped)
        * e.eigenvectors.transpose();
    for (i, row) in t.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = p[(i, j)];
        }
    }
}

/// One element's energy, internal forces (12) and, when asked, tangent (12×12).
pub(crate) type ElementState = (f64, [f64; 12], Option<Box<[[f64; 12]; 12]>>);

fn element_state(
    x: [[f64; 3]; 4],
    u: [[f64; 3]; 4],
    m: &impl Hyperelastic,
    with_tangent: bool,
    project: bool,
) -> Option<ElementState> {
    let (v, g) = gradients(x)?;
    let mut f = Matrix3::identity();
    for a in 0..4 {
        for i in 0..3 {
            for jj in 0..3 {
                f[(i, jj)] += u[a][i] * g[a][jj];
            }
        }
    }
    let w = m.energy(&f)?;
    let mut force = [0.0; 12];
    let tangent = if with_tangent {
        let (p, mut t) = m.stress_tangent(&f)?;
        if project {
            project_to_psd(&mut t);
        }
        for a in 0..4 {
            for i in 0..3 {
                force[3 * a + i] = v * (0..3).map(|jj| p[(i, jj)] * g[a][jj]).sum::<f64>();
            }
        }
        let mut k = Box::new([[0.0; 12]; 12]);
        for a in 0..4 {
            for b in 0..4 {
                for i in 0..3 {
                    for kk in 0..3 {
                        let mut s = 0.0;
                        for jj in 0..3 {
                            for l in 0..3 {
                                s += t[3 * i + jj][3 * kk + l] * g[a][jj] * g[b][l];
                            }
                        }
                        k[3 * a + i][3 * b + kk] = v * s;
                    }
                }
            }
        }
        Some(k)
    } else {
        let p = m.stress(&f)?;
        for a in 0..4 {
            for i in 0..3 {
                force[3 * a + i] = v * (0..3).map(|jj| p[(i, jj)] * g[a][jj]).sum::<f64>();
            }
        }
        None
    };
    Some((v * w, force, tangent))
}

/// The mesh's state at a displacement.
pub struct Internal {
    /// Stored energy ∫ W dV.
    pub energy: f64,
    /// Internal forces, 3 per node.
    pub forces: Vec<f64>,
    /// The tangent's lower triangle as triplets (empty unless asked for).
    pub tangent: Vec<(usize, usize, f64)>,
}

/// The mesh's stored energy, internal forces and, when asked, tangent at displacement `u`; an
/// element with J ≤ 0 (or flat) is a reported `DegenerateElement` failure naming it.
pub fn internal_state(mesh: &TetMesh, u: &[[f64; 3]], with_tangent: bool) -> Result<Internal> {
    internal_state_of(mesh, u, with_tangent, Energy::CalculixNeoHooke)
}

/// One element's state with the chosen energy.
pub(crate) fn element_state_of(
    mesh: &TetMesh,
    e: usize,
    u: &[[f64; 3]],
    with_tangent: bool,
    project: bool,
    energy: Energy,
) -> Option<ElementState> {
    let (t, m) = (mesh.tets[e], mesh.material[e]);
    let (x, ue) = (t.map(|n| mesh.nodes[n as usize]), t.map(|n| u[n as usize]));
    match energy {
        Energy::CalculixNeoHooke => {
            element_state(x, ue, &NeoHooke::from_elastic(m), with_tangent, project)
        }
        Energy::StableNeoHooke => element_state(
            x,
            ue,
            &StableNeoHooke::from_elastic(m),
            with_tangent,
            project,
        ),
    }
}

/// As [`internal_state`], with the chosen energy.
pub(crate) fn internal_state_of(
    mesh: &TetMesh,
    u: &[[f64; 3]],
    with_tangent: bool,
    energy: Energy,
) -> Result<Internal> {
    let per: Vec<Option<ElementState>> = (0..mesh.tets.len())
        .into_par_iter()
        // The stable energy's tangent turns indefinite under compression: projected for the
        // factored Newton steps, which need a positive definite matrix.
        .map(|e| {
            element_state_of(
                mesh,
                e,
                u,
                with_tangent,
                energy == Energy::StableNeoHooke,
                energy,
            )
        })
        .collect();
    let mut energy = 0.0;
    let mut f = vec![0.0; mesh.ndof()];
    for (e, s) in per.iter().enumerate() {
        let tet = mesh.tets[e];
        let (w, fe, _) = s.as_ref().ok_or_else(|| {
            Error::numerical(
                NumericalKind::DegenerateElement,
                format!(
                    "tetrahedron {e} (nodes {tet:?}) is inverted (J ≤ 0) in the nonlinear solve"
                ),
            )
        })?;
        energy += w;
        for a in 0..12 {
            f[3 * tet[a / 3] as usize + a % 3] += fe[a];
        }
    }
    let k = if with_tangent {
        super::blocks::lower_triplets(mesh.nodes.len(), &mesh.tets, |e| {
            per[e]
                .as_ref()
                .and_then(|(_, _, ke)| ke.as_deref())
                .ok_or_else(|| Error::numerical(NumericalKind::Singular, "no element tangent"))
        })?
    } else {
        Vec::new()
    };
    Ok(Internal {
        energy,
        forces: f,
        tangent: k,
    })
}

/// The energy criterion's tolerance: the last correction's work against the residual relative
/// to the step's first (quadratic convergence takes it from 1 to round-off in a few iterations).
const ENERGY_TOLERANCE: f64 = 1e-20;

/// Newton's method settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Newton {
    pub load_steps: usize,
    pub max_iterations: usize,
    /// On the relative free residual.
    pub tolerance: f64,
    /// How many times a failing step may be halved.
    pub max_cuts: usize,
    pub energy: Energy,
}

impl Default for Newton {
    fn default() -> Newton {
        Newton {
            load_steps: 4,
            max_iterations: 25,
            tolerance: 1e-10,
            max_cuts: 6,
            energy: Energy::StableNeoHooke,
        }
    }
}

/// One converged load step (for report.json).
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The load factor reached, in (0, 1].
    pub load: f64,
    pub iterations: usize,
    /// The relative free residual before each iteration and at convergence.
    pub residuals: Vec<f64>,
    /// Conjugate-gradient iterations in all (`newton_krylov`; 0 for factored Newton steps).
    pub krylov_iterations: usize,
}

/// The nonlinear solution: displacements (mm) and the steps taken.
#[derive(Clone, Debug)]
pub struct Solution {
    pub displacements: Vec<[f64; 3]>,
    pub steps: Vec<Step>,
    /// Steps cut in half on the way.
    pub cuts: usize,
}

/// A failed step: why, and its residual history.
struct StepFailure {
    why: String,
    residuals: Vec<f64>,
}

/// The force and energy scales of convergence tests: f₀, the internal-force norm of a 10⁻⁴
/// strain in the stiffest tissue (a rigid move has no other force scale), and the energy below
/// which a difference is round-off (sums of W V with W = O(E) round-off each: Ī₁ − 3 cancels).
pub(crate) fn scales(mesh: &TetMesh) -> (f64, f64) {
    let e_max = mesh
        .material
        .iter()
        .map(|m| m.youngs_kpa)
        .fold(0.0, f64::max);
    let volumes: Vec<f64> = mesh
        .tets
        .iter()
        .filter_map(|t| gradients(t.map(|n| mesh.nodes[n as usize])).map(|(v, _)| v))
        .collect();
    let f0 = 1e-4
        * e_max
        * volumes
            .iter()
            .map(|v| v.powf(4.0 / 3.0))
            .sum::<f64>()
            .sqrt();
    (f0, 1e-13 * e_max * volumes.iter().sum::<f64>())
}

/// The neo-Hookean solve with `holds` and dead `loads` (see the module docs).
pub fn solve(mesh: &TetMesh, holds: &[Hold], loads: &Loads, opts: &Newton) -> Result<Solution> {
    if opts.load_steps == 0 || opts.max_iterations == 0 || !(opts.tolerance > 0.0) {
        return Err(Error::config(
            "nonlinear volumetric model: load steps and Newton iterations must be ≥ 1 and the tolerance > 0",
        ));
    }
    let fr = frames(holds, mesh.nodes.len())?;
    let f_ext = loads.vector_linear(&mesh.nodes)?;
    let fixed: Vec<bool> = fr
        .iter()
        .flat_map(|f| std::array::from_fn::<bool, 3, _>(|i| i < f.held))
        .collect();
    let (f0, energy_noise) = scales(mesh);
    let mut solver = Solver {
        mesh,
        frames: fr,
        fixed,
        f_ext,
        f0,
        energy_noise,
        opts: *opts,
        sys: None,
    };
    let mut u = vec![[0.0; 3]; mesh.nodes.len()];
    let mut steps = Vec::new();
    let (mut done, mut ds, mut cuts, mut in_a_row) = (0.0_f64, 1.0 / opts.load_steps as f64, 0, 0);
    while done < 1.0 {
        let s = if done + ds > 1.0 - 1e-12 {
            1.0
        } else {
            done + ds
        };
        match solver.step(&mut u, s) {
            Ok(step) => {
                // Adaptive load steps: a step that converged quickly lets the next grow back
                // towards the first size.
                if step.iterations <= 6 {
                    ds = (ds * 2.0).min(1.0 / opts.load_steps as f64);
                }
                steps.push(step);
                done = s;
                in_a_row = 0;
            }
            Err(fail) => {
                if in_a_row >= opts.max_cuts {
                    let history: Vec<String> =
                        fail.residuals.iter().map(|r| format!("{r:.3e}")).collect();
                    return Err(Error::numerical(
                        NumericalKind::NotConverged,
                        format!(
                            "the nonlinear (neo-Hookean) solve did not converge at load {s:.4} after {in_a_row} step cuts in a row: {}; relative residual history [{}] (try more load steps or Newton iterations)",
                            fail.why,
                            history.join(", ")
                        ),
                    ));
                }
                cuts += 1;
                in_a_row += 1;
                ds /= 2.0;
            }
        }
    }
    Ok(Solution {
        displacements: u,
        steps,
        cuts,
    })
}

struct Solver<'a> {
    mesh: &'a TetMesh,
    frames: Vec<Frame>,
    fixed: Vec<bool>,
    f_ext: Vec<f64>,
    f0: f64,
    energy_noise: f64,
    opts: Newton,
    sys: Option<System>,
}

impl Solver<'_> {
    /// Potential energy and residual (internal − s·external forces) in local frames.
    fn local(&self, r: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; r.len()];
        for (v, f) in self.frames.iter().enumerate() {
            let l = to_local(&f.axes, [r[3 * v], r[3 * v + 1], r[3 * v + 2]]);
            out[3 * v..3 * v + 3].copy_from_slice(&l);
        }
        out
    }

    fn energy(&self, u: &[[f64; 3]], s: f64) -> Option<f64> {
        let w = internal_state_of(self.mesh, u, false, self.opts.energy)
            .ok()?
            .energy;
        let work: f64 = u
            .iter()
            .flatten()
            .zip(&self.f_ext)
            .map(|(a, b)| a * b)
            .sum();
        Some(w - s * work)
    }

    /// Solve load step s from `u` (left unchanged on failure).
    fn step(&mut self, u: &mut Vec<[f64; 3]>, s: f64) -> std::result::Result<Step, StepFailure> {
        let mut x = u.clone();
        let mut residuals = Vec::new();
        let mut step_scale: Option<f64> = None;
        let (mut first_work, mut last_work): (Option<f64>, Option<f64>) = (None, None);
        let fail = |why: String, residuals: &[f64]| StepFailure {
            why,
            residuals: residuals.to_vec(),
        };
        for it in 0..=self.opts.max_iterations {
            let Internal {
                energy,
                forces: f_int,
                tangent: k,
            } = internal_state_of(self.mesh, &x, true, self.opts.energy)
                .map_err(|e| fail(e.to_string(), &residuals))?;
            let r: Vec<f64> = f_int
                .iter()
                .zip(&self.f_ext)
                .map(|(a, b)| a - s * b)
                .collect();
            let rl = self.local(&r);
            // The gap of each held local component to its target s · value.
            let mut gap = vec![0.0; r.len()];
            let mut gap_max: f64 = 0.0;
            let mut target_max: f64 = 0.0;
            for (v, f) in self.frames.iter().enumerate() {
                let now = to_local(&f.axes, x[v]);
                for c in 0..f.held {
                    gap[3 * v + c] = s * f.values[c] - now[c];
                    gap_max = gap_max.max(gap[3 * v + c].abs());
                    target_max = target_max.max((s * f.values[c]).abs());
                }
            }
            let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
            let free: Vec<f64> = rl
                .iter()
                .zip(&self.fixed)
                .map(|(r, h)| if *h { 0.0 } else { *r })
                .collect();
            // The step's own residual scale: the out-of-balance force its held increments
            // cause (the first iterate after they are applied), else the internal and external
            // forces, else f₀ (a rigid move has none of them).
            let held = gap_max <= 1e-13 * (1.0 + target_max);
            let free_norm = norm(&free);
            if held && step_scale.is_none() {
                step_scale = Some(free_norm);
            }
            let reference = norm(&f_int)
                .max(s * norm(&self.f_ext))
                .max(step_scale.unwrap_or(0.0))
                .max(self.f0);
            let rel = free_norm / reference;
            residuals.push(rel);
            if !rel.is_finite() {
                return Err(fail("the residual is not finite".into(), &residuals));
            }
            // Force criterion, or the energy criterion of the last Newton correction (the work
            // of the correction against the residual, relative to the step's first; Bathe,
            // Finite Element Procedures §8.4.4): either means no further digit is to be had.
            let energy_converged = match (first_work, last_work) {
                (Some(w0), Some(w)) => w <= ENERGY_TOLERANCE * w0,
                _ => false,
            };
            if held && it > 0 && (rel <= self.opts.tolerance || energy_converged) {
                *u = x;
                return Ok(Step {
                    load: s,
                    iterations: it,
                    residuals,
                    krylov_iterations: 0,
                });
            }
            if it == self.opts.max_iterations {
                break;
            }
            let delta = self
                .newton_direction(&k, &rl, &gap)
                .map_err(|e| fail(e.to_string(), &residuals))?;
            let slope: f64 = rl
                .iter()
                .zip(&delta)
                .zip(&self.fixed)
                .map(|((r, d), h)| if *h { 0.0 } else { r * d })
                .sum();
            if held {
                last_work = Some(slope.abs());
                first_work.get_or_insert(slope.abs());
            }
            let mut alpha = 1.0;
            let mut accepted = None;
            // The held increments are applied whole: a shortened step would leave a fraction
            // of the gap for the next iteration, and halving it again and again never closes
            // it (the failure measured on the saw lines: a free residual at round-off, the gap open
            // after 25 iterations). If the whole increment inverts an element, the load step
            // is cut instead.
            let tries = if held { 30 } else { 1 };
            for _ in 0..tries {
                let trial: Vec<[f64; 3]> = x
                    .iter()
                    .zip(self.frames.iter())
                    .enumerate()
                    .map(|(v, (p, f))| {
                        let d =
                            to_global(&f.axes, [delta[3 * v], delta[3 * v + 1], delta[3 * v + 2]]);
                        [0, 1, 2].map(|c| p[c] + alpha * d[c])
                    })
                    .collect();
                if let Some(e) = self.energy(&trial, s) {
                    // While held values still move, any admissible (uninverted) state is
                    // accepted; after that the energy must decrease (Armijo, with a round-off
                    // allowance).
                    let before = energy - s * self.work(&x);
                    let armijo = e
                        <= before + 1e-4 * alpha * slope + self.energy_noise + 1e-13 * before.abs();
                    if !held || armijo {
                        accepted = Some(trial);
                        break;
                    }
                }
                alpha /= 2.0;
            }
            match accepted {
                Some(t) => x = t,
                None if !held => {
                    return Err(fail(
                        "the step's held increments invert an element when applied whole".into(),
                        &residuals,
                    ));
                }
                None => {
                    return Err(fail(
                        "the line search found no step that keeps every element uninverted and lowers the energy".into(),
                        &residuals,
                    ));
                }
            }
        }
        Err(fail(
            format!(
                "no convergence in {} Newton iterations",
                self.opts.max_iterations
            ),
            &residuals,
        ))
    }

    fn work(&self, u: &[[f64; 3]]) -> f64 {
        u.iter()
            .flatten()
            .zip(&self.f_ext)
            .map(|(a, b)| a * b)
            .sum()
    }

    /// Δ′ solving K′ Δ′ = −r′ on the free local components, Δ′ = gap on the held ones.
    fn newton_direction(
        &mut self,
        k: &[(usize, usize, f64)],
        rl: &[f64],
        gap: &[f64],
    ) -> Result<Vec<f64>> {
        let kl = rotate_lower(k, &self.frames);
        match &mut self.sys {
            Some(sys) => sys.refactor(kl)?,
            None => {
                self.sys = Some(System::with_ordering(
                    rl.len(),
                    kl,
                    &self.fixed,
                    Ordering::NestedDissection,
                )?)
            }
        }
        let sys = self
            .sys
            .as_ref()
            .ok_or_else(|| Error::numerical(NumericalKind::Singular, "no tangent factor"))?;
        let rhs: Vec<f64> = rl.iter().map(|r| -r).collect();
        Ok(sys.solve(&[rhs], &[gap.to_vec()]).remove(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f_of(a: [[f64; 3]; 3]) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| a[i][j])
    }

    #[test]
    fn stress_and_tangent_are_the_derivatives_of_the_energy() {
        let m = NeoHooke::from_elastic(TissueElastic {
            youngs_kpa: 10.0,
            poisson: 0.45,
        });
        let f = f_of([[1.2, 0.3, -0.1], [0.05, 0.9, 0.2], [-0.2, 0.1, 1.1]]);
        let (p, t) = m.stress_tangent(&f).unwrap();
        let h = 1e-6;
        for k in 0..3 {
            for l in 0..3 {
                let mut fp = f;
                let mut fm = f;
                fp[(k, l)] += h;
                fm[(k, l)] -= h;
                let dw = (m.energy(&fp).unwrap() - m.energy(&fm).unwrap()) / (2.0 * h);
                assert!((dw - p[(k, l)]).abs() < 1e-7 * p.norm(), "P {k}{l}");
                let dp = (m.stress(&fp).unwrap() - m.stress(&fm).unwrap()) / (2.0 * h);
                for i in 0..3 {
                    for j in 0..3 {
                        let e = t[3 * i + j][3 * k + l];
                        assert!((dp[(i, j)] - e).abs() < 1e-6 * (1.0 + e.abs()), "A");
                    }
                }
            }
        }
        // The small-strain limit: A(I) = λ δij δkl + μ (δik δjl + δil δjk).
        let (_, t0) = m.stress_tangent(&Matrix3::identity()).unwrap();
        let (lambda, mu) = TissueElastic {
            youngs_kpa: 10.0,
            poisson: 0.45,
        }
        .lame();
        let d = |a: usize, b: usize| if a == b { 1.0 } else { 0.0 };
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        let e = lambda * d(i, j) * d(k, l)
                            + mu * (d(i, k) * d(j, l) + d(i, l) * d(j, k));
                        assert!((t0[3 * i + j][3 * k + l] - e).abs() < 1e-12 * lambda);
                    }
                }
            }
        }
        assert!(
            m.energy(&f_of([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
                .is_none()
        );
    }
}

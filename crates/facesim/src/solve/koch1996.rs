//! The `koch1996` model: Koch et al. 1996 eq. 20–23.
//!
//! f_def,i = k_c k_i Σ_j c_ij (|s_ij| − |s_ij − t^j|) (s_ij − t^j)/|s_ij − t^j| with s_ij − t^j
//! the current spring vector (skin now − moved attachment) and |s_ij| its pre-operative length;
//! F_def (eq. 22) is evaluated lumped at the value DOFs (k_i already carries the area);
//! K a = F_init + F_def (eq. 23), forces recomputed at each increment.

use super::linearised::{DofResponses, RestSprings};
use super::problem::{Problem, StepRecord};
use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::System;
use crate::fem::sparse::SymmetricCsr;
use crate::osteotomy::Plan;
use crate::springs::SpringSet;
use crate::vec3::{norm, sub};

/// The DOFs of x, y, z after the last load increment, the per-increment records, and the
/// linearised recursion's responses to `moves` (linearised.rs), on the same factor of K.
pub(super) fn solve(
    pr: &Problem,
    moves: &[Vec<[f64; 3]>],
) -> Result<([Vec<f64>; 3], Vec<StepRecord>, DofResponses)> {
    let (springs, p, a_init) = (pr.springs, pr.p, &pr.a_init);
    let nd = pr.fem.ndof();
    pr.fem
        .check_constraints(&|t: usize| pr.material(t), &pr.fixed)?;
    let sys = System::new(nd, pr.k.clone(), &pr.fixed)?;
    let k_rows = SymmetricCsr::from_lower(nd, &pr.k);
    let f_init: Vec<Vec<f64>> = a_init.iter().map(|x| k_rows.apply(x)).collect();
    let max_move = max_bone_move(springs, pr.plan);
    let dofs = pr.fem.dofs();
    let mut a = a_init.clone();
    let mut history = Vec::new();
    for step in 1..=p.steps {
        let (xb, _) = pr
            .plan
            .apply(&springs.attachments, step as f64 / p.steps as f64);
        // F_init + F_def (eq. 22), F_def lumped at the value DOFs.
        let mut f = f_init.clone();
        for (s, w) in springs.springs.iter().zip(&pr.weight) {
            let g = dofs.value(s.skin);
            let xs = [0, 1, 2].map(|c| a[c][g]);
            let d = sub(xs, xb[s.bone]);
            let l = norm(d).max(1e-12);
            for c in 0..3 {
                f[c][g] += w * (s.rest - l) * d[c] / l;
            }
        }
        let sol = sys.solve(&f, a_init);
        a = [sol[0].clone(), sol[1].clone(), sol[2].clone()];
        // eq. 23 with forces taken at the current shape is a fixed-point iteration: it
        // diverges when the springs are much stiffer than the skin. The skin cannot
        // follow the bone by more than the bone moves plus its own size; beyond that the
        // iteration has diverged.
        let bound = 2.0 * max_move + 10.0;
        let d = pr.max_displacement(&a);
        if !d.is_finite() || d > bound {
            return Err(Error::numerical(
                NumericalKind::Diverged,
                format!(
                    "koch1996 diverged at load step {step}/{}: skin displacement {d:.3e} mm exceeds {bound:.1} mm (bone moves at most {max_move:.1} mm); lower [solve] k_c, raise [surface] alpha/beta or use model = \"equilibrium\"",
                    p.steps
                ),
            ));
        }
        history.push(StepRecord {
            step,
            iterations: 1,
            residual_history: vec![],
            factorizations: 0,
            cg_iterations: 0,
            max_displacement_mm: d,
        });
    }
    let responses = if moves.is_empty() {
        DofResponses::none()
    } else {
        responses(pr, &sys, moves)
    };
    Ok((a, history, responses))
}

/// The increments linearised at rest: K δa_k = Σ H_s ((k/steps) δx_b − δx_s(δa_{k−1})),
/// δa_0 = 0, fixed DOFs still; all moves at once per increment, on the run's factor of K.
fn responses(pr: &Problem, sys: &System, moves: &[Vec<[f64; 3]>]) -> DofResponses {
    let start = std::time::Instant::now();
    let rest = RestSprings::new(pr);
    let nd = pr.fem.ndof();
    let zero = vec![vec![0.0; nd]; 3 * moves.len()];
    let mut da: Vec<[Vec<f64>; 3]> =
        vec![[vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]]; moves.len()];
    for step in 1..=pr.p.steps {
        let scale = step as f64 / pr.p.steps as f64;
        let rhs: Vec<Vec<f64>> = moves
            .iter()
            .zip(&da)
            .flat_map(|(m, d)| rest.force(pr, m, scale, Some(d)))
            .collect();
        let mut sol = sys.solve(&rhs, &zero).into_iter();
        for d in &mut da {
            for c in d.iter_mut() {
                *c = sol.next().unwrap_or_default();
            }
        }
    }
    DofResponses {
        columns: da,
        wall_s: start.elapsed().as_secs_f64(),
    }
}

/// Largest distance any attachment moves under the whole plan.
fn max_bone_move(springs: &SpringSet, plan: &Plan) -> f64 {
    let (moved, _) = plan.apply(&springs.attachments, 1.0);
    moved
        .iter()
        .zip(&springs.attachments)
        .map(|(p, q)| norm(sub(*p, *q)))
        .fold(0.0, f64::max)
}

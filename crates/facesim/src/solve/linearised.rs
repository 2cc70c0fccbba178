//! The C1 models linearised at the pre-operative state, for the plan basis
//! (docs/design/plan-basis.md, "C1 models").
//!
//! At rest (a = a_init, attachments x_b where they were traced) every spring has its rest length,
//! so the preloaded skin is an equilibrium. A small move δx_b of the attachments changes spring
//! s's force on its skin vertex by H_s (δx_b − δx_s), with H_s = w [n nᵀ + (1 − L0/L)(I − n nᵀ)]
//! the spring energy's Hessian (n the spring's unit vector; L = L0 at rest, so H_s = w n nᵀ up to
//! rounding). Then
//! - `equilibrium`: (I₃ ⊗ K + Σ H_s) δa = Σ H_s δx_b (equilibrium.rs solves it);
//! - `koch1996`: the increments K a_k = F_init + F_def(a_{k−1}, x_b(k/steps)) linearise to
//!   K δa_k = Σ H_s ((k/steps) δx_b − δx_s(δa_{k−1})) (koch1996.rs runs the recursion).
//!
//! Both are linear in δx_b, and a segment's δx_b = M·[x_b; 1] is linear in M's entries, so the
//! responses to the unit matrices E_k are the basis's columns. Neither model is linear in the
//! plan (the springs turn and stretch), so the basis is a linear preview whose error grows with
//! the square of the move (measured in docs/design/plan-basis.md).

use super::problem::Problem;
use crate::vec3::{norm, sub};

pub(super) type Block = [[f64; 3]; 3];

/// The linearised responses: per move, the change of the DOFs of x, y, z.
pub(super) struct DofResponses {
    pub columns: Vec<[Vec<f64>; 3]>,
    pub wall_s: f64,
}

impl DofResponses {
    pub fn none() -> DofResponses {
        DofResponses {
            columns: Vec::new(),
            wall_s: 0.0,
        }
    }
}

/// Each spring at rest: its skin vertex's value DOF, its attachment and its Hessian H_s.
pub(super) struct RestSprings {
    dof: Vec<usize>,
    bone: Vec<usize>,
    block: Vec<Block>,
}

impl RestSprings {
    pub fn new(pr: &Problem) -> RestSprings {
        let dofs = pr.fem.dofs();
        let (mut dof, mut bone, mut block) = (Vec::new(), Vec::new(), Vec::new());
        for (s, w) in pr.springs.springs.iter().zip(&pr.weight) {
            let g = dofs.value(s.skin);
            let d = sub(
                [0, 1, 2].map(|c| pr.a_init[c][g]),
                pr.springs.attachments[s.bone],
            );
            let l = norm(d).max(1e-12);
            let n = d.map(|x| x / l);
            let geo = 1.0 - s.rest / l;
            let h: Block = std::array::from_fn(|r| {
                std::array::from_fn(|c| {
                    let id = if r == c { 1.0 } else { 0.0 };
                    w * (n[r] * n[c] + geo * (id - n[r] * n[c]))
                })
            });
            dof.push(g);
            bone.push(s.bone);
            block.push(h);
        }
        RestSprings { dof, bone, block }
    }

    /// The first-order change of the spring forces, Σ_s H_s (scale·δx_b − δx_s), per coordinate
    /// field (`nd` DOFs), zero on fixed DOFs; `skin` the DOF change (None: the skin stays).
    pub fn force(
        &self,
        pr: &Problem,
        attachment_move: &[[f64; 3]],
        scale: f64,
        skin: Option<&[Vec<f64>; 3]>,
    ) -> [Vec<f64>; 3] {
        let nd = pr.fem.ndof();
        let mut f = [vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]];
        for ((&g, &b), h) in self.dof.iter().zip(&self.bone).zip(&self.block) {
            let xb = attachment_move.get(b).copied().unwrap_or([0.0; 3]);
            let xs = skin.map_or([0.0; 3], |a| [a[0][g], a[1][g], a[2][g]]);
            let d: [f64; 3] = std::array::from_fn(|c| scale * xb[c] - xs[c]);
            for (r, fr) in f.iter_mut().enumerate() {
                fr[g] += h[r][0] * d[0] + h[r][1] * d[1] + h[r][2] * d[2];
            }
        }
        for fc in &mut f {
            for (v, fixed) in fc.iter_mut().zip(&pr.fixed) {
                if *fixed {
                    *v = 0.0;
                }
            }
        }
        f
    }
}

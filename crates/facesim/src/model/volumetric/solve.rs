//! The solve stage: K u = 0 under the holds on the linear mesh's node ordering, the rounds of
//! the holds that read the solution (`rounds`), then for the neo-Hookean material Newton from the
//! linear answer (`tet::newton_krylov`; load steps when it cannot start there). The linear models
//! keep their factor for the plan basis (no second factorisation).

use super::mesh::ordering;
use super::report::NewtonStep;
use super::rounds::{LiftOff, OneSidedContact, Round, Tearing};
use super::state::{OneSidedOutcome, Solving, constrain, no_factor, stiffness};
use crate::case::Tet;
use crate::error::Result;
use crate::fem::cholesky::MeshAnalyses;
use crate::fem::ordering::NodeOrder;
use crate::tet::conditions::Holds;
use crate::tet::from_ct::NodeKind;
use crate::tet::newton_krylov;
use crate::tet::nonlinear::{self, Newton};
use crate::tet::plan_holds::LinearHold;
use crate::tet::quadratic::Tet10Mesh;
use crate::tet::{Constrained, Hold, Loads, TetMesh, TissueElastic};

/// What the solve stage hands on.
pub(super) struct Solution {
    pub(super) displacement: Vec<[f64; 3]>,
    /// Nonlinear material: the load steps.
    pub(super) newton: Option<Vec<NewtonStep>>,
    /// The last factor, for the plan basis.
    pub(super) factor: Option<Constrained>,
    /// Nonlinear material: the linear answer Newton started from.
    pub(super) linear_start: Option<Vec<[f64; 3]>>,
    pub(super) order: Option<MeshAnalyses>,
    pub(super) linear: TetMesh,
    pub(super) constraint: Vec<u8>,
    pub(super) linear_hold: Vec<LinearHold>,
    pub(super) lifted: Vec<usize>,
    pub(super) torn: Vec<bool>,
    pub(super) one_sided: OneSidedOutcome,
    /// Why Newton fell back to load steps (a warning).
    pub(super) fallback: Option<String>,
}

/// What the solve reads beside the holds.
pub(super) struct Inputs<'a> {
    pub(super) quadratic: Option<&'a Tet10Mesh>,
    pub(super) kind: &'a [NodeKind],
    /// The tissues' materials before tearing.
    pub(super) material: &'a [TissueElastic],
    pub(super) raised: &'a [bool],
    pub(super) carries_face: &'a [bool],
    /// The linear models (any quadratic element, or the linear material) solve K u = f once.
    pub(super) linear_solve: bool,
    /// Solved for its face alone (`Purpose::FaceOnly`): a 10-node system iterates.
    pub(super) face_only: bool,
    /// The tissue may tear (`[tet] tear_gap`, the 4-node element, an orthognathic move).
    pub(super) tears: bool,
}

/// Solve the model under `holds`: the first solve, the rounds, Newton for the neo-Hookean
/// material.
pub(super) fn solve(inp: &Inputs, linear: TetMesh, holds: Holds, t: &Tet) -> Result<Solution> {
    let nodes = inp.kind.len();
    // The linear mesh's node ordering, once for every factor of this run and its re-solves (the
    // 10-node element orders its own DOFs).
    // METIS is sequential: it runs beside the element assembly, which it does not depend on.
    let (order, k) = rayon::join(
        || match inp.quadratic {
            None => {
                let solved: Vec<bool> = holds
                    .hold
                    .iter()
                    .map(|h| !matches!(h, Hold::Fixed(_)))
                    .collect();
                NodeOrder::of_tets(&solved, &linear.tets).map(MeshAnalyses::new)
            }
            Some(_) => None,
        },
        || stiffness(inp.quadratic, &linear),
    );
    let k = k?;
    let f = Loads::none().nodal_vector(nodes)?;
    let c = constrain(
        inp.quadratic,
        &k,
        &holds.hold,
        ordering(&order),
        inp.face_only,
    )?;
    let u = c.solve(&[(&holds.hold, &f)])?.remove(0);
    let mut s = Solving {
        nodes,
        kind: inp.kind,
        quadratic: inp.quadratic,
        face_only: inp.face_only,
        order,
        f,
        torn: vec![false; linear.tets.len()],
        linear,
        constraint: holds.constraint,
        hold: holds.hold,
        linear_hold: holds.linear,
        c: Some(c),
        u,
        lifted: Vec::new(),
        one_sided: OneSidedOutcome {
            settled: true,
            lifted_in_tension: 0,
            penetration_mm: 0.0,
        },
    };
    let contact = OneSidedContact {
        raised: inp.raised,
        k: &k,
    };
    contact.run(&mut s)?;
    drop(k);
    if t.release_cuts && t.sliding {
        LiftOff.run(&mut s)?;
    }
    if inp.tears {
        Tearing {
            carries_face: inp.carries_face,
            material: inp.material,
        }
        .run(&mut s)?;
    }
    let (displacement, newton, linear_start, fallback) = if inp.linear_solve {
        (std::mem::take(&mut s.u), None, None, None)
    } else {
        newton(&mut s, t)?
    };
    Ok(Solution {
        displacement,
        newton,
        factor: s.c,
        linear_start,
        order: s.order,
        linear: s.linear,
        constraint: s.constraint,
        linear_hold: s.linear_hold,
        lifted: s.lifted,
        torn: s.torn,
        one_sided: s.one_sided,
        fallback,
    })
}

/// The displacement, Newton's steps, the linear start and a fallback's warning.
type Newtoned = (
    Vec<[f64; 3]>,
    Option<Vec<NewtonStep>>,
    Option<Vec<[f64; 3]>>,
    Option<String>,
);

/// The hyperelastic model: Newton from the linear answer, the linear factor preconditioning
/// each Newton system (`tet::newton_krylov`); too far from the linear answer for Newton to start
/// there, load steps, each Newton system factored (slower, more robust).
fn newton(s: &mut Solving, t: &Tet) -> Result<Newtoned> {
    let c = s.c.as_ref().ok_or_else(no_factor)?;
    let mut fallback = None;
    let sol = match newton_krylov::solve(&s.linear, c, &s.u, &newton_krylov::Options::default()) {
        Ok(sol) => sol,
        Err(e) => {
            fallback = Some(format!(
                "the nonlinear solve from the linear answer failed ({e}); solved again in {} load steps",
                t.load_steps
            ));
            let opts = Newton {
                load_steps: t.load_steps,
                ..Newton::default()
            };
            nonlinear::solve(&s.linear, &s.hold, &Loads::none(), &opts)?
        }
    };
    let steps = sol
        .steps
        .iter()
        .map(|s| NewtonStep {
            load: s.load,
            iterations: s.iterations,
            residual: s.residuals.last().copied().unwrap_or(0.0),
            krylov_iterations: s.krylov_iterations,
        })
        .collect();
    Ok((
        sol.displacements,
        Some(steps),
        Some(std::mem::take(&mut s.u)),
        fallback,
    ))
}

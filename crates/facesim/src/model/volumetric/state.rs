//! The state the solve stage and its rounds share: the mesh, its holds, the factor kept between
//! rounds and the solution so far. `solve` drives it; each `rounds::Round` reads and changes it.

use super::mesh::ordering;
use crate::error::{Error, Result};
use crate::fem::cholesky::{MeshAnalyses, Ordering};
use crate::tet::from_ct::NodeKind;
use crate::tet::plan_holds::LinearHold;
use crate::tet::quadratic::Tet10Mesh;
use crate::tet::vtu::FREE;
use crate::tet::{Constrained, Hold, TetMesh};

/// The stiffness of the solved mesh: the 10-node one when there is one, else `linear`.
pub(super) fn stiffness(
    quadratic: Option<&Tet10Mesh>,
    linear: &TetMesh,
) -> Result<Vec<(usize, usize, f64)>> {
    match quadratic {
        Some(q) => q.assemble(),
        None => linear.assemble(),
    }
}

/// The solved mesh's system under `hold`: the 10-node one factored where its factor fits, else
/// solved by conjugate gradients with the p-multigrid preconditioner (`Constrained::quadratic`);
/// the 4-node one factored. A 10-node system solved for its face alone (`face_only`: no plan
/// basis to share a factor with) always iterates.
pub(super) fn constrain(
    quadratic: Option<&Tet10Mesh>,
    k: &[(usize, usize, f64)],
    hold: &[Hold],
    ordering: Ordering<'_>,
    face_only: bool,
) -> Result<Constrained> {
    match quadratic {
        Some(q) if face_only => Constrained::iterative(k, hold, q.corners, &q.edges),
        Some(q) => Constrained::quadratic(k, hold, (q.corners, &q.edges, &q.tets), ordering),
        None => Constrained::ordered(k, hold, hold.len(), ordering),
    }
}

/// A solve in progress: the holds, the factor and the displacement the rounds change.
pub(super) struct Solving<'a> {
    /// Solved nodes, and their kinds.
    pub(super) nodes: usize,
    pub(super) kind: &'a [NodeKind],
    pub(super) quadratic: Option<&'a Tet10Mesh>,
    /// A 10-node system iterates even where its factor fits (`constrain`).
    pub(super) face_only: bool,
    pub(super) order: Option<MeshAnalyses>,
    pub(super) f: Vec<f64>,
    /// The 4-node mesh and its materials (torn tetrahedra a trace).
    pub(super) linear: TetMesh,
    pub(super) constraint: Vec<u8>,
    pub(super) hold: Vec<Hold>,
    pub(super) linear_hold: Vec<LinearHold>,
    /// None only while a new factor is made (the old one goes first).
    pub(super) c: Option<Constrained>,
    pub(super) u: Vec<[f64; 3]>,
    /// The nodes lifted off the bone so far, and the tetrahedra torn.
    pub(super) lifted: Vec<usize>,
    pub(super) torn: Vec<bool>,
    pub(super) one_sided: OneSidedOutcome,
}

/// The factor of a solve between rounds: always there but while [`Solving::refactor`] makes a
/// new one.
pub(super) fn no_factor() -> Error {
    Error::config("the volumetric solve lost its factor between rounds")
}

impl Solving<'_> {
    /// Solve again on the current factor and holds.
    pub(super) fn solve(&mut self) -> Result<()> {
        let c = self.c.as_ref().ok_or_else(no_factor)?;
        self.u = c.solve(&[(&self.hold, &self.f)])?.remove(0);
        Ok(())
    }

    /// The current factor, to border it with freed or rested nodes.
    pub(super) fn factor_mut(&mut self) -> Result<&mut Constrained> {
        self.c.as_mut().ok_or_else(no_factor)
    }

    /// Factor the stiffness again (after a material changed); the old factor goes before the
    /// new one is made.
    pub(super) fn refactor(&mut self) -> Result<()> {
        self.c = None;
        let k = stiffness(self.quadratic, &self.linear)?;
        self.c = Some(constrain(
            self.quadratic,
            &k,
            &self.hold,
            ordering(&self.order),
            self.face_only,
        )?);
        Ok(())
    }

    /// Free `nodes` (the tissue lifts off there): held nowhere, in the run and the plan basis.
    pub(super) fn free(&mut self, nodes: &[usize]) {
        for &n in nodes {
            self.constraint[n] = FREE;
            self.hold[n] = Hold::Free;
            self.linear_hold[n] = LinearHold::Free;
        }
        self.lifted.extend(nodes);
    }

    /// The solved elements the current displacement turns inside out.
    pub(super) fn inverted(&self) -> Vec<usize> {
        match self.quadratic {
            Some(q) => q.inverted_after(&self.u),
            None => self.linear.inverted_after(&self.u),
        }
    }

    /// The nodes of solved element `e`.
    pub(super) fn cell(&self, e: usize) -> Vec<u32> {
        match self.quadratic {
            Some(q) => q.tets[e].to_vec(),
            None => self.linear.tets[e].to_vec(),
        }
    }
}

/// How the one-sided contact ended (report.json `tet.lifted_in_tension`, …).
pub(super) struct OneSidedOutcome {
    /// Every raised node still on its bone pushed by it, every lifted one clear of it.
    pub(super) settled: bool,
    pub(super) lifted_in_tension: usize,
    /// The deepest a lifted node lies inside its bone's move (mm).
    pub(super) penetration_mm: f64,
}

//! The C1 solve's shared types (Koch §4): the method, its parameters, the step record, the
//! solution, and the problem both methods solve. Its own file so that the methods
//! (`equilibrium`, `koch1996`, `linearised`, `restrict`) and `solve/mod.rs`, which dispatches
//! to them, take these from one place without importing each other.

use crate::fem::assembly::FemMesh;
use crate::fem::element::Material;
use crate::mesh::Mesh;
use crate::osteotomy::Plan;
use crate::springs::SpringSet;
use crate::vec3::norm;
use serde::{Deserialize, Serialize};

/// How the C1 model is solved (the case's `[solve] model`, `crate::case::SolveModel::c1_method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Newton's method on the equilibrium equations (docs/design/pipeline.md §5).
    Equilibrium,
    /// Koch's load steps, eq. 20–23.
    Koch1996,
}

impl Method {
    /// The C1 method of a case's `[solve] model`; None for the volumetric model, which is no C1
    /// model (`crate::model` dispatches on this).
    pub fn of(model: crate::case::SolveModel) -> Option<Method> {
        use crate::case::SolveModel;
        match model {
            SolveModel::Equilibrium => Some(Method::Equilibrium),
            SolveModel::Koch1996 => Some(Method::Koch1996),
            SolveModel::Tet => None,
        }
    }

    /// The spring force scale k_c (Koch eq. 20) of `[solve]`: Koch's own iteration was
    /// calibrated with its own constant (docs/design/pipeline.md).
    pub fn k_c(self, solve: &crate::case::Solve) -> f64 {
        match self {
            Method::Koch1996 => solve.koch_k_c,
            Method::Equilibrium => solve.k_c,
        }
    }
}

pub struct Params {
    pub model: Method,
    pub steps: usize,
    pub alpha: f64,
    pub beta: f64,
    /// Per-region (α, β) overrides, later ones winning.
    pub regions: Vec<crate::case::SurfaceRegion>,
    /// Force scale k_c (eq. 20): spring stiffness per unit c per mm² of skin.
    pub k_c: f64,
    pub tolerance: f64,
    pub max_iterations: usize,
    /// Solve only on the skin the bone moves can reach (exact; `[solve] restrict`).
    pub restrict: bool,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StepRecord {
    pub step: usize,
    pub iterations: usize,
    pub residual_history: Vec<f64>,
    /// Coupled tangent factorisations in this step (equilibrium model; only when conjugate
    /// gradients stall).
    pub factorizations: usize,
    /// Preconditioned conjugate-gradient iterations in this step (equilibrium model).
    pub cg_iterations: usize,
    pub max_displacement_mm: f64,
}

pub struct Solution {
    pub fem: FemMesh,
    /// DOFs of x, y, z.
    pub a: [Vec<f64>; 3],
    pub positions: Vec<[f64; 3]>,
    pub history: Vec<StepRecord>,
    pub unknowns: usize,
    /// Skin vertices in the mesh the equations were assembled on (the restricted piece or all).
    pub solved_vertices: usize,
}

/// What both models solve: the C1 skin with its preloaded DOFs, per-element materials, fixed
/// DOFs, the scalar stiffness K (lower triangle) and the spring weights k_c k_i c_ij (eq. 20).
pub(super) struct Problem<'a> {
    pub(super) skin: &'a Mesh,
    pub(super) springs: &'a SpringSet,
    pub(super) plan: &'a Plan,
    pub(super) p: &'a Params,
    pub(super) fem: FemMesh,
    pub(super) a_init: [Vec<f64>; 3],
    pub(super) mats: Vec<Material>,
    pub(super) fixed: Vec<bool>,
    pub(super) k: Vec<(usize, usize, f64)>,
    pub(super) weight: Vec<f64>,
}

impl Problem<'_> {
    pub(super) fn material(&self, t: usize) -> Material {
        self.mats[t]
    }

    /// Largest skin displacement from a_init over the vertices.
    pub(super) fn max_displacement(&self, a: &[Vec<f64>; 3]) -> f64 {
        let dofs = self.fem.dofs();
        (0..self.skin.vertices.len())
            .map(|i| {
                let g = dofs.value(i);
                norm([0, 1, 2].map(|c| a[c][g] - self.a_init[c][g]))
            })
            .fold(0.0, f64::max)
    }
}

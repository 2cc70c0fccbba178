//! The predicted face (Koch §4.4–4.5, docs/pipeline.md §5).
//!
//! Both models start from the preloaded C1 skin (a_init, F_init = K a_init) with rigid nodes
//! outside `[surface] movable`, and move the spring attachments by the plan in `steps` load
//! increments:
//! - `koch1996` (koch1996.rs): the paper's eq. 20–23, forces recomputed at each increment;
//! - `equilibrium` (equilibrium.rs): the minimum of skin plus spring energy, by Newton.
//!
//! restrict.rs cuts the skin down to the piece the bone moves can reach (exact), checks.rs
//! refuses plans no skin can follow.

mod checks;
mod equilibrium;
mod koch1996;
mod linearised;
mod restrict;

use crate::error::{Error, Result};
use crate::fem::assembly::{FemMesh, rigid_dofs};
use crate::fem::element::Material;
use crate::fem::preload::initial_dofs_fields;
use crate::mesh::Mesh;
use crate::osteotomy::Plan;
use crate::springs::SpringSet;
use crate::vec3::norm;
use serde::{Deserialize, Serialize};

/// How the C1 model is solved (the case's `[solve] model`, `crate::case::SolveModel::c1_method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Newton's method on the equilibrium equations (docs/pipeline.md §5).
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
    /// calibrated with its own constant (docs/pipeline.md).
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

/// The C1 mesh over the skin's (u, v) parameter columns.
fn fem_mesh(skin: &Mesh) -> Result<FemMesh> {
    let column = |name: &str| {
        skin.column(name).ok_or_else(|| {
            Error::config(format!(
                "the skin mesh has no '{name}' parameter coordinate"
            ))
        })
    };
    let (u, v) = (column("u")?, column("v")?);
    let uv: Vec<[f64; 2]> = u.iter().zip(v).map(|(a, b)| [*a, *b]).collect();
    FemMesh::new(uv, skin.triangles.clone())
}

/// The skin's C1 mesh over its (u, v) columns and the preloaded DOFs a_init of x, y, z (§5).
fn preloaded(skin: &Mesh) -> Result<(FemMesh, [Vec<f64>; 3])> {
    let fem = fem_mesh(skin)?;
    let xyz: [Vec<f64>; 3] = [0, 1, 2].map(|c| skin.vertices.iter().map(|x| x[c]).collect());
    let mut a = initial_dofs_fields(&fem, &[&xyz[0], &xyz[1], &xyz[2]])?.into_iter();
    let mut next = || a.next().unwrap_or_default();
    let a = [next(), next(), next()];
    Ok((fem, a))
}

/// Solve for the predicted face: on the reachable piece of the skin when `[solve] restrict` is on
/// and part of the skin is rigid (exact), else on the whole mesh. The returned C1 field covers the
/// whole face either way (the rigid part keeps its preloaded DOFs).
pub fn solve(
    skin: &Mesh,
    springs: &SpringSet,
    plan: &Plan,
    rigid: &[bool],
    p: &Params,
) -> Result<Solution> {
    Ok(solve_linearised(skin, springs, plan, rigid, p, &[])?.0)
}

/// The model's response to small attachment moves, linearised at the pre-operative state
/// (linearised.rs, docs/plan-basis.md): per requested move, the skin vertices' displacement.
pub(crate) struct Responses {
    /// Per move, one displacement (mm per unit move) per skin vertex (`skin`'s order).
    pub columns: Vec<Vec<[f64; 3]>>,
    /// Wall time of the tangent solves (s), which run on the solve's own factor.
    pub wall_s: f64,
}

/// [`solve`], and the linearised responses to `moves` (each one displacement per attachment of
/// `springs`, LPS mm), solved with the run's own factor (the equilibrium model's
/// preconditioner, koch1996's K).
pub(crate) fn solve_linearised(
    skin: &Mesh,
    springs: &SpringSet,
    plan: &Plan,
    rigid: &[bool],
    p: &Params,
    moves: &[Vec<[f64; 3]>],
) -> Result<(Solution, Responses)> {
    checks::check_plan_reach(skin, springs, plan)?;
    let Some(r) = p
        .restrict
        .then(|| restrict::Restriction::new(skin, springs, rigid))
        .flatten()
    else {
        return solve_mesh(skin, springs, plan, rigid, p, None, moves);
    };
    // One preload, of the whole face: the piece takes its DOFs from it, so its fixed rim holds
    // exactly the values the whole-face field keeps there (fits at the piece's edge would see a
    // truncated neighbourhood) and the restricted solve equals the whole-mesh one.
    let (fem, mut a) = preloaded(skin)?;
    let piece = fem_mesh(&r.skin)?;
    let edges = r.edges_to_full(&fem, &piece);
    let a_piece = r.piece_dofs(&fem, &a, &piece, &edges);
    let (s, piece_responses) = solve_mesh(
        &r.skin,
        &r.springs,
        plan,
        &r.rigid,
        p,
        Some((piece, a_piece)),
        moves,
    )?;
    r.merge_free(&fem, &mut a, &s, &edges);
    let mut positions = skin.vertices.clone();
    for (i, &g) in r.to_full.iter().enumerate() {
        positions[g] = s.positions[i];
    }
    // Vertices off the piece are rigid: they do not move.
    let columns = piece_responses
        .columns
        .into_iter()
        .map(|c| {
            let mut full = vec![[0.0; 3]; skin.vertices.len()];
            for (i, &g) in r.to_full.iter().enumerate() {
                full[g] = c[i];
            }
            full
        })
        .collect();
    Ok((
        Solution {
            fem,
            a,
            positions,
            history: s.history,
            unknowns: s.unknowns,
            solved_vertices: s.solved_vertices,
        },
        Responses {
            columns,
            wall_s: piece_responses.wall_s,
        },
    ))
}

/// What both models solve: the C1 skin with its preloaded DOFs, per-element materials, fixed
/// DOFs, the scalar stiffness K (lower triangle) and the spring weights k_c k_i c_ij (eq. 20).
struct Problem<'a> {
    skin: &'a Mesh,
    springs: &'a SpringSet,
    plan: &'a Plan,
    p: &'a Params,
    fem: FemMesh,
    a_init: [Vec<f64>; 3],
    mats: Vec<Material>,
    fixed: Vec<bool>,
    k: Vec<(usize, usize, f64)>,
    weight: Vec<f64>,
}

impl Problem<'_> {
    fn material(&self, t: usize) -> Material {
        self.mats[t]
    }

    /// Largest skin displacement from a_init over the vertices.
    fn max_displacement(&self, a: &[Vec<f64>; 3]) -> f64 {
        let dofs = self.fem.dofs();
        (0..self.skin.vertices.len())
            .map(|i| {
                let g = dofs.value(i);
                norm([0, 1, 2].map(|c| a[c][g] - self.a_init[c][g]))
            })
            .fold(0.0, f64::max)
    }
}

/// Per-element (α, β): the defaults, or the last [[surface.region]] containing the triangle's
/// centroid (Koch §4.2).
fn materials(skin: &Mesh, p: &Params) -> Vec<Material> {
    skin.triangles
        .iter()
        .map(|t| {
            let c = t
                .iter()
                .fold([0.0; 3], |a, &v| {
                    crate::vec3::add(a, skin.vertices[v as usize])
                })
                .map(|x| x / 3.0);
            let (al, be) = p
                .regions
                .iter()
                .rev()
                .find(|r| r.shape.contains(c))
                .map_or((p.alpha, p.beta), |r| (r.alpha, r.beta));
            Material::isotropic(al, be)
        })
        .collect()
}

/// One solve on `skin` (the whole face or the restricted piece, whose preloaded DOFs `pre`
/// then come from the whole face), by the model `p.model`, and the linearised responses to
/// `moves`.
fn solve_mesh(
    skin: &Mesh,
    springs: &SpringSet,
    plan: &Plan,
    rigid: &[bool],
    p: &Params,
    pre: Option<(FemMesh, [Vec<f64>; 3])>,
    moves: &[Vec<[f64; 3]>],
) -> Result<(Solution, Responses)> {
    let (fem, a_init) = match pre {
        Some(x) => x,
        None => preloaded(skin)?,
    };
    let mats = materials(skin, p);
    let fixed = rigid_dofs(&fem, rigid);
    let (k, _) = fem.assemble(&|t: usize| mats[t], 0.0);
    let weight: Vec<f64> = springs
        .springs
        .iter()
        .map(|s| p.k_c * springs.k[s.skin] * s.c)
        .collect();
    let pr = Problem {
        skin,
        springs,
        plan,
        p,
        fem,
        a_init,
        mats,
        fixed,
        k,
        weight,
    };
    let (a, history, responses) = match p.model {
        Method::Koch1996 => koch1996::solve(&pr, moves)?,
        Method::Equilibrium => equilibrium::solve(&pr, moves)?,
    };
    let nv = skin.vertices.len();
    let dofs = pr.fem.dofs();
    let positions: Vec<[f64; 3]> = (0..nv)
        .map(|i| [0, 1, 2].map(|c| a[c][dofs.value(i)]))
        .collect();
    checks::check_not_through_skin(skin, &positions, springs, plan)?;
    let unknowns = 3 * (pr.fem.ndof() - pr.fixed.iter().filter(|f| **f).count());
    let columns = responses
        .columns
        .iter()
        .map(|da| {
            (0..nv)
                .map(|i| [0, 1, 2].map(|c| da[c][dofs.value(i)]))
                .collect()
        })
        .collect();
    Ok((
        Solution {
            fem: pr.fem,
            a,
            positions,
            history,
            unknowns,
            solved_vertices: nv,
        },
        Responses {
            columns,
            wall_s: responses.wall_s,
        },
    ))
}

//! The predicted face (Koch §4.4–4.5, docs/design/pipeline.md §5).
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
mod problem;
mod restrict;

use crate::error::{Error, Result};
use crate::fem::assembly::{FemMesh, rigid_dofs};
use crate::fem::element::Material;
use crate::fem::preload::initial_dofs_fields;
use crate::mesh::Mesh;
use crate::osteotomy::Plan;
use crate::springs::SpringSet;
use problem::Problem;
pub use problem::{Method, Params, Solution, StepRecord};

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
/// (linearised.rs, docs/design/plan-basis.md): per requested move, the skin vertices' displacement.
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

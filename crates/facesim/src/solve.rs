//! Stage 6b — the predicted face (Koch §4.4–4.5, MODEL.md §6).
//!
//! Both models start from the preloaded C1 skin (a_init, F_init = K a_init) with rigid nodes
//! outside `[surface] movable`, and move the spring attachments by the plan in `steps` load
//! increments.
//!
//! - `koch1996`: eq. 20–23. f_def,i = k_c k_i Σ_j c_ij (|s_ij| − |s_ij − t^j|) (s_ij − t^j)/|s_ij − t^j|
//!   with s_ij − t^j the current spring vector (skin now − moved attachment) and |s_ij| its
//!   pre-operative length; F_def (eq. 22) is evaluated lumped at the value DOFs (k_i already
//!   carries the area); K a = F_init + F_def (eq. 23), forces recomputed at each increment.
//! - `equilibrium`: minimise E(a) = ½ (a − a_init)ᵀ K (a − a_init) + Σ ½ k_c k_i c (|x_i − x_b'| − L0)²
//!   over the three coordinate fields together, by Newton per increment. The spring Hessian
//!   k c [n nᵀ + (1 − L0/L)(I − n nᵀ)] couples x, y, z at a vertex. The exact tangent is used when
//!   it is positive definite; otherwise compressed springs' negative lateral part is dropped for
//!   that iteration (a positive definite modified Newton step). Each Newton system is solved by
//!   conjugate gradients (inexact Newton: to 1e-1 … 1e-3 of the residual, as far as the iteration
//!   needs) preconditioned by one single-precision factorisation of the decoupled
//!   K + diag(tr H₀ / 3) that serves x, y and z for the whole solve (the coupled tangent has 3× the
//!   unknowns and 3×3 blocks: ~25× the factorisation cost); if they stall, the coupled tangent is
//!   factored instead. Load increments start from a linear predictor. Converged when |r|/|r0| or
//!   |Δa|/|a − a_init| falls below the tolerance — for the last increment; the energy is
//!   conservative, so the equilibrium does not depend on the load path and earlier increments
//!   stop at 1e-2 (they only keep Newton close to the path). Not converging within the iteration
//!   limit is an error, never a silent result.

use crate::case::SolveModel;
use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::{FemMesh, System, multiply, rigid_dofs};
use crate::fem::element::Material;
use crate::fem::precond::Precond;
use crate::fem::preload::initial_dofs_fields;
use crate::mesh::{Mesh, norm, sub};
use crate::osteotomy::Plan;
use crate::springs::SpringSet;
use serde::Serialize;

/// Relative residual at which load increments before the last stop (equilibrium model).
const INTERMEDIATE_TOLERANCE: f64 = 1e-2;

pub struct Params {
    pub model: SolveModel,
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

#[derive(Clone, Debug, Serialize)]
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

/// A plan that moves bone through the skin is impossible, whatever the tissue: after the solve,
/// no main spring may point the other way than before (skin outside its bone attachment).
fn check_not_through_skin(
    skin: &Mesh,
    positions: &[[f64; 3]],
    springs: &SpringSet,
    plan: &Plan,
) -> Result<()> {
    let (moved, _) = plan.apply(&springs.attachments, 1.0);
    let mut flipped = 0;
    let mut worst: Option<(usize, f64)> = None;
    for s in springs
        .springs
        .iter()
        .filter(|s| s.kind == crate::springs::Kind::Main)
    {
        let pre = sub(skin.vertices[s.skin], springs.attachments[s.bone]);
        let post = sub(positions[s.skin], moved[s.bone]);
        let along = crate::mesh::dot(pre, post) / norm(pre).max(1e-12);
        if along <= 0.0 {
            flipped += 1;
            if worst.is_none_or(|(_, a)| along < a) {
                worst = Some((s.skin, along));
            }
        }
    }
    if let Some((v, along)) = worst {
        let p = skin.vertices[v];
        return Err(Error::impossible_plan(format!(
            "the bone moves through the skin at {flipped} skin vertices (worst at ({:.0}, {:.0}, {:.0}) LPS mm, {:.1} mm beyond it); check the osteotomy's translate (mm) and rotate_deg (degrees)",
            p[0], p[1], p[2], -along
        )));
    }
    Ok(())
}

/// Before solving: bone moved beyond the pre-operative skin by more than the tissue's own
/// thickness there cannot be followed by any skin (it would have to double in thickness while the
/// bone passes through it) — a plan in the wrong units or direction. Refused with the place.
fn check_plan_reach(skin: &Mesh, springs: &SpringSet, plan: &Plan) -> Result<()> {
    let (moved, _) = plan.apply(&springs.attachments, 1.0);
    let mut count = 0;
    let mut worst: Option<(usize, f64, f64)> = None;
    for s in springs
        .springs
        .iter()
        .filter(|s| s.kind == crate::springs::Kind::Main)
    {
        let pre = sub(skin.vertices[s.skin], springs.attachments[s.bone]);
        let l = norm(pre).max(1e-12);
        // Signed distance of the moved bone point in front of the pre-operative skin.
        let beyond = -crate::mesh::dot(pre, sub(skin.vertices[s.skin], moved[s.bone])) / l;
        if beyond > l {
            count += 1;
            if worst.is_none_or(|(_, b, _)| beyond > b) {
                worst = Some((s.skin, beyond, l));
            }
        }
    }
    if let Some((v, beyond, l)) = worst {
        let p = skin.vertices[v];
        return Err(Error::impossible_plan(format!(
            "the bone moves through the skin at {count} skin vertices (worst at ({:.0}, {:.0}, {:.0}) LPS mm: {beyond:.1} mm beyond the skin, where the soft tissue is {l:.1} mm thick); check the osteotomy's translate (mm), rotate_deg (degrees) and direction (LPS: −y is anterior)",
            p[0], p[1], p[2]
        )));
    }
    Ok(())
}

/// The skin the bone moves can reach: the movable vertices, their rigid neighbours (so every free
/// DOF keeps its whole fitting neighbourhood) and every triangle touching them. Triangles whose
/// twelve DOFs are all fixed add nothing to the equilibrium of the free ones, so solving on this
/// piece is exact; on the real CT it is a fraction of the face (MODEL.md §6, issue 6).
struct Restriction {
    skin: Mesh,
    springs: SpringSet,
    rigid: Vec<bool>,
    /// Sub-mesh vertex → full-mesh vertex (increasing, so edge orientation is preserved).
    to_full: Vec<usize>,
}

impl Restriction {
    fn new(skin: &Mesh, springs: &SpringSet, rigid: &[bool]) -> Option<Restriction> {
        let nv = skin.vertices.len();
        let mut near: Vec<bool> = rigid.iter().map(|r| !r).collect();
        for t in &skin.triangles {
            if t.iter().any(|&v| !rigid[v as usize]) {
                for &v in t {
                    near[v as usize] = true;
                }
            }
        }
        let keep: Vec<&[u32; 3]> = skin
            .triangles
            .iter()
            .filter(|t| t.iter().any(|&v| near[v as usize]))
            .collect();
        if keep.len() == skin.triangles.len() || keep.is_empty() {
            return None;
        }
        let mut used = vec![false; nv];
        for t in &keep {
            for &v in *t {
                used[v as usize] = true;
            }
        }
        let to_full: Vec<usize> = (0..nv).filter(|&v| used[v]).collect();
        let mut to_sub = vec![u32::MAX; nv];
        for (i, &v) in to_full.iter().enumerate() {
            to_sub[v] = i as u32;
        }
        let mut sub = Mesh::new(
            to_full.iter().map(|&v| skin.vertices[v]).collect(),
            keep.iter().map(|t| t.map(|v| to_sub[v as usize])).collect(),
        );
        sub.vertex_columns = skin
            .vertex_columns
            .iter()
            .map(|c| crate::mesh::Column {
                name: c.name.clone(),
                values: to_full.iter().map(|&v| c.values[v]).collect(),
            })
            .collect();
        let sub_springs = SpringSet {
            attachment_of: to_full.iter().map(|&v| springs.attachment_of[v]).collect(),
            attachments: springs.attachments.clone(),
            springs: springs
                .springs
                .iter()
                .filter(|s| used[s.skin])
                .map(|s| crate::springs::Spring {
                    skin: to_sub[s.skin] as usize,
                    ..s.clone()
                })
                .collect(),
            k: to_full.iter().map(|&v| springs.k[v]).collect(),
            misses: Vec::new(),
        };
        Some(Restriction {
            skin: sub,
            springs: sub_springs,
            rigid: to_full.iter().map(|&v| rigid[v]).collect(),
            to_full,
        })
    }
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
    check_plan_reach(skin, springs, plan)?;
    let Some(r) = p
        .restrict
        .then(|| Restriction::new(skin, springs, rigid))
        .flatten()
    else {
        return solve_mesh(skin, springs, plan, rigid, p, None);
    };
    // One preload, of the whole face: the piece takes its DOFs from it, so its fixed rim holds
    // exactly the values the whole-face field keeps there (fits at the piece's edge would see a
    // truncated neighbourhood) and the restricted solve equals the whole-mesh one.
    let (fem, mut a) = preloaded(skin)?;
    let edge_index: std::collections::HashMap<[u32; 2], usize> =
        fem.edges.iter().enumerate().map(|(i, e)| (*e, i)).collect();
    let (nv_sub, nv) = (r.skin.vertices.len(), skin.vertices.len());
    let piece = fem_mesh(&r.skin)?;
    let a_piece = [0, 1, 2].map(|c| {
        let mut x = vec![0.0; piece.ndof()];
        for (i, &g) in r.to_full.iter().enumerate() {
            x[3 * i..3 * i + 3].copy_from_slice(&a[c][3 * g..3 * g + 3]);
        }
        for (e, ed) in piece.edges.iter().enumerate() {
            let full = [
                r.to_full[ed[0] as usize] as u32,
                r.to_full[ed[1] as usize] as u32,
            ];
            if let Some(&fe) = edge_index.get(&full) {
                x[3 * nv_sub + e] = a[c][3 * nv + fe];
            }
        }
        x
    });
    let s = solve_mesh(
        &r.skin,
        &r.springs,
        plan,
        &r.rigid,
        p,
        Some((piece, a_piece)),
    )?;
    for c in 0..3 {
        // Only the free DOFs come from the piece: fixed ones keep the whole face's preload
        // (the piece's fits at its edge see a truncated neighbourhood).
        for (i, &g) in r.to_full.iter().enumerate() {
            if !r.rigid[i] {
                for k in 0..3 {
                    a[c][3 * g + k] = s.a[c][3 * i + k];
                }
            }
        }
        for (e, ed) in s.fem.edges.iter().enumerate() {
            if r.rigid[ed[0] as usize] && r.rigid[ed[1] as usize] {
                continue;
            }
            let full = [
                r.to_full[ed[0] as usize] as u32,
                r.to_full[ed[1] as usize] as u32,
            ];
            if let Some(&fe) = edge_index.get(&full) {
                a[c][3 * nv + fe] = s.a[c][3 * nv_sub + e];
            }
        }
    }
    let mut positions = skin.vertices.clone();
    for (i, &g) in r.to_full.iter().enumerate() {
        positions[g] = s.positions[i];
    }
    Ok(Solution {
        fem,
        a,
        positions,
        history: s.history,
        unknowns: s.unknowns,
        solved_vertices: s.solved_vertices,
    })
}

fn solve_mesh(
    skin: &Mesh,
    springs: &SpringSet,
    plan: &Plan,
    rigid: &[bool],
    p: &Params,
    pre: Option<(FemMesh, [Vec<f64>; 3])>,
) -> Result<Solution> {
    let (fem, a_init) = match pre {
        Some(x) => x,
        None => preloaded(skin)?,
    };
    let nd = fem.ndof();
    // Per-element (α, β): the defaults, or the last [[surface.region]] containing the triangle's
    // centroid (Koch §4.2).
    let mats: Vec<Material> = skin
        .triangles
        .iter()
        .map(|t| {
            let c = t
                .iter()
                .fold([0.0; 3], |a, &v| {
                    crate::mesh::add(a, skin.vertices[v as usize])
                })
                .map(|x| x / 3.0);
            let (al, be) = p
                .regions
                .iter()
                .rev()
                .find(|r| crate::osteotomy::inside(&r.shape, None, c))
                .map_or((p.alpha, p.beta), |r| (r.alpha, r.beta));
            Material::isotropic(al, be)
        })
        .collect();
    let material = |t: usize| mats[t];
    let fixed = rigid_dofs(&fem, rigid);
    let (k, _) = fem.assemble(&material, 0.0);
    let nv = skin.vertices.len();
    let weight: Vec<f64> = springs
        .springs
        .iter()
        .map(|s| p.k_c * springs.k[s.skin] * s.c)
        .collect();
    let value_dof = |i: usize| 3 * i;
    let mut a = a_init.clone();
    let mut history = Vec::new();
    let max_move = {
        let (moved, _) = plan.apply(&springs.attachments, 1.0);
        moved
            .iter()
            .zip(&springs.attachments)
            .map(|(p, q)| norm(sub(*p, *q)))
            .fold(0.0, f64::max)
    };
    let disp = |a: &[Vec<f64>; 3]| {
        (0..nv)
            .map(|i| norm([0, 1, 2].map(|c| a[c][value_dof(i)] - a_init[c][value_dof(i)])))
            .fold(0.0, f64::max)
    };
    match p.model {
        SolveModel::Koch1996 => {
            fem.check_constraints(&material, &fixed)?;
            let sys = System::new(nd, k.clone(), &fixed)?;
            let f_init: Vec<Vec<f64>> = a_init.iter().map(|x| multiply(&k, x)).collect();
            for step in 1..=p.steps {
                let (xb, _) = plan.apply(&springs.attachments, step as f64 / p.steps as f64);
                let mut f = f_init.clone();
                for (s, w) in springs.springs.iter().zip(&weight) {
                    let xs = [0, 1, 2].map(|c| a[c][value_dof(s.skin)]);
                    let d = sub(xs, xb[s.bone]);
                    let l = norm(d).max(1e-12);
                    for c in 0..3 {
                        f[c][value_dof(s.skin)] += w * (s.rest - l) * d[c] / l;
                    }
                }
                let sol = sys.solve(&f, &a_init);
                a = [sol[0].clone(), sol[1].clone(), sol[2].clone()];
                // eq. 23 with forces taken at the current shape is a fixed-point iteration: it
                // diverges when the springs are much stiffer than the skin. The skin cannot
                // follow the bone by more than the bone moves plus its own size; beyond that the
                // iteration has diverged.
                let bound = 2.0 * max_move + 10.0;
                let d = disp(&a);
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
                    max_displacement_mm: disp(&a),
                });
            }
            let positions: Vec<[f64; 3]> = (0..nv)
                .map(|i| [0, 1, 2].map(|c| a[c][value_dof(i)]))
                .collect();
            check_not_through_skin(skin, &positions, springs, plan)?;
            Ok(Solution {
                fem,
                a,
                positions,
                history,
                unknowns: 3 * (nd - fixed.iter().filter(|f| **f).count()),
                solved_vertices: nv,
            })
        }
        SolveModel::Equilibrium => {
            // Stacked unknowns: coordinate c of DOF g at c·nd + g.
            let fixed3: Vec<bool> = (0..3 * nd).map(|i| fixed[i % nd]).collect();
            let spring_vertices: Vec<usize> = {
                let mut v: Vec<usize> = springs.springs.iter().map(|s| s.skin).collect();
                v.sort_unstable();
                v.dedup();
                v
            };
            let build = |hess: &[[[f64; 3]; 3]]| -> Vec<(usize, usize, f64)> {
                let mut t = Vec::with_capacity(3 * k.len() + 6 * spring_vertices.len());
                for c in 0..3 {
                    t.extend(
                        k.iter()
                            .map(|&(r, col, val)| (c * nd + r, c * nd + col, val)),
                    );
                }
                for (n, &i) in spring_vertices.iter().enumerate() {
                    let g = value_dof(i);
                    for r in 0..3 {
                        for c in 0..=r {
                            t.push((r * nd + g, c * nd + g, hess[n][r][c]));
                        }
                    }
                }
                t
            };
            let slot: std::collections::HashMap<usize, usize> = spring_vertices
                .iter()
                .enumerate()
                .map(|(n, &i)| (i, n))
                .collect();
            // Gradient and modified Newton Hessian of the spring energy at the current a.
            let springs_at = |a: &[Vec<f64>; 3], xb: &[[f64; 3]]| {
                let mut grad = [vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]];
                let mut hess = vec![[[0.0; 3]; 3]; spring_vertices.len()];
                let mut clamped = vec![[[0.0; 3]; 3]; spring_vertices.len()];
                for (s, w) in springs.springs.iter().zip(&weight) {
                    let g = value_dof(s.skin);
                    let xs = [0, 1, 2].map(|c| a[c][g]);
                    let d = sub(xs, xb[s.bone]);
                    let l = norm(d).max(1e-12);
                    let n = d.map(|x| x / l);
                    let geo = 1.0 - s.rest / l;
                    let (h, hc) = (&mut hess[slot[&s.skin]], &mut clamped[slot[&s.skin]]);
                    for r in 0..3 {
                        grad[r][g] += w * (l - s.rest) * n[r];
                        for c in 0..3 {
                            let id = if r == c { 1.0 } else { 0.0 };
                            h[r][c] += w * (n[r] * n[c] + geo * (id - n[r] * n[c]));
                            hc[r][c] += w * (n[r] * n[c] + geo.max(0.0) * (id - n[r] * n[c]));
                        }
                    }
                }
                (grad, hess, clamped)
            };
            let (_, _, h0) = springs_at(&a, &springs.attachments);
            // Preconditioner for the Newton systems: the coordinate fields decoupled, each spring
            // vertex's 3×3 stiffness replaced by its mean eigenvalue (trace / 3) times I. One
            // scalar factorisation of K + D (single precision, src/fem/precond.rs) serves x, y
            // and z and the whole solve, where the coupled tangent (3× the unknowns, 3×3 blocks)
            // costs ~25× more to factor. (Splitting each vertex's field into its normal and
            // tangential parts, with the spring stiffness along the normal only, was tried: CG
            // needed 2.3× more iterations, since K does not commute with the per-vertex frames.)
            let precond = {
                let mut d = vec![0.0; nd];
                for (n, &i) in spring_vertices.iter().enumerate() {
                    d[value_dof(i)] = (h0[n][0][0] + h0[n][1][1] + h0[n][2][2]) / 3.0;
                }
                Precond::new(nd, &k, &d, &fixed).map_err(|e| {
                    Error::numerical(NumericalKind::Singular, format!(
                        "{e} (equilibrium model: no rigid node and too few springs to hold the skin)"
                    ))
                })?
            };
            let k_rows = Csr::symmetric(nd, &k);
            // The coupled tangent, factored only when conjugate gradients fail to converge.
            let mut direct: Option<System> = None;
            let zero = vec![0.0; 3 * nd];
            // Largest spring force scale, for the absolute floor of the residual test (computed
            // once, not per iteration).
            let scale = springs
                .springs
                .iter()
                .zip(&weight)
                .map(|(s, w)| w * s.rest)
                .fold(0.0, f64::max)
                .max(1e-300);
            let mut previous_step = a.clone();
            for step in 1..=p.steps {
                let (xb, _) = plan.apply(&springs.attachments, step as f64 / p.steps as f64);
                // Predictor: the load increments are equal, so start from the last state plus
                // the last increment's change (the response is close to linear per increment).
                let here = a.clone();
                if step > 1 {
                    for c in 0..3 {
                        for g in 0..nd {
                            a[c][g] += a[c][g] - previous_step[c][g];
                        }
                    }
                }
                previous_step = here;
                let mut res_hist = Vec::new();
                let mut r0 = None;
                let mut converged = false;
                let mut factorizations = 0;
                let mut cg_iterations = 0;
                let mut it = 0;
                while it < p.max_iterations {
                    it += 1;
                    let (grad, hess, clamped) = springs_at(&a, &xb);
                    let da: Vec<f64> = (0..3)
                        .flat_map(|c| a[c].iter().zip(&a_init[c]).map(|(x, y)| x - y))
                        .collect();
                    let mut r = k_rows.apply3(&da, nd);
                    for c in 0..3 {
                        for g in 0..nd {
                            r[c * nd + g] = if fixed[g] {
                                0.0
                            } else {
                                r[c * nd + g] + grad[c][g]
                            };
                        }
                    }
                    let rn = r.iter().map(|x| x * x).sum::<f64>().sqrt();
                    let r0v = *r0.get_or_insert(rn);
                    let previous = res_hist.last().copied();
                    res_hist.push(rn);
                    // The load increments only keep Newton near the equilibrium path: the energy
                    // is conservative, so the final equilibrium does not depend on the path and
                    // only the last increment needs the full tolerance.
                    let tol_here = if step < p.steps {
                        INTERMEDIATE_TOLERANCE.max(p.tolerance)
                    } else {
                        p.tolerance
                    };
                    let target = tol_here * r0v.max(1e-12 * scale);
                    if rn <= target {
                        converged = true;
                        break;
                    }
                    // Newton step: conjugate gradients on the tangent (exact when positive
                    // definite, else with compressed springs' negative lateral part dropped),
                    // preconditioned by the decoupled factor, to `cg_tol` of the residual (an
                    // inexact Newton step). If they stall, the coupled tangent is factored instead; that
                    // factor is kept while it contracts the residual 4× per iteration.
                    const RHO: f64 = 0.25;
                    let apply_p = |v: &[f64]| -> Vec<f64> { precond.apply(v) };
                    let apply_a = |h: &[[[f64; 3]; 3]], v: &[f64]| -> Vec<f64> {
                        let mut y = k_rows.apply3(v, nd);
                        for (n, &i) in spring_vertices.iter().enumerate() {
                            let g = value_dof(i);
                            for r in 0..3 {
                                for c in 0..3 {
                                    y[r * nd + g] += h[n][r][c] * v[c * nd + g];
                                }
                            }
                        }
                        for (i, f) in fixed3.iter().enumerate() {
                            if *f {
                                y[i] = 0.0;
                            }
                        }
                        y
                    };
                    let neg: Vec<f64> = r.iter().map(|x| -x).collect();
                    let stale = previous.is_some_and(|q| rn > RHO * q);
                    // Inexact Newton (Eisenstat & Walker 1996): CG reduces the residual only as
                    // far as this iteration needs to reach the target, between 1e-1 and 1e-3.
                    let cg_tol = (target / rn).clamp(1e-3, 1e-1);
                    let iterative = if direct.is_none() || stale {
                        pcg(|v| apply_a(&hess, v), apply_p, &neg, cg_tol, 400)
                            .or_else(|| pcg(|v| apply_a(&clamped, v), apply_p, &neg, cg_tol, 400))
                    } else {
                        None
                    };
                    let d = match iterative {
                        Some((d, n)) => {
                            cg_iterations += n;
                            d
                        }
                        None => {
                            let refactor = direct.is_none() || stale;
                            let sys = match direct.as_mut() {
                                Some(s) => s,
                                None => direct.insert(System::new(3 * nd, build(&h0), &fixed3)?),
                            };
                            if refactor {
                                if sys.refactor(build(&hess)).is_err() {
                                    sys.refactor(build(&clamped))?;
                                }
                                factorizations += 1;
                            }
                            sys.solve(&[neg], std::slice::from_ref(&zero)).remove(0)
                        }
                    };
                    for c in 0..3 {
                        for g in 0..nd {
                            a[c][g] += d[c * nd + g];
                        }
                    }
                    let dn = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                    let un = (0..3)
                        .flat_map(|c| {
                            a[c].iter()
                                .zip(&a_init[c])
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
                    if dn <= tol_here * un.max(1e-12) {
                        converged = true;
                        res_hist.push(rn);
                        break;
                    }
                }
                if !converged {
                    return Err(Error::numerical(
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
                    ));
                }
                history.push(StepRecord {
                    step,
                    iterations: it,
                    residual_history: res_hist,
                    factorizations,
                    cg_iterations,
                    max_displacement_mm: disp(&a),
                });
            }
            let unknowns = 3 * nd - fixed3.iter().filter(|f| **f).count();
            let positions: Vec<[f64; 3]> = (0..nv)
                .map(|i| [0, 1, 2].map(|c| a[c][value_dof(i)]))
                .collect();
            check_not_through_skin(skin, &positions, springs, plan)?;
            Ok(Solution {
                fem,
                a: a.clone(),
                positions,
                history,
                unknowns,
                solved_vertices: nv,
            })
        }
    }
}

/// Preconditioned conjugate gradients for A x = b (A symmetric positive definite, given as a
/// product), from x = 0 to |r| ≤ tol |b|. Returns the solution and the iterations, or None on
/// negative curvature (A not positive definite), a non-finite value or no convergence in
/// `max_it` iterations.
fn pcg(
    a: impl Fn(&[f64]) -> Vec<f64>,
    p: impl Fn(&[f64]) -> Vec<f64>,
    b: &[f64],
    tol: f64,
    max_it: usize,
) -> Option<(Vec<f64>, usize)> {
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x * y).sum::<f64>();
    let bn = dot(b, b).sqrt();
    let mut x = vec![0.0; b.len()];
    if bn == 0.0 {
        return Some((x, 0));
    }
    let mut r = b.to_vec();
    let mut z = p(&r);
    let mut d = z.clone();
    let mut rz = dot(&r, &z);
    for it in 1..=max_it {
        let ad = a(&d);
        let curv = dot(&d, &ad);
        if !(curv > 0.0) {
            return None;
        }
        let alpha = rz / curv;
        for i in 0..x.len() {
            x[i] += alpha * d[i];
            r[i] -= alpha * ad[i];
        }
        let rn = dot(&r, &r).sqrt();
        if !rn.is_finite() {
            return None;
        }
        if rn <= tol * bn {
            return Some((x, it));
        }
        z = p(&r);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..d.len() {
            d[i] = z[i] + beta * d[i];
        }
    }
    None
}

/// A symmetric matrix (given by lower-triangle triplets, duplicates summed) stored by rows, for
/// the products inside conjugate gradients: one pass applies it to x, y and z together, rows in
/// parallel.
struct Csr {
    start: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f64>,
}

impl Csr {
    fn symmetric(n: usize, lower: &[(usize, usize, f64)]) -> Csr {
        let mut t: Vec<(u32, u32, f64)> = Vec::with_capacity(2 * lower.len());
        for &(r, c, v) in lower {
            t.push((r as u32, c as u32, v));
            if r != c {
                t.push((c as u32, r as u32, v));
            }
        }
        t.sort_unstable_by_key(|e| (e.0, e.1));
        let mut start = vec![0usize; n + 1];
        let (mut cols, mut vals): (Vec<u32>, Vec<f64>) = (Vec::new(), Vec::new());
        let mut last: Option<(u32, u32)> = None;
        for (r, c, v) in t {
            if last == Some((r, c)) {
                if let Some(x) = vals.last_mut() {
                    *x += v;
                }
                continue;
            }
            last = Some((r, c));
            cols.push(c);
            vals.push(v);
            start[r as usize + 1] = cols.len();
        }
        for i in 1..=n {
            start[i] = start[i].max(start[i - 1]);
        }
        Csr { start, cols, vals }
    }

    /// y = (I₃ ⊗ K) v for v stacked as three blocks of n.
    fn apply3(&self, v: &[f64], n: usize) -> Vec<f64> {
        use rayon::prelude::*;
        let rows: Vec<[f64; 3]> = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .map(|r| {
                let mut y = [0.0; 3];
                for j in self.start[r]..self.start[r + 1] {
                    let (c, w) = (self.cols[j] as usize, self.vals[j]);
                    y[0] += w * v[c];
                    y[1] += w * v[n + c];
                    y[2] += w * v[2 * n + c];
                }
                y
            })
            .collect();
        let mut out = vec![0.0; 3 * n];
        for (r, y) in rows.iter().enumerate() {
            out[r] = y[0];
            out[n + r] = y[1];
            out[2 * n + r] = y[2];
        }
        out
    }
}

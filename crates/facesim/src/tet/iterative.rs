//! The 10-node model's iterative solve in the nodes' own frames: conjugate gradients with the
//! two-level p-multigrid preconditioner of fem/pmultigrid.rs, for a model whose Cholesky factor
//! would not fit (`Constrained::quadratic`).
//!
//! Each node's DOFs are its displacement's components along its frame (tet/holds.rs: sliding
//! nodes rotated, held components prescribed). The prolongation from the corners' linear field
//! follows them: a corner keeps its free components; an edge midpoint m of corners a, b takes
//! ½ (R_a u_a + R_b u_b) in its own frame, u′_m = ½ R_mᵀ (R_a u_a + R_b u_b), with the held
//! components of a, b (prescribed, no correction) and of m (not unknowns) dropped. With no
//! holds this is the exact embedding of the linear field in the quadratic one.

use crate::error::Result;
use crate::fem::block_sparse::{Block, SymmetricBlocks, congruence, interleave, transposed};
use crate::fem::pmultigrid::{Parents, Transfer, TwoLevel, mask, product};
use std::sync::Mutex;

/// Right-hand sides solved together at most. Each batch shares every pass over the operator and
/// the coarse factor; a batch's work vectors (some fifteen alive at once, 25 MB each for four
/// on the real CT's 0.79 M unknowns) stay well below the operator's memory. Measured on the
/// real CT's 10-node plan basis (12 right-hand sides, docs/lab/performance.md "The 10-node
/// element"): twelve at once 2.39 GB peak heap in that stage, four at a time 1.14 GB, for the
/// same CPU time within the shared machine's spread.
const BATCH: usize = 4;

/// A node's frame as the solve needs it: its axes (rows: e₀, e₁, e₂ in the global frame; None:
/// the global axes) and how many leading local components are held.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct NodeFrame {
    pub(crate) axes: Option<[[f64; 3]; 3]>,
    pub(crate) held: usize,
}

impl NodeFrame {
    /// R as a block (columns e₀, e₁, e₂): global = R · local.
    fn rotation(&self) -> Block {
        match self.axes {
            None => mask([true; 3]),
            Some(e) => std::array::from_fn(|i| e[i % 3][i / 3]),
        }
    }

    fn free(&self) -> [bool; 3] {
        std::array::from_fn(|c| c >= self.held)
    }
}

/// The last solve's conjugate-gradient iterations and final relative residual.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterativeSolve {
    pub iterations: usize,
    pub relative_residual: f64,
}

/// A 10-node stiffness in its nodes' frames with the two-level preconditioner.
pub(crate) struct Iterative {
    corners: usize,
    edges: Vec<[u32; 2]>,
    /// None only while the preconditioner is rebuilt for new holds.
    level: Option<TwoLevel>,
    last: Mutex<Option<IterativeSolve>>,
    /// The last single solve's displacement (local frames): the next single solve's start
    /// (`TwoLevel::solve_many`'s guess), as the rounds re-solve after freeing a few nodes.
    previous: Mutex<Option<Vec<f64>>>,
}

/// The prolongation for `frames` (corners first, then the midpoint of `edges[e]` at node
/// `corners + e`), and the unknowns of the fine level.
pub(crate) fn transfer(
    frames: &[NodeFrame],
    corners: usize,
    edges: &[[u32; 2]],
) -> (Transfer, Vec<bool>) {
    let parents = frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let keep = mask(f.free());
            if i < corners {
                return Parents::one(i as u32, keep);
            }
            let [a, b] = edges[i - corners];
            // ½ mask_m R_mᵀ R_x mask_x for each end x.
            let to_m = transposed(&f.rotation());
            let from = |x: u32| -> Block {
                let fx = &frames[x as usize];
                let s = product(
                    &keep,
                    &product(&to_m, &product(&fx.rotation(), &mask(fx.free()))),
                );
                s.map(|v| 0.5 * v)
            };
            Parents::two(a, from(a), b, from(b))
        })
        .collect();
    let coarse_free = frames[..corners].iter().flat_map(|f| f.free()).collect();
    let free = frames.iter().flat_map(|f| f.free()).collect();
    (
        Transfer {
            parents,
            coarse_free,
        },
        free,
    )
}

impl Iterative {
    /// Set up for the global-frame stiffness `k` (lower triangle, 3 DOFs per node) held as
    /// `frames` say.
    pub(crate) fn new(
        k: &[(usize, usize, f64)],
        frames: &[NodeFrame],
        corners: usize,
        edges: &[[u32; 2]],
    ) -> Result<Iterative> {
        let mut a = SymmetricBlocks::from_lower(frames.len(), k);
        // Into the nodes' frames: block (i, j) → R_iᵀ K_ij R_j.
        a.map_blocks(|i, j, b| {
            if frames[i].axes.is_some() || frames[j].axes.is_some() {
                *b = congruence(&frames[i].rotation(), b, &frames[j].rotation());
            }
        });
        let (t, free) = transfer(frames, corners, edges);
        let level = TwoLevel::new(a, free, t, || {
            edges.iter().map(|e| (e[1] as usize, e[0] as usize))
        })?;
        Ok(Iterative {
            corners,
            edges: edges.to_vec(),
            level: Some(level),
            last: Mutex::new(None),
            previous: Mutex::new(None),
        })
    }

    /// Other holds on the same frames' axes (nodes freed, or held again): the operator kept,
    /// the preconditioner's coarse level too while no DOF it was made on is held
    /// (`TwoLevel::with_holds`).
    pub(crate) fn set_holds(&mut self, frames: &[NodeFrame]) -> Result<()> {
        let level = self.level.take().ok_or_else(|| {
            crate::error::Error::config("the iterative solve lost its preconditioner")
        })?;
        let free = frames.iter().flat_map(|f| f.free()).collect();
        let (corners, edges) = (self.corners, &self.edges);
        self.level = Some(level.with_holds(
            free,
            || transfer(frames, corners, edges).0,
            || edges.iter().map(|e| (e[1] as usize, e[0] as usize)),
        )?);
        Ok(())
    }

    fn level(&self) -> Result<&TwoLevel> {
        self.level.as_ref().ok_or_else(|| {
            crate::error::Error::config("the iterative solve lost its preconditioner")
        })
    }

    /// K u = f in the local frames for each (loads, held values) pair: `rhs` the loads (read
    /// on the free DOFs), `prescribed` the held DOFs' values (zero on the free ones); u equals
    /// the prescribed values on the held DOFs; to a relative residual of `tolerance`. The pairs
    /// are solved together
    /// (`TwoLevel::solve_many`: one pass over the operator per iteration for all of them).
    pub(crate) fn solve_many(
        &self,
        rhs: &[Vec<f64>],
        prescribed: &[Vec<f64>],
        tolerance: f64,
    ) -> Result<Vec<Vec<f64>>> {
        if rhs.len() > BATCH {
            let mut out = Vec::with_capacity(rhs.len());
            for (f, p) in rhs.chunks(BATCH).zip(prescribed.chunks(BATCH)) {
                out.extend(self.solve_many(f, p, tolerance)?);
            }
            return Ok(out);
        }
        let level = self.level()?;
        let k = rhs.len();
        let held = level.full_product_many(&interleave(prescribed), k);
        let bs: Vec<Vec<f64>> = rhs
            .iter()
            .enumerate()
            .map(|(v, f)| {
                f.iter()
                    .zip(held.iter().skip(v).step_by(k))
                    .map(|(f, h)| f - h)
                    .collect()
            })
            .collect();
        // A single solve starts from the previous one's unknowns (the rounds' re-solves); a
        // batch (the plan basis's columns, other held values) from zero.
        let previous = self.previous.lock().ok().and_then(|p| p.clone());
        let guess: Option<Vec<Vec<f64>>> = match (k, previous) {
            (1, Some(u)) if u.len() == prescribed[0].len() => Some(vec![u]),
            _ => None,
        };
        let solved = level.solve_many(&bs, guess.as_deref(), tolerance)?;
        if let Ok(mut last) = self.last.lock() {
            // The batch's slowest solve.
            *last = solved
                .iter()
                .map(|s| IterativeSolve {
                    iterations: s.iterations,
                    relative_residual: s.relative_residual,
                })
                .reduce(|a, b| IterativeSolve {
                    iterations: a.iterations.max(b.iterations),
                    relative_residual: a.relative_residual.max(b.relative_residual),
                });
        }
        let u: Vec<Vec<f64>> = solved
            .into_iter()
            .zip(prescribed)
            .map(|(s, p)| p.iter().zip(&s.x).map(|(p, x)| p + x).collect())
            .collect();
        if k == 1
            && let Ok(mut previous) = self.previous.lock()
        {
            *previous = Some(u[0].clone());
        }
        Ok(u)
    }

    /// The last solve's iterations and residual.
    pub(crate) fn last_solve(&self) -> Option<IterativeSolve> {
        self.last.lock().ok().and_then(|l| *l)
    }

    /// Nonzeros of the coarse (linear) level's factor.
    pub(crate) fn factor_nnz(&self) -> usize {
        self.level.as_ref().map_or(0, TwoLevel::coarse_factor_nnz)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tet::holds::{Constrained, Hold, SolverUsed, to_local};
    use crate::tet::quadratic::{Rule, Tet10Mesh};
    use crate::tet::{TetMesh, TissueElastic};

    /// n³ sheared cubes (6 tetrahedra each), two tissues, as a 10-node mesh.
    fn block(n: usize) -> Tet10Mesh {
        let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
        let mut nodes = Vec::new();
        for k in 0..=n {
            for j in 0..=n {
                for i in 0..=n {
                    let (x, y, z) = (i as f64, j as f64, k as f64);
                    nodes.push([x + 0.1 * y + 0.05 * z, y, z]);
                }
            }
        }
        let mut tets = Vec::new();
        let mut material = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    for mut t in crate::mesh::kuhn_cell([i, j, k], id) {
                        if crate::tet::gradients(t.map(|v| nodes[v as usize])).is_none() {
                            t.swap(2, 3);
                        }
                        tets.push(t);
                        material.push(TissueElastic {
                            youngs_kpa: if k < n / 2 { 3.0 } else { 30.0 },
                            poisson: if i < n / 2 { 0.45 } else { 0.3 },
                        });
                    }
                }
            }
        }
        Tet10Mesh::from_linear(
            &TetMesh {
                nodes,
                tets,
                material,
            },
            Rule::Full,
        )
    }

    /// The bottom (z = 0) held on a rigid move, the side y = 0 sliding on normals that turn
    /// from node to node (so a midpoint's frame is neither of its corners'), its edge on x = 0
    /// on a rail, the rest free.
    fn holds(m: &Tet10Mesh) -> Vec<Hold> {
        m.nodes
            .iter()
            .map(|p| {
                if p[2] == 0.0 {
                    Hold::Fixed([0.3 - 0.05 * p[1], 0.05 * p[0], 0.2])
                } else if p[1] == 0.0 && p[0] - 0.05 * p[2] <= 1e-9 {
                    Hold::Rail {
                        direction: [0.1, 0.2, 1.0],
                        offset: [0.0, 0.02, 0.0],
                    }
                } else if p[1] == 0.0 {
                    Hold::Slide {
                        normal: [0.3 * (p[0] + p[2]).sin(), 1.0, 0.2 * p[2]],
                        value: 0.01 * p[0],
                    }
                } else {
                    Hold::Free
                }
            })
            .collect()
    }

    fn frames_of(h: &[Hold]) -> Vec<NodeFrame> {
        h.iter()
            .enumerate()
            .map(|(n, h)| {
                let f = h.frame(n).unwrap();
                NodeFrame {
                    axes: f.axes,
                    held: f.held,
                }
            })
            .collect()
    }

    /// max |a − b| / max |b| over the nodes.
    fn relative_difference(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
        let d = a
            .iter()
            .zip(b)
            .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()))
            .fold(0.0, f64::max);
        let s = b.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
        d / s
    }

    /// PCG with the p-multigrid preconditioner gives the direct factor's displacement to 1e-8
    /// (held values and a nodal load; then sliding nodes freed, then held again: the rounds'
    /// re-solves).
    #[test]
    fn pmultigrid_solve_equals_the_direct_factor() {
        let m = block(4);
        let k = m.assemble().unwrap();
        let h = holds(&m);
        let mut direct = Constrained::new(&k, &h, m.nodes.len()).unwrap();
        let mut pcg = Constrained::iterative(&k, &h, m.corners, &m.edges).unwrap();
        assert_eq!(direct.solver_used(), SolverUsed::Direct);
        let mut load = vec![0.0; m.ndof()];
        let top = m.nodes.iter().position(|p| p[2] == 4.0).unwrap();
        load[3 * top] = 0.7;
        load[3 * top + 2] = -0.4;
        let zero = vec![0.0; m.ndof()];
        let sliding: Vec<usize> = (0..m.nodes.len())
            .filter(|n| matches!(h[*n], Hold::Slide { .. }))
            .step_by(3)
            .collect();
        assert!(sliding.len() > 4);
        let mut h_now = h.clone();
        for round in 0..3 {
            if round == 1 {
                direct.free_nodes(&sliding).unwrap();
                pcg.free_nodes(&sliding).unwrap();
                sliding.iter().for_each(|n| h_now[*n] = Hold::Free);
            }
            if round == 2 {
                let rests: Vec<(usize, Hold)> = sliding.iter().map(|n| (*n, h[*n])).collect();
                direct.rest_nodes(&rests).unwrap();
                pcg.rest_nodes(&rests).unwrap();
                h_now = h.clone();
            }
            let cases: [(&[Hold], &[f64]); 2] = [(&h_now, &zero), (&h_now, &load)];
            let a = direct.solve(&cases).unwrap();
            let b = pcg.solve(&cases).unwrap();
            for (c, (x, y)) in b.iter().zip(&a).enumerate() {
                let d = relative_difference(x, y);
                assert!(d < 1e-8, "round {round}, case {c}: {d:e}");
            }
            let SolverUsed::PcgPmultigrid(Some(s)) = pcg.solver_used() else {
                panic!("the iterative solve reports no iterations");
            };
            assert!(s.relative_residual <= crate::fem::pmultigrid::TOLERANCE);
            assert!(s.iterations > 0);
        }
    }

    /// Several cases solved together (the plan basis's batch: lockstep conjugate gradients,
    /// one product per iteration for all) give each the direct factor's displacement to 1e-8,
    /// cases converging at different iterations included (a zero one, one held values only,
    /// loads of different scales), with nodes freed.
    #[test]
    fn batched_pmultigrid_solves_equal_the_direct_factor() {
        let m = block(4);
        let k = m.assemble().unwrap();
        let h = holds(&m);
        let mut direct = Constrained::new(&k, &h, m.nodes.len()).unwrap();
        let mut pcg = Constrained::iterative(&k, &h, m.corners, &m.edges).unwrap();
        let still: Vec<Hold> = h
            .iter()
            .map(|x| match x {
                Hold::Fixed(_) => Hold::Fixed([0.0; 3]),
                Hold::Slide { normal, .. } => Hold::Slide {
                    normal: *normal,
                    value: 0.0,
                },
                Hold::Rail { direction, .. } => Hold::Rail {
                    direction: *direction,
                    offset: [0.0; 3],
                },
                Hold::Free => Hold::Free,
            })
            .collect();
        let zero = vec![0.0; m.ndof()];
        let loads: Vec<Vec<f64>> = (0..3)
            .map(|c| {
                (0..m.ndof())
                    .map(|i| 10f64.powi(c as i32) * ((i * (c + 3)) as f64 * 0.37).sin())
                    .collect()
            })
            .collect();
        let sliding: Vec<usize> = (0..m.nodes.len())
            .filter(|n| matches!(h[*n], Hold::Slide { .. }))
            .step_by(2)
            .collect();
        for round in 0..2 {
            let mut h_now = h.clone();
            let mut still_now = still.clone();
            if round == 1 {
                direct.free_nodes(&sliding).unwrap();
                pcg.free_nodes(&sliding).unwrap();
                for n in &sliding {
                    h_now[*n] = Hold::Free;
                    still_now[*n] = Hold::Free;
                }
            }
            let cases: Vec<(&[Hold], &[f64])> = vec![
                (&h_now, &zero),
                (&still_now, &zero),
                (&still_now, &loads[0]),
                (&h_now, &loads[1]),
                (&still_now, &loads[2]),
            ];
            let a = direct.solve(&cases).unwrap();
            let b = pcg.solve(&cases).unwrap();
            for (c, (x, y)) in b.iter().zip(&a).enumerate() {
                if y.iter().flatten().all(|v| *v == 0.0) {
                    assert!(
                        x.iter().flatten().all(|v| *v == 0.0),
                        "round {round}, case {c}"
                    );
                    continue;
                }
                let d = relative_difference(x, y);
                assert!(d < 1e-8, "round {round}, case {c}: {d:e}");
            }
            // Each case alone gives the same displacement as in the batch.
            for (c, case) in cases.iter().enumerate() {
                let alone = pcg.solve(&[*case]).unwrap().remove(0);
                let s = alone.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
                let d = alone
                    .iter()
                    .flatten()
                    .zip(b[c].iter().flatten())
                    .map(|(p, q)| (p - q).abs())
                    .fold(0.0, f64::max);
                assert!(d <= 1e-9 * s, "round {round}, case {c}: {d:e}");
            }
        }
    }

    /// A re-solve after freeing a few nodes starts from the previous solve (the rounds): it
    /// gives the direct factor's displacement to 1e-8 in fewer iterations than from zero.
    #[test]
    fn warm_started_resolve_equals_the_direct_factor() {
        let m = block(4);
        let k = m.assemble().unwrap();
        let h = holds(&m);
        let mut direct = Constrained::new(&k, &h, m.nodes.len()).unwrap();
        let mut warm = Constrained::iterative(&k, &h, m.corners, &m.edges).unwrap();
        let mut load = vec![0.0; m.ndof()];
        let top = m.nodes.iter().position(|p| p[2] == 4.0).unwrap();
        load[3 * top + 1] = 0.5;
        warm.solve(&[(&h, &load)]).unwrap();
        let freed: Vec<usize> = (0..m.nodes.len())
            .filter(|n| matches!(h[*n], Hold::Slide { .. }))
            .take(2)
            .collect();
        let mut h_now = h.clone();
        freed.iter().for_each(|n| h_now[*n] = Hold::Free);
        direct.free_nodes(&freed).unwrap();
        warm.free_nodes(&freed).unwrap();
        let cold = Constrained::iterative(&k, &h_now, m.corners, &m.edges).unwrap();
        let want = direct.solve(&[(&h_now, &load)]).unwrap().remove(0);
        let got = warm.solve(&[(&h_now, &load)]).unwrap().remove(0);
        let d = relative_difference(&got, &want);
        assert!(d < 1e-8, "{d:e}");
        let from_zero = cold.solve(&[(&h_now, &load)]).unwrap().remove(0);
        assert!(relative_difference(&from_zero, &want) < 1e-8);
        let its = |c: &Constrained| match c.solver_used() {
            SolverUsed::PcgPmultigrid(Some(s)) => s.iterations,
            _ => panic!("no iterative solve"),
        };
        assert!(its(&warm) < its(&cold), "{} vs {}", its(&warm), its(&cold));
    }

    /// A linear field on the corners prolongs to the same linear field at the midpoints, each
    /// node's DOFs in its own (rotated) frame: P is the exact embedding of P1 in P2.
    #[test]
    fn prolongation_embeds_linear_fields_exactly() {
        let m = block(2);
        // Every node in a frame of its own, nothing held.
        let frames: Vec<NodeFrame> = frames_of(
            &m.nodes
                .iter()
                .map(|p| Hold::Slide {
                    normal: [p[0].sin() + 0.1, 1.0 - p[2], 0.3 * p[1] + 0.2],
                    value: 0.0,
                })
                .collect::<Vec<_>>(),
        )
        .into_iter()
        .map(|f| NodeFrame { held: 0, ..f })
        .collect();
        let (t, free) = transfer(&frames, m.corners, &m.edges);
        assert!(free.iter().all(|f| *f));
        let u = |p: [f64; 3]| {
            [
                0.3 * p[0] - 0.2 * p[1] + 0.1 * p[2] + 1.0,
                0.5 * p[1] + 0.7 * p[2] - 0.4,
                -0.6 * p[0] + 0.2 * p[2] + 0.05,
            ]
        };
        let local = |n: usize| to_local(&frames[n].axes, u(m.nodes[n]));
        let coarse: Vec<f64> = (0..m.corners).flat_map(local).collect();
        let fine = t.prolong(&coarse);
        for n in 0..m.nodes.len() {
            let want = local(n);
            for c in 0..3 {
                assert!(
                    (fine[3 * n + c] - want[c]).abs() < 1e-13,
                    "node {n}: {:?} vs {want:?}",
                    &fine[3 * n..3 * n + 3]
                );
            }
        }
    }

    /// Without holds the Galerkin operator Pᵀ K₂ P is the 4-node stiffness on the corners
    /// (the 10-node rule integrates the linear field's constant strain exactly).
    #[test]
    fn galerkin_operator_is_the_linear_stiffness() {
        let m = block(3);
        let linear = TetMesh {
            nodes: m.nodes[..m.corners].to_vec(),
            tets: m.tets.iter().map(|t| [t[0], t[1], t[2], t[3]]).collect(),
            material: m.material.clone(),
        };
        let free = vec![
            NodeFrame {
                axes: None,
                held: 0
            };
            m.nodes.len()
        ];
        let (t, _) = transfer(&free, m.corners, &m.edges);
        let fine = SymmetricBlocks::from_lower(m.nodes.len(), &m.assemble().unwrap());
        let coarse = t
            .galerkin(&fine, || {
                m.edges.iter().map(|e| (e[1] as usize, e[0] as usize))
            })
            .unwrap();
        let n = 3 * m.corners;
        let mut got = vec![0.0; n * n];
        for (r, c, v) in coarse.lower_triplets() {
            got[r * n + c] += v;
        }
        let mut want = vec![0.0; n * n];
        for (r, c, v) in linear.assemble().unwrap() {
            want[r * n + c] += v;
        }
        let scale = want.iter().map(|v| v.abs()).fold(0.0, f64::max);
        for e in 0..n * n {
            assert!(
                (got[e] - want[e]).abs() < 1e-12 * scale,
                "({}, {}): {} vs {}",
                e / n,
                e % n,
                got[e],
                want[e]
            );
        }
    }
}

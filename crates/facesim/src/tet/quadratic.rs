//! Quadratic (10-node) tetrahedra: the cure for volumetric locking of nearly incompressible
//! tissue (ν → 0.5), where linear tetrahedra cannot represent divergence-free fields and stiffen.
//!
//! Straight-sided elements: the corners of a [`TetMesh`] plus one node at each edge's midpoint,
//! numbered as CalculiX's C3D10 (corners 0–3, then the midpoints of edges 0–1, 1–2, 2–0, 0–3,
//! 1–3, 2–3), so an independent engine can be run on the same mesh. With barycentric coordinates
//! Lᵢ and the linear tetrahedron's gradients gᵢ = ∇Lᵢ, the shape functions are Lᵢ(2Lᵢ − 1) at
//! corners and 4 Lᵢ Lⱼ at edges, with gradients (4Lᵢ − 1) gᵢ and 4 (Lᵢ gⱼ + Lⱼ gᵢ).
//!
//! Two integration rules for K = ∫ (λ div v div u + 2 μ ε(v) : ε(u)) dV:
//! - [`Rule::Full`]: the 4-point Gauss rule (degree 2, exact for straight-sided elements), as
//!   CalculiX's C3D10;
//! - [`Rule::MeanDilatation`]: the μ term as in `Full`, the λ term at the centroid. div u of a
//!   quadratic field is linear, so its centroid value is its element mean, and the λ term is that
//!   of the mixed P2–P0 element (displacement quadratic, pressure constant per element,
//!   p = λ mean(div u)) with the pressure condensed — the mean-dilatation idea of Nagtegaal,
//!   Parks & Rice (1974) and Hughes' B̄ (1980). At most one constraint per element instead of
//!   four: crates/facesim/tests/library/tet_physics.rs measures that it does not lock (Lamé's sphere at ν = 0.4999).

use super::holds::{Constrained, Hold, Loads};
use super::{TetMesh, TissueElastic, gradients};
use crate::error::{Error, NumericalKind, Result};
use std::collections::HashMap;

/// Local corner pairs of the six edges, in C3D10 order.
pub(crate) const EDGES: [[usize; 2]; 6] = [[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]];

/// How the element stiffness is integrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rule {
    Full,
    MeanDilatation,
}

/// A 10-node tetrahedral mesh: `nodes` holds the linear mesh's corners (same indices) followed by
/// one midpoint per edge (node `corners + e` for edge `e` of `edges`).
pub struct Tet10Mesh {
    pub nodes: Vec<[f64; 3]>,
    /// Number of corner nodes (the linear mesh's nodes).
    pub corners: usize,
    /// Each edge as (low, high) corner indices; its midpoint is node `corners + e`.
    pub edges: Vec<[u32; 2]>,
    pub tets: Vec<[u32; 10]>,
    pub material: Vec<TissueElastic>,
    pub rule: Rule,
    edge_index: HashMap<(u32, u32), u32>,
}

/// The gradients of the ten shape functions at barycentric point `l` (linear gradients `g`).
fn shape_gradients(l: [f64; 4], g: &[[f64; 3]; 4]) -> [[f64; 3]; 10] {
    let mut out = [[0.0; 3]; 10];
    for i in 0..4 {
        out[i] = g[i].map(|c| (4.0 * l[i] - 1.0) * c);
    }
    for (e, [i, j]) in EDGES.iter().enumerate() {
        out[4 + e] = std::array::from_fn(|c| 4.0 * (l[*i] * g[*j][c] + l[*j] * g[*i][c]));
    }
    out
}

/// Adds w (λ_w ∇N_a ∇N_bᵀ + μ_w ∇N_b ∇N_aᵀ + μ_w (∇N_a · ∇N_b) I) to k for all node pairs.
fn add_point(k: &mut [[f64; 30]; 30], d: &[[f64; 3]; 10], lambda: f64, mu: f64) {
    for a in 0..10 {
        for b in 0..10 {
            let dot: f64 = (0..3).map(|c| d[a][c] * d[b][c]).sum();
            for i in 0..3 {
                for j in 0..3 {
                    let id = if i == j { mu * dot } else { 0.0 };
                    k[3 * a + i][3 * b + j] +=
                        lambda * d[a][i] * d[b][j] + mu * d[a][j] * d[b][i] + id;
                }
            }
        }
    }
}

/// The 30×30 element stiffness of a straight-sided 10-node tetrahedron with corners `x`.
pub(crate) fn element_stiffness(
    x: [[f64; 3]; 4],
    m: TissueElastic,
    rule: Rule,
) -> Option<[[f64; 30]; 30]> {
    let (v, g) = gradients(x)?;
    let (lambda, mu) = m.lame();
    // The degree-2 rule: weights V/4 at the permutations of (a, b, b, b).
    let (a, b) = (0.585_410_196_624_968_5, 0.138_196_601_125_010_5);
    let mut k = [[0.0; 30]; 30];
    let w = v / 4.0;
    let volumetric = if rule == Rule::Full { w * lambda } else { 0.0 };
    for q in 0..4 {
        let l: [f64; 4] = std::array::from_fn(|i| if i == q { a } else { b });
        add_point(&mut k, &shape_gradients(l, &g), volumetric, w * mu);
    }
    if rule == Rule::MeanDilatation {
        let d = shape_gradients([0.25; 4], &g);
        add_point(&mut k, &d, v * lambda, 0.0);
    }
    Some(k)
}

impl Tet10Mesh {
    /// Which nodes are solved, from which corners are: a midpoint is when either end is.
    pub(crate) fn solved_nodes(&self, corner_solved: &[bool]) -> Vec<bool> {
        let mut solved = corner_solved.to_vec();
        solved.extend(
            self.edges
                .iter()
                .map(|[a, b]| corner_solved[*a as usize] || corner_solved[*b as usize]),
        );
        solved
    }

    /// Adds a midpoint node on every edge of `m`; corner nodes keep their indices.
    pub fn from_linear(m: &TetMesh, rule: Rule) -> Tet10Mesh {
        let corners = m.nodes.len();
        let mut nodes = m.nodes.clone();
        let mut edges = Vec::new();
        let mut edge_index = HashMap::new();
        let tets = m
            .tets
            .iter()
            .map(|t| {
                let mut t10 = [0u32; 10];
                t10[..4].copy_from_slice(t);
                for (e, [i, j]) in EDGES.iter().enumerate() {
                    let (p, q) = (t[*i].min(t[*j]), t[*i].max(t[*j]));
                    let id = *edge_index.entry((p, q)).or_insert_with(|| {
                        edges.push([p, q]);
                        let (x, y) = (m.nodes[p as usize], m.nodes[q as usize]);
                        nodes.push(std::array::from_fn(|c| 0.5 * (x[c] + y[c])));
                        (edges.len() - 1) as u32
                    });
                    t10[4 + e] = corners as u32 + id;
                }
                t10
            })
            .collect();
        Tet10Mesh {
            nodes,
            corners,
            edges,
            tets,
            material: m.material.clone(),
            rule,
            edge_index,
        }
    }

    pub fn ndof(&self) -> usize {
        3 * self.nodes.len()
    }

    /// The midpoint node of the edge between corners `a` and `b`, if that edge exists.
    pub fn midpoint(&self, a: u32, b: u32) -> Option<u32> {
        self.edge_index
            .get(&(a.min(b), a.max(b)))
            .map(|e| self.corners as u32 + e)
    }

    /// K's lower triangle as triplets; a flat or inverted tetrahedron is a reported failure.
    pub fn assemble(&self) -> Result<Vec<(usize, usize, f64)>> {
        super::blocks::lower_triplets(self.nodes.len(), &self.tets, |t| {
            let tet = self.tets[t];
            let x = [0, 1, 2, 3].map(|c| self.nodes[tet[c] as usize]);
            element_stiffness(x, self.material[t], self.rule).ok_or_else(|| {
                Error::numerical(
                    NumericalKind::DegenerateElement,
                    format!(
                        "tetrahedron {t} (corners {:?}) is flat or inverted",
                        &tet[..4]
                    ),
                )
            })
        })
    }

    /// The consistent nodal forces of `loads`: a uniform pressure on a flat 6-node triangle puts
    /// nothing on its corners and a third of the face's force on each edge midpoint (∫ of the
    /// corner functions Lᵢ(2Lᵢ − 1) over a triangle is 0, of 4 Lᵢ Lⱼ is A/3). Pressure faces are
    /// given by their three corners.
    pub(crate) fn load_vector(&self, loads: &Loads) -> Result<Vec<f64>> {
        let mut f = loads.nodal_vector(self.nodes.len())?;
        for r in loads.face_forces(&self.nodes) {
            let (face, force) = r?;
            for e in 0..3 {
                let (a, b) = (face[e], face[(e + 1) % 3]);
                let m = self.midpoint(a, b).ok_or_else(|| {
                    Error::config(format!(
                        "volumetric model: pressure face {face:?} is not a face of the mesh"
                    ))
                })?;
                for c in 0..3 {
                    f[3 * m as usize + c] += force[c] / 3.0;
                }
            }
        }
        Ok(f)
    }

    /// Linear elasticity with per-node holds (corners and midpoints) and loads, as
    /// [`TetMesh::solve`].
    pub fn solve(&self, holds: &[Hold], loads: &Loads) -> Result<Vec<[f64; 3]>> {
        let f = self.load_vector(loads)?;
        let c = Constrained::new(&self.assemble()?, holds, self.nodes.len())?;
        Ok(c.solve(&[(holds, &f)])?.remove(0))
    }

    /// The corner tetrahedra flat or inverted once the nodes move by `u` (straight-sided test).
    pub fn inverted_after(&self, u: &[[f64; 3]]) -> Vec<usize> {
        let corners: Vec<[u32; 4]> = self.tets.iter().map(|t| [t[0], t[1], t[2], t[3]]).collect();
        super::inverted_after(&self.nodes, &corners, u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const X: [[f64; 3]; 4] = [
        [0.1, 0.0, 0.2],
        [2.0, 0.3, 0.0],
        [0.2, 1.7, 0.1],
        [0.4, 0.5, 2.2],
    ];

    fn nodes10() -> [[f64; 3]; 10] {
        let mut n = [[0.0; 3]; 10];
        n[..4].copy_from_slice(&X);
        for (e, [i, j]) in EDGES.iter().enumerate() {
            n[4 + e] = std::array::from_fn(|c| 0.5 * (X[*i][c] + X[*j][c]));
        }
        n
    }

    #[test]
    fn shape_gradients_reproduce_quadratic_fields() {
        let (_, g) = gradients(X).unwrap();
        let n = nodes10();
        let f = |p: [f64; 3]| 0.3 * p[0] * p[1] - 0.7 * p[2] * p[2] + p[0] + 0.2;
        let df = |p: [f64; 3]| [0.3 * p[1] + 1.0, 0.3 * p[0], -1.4 * p[2]];
        for l in [[0.25; 4], [0.1, 0.2, 0.3, 0.4], [0.7, 0.1, 0.1, 0.1]] {
            let p: [f64; 3] = std::array::from_fn(|c| (0..4).map(|i| l[i] * X[i][c]).sum());
            let d = shape_gradients(l, &g);
            let got: [f64; 3] = std::array::from_fn(|c| (0..10).map(|a| f(n[a]) * d[a][c]).sum());
            let want = df(p);
            for c in 0..3 {
                assert!((got[c] - want[c]).abs() < 1e-12, "{got:?} {want:?}");
            }
        }
    }

    #[test]
    fn stiffness_has_six_rigid_modes_and_the_exact_stretch_energy() {
        let m = TissueElastic {
            youngs_kpa: 3.0,
            poisson: 0.45,
        };
        let n = nodes10();
        for rule in [Rule::Full, Rule::MeanDilatation] {
            let k = element_stiffness(X, m, rule).unwrap();
            let apply = |u: &[f64; 30]| -> [f64; 30] {
                std::array::from_fn(|r| (0..30).map(|c| k[r][c] * u[c]).sum())
            };
            for d in 0..3 {
                let t: [f64; 30] = std::array::from_fn(|i| if i % 3 == d { 1.0 } else { 0.0 });
                let w: [f64; 3] = std::array::from_fn(|c| if c == d { 1.0 } else { 0.0 });
                let r: [f64; 30] = std::array::from_fn(|i| {
                    let p = n[i / 3];
                    [
                        w[1] * p[2] - w[2] * p[1],
                        w[2] * p[0] - w[0] * p[2],
                        w[0] * p[1] - w[1] * p[0],
                    ][i % 3]
                });
                for mode in [t, r] {
                    assert!(apply(&mode).iter().all(|f| f.abs() < 1e-12));
                }
            }
            let s = 1e-2;
            let u: [f64; 30] =
                std::array::from_fn(|i| if i % 3 == 0 { s * n[i / 3][0] } else { 0.0 });
            let e = 0.5 * (0..30).map(|i| u[i] * apply(&u)[i]).sum::<f64>();
            let (v, _) = gradients(X).unwrap();
            let (l, mu) = m.lame();
            assert!((e - 0.5 * v * (l + 2.0 * mu) * s * s).abs() < 1e-13, "{e}");
        }
    }
}

//! Tetrahedral finite elements for the volumetric soft-tissue model.
//!
//! - this module: the linear tetrahedron, small-strain isotropic elasticity with a material per
//!   element, assembly, [`TetMesh::solve`] (holds and loads), [`TetMesh::inverted_after`] (the
//!   elements a large linear move inverts), and the older `solve_linear` / `solve_dofs`;
//! - [`holds`]: per-node conditions ([`Hold`]: free, fixed, sliding n · u = value, on a rail),
//!   imposed by rotating a node's DOFs into its frame; [`Constrained`] factors once and solves
//!   many hold values and loads; [`Loads`]: nodal forces and pressure on boundary faces;
//! - [`quadratic`]: 10-node tetrahedra (C3D10 numbering) that do not lock as ν → 0.5
//!   (`Tet10Mesh::from_linear`, the same `solve`);
//! - [`stuffing`], [`from_ct`], [`quality`]: the mesh of the soft tissue from the CT
//!   (isosurface stuffing) and its quality figures; [`embed`]: the face carried by the mesh;
//!   [`vtu`]: tets.vtu;
//! - [`nonlinear`]: compressible neo-Hookean tissue (CalculiX's NEO HOOKE) by Newton's method
//!   with load steps, exact for rigid bone moves of any size.
//!
//! Small-strain isotropic linear elasticity per element, σ = λ tr(ε) I + 2 μ ε with
//! λ = E ν / ((1 + ν)(1 − 2ν)) and μ = E / (2 (1 + ν)). For linear shape functions N_a with
//! constant gradients g_a, the 3×3 block of the element stiffness coupling nodes a and b is
//! K_ab = V (λ g_a g_bᵀ + μ g_b g_aᵀ + μ (g_a · g_b) I) (the Galerkin form of ∫ ε(v) : σ(u) dV).
//! Node n's displacement components are DOFs 3n, 3n + 1, 3n + 2. Units: mm, kPa (any consistent
//! units give the same displacements, which are all a prescribed-displacement problem yields).

pub mod blocks;
pub(crate) mod bone_normal;
pub mod conditions;
pub mod embed;
pub mod from_ct;
pub mod graded;
pub mod holds;
pub mod hyperelastic;
pub(crate) mod iterative;
pub mod newton_krylov;
pub mod nonlinear;
pub(crate) mod plan_holds;
pub mod quadratic;
pub mod quality;
pub(crate) mod stable_neo_hooke;
pub mod stuffing;
pub(crate) mod tangent;
pub mod vtu;

pub use holds::{Constrained, Hold, Loads};

use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::System;
use crate::fem::cholesky::Ordering;

// An element's material is the case's `TissueElastic` (one type for `[tet.skin]` and the mesh).
pub use crate::case::TissueElastic;

/// Nodes (LPS mm), tetrahedra (four node indices, positive volume: the fourth node on the side
/// the first three wind counter-clockwise about) and one material per tetrahedron.
pub struct TetMesh {
    pub nodes: Vec<[f64; 3]>,
    pub tets: Vec<[u32; 4]>,
    pub material: Vec<TissueElastic>,
}

/// Volume and shape-function gradients of a tetrahedron; None when it is flat or inverted.
pub fn gradients(x: [[f64; 3]; 4]) -> Option<(f64, [[f64; 3]; 4])> {
    let e = [1, 2, 3].map(|k| [0, 1, 2].map(|c| x[k][c] - x[0][c]));
    // Rows of J⁻¹ (J's columns are the edges from node 0) are ∇N1..∇N3: cofactors / det.
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let c = [cross(e[1], e[2]), cross(e[2], e[0]), cross(e[0], e[1])];
    let det = (0..3).map(|k| e[0][k] * c[0][k]).sum::<f64>();
    let scale = (0..3)
        .map(|k| e[k].iter().map(|v| v * v).sum::<f64>())
        .fold(0.0, f64::max)
        .powf(1.5);
    if !(det > 1e-12 * scale) {
        return None;
    }
    let g1 = c[0].map(|v| v / det);
    let g2 = c[1].map(|v| v / det);
    let g3 = c[2].map(|v| v / det);
    let g0 = [0, 1, 2].map(|k| -(g1[k] + g2[k] + g3[k]));
    Some((det / 6.0, [g0, g1, g2, g3]))
}

/// The 12×12 element stiffness (row 3a + i, column 3b + j).
pub(crate) fn element_stiffness(x: [[f64; 3]; 4], m: TissueElastic) -> Option<[[f64; 12]; 12]> {
    let (lambda, mu) = m.lame();
    element_stiffness_lame(x, lambda, mu)
}

/// The same for Lamé's (λ, μ): linear in each, so K = λ K_λ + μ K_μ per element (the affine
/// form the reduced model takes apart, `crate::reduced`).
pub(crate) fn element_stiffness_lame(
    x: [[f64; 3]; 4],
    lambda: f64,
    mu: f64,
) -> Option<[[f64; 12]; 12]> {
    let (v, g) = gradients(x)?;
    let mut k = [[0.0; 12]; 12];
    for a in 0..4 {
        for b in 0..4 {
            let dot: f64 = (0..3).map(|c| g[a][c] * g[b][c]).sum();
            for i in 0..3 {
                for j in 0..3 {
                    let id = if i == j { 1.0 } else { 0.0 };
                    k[3 * a + i][3 * b + j] =
                        v * (lambda * g[a][i] * g[b][j] + mu * g[a][j] * g[b][i] + mu * dot * id);
                }
            }
        }
    }
    Some(k)
}

impl TetMesh {
    pub fn ndof(&self) -> usize {
        3 * self.nodes.len()
    }

    /// K's lower triangle as triplets, one per entry; an inverted or
    /// flat tetrahedron is a reported failure naming it.
    pub fn assemble(&self) -> Result<Vec<(usize, usize, f64)>> {
        blocks::lower_triplets(self.nodes.len(), &self.tets, |t| {
            let tet = self.tets[t];
            element_stiffness(tet.map(|n| self.nodes[n as usize]), self.material[t]).ok_or_else(
                || {
                    Error::numerical(
                        NumericalKind::DegenerateElement,
                        format!("tetrahedron {t} (nodes {tet:?}) is flat or inverted"),
                    )
                },
            )
        })
    }

    /// Small-strain linear elasticity with per-node holds (fixed, sliding, on a rail or free) and
    /// loads (nodal forces, pressure on boundary faces): the displacement of every node. For
    /// many hold values or loads on one factor, use [`Constrained`] with [`TetMesh::assemble`].
    pub fn solve(&self, holds: &[Hold], loads: &Loads) -> Result<Vec<[f64; 3]>> {
        let f = loads.vector_linear(&self.nodes)?;
        let c = Constrained::new(&self.assemble()?, holds, self.nodes.len())?;
        Ok(c.solve(&[(holds, &f)])?.remove(0))
    }

    /// The tetrahedra that are flat or inverted once the nodes have moved by `u` (a large move
    /// in the linear model; the pipeline warns and names the nonlinear option), ascending.
    pub fn inverted_after(&self, u: &[[f64; 3]]) -> Vec<usize> {
        inverted_after(&self.nodes, &self.tets, u)
    }

    /// Small-strain linear elasticity with the nodes of `prescribed` held at their displacement
    /// and no body force: the displacement of every node.
    pub fn solve_linear(&self, prescribed: &[Option<[f64; 3]>]) -> Result<Vec<[f64; 3]>> {
        let fixed: Vec<bool> = prescribed.iter().flat_map(|p| [p.is_some(); 3]).collect();
        let values: Vec<f64> = prescribed
            .iter()
            .flat_map(|p| p.unwrap_or([0.0; 3]))
            .collect();
        let u = self.solve_dofs(&fixed, &values)?;
        Ok(u.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
    }

    /// The same with single displacement components held (`fixed[3n + c]` at `values[3n + c]`):
    /// sliding and symmetry conditions hold one component and leave the others free.
    pub fn solve_dofs(&self, fixed: &[bool], values: &[f64]) -> Result<Vec<f64>> {
        let n = self.ndof();
        if !fixed.iter().any(|f| *f) {
            return Err(Error::config(
                "volumetric model: no node is held (no bone in the region): the tissue would float",
            ));
        }
        let sys = System::with_ordering(n, self.assemble()?, fixed, Ordering::NestedDissection).map_err(|e| match e {
            Error::Numerical { kind, .. } => Error::numerical(
                kind,
                "the tetrahedral stiffness matrix is singular: a piece of tissue is held by no node",
            ),
            other => other,
        })?;
        Ok(sys.solve(&[vec![0.0; n]], &[values.to_vec()]).remove(0))
    }
}

/// The affine parts of the linear tetrahedral stiffness: for each tissue slot s present in
/// `slot` (per tetrahedron, `case::Tet::slot`), K_λ,s and K_μ,s, so that K = Σ_s (λ_s K_λ,s +
/// μ_s K_μ,s) (Rozza, Huynh & Patera 2008 §2: an affine parametric operator). This lists them,
/// (slot, λ or not) in slot order; [`LameTerms::term`] assembles one, so that only one is in
/// memory at a time.
pub(crate) fn lame_term_list(slot: &[usize]) -> Vec<(usize, bool)> {
    let mut present: Vec<usize> = slot.to_vec();
    present.sort_unstable();
    present.dedup();
    present
        .into_iter()
        .flat_map(|s| [(s, true), (s, false)])
        .collect()
}

/// The affine parts (see [`lame_term_list`]) on one pattern: each part sums only its own
/// tissue's elements, so all Q parts cost about one assembly, and every part's blocks share the
/// pattern's layout (elements of other tissues add nothing). `scale` multiplies each
/// tetrahedron's part (1, or a torn element's trace).
pub(crate) struct LameTerms<'a> {
    nodes: &'a [[f64; 3]],
    tets: &'a [[u32; 4]],
    scale: &'a [f64],
    pattern: blocks::BlockPattern,
    /// Per tissue slot, its tetrahedra.
    of_slot: Vec<Vec<usize>>,
}

impl<'a> LameTerms<'a> {
    pub(crate) fn new(
        nodes: &'a [[f64; 3]],
        tets: &'a [[u32; 4]],
        slot: &[usize],
        scale: &'a [f64],
    ) -> LameTerms<'a> {
        let mut of_slot = vec![Vec::new(); slot.iter().max().map_or(0, |s| s + 1)];
        for (t, s) in slot.iter().enumerate() {
            of_slot[*s].push(t);
        }
        LameTerms {
            nodes,
            tets,
            scale,
            pattern: blocks::BlockPattern::new(nodes.len(), tets),
            of_slot,
        }
    }

    /// Each lower-triangle entry (row DOF, column DOF, its place in [`Self::term`]'s values),
    /// the same for every part.
    pub(crate) fn for_each_lower(&self, f: impl FnMut(usize, usize, usize)) {
        self.pattern.for_each_lower(f)
    }

    /// One part's values, 9 per node block ([`blocks::BlockPattern::sum`]).
    pub(crate) fn term(&self, (s, is_lambda): (usize, bool)) -> Result<Vec<[f64; 9]>> {
        let (l, m) = if is_lambda { (1.0, 0.0) } else { (0.0, 1.0) };
        let own = self.of_slot.get(s).map_or(&[][..], |v| v.as_slice());
        self.pattern.sum(self.tets, own.iter().copied(), |t| {
            let tet = self.tets[t];
            element_stiffness_lame(
                tet.map(|n| self.nodes[n as usize]),
                l * self.scale[t],
                m * self.scale[t],
            )
            .ok_or_else(|| {
                Error::numerical(
                    NumericalKind::DegenerateElement,
                    format!("tetrahedron {t} (nodes {tet:?}) is flat or inverted"),
                )
            })
        })
    }
}

/// The tetrahedra (corner indices into `nodes`) flat or inverted at `nodes + u`.
pub fn inverted_after(nodes: &[[f64; 3]], tets: &[[u32; 4]], u: &[[f64; 3]]) -> Vec<usize> {
    let at = |n: u32| -> [f64; 3] {
        let (p, d) = (
            nodes[n as usize],
            u.get(n as usize).copied().unwrap_or([f64::NAN; 3]),
        );
        [p[0] + d[0], p[1] + d[1], p[2] + d[2]]
    };
    tets.iter()
        .enumerate()
        .filter(|(_, t)| gradients(t.map(at)).is_none())
        .map(|(i, _)| i)
        .collect()
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
    const M: TissueElastic = TissueElastic {
        youngs_kpa: 3.0,
        poisson: 0.3,
    };

    fn apply(k: &[[f64; 12]; 12], u: &[f64; 12]) -> [f64; 12] {
        std::array::from_fn(|r| (0..12).map(|c| k[r][c] * u[c]).sum())
    }

    #[test]
    fn gradients_sum_to_zero_and_reproduce_coordinates() {
        let (v, g) = gradients(X).unwrap();
        assert!(v > 0.0);
        // Σ_a x_a ⊗ ∇N_a = I: linear fields are interpolated exactly.
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..4).map(|a| X[a][i] * g[a][j]).sum();
                assert!(
                    (s - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12,
                    "{i}{j}: {s}"
                );
            }
        }
        let swapped = [X[1], X[0], X[2], X[3]];
        assert!(
            gradients(swapped).is_none(),
            "an inverted element is refused"
        );
    }

    #[test]
    fn stiffness_is_symmetric_with_six_rigid_modes_and_positive_strain_energy() {
        let k = element_stiffness(X, M).unwrap();
        for r in 0..12 {
            for c in 0..12 {
                assert!((k[r][c] - k[c][r]).abs() < 1e-12);
            }
        }
        // Translations and infinitesimal rotations u = ω × x carry no strain: K u = 0.
        let mut modes: Vec<[f64; 12]> = Vec::new();
        for d in 0..3 {
            modes.push(std::array::from_fn(|i| if i % 3 == d { 1.0 } else { 0.0 }));
            let w: [f64; 3] = std::array::from_fn(|c| if c == d { 1.0 } else { 0.0 });
            modes.push(std::array::from_fn(|i| {
                let p = X[i / 3];
                let r = [
                    w[1] * p[2] - w[2] * p[1],
                    w[2] * p[0] - w[0] * p[2],
                    w[0] * p[1] - w[1] * p[0],
                ];
                r[i % 3]
            }));
        }
        for m in &modes {
            assert!(apply(&k, m).iter().all(|f| f.abs() < 1e-12));
        }
        // A uniform stretch ε_xx = s has energy ½ V (λ + 2μ) s².
        let s = 1e-2;
        let u: [f64; 12] = std::array::from_fn(|i| if i % 3 == 0 { s * X[i / 3][0] } else { 0.0 });
        let e = 0.5 * (0..12).map(|i| u[i] * apply(&k, &u)[i]).sum::<f64>();
        let (v, _) = gradients(X).unwrap();
        let (l, mu) = M.lame();
        assert!((e - 0.5 * v * (l + 2.0 * mu) * s * s).abs() < 1e-14, "{e}");
    }
}

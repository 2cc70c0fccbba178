//! The certified reduced-basis model of the linear tetrahedral model (docs/design/reduced.md):
//! its stiffness is affine in the tissues' Lamé parameters, so a greedy over the parameter box
//! picks a few full solves as a basis, and any parameter set is then solved in microseconds with
//! a certified bound on its error.
//!
//! - [`affine`]: A(θ) = Σ θ_q A_q, f(θ) = Σ θ_q f_q on the free unknowns (holds in node frames);
//! - [`basis`]: the greedy, the online solve and the bound (min-θ coercivity, residual dual norm);
//! - [`dual`]: primal–dual output bounds: a dual reduced basis per output, its corrected output
//!   and the bound on it;
//! - [`norm`]: the largest gain from the energy norm to the face's displacement (mm), by Lanczos.

pub mod affine;
pub mod basis;
pub mod dual;
pub mod norm;

pub use affine::Affine;
pub use basis::{Basis, Greedy, GreedyStep, Online, OnlineForm};

use serde::{Deserialize, Serialize};

/// A face displacement linear in reduced coefficients: lift + Σ_n c_n columns[n] (mm per
/// vertex): what the sampling needs of a reduced model.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearFace {
    pub lift: Vec<[f64; 3]>,
    pub columns: Vec<Vec<[f64; 3]>>,
    /// The vertices some field moves, and their fields side by side per vertex (lift, then each
    /// column: 3 (N + 1) values). Most of a face is still (held skin, beyond the modelled
    /// region) and its fields are exactly zero, so the whole face is one contiguous pass over
    /// what moves instead of N + 1 passes over everything.
    moving: Vec<u32>,
    rows: Vec<f64>,
}

impl LinearFace {
    pub fn new(lift: Vec<[f64; 3]>, columns: Vec<Vec<[f64; 3]>>) -> Self {
        let fields = || std::iter::once(&lift).chain(&columns);
        let moving: Vec<u32> = (0..lift.len())
            .filter(|v| fields().any(|f| f[*v] != [0.0; 3]))
            .map(|v| v as u32)
            .collect();
        let rows = moving
            .iter()
            .flat_map(|v| fields().flat_map(move |f| f[*v as usize]))
            .collect();
        LinearFace {
            lift,
            columns,
            moving,
            rows,
        }
    }

    /// How many vertices some field moves.
    pub fn moving(&self) -> usize {
        self.moving.len()
    }

    /// Whether some field moves vertex `v` (else every answer leaves it exactly still).
    pub fn moves(&self, v: usize) -> bool {
        self.moving.binary_search(&(v as u32)).is_ok()
    }

    /// The displacement of vertex `v` for coefficients `c`.
    pub fn at(&self, v: usize, c: &[f64]) -> [f64; 3] {
        let mut d = self.lift[v];
        for (col, w) in self.columns.iter().zip(c) {
            for k in 0..3 {
                d[k] += w * col[v][k];
            }
        }
        d
    }

    /// Every vertex's displacement (the still ones exactly zero, as [`Self::at`] gives them).
    pub fn all(&self, c: &[f64]) -> Vec<[f64; 3]> {
        let mut out = vec![[0.0; 3]; self.lift.len()];
        let width = 3 * (self.columns.len() + 1);
        if c.len() != self.columns.len() {
            return (0..self.lift.len()).map(|v| self.at(v, c)).collect();
        }
        for (v, r) in self.moving.iter().zip(self.rows.chunks_exact(width)) {
            let mut d = [r[0], r[1], r[2]];
            for (w, col) in c.iter().zip(r[3..].chunks_exact(3)) {
                d[0] += w * col[0];
                d[1] += w * col[1];
                d[2] += w * col[2];
            }
            out[*v as usize] = d;
        }
        out
    }
}

/// The certified bound (mm) on a linear output's error y = C e, through the residual's Riesz
/// representer ρ = X⁻¹ r (docs/design/reduced.md "The face, in mm"): e = T⁻¹ ρ with T = X⁻¹ A(θ),
/// whose spectrum lies in [α_LB, γ_UB] (every A_q positive semi-definite), so with
/// c = (1/α_LB + 1/γ_UB)/2
///
/// ```text
/// ‖C e‖ ≤ c ‖C ρ‖ + g (1/α_LB − 1/γ_UB)/2 ‖ρ‖_X,
/// ```
///
/// g the output's gain (‖C v‖ ≤ g ‖v‖_X). Never above g Δ, which it falls back to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputBound {
    pub gain: f64,
    /// F with ‖C ρ‖ = ‖F y‖ for ρ of Riesz coordinates y: `rows` × k, row-major (empty: the
    /// plain g Δ).
    pub factor: Vec<f64>,
    pub rows: usize,
}

impl OutputBound {
    /// From the gain and the output's images C e_i of the Riesz space's vectors: F is their
    /// matrix when it has at most k rows (a landmark: 3), else Λ^½ Uᵀ of their Gram matrix
    /// U Λ Uᵀ (the face: k × k instead of 3 × vertices).
    pub fn new(gain: f64, images: &[Vec<f64>]) -> OutputBound {
        let k = images.len();
        let m = images.first().map_or(0, Vec::len);
        if k == 0 {
            return OutputBound {
                gain,
                factor: Vec::new(),
                rows: 0,
            };
        }
        if m <= k {
            let factor = (0..m)
                .flat_map(|r| images.iter().map(move |col| col[r]))
                .collect();
            return OutputBound {
                gain,
                factor,
                rows: m,
            };
        }
        let gram = nalgebra::DMatrix::from_fn(k, k, |i, j| basis::dot(&images[i], &images[j]));
        let e = nalgebra::SymmetricEigen::new(gram);
        let mut factor = vec![0.0; k * k];
        for r in 0..k {
            let s = e.eigenvalues[r].max(0.0).sqrt();
            for j in 0..k {
                factor[r * k + j] = s * e.eigenvectors[(j, r)];
            }
        }
        OutputBound {
            gain,
            factor,
            rows: k,
        }
    }

    /// Whether the gain is finite and not negative and the factor has whole rows of finite
    /// values (a stored model is checked on read).
    pub fn consistent(&self) -> bool {
        self.gain.is_finite()
            && self.gain >= 0.0
            && (self.rows == 0 || self.factor.len().is_multiple_of(self.rows))
            && (self.rows > 0 || self.factor.is_empty())
            && self.factor.iter().all(|x| x.is_finite())
    }

    /// The bound (mm) for the online answer `o`.
    pub fn bound(&self, o: &Online) -> f64 {
        let plain = self.gain * o.energy_bound;
        if self.rows == 0 || !(o.gamma.is_finite() && o.alpha > 0.0) {
            return plain;
        }
        let cols = self.factor.len() / self.rows;
        let y = &o.coordinates[..cols.min(o.coordinates.len())];
        let fy = self
            .factor
            .chunks_exact(cols)
            .map(|row| basis::dot(&row[..y.len()], y).powi(2))
            .sum::<f64>()
            .sqrt();
        let (a, g) = (1.0 / o.alpha, 1.0 / o.gamma);
        // The coordinates' round-off (floor, in the X-norm) reaches the output through g.
        let split =
            0.5 * (a + g) * (fy + self.gain * o.floor) + self.gain * 0.5 * (a - g) * o.residual;
        split.min(plain)
    }
}

/// report.json `uncertainty.reduced[]`: how one reduced model was built (docs/design/reduced.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReducedReport {
    /// The sliding state it was built for.
    pub sliding: bool,
    pub basis_size: usize,
    /// Factorisations of the full model (the reference, and a snapshot whose conjugate
    /// gradients did not converge), and the cheaper solves with the reference's factor (Riesz
    /// representers, the snapshots' preconditioner, Lanczos; one per column).
    pub full_factorisations: usize,
    pub reference_solves: usize,
    /// Conjugate-gradient iterations of the snapshots after the first (each one product with
    /// the full matrix; their preconditioner solves are in `reference_solves`).
    #[serde(default)]
    pub cg_iterations: usize,
    pub offline_seconds: f64,
    /// σ: ‖face error‖₂ ≤ σ ‖e‖_X.
    pub face_gain: f64,
    pub greedy: Vec<GreedyStep>,
    /// The landmarks' dual bases (primal–dual output bounds; absent in a model stored before
    /// them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dual: Option<DualReport>,
}

/// report.json `uncertainty.reduced[].dual`: how the outputs' dual bases were built.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DualReport {
    /// dim W per output (three adjoints at θ̄, then three per greedy round).
    pub sizes: Vec<usize>,
    /// The largest relative dual bound ‖r_du‖_X' / (α_LB ‖ψ_N‖_X) over the training set and
    /// the outputs, at the end.
    pub largest_relative_bound: f64,
    pub cg_iterations: usize,
    /// Solves with X's factor (one per column): the snapshots' preconditioner and the Riesz
    /// representers of A_q w.
    pub reference_solves: usize,
    pub full_factorisations: usize,
    pub seconds: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tet::{Constrained, Hold, Loads, TetMesh, TissueElastic};

    /// n³ sheared cubes of side 1 mm, 6 tetrahedra each (Kuhn), tissue slot by layer and column:
    /// three tissues. The bottom held on a rigid move, one side sliding on its plane, the rest free.
    fn block(n: usize) -> (TetMesh, Vec<usize>, Vec<Hold>) {
        let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
        let mut nodes = Vec::new();
        for k in 0..=n {
            for j in 0..=n {
                for i in 0..=n {
                    let (x, y, z) = (i as f64, j as f64, k as f64);
                    nodes.push([x + 0.1 * y, y + 0.05 * z, z]);
                }
            }
        }
        let mut tets = Vec::new();
        let mut slot = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    for mut t in crate::mesh::kuhn_cell([i, j, k], id) {
                        let x = t.map(|v| nodes[v as usize]);
                        if crate::tet::gradients(x).is_none() {
                            t.swap(2, 3);
                        }
                        tets.push(t);
                        slot.push(if k >= n / 2 {
                            0
                        } else if i < n / 2 {
                            1
                        } else {
                            2
                        });
                    }
                }
            }
        }
        let holds = nodes
            .iter()
            .map(|p| {
                if p[2] == 0.0 {
                    // A small rigid rotation about z and a translation.
                    let (c, s) = (0.05f64.cos(), 0.05f64.sin());
                    Hold::Fixed([
                        c * p[0] - s * p[1] - p[0] + 0.3,
                        s * p[0] + c * p[1] - p[1],
                        0.2,
                    ])
                } else if p[1] == 0.0 {
                    Hold::Slide {
                        normal: [0.0, 1.0, 0.0],
                        value: 0.0,
                    }
                } else {
                    Hold::Free
                }
            })
            .collect();
        let m = TetMesh {
            nodes,
            tets,
            material: Vec::new(),
        };
        (m, slot, holds)
    }

    /// θ for materials per slot: (λ, μ) per slot present, the order of `lame_term_list`.
    fn theta(m: &[TissueElastic]) -> Vec<f64> {
        m.iter()
            .flat_map(|e| {
                let (l, mu) = e.lame();
                [l, mu]
            })
            .collect()
    }

    fn tissue(e: f64, nu: f64) -> TissueElastic {
        TissueElastic {
            youngs_kpa: e,
            poisson: nu,
        }
    }

    /// The block's affine system: its Lamé terms by tissue slot, each element scaled.
    fn affine_of(m: &TetMesh, slot: &[usize], scale: &[f64], holds: &[Hold]) -> Affine {
        let list = crate::tet::lame_term_list(slot);
        let lame = crate::tet::LameTerms::new(&m.nodes, &m.tets, slot, scale);
        Affine::new(
            &lame,
            &list,
            holds,
            crate::fem::cholesky::Ordering::NestedDissection,
        )
        .unwrap()
    }

    fn energy(sys: &Affine, theta: &[f64], e: &[f64]) -> f64 {
        (0..sys.terms())
            .map(|q| theta[q] * basis::dot(e, &sys.apply(q, e)))
            .sum::<f64>()
            .sqrt()
    }

    #[test]
    fn products_with_several_vectors_equal_the_products_one_at_a_time() {
        let (mut m, slot, holds) = block(4);
        let mats = [tissue(30.0, 0.45), tissue(10.0, 0.47), tissue(2.0, 0.46)];
        m.material = slot.iter().map(|s| mats[*s]).collect();
        let sys = affine_of(&m, &slot, &vec![1.0; slot.len()], &holds);
        let n = sys.unknowns();
        let xs: Vec<Vec<f64>> = (0..3)
            .map(|j| {
                (0..n)
                    .map(|i| ((i * 31 + j * 17) % 13) as f64 - 6.0)
                    .collect()
            })
            .collect();
        let refs: Vec<&[f64]> = xs.iter().map(Vec::as_slice).collect();
        let values = sys.values_at(&theta(&mats));
        let together = sys.apply_values_many(&values, &refs);
        for q in 0..sys.terms() {
            for (x, y) in xs.iter().zip(sys.apply_many(q, &refs)) {
                assert_eq!(y, sys.apply(q, x), "term {q}");
            }
        }
        for (x, y) in xs.iter().zip(together) {
            assert_eq!(y, sys.apply_values(&values, x));
        }
    }

    #[test]
    fn the_affine_sum_is_the_assembled_model_and_the_bound_holds() {
        let (mut m, slot, holds) = block(5);
        let mats = [tissue(30.0, 0.45), tissue(10.0, 0.47), tissue(2.0, 0.46)];
        // Every seventh element torn: its parts scaled as its material is.
        let scale: Vec<f64> = (0..slot.len())
            .map(|t| if t % 7 == 0 { 1e-4 } else { 1.0 })
            .collect();
        m.material = slot
            .iter()
            .zip(&scale)
            .map(|(s, k)| TissueElastic {
                youngs_kpa: mats[*s].youngs_kpa * k,
                ..mats[*s]
            })
            .collect();
        let sys = affine_of(&m, &slot, &scale, &holds);
        // The truth of the affine form equals the model's own solve (an independent path:
        // per-element materials, `Constrained`).
        let th = theta(&mats);
        let k = sys.factor(&th).unwrap();
        let u = affine::solve_columns(&k, &[sys.rhs(&th)]).remove(0);
        let direct = Constrained::new(&m.assemble().unwrap(), &holds, m.nodes.len())
            .unwrap()
            .solve(&[(&holds, &Loads::none().nodal_vector(m.nodes.len()).unwrap())])
            .unwrap()
            .remove(0);
        let ours = sys.expand(&u, true);
        let diff = ours
            .iter()
            .zip(&direct)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
            .fold(0.0, f64::max);
        assert!(diff < 1e-10, "affine truth vs assembled solve: {diff}");
        // The greedy on a training box: moduli ratios 3× either way, ν 0.45–0.49.
        let point = |x: [f64; 4]| {
            let nu = 0.45 + 0.04 * x[0];
            theta(&[
                tissue(30.0 * 3f64.powf(2.0 * x[1] - 1.0), nu),
                tissue(10.0 * 3f64.powf(2.0 * x[2] - 1.0), nu),
                tissue(2.0 * 3f64.powf(2.0 * x[3] - 1.0), nu),
            ])
        };
        let halton = |i: usize, b: usize| {
            let (mut f, mut r, mut i) = (1.0, 0.0, i + 1);
            while i > 0 {
                f /= b as f64;
                r += f * (i % b) as f64;
                i /= b;
            }
            r
        };
        let train: Vec<Vec<f64>> = (0..100)
            .map(|i| point([2, 3, 5, 7].map(|b| halton(i, b))))
            .collect();
        let greedy = Greedy {
            tolerance: 1e-6,
            max_size: 40,
            batch: 4,
        };
        let (b, _) = Basis::build(&sys, &th, &train, greedy, &|_| {}).unwrap();
        let h = &b.history;
        assert!(
            h.last().unwrap().max_relative_bound < 1e-3 * h[0].max_relative_bound,
            "the greedy's bound falls with N: {:?}",
            h.iter().map(|s| s.max_relative_bound).collect::<Vec<_>>()
        );
        // New points (not trained on): true error ≤ bound, and the bound is not vacuous.
        let mut worst_ratio: f64 = 0.0;
        for i in 0..12 {
            let t = point([11, 13, 17, 19].map(|b| halton(i + 7, b)));
            let truth = affine::solve_columns(&sys.factor(&t).unwrap(), &[sys.rhs(&t)]).remove(0);
            // A basis of half the size, so the error is well above round-off.
            let (small, _) = Basis::build(
                &sys,
                &th,
                &train,
                Greedy {
                    tolerance: 0.0,
                    max_size: 4,
                    batch: 1,
                },
                &|_| {},
            )
            .unwrap();
            for basis in [&b, &small] {
                let o = basis.solve(&t).unwrap();
                let e: Vec<f64> = truth
                    .iter()
                    .zip(basis.expand(&o.coefficients))
                    .map(|(a, b)| a - b)
                    .collect();
                let true_error = energy(&sys, &th, &e);
                assert!(
                    true_error <= o.energy_bound,
                    "N = {}: true {true_error:.3e} > bound {:.3e}",
                    basis.size(),
                    o.energy_bound
                );
                if basis.size() == 4 {
                    worst_ratio = worst_ratio.max(o.energy_bound / true_error);
                }
            }
        }
        assert!(worst_ratio < 30.0, "effectivity {worst_ratio}");
    }

    #[test]
    fn snapshots_by_conjugate_gradients_build_a_basis_whose_residual_is_the_full_ones() {
        let (m, slot, holds) = block(4);
        let mats = [tissue(30.0, 0.45), tissue(10.0, 0.47), tissue(2.0, 0.46)];
        let sys = affine_of(&m, &slot, &vec![1.0; slot.len()], &holds);
        let th = theta(&mats);
        // Moduli 4× either way, ν 0.45–0.49: a wide box for the preconditioner X = A(θ̄).
        let point = |i: usize| {
            let x = |k: u64| ((i as u64 * 2_654_435_761 + k * 40_503) % 1000) as f64 / 999.0;
            let nu = 0.45 + 0.04 * x(1);
            theta(&[
                tissue(30.0 * 4f64.powf(2.0 * x(2) - 1.0), nu),
                tissue(10.0 * 4f64.powf(2.0 * x(3) - 1.0), nu),
                tissue(2.0 * 4f64.powf(2.0 * x(4) - 1.0), nu),
            ])
        };
        let train: Vec<Vec<f64>> = (0..60).map(point).collect();
        let greedy = Greedy {
            tolerance: 0.0,
            max_size: 9,
            batch: 4,
        };
        let (mut b, x) = Basis::build(&sys, &th, &train, greedy, &|_| {}).unwrap();
        assert_eq!(b.size(), 9);
        // An output: every third free unknown. Its gain σ² = λ_max(C X⁻¹ Cᵀ) and its images of
        // the Riesz space make its bound through the Riesz representer.
        let picked: Vec<usize> = (0..sys.unknowns()).step_by(3).collect();
        let out = |v: &[f64]| -> Vec<f64> { picked.iter().map(|i| v[*i]).collect() };
        let gain = norm::largest_eigenvalue(picked.len(), 200, &|y: &[f64]| {
            let mut full = vec![0.0; sys.unknowns()];
            for (i, a) in picked.iter().zip(y) {
                full[*i] = *a;
            }
            out(&affine::solve_columns(&x, &[full]).remove(0))
        })
        .sqrt();
        let images: Vec<Vec<f64>> = std::mem::take(&mut b.riesz_space)
            .iter()
            .map(|e| out(e))
            .collect();
        let face = OutputBound::new(gain, &images);
        assert_eq!(face.rows, images.len());
        // Every snapshot converged without a factorisation of its own: X's is the only one.
        assert_eq!(b.full_factorisations, 1);
        assert!(b.cg_iterations >= 8, "{} iterations", b.cg_iterations);
        // Batches of 4 after the first vector: sizes 1, 5, 9.
        let sizes: Vec<usize> = b.history.iter().map(|h| h.size).collect();
        assert_eq!(sizes, [1, 5, 9]);
        // The online residual norm (block Gram–Schmidt coordinates of the Riesz
        // representers) is the full residual's dual norm, √(rᵀ X⁻¹ r), at points not trained on.
        for i in 100..106 {
            let t = point(i);
            let o = b.solve(&t).unwrap();
            let u = b.expand(&o.coefficients);
            let mut r = sys.rhs(&t);
            for (q, tq) in t.iter().enumerate() {
                for (a, b) in r.iter_mut().zip(sys.apply(q, &u)) {
                    *a -= tq * b;
                }
            }
            let z = affine::solve_columns(&x, std::slice::from_ref(&r)).remove(0);
            let direct = basis::dot(&r, &z).sqrt();
            // The direct residual f − A u cancels: it is exact to round-off in ‖f‖_X' only.
            let f = sys.rhs(&t);
            let zf = affine::solve_columns(&x, std::slice::from_ref(&f)).remove(0);
            let scale = basis::dot(&f, &zf).sqrt();
            assert!(
                (o.residual - direct).abs() <= 1e-6 * direct + 1e-10 * scale,
                "θ {i}: online {} vs full {direct} (‖f‖ {scale})",
                o.residual
            );
            // And the bounds hold against the factorised truth: the energy's, and the output's
            // through the Riesz representer, which is at most its gain × Δ.
            let truth = affine::solve_columns(&sys.factor(&t).unwrap(), &[sys.rhs(&t)]).remove(0);
            let e: Vec<f64> = truth.iter().zip(&u).map(|(a, b)| a - b).collect();
            assert!(energy(&sys, &th, &e) <= o.energy_bound);
            let ce = out(&e).iter().map(|a| a * a).sum::<f64>().sqrt();
            let split = face.bound(&o);
            assert!(
                ce <= split,
                "θ {i}: output error {ce:.3e} > its bound {split:.3e}"
            );
            assert!(
                split <= gain * o.energy_bound,
                "{split} > {}",
                gain * o.energy_bound
            );
        }
    }

    /// A three-component output of the block: the displacement components of free unknowns
    /// near the top (each column a unit functional, or a sum of two).
    fn output_columns(sys: &Affine) -> Vec<Vec<f64>> {
        let n = sys.unknowns();
        let picks = [[n - 1, n - 1], [n - 5, n - 9], [n / 2, n - 14]];
        picks
            .iter()
            .map(|p| {
                let mut l = vec![0.0; n];
                for i in p {
                    l[*i] += 1.0;
                }
                l
            })
            .collect()
    }

    /// The block's system, θ̄, a deliberately small basis (so its error is well above
    /// round-off), the output columns, their adjoints at θ̄ and the factor of X.
    struct DualSetup {
        sys: Affine,
        th: Vec<f64>,
        b: Basis,
        l: Vec<Vec<f64>>,
        z: Vec<Vec<f64>>,
        x: crate::fem::cholesky::Cholesky<f64>,
    }

    fn dual_setup(n: usize) -> DualSetup {
        let (m, slot, holds) = block(n);
        let mats = [tissue(30.0, 0.45), tissue(10.0, 0.47), tissue(2.0, 0.46)];
        let sys = affine_of(&m, &slot, &vec![1.0; slot.len()], &holds);
        let th = theta(&mats);
        let train: Vec<Vec<f64>> = (0..40).map(|i| box_point(&mats, i)).collect();
        let greedy = Greedy {
            tolerance: 0.0,
            max_size: 3,
            batch: 1,
        };
        let (b, x) = Basis::build(&sys, &th, &train, greedy, &|_| {}).unwrap();
        let l = output_columns(&sys);
        let z = affine::solve_columns(&x, &l);
        DualSetup {
            sys,
            th,
            b,
            l,
            z,
            x,
        }
    }

    /// θ at a pseudo-random point of the box: moduli 4× either way, ν 0.45–0.49.
    fn box_point(mats: &[TissueElastic; 3], i: usize) -> Vec<f64> {
        let x = |k: u64| ((i as u64 * 2_654_435_761 + k * 40_503) % 1000) as f64 / 999.0;
        let nu = 0.45 + 0.04 * x(1);
        theta(&[
            tissue(mats[0].youngs_kpa * 4f64.powf(2.0 * x(2) - 1.0), nu),
            tissue(mats[1].youngs_kpa * 4f64.powf(2.0 * x(3) - 1.0), nu),
            tissue(mats[2].youngs_kpa * 4f64.powf(2.0 * x(4) - 1.0), nu),
        ])
    }

    /// lᵀ u(θ) by factorising A(θ), and lᵀ u_N of the basis's answer `o`.
    fn outputs_at(
        sys: &Affine,
        b: &Basis,
        l: &[Vec<f64>],
        t: &[f64],
        o: &basis::Online,
    ) -> (Vec<f64>, Vec<f64>) {
        let truth = affine::solve_columns(&sys.factor(t).unwrap(), &[sys.rhs(t)]).remove(0);
        let un = b.expand(&o.coefficients);
        (
            l.iter().map(|lj| basis::dot(lj, &truth)).collect(),
            l.iter().map(|lj| basis::dot(lj, &un)).collect(),
        )
    }

    #[test]
    fn with_the_exact_adjoint_in_its_space_the_corrected_output_is_exact() {
        let DualSetup {
            sys,
            th,
            b,
            l,
            z,
            x,
        } = dual_setup(4);
        let ctx = dual::DualContext {
            sys: &sys,
            x: &x,
            theta_bar: &th,
            primal: &b,
        };
        let mats = [tissue(30.0, 0.45), tissue(10.0, 0.47), tissue(2.0, 0.46)];
        let at = box_point(&mats, 777);
        // One round at θ* with the snapshots solved to the end (accuracy 0: conjugate gradients
        // never stop early, so each is factorised): W holds A(θ*)⁻¹ l_j exactly.
        let greedy = dual::DualGreedy {
            tolerance: 0.0,
            rounds: 1,
            snapshot_accuracy: 0.0,
        };
        let mut cost = dual::DualCost::default();
        let d = dual::build(&ctx, &l, &z, std::slice::from_ref(&at), greedy, &mut cost).unwrap();
        assert_eq!(d.size(), 6);
        assert_eq!(cost.full_factorisations, 3);
        let o = b.solve(&at).unwrap();
        let (truth, reduced) = outputs_at(&sys, &b, &l, &at, &o);
        let a = d.answer(&at, &o).unwrap();
        for j in 0..3 {
            let before = (truth[j] - reduced[j]).abs();
            let after = (truth[j] - reduced[j] - a.correction[j]).abs();
            // ψᵀ r = lᵀ e exactly when ψ_N = ψ: the corrected output is the full model's to
            // the round-off of the reduced sums.
            assert!(
                before > 1e-6 * truth[j].abs(),
                "component {j}: the basis must be inexact here ({before:.3e})"
            );
            assert!(
                after <= 1e-9 * before + 1e-13 * truth[j].abs(),
                "component {j}: corrected error {after:.3e}, uncorrected {before:.3e}"
            );
            assert!(
                after <= a.bound[j],
                "{after:.3e} > bound {:.3e}",
                a.bound[j]
            );
        }
        // With no snapshot (W = the adjoints at θ̄ alone) the same point is not exact.
        let only_theta_bar = dual::DualGreedy {
            tolerance: 0.0,
            rounds: 0,
            snapshot_accuracy: 0.0,
        };
        let mut cost0 = dual::DualCost::default();
        let d0 = dual::build(&ctx, &l, &z, &[], only_theta_bar, &mut cost0).unwrap();
        let a0 = d0.answer(&at, &o).unwrap();
        let worst0 = (0..3)
            .map(|j| (truth[j] - reduced[j] - a0.correction[j]).abs())
            .fold(0.0, f64::max);
        assert!(worst0 > 1e-6 * truth.iter().map(|t| t.abs()).fold(0.0, f64::max));
    }

    #[test]
    fn the_primal_dual_bound_holds_and_is_far_below_the_energy_norms() {
        let DualSetup {
            sys,
            th,
            b,
            l,
            z,
            x,
        } = dual_setup(5);
        let ctx = dual::DualContext {
            sys: &sys,
            x: &x,
            theta_bar: &th,
            primal: &b,
        };
        let mats = [tissue(30.0, 0.45), tissue(10.0, 0.47), tissue(2.0, 0.46)];
        let train: Vec<Vec<f64>> = (0..40).map(|i| box_point(&mats, i)).collect();
        let greedy = dual::DualGreedy {
            tolerance: 0.0,
            rounds: 3,
            snapshot_accuracy: 1e-3,
        };
        let mut cost = dual::DualCost::default();
        let d = dual::build(&ctx, &l, &z, &train, greedy, &mut cost).unwrap();
        assert_eq!(d.size(), 12);
        let g: Vec<f64> = d.greedy.iter().map(|s| s.1).collect();
        assert!(g[3] < 0.1 * g[0], "the dual greedy's bound falls: {g:?}");
        assert!(cost.cg_iterations > 0 && cost.full_factorisations == 0);
        // ‖l_j‖_X' : |lᵀ e| ≤ ‖l‖_X' ‖e‖_X ≤ ‖l‖_X' Δ, the energy norm's output bound.
        let dual_norms: Vec<f64> = l
            .iter()
            .zip(&z)
            .map(|(a, b)| basis::dot(a, b).sqrt())
            .collect();
        let mut ratios = Vec::new();
        for i in 200..220 {
            let t = box_point(&mats, i);
            let o = b.solve(&t).unwrap();
            let (truth, reduced) = outputs_at(&sys, &b, &l, &t, &o);
            let a = d.answer(&t, &o).unwrap();
            for j in 0..3 {
                let err = (truth[j] - reduced[j] - a.correction[j]).abs();
                assert!(
                    err <= a.bound[j],
                    "θ {i}, component {j}: corrected error {err:.3e} > bound {:.3e}",
                    a.bound[j]
                );
                ratios.push(a.bound[j] / (dual_norms[j] * o.energy_bound));
            }
        }
        // Far below the energy norm's output bound: a dual that corrected nothing would give
        // about 1 (‖r_du‖_X' ≈ ‖l‖_X').
        ratios.sort_by(f64::total_cmp);
        let (median, max) = (ratios[ratios.len() / 2], ratios[ratios.len() - 1]);
        assert!(
            median < 0.15 && max < 0.5,
            "primal–dual ÷ energy-norm bound: median {median:.3}, max {max:.3}"
        );
    }

    #[test]
    fn the_packed_face_is_the_sum_of_its_fields_and_skips_only_still_vertices() {
        // 7 vertices, 3 columns; vertices 1 and 4 still in every field, vertex 5 moved by a
        // column alone, vertex 6 by the lift alone.
        let v = |s: f64| [s, -2.0 * s, 0.5 * s];
        let still = |i: usize| i == 1 || i == 4;
        let lift: Vec<[f64; 3]> = (0..7)
            .map(|i| {
                if still(i) || i == 5 {
                    [0.0; 3]
                } else {
                    v(i as f64 + 1.0)
                }
            })
            .collect();
        let columns: Vec<Vec<[f64; 3]>> = (0..3)
            .map(|n| {
                (0..7)
                    .map(|i| {
                        if still(i) || i == 6 {
                            [0.0; 3]
                        } else {
                            v(0.3 * (n as f64 + 1.0) - 0.1 * i as f64)
                        }
                    })
                    .collect()
            })
            .collect();
        let face = LinearFace::new(lift, columns);
        assert_eq!(face.moving(), 5);
        let c = [0.7, -1.3, 2.1];
        let all = face.all(&c);
        for (i, d) in all.iter().enumerate() {
            // Written out: lift + Σ c_n column_n, independently of `at`.
            let want: [f64; 3] = std::array::from_fn(|k| {
                face.lift[i][k] + (0..3).map(|n| c[n] * face.columns[n][i][k]).sum::<f64>()
            });
            for k in 0..3 {
                assert!(
                    (d[k] - want[k]).abs() < 1e-14,
                    "vertex {i}: {d:?} vs {want:?}"
                );
            }
            assert_eq!(*d, face.at(i, &c));
        }
        assert_eq!(all[1], [0.0; 3]);
        assert_eq!(all[4], [0.0; 3]);
    }
}

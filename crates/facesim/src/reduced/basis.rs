//! The reduced basis: built by a greedy over a training set with the error bound as its
//! indicator, solved online in O(N³ + Q²N²) for any θ with a certified bound on the error in
//! the energy norm of the reference parameter θ̄ (Rozza, Huynh & Patera 2008 §4 and §6;
//! Quarteroni, Manzoni & Negri 2016 ch. 3 and 7).
//!
//! - X = A(θ̄), the inner product of the space; the basis is X-orthonormal.
//! - Online: A_N(θ) = Σ θ_q Vᵀ A_q V, f_N(θ) = Σ θ_q Vᵀ f_q, A_N c = f_N.
//! - The residual r(θ) = f(θ) − A(θ) V c has the dual norm ‖r‖_X' = ‖X⁻¹ r‖_X, and X⁻¹ r is a
//!   combination of the Riesz representers X⁻¹ f_q and X⁻¹ A_q v_n with weights (θ, −c θ)
//!   (Rozza et al. eq. 4.21–4.23). Those are kept in an X-orthonormal basis (Gram–Schmidt), so
//!   the norm is the Euclidean norm of T w: accurate to round-off in ‖r‖ itself, where the
//!   textbook quadratic form loses half the digits (Buhr, Engwer, Ohlberger & Rave 2014).
//! - Coercivity: every A_q is positive semi-definite and θ_q > 0, so
//!   vᵀ A(θ) v ≥ min_q (θ_q / θ̄_q) vᵀ X v: the min-θ lower bound α_LB(θ) (Rozza et al. §4.2.2).
//! - The bound: ‖u(θ) − V c‖_X ≤ Δ(θ) = ‖r(θ)‖_X' / α_LB(θ) (Rozza et al. Prop. 4.1).

use super::affine::{Affine, solve_columns};
use crate::error::{Error, NumericalKind, Result};
use crate::fem::cholesky::Cholesky;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// When the greedy stops: the largest relative bound Δ/‖u_N‖_X over the training set, or the
/// basis size.
#[derive(Clone, Copy, Debug)]
pub struct Greedy {
    pub tolerance: f64,
    pub max_size: usize,
    /// Snapshots added per step (the training points of the largest bounds, spread over the
    /// box): their conjugate-gradient solves share each solve with X's factor.
    pub batch: usize,
}

/// One step of the greedy: the basis size and the largest relative bound over the training
/// set with that basis (before the next snapshot).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GreedyStep {
    pub size: usize,
    pub max_relative_bound: f64,
    /// The parameter of the next snapshot (the training point of the largest bound).
    pub worst: Vec<f64>,
}

/// The reduced model on an [`Affine`] system.
pub struct Basis {
    /// X-orthonormal basis vectors (free values).
    pub vectors: Vec<Vec<f64>>,
    /// Everything the online solve and its bound need (and all a stored model keeps).
    pub form: OnlineForm,
    pub history: Vec<GreedyStep>,
    /// Factorisations of the full model the build took: X, and one per snapshot whose
    /// conjugate gradients did not converge (none so far).
    pub full_factorisations: usize,
    /// Solves with the factor of X (Riesz representers and the snapshots' preconditioner; a
    /// solve of several columns at once counts each column), the cheaper work.
    pub riesz_solves: usize,
    /// Conjugate-gradient iterations over the snapshots after the first (each a product with
    /// A(θ) and a preconditioner solve of its column).
    pub cg_iterations: usize,
    /// The X-orthonormal vectors (free values) the Riesz coordinates refer to: an output's
    /// images of them make its bound through the Riesz representer ([`super::OutputBound`]).
    /// Taken by the caller; node-sized, so dropped once those images are made.
    pub riesz_space: Vec<Vec<f64>>,
}

/// The online data of a reduced model: N×N and N-sized arrays, independent of the mesh size
/// (docs/design/reduced.md "The stored model"). Serialised into `reduced_model.bin` and the page.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OnlineForm {
    /// θ̄: the reference parameters, X = A(θ̄).
    pub theta_bar: Vec<f64>,
    /// Per term q: Vᵀ A_q V (N×N, row-major) and Vᵀ f_q.
    pub matrices: Vec<Vec<f64>>,
    pub loads: Vec<Vec<f64>>,
    /// The residual's Riesz representers in an X-orthonormal basis: column j holds the
    /// coordinates of X⁻¹ f_q (j = q) or X⁻¹ A_q v_n (j = Q + n Q + q); shorter columns are
    /// zero beyond their length.
    pub riesz: Vec<Vec<f64>>,
    /// ‖ρ_j‖_X (for the round-off floor).
    pub riesz_norms: Vec<f64>,
    /// The full model's free unknowns (for the round-off floor).
    pub unknowns: usize,
}

/// The answer at one θ: the coefficients and the certified bound.
#[derive(Clone, Debug)]
pub struct Online {
    pub coefficients: DVector<f64>,
    /// Δ(θ): the bound on ‖u − u_N‖_X.
    pub energy_bound: f64,
    /// ‖u_N‖_X.
    pub energy_norm: f64,
    /// ‖r(θ)‖_X', with its round-off floor.
    pub residual: f64,
    /// α_LB(θ) = min_q θ_q/θ̄_q and γ_UB(θ) = max_q θ_q/θ̄_q: the spectrum of X⁻¹A(θ) lies
    /// between them.
    pub alpha: f64,
    pub gamma: f64,
    /// X⁻¹ r(θ) in the X-orthonormal Riesz space's coordinates (its norm is the residual's
    /// without the floor), and the floor: what an output bound through the Riesz representer
    /// needs ([`super::OutputBound`]).
    pub coordinates: Vec<f64>,
    pub floor: f64,
}

impl Basis {
    /// The greedy over `train` from the snapshot at θ̄; with the factor of X (which must be in the box the training
    /// set spans, every entry positive).
    pub fn build(
        sys: &Affine,
        theta_bar: &[f64],
        train: &[Vec<f64>],
        greedy: Greedy,
        progress: &dyn Fn(&str),
    ) -> Result<(Basis, Cholesky<f64>)> {
        let q = sys.terms();
        if theta_bar.len() != q || theta_bar.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(Error::config(
                "reduced model: the reference parameters must be positive, one per term",
            ));
        }
        let x = sys.factor(theta_bar)?;
        // X's values, so that X v is one pass over the pattern (Gram–Schmidt needs four).
        let x_values = sys.values_at(theta_bar);
        let loads: Vec<Vec<f64>> = (0..q).map(|k| sys.load(k).to_vec()).collect();
        let mut basis = Basis {
            vectors: Vec::new(),
            form: OnlineForm {
                theta_bar: theta_bar.to_vec(),
                matrices: vec![Vec::new(); q],
                loads: vec![Vec::new(); q],
                riesz: Vec::new(),
                riesz_norms: Vec::new(),
                unknowns: sys.unknowns(),
            },
            history: Vec::new(),
            full_factorisations: 1,
            riesz_solves: q,
            cg_iterations: 0,
            riesz_space: Vec::new(),
        };
        // The X-orthonormal basis the Riesz coordinates refer to, needed only while the basis
        // grows (two vectors per term and basis vector: most of the build's memory).
        // Room for every vector the greedy can add (Q per basis vector and the Q loads): a
        // space grown block by block would be copied at each growth, twice its size at once.
        let columns = q * (greedy.max_size + greedy.batch.max(1) + 1);
        let mut space = RieszSpace {
            n: sys.unknowns(),
            e: Vec::with_capacity(columns * sys.unknowns()),
            xe: Vec::with_capacity(columns * sys.unknowns()),
        };
        basis.push_riesz(&mut space, &x, &loads);
        // The first snapshot: the solution at θ̄ itself.
        let mut snapshots = solve_columns(&x, &[sys.rhs(theta_bar)]);
        basis.riesz_solves += 1;
        loop {
            let grew = basis.add(sys, (&x, &x_values), &loads, &mut space, snapshots)?;
            if grew == 0 {
                break;
            }
            progress(&format!(
                "reduced model: basis of {} vectors",
                basis.vectors.len()
            ));
            let bounds: Vec<(usize, f64)> = train
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    let rel = basis.solve(t).as_ref().map_or(f64::INFINITY, |o| {
                        o.energy_bound / o.energy_norm.max(1e-300)
                    });
                    (i, rel)
                })
                .collect();
            let (worst, rel) = bounds.iter().fold((None, f64::NEG_INFINITY), |a, b| {
                if b.1 > a.1 { (Some(b.0), b.1) } else { a }
            });
            let worst = worst.map_or(theta_bar, |i| train[i].as_slice());
            basis.history.push(GreedyStep {
                size: basis.vectors.len(),
                max_relative_bound: rel,
                worst: worst.to_vec(),
            });
            if rel <= greedy.tolerance || basis.vectors.len() >= greedy.max_size {
                break;
            }
            let room = greedy.max_size - basis.vectors.len();
            let picked = pick(train, &bounds, greedy.batch.clamp(1, room));
            snapshots = basis.snapshots(sys, &x, &picked)?;
        }
        basis.riesz_space = space.into_columns();
        Ok((basis, x))
    }

    /// Add the Riesz representers X⁻¹ g of `g` to the space, and their coordinates and norms to
    /// the online form. The columns are solved in place in one matrix beside a copy of `g`:
    /// two blocks alive, not four.
    fn push_riesz(&mut self, space: &mut RieszSpace, x: &Cholesky<f64>, g: &[Vec<f64>]) {
        let Some(n) = g.first().map(Vec::len) else {
            return;
        };
        let mut gm = faer::Mat::<f64>::zeros(n, g.len());
        for (j, c) in g.iter().enumerate() {
            gm.col_as_slice_mut(j).copy_from_slice(c);
        }
        let mut rho = gm.clone();
        x.solve_in_place(rho.as_mut());
        for (coords, norm) in space.push(rho, gm) {
            self.form.riesz.push(coords);
            self.form.riesz_norms.push(norm);
        }
    }

    /// Orthonormalise each of `snapshots` against the basis in X (Gram–Schmidt twice) and add
    /// it with its reduced matrices and Riesz inner products; how many added something new.
    fn add(
        &mut self,
        sys: &Affine,
        (x, x_values): (&Cholesky<f64>, &[f64]),
        loads: &[Vec<f64>],
        space: &mut RieszSpace,
        snapshots: Vec<Vec<f64>>,
    ) -> Result<usize> {
        let q = sys.terms();
        let xu = |v: &[f64]| sys.apply_values(x_values, v);
        let mut av_all: Vec<Vec<f64>> = Vec::new();
        for mut u in snapshots {
            let norm0 = dot(&u, &xu(&u)).sqrt();
            for _ in 0..2 {
                let xv = xu(&u);
                for v in &self.vectors {
                    let p = dot(v, &xv);
                    for (a, b) in u.iter_mut().zip(v) {
                        *a -= p * b;
                    }
                }
            }
            let norm = dot(&u, &xu(&u)).sqrt();
            if !(norm > 1e-10 * norm0) || !norm.is_finite() {
                continue;
            }
            u.iter_mut().for_each(|a| *a /= norm);
            let n = self.vectors.len();
            let av: Vec<Vec<f64>> = (0..q).map(|k| sys.apply(k, &u)).collect();
            self.vectors.push(u);
            let m = n + 1;
            for (k, avk) in av.iter().enumerate() {
                let old = &self.form.matrices[k];
                let mut a = vec![0.0; m * m];
                for i in 0..n {
                    a[i * m..i * m + n].copy_from_slice(&old[i * n..(i + 1) * n]);
                }
                for (j, v) in self.vectors.iter().enumerate() {
                    let e = dot(v, avk);
                    a[n * m + j] = e;
                    a[j * m + n] = e;
                }
                self.form.matrices[k] = a;
                let f = dot(&self.vectors[n], &loads[k]);
                self.form.loads[k].push(f);
            }
            av_all.extend(av);
        }
        // One solve of all the new vectors' columns, one block Gram–Schmidt of them.
        let added = av_all.len() / q.max(1);
        self.riesz_solves += av_all.len();
        self.push_riesz(space, x, &av_all);
        Ok(added)
    }

    /// The full solutions at `points`, by conjugate gradients preconditioned with X's factor
    /// from the reduced solution, all points' preconditioner solves done at once. Each stops
    /// when its certified error ‖r‖_X' / α_LB(θ) is below [`SNAPSHOT_ACCURACY`] × the reduced
    /// model's own bound there: the snapshot is then accurate far beyond what the basis lacks
    /// at that point, and the bound of the basis it builds stays exact whatever the snapshot
    /// (it is computed from the full residual). A point that has not converged after
    /// [`CG_ITERATIONS`] is solved with its own factorisation.
    fn snapshots(
        &mut self,
        sys: &Affine,
        x: &Cholesky<f64>,
        points: &[&[f64]],
    ) -> Result<Vec<Vec<f64>>> {
        let mut problems = Vec::with_capacity(points.len());
        let mut at = Vec::with_capacity(points.len());
        for (i, t) in points.iter().enumerate() {
            // A point the reduced system cannot answer (not positive definite in round-off)
            // has no start and no bound to stop at: it is factorised below.
            let Ok(o) = self.solve(t) else { continue };
            problems.push(Problem {
                theta: t,
                rhs: sys.rhs(t),
                start: self.expand(&o.coefficients),
                alpha: o.alpha,
                tolerance: SNAPSHOT_ACCURACY * o.energy_bound,
            });
            at.push(i);
        }
        let solved = conjugate_gradients(sys, x, problems);
        self.cg_iterations += solved.iterations;
        self.riesz_solves += solved.preconditioner_solves;
        let mut out: Vec<Option<Vec<f64>>> = vec![None; points.len()];
        for (i, u) in at.into_iter().zip(solved.solutions) {
            out[i] = u;
        }
        out.into_iter()
            .zip(points)
            .map(|(u, t)| match u {
                Some(u) => Ok(u),
                None => {
                    self.full_factorisations += 1;
                    solve_factorised(sys, t, &sys.rhs(t))
                }
            })
            .collect()
    }

    /// N.
    pub fn size(&self) -> usize {
        self.vectors.len()
    }

    /// The reduced solution at θ and its bound (θ positive, one per term).
    pub fn solve(&self, theta: &[f64]) -> Result<Online> {
        self.form.solve(theta)
    }

    /// The free values V c.
    pub(crate) fn expand(&self, c: &DVector<f64>) -> Vec<f64> {
        let mut u = vec![0.0; self.vectors.first().map_or(0, Vec::len)];
        for (v, w) in self.vectors.iter().zip(c.iter()) {
            for (a, b) in u.iter_mut().zip(v) {
                *a += w * b;
            }
        }
        u
    }
}

impl OnlineForm {
    /// N.
    pub fn size(&self) -> usize {
        self.loads.first().map_or(0, Vec::len)
    }

    /// Q.
    pub fn terms(&self) -> usize {
        self.theta_bar.len()
    }

    /// The reduced solution at θ and its bound (θ positive, one per term).
    pub fn solve(&self, theta: &[f64]) -> Result<Online> {
        let q = self.terms();
        let n = self.size();
        if theta.len() != q || theta.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(Error::config(format!(
                "reduced model: parameters {theta:?} are not {q} positive values"
            )));
        }
        let mut a = DMatrix::zeros(n, n);
        let mut f = DVector::zeros(n);
        for k in 0..q {
            a += DMatrix::from_row_slice(n, n, &self.matrices[k]) * theta[k];
            f += DVector::from_column_slice(&self.loads[k]) * theta[k];
        }
        let c = a
            .cholesky()
            .ok_or_else(|| {
                Error::numerical(
                    NumericalKind::Singular,
                    "the reduced system is not positive definite",
                )
            })?
            .solve(&f);
        // X⁻¹ r = Σ_j w_j ρ_j with w = (θ, −c_n θ_q).
        let w: Vec<f64> = theta
            .iter()
            .copied()
            .chain((0..n * q).map(|i| -c[i / q] * theta[i % q]))
            .collect();
        let (coordinates, floor) = self.residual_coordinates(&w);
        let residual = dot(&coordinates, &coordinates).sqrt() + floor;
        let ratios = theta.iter().zip(&self.theta_bar).map(|(t, b)| t / b);
        let alpha = ratios.clone().fold(f64::INFINITY, f64::min);
        let gamma = ratios.fold(0.0, f64::max);
        Ok(Online {
            energy_norm: c.norm(),
            coefficients: c,
            residual,
            energy_bound: residual / alpha,
            alpha,
            gamma,
            coordinates,
            floor,
        })
    }

    /// The coordinates of Σ_j w_j ρ_j and their round-off ([`riesz_combination`]).
    fn residual_coordinates(&self, w: &[f64]) -> (Vec<f64>, f64) {
        riesz_combination(&self.riesz, &self.riesz_norms, self.unknowns, w)
    }

    /// Whether the arrays have the sizes N and Q imply (a stored model is checked on read).
    pub fn consistent(&self) -> bool {
        let (n, q) = (self.size(), self.terms());
        self.matrices.len() == q
            && self.loads.len() == q
            && self.matrices.iter().all(|m| m.len() == n * n)
            && self.loads.iter().all(|f| f.len() == n)
            && self.riesz.len() == q * (n + 1)
            && self.riesz_norms.len() == q * (n + 1)
            && self.riesz.iter().all(|c| c.len() <= q * (n + 1))
            && self.theta_bar.iter().all(|t| *t > 0.0 && t.is_finite())
    }
}

/// The X-orthonormal vectors e_i that Riesz representers ρ_j are kept in as coordinates
/// (ρ_j = Σ_i t_ij e_i), with X e_i to take inner products of new vectors without applying X;
/// each stored column after column in one array (n × k, column-major), so that a block of new
/// vectors meets all of them in matrix products.
pub(super) struct RieszSpace {
    n: usize,
    e: Vec<f64>,
    xe: Vec<f64>,
}

impl RieszSpace {
    /// An empty space of vectors of `n` values.
    pub(super) fn new(n: usize) -> RieszSpace {
        RieszSpace {
            n,
            e: Vec::new(),
            xe: Vec::new(),
        }
    }

    fn len(&self) -> usize {
        self.e.len().checked_div(self.n).unwrap_or(0)
    }

    /// The vectors e_i, one per column.
    fn into_columns(self) -> Vec<Vec<f64>> {
        if self.n == 0 {
            return Vec::new();
        }
        self.e.chunks(self.n).map(<[f64]>::to_vec).collect()
    }

    /// Add each ρ (a column of `r`) with X ρ = g (that column of `gm`), in order: its
    /// coordinates and ‖ρ‖_X. Classical Gram–Schmidt twice against the vectors already there,
    /// as matrix products, then twice against the block's own earlier columns; a direction
    /// already spanned adds no new e. The products use the current thread pool
    /// (`Prediction::reduced` gives each of several builds its own).
    pub(super) fn push(
        &mut self,
        mut r: faer::Mat<f64>,
        mut gm: faer::Mat<f64>,
    ) -> Vec<(Vec<f64>, f64)> {
        use faer::{Mat, MatRef};
        let (n, m) = (self.n, r.ncols());
        let norm0: Vec<f64> = (0..m)
            .map(|j| dot(r.col_as_slice(j), gm.col_as_slice(j)).max(0.0).sqrt())
            .collect();
        let old = self.len();
        let mut coords = Mat::<f64>::zeros(old, m);
        if old > 0 {
            let e = MatRef::from_column_major_slice(&self.e, n, old);
            let xe = MatRef::from_column_major_slice(&self.xe, n, old);
            for _ in 0..2 {
                coords += sweep((e, xe), (r.as_mut(), gm.as_mut()));
            }
        }
        // The block's own Gram–Schmidt, in place in its columns (a rejected one zeroed); the
        // accepted ones are then appended to the space at once.
        let mut accepted: Vec<usize> = Vec::new();
        let mut out = Vec::with_capacity(m);
        for (j, norm0) in norm0.into_iter().enumerate() {
            let mut c: Vec<f64> = (0..old).map(|i| coords[(i, j)]).collect();
            let mut p = Mat::<f64>::zeros(j, 1);
            for _ in 0..2 {
                let (rl, mut rr) = r.as_mut().split_at_col_mut(j);
                let (gl, mut gr) = gm.as_mut().split_at_col_mut(j);
                p += sweep(
                    (rl.as_ref(), gl.as_ref()),
                    (rr.as_mut().subcols_mut(0, 1), gr.as_mut().subcols_mut(0, 1)),
                );
            }
            c.extend(accepted.iter().map(|a| p[(*a, 0)]));
            let rho = r.col_as_slice_mut(j);
            let rest = dot(rho, gm.col_as_slice(j)).max(0.0).sqrt();
            if rest > 1e-12 * norm0 {
                rho.iter_mut().for_each(|a| *a /= rest);
                gm.col_as_slice_mut(j).iter_mut().for_each(|a| *a /= rest);
                accepted.push(j);
                c.push(rest);
            } else {
                rho.fill(0.0);
                gm.col_as_slice_mut(j).fill(0.0);
            }
            out.push((c, norm0));
        }
        for &a in &accepted {
            self.e.extend_from_slice(r.col_as_slice(a));
            self.xe.extend_from_slice(gm.col_as_slice(a));
        }
        out
    }
}

/// One classical Gram–Schmidt sweep of the columns of `r` (X images `g`) against the
/// X-orthonormal columns of `e` (X images `xe`): P = eᵀ g = (r, e)_X, r −= e P, g −= xe P;
/// returns P.
fn sweep(
    (e, xe): (faer::MatRef<'_, f64>, faer::MatRef<'_, f64>),
    (mut r, mut g): (faer::MatMut<'_, f64>, faer::MatMut<'_, f64>),
) -> faer::Mat<f64> {
    use faer::{Accum, Mat, Par, linalg::matmul::matmul};
    let par = Par::rayon(0);
    let mut p = Mat::<f64>::zeros(e.ncols(), r.ncols());
    matmul(
        p.as_mut(),
        Accum::Replace,
        e.transpose(),
        g.as_ref(),
        1.0,
        par,
    );
    matmul(r.as_mut(), Accum::Add, e, p.as_ref(), -1.0, par);
    matmul(g.as_mut(), Accum::Add, xe, p.as_ref(), -1.0, par);
    p
}

/// A snapshot's certified error, relative to the reduced model's bound at its point, at which
/// its conjugate gradients stop. The bound overestimates the basis's true error 10–50×
/// (docs/design/reduced.md), so this keeps the snapshot's error well below it.
pub(super) const SNAPSHOT_ACCURACY: f64 = 1e-3;

/// Conjugate-gradient iterations before a snapshot falls back to its own factorisation. The
/// preconditioned iteration divides the error by about 2 each (the parameter box's moduli
/// span a condition number of X⁻¹ A(θ) of order 10); 30 iterations is twice what the real CT needs.
pub(super) const CG_ITERATIONS: usize = 30;

/// Up to `count` training points to add as snapshots: the largest bound first, then the next
/// largest that lie apart from those picked (a quarter of the box's diagonal in log θ), so one
/// step does not spend its snapshots on one corner of the box.
fn pick<'a>(train: &'a [Vec<f64>], bounds: &[(usize, f64)], count: usize) -> Vec<&'a [f64]> {
    let q = train.first().map_or(0, Vec::len);
    let (lo, hi) = train.iter().fold(
        (vec![f64::INFINITY; q], vec![f64::NEG_INFINITY; q]),
        |(mut lo, mut hi), t| {
            for (k, v) in t.iter().enumerate() {
                lo[k] = lo[k].min(v.ln());
                hi[k] = hi[k].max(v.ln());
            }
            (lo, hi)
        },
    );
    let at = |t: &[f64]| -> Vec<f64> {
        t.iter()
            .enumerate()
            .map(|(k, v)| {
                let w = hi[k] - lo[k];
                if w > 0.0 { (v.ln() - lo[k]) / w } else { 0.0 }
            })
            .collect()
    };
    let spread = (q as f64).sqrt() * 0.25;
    let mut order: Vec<&(usize, f64)> = bounds.iter().collect();
    order.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut picked: Vec<(&'a [f64], Vec<f64>)> = Vec::new();
    for (i, _) in order {
        if picked.len() == count {
            break;
        }
        let y = at(&train[*i]);
        let apart = picked.iter().all(|(_, z)| {
            y.iter()
                .zip(z)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
                >= spread
        });
        if apart {
            picked.push((&train[*i], y));
        }
    }
    picked.into_iter().map(|(t, _)| t).collect()
}

/// One system A(θ) u = b for [`conjugate_gradients`]: its start, α_LB(θ) and the certified
/// error ‖u − u_k‖_X ≤ ‖r_k‖_X' / α_LB at which it stops.
pub(super) struct Problem<'a> {
    pub theta: &'a [f64],
    pub rhs: Vec<f64>,
    pub start: Vec<f64>,
    pub alpha: f64,
    pub tolerance: f64,
}

/// What [`conjugate_gradients`] did: per problem its solution (None: not converged in
/// [`CG_ITERATIONS`]), the iterations (products with A(θ)) and the preconditioner solves.
pub(super) struct Solved {
    pub solutions: Vec<Option<Vec<f64>>>,
    pub iterations: usize,
    pub preconditioner_solves: usize,
}

/// Conjugate gradients on each A(θ) u = b, preconditioned with X's factor: the preconditioned
/// operator X⁻¹A(θ) has its spectrum in [α_LB, γ_UB], so the rate is set by the parameter box,
/// not by the mesh. The problems still iterating share one block solve with X's factor per
/// iteration. Each stops when ‖r‖_X' / α_LB(θ) (‖r‖_X' = √(rᵀ X⁻¹ r), which the iteration
/// computes) is below its tolerance.
pub(super) fn conjugate_gradients(
    sys: &Affine,
    x: &Cholesky<f64>,
    problems: Vec<Problem>,
) -> Solved {
    struct Column {
        at: usize,
        /// Its θ's place in `values`: the components of one output share a θ, so A(θ)'s values
        /// and each product's pass over them.
        group: usize,
        u: Vec<f64>,
        r: Vec<f64>,
        p: Vec<f64>,
        rz: f64,
        alpha: f64,
        tol: f64,
    }
    impl Column {
        fn converged(&self) -> bool {
            self.rz.max(0.0).sqrt() / self.alpha <= self.tol
        }
    }
    let mut solved = Solved {
        solutions: vec![None; problems.len()],
        iterations: 0,
        preconditioner_solves: 0,
    };
    let mut thetas: Vec<&[f64]> = Vec::new();
    let mut values: Vec<Vec<f64>> = Vec::new();
    let mut cols: Vec<Column> = problems
        .into_iter()
        .enumerate()
        .map(|(at, p)| {
            let group = match thetas.iter().position(|t| *t == p.theta) {
                Some(g) => g,
                None => {
                    thetas.push(p.theta);
                    values.push(sys.values_at(p.theta));
                    values.len() - 1
                }
            };
            let au = sys.apply_values(&values[group], &p.start);
            let r = p.rhs.iter().zip(&au).map(|(b, a)| b - a).collect();
            Column {
                at,
                group,
                u: p.start,
                r,
                p: Vec::new(),
                rz: 0.0,
                alpha: p.alpha,
                tol: p.tolerance,
            }
        })
        .collect();
    let precondition = |cols: &[Column], solves: &mut usize| {
        let rs: Vec<Vec<f64>> = cols.iter().map(|c| c.r.clone()).collect();
        *solves += rs.len();
        solve_columns(x, &rs)
    };
    let zs = precondition(&cols, &mut solved.preconditioner_solves);
    for (c, z) in cols.iter_mut().zip(zs) {
        c.rz = dot(&c.r, &z);
        c.p = z;
    }
    for _ in 0..CG_ITERATIONS {
        let (done, going): (Vec<Column>, Vec<Column>) =
            cols.into_iter().partition(Column::converged);
        for c in done {
            solved.solutions[c.at] = Some(c.u);
        }
        cols = going;
        if cols.is_empty() {
            break;
        }
        let jobs: Vec<(usize, &[f64])> = cols.iter().map(|c| (c.group, c.p.as_slice())).collect();
        let aps = products(sys, &values, &jobs);
        for (c, ap) in cols.iter_mut().zip(aps) {
            let a = c.rz / dot(&c.p, &ap);
            c.u.iter_mut().zip(&c.p).for_each(|(x, y)| *x += a * y);
            c.r.iter_mut().zip(&ap).for_each(|(x, y)| *x -= a * y);
            solved.iterations += 1;
        }
        let zs = precondition(&cols, &mut solved.preconditioner_solves);
        for (c, z) in cols.iter_mut().zip(zs) {
            let rz = dot(&c.r, &z);
            let beta = rz / c.rz;
            c.rz = rz;
            c.p.iter_mut().zip(&z).for_each(|(x, y)| *x = y + beta * *x);
        }
    }
    for c in cols.into_iter().filter(Column::converged) {
        solved.solutions[c.at] = Some(c.u);
    }
    solved
}

/// A(θ) p for each (θ's group, an index into `values`; p) of `jobs`: one pass over a group's
/// values for all its vectors.
fn products(sys: &Affine, values: &[Vec<f64>], jobs: &[(usize, &[f64])]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::new(); jobs.len()];
    for (g, v) in values.iter().enumerate() {
        let members: Vec<usize> = (0..jobs.len()).filter(|i| jobs[*i].0 == g).collect();
        if members.is_empty() {
            continue;
        }
        let xs: Vec<&[f64]> = members.iter().map(|i| jobs[*i].1).collect();
        for (i, y) in members.iter().zip(sys.apply_values_many(v, &xs)) {
            out[*i] = y;
        }
    }
    out
}

/// A(θ) u = b with A(θ)'s own factorisation: a problem whose conjugate gradients did not
/// converge.
pub(super) fn solve_factorised(sys: &Affine, theta: &[f64], b: &[f64]) -> Result<Vec<f64>> {
    let k = sys.factor(theta)?;
    Ok(solve_columns(&k, &[b.to_vec()]).remove(0))
}

pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The coordinates of Σ_j w_j ρ_j, a residual's Riesz representer from the Riesz columns ρ_j
/// (`riesz`, of norms `norms` in the X-norm), and their round-off in the X-norm: the
/// coordinates carry ε ‖ρ_j‖ per unknown summed (Higham 2002 §3.1, γ_n), so the floor is
/// n ε Σ |w_j| ‖ρ_j‖_X with n the full model's `unknowns`. Columns of weight 0 are skipped
/// (a landmark's dual residual weighs one output column of several).
pub(super) fn riesz_combination(
    riesz: &[Vec<f64>],
    norms: &[f64],
    unknowns: usize,
    w: &[f64],
) -> (Vec<f64>, f64) {
    let rows = riesz.iter().map(Vec::len).max().unwrap_or(0);
    let mut y = vec![0.0; rows];
    let mut floor = 0.0;
    for ((wj, col), norm) in w.iter().zip(riesz).zip(norms) {
        if *wj == 0.0 {
            continue;
        }
        for (a, b) in y.iter_mut().zip(col) {
            *a += wj * b;
        }
        floor += wj.abs() * norm;
    }
    (y, unknowns as f64 * f64::EPSILON * floor)
}

#[cfg(test)]
mod tests {
    use super::pick;

    #[test]
    fn a_batch_takes_the_largest_bounds_that_lie_apart() {
        // Three points in one corner of the box (bounds 10, 9, 8) and one far (bound 1).
        let train = vec![
            vec![1.0, 1.0],
            vec![1.05, 1.0],
            vec![1.0, 1.05],
            vec![10.0, 10.0],
            vec![1.0, 10.0],
        ];
        let bounds = [(0, 10.0), (1, 9.0), (2, 8.0), (3, 1.0), (4, 0.5)];
        let got = pick(&train, &bounds, 2);
        assert_eq!(got, [&train[0][..], &train[3][..]]);
        let got = pick(&train, &bounds, 3);
        assert_eq!(got, [&train[0][..], &train[3][..], &train[4][..]]);
        assert_eq!(pick(&train, &bounds, 1), [&train[0][..]]);
    }
}

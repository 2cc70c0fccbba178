//! Conjugate gradients preconditioned by a two-level p-multigrid cycle: the solve of a
//! quadratic (10-node) tetrahedral model too large for its Cholesky factor
//! (`fem::assembly::MAX_FACTOR_BYTES`).
//!
//! The coarse space is the linear (4-node) field on the corner nodes, embedded exactly in the
//! quadratic one: the prolongation P carries each corner's DOFs to itself and gives each edge
//! midpoint the mean of its two corners (a linear field is its own quadratic interpolant), in
//! each node's own frame with its held components dropped (the caller's [`Transfer`]). The
//! coarse operator is the Galerkin product A_c = Pᵀ A P, on the linear stiffness's pattern,
//! factored once with the sparse Cholesky (fem/cholesky.rs) and kept in f32 (`CoarseFactor`):
//! it is a tenth of the fine problem on the real CT. The fine level is smoothed by Chebyshev
//! polynomials in the 3×3 node-block Jacobi preconditioned operator D⁻¹A.
//!
//! One cycle, from a residual r (symmetric, so an admissible CG preconditioner; Tatebe 1993,
//! "The multigrid preconditioned conjugate gradient method"):
//!   x₁ = S r, x₂ = x₁ + P A_c⁻¹ Pᵀ (r − A x₁), x = x₂ + S (r − A x₂),
//! S the Chebyshev smoother, a fixed polynomial in D⁻¹A times D⁻¹ (symmetric). The two-level
//! theory of the Galerkin coarse space (Hackbusch 1985, ch. 7; for p-multigrid on simplices
//! Rønquist & Patera 1987, Helenbrook, Mavriplis & Atkins 2003) bounds the iterations
//! independently of the mesh size.
//!
//! Smoother: Chebyshev of degree 4 over [λ_max/30, 1.1 λ_max] of D⁻¹A (Adams, Brezina, Hu &
//! Tuminaro 2003, "Parallel multigrid smoothing: polynomial versus Gauss–Seidel"): symmetric by
//! construction, built from products alone (no sweep order, so it runs on every core, where a
//! symmetric Gauss–Seidel sweep is sequential and needs the matrix by rows and by columns,
//! which the lower block triangle stored here gives only by columns). The interval is Adams et
//! al.'s usual one. The degree is chosen by time to solution: on the 10-node real CT, degrees
//! 2, 3 and 4 take 36, 27 and 22 iterations to 1e-10, and degree 4 the least time, as on the
//! jaws sample, where 3 and 4 tie (docs/lab/performance.md "The coarse solve in f32").
//!
//! Held DOFs: the operator is given on every DOF, and `free` marks the unknowns; the iterates
//! are zero on the others and products are taken with them zeroed, so A below is the free–free
//! block.

use super::assembly::System;
use super::block_sparse::{
    Block, Partials, SymmetricBlocks, column, congruence, interleave, times, transposed,
};
use super::cholesky::{Cholesky, Ordering};
use crate::error::{Error, NumericalKind, Result};
use rayon::prelude::*;

/// PCG stops at ‖b − A x‖ ≤ TOLERANCE ‖b‖: the displacement then equals the direct solve's to
/// about 1e-9 relative on the test meshes (fem/pmultigrid.rs tests, tet/quadratic.rs tests),
/// below the 1e-6 a face needs.
pub(crate) const TOLERANCE: f64 = 1e-10;
/// Iterations before the solve is refused as not converging (the real CT takes tens).
pub(crate) const MAX_ITERATIONS: usize = 2000;
/// The Chebyshev smoother's degree and the lower end of its interval (a fraction of λ_max).
const DEGREE: usize = 4;
const SMOOTHED_FRACTION: f64 = 1.0 / 30.0;
/// Power iterations for λ_max(D⁻¹A) and the safety factor on the estimate (from below).
const POWER_ITERATIONS: usize = 20;
const LAMBDA_SAFETY: f64 = 1.1;

/// A fine node's coarse parents: one or two (coarse node, 3×3 map from the coarse node's DOFs
/// to the fine node's, row-major).
#[derive(Clone, Copy)]
pub(crate) struct Parents {
    count: u8,
    of: [(u32, Block); 2],
}

impl Parents {
    pub(crate) fn one(a: u32, s: Block) -> Parents {
        Parents {
            count: 1,
            of: [(a, s), (a, [0.0; 9])],
        }
    }

    pub(crate) fn two(a: u32, sa: Block, b: u32, sb: Block) -> Parents {
        Parents {
            count: 2,
            of: [(a, sa), (b, sb)],
        }
    }

    fn all(&self) -> &[(u32, Block)] {
        &self.of[..self.count as usize]
    }
}

/// The prolongation P from the coarse DOFs (3 per coarse node) to the fine ones, by fine node,
/// and which coarse DOFs are unknowns.
pub(crate) struct Transfer {
    pub(crate) parents: Vec<Parents>,
    pub(crate) coarse_free: Vec<bool>,
}

impl Transfer {
    fn coarse_nodes(&self) -> usize {
        self.coarse_free.len() / 3
    }

    /// P x_c.
    #[cfg(test)]
    pub(crate) fn prolong(&self, xc: &[f64]) -> Vec<f64> {
        self.prolong_many(xc, 1)
    }

    /// P X_c for k vectors interleaved (entry (DOF d, vector v) at d k + v).
    #[cfg(test)]
    fn prolong_many(&self, xc: &[f64], k: usize) -> Vec<f64> {
        let mut x = vec![0.0; 3 * k * self.parents.len()];
        self.add_prolonged(xc, k, &mut x);
        x
    }

    /// x += P X_c for k vectors interleaved.
    fn add_prolonged(&self, xc: &[f64], k: usize, x: &mut [f64]) {
        x.par_chunks_mut(3 * k)
            .zip(self.parents.par_iter())
            .for_each(|(xi, p)| {
                for (a, s) in p.all() {
                    let xa = &xc[3 * k * *a as usize..3 * k * (*a as usize + 1)];
                    for r in 0..3 {
                        for v in 0..k {
                            xi[r * k + v] += s[3 * r] * xa[v]
                                + s[3 * r + 1] * xa[k + v]
                                + s[3 * r + 2] * xa[2 * k + v];
                        }
                    }
                }
            });
    }

    /// Pᵀ R for k vectors interleaved.
    fn restrict_many(&self, r: &[f64], k: usize) -> Vec<f64> {
        let mut rc = vec![0.0; self.coarse_free.len() * k];
        for (i, p) in self.parents.iter().enumerate() {
            let ri = &r[3 * k * i..3 * k * (i + 1)];
            for (a, s) in p.all() {
                let ra = &mut rc[3 * k * *a as usize..3 * k * (*a as usize + 1)];
                for c in 0..3 {
                    for v in 0..k {
                        ra[c * k + v] +=
                            s[c] * ri[v] + s[3 + c] * ri[k + v] + s[6 + c] * ri[2 * k + v];
                    }
                }
            }
        }
        rc
    }

    /// Pᵀ A P on the coarse pattern `pairs` (coarse node pairs, row ≥ column, that share a fine
    /// element; every pair a fine block's parents make must be among them).
    pub(crate) fn galerkin<I: Iterator<Item = (usize, usize)>>(
        &self,
        fine: &SymmetricBlocks,
        pairs: impl Fn() -> I,
    ) -> Result<SymmetricBlocks> {
        let mut coarse = SymmetricBlocks::with_pairs(self.coarse_nodes(), pairs);
        let mut missing = None;
        let mut add = |a: usize, b: usize, m: Block| match coarse.block_mut(a, b) {
            Some(blk) => blk.iter_mut().zip(m).for_each(|(x, y)| *x += y),
            None => missing = Some((a, b)),
        };
        fine.for_each(|i, j, aij| {
            let (pi, pj) = (self.parents[i].all(), self.parents[j].all());
            for (a, sa) in pi {
                for (b, sb) in pj {
                    let (a, b) = (*a as usize, *b as usize);
                    let c = congruence(sa, aij, sb);
                    if i == j {
                        // The diagonal block holds both orders of each parent pair.
                        if a >= b {
                            add(a, b, c);
                        }
                    } else if a > b {
                        add(a, b, c);
                    } else if a < b {
                        add(b, a, transposed(&c));
                    } else {
                        let t = transposed(&c);
                        add(a, a, std::array::from_fn(|e| c[e] + t[e]));
                    }
                }
            }
        });
        match missing {
            Some((a, b)) => Err(Error::numerical(
                NumericalKind::Singular,
                format!("p-multigrid: coarse nodes {a} and {b} couple outside the coarse pattern"),
            )),
            None => Ok(coarse),
        }
    }
}

/// The Chebyshev smoother in D⁻¹A (D the free part of each node's diagonal block).
struct Smoother {
    /// Per node, the inverse of its diagonal block on its free DOFs (zero on the held ones).
    inverse: Vec<Block>,
    lo: f64,
    hi: f64,
}

impl Smoother {
    fn new(level: &Operator) -> Result<Smoother> {
        let inverse = (0..level.a.nodes())
            .map(|i| masked_inverse(level.a.diagonal(i), &level.free[3 * i..3 * i + 3]))
            .collect::<Option<Vec<Block>>>()
            .ok_or_else(|| {
                Error::numerical(
                    NumericalKind::Singular,
                    "p-multigrid: a node's stiffness block is singular on its free DOFs",
                )
            })?;
        let mut s = Smoother {
            inverse,
            lo: 0.0,
            hi: 1.0,
        };
        // λ_max(D⁻¹A) by power iteration from a fixed start (estimates from below).
        let mut v: Vec<f64> = (0..level.free.len())
            .map(|i| {
                if level.free[i] {
                    1.0 + 0.5 * ((i as f64) * 0.618_033_988_7).fract()
                } else {
                    0.0
                }
            })
            .collect();
        let (mut av, mut w) = (vec![0.0; v.len()], vec![0.0; v.len()]);
        let mut partials = Partials::default();
        let mut lambda = 0.0;
        for _ in 0..POWER_ITERATIONS {
            level.cycle_product(&v, 1, &mut av, &mut partials);
            s.jacobi(&av, 1, &mut w);
            let (nw, nv) = (norm(&w), norm(&v));
            if !(nw > 0.0 && nv > 0.0) {
                break;
            }
            lambda = nw / nv;
            v.iter_mut().zip(&w).for_each(|(v, w)| *v = w / nw);
        }
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(Error::numerical(
                NumericalKind::Singular,
                "p-multigrid: the smoother's spectrum estimate failed",
            ));
        }
        s.hi = LAMBDA_SAFETY * lambda;
        s.lo = SMOOTHED_FRACTION * s.hi;
        Ok(s)
    }

    /// z = D⁻¹ R for k vectors interleaved (zero on the held DOFs).
    fn jacobi(&self, r: &[f64], k: usize, z: &mut [f64]) {
        z.par_chunks_mut(3 * k)
            .zip(r.par_chunks(3 * k))
            .zip(self.inverse.par_iter())
            .for_each(|((z, r), m)| {
                for a in 0..3 {
                    for v in 0..k {
                        z[a * k + v] =
                            m[3 * a] * r[v] + m[3 * a + 1] * r[k + v] + m[3 * a + 2] * r[2 * k + v];
                    }
                }
            });
    }

    /// x = the Chebyshev iteration for A x = r from x = 0, `DEGREE` steps (Saad, "Iterative
    /// methods for sparse linear systems", 2nd ed., Algorithm 12.1, preconditioned by D), for
    /// k right-hand sides interleaved (the same polynomial for each); x is zero on the held
    /// DOFs.
    fn smooth(&self, level: &Operator, r: &[f64], k: usize, x: &mut [f64], w: &mut SmoothWork) {
        let n = r.len();
        let (res, d, ad) = (&mut w.res[..n], &mut w.d[..n], &mut w.ad[..n]);
        let theta = 0.5 * (self.hi + self.lo);
        let delta = 0.5 * (self.hi - self.lo);
        let sigma = theta / delta;
        let mut rho = 1.0 / sigma;
        self.jacobi(r, k, d);
        d.par_iter_mut().for_each(|d| *d /= theta);
        x.copy_from_slice(d);
        res.copy_from_slice(r);
        for _ in 1..DEGREE {
            level.cycle_product(d, k, ad, &mut w.partials);
            res.par_iter_mut().zip(&*ad).for_each(|(r, a)| *r -= a);
            let rho_next = 1.0 / (2.0 * sigma - rho);
            // D⁻¹ res into ad, whose product is spent.
            self.jacobi(res, k, ad);
            d.par_iter_mut().zip(&*ad).for_each(|(d, z)| {
                *d = rho_next * rho * *d + 2.0 * rho_next / delta * z;
            });
            x.par_iter_mut().zip(&*d).for_each(|(x, d)| *x += d);
            rho = rho_next;
        }
    }
}

/// The smoother's work vectors (each for the largest batch), kept across the cycles.
struct SmoothWork {
    res: Vec<f64>,
    d: Vec<f64>,
    ad: Vec<f64>,
    partials: Partials,
}

/// The cycle's work vectors.
struct CycleWork {
    smooth: SmoothWork,
    t1: Vec<f64>,
    t2: Vec<f64>,
}

impl CycleWork {
    /// For k vectors of n DOFs.
    fn new(n: usize, k: usize) -> CycleWork {
        let v = || vec![0.0; n * k];
        CycleWork {
            smooth: SmoothWork {
                res: v(),
                d: v(),
                ad: v(),
                partials: Partials::default(),
            },
            t1: v(),
            t2: v(),
        }
    }
}

/// The inverse of `b` on the DOFs `free` marks (zero rows and columns on the others), or None
/// when that part is singular.
fn masked_inverse(b: &Block, free: &[bool]) -> Option<Block> {
    let m = nalgebra::Matrix3::from_fn(|r, c| {
        if free[r] && free[c] {
            b[3 * r + c]
        } else if r == c {
            1.0
        } else {
            0.0
        }
    });
    let inv = m.try_inverse()?;
    Some(std::array::from_fn(|e| {
        let (r, c) = (e / 3, e % 3);
        if free[r] && free[c] { inv[(r, c)] } else { 0.0 }
    }))
}

/// Whether every DOF `inner` marks is marked in `outer`.
fn covers(outer: &[bool], inner: &[bool]) -> bool {
    outer.len() == inner.len() && outer.iter().zip(inner).all(|(o, i)| *o || !*i)
}

fn norm(v: &[f64]) -> f64 {
    v.par_iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// The coarse level's factor, its entries rounded to f32, and its unknowns. The factor is made
/// in f64 and rounded once: L₃₂ L₃₂ᵀ is still symmetric positive definite, so the cycle stays
/// an admissible preconditioner, and the rounding (relative 6e-8) is far below the two-level
/// cycle's own error: the iterations to 1e-10 were the same to the one on the real CT's and
/// the jaws' 10-node runs (docs/lab/performance.md "The coarse solve in f32"). The sweeps read
/// half the bytes, and the factor kept is half the size.
struct CoarseFactor {
    /// The coarse DOFs that are unknowns, in the factor's column order.
    free: Vec<usize>,
    llt: Cholesky<f32>,
}

impl CoarseFactor {
    fn new(system: System) -> CoarseFactor {
        let (free, llt) = system.into_factor();
        CoarseFactor {
            free,
            llt: llt.to_f32(),
        }
    }

    /// A_c⁻¹ R for k vectors interleaved over every coarse DOF (zero on the held ones). The
    /// columns are split between two threads: a triangular sweep runs on one core, and the
    /// cycle has nothing else to do meanwhile.
    fn solve(&self, r: &[f64], k: usize) -> Vec<f64> {
        let half = k / 2;
        let (a, b) = rayon::join(
            || self.solve_columns(r, k, 0..half),
            || self.solve_columns(r, k, half..k),
        );
        let mut x = vec![0.0; r.len()];
        for (part, cols) in [(a, 0..half), (b, half..k)] {
            let m = cols.len();
            for (i, &g) in self.free.iter().enumerate() {
                x[g * k + cols.start..g * k + cols.end].copy_from_slice(&part[i * m..(i + 1) * m]);
            }
        }
        x
    }

    /// The solves of the vectors `cols` of k interleaved ones, interleaved over the unknowns.
    fn solve_columns(&self, r: &[f64], k: usize, cols: std::ops::Range<usize>) -> Vec<f64> {
        let (nf, m) = (self.free.len(), cols.len());
        if m == 0 {
            return Vec::new();
        }
        let mut b =
            faer::Mat::<f32>::from_fn(nf, m, |i, c| r[self.free[i] * k + cols.start + c] as f32);
        self.llt.solve_in_place(b.as_mut());
        let mut out = vec![0.0; nf * m];
        for (i, o) in out.chunks_exact_mut(m).enumerate() {
            o.iter_mut()
                .enumerate()
                .for_each(|(c, o)| *o = f64::from(b[(i, c)]));
        }
        out
    }
}

/// The fine operator and its unknowns.
struct Operator {
    a: SymmetricBlocks,
    /// A rounded to f32, for the cycle's products alone (smoothing and its residuals): the
    /// cycle stays a fixed symmetric positive definite preconditioner (the same operator in
    /// each of its products), and its products read half the bytes; conjugate gradients take
    /// theirs with A.
    a32: SymmetricBlocks<f32>,
    free: Vec<bool>,
}

impl Operator {
    fn new(a: SymmetricBlocks, free: Vec<bool>) -> Operator {
        let a32 = a.to_f32();
        Operator { a, a32, free }
    }

    /// y = A X on the free DOFs for k vectors interleaved, X zero on the held DOFs (y is zero
    /// there).
    fn product(&self, x: &[f64], k: usize, y: &mut [f64], partials: &mut Partials) {
        self.a.apply_many_into(x, k, y, partials);
        self.zero_held(y, k);
    }

    /// The same with A rounded to f32 (the cycle's products).
    fn cycle_product(&self, x: &[f64], k: usize, y: &mut [f64], partials: &mut Partials) {
        self.a32.apply_many_into(x, k, y, partials);
        self.zero_held(y, k);
    }

    /// The held DOFs' entries of k interleaved vectors set to zero.
    fn zero_held(&self, x: &mut [f64], k: usize) {
        if k == 0 {
            return;
        }
        x.par_chunks_mut(k)
            .zip(self.free.par_iter())
            .for_each(|(x, f)| {
                if !*f {
                    x.iter_mut().for_each(|x| *x = 0.0);
                }
            });
    }
}

/// One PCG solve: the unknowns, the iterations and the final relative residual ‖b − A x‖ / ‖b‖
/// (recomputed from x, not the recurrence's).
pub(crate) struct Solved {
    pub(crate) x: Vec<f64>,
    pub(crate) iterations: usize,
    pub(crate) relative_residual: f64,
}

/// The two-level preconditioner over a fine operator, and CG with it.
pub(crate) struct TwoLevel {
    fine: Operator,
    transfer: Transfer,
    coarse: CoarseFactor,
    smoother: Smoother,
    /// The fine DOFs free when the coarse level was made: P maps into them.
    coarse_within: Vec<bool>,
}

impl TwoLevel {
    /// Set up over the symmetric operator `a` (every DOF) with unknowns `free`, prolongation
    /// `transfer` and the coarse pattern `pairs` (see [`Transfer::galerkin`]); the coarse
    /// operator factored in nested-dissection order.
    pub(crate) fn new<I: Iterator<Item = (usize, usize)>>(
        a: SymmetricBlocks,
        free: Vec<bool>,
        transfer: Transfer,
        pairs: impl Fn() -> I,
    ) -> Result<TwoLevel> {
        Self::over(Operator::new(a, free), transfer, pairs)
    }

    /// The same over the operator `fine`.
    fn over<I: Iterator<Item = (usize, usize)>>(
        fine: Operator,
        transfer: Transfer,
        pairs: impl Fn() -> I,
    ) -> Result<TwoLevel> {
        let galerkin = transfer.galerkin(&fine.a, pairs)?;
        let fixed: Vec<bool> = transfer.coarse_free.iter().map(|f| !f).collect();
        let coarse = CoarseFactor::new(System::with_ordering(
            fixed.len(),
            galerkin.lower_triplets(),
            &fixed,
            Ordering::NestedDissection,
        )?);
        let smoother = Smoother::new(&fine)?;
        let coarse_within = fine.free.clone();
        Ok(TwoLevel {
            fine,
            transfer,
            coarse,
            smoother,
            coarse_within,
        })
    }

    /// The same operator with other unknowns `free` (nodes freed or held again). While every
    /// DOF free when the coarse level was made is still free (the rounds free nodes and hold
    /// only those again), that level is kept: P still maps into unknowns, and Pᵀ A P, which
    /// reads A on those DOFs alone, is unchanged, so the cycle is the Galerkin two-level one
    /// over a coarse space that leaves out the freed DOFs (the smoother reaches them). Only
    /// the smoother is made again. Otherwise the coarse level is made anew with
    /// `transfer()`'s prolongation.
    pub(crate) fn with_holds<I: Iterator<Item = (usize, usize)>>(
        self,
        free: Vec<bool>,
        transfer: impl FnOnce() -> Transfer,
        pairs: impl Fn() -> I,
    ) -> Result<TwoLevel> {
        let TwoLevel {
            fine,
            transfer: kept,
            coarse,
            coarse_within,
            ..
        } = self;
        let fine = Operator { free, ..fine };
        if covers(&fine.free, &coarse_within) {
            let smoother = Smoother::new(&fine)?;
            return Ok(TwoLevel {
                fine,
                transfer: kept,
                coarse,
                smoother,
                coarse_within,
            });
        }
        // The old coarse factor goes before the new one is made.
        drop(coarse);
        Self::over(fine, transfer(), pairs)
    }

    /// A X over every DOF for k vectors interleaved (X's held entries included): the held
    /// values' part of the right-hand sides.
    pub(crate) fn full_product_many(&self, x: &[f64], k: usize) -> Vec<f64> {
        self.fine.a.apply_many(x, k)
    }

    /// Nonzeros of the coarse factor.
    pub(crate) fn coarse_factor_nnz(&self) -> usize {
        self.coarse.llt.pattern().factor_nnz()
    }

    /// z = the cycle applied to k residuals R interleaved (each vector's cycle is the
    /// single-vector one; the coarse solves are one multi-column solve on the factor).
    fn precondition(&self, r: &[f64], k: usize, z: &mut [f64], w: &mut CycleWork) {
        let level = &self.fine;
        let n = r.len();
        let (t1, t2) = (&mut w.t1[..n], &mut w.t2[..n]);
        self.smoother.smooth(level, r, k, z, &mut w.smooth);
        level.cycle_product(z, k, t1, &mut w.smooth.partials);
        t1.par_iter_mut().zip(r).for_each(|(t, r)| *t = r - *t);
        let rc = self.transfer.restrict_many(t1, k);
        let ec = self.coarse.solve(&rc, k);
        self.transfer.add_prolonged(&ec, k, z);
        level.zero_held(z, k);
        level.cycle_product(z, k, t1, &mut w.smooth.partials);
        t1.par_iter_mut().zip(r).for_each(|(t, r)| *t = r - *t);
        self.smoother.smooth(level, t1, k, t2, &mut w.smooth);
        z.par_iter_mut().zip(&*t2).for_each(|(z, p)| *z += p);
    }

    /// A x = b on the free DOFs for each b (b's held entries ignored; x zero there), to
    /// ‖b − A x‖ ≤ `tolerance` ‖b‖ ([`TOLERANCE`] unless the caller needs less); not converging in [`MAX_ITERATIONS`] is an error. The
    /// right-hand sides are solved together: conjugate gradients run on each
    /// in lockstep (its own step lengths, its own stop), so that every product and
    /// preconditioner cycle serves all the vectors still iterating in one pass over the
    /// operator and the coarse factor. Each vector's iterates are those of its own solve: the
    /// batch changes the cost, not the result.
    ///
    /// `guess`: a start for each vector (its held entries ignored), e.g. the previous round's
    /// solution when a few nodes were freed: CG from x₀ minimises the same error norm over
    /// x₀ + the Krylov space of r₀ = b − A x₀, and stops at the same ‖b − A x‖ ≤ tol ‖b‖, so
    /// a start near the solution saves the iterations that take ‖r‖ from ‖b‖ down to ‖r₀‖. A
    /// start with ‖r₀‖ ≥ ‖b‖ is no better than zero, which is taken instead.
    pub(crate) fn solve_many(
        &self,
        bs: &[Vec<f64>],
        guess: Option<&[Vec<f64>]>,
        tolerance: f64,
    ) -> Result<Vec<Solved>> {
        let level = &self.fine;
        let n = level.free.len();
        let total = bs.len();
        let b = {
            let mut b = interleave(bs);
            level.zero_held(&mut b, total);
            b
        };
        let b_norm = column_norms(&b, total);
        let mut x_done: Vec<Vec<f64>> = vec![vec![0.0; n]; total];
        let mut iterations = vec![0usize; total];
        // The vectors still iterating (their columns in r, d, x below, in this order).
        let mut active: Vec<usize> = (0..total).filter(|v| b_norm[*v] > 0.0).collect();
        let mut k = active.len();
        // Allocated once for the batch: the kernel maps and zeroes a fresh vector's pages.
        let mut work = CycleWork::new(n, k);
        let mut partials = Partials::default();
        let mut ad = vec![0.0; n * k];
        let mut r = select(&b, total, &active);
        let mut x = vec![0.0; n * k];
        if let Some(g) =
            guess.filter(|g| k > 0 && g.len() == total && g.iter().all(|g| g.len() == n))
        {
            let mut x0 = select(&interleave(g), total, &active);
            level.zero_held(&mut x0, k);
            level.product(&x0, k, &mut ad, &mut partials);
            let r0: Vec<f64> = r.par_iter().zip(&ad).map(|(r, a)| r - a).collect();
            let r0_norm = column_norms(&r0, k);
            for a in 0..k {
                if r0_norm[a] < b_norm[active[a]] {
                    for e in 0..n {
                        x[e * k + a] = x0[e * k + a];
                        r[e * k + a] = r0[e * k + a];
                    }
                }
            }
        }
        let mut z = vec![0.0; n * k];
        if k > 0 {
            self.precondition(&r, k, &mut z, &mut work);
        }
        let mut d = z.clone();
        let mut rz = column_dots(&r, &z, k);
        let not_converged = || {
            Error::numerical(
                NumericalKind::NotConverged,
                format!(
                    "the iterative solve of {} unknowns (conjugate gradients, p-multigrid) did not reach a relative residual of {tolerance:e} in {MAX_ITERATIONS} iterations",
                    level.free.iter().filter(|f| **f).count()
                ),
            )
        };
        let mut it = 0;
        while k > 0 {
            it += 1;
            if it > MAX_ITERATIONS {
                return Err(not_converged());
            }
            let ad = &mut ad[..n * k];
            level.product(&d, k, ad, &mut partials);
            let curv = column_dots(&d, ad, k);
            // A not positive definite along d (the CG of fem/pcg.rs refuses it likewise).
            if curv.iter().any(|c| !(*c > 0.0)) {
                return Err(not_converged());
            }
            let alpha: Vec<f64> = rz.iter().zip(&curv).map(|(a, c)| a / c).collect();
            x.par_chunks_mut(k).zip(d.par_chunks(k)).for_each(|(x, d)| {
                x.iter_mut()
                    .zip(d)
                    .zip(&alpha)
                    .for_each(|((x, d), a)| *x += a * d)
            });
            r.par_chunks_mut(k)
                .zip(ad.par_chunks(k))
                .for_each(|(r, ad)| {
                    r.iter_mut()
                        .zip(ad)
                        .zip(&alpha)
                        .for_each(|((r, ad), a)| *r -= a * ad)
                });
            let r_norm = column_norms(&r, k);
            if r_norm.iter().any(|v| !v.is_finite()) {
                return Err(not_converged());
            }
            let going: Vec<usize> = (0..k)
                .filter(|a| r_norm[*a] > tolerance * b_norm[active[*a]])
                .collect();
            if going.len() < k {
                for a in (0..k).filter(|a| !going.contains(a)) {
                    x_done[active[a]] = column(&x, k, a);
                    iterations[active[a]] = it;
                }
                x = select(&x, k, &going);
                r = select(&r, k, &going);
                d = select(&d, k, &going);
                rz = going.iter().map(|a| rz[*a]).collect();
                active = going.iter().map(|a| active[*a]).collect();
                k = active.len();
                if k == 0 {
                    break;
                }
            }
            let z = &mut z[..n * k];
            self.precondition(&r, k, z, &mut work);
            let rz_new = column_dots(&r, z, k);
            let beta: Vec<f64> = rz_new.iter().zip(&rz).map(|(n, o)| n / o).collect();
            rz = rz_new;
            d.par_chunks_mut(k).zip(z.par_chunks(k)).for_each(|(d, z)| {
                d.iter_mut()
                    .zip(z)
                    .zip(&beta)
                    .for_each(|((d, z), b)| *d = z + b * *d)
            });
        }
        // The residuals from the solutions, not the recurrence's.
        let xs = interleave(&x_done);
        let mut ax = vec![0.0; n * total];
        level.product(&xs, total, &mut ax, &mut partials);
        let rb: Vec<f64> = b.par_iter().zip(&ax).map(|(b, a)| b - a).collect();
        let r_norm = column_norms(&rb, total);
        Ok(x_done
            .into_iter()
            .enumerate()
            .map(|(v, x)| Solved {
                x,
                iterations: iterations[v],
                relative_residual: if b_norm[v] > 0.0 {
                    r_norm[v] / b_norm[v]
                } else {
                    0.0
                },
            })
            .collect())
    }
}

/// Per vector, u · v over k interleaved vectors.
fn column_dots(u: &[f64], w: &[f64], k: usize) -> Vec<f64> {
    if k == 0 {
        return Vec::new();
    }
    u.par_chunks(k * 1024)
        .zip(w.par_chunks(k * 1024))
        .map(|(u, w)| {
            let mut s = vec![0.0; k];
            for (u, w) in u.chunks_exact(k).zip(w.chunks_exact(k)) {
                s.iter_mut()
                    .zip(u.iter().zip(w))
                    .for_each(|(s, (a, b))| *s += a * b);
            }
            s
        })
        .reduce(
            || vec![0.0; k],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(a, b)| *a += b);
                a
            },
        )
}

/// Per vector, its Euclidean norm.
fn column_norms(u: &[f64], k: usize) -> Vec<f64> {
    column_dots(u, u, k).into_iter().map(f64::sqrt).collect()
}

/// The vectors `keep` (indices into k interleaved vectors), interleaved.
fn select(u: &[f64], k: usize, keep: &[usize]) -> Vec<f64> {
    let m = keep.len();
    let mut out = vec![0.0; u.len() / k.max(1) * m];
    if m == 0 {
        return out;
    }
    out.par_chunks_mut(m)
        .zip(u.par_chunks(k))
        .for_each(|(o, u)| o.iter_mut().zip(keep).for_each(|(o, a)| *o = u[*a]));
    out
}

/// The 3×3 identity restricted to the DOFs `free` marks.
pub(crate) fn mask(free: [bool; 3]) -> Block {
    std::array::from_fn(|e| if e % 4 == 0 && free[e / 3] { 1.0 } else { 0.0 })
}

/// a · b (re-exported for building the prolongation's blocks).
pub(crate) fn product(a: &Block, b: &Block) -> Block {
    times(a, b)
}

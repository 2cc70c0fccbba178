//! The linear model's system in affine form on its free unknowns: A(θ) = Σ_q θ_q A_q and
//! f(θ) = Σ_q θ_q f_q (Rozza, Huynh & Patera 2008 eq. 2.3), where each A_q is the stiffness of
//! one Lamé parameter of one tissue (positive semi-definite) and f_q = −A_q,fc g moves the held
//! components to their values g (the bone's move; no θ in g). The holds are imposed as in
//! `tet::holds::Constrained`: each node's DOFs in its own frame, held components prescribed.

use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::free_dofs;
use crate::fem::cholesky::{Cholesky, Ordering, Pattern};
use crate::tet::Hold;
use crate::tet::holds::{Frame, frames, rotate_lower, to_global};
use faer::sparse::{SparseColMat, Triplet};

/// A(θ), f(θ) on the free unknowns, and the held values.
pub struct Affine {
    frames: Vec<Frame>,
    /// Free index → DOF (3 node + local component).
    free: Vec<usize>,
    /// The free–free matrices by rows, both triangles, on one pattern: row r's entries are
    /// `cols[start[r]..start[r + 1]]`, term q's values `vals[q][…]`.
    start: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<Vec<f64>>,
    /// The lower triangle's entries (row, column, slot in `vals`), for the factor.
    lower: Vec<(u32, u32, usize)>,
    f: Vec<Vec<f64>>,
    pattern: Pattern,
}

impl Affine {
    /// From the terms' lower triangles (3 DOFs per node, global frame, one triplet per entry in
    /// the same order for every term: `tet::lame_terms`) and the nodes' holds (their values give
    /// g). Nothing held, or a hold that is not finite, is an error.
    pub fn new(terms: &[Vec<(usize, usize, f64)>], holds: &[Hold]) -> Result<Affine> {
        let nodes = holds.len();
        let frames = frames(holds, nodes)?;
        let fixed: Vec<bool> = frames
            .iter()
            .flat_map(|f| std::array::from_fn::<bool, 3, _>(|i| i < f.held))
            .collect();
        let g: Vec<f64> = frames.iter().flat_map(|f| f.values).collect();
        let (free_index, free) = free_dofs(&fixed);
        let nf = free.len();
        let Some(first) = terms.first() else {
            return Err(Error::config("reduced model: no stiffness term"));
        };
        // The pattern from the first term; every term's rotated triplets follow it entry for
        // entry (rotation depends on the frames only).
        let rotated0 = rotate_lower(first, &frames);
        let mut entries: Vec<(u32, u32, u32)> = Vec::new();
        let mut coupling: Vec<(u32, usize, u32)> = Vec::new();
        for (i, &(r, c, _)) in rotated0.iter().enumerate() {
            let (fr, fc) = (free_index[r], free_index[c]);
            match (fr != usize::MAX, fc != usize::MAX) {
                (true, true) => {
                    entries.push((fr as u32, fc as u32, i as u32));
                    if fr != fc {
                        entries.push((fc as u32, fr as u32, i as u32));
                    }
                }
                (true, false) => coupling.push((fr as u32, c, i as u32)),
                (false, true) => coupling.push((fc as u32, r, i as u32)),
                (false, false) => {}
            }
        }
        entries.sort_unstable_by_key(|e| (e.0, e.1));
        let mut start = vec![0usize; nf + 1];
        let mut cols: Vec<u32> = Vec::new();
        let mut slot_of: Vec<(usize, u32)> = Vec::with_capacity(entries.len());
        let mut last = None;
        for &(r, c, i) in &entries {
            if last != Some((r, c)) {
                cols.push(c);
                start[r as usize + 1] = cols.len();
                last = Some((r, c));
            }
            slot_of.push((cols.len() - 1, i));
        }
        for r in 1..=nf {
            start[r] = start[r].max(start[r - 1]);
        }
        drop(entries);
        let mut lower = Vec::new();
        for r in 0..nf {
            for s in start[r]..start[r + 1] {
                if cols[s] as usize <= r {
                    lower.push((r as u32, cols[s], s));
                }
            }
        }
        let mut vals = Vec::with_capacity(terms.len());
        let mut f = Vec::with_capacity(terms.len());
        for (q, term) in terms.iter().enumerate() {
            let rotated = if q == 0 {
                rotated0.clone()
            } else {
                rotate_lower(term, &frames)
            };
            if rotated.len() != rotated0.len()
                || rotated
                    .iter()
                    .zip(&rotated0)
                    .any(|(a, b)| (a.0, a.1) != (b.0, b.1))
            {
                return Err(Error::config(format!(
                    "reduced model: stiffness term {q} is not on the first term's pattern"
                )));
            }
            let mut v = vec![0.0; cols.len()];
            for &(s, i) in &slot_of {
                v[s] += rotated[i as usize].2;
            }
            let mut fq = vec![0.0; nf];
            for &(fr, held, i) in &coupling {
                fq[fr as usize] -= rotated[i as usize].2 * g[held];
            }
            vals.push(v);
            f.push(fq);
        }
        let ones = vec![1.0; vals.len()];
        let m = lower_matrix(&lower, &vals, nf, &ones)?;
        let pattern = Pattern::analyse_with(m.symbolic(), Ordering::NestedDissection)
            .map_err(|e| Error::numerical(NumericalKind::Singular, format!("{e:?}")))?;
        Ok(Affine {
            frames,
            free,
            start,
            cols,
            vals,
            lower,
            f,
            pattern,
        })
    }

    /// Q, the number of terms.
    pub fn terms(&self) -> usize {
        self.vals.len()
    }

    /// The free unknowns.
    pub fn unknowns(&self) -> usize {
        self.free.len()
    }

    /// A_q x.
    pub fn apply(&self, q: usize, x: &[f64]) -> Vec<f64> {
        self.apply_values(&self.vals[q], x)
    }

    /// The values of A(θ) = Σ θ_q A_q on the pattern of [`Self::apply`]: one pass applies it
    /// (with [`Self::apply_values`]) where Q passes would apply the terms one by one.
    pub fn values_at(&self, theta: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.cols.len()];
        for (t, v) in theta.iter().zip(&self.vals) {
            for (o, v) in out.iter_mut().zip(v) {
                *o += t * v;
            }
        }
        out
    }

    /// The matrix with values `v` (from [`Self::values_at`]) times x.
    pub fn apply_values(&self, v: &[f64], x: &[f64]) -> Vec<f64> {
        use rayon::prelude::*;
        (0..self.free.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|r| {
                (self.start[r]..self.start[r + 1])
                    .map(|s| v[s] * x[self.cols[s] as usize])
                    .sum()
            })
            .collect()
    }

    /// f_q.
    pub fn load(&self, q: usize) -> &[f64] {
        &self.f[q]
    }

    /// f(θ).
    pub fn rhs(&self, theta: &[f64]) -> Vec<f64> {
        let mut b = vec![0.0; self.free.len()];
        for (t, fq) in theta.iter().zip(&self.f) {
            for (x, y) in b.iter_mut().zip(fq) {
                *x += t * y;
            }
        }
        b
    }

    /// The factor of A(θ) (the symbolic analysis is shared by every θ).
    pub fn factor(&self, theta: &[f64]) -> Result<Cholesky<f64>> {
        let m = lower_matrix(&self.lower, &self.vals, self.free.len(), theta)?;
        Cholesky::factor(&self.pattern, m.as_ref()).map_err(|e| {
            Error::numerical(
                NumericalKind::Singular,
                format!("the reduced model's truth matrix is not positive definite ({e:?})"),
            )
        })
    }

    /// Node displacements (global frame) of free values `u` with the held components at their
    /// values (`lift`) or at zero (a basis vector: the homogeneous part).
    pub fn expand(&self, u: &[f64], lift: bool) -> Vec<[f64; 3]> {
        let mut local: Vec<f64> = self
            .frames
            .iter()
            .flat_map(|f| if lift { f.values } else { [0.0; 3] })
            .collect();
        for (i, g) in self.free.iter().enumerate() {
            local[*g] = u[i];
        }
        self.frames
            .iter()
            .enumerate()
            .map(|(n, f)| to_global(&f.axes, [local[3 * n], local[3 * n + 1], local[3 * n + 2]]))
            .collect()
    }

    /// The transpose of `expand(·, false)`: node forces (global frame) to free values.
    pub fn restrict(&self, forces: &[[f64; 3]]) -> Vec<f64> {
        use crate::tet::holds::to_local;
        let local: Vec<[f64; 3]> = self
            .frames
            .iter()
            .zip(forces)
            .map(|(f, v)| to_local(&f.axes, *v))
            .collect();
        self.free.iter().map(|g| local[g / 3][g % 3]).collect()
    }
}

/// The lower triangle of Σ_q θ_q A_q.
fn lower_matrix(
    lower: &[(u32, u32, usize)],
    vals: &[Vec<f64>],
    n: usize,
    theta: &[f64],
) -> Result<SparseColMat<usize, f64>> {
    let t: Vec<Triplet<usize, usize, f64>> = lower
        .iter()
        .map(|&(r, c, s)| {
            let v = theta.iter().zip(vals).map(|(t, v)| t * v[s]).sum();
            Triplet::new(r as usize, c as usize, v)
        })
        .collect();
    SparseColMat::try_new_from_triplets(n, n, &t)
        .map_err(|e| Error::numerical(NumericalKind::Singular, format!("sparse matrix: {e:?}")))
}

/// Solve with a factor for each column of `b` (free values), in place.
pub fn solve_columns(factor: &Cholesky<f64>, b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    if b.is_empty() {
        return Vec::new();
    }
    let n = b[0].len();
    let mut m = faer::Mat::<f64>::zeros(n, b.len());
    for (c, col) in b.iter().enumerate() {
        for (r, x) in col.iter().enumerate() {
            m[(r, c)] = *x;
        }
    }
    factor.solve_in_place(m.as_mut());
    (0..b.len())
        .map(|c| (0..n).map(|r| m[(r, c)]).collect())
        .collect()
}

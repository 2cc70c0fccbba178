//! The linear model's system in affine form on its free unknowns: A(θ) = Σ_q θ_q A_q and
//! f(θ) = Σ_q θ_q f_q (Rozza, Huynh & Patera 2008 eq. 2.3), where each A_q is the stiffness of
//! one Lamé parameter of one tissue (positive semi-definite) and f_q = −A_q,fc g moves the held
//! components to their values g (the bone's move; no θ in g). The holds are imposed as in
//! `tet::holds::Constrained`: each node's DOFs in its own frame, held components prescribed.

use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::free_dofs;
use crate::fem::cholesky::{Cholesky, Ordering, Pattern};
use crate::tet::Hold;
use crate::tet::LameTerms;
use crate::tet::holds::{Frame, frames, rotate_entry, to_global};
use faer::sparse::{SparseColMat, Triplet};

/// A(θ), f(θ) on the free unknowns, and the held values.
pub struct Affine {
    frames: Vec<Frame>,
    /// Free index → DOF (3 node + local component).
    free: Vec<usize>,
    /// The free–free pattern by rows, both triangles: row r's columns are
    /// `cols[start[r]..start[r + 1]]`.
    start: Vec<usize>,
    cols: Vec<u32>,
    /// Each term's nonzero entries only: a tissue's terms touch its own elements' rows, so the
    /// Q terms together hold about twice the pattern, not Q times it.
    terms: Vec<Term>,
    /// The lower triangle's entries (row, column, slot in the pattern), for the factor.
    lower: Vec<(u32, u32, usize)>,
    f: Vec<Vec<f64>>,
    pattern: Pattern,
}

/// One term's nonzero entries by rows: row r's are `entries[start[r]..start[r + 1]]`.
struct Term {
    start: Vec<usize>,
    entries: Vec<Entry>,
}

struct Entry {
    col: u32,
    /// Its place in the shared pattern.
    slot: u32,
    value: f64,
}

impl Affine {
    /// From the Lamé parts `list` of `lame` (3 DOFs per node, global frame) and the nodes'
    /// holds (their values give g). Where each part's entries go (rotation into the nodes'
    /// frames, free or held) depends on the frames only, so it is worked out once and each part
    /// is then one pass over its values, made one at a time. X's factor is analysed in
    /// `ordering` (the run's node ordering, when it has one). Nothing held, or a hold that is
    /// not finite, is an error.
    pub(crate) fn new(
        lame: &LameTerms,
        list: &[(usize, bool)],
        holds: &[Hold],
        ordering: Ordering<'_>,
    ) -> Result<Affine> {
        let nodes = holds.len();
        let frames = frames(holds, nodes)?;
        let fixed: Vec<bool> = frames
            .iter()
            .flat_map(|f| std::array::from_fn::<bool, 3, _>(|i| i < f.held))
            .collect();
        let g: Vec<f64> = frames.iter().flat_map(|f| f.values).collect();
        let (free_index, free) = free_dofs(&fixed);
        let nf = free.len();
        if list.is_empty() {
            return Err(Error::config("reduced model: no stiffness term"));
        }
        // Each lower entry's shares of the free–free entries (both triangles) and of the
        // coupling to held components. The free–free shares are bucketed by row in two passes
        // (count, then fill), 12 bytes each: a weight other than 1 (a rotated node's) is an
        // index into `weights`.
        let free_pair = |li: usize, lj: usize| {
            let (fr, fc) = (free_index[li], free_index[lj]);
            (fr != usize::MAX, fc != usize::MAX, fr, fc)
        };
        let mut row_start = vec![0usize; nf + 1];
        let mut coupling: Vec<(u32, u32, u32, f64)> = Vec::new();
        lame.for_each_lower(|r, c, i| {
            rotate_entry(r, c, &frames, |li, lj, w| match free_pair(li, lj) {
                (true, true, fr, fc) => {
                    row_start[fr + 1] += 1;
                    if fr != fc {
                        row_start[fc + 1] += 1;
                    }
                }
                (true, false, fr, _) => coupling.push((fr as u32, lj as u32, i as u32, w)),
                (false, true, _, fc) => coupling.push((fc as u32, li as u32, i as u32, w)),
                (false, false, _, _) => {}
            })
        });
        for r in 0..nf {
            row_start[r + 1] += row_start[r];
        }
        // (column, value index, weight index) per share, by row.
        let mut shares = vec![(0u32, 0u32, 0u32); row_start[nf]];
        let mut weights = vec![1.0];
        let mut next = row_start.clone();
        lame.for_each_lower(|r, c, i| {
            rotate_entry(r, c, &frames, |li, lj, w| {
                if let (true, true, fr, fc) = free_pair(li, lj) {
                    let k = if w == 1.0 {
                        0
                    } else {
                        weights.push(w);
                        weights.len() as u32 - 1
                    };
                    shares[next[fr]] = (fc as u32, i as u32, k);
                    next[fr] += 1;
                    if fr != fc {
                        shares[next[fc]] = (fr as u32, i as u32, k);
                        next[fc] += 1;
                    }
                }
            })
        });
        drop(next);
        // Per row, the shares by column: the pattern, and where each share goes in it.
        let mut start = vec![0usize; nf + 1];
        let mut cols: Vec<u32> = Vec::new();
        let mut gather: Vec<(u32, u32, u32)> = Vec::with_capacity(shares.len());
        for r in 0..nf {
            let row = &mut shares[row_start[r]..row_start[r + 1]];
            row.sort_unstable_by_key(|e| e.0);
            let mut last = None;
            for &(c, i, k) in row.iter() {
                if last != Some(c) {
                    cols.push(c);
                    last = Some(c);
                }
                gather.push(((cols.len() - 1) as u32, i, k));
            }
            start[r + 1] = cols.len();
        }
        drop((shares, row_start));
        let mut lower = Vec::new();
        for r in 0..nf {
            for s in start[r]..start[r + 1] {
                if cols[s] as usize <= r {
                    lower.push((r as u32, cols[s], s));
                }
            }
        }
        let mut terms = Vec::with_capacity(list.len());
        let mut f = Vec::with_capacity(list.len());
        for part in list {
            let blocks = lame.term(*part)?;
            let values = blocks.as_flattened();
            let mut v = vec![0.0; cols.len()];
            for &(s, i, k) in &gather {
                v[s as usize] += weights[k as usize] * values[i as usize];
            }
            let mut fq = vec![0.0; nf];
            for &(fr, held, i, w) in &coupling {
                fq[fr as usize] -= w * values[i as usize] * g[held as usize];
            }
            drop(blocks);
            let mut t = Term {
                start: vec![0; nf + 1],
                entries: Vec::new(),
            };
            for r in 0..nf {
                for s in start[r]..start[r + 1] {
                    if v[s] != 0.0 {
                        t.entries.push(Entry {
                            col: cols[s],
                            slot: s as u32,
                            value: v[s],
                        });
                    }
                }
                t.start[r + 1] = t.entries.len();
            }
            terms.push(t);
            f.push(fq);
        }
        let ones = values_of(&terms, cols.len(), &vec![1.0; list.len()]);
        let m = lower_matrix(&lower, &ones, nf)?;
        let pattern = Pattern::analyse_with(m.symbolic(), ordering, &free)
            .map_err(|e| Error::numerical(NumericalKind::Singular, format!("{e:?}")))?;
        Ok(Affine {
            frames,
            free,
            start,
            cols,
            terms,
            lower,
            f,
            pattern,
        })
    }

    /// Q, the number of terms.
    pub fn terms(&self) -> usize {
        self.terms.len()
    }

    /// The free unknowns.
    pub fn unknowns(&self) -> usize {
        self.free.len()
    }

    /// A_q x: term q's own entries only.
    pub fn apply(&self, q: usize, x: &[f64]) -> Vec<f64> {
        use rayon::prelude::*;
        let t = &self.terms[q];
        (0..self.free.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|r| {
                t.entries[t.start[r]..t.start[r + 1]]
                    .iter()
                    .map(|e| e.value * x[e.col as usize])
                    .sum()
            })
            .collect()
    }

    /// A_q x for each x of `xs`, in one pass over the term's entries (the product streams the
    /// matrix from memory; several vectors share that stream).
    pub(crate) fn apply_many(&self, q: usize, xs: &[&[f64]]) -> Vec<Vec<f64>> {
        let t = &self.terms[q];
        rows_times(self.free.len(), xs, |r, x, out| {
            for e in &t.entries[t.start[r]..t.start[r + 1]] {
                let c = e.col as usize;
                for (o, xj) in out.iter_mut().zip(x) {
                    *o += e.value * xj[c];
                }
            }
        })
    }

    /// The values of A(θ) = Σ θ_q A_q on the pattern of [`Self::apply_values`]: one pass applies
    /// it where Q passes would apply the terms one by one.
    pub(crate) fn values_at(&self, theta: &[f64]) -> Vec<f64> {
        values_of(&self.terms, self.cols.len(), theta)
    }

    /// The matrix with values `v` (from [`Self::values_at`]) times x.
    pub(crate) fn apply_values(&self, v: &[f64], x: &[f64]) -> Vec<f64> {
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

    /// The matrix with values `v` times each x of `xs`, in one pass over the pattern.
    pub(crate) fn apply_values_many(&self, v: &[f64], xs: &[&[f64]]) -> Vec<Vec<f64>> {
        rows_times(self.free.len(), xs, |r, x, out| {
            for s in self.start[r]..self.start[r + 1] {
                let c = self.cols[s] as usize;
                for (o, xj) in out.iter_mut().zip(x) {
                    *o += v[s] * xj[c];
                }
            }
        })
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
        let m = lower_matrix(&self.lower, &self.values_at(theta), self.free.len())?;
        Cholesky::factor(&self.pattern, m.as_ref()).map_err(|e| {
            Error::numerical(
                NumericalKind::Singular,
                format!("the reduced model's truth matrix is not positive definite ({e:?})"),
            )
        })
    }

    /// Node displacements (global frame) of free values `u` with the held components at their
    /// values (`lift`) or at zero (a basis vector: the homogeneous part).
    pub(crate) fn expand(&self, u: &[f64], lift: bool) -> Vec<[f64; 3]> {
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

/// Rows 0..n of a product with the vectors `xs`, `row(r, xs, out)` adding row r's entries to
/// `out` (one per vector); returned as one vector per x. Rows in parallel chunks.
fn rows_times(
    n: usize,
    xs: &[&[f64]],
    row: impl Fn(usize, &[&[f64]], &mut [f64]) + Sync,
) -> Vec<Vec<f64>> {
    use rayon::prelude::*;
    let k = xs.len();
    if k == 0 {
        return Vec::new();
    }
    let mut flat = vec![0.0; n * k];
    flat.par_chunks_mut(k)
        .with_min_len(4096)
        .enumerate()
        .for_each(|(r, out)| row(r, xs, out));
    (0..k)
        .map(|j| flat.iter().skip(j).step_by(k).copied().collect())
        .collect()
}

/// Σ_q θ_q A_q's values on a pattern of `len` entries.
fn values_of(terms: &[Term], len: usize, theta: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; len];
    for (t, term) in theta.iter().zip(terms) {
        for e in &term.entries {
            out[e.slot as usize] += t * e.value;
        }
    }
    out
}

/// The lower triangle of the matrix with `values` on the pattern.
fn lower_matrix(
    lower: &[(u32, u32, usize)],
    values: &[f64],
    n: usize,
) -> Result<SparseColMat<usize, f64>> {
    let t: Vec<Triplet<usize, usize, f64>> = lower
        .iter()
        .map(|&(r, c, s)| Triplet::new(r as usize, c as usize, values[s]))
        .collect();
    SparseColMat::try_new_from_triplets(n, n, &t)
        .map_err(|e| Error::numerical(NumericalKind::Singular, format!("sparse matrix: {e:?}")))
}

/// Solve with a factor for each column of `b` (free values), in place.
pub(crate) fn solve_columns(factor: &Cholesky<f64>, b: &[Vec<f64>]) -> Vec<Vec<f64>> {
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

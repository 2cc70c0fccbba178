//! A symmetric sparse matrix of 3×3 node blocks (3 DOFs per node), its lower block triangle
//! stored row by row: the operator of the iterative solve (fem/pmultigrid.rs), applied to a
//! vector in one pass over the blocks. Blocks instead of scalar entries: one index per nine
//! values (the 10-node real CT's 0.35 M nodes: 12 bytes per scalar entry as triplets of u32
//! and f64, 8.4 per entry in blocks), and 3×3 products the compiler unrolls.

use rayon::prelude::*;

/// A 3×3 block, row-major: entry (r, c) at 3 r + c.
pub(crate) type Block = [f64; 9];

pub(crate) struct SymmetricBlocks {
    /// Per row node i, its blocks ptr[i]..ptr[i + 1]: column nodes j ≤ i ascending, the
    /// diagonal block last (stored whole).
    ptr: Vec<usize>,
    col: Vec<u32>,
    val: Vec<Block>,
}

impl SymmetricBlocks {
    /// The pattern of the node pairs `pairs` (row ≥ column, repeats allowed; `pairs` is called
    /// twice: to count and to fill) and every diagonal block, values zero.
    pub(crate) fn with_pairs<I: Iterator<Item = (usize, usize)>>(
        nodes: usize,
        pairs: impl Fn() -> I,
    ) -> SymmetricBlocks {
        let mut start = vec![0usize; nodes + 1];
        for (i, _) in pairs() {
            start[i + 1] += 1;
        }
        for i in 0..nodes {
            start[i + 1] += start[i] + 1;
        }
        let mut fill: Vec<usize> = start[..nodes].to_vec();
        let mut cols = vec![0u32; start[nodes]];
        for i in 0..nodes {
            cols[fill[i]] = i as u32;
            fill[i] += 1;
        }
        for (i, j) in pairs() {
            cols[fill[i]] = j as u32;
            fill[i] += 1;
        }
        let mut ptr = Vec::with_capacity(nodes + 1);
        ptr.push(0);
        let mut col = Vec::with_capacity(cols.len());
        for i in 0..nodes {
            let row = &mut cols[start[i]..start[i + 1]];
            row.sort_unstable();
            let first = col.len();
            for &j in row.iter() {
                if col.len() == first || col[col.len() - 1] != j {
                    col.push(j);
                }
            }
            ptr.push(col.len());
        }
        col.shrink_to_fit();
        let val = vec![[0.0; 9]; col.len()];
        SymmetricBlocks { ptr, col, val }
    }

    /// The matrix whose lower triangle (row ≥ column, duplicates summed) is `k`, DOF 3n + c for
    /// component c of node n.
    pub(crate) fn from_lower(nodes: usize, k: &[(usize, usize, f64)]) -> SymmetricBlocks {
        let mut m = Self::with_pairs(nodes, || k.iter().map(|&(r, c, _)| (r / 3, c / 3)));
        for &(r, c, v) in k {
            let (i, j) = (r / 3, c / 3);
            let (a, b) = (r % 3, c % 3);
            // Present: the pattern was made from these entries.
            if let Some(blk) = m.block_mut(i, j) {
                blk[3 * a + b] += v;
                if i == j && a != b {
                    blk[3 * b + a] += v;
                }
            }
        }
        m
    }

    pub(crate) fn nodes(&self) -> usize {
        self.ptr.len() - 1
    }

    /// Block (i, j), i ≥ j, if in the pattern.
    pub(crate) fn block_mut(&mut self, i: usize, j: usize) -> Option<&mut Block> {
        let row = &self.col[self.ptr[i]..self.ptr[i + 1]];
        let p = row.binary_search(&(j as u32)).ok()?;
        Some(&mut self.val[self.ptr[i] + p])
    }

    /// The diagonal block of node i.
    pub(crate) fn diagonal(&self, i: usize) -> &Block {
        &self.val[self.ptr[i + 1] - 1]
    }

    /// Each stored block: (row node, column node, block), rows ascending.
    pub(crate) fn for_each(&self, mut f: impl FnMut(usize, usize, &Block)) {
        for i in 0..self.nodes() {
            for p in self.ptr[i]..self.ptr[i + 1] {
                f(i, self.col[p] as usize, &self.val[p]);
            }
        }
    }

    /// Each stored block changed in place by `f(row node, column node, block)`, in parallel.
    pub(crate) fn map_blocks(&mut self, f: impl Fn(usize, usize, &mut Block) + Sync) {
        let (ptr, col) = (&self.ptr, &self.col);
        let rows: Vec<usize> = (0..ptr.len() - 1).collect();
        // Rows' blocks are contiguous: split the values at the row starts.
        let mut rest: &mut [Block] = &mut self.val;
        let mut parts = Vec::with_capacity(rows.len());
        for i in &rows {
            let (head, tail) = rest.split_at_mut(ptr[i + 1] - ptr[*i]);
            parts.push((*i, head));
            rest = tail;
        }
        parts
            .into_par_iter()
            .with_min_len(1024)
            .for_each(|(i, blocks)| {
                for (q, b) in blocks.iter_mut().enumerate() {
                    f(i, col[ptr[i] + q] as usize, b);
                }
            });
    }

    /// The lower triangle as triplets (row ≥ column), DOF 3n + c; zeros left out.
    pub(crate) fn lower_triplets(&self) -> Vec<(usize, usize, f64)> {
        let mut out = Vec::with_capacity(9 * self.col.len());
        self.for_each(|i, j, b| {
            for r in 0..3 {
                for c in 0..3 {
                    if (i != j || c <= r) && b[3 * r + c] != 0.0 {
                        out.push((3 * i + r, 3 * j + c, b[3 * r + c]));
                    }
                }
            }
        });
        out
    }

    /// Row boundaries splitting the rows among the threads in runs of about equal block counts.
    fn row_runs(&self) -> Vec<usize> {
        let parts = rayon::current_num_threads().max(1);
        let per = self.col.len().div_ceil(parts).max(1);
        let mut bounds = vec![0usize];
        for i in 0..self.nodes() {
            if self.ptr[i + 1] >= per * bounds.len() {
                bounds.push(i + 1);
            }
        }
        if *bounds.last().unwrap_or(&0) != self.nodes() {
            bounds.push(self.nodes());
        }
        bounds
    }

    /// y = A x (x with 3 entries per node). The rows are split among the threads in runs of
    /// about equal block counts, each adding into its own y (a lower block scatters into the
    /// column node's rows too), the parts summed.
    pub(crate) fn apply(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        let bounds = self.row_runs();
        let partial: Vec<Vec<f64>> = bounds
            .par_windows(2)
            .map(|w| {
                let mut y = vec![0.0; n];
                for i in w[0]..w[1] {
                    let xi = [x[3 * i], x[3 * i + 1], x[3 * i + 2]];
                    let mut yi = [0.0; 3];
                    for p in self.ptr[i]..self.ptr[i + 1] {
                        let j = self.col[p] as usize;
                        let b = &self.val[p];
                        let xj = [x[3 * j], x[3 * j + 1], x[3 * j + 2]];
                        for r in 0..3 {
                            yi[r] += b[3 * r] * xj[0] + b[3 * r + 1] * xj[1] + b[3 * r + 2] * xj[2];
                        }
                        if j != i {
                            for c in 0..3 {
                                y[3 * j + c] += b[c] * xi[0] + b[3 + c] * xi[1] + b[6 + c] * xi[2];
                            }
                        }
                    }
                    for r in 0..3 {
                        y[3 * i + r] += yi[r];
                    }
                }
                y
            })
            .collect();
        sum_parts(partial, n)
    }
}

impl SymmetricBlocks {
    /// Y = A X for `k` vectors at once, interleaved: entry (DOF d, vector v) at d k + v. One
    /// pass over the blocks serves every vector, so the matrix (the solve's memory traffic) is
    /// read once for the k products instead of k times (the plan basis's 12 right-hand sides).
    pub(crate) fn apply_many(&self, x: &[f64], k: usize) -> Vec<f64> {
        // The vector count as a constant, so that the inner loops over it unroll.
        macro_rules! dispatch {
            ($($n:literal)*) => {
                match k {
                    $($n => self.apply_k::<$n>(x),)*
                    _ => interleave(
                        &(0..k).map(|v| self.apply(&column(x, k, v))).collect::<Vec<_>>(),
                    ),
                }
            };
        }
        dispatch!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
    }

    fn apply_k<const K: usize>(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        let bounds = self.row_runs();
        let at = |i: usize| -> [[f64; K]; 3] {
            std::array::from_fn(|c| std::array::from_fn(|v| x[(3 * i + c) * K + v]))
        };
        let partial: Vec<Vec<f64>> = bounds
            .par_windows(2)
            .map(|w| {
                let mut y = vec![0.0; n];
                for i in w[0]..w[1] {
                    let xi = at(i);
                    let mut yi = [[0.0; K]; 3];
                    for p in self.ptr[i]..self.ptr[i + 1] {
                        let j = self.col[p] as usize;
                        let b = &self.val[p];
                        let xj = at(j);
                        for r in 0..3 {
                            for v in 0..K {
                                yi[r][v] += b[3 * r] * xj[0][v]
                                    + b[3 * r + 1] * xj[1][v]
                                    + b[3 * r + 2] * xj[2][v];
                            }
                        }
                        if j != i {
                            let yj = &mut y[3 * j * K..3 * (j + 1) * K];
                            for c in 0..3 {
                                for v in 0..K {
                                    yj[c * K + v] +=
                                        b[c] * xi[0][v] + b[3 + c] * xi[1][v] + b[6 + c] * xi[2][v];
                                }
                            }
                        }
                    }
                    let yi_out = &mut y[3 * i * K..3 * (i + 1) * K];
                    for r in 0..3 {
                        for v in 0..K {
                            yi_out[r * K + v] += yi[r][v];
                        }
                    }
                }
                y
            })
            .collect();
        sum_parts(partial, n)
    }
}

/// Separate vectors into the interleaved layout of [`SymmetricBlocks::apply_many`].
pub(crate) fn interleave(columns: &[Vec<f64>]) -> Vec<f64> {
    let k = columns.len();
    let n = columns.first().map_or(0, Vec::len);
    let mut out = vec![0.0; n * k];
    for (v, c) in columns.iter().enumerate() {
        for (d, x) in c.iter().enumerate() {
            out[d * k + v] = *x;
        }
    }
    out
}

/// Vector v of an interleaved set of k.
pub(crate) fn column(x: &[f64], k: usize, v: usize) -> Vec<f64> {
    x.iter().skip(v).step_by(k).copied().collect()
}

/// a · b for 3×3 row-major blocks.
pub(crate) fn times(a: &Block, b: &Block) -> Block {
    std::array::from_fn(|e| {
        let (r, c) = (e / 3, e % 3);
        a[3 * r] * b[c] + a[3 * r + 1] * b[3 + c] + a[3 * r + 2] * b[6 + c]
    })
}

/// aᵀ.
pub(crate) fn transposed(a: &Block) -> Block {
    std::array::from_fn(|e| a[3 * (e % 3) + e / 3])
}

/// aᵀ b c.
pub(crate) fn congruence(a: &Block, b: &Block, c: &Block) -> Block {
    times(&transposed(a), &times(b, c))
}

/// The threads' partial products summed into one vector of `n` entries.
fn sum_parts(partial: Vec<Vec<f64>>, n: usize) -> Vec<f64> {
    let mut parts = partial.into_iter();
    let mut y = parts.next().unwrap_or_else(|| vec![0.0; n]);
    for p in parts {
        y.par_iter_mut()
            .zip(p.par_iter())
            .for_each(|(a, b)| *a += b);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The product equals the dense symmetric matrix's, duplicates summed.
    #[test]
    fn product_equals_the_dense_symmetric_product() {
        let nodes = 5;
        let n = 3 * nodes;
        let mut k = Vec::new();
        let mut dense = vec![vec![0.0; n]; n];
        for r in 0..n {
            for c in 0..=r {
                // A sparse pattern: nodes 0 and 4 not coupled, some entries twice.
                if (r / 3, c / 3) == (4, 0) {
                    continue;
                }
                let v = ((r * 7 + c * 3) as f64).sin();
                k.push((r, c, v));
                if (r + c) % 4 == 0 {
                    k.push((r, c, 0.5));
                }
                let v = v + if (r + c) % 4 == 0 { 0.5 } else { 0.0 };
                dense[r][c] += v;
                if r != c {
                    dense[c][r] += v;
                }
            }
        }
        let m = SymmetricBlocks::from_lower(nodes, &k);
        let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).cos()).collect();
        let y = m.apply(&x);
        for r in 0..n {
            let want: f64 = (0..n).map(|c| dense[r][c] * x[c]).sum();
            assert!((y[r] - want).abs() < 1e-12, "row {r}: {} vs {want}", y[r]);
        }
        // Several vectors at once, interleaved: each the single product (up to summation
        // order), for a vector count with an unrolled kernel and one past them.
        for k in [3, 17] {
            let xs: Vec<Vec<f64>> = (0..k)
                .map(|v| {
                    (0..n)
                        .map(|i| ((i * (v + 2)) as f64 * 0.17).sin())
                        .collect()
                })
                .collect();
            let ys = m.apply_many(&interleave(&xs), k);
            for (v, x) in xs.iter().enumerate() {
                let y = m.apply(x);
                let got = column(&ys, k, v);
                for r in 0..n {
                    assert!((got[r] - y[r]).abs() < 1e-12, "k {k}, vector {v}, row {r}");
                }
            }
        }
        let mut back = vec![vec![0.0; n]; n];
        for (r, c, v) in m.lower_triplets() {
            back[r][c] += v;
        }
        for r in 0..n {
            for c in 0..=r {
                assert!((back[r][c] - dense[r][c]).abs() < 1e-12);
            }
        }
    }
}

//! A symmetric sparse matrix of 3×3 node blocks (3 DOFs per node), its lower block triangle
//! stored row by row: the operator of the iterative solve (fem/pmultigrid.rs), applied to a
//! vector in one pass over the blocks. Blocks instead of scalar entries: one index per nine
//! values (the 10-node real CT's 0.35 M nodes: 12 bytes per scalar entry as triplets of u32
//! and f64, 8.4 per entry in blocks), and 3×3 products the compiler unrolls.

use rayon::prelude::*;

/// A 3×3 block, row-major: entry (r, c) at 3 r + c.
pub(crate) type Block = [f64; 9];

/// A stored entry: f64, or f32 for a copy that only a preconditioner reads (half the memory
/// traffic of its products; the arithmetic is f64 either way).
pub(crate) trait Entry: Copy + Send + Sync + Into<f64> {}
impl Entry for f64 {}
impl Entry for f32 {}

pub(crate) struct SymmetricBlocks<T = f64> {
    /// Per row node i, its blocks ptr[i]..ptr[i + 1]: column nodes j ≤ i ascending, the
    /// diagonal block last (stored whole).
    ptr: Vec<usize>,
    col: Vec<u32>,
    val: Vec<[T; 9]>,
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

    /// The same matrix with its entries rounded to f32.
    pub(crate) fn to_f32(&self) -> SymmetricBlocks<f32> {
        SymmetricBlocks {
            ptr: self.ptr.clone(),
            col: self.col.clone(),
            val: self.val.par_iter().map(|b| b.map(|v| v as f32)).collect(),
        }
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
}

/// The per-thread partial products of [`SymmetricBlocks::apply_many_into`], kept from one
/// product to the next: allocated anew each time, their pages were mapped and zeroed by the
/// kernel at every product (a fifth of the 10-node solve's time was system time).
#[derive(Default)]
pub(crate) struct Partials(Vec<Vec<f64>>);

impl<T: Entry> SymmetricBlocks<T> {
    pub(crate) fn nodes(&self) -> usize {
        self.ptr.len() - 1
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

    /// y = A x (x with 3 entries per node).
    #[cfg(test)]
    pub(crate) fn apply(&self, x: &[f64]) -> Vec<f64> {
        self.apply_many(x, 1)
    }

    /// Y = A X for `k` vectors at once, interleaved: entry (DOF d, vector v) at d k + v. One
    /// pass over the blocks serves every vector, so the matrix (the solve's memory traffic) is
    /// read once for the k products instead of k times (the plan basis's right-hand sides).
    pub(crate) fn apply_many(&self, x: &[f64], k: usize) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        self.apply_many_into(x, k, &mut y, &mut Partials::default());
        y
    }

    /// [`SymmetricBlocks::apply_many`] into `y` (overwritten), with the threads' partial
    /// products in `partials`.
    pub(crate) fn apply_many_into(
        &self,
        x: &[f64],
        k: usize,
        y: &mut [f64],
        partials: &mut Partials,
    ) {
        // The vector count as a constant, so that the inner loops over it unroll.
        macro_rules! dispatch {
            ($($n:literal)*) => {
                match k {
                    $($n => self.apply_k::<$n>(x, y, partials),)*
                    _ => {
                        for v in 0..k {
                            let yv = self.apply_many(&column(x, k, v), 1);
                            y.iter_mut().skip(v).step_by(k).zip(yv).for_each(|(y, a)| *y = a);
                        }
                    }
                }
            };
        }
        dispatch!(1 2 3 4 5 6 7 8)
    }

    /// The rows are split among the threads in runs of about equal block counts. A lower block
    /// scatters into its column node's rows too, all before the run's end: the last run adds
    /// into y itself, each other run into its own partial vector up to its end, the partials
    /// then summed into y.
    fn apply_k<const K: usize>(&self, x: &[f64], y: &mut [f64], partials: &mut Partials) {
        let bounds = self.row_runs();
        let runs = bounds.len() - 1;
        partials.0.resize_with(runs.saturating_sub(1), Vec::new);
        for (p, w) in partials.0.iter_mut().zip(bounds.windows(2)) {
            p.resize(3 * K * w[1], 0.0);
        }
        let mut outs: Vec<&mut [f64]> = partials
            .0
            .iter_mut()
            .zip(bounds.windows(2))
            .map(|(p, w)| &mut p[..3 * K * w[1]])
            .collect();
        outs.push(y);
        outs.par_iter_mut()
            .zip(bounds.par_windows(2))
            .for_each(|(out, w)| {
                out.fill(0.0);
                self.rows_k::<K>(x, w[0]..w[1], out);
            });
        let y = outs.pop().unwrap_or_default();
        for p in outs {
            y[..p.len()]
                .par_iter_mut()
                .zip(p.par_iter())
                .for_each(|(a, b)| *a += b);
        }
    }

    /// The `rows`' blocks' part of A X added into `y` (rows and their column nodes), with
    /// 256-bit vector instructions where the processor has them: the build targets the x86-64
    /// baseline, whose 128-bit registers hold half of a four-vector row (so the kernel spilled
    /// to the stack), and the block products are most of the iterative solve's time.
    fn rows_k<const K: usize>(&self, x: &[f64], rows: std::ops::Range<usize>, y: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            unsafe { self.rows_k_avx2::<K>(x, rows, y) };
            return;
        }
        self.rows_k_portable::<K>(x, rows, y);
    }

    /// [`Self::rows_k`] compiled for AVX2: the same operations in the same order (Rust contracts
    /// no multiply and add into an FMA), four vectors' entries to a register.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn rows_k_avx2<const K: usize>(&self, x: &[f64], rows: std::ops::Range<usize>, y: &mut [f64]) {
        self.rows_k_portable::<K>(x, rows, y);
    }

    #[inline(always)]
    fn rows_k_portable<const K: usize>(
        &self,
        x: &[f64],
        rows: std::ops::Range<usize>,
        y: &mut [f64],
    ) {
        let at = |i: usize| -> [[f64; K]; 3] {
            std::array::from_fn(|c| std::array::from_fn(|v| x[(3 * i + c) * K + v]))
        };
        for i in rows {
            let xi = at(i);
            let mut yi = [[0.0; K]; 3];
            for p in self.ptr[i]..self.ptr[i + 1] {
                let j = self.col[p] as usize;
                let b: [f64; 9] = self.val[p].map(Into::into);
                let xj = at(j);
                for r in 0..3 {
                    for v in 0..K {
                        yi[r][v] +=
                            b[3 * r] * xj[0][v] + b[3 * r + 1] * xj[1][v] + b[3 * r + 2] * xj[2][v];
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

//! The one symmetric sparse matrix–vector product: K stored by rows from its lower-triangle
//! triplets (as `FemMesh::assemble` gives them). Each row is summed in increasing column order,
//! which for triplets sorted by (column, row) without duplicates is also the order a
//! column-by-column scatter of the lower triangle adds them in: results do not depend on which
//! of the two a caller used before, nor on the thread count.

/// y = K x for K given by its lower-triangle triplets (duplicates summed).
pub fn multiply(k: &[(usize, usize, f64)], x: &[f64]) -> Vec<f64> {
    SymmetricCsr::from_lower(x.len(), k).apply(x)
}

/// A symmetric matrix (given by lower-triangle triplets, duplicates summed) stored by rows with
/// both triangles, so a product is one pass over each row, rows in parallel.
pub(crate) struct SymmetricCsr {
    start: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f64>,
}

impl SymmetricCsr {
    pub(crate) fn from_lower(n: usize, lower: &[(usize, usize, f64)]) -> SymmetricCsr {
        let mut t: Vec<(u32, u32, f64)> = Vec::with_capacity(2 * lower.len());
        for &(r, c, v) in lower {
            t.push((r as u32, c as u32, v));
            if r != c {
                t.push((c as u32, r as u32, v));
            }
        }
        t.sort_unstable_by_key(|e| (e.0, e.1));
        let mut start = vec![0usize; n + 1];
        let (mut cols, mut vals): (Vec<u32>, Vec<f64>) = (Vec::new(), Vec::new());
        let mut last: Option<(u32, u32)> = None;
        for (r, c, v) in t {
            if last == Some((r, c)) {
                if let Some(x) = vals.last_mut() {
                    *x += v;
                }
                continue;
            }
            last = Some((r, c));
            cols.push(c);
            vals.push(v);
            start[r as usize + 1] = cols.len();
        }
        for i in 1..=n {
            start[i] = start[i].max(start[i - 1]);
        }
        SymmetricCsr { start, cols, vals }
    }

    /// y = K x.
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        use rayon::prelude::*;
        (0..self.start.len() - 1)
            .into_par_iter()
            .with_min_len(4096)
            .map(|r| {
                let mut y = 0.0;
                for j in self.start[r]..self.start[r + 1] {
                    y += self.vals[j] * x[self.cols[j] as usize];
                }
                y
            })
            .collect()
    }

    /// y = (I₃ ⊗ K) v for v stacked as three blocks of n.
    pub(crate) fn apply3(&self, v: &[f64], n: usize) -> Vec<f64> {
        use rayon::prelude::*;
        let rows: Vec<[f64; 3]> = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .map(|r| {
                let mut y = [0.0; 3];
                for j in self.start[r]..self.start[r + 1] {
                    let (c, w) = (self.cols[j] as usize, self.vals[j]);
                    y[0] += w * v[c];
                    y[1] += w * v[n + c];
                    y[2] += w * v[2 * n + c];
                }
                y
            })
            .collect();
        let mut out = vec![0.0; 3 * n];
        for (r, y) in rows.iter().enumerate() {
            out[r] = y[0];
            out[n + r] = y[1];
            out[2 * n + r] = y[2];
        }
        out
    }
}

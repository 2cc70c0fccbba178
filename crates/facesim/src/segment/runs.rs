//! Voxel masks as runs along x, and their connected components.
//!
//! A head CT's masks (tissue above a threshold, outside air, bone) are a few large blobs: stored
//! as runs of consecutive set voxels along each x row they take ~1 % of the voxel count, and a
//! union–find over runs (two runs are joined when they touch across neighbouring rows) labels
//! components without a u32 field the size of the volume. Runs are found slice by slice in
//! parallel; the union–find pass over the runs is serial but touches each run a few times.

use crate::union_find::UnionFind;
use rayon::prelude::*;

/// Runs [x0, x1) of set voxels per row; row r = j + ny·k owns runs\[row_start\[r\]..row_start\[r+1\]\].
pub struct Runs {
    pub dims: [usize; 3],
    pub row_start: Vec<usize>,
    pub runs: Vec<[u32; 2]>,
}

impl Runs {
    /// Runs of the voxels where `set(a)` holds (a = i + nx (j + ny k)).
    pub fn find(dims: [usize; 3], set: impl Fn(usize) -> bool + Sync) -> Runs {
        let [nx, ny, nz] = dims;
        let per_slice: Vec<(Vec<usize>, Vec<[u32; 2]>)> = (0..nz)
            .into_par_iter()
            .map(|k| {
                let mut counts = Vec::with_capacity(ny);
                let mut runs = Vec::new();
                for j in 0..ny {
                    let base = nx * (j + ny * k);
                    let before = runs.len();
                    let mut i = 0;
                    while i < nx {
                        if set(base + i) {
                            let s = i;
                            while i < nx && set(base + i) {
                                i += 1;
                            }
                            runs.push([s as u32, i as u32]);
                        } else {
                            i += 1;
                        }
                    }
                    counts.push(runs.len() - before);
                }
                (counts, runs)
            })
            .collect();
        Self::concat(dims, per_slice)
    }

    fn concat(dims: [usize; 3], per_slice: Vec<(Vec<usize>, Vec<[u32; 2]>)>) -> Runs {
        let total: usize = per_slice.iter().map(|(_, r)| r.len()).sum();
        let mut row_start = Vec::with_capacity(dims[1] * dims[2] + 1);
        let mut runs = Vec::with_capacity(total);
        row_start.push(0);
        for (counts, r) in per_slice {
            for c in counts {
                row_start.push(row_start.last().copied().unwrap_or(0) + c);
            }
            runs.extend(r);
        }
        Runs {
            dims,
            row_start,
            runs,
        }
    }

    /// The runs `keep(run index)` selects.
    pub fn filter(&self, keep: impl Fn(usize) -> bool) -> Runs {
        let mut row_start = Vec::with_capacity(self.row_start.len());
        let mut runs = Vec::new();
        row_start.push(0);
        for r in 0..self.row_start.len() - 1 {
            for q in self.row_start[r]..self.row_start[r + 1] {
                if keep(q) {
                    runs.push(self.runs[q]);
                }
            }
            row_start.push(runs.len());
        }
        Runs {
            dims: self.dims,
            row_start,
            runs,
        }
    }

    /// The gaps between the runs of each row: the runs of the complement mask.
    pub fn complement(&self) -> Runs {
        let nx = self.dims[0] as u32;
        let mut row_start = Vec::with_capacity(self.row_start.len());
        let mut runs = Vec::with_capacity(self.runs.len() + self.row_start.len());
        row_start.push(0);
        for r in 0..self.row_start.len() - 1 {
            let mut x = 0;
            for q in self.runs_in_row(r) {
                if q[0] > x {
                    runs.push([x, q[0]]);
                }
                x = q[1];
            }
            if x < nx {
                runs.push([x, nx]);
            }
            row_start.push(runs.len());
        }
        Runs {
            dims: self.dims,
            row_start,
            runs,
        }
    }

    pub fn voxels(&self) -> usize {
        self.runs.iter().map(|r| (r[1] - r[0]) as usize).sum()
    }

    /// Row (j, k) of run-row index r.
    pub fn row(&self, r: usize) -> (usize, usize) {
        (r % self.dims[1], r / self.dims[1])
    }

    /// The runs of run-row r = j + ny·k.
    pub(crate) fn runs_in_row(&self, r: usize) -> &[[u32; 2]] {
        &self.runs[self.row_start[r]..self.row_start[r + 1]]
    }

    /// Whether voxel (i, j, k) is in the mask (false outside the grid).
    pub fn contains(&self, i: usize, j: usize, k: usize) -> bool {
        let [nx, ny, nz] = self.dims;
        if i >= nx || j >= ny || k >= nz {
            return false;
        }
        let runs = self.runs_in_row(j + ny * k);
        let at = runs.partition_point(|r| r[1] as usize <= i);
        at < runs.len() && runs[at][0] as usize <= i
    }

    /// The mask as one bool per voxel.
    pub(crate) fn paint(&self) -> Vec<bool> {
        let mut m = vec![false; self.dims.iter().product()];
        self.paint_into(&mut m, true);
        m
    }

    /// Set `value` at every voxel of the mask in `field` (one entry per voxel; slices in
    /// parallel).
    pub(crate) fn paint_into<T: Copy + Send + Sync>(&self, field: &mut [T], value: T) {
        let [nx, ny, _] = self.dims;
        if nx * ny == 0 {
            return;
        }
        field
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, sl)| {
                for j in 0..ny {
                    for q in self.runs_in_row(j + ny * k) {
                        sl[nx * j + q[0] as usize..nx * j + q[1] as usize].fill(value);
                    }
                }
            });
    }

    /// Connected components (6- or 26-connectivity): component id per run and each
    /// component's voxel count.
    pub fn components(&self, conn26: bool) -> (Vec<u32>, Vec<usize>) {
        let [_, ny, nz] = self.dims;
        let mut sets = UnionFind::new(self.runs.len());
        // Backward neighbour rows (dj, dk): every adjacency is visited from its later row.
        let back: &[(i64, i64)] = if conn26 {
            &[(-1, 0), (-1, -1), (0, -1), (1, -1)]
        } else {
            &[(-1, 0), (0, -1)]
        };
        // Runs [a0, a1) and [b0, b1) touch across rows when they overlap (6-connectivity) or
        // overlap after widening by one voxel (26-connectivity: diagonal neighbours).
        let slack = conn26 as u32;
        for k in 0..nz {
            for j in 0..ny {
                let r = j + ny * k;
                let mine = self.row_start[r]..self.row_start[r + 1];
                if mine.is_empty() {
                    continue;
                }
                for &(dj, dk) in back {
                    let (jj, kk) = (j as i64 + dj, k as i64 + dk);
                    if jj < 0 || kk < 0 || jj >= ny as i64 {
                        continue;
                    }
                    let o = jj as usize + ny * kk as usize;
                    let (mut p, mut q) = (mine.start, self.row_start[o]);
                    let (pe, qe) = (mine.end, self.row_start[o + 1]);
                    while p < pe && q < qe {
                        let (a, b) = (self.runs[p], self.runs[q]);
                        if a[0] < b[1] + slack && b[0] < a[1] + slack {
                            sets.union(p, q);
                        }
                        // Advance whichever run ends first.
                        if a[1] < b[1] {
                            p += 1;
                        } else {
                            q += 1;
                        }
                    }
                }
            }
        }
        let (id, count) = sets.labels();
        let mut sizes = vec![0; count];
        for (q, &c) in id.iter().enumerate() {
            sizes[c as usize] += (self.runs[q][1] - self.runs[q][0]) as usize;
        }
        (id, sizes)
    }
}

/// Connected components of a voxel mask: component id per voxel (u32::MAX outside) and each
/// component's size (for tests and small volumes; the pipeline works on runs).
pub fn components(mask: &[bool], dims: [usize; 3], conn26: bool) -> (Vec<u32>, Vec<usize>) {
    let runs = Runs::find(dims, |a| mask[a]);
    let (cid, sizes) = runs.components(conn26);
    let mut id = vec![u32::MAX; mask.len()];
    for r in 0..runs.row_start.len() - 1 {
        let (j, k) = runs.row(r);
        let base = dims[0] * (j + dims[1] * k);
        for q in runs.row_start[r]..runs.row_start[r + 1] {
            let [a, b] = runs.runs[q];
            id[base + a as usize..base + b as usize].fill(cid[q]);
        }
    }
    (id, sizes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Components by breadth-first search over voxels: the reference.
    fn flood(mask: &[bool], dims: [usize; 3], conn26: bool) -> Vec<u32> {
        let [nx, ny, nz] = dims;
        let mut id = vec![u32::MAX; mask.len()];
        let mut next = 0;
        for s in 0..mask.len() {
            if !mask[s] || id[s] != u32::MAX {
                continue;
            }
            id[s] = next;
            let mut queue = vec![s];
            while let Some(a) = queue.pop() {
                let (i, j, k) = (a % nx, (a / nx) % ny, a / (nx * ny));
                for dk in -1i64..=1 {
                    for dj in -1i64..=1 {
                        for di in -1i64..=1 {
                            let steps = di.abs() + dj.abs() + dk.abs();
                            if steps == 0 || (!conn26 && steps > 1) {
                                continue;
                            }
                            let (x, y, z) = (i as i64 + di, j as i64 + dj, k as i64 + dk);
                            if x < 0 || y < 0 || z < 0 {
                                continue;
                            }
                            let (x, y, z) = (x as usize, y as usize, z as usize);
                            if x >= nx || y >= ny || z >= nz {
                                continue;
                            }
                            let b = x + nx * (y + ny * z);
                            if mask[b] && id[b] == u32::MAX {
                                id[b] = next;
                                queue.push(b);
                            }
                        }
                    }
                }
            }
            next += 1;
        }
        id
    }

    #[test]
    fn run_components_equal_a_voxel_flood_fill() {
        let dims = [17, 11, 9];
        let n = 17 * 11 * 9;
        let mut state = 12345u64;
        for density in [0.2, 0.35, 0.5, 0.7] {
            let mask: Vec<bool> = (0..n)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    ((state >> 33) as f64 / (1u64 << 31) as f64) < density
                })
                .collect();
            for conn26 in [false, true] {
                let (id, sizes) = components(&mask, dims, conn26);
                let reference = flood(&mask, dims, conn26);
                let count = reference
                    .iter()
                    .filter(|&&x| x != u32::MAX)
                    .max()
                    .map_or(0, |m| m + 1);
                assert_eq!(sizes.len() as u32, count, "density {density}, 26: {conn26}");
                // The same partition: a bijection between the two labellings.
                let mut map = std::collections::HashMap::new();
                for a in 0..n {
                    assert_eq!(id[a] == u32::MAX, reference[a] == u32::MAX);
                    if id[a] != u32::MAX {
                        assert_eq!(*map.entry(id[a]).or_insert(reference[a]), reference[a]);
                    }
                }
                assert_eq!(
                    sizes.iter().sum::<usize>(),
                    mask.iter().filter(|m| **m).count()
                );
            }
        }
    }

    #[test]
    fn complement_and_paint_invert_the_mask() {
        let dims = [7, 4, 3];
        let mask: Vec<bool> = (0..84).map(|a| (a * 7 + 3) % 5 < 2).collect();
        let runs = Runs::find(dims, |a| mask[a]);
        assert_eq!(runs.paint(), mask);
        let inverse: Vec<bool> = mask.iter().map(|m| !m).collect();
        assert_eq!(runs.complement().paint(), inverse);
        assert_eq!(runs.voxels() + runs.complement().voxels(), 84);
    }
}

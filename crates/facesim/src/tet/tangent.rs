//! The tangent stiffness of a linear-tetrahedron mesh as a symmetric block-sparse matrix (3×3
//! blocks per node pair), in the nodes' hold frames, assembled by a scatter map built once from
//! the mesh: a Newton iteration reassembles values without sorting triplets, and applies the
//! matrix to vectors (the Krylov solve of `newton_krylov`) without a factorisation.

use super::holds::Frame;
use rayon::prelude::*;

/// Block (row node, col node) with row ≥ col; blocks of one row are contiguous.
pub(crate) struct BlockMatrix {
    row_start: Vec<usize>,
    col: Vec<u32>,
    /// Row-major 3×3 blocks.
    pub(crate) values: Vec<[f64; 9]>,
    /// Per tetrahedron, per corner pair (a, b) with a ≤ b in [`PAIRS`]: the block's index and
    /// whether the stored block is the pair's transpose.
    slots: Vec<[(u32, bool); 10]>,
}

/// The ten corner pairs of a tetrahedron (diagonal first).
const PAIRS: [(usize, usize); 10] = [
    (0, 0),
    (1, 1),
    (2, 2),
    (3, 3),
    (1, 0),
    (2, 0),
    (3, 0),
    (2, 1),
    (3, 1),
    (3, 2),
];

impl BlockMatrix {
    /// The pattern of `tets` over `nodes` nodes (values zero).
    pub(crate) fn new(nodes: usize, tets: &[[u32; 4]]) -> BlockMatrix {
        let mut rows: Vec<Vec<u32>> = vec![Vec::new(); nodes];
        for t in tets {
            for &(a, b) in &PAIRS {
                let (r, c) = (t[a].max(t[b]), t[a].min(t[b]));
                rows[r as usize].push(c);
            }
        }
        rows.par_iter_mut().for_each(|r| {
            r.sort_unstable();
            r.dedup();
        });
        let mut row_start = Vec::with_capacity(nodes + 1);
        row_start.push(0);
        for r in &rows {
            row_start.push(row_start.last().copied().unwrap_or(0) + r.len());
        }
        let col: Vec<u32> = rows.into_iter().flatten().collect();
        let slots = tets
            .par_iter()
            .map(|t| {
                PAIRS.map(|(a, b)| {
                    let (r, c) = (t[a].max(t[b]) as usize, t[a].min(t[b]));
                    let row = &col[row_start[r]..row_start[r + 1]];
                    let k = row.binary_search(&c).unwrap_or(0);
                    ((row_start[r] + k) as u32, t[a] < t[b])
                })
            })
            .collect();
        BlockMatrix {
            values: vec![[0.0; 9]; col.len()],
            row_start,
            col,
            slots,
        }
    }

    /// Assemble from element matrices (12×12, global components; `element(e)` is None for an
    /// element to leave out), rotated into the node frames: K′_ab = R_aᵀ K_ab R_b.
    pub(crate) fn assemble(
        &mut self,
        tets: &[[u32; 4]],
        frames: &[Frame],
        element: impl Fn(usize) -> Option<Box<[[f64; 12]; 12]>> + Sync,
    ) {
        let local: Vec<Option<[[f64; 9]; 10]>> = (0..tets.len())
            .into_par_iter()
            .map(|e| {
                let k = element(e)?;
                let t = tets[e];
                Some(PAIRS.map(|(a, b)| {
                    let mut blk = [[0.0; 3]; 3];
                    for (i, row) in blk.iter_mut().enumerate() {
                        for (j, v) in row.iter_mut().enumerate() {
                            *v = k[3 * a + i][3 * b + j];
                        }
                    }
                    let blk = rotate(
                        &frames[t[a] as usize].axes,
                        blk,
                        &frames[t[b] as usize].axes,
                    );
                    std::array::from_fn(|x| blk[x / 3][x % 3])
                }))
            })
            .collect();
        self.values.iter_mut().for_each(|v| *v = [0.0; 9]);
        for (e, blocks) in local.iter().enumerate() {
            let Some(blocks) = blocks else { continue };
            for (p, blk) in blocks.iter().enumerate() {
                let (slot, transposed) = self.slots[e][p];
                let (a, b) = PAIRS[p];
                // A diagonal pair of the element adds to a diagonal block whole.
                let v = &mut self.values[slot as usize];
                for x in 0..9 {
                    let y = if transposed && a != b {
                        3 * (x % 3) + x / 3
                    } else {
                        x
                    };
                    v[x] += blk[y];
                }
            }
        }
    }

    /// y = K x, both 3 entries per node (K symmetric, its lower blocks stored).
    pub(crate) fn apply(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        for r in 0..self.row_start.len() - 1 {
            for k in self.row_start[r]..self.row_start[r + 1] {
                let c = self.col[k] as usize;
                let b = &self.values[k];
                for i in 0..3 {
                    y[3 * r + i] += b[3 * i] * x[3 * c]
                        + b[3 * i + 1] * x[3 * c + 1]
                        + b[3 * i + 2] * x[3 * c + 2];
                }
                if c != r {
                    for j in 0..3 {
                        y[3 * c + j] +=
                            b[j] * x[3 * r] + b[3 + j] * x[3 * r + 1] + b[6 + j] * x[3 * r + 2];
                    }
                }
            }
        }
        y
    }
}

/// R_aᵀ B R_b for 3×3 B, with a node's local axes (rows eᵢ) or the identity.
fn rotate(
    ra: &Option<[[f64; 3]; 3]>,
    b: [[f64; 3]; 3],
    rb: &Option<[[f64; 3]; 3]>,
) -> [[f64; 3]; 3] {
    let left = match ra {
        None => b,
        Some(r) => std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|c| r[i][c] * b[c][j]).sum())
        }),
    };
    match rb {
        None => left,
        Some(r) => std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|d| left[i][d] * r[j][d]).sum())
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tet::holds::{Hold, frames, rotate_lower};

    /// The block matrix applied to a vector equals the rotated triplet matrix of the same
    /// elements (the path the linear solve takes), frames included.
    #[test]
    fn block_assembly_equals_the_rotated_triplets() {
        let tets = vec![[0u32, 1, 2, 3], [1, 2, 3, 4]];
        let elements: Vec<[[f64; 12]; 12]> = (0..2)
            .map(|e| {
                // A symmetric matrix with distinct entries.
                std::array::from_fn(|i| {
                    std::array::from_fn(|j| {
                        let (a, b) = (i.min(j) as f64, i.max(j) as f64);
                        1.0 + a * 0.37 + b * b * 0.11 + e as f64 * 0.5
                    })
                })
            })
            .collect();
        let holds = vec![
            Hold::Free,
            Hold::Slide {
                normal: [0.3, 0.5, 0.8],
                value: 0.0,
            },
            Hold::Fixed([0.0; 3]),
            Hold::Free,
            Hold::Rail {
                direction: [1.0, -1.0, 0.2],
                offset: [0.0; 3],
            },
        ];
        let fr = frames(&holds, 5).unwrap();
        let mut m = BlockMatrix::new(5, &tets);
        m.assemble(&tets, &fr, |e| Some(Box::new(elements[e])));
        let mut triplets = Vec::new();
        for (e, t) in tets.iter().enumerate() {
            for i in 0..12 {
                for j in 0..=i {
                    let (gi, gj) = (3 * t[i / 3] as usize + i % 3, 3 * t[j / 3] as usize + j % 3);
                    let (r, c) = (gi.max(gj), gi.min(gj));
                    triplets.push((r, c, elements[e][i][j]));
                }
            }
        }
        let lower = rotate_lower(&triplets, &fr);
        let x: Vec<f64> = (0..15).map(|i| (i as f64 * 0.7).sin()).collect();
        let mut want = [0.0; 15];
        for &(r, c, v) in &lower {
            want[r] += v * x[c];
            if r != c {
                want[c] += v * x[r];
            }
        }
        let got = m.apply(&x);
        for i in 0..15 {
            assert!(
                (got[i] - want[i]).abs() < 1e-12 * (1.0 + want[i].abs()),
                "{i}"
            );
        }
    }
}

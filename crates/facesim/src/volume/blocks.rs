//! The least and greatest value of a field over boxes of voxels, from per-block extremes: a
//! conservative answer (the blocks covering a box may hold more voxels than it) in one lookup per
//! block. Trilinear samples ([`sample_field`](super::sample_field)) are convex combinations of
//! voxel values, so every sample whose eight voxels lie in a box lies within the box's range:
//! the mesher asks whether an iso-surface can cross a region before it samples the region point
//! by point (tet/from_ct.rs).

/// Voxels per block edge: small enough that a mesher's cube covers few extra voxels, large
/// enough that a cube's query reads few blocks.
const BLOCK: usize = 4;

/// Per-block minimum and maximum of a field on a `dims` grid.
pub(crate) struct BlockRange {
    dims: [usize; 3],
    blocks: [usize; 3],
    min: Vec<f32>,
    max: Vec<f32>,
}

impl BlockRange {
    pub(crate) fn new(data: &[f32], dims: [usize; 3]) -> BlockRange {
        let blocks = dims.map(|d| d.div_ceil(BLOCK).max(1));
        let n = blocks[0] * blocks[1] * blocks[2];
        let (mut min, mut max) = (vec![f32::INFINITY; n], vec![f32::NEG_INFINITY; n]);
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                let row = dims[0] * (y + dims[1] * z);
                let b_row = blocks[0] * (y / BLOCK + blocks[1] * (z / BLOCK));
                for (x, &v) in data[row..row + dims[0]].iter().enumerate() {
                    let b = b_row + x / BLOCK;
                    min[b] = min[b].min(v);
                    max[b] = max[b].max(v);
                }
            }
        }
        BlockRange {
            dims,
            blocks,
            min,
            max,
        }
    }

    /// The least and greatest value over voxels `lo..=hi` (indices per axis, within the grid),
    /// or over a superset of them.
    pub(crate) fn range(&self, lo: [usize; 3], hi: [usize; 3]) -> (f32, f32) {
        let (mut least, mut most) = (f32::INFINITY, f32::NEG_INFINITY);
        for bz in lo[2] / BLOCK..=hi[2] / BLOCK {
            for by in lo[1] / BLOCK..=hi[1] / BLOCK {
                let row = self.blocks[0] * (by + self.blocks[1] * bz);
                for b in row + lo[0] / BLOCK..=row + hi[0] / BLOCK {
                    least = least.min(self.min[b]);
                    most = most.max(self.max[b]);
                }
            }
        }
        (least, most)
    }

    /// The voxels whose values every trilinear sample at voxel coordinates within `lo..=hi`
    /// reads, or None when such a sample may fall outside the grid (where a sample takes its
    /// `outside` value, not a voxel's) or the grid is flat along an axis. `slack` (voxels)
    /// widens the box for the rounding of points computed another way than its corners.
    pub(crate) fn voxels_read(
        &self,
        lo: [f64; 3],
        hi: [f64; 3],
        slack: f64,
    ) -> Option<([usize; 3], [usize; 3])> {
        let mut first = [0; 3];
        let mut last = [0; 3];
        for a in 0..3 {
            let n = self.dims[a];
            let (l, h) = (lo[a] - slack, hi[a] + slack);
            // sample_field's own test for a sample inside the grid.
            if n < 2 || !(l > -0.5 && h < n as f64 - 0.5) {
                return None;
            }
            // The lower of the two voxels a sample reads along this axis, as sample_field picks it.
            let base = |x: f64| (x.clamp(0.0, (n - 1) as f64).floor() as usize).min(n - 2);
            first[a] = base(l);
            last[a] = base(h) + 1;
        }
        Some((first, last))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::sample_field;

    fn field(dims: [usize; 3]) -> Vec<f32> {
        // Deterministic, rough: neighbouring voxels differ by up to hundreds of HU.
        let mut s = 0x9e37_79b9_u32;
        (0..dims[0] * dims[1] * dims[2])
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s % 2000) as f32 - 1000.0
            })
            .collect()
    }

    #[test]
    fn every_sample_in_a_box_lies_within_its_range_and_the_range_is_reached() {
        let dims = [13, 9, 7];
        let data = field(dims);
        let r = BlockRange::new(&data, dims);
        let mut tested = 0;
        for (lo, hi) in [
            ([0.2, 0.1, 0.3], [3.7, 2.2, 1.9]),
            ([-0.4, -0.4, -0.4], [11.9, 7.9, 5.9]),
            ([4.5, 3.0, 2.0], [4.5, 3.0, 2.0]),
            ([7.1, 0.0, 4.9], [11.2, 8.4, 6.4]),
        ] {
            let (first, last) = r.voxels_read(lo, hi, 1e-6).unwrap();
            let (least, most) = r.range(first, last);
            // The range may be wider than the box's voxels (whole blocks), never narrower.
            for z in first[2]..=last[2] {
                for y in first[1]..=last[1] {
                    for x in first[0]..=last[0] {
                        let v = data[x + dims[0] * (y + dims[1] * z)];
                        assert!(least <= v && v <= most);
                    }
                }
            }
            for k in 0..=20 {
                for j in 0..=20 {
                    for i in 0..=20 {
                        let t = [i, j, k].map(|u| u as f64 / 20.0);
                        let c = std::array::from_fn(|a| lo[a] + t[a] * (hi[a] - lo[a]));
                        let v = sample_field(&data, dims, c, f32::NAN);
                        assert!(
                            least <= v && v <= most,
                            "{v} outside {least}..{most} at {c:?}"
                        );
                        tested += 1;
                    }
                }
            }
        }
        assert!(tested > 30_000);
    }

    #[test]
    fn a_box_reaching_past_the_grid_has_no_voxel_range() {
        let dims = [8, 8, 8];
        let r = BlockRange::new(&field(dims), dims);
        assert!(
            r.voxels_read([-0.6, 1.0, 1.0], [3.0, 3.0, 3.0], 0.0)
                .is_none()
        );
        assert!(
            r.voxels_read([1.0, 1.0, 1.0], [3.0, 3.0, 7.5], 0.0)
                .is_none()
        );
        assert!(
            r.voxels_read([1.0, 1.0, 1.0], [3.0, 3.0, 7.4], 0.0)
                .is_some()
        );
        let flat = BlockRange::new(&field([8, 8, 1]), [8, 8, 1]);
        assert!(
            flat.voxels_read([1.0, 1.0, 0.0], [3.0, 3.0, 0.0], 0.0)
                .is_none()
        );
    }
}

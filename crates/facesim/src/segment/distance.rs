//! Squared Euclidean distance transform of a voxel mask (Felzenszwalb & Huttenlocher 2012:
//! separable, exact, anisotropic spacing), optionally only within a band.
//!
//! The skin layer needs distances to the outside air only up to the skin thickness (a few
//! voxels), so `distance_sq_within` cuts every pass at the band: values beyond it become
//! infinite, and the later passes skip lines with nothing finite in them (the head's interior
//! and most of the air). Values within the band are exact.

use rayon::prelude::*;

const INF: f32 = f32::MAX / 4.0;

/// Squared distance (mm²) from every voxel to the nearest voxel with `source` set.
pub fn distance_sq(source: &[bool], dims: [usize; 3], spacing: [f64; 3]) -> Vec<f32> {
    distance_sq_within(source, dims, spacing, f32::INFINITY)
}

/// As `distance_sq` where the squared distance is ≤ `band_sq`; f32::MAX / 4 beyond it.
pub fn distance_sq_within(
    source: &[bool],
    dims: [usize; 3],
    spacing: [f64; 3],
    band_sq: f32,
) -> Vec<f32> {
    let [nx, ny, nz] = dims;
    let slice = nx * ny;
    let mut d = vec![INF; source.len()];
    if slice == 0 || nz == 0 {
        return d;
    }
    let h2 = spacing.map(|s| (s * s) as f32);
    let cut = |x: f32| if x <= band_sq { x } else { INF };
    // x and y lines lie within one z slice: slices in parallel, in place.
    d.par_chunks_mut(slice)
        .zip(source.par_chunks(slice))
        .for_each(|(sl, src)| {
            // x: on a binary mask, the distance to the nearest source in the row is two sweeps.
            for (row, s) in sl.chunks_mut(nx).zip(src.chunks(nx)) {
                let mut last: Option<usize> = None;
                for i in 0..nx {
                    if s[i] {
                        last = Some(i);
                    }
                    if let Some(l) = last {
                        row[i] = cut(h2[0] * ((i - l) as f32).powi(2));
                    }
                }
                let mut next: Option<usize> = None;
                for i in (0..nx).rev() {
                    if s[i] {
                        next = Some(i);
                    }
                    if let Some(l) = next {
                        row[i] = row[i].min(cut(h2[0] * ((l - i) as f32).powi(2)));
                    }
                }
            }
            // y lines in tiles of 16 columns (one cache line of each row per tile).
            const W: usize = 16;
            let mut line = Lines::new(ny);
            let mut tile = vec![0f32; W * ny];
            for i0 in (0..nx).step_by(W) {
                let w = W.min(nx - i0);
                for j in 0..ny {
                    tile[j * W..j * W + w].copy_from_slice(&sl[j * nx + i0..j * nx + i0 + w]);
                }
                for c in 0..w {
                    line.strided(&mut tile, c, W, h2[1], cut);
                }
                for j in 0..ny {
                    sl[j * nx + i0..j * nx + i0 + w].copy_from_slice(&tile[j * W..j * W + w]);
                }
            }
        });
    // z lines cross the slices: rows j in parallel; each gathers the nz × nx block of its
    // columns (contiguous reads), transforms every column and writes the block back.
    let shared = SharedMut(d.as_mut_ptr());
    (0..ny).into_par_iter().for_each(|j| {
        let shared = &shared;
        let mut block = vec![0f32; nz * nx];
        for k in 0..nz {
            let at = j * nx + k * slice;
            // SAFETY: row j of every slice belongs to this task alone; no other task reads or
            // writes it.
            let row = unsafe { std::slice::from_raw_parts(shared.0.add(at), nx) };
            block[k * nx..(k + 1) * nx].copy_from_slice(row);
        }
        let mut line = Lines::new(nz);
        for i in 0..nx {
            line.strided(&mut block, i, nx, h2[2], cut);
        }
        for k in 0..nz {
            let at = j * nx + k * slice;
            // SAFETY: as above — row j of slice k is this task's.
            let row = unsafe { std::slice::from_raw_parts_mut(shared.0.add(at), nx) };
            row.copy_from_slice(&block[k * nx..(k + 1) * nx]);
        }
    });
    d
}

/// The distance field's pointer, shared by tasks that write disjoint rows.
struct SharedMut(*mut f32);
unsafe impl Sync for SharedMut {}

/// Buffers for 1-D transforms of lines of one length (allocated once per task).
struct Lines {
    f: Vec<f32>,
    out: Vec<f32>,
    v: Vec<usize>,
    z: Vec<f64>,
}

impl Lines {
    fn new(n: usize) -> Lines {
        Lines {
            f: vec![0.0; n],
            out: vec![0.0; n],
            v: vec![0; n],
            z: vec![0.0; n + 1],
        }
    }

    /// Transform the line buf[first + q·stride] (q < the line length) in place, each result
    /// passed through `cut`; lines the transform would leave unchanged are skipped.
    fn strided(
        &mut self,
        buf: &mut [f32],
        first: usize,
        stride: usize,
        h2: f32,
        cut: impl Fn(f32) -> f32,
    ) {
        let n = self.f.len();
        if !self.load((0..n).map(|q| buf[first + q * stride])) {
            return;
        }
        self.transform(h2);
        for q in 0..n {
            buf[first + q * stride] = cut(self.out[q]);
        }
    }

    /// Load a line; false when the transform would return it unchanged (all sources, or
    /// nothing finite).
    fn load(&mut self, values: impl Iterator<Item = f32>) -> bool {
        let (mut finite, mut nonzero) = (false, false);
        for (f, x) in self.f.iter_mut().zip(values) {
            *f = x;
            finite |= x < INF;
            nonzero |= x != 0.0;
        }
        finite && nonzero
    }

    /// Lower envelope of parabolas: out[q] = min_p f[p] + h2 (q − p)², skipping infinite f.
    fn transform(&mut self, h2: f32) {
        let (f, v, z) = (&self.f, &mut self.v, &mut self.z);
        let n = f.len();
        self.out.fill(INF);
        let Some(q0) = f.iter().position(|&x| x < INF) else {
            return;
        };
        let mut k = 0usize;
        v[0] = q0;
        z[0] = f64::NEG_INFINITY;
        z[1] = f64::INFINITY;
        let h2 = h2 as f64;
        for q in q0 + 1..n {
            // Inside a run of sources (zeros) only the run's ends can be nearest to a point
            // outside it, and inside it the answer is 0: long runs of air cost no divisions.
            if f[q] >= INF || (f[q] == 0.0 && f[q - 1] == 0.0 && q + 1 < n && f[q + 1] == 0.0) {
                continue;
            }
            let fq = f[q] as f64 + h2 * (q * q) as f64;
            loop {
                let p = v[k];
                let s = (fq - (f[p] as f64 + h2 * (p * p) as f64)) / (2.0 * h2 * (q - p) as f64);
                if s <= z[k] {
                    if k > 0 {
                        k -= 1;
                        continue;
                    }
                    // The new parabola is lowest everywhere so far.
                    v[0] = q;
                    z[1] = f64::INFINITY;
                    break;
                }
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
                break;
            }
        }
        k = 0;
        for (q, o) in self.out.iter_mut().enumerate() {
            while z[k + 1] < q as f64 {
                k += 1;
            }
            if f[q] == 0.0 {
                *o = 0.0;
                continue;
            }
            let p = v[k];
            *o = (f[p] as f64 + h2 * (q as f64 - p as f64).powi(2)) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_transform_is_exact_on_a_point() {
        let dims = [9, 7, 5];
        let mut src = vec![false; 9 * 7 * 5];
        src[4 + 9 * (3 + 7 * 2)] = true;
        let d = distance_sq(&src, dims, [1.0, 2.0, 0.5]);
        for k in 0..5 {
            for j in 0..7 {
                for i in 0..9 {
                    let e = ((i as f64 - 4.0) * 1.0).powi(2)
                        + ((j as f64 - 3.0) * 2.0).powi(2)
                        + ((k as f64 - 2.0) * 0.5).powi(2);
                    assert!((d[i + 9 * (j + 7 * k)] as f64 - e).abs() < 1e-4);
                }
            }
        }
    }

    fn brute_force(src: &[bool], dims: [usize; 3], sp: [f64; 3]) -> Vec<f64> {
        let [nx, ny, _] = dims;
        let pos = |a: usize| {
            let (i, j, k) = (a % nx, (a / nx) % ny, a / (nx * ny));
            [i as f64 * sp[0], j as f64 * sp[1], k as f64 * sp[2]]
        };
        (0..src.len())
            .map(|a| {
                let p = pos(a);
                (0..src.len())
                    .filter(|&b| src[b])
                    .map(|b| {
                        let q = pos(b);
                        (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>()
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    #[test]
    fn distance_transform_matches_brute_force_on_scattered_sources() {
        let dims = [11, 6, 8];
        let n = 11 * 6 * 8;
        let sp = [0.7, 1.3, 2.0];
        let src: Vec<bool> = (0..n).map(|a| (a * 37 + 11) % 53 == 0).collect();
        let d = distance_sq(&src, dims, sp);
        for (a, e) in brute_force(&src, dims, sp).into_iter().enumerate() {
            assert!(
                (d[a] as f64 - e).abs() < 1e-3 * e.max(1.0),
                "voxel {a}: {} vs {e}",
                d[a]
            );
        }
    }

    #[test]
    fn the_band_is_exact_inside_and_infinite_outside() {
        let dims = [13, 9, 10];
        let n = 13 * 9 * 10;
        let sp = [0.5, 0.8, 1.1];
        // A slab of sources plus scattered ones: many lines with no finite value in the band.
        let src: Vec<bool> = (0..n)
            .map(|a| a / (13 * 9) == 0 || (a * 29 + 5) % 97 == 0)
            .collect();
        let band = 2.5f32;
        let d = distance_sq_within(&src, dims, sp, band);
        for (a, e) in brute_force(&src, dims, sp).into_iter().enumerate() {
            if e <= band as f64 - 1e-4 {
                assert!((d[a] as f64 - e).abs() < 1e-4, "voxel {a}: {} vs {e}", d[a]);
            } else if e > band as f64 + 1e-4 {
                assert!(
                    d[a] > band,
                    "voxel {a}: {} should lie beyond the band",
                    d[a]
                );
            }
        }
    }
}

//! The CT resampled on a grid of the head frame: (s, v, a) = lateral, up, forward, one cell a
//! millimetre, each cell outside the CT, soft, bone or tooth. The detectors walk it along the
//! frame's axes, so a head pitched in the scanner reads as an upright one.

use crate::anatomy::bone::Bone;
use crate::labels;
use crate::landmarks::HeadFrame;
use rayon::prelude::*;

/// Cell size (mm).
pub(super) const H: f64 = 1.0;
/// Bone-labelled voxels at least this bright are tooth (enamel, dentine); bone is mostly below.
pub(super) const TOOTH_HU: f32 = 1200.0;

pub(super) const OUT: u8 = 0;
pub(super) const SOFT: u8 = 1;
pub(super) const BONE: u8 = 2;
pub(super) const TOOTH: u8 = 3;

/// Frame coordinates the jaws lie in, relative to the frame's origin (the nose tip's level on
/// the midsagittal plane): lateral, vertical, anterior bounds (mm).
pub(super) const LO: [f64; 3] = [-80.0, -160.0, -170.0];
pub(super) const HI: [f64; 3] = [80.0, 40.0, 20.0];

pub(super) struct Grid {
    pub n: [usize; 3],
    cells: Vec<u8>,
}

impl Grid {
    /// Nearest-voxel classes of the cells of [LO, HI].
    pub fn new(bone: &Bone, frame: &HeadFrame) -> Grid {
        let n = [0, 1, 2].map(|k| ((HI[k] - LO[k]) / H).round() as usize + 1);
        let vol = bone.vol;
        let map = vol.voxel_map();
        let dims = vol.dims;
        let per_row = n[0];
        let mut cells = vec![OUT; n[0] * n[1] * n[2]];
        // One row of s per (v, a): its voxel coordinates step linearly.
        let origin = map.to_voxel(frame.point([LO[0], 0.0, 0.0]));
        let zero = map.to_voxel(frame.point([0.0, 0.0, 0.0]));
        let axis = |k: usize| {
            let mut c = [0.0; 3];
            c[k] = H;
            let q = map.to_voxel(frame.point(c));
            [q[0] - zero[0], q[1] - zero[1], q[2] - zero[2]]
        };
        let (ds, dv, da) = (axis(0), axis(1), axis(2));
        cells
            .par_chunks_mut(per_row)
            .enumerate()
            .for_each(|(row, out)| {
                let (iv, ia) = (row / n[2], row % n[2]);
                let (fv, fa) = (LO[1] / H + iv as f64, LO[2] / H + ia as f64);
                for (is, cell) in out.iter_mut().enumerate() {
                    let f = is as f64;
                    let c = [0, 1, 2].map(|k| origin[k] + f * ds[k] + fv * dv[k] + fa * da[k]);
                    if (0..3).any(|k| !(c[k] > -0.5 && c[k] < dims[k] as f64 - 0.5)) {
                        continue;
                    }
                    let [i, j, l] = c.map(|x| x.round() as usize);
                    let idx = vol.idx(i, j, l);
                    *cell = if bone.labels.get(idx) != Some(&labels::BONE) {
                        SOFT
                    } else if vol.data.get(idx).is_some_and(|h| *h >= TOOTH_HU) {
                        TOOTH
                    } else {
                        BONE
                    };
                }
            });
        Grid { n, cells }
    }

    /// The class of cell (is, iv, ia); OUT beyond the grid.
    #[inline]
    pub fn at(&self, is: isize, iv: isize, ia: isize) -> u8 {
        if is < 0 || iv < 0 || ia < 0 {
            return OUT;
        }
        let (is, iv, ia) = (is as usize, iv as usize, ia as usize);
        if is >= self.n[0] || iv >= self.n[1] || ia >= self.n[2] {
            return OUT;
        }
        self.cells[(iv * self.n[2] + ia) * self.n[0] + is]
    }

    /// The index along axis k nearest to coordinate x (may be outside the grid).
    #[inline]
    pub fn index(&self, k: usize, x: f64) -> isize {
        ((x - LO[k]) / H).round() as isize
    }

    /// The coordinate along axis k of index i.
    #[inline]
    pub fn coord(&self, k: usize, i: isize) -> f64 {
        LO[k] + i as f64 * H
    }
}

/// Whether a cell class is bone (teeth included).
#[inline]
pub(super) fn hard(c: u8) -> bool {
    c >= BONE
}

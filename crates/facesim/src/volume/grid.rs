//! The volume itself: voxels (HU) on a grid with its voxel-to-LPS affine (mm), and the geometry
//! every reader and stage shares. The readers beside it build this type; `mod.rs` only picks the
//! reader by file.

use crate::error::{Error, Result};
use serde::Serialize;
use std::path::Path;

/// Largest volume we agree to allocate (voxels). 1024³ f32 is 4 GiB: refuse anything larger
/// before allocating, so a corrupt header cannot exhaust memory.
pub(crate) const MAX_VOXELS: usize = 1 << 30;

#[derive(Clone, Debug)]
pub struct Volume {
    /// Voxel counts along i, j, k.
    pub dims: [usize; 3],
    /// Voxel size along i, j, k in mm (all > 0).
    pub spacing: [f64; 3],
    /// LPS position (mm) of the centre of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// Unit LPS direction of the i, j, k axes: `direction[c]` is the direction of axis c.
    pub direction: [[f64; 3]; 3],
    /// HU values, i fastest: index = i + nx (j + ny k).
    pub data: Vec<f32>,
}

/// `facesim inspect` output (docs/reference/case.md).
#[derive(Serialize, Debug, PartialEq)]
pub struct Inspect {
    pub dims: [usize; 3],
    pub spacing: [f64; 3],
    pub origin: [f64; 3],
    pub direction: [[f64; 3]; 3],
    pub hu_min: f64,
    pub hu_max: f64,
    pub hu_mean: f64,
}

impl Volume {
    /// Validate geometry and size; used by every reader before it allocates voxel data.
    pub(crate) fn check_geometry(
        path: &Path,
        dims: [usize; 3],
        spacing: [f64; 3],
        origin: [f64; 3],
        direction: [[f64; 3]; 3],
    ) -> Result<()> {
        if dims.contains(&0) {
            return Err(Error::input(
                path,
                format!("empty volume, dimensions {dims:?}"),
            ));
        }
        let n = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        match n {
            Some(n) if n <= MAX_VOXELS => {}
            _ => {
                return Err(Error::input(
                    path,
                    format!("dimensions {dims:?} exceed the limit of {MAX_VOXELS} voxels"),
                ));
            }
        }
        if spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
            return Err(Error::input(
                path,
                format!("voxel spacing {spacing:?} must be finite and positive"),
            ));
        }
        if origin.iter().any(|o| !o.is_finite())
            || direction.iter().flatten().any(|d| !d.is_finite())
        {
            return Err(Error::input(path, "non-finite origin or orientation"));
        }
        let det = det3(direction);
        if det.abs() < 1e-3 {
            return Err(Error::input(
                path,
                "degenerate orientation (axes are parallel)",
            ));
        }
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.data.len()
    }
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    #[inline]
    pub fn idx(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    #[inline]
    pub fn ijk(&self, idx: usize) -> [usize; 3] {
        let nx = self.dims[0];
        let ny = self.dims[1];
        [idx % nx, (idx / nx) % ny, idx / (nx * ny)]
    }

    /// Continuous voxel coordinates → LPS mm.
    pub fn to_world(&self, c: [f64; 3]) -> [f64; 3] {
        let mut p = self.origin;
        for (a, &ca) in c.iter().enumerate() {
            for (r, pr) in p.iter_mut().enumerate() {
                *pr += self.direction[a][r] * self.spacing[a] * ca;
            }
        }
        p
    }

    /// The LPS mm → voxel map with the direction matrix inverted once, for loops that map many
    /// points (ray marching, spring tracing).
    pub(crate) fn voxel_map(&self) -> VoxelMap {
        VoxelMap {
            origin: self.origin,
            inv: inv3(self.direction),
            spacing: self.spacing,
        }
    }

    /// LPS mm → continuous voxel coordinates.
    pub fn to_voxel(&self, p: [f64; 3]) -> [f64; 3] {
        self.voxel_map().to_voxel(p)
    }

    /// Trilinear interpolation at LPS point `p`; `outside` beyond the grid (clamped at the
    /// outermost voxel centres, so the border half-voxel takes the border value).
    pub fn sample(&self, p: [f64; 3], outside: f32) -> f32 {
        sample_field(&self.data, self.dims, self.to_voxel(p), outside)
    }

    pub fn voxel_volume(&self) -> f64 {
        self.spacing[0] * self.spacing[1] * self.spacing[2] * det3(self.direction).abs()
    }

    /// World-space bounding box of the voxel centres.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for corner in 0..8 {
            let c = [
                if corner & 1 != 0 {
                    (self.dims[0] - 1) as f64
                } else {
                    0.0
                },
                if corner & 2 != 0 {
                    (self.dims[1] - 1) as f64
                } else {
                    0.0
                },
                if corner & 4 != 0 {
                    (self.dims[2] - 1) as f64
                } else {
                    0.0
                },
            ];
            let p = self.to_world(c);
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    }

    pub fn inspect(&self) -> Inspect {
        let (mut lo, mut hi, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for &v in &self.data {
            let v = v as f64;
            lo = lo.min(v);
            hi = hi.max(v);
            sum += v;
        }
        Inspect {
            dims: self.dims,
            spacing: self.spacing,
            origin: self.origin,
            direction: self.direction,
            hu_min: lo,
            hu_max: hi,
            hu_mean: sum / self.data.len() as f64,
        }
    }

    /// Reject NaN/infinite voxels: they would poison every threshold downstream.
    pub(crate) fn check_finite(&self, path: &Path) -> Result<()> {
        if let Some(i) = self.data.iter().position(|v| !v.is_finite()) {
            return Err(Error::input(
                path,
                format!("non-finite voxel value at voxel {:?}", self.ijk(i)),
            ));
        }
        Ok(())
    }
}

/// Trilinear interpolation in a scalar field laid out like [`Volume::data`], at continuous
/// voxel coordinates `c`.
/// LPS mm → continuous voxel coordinates of one volume (see `Volume::voxel_map`).
#[derive(Clone, Copy, Debug)]
pub struct VoxelMap {
    origin: [f64; 3],
    inv: [[f64; 3]; 3],
    spacing: [f64; 3],
}

impl VoxelMap {
    #[inline]
    pub fn to_voxel(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.origin[0],
            p[1] - self.origin[1],
            p[2] - self.origin[2],
        ];
        let inv = &self.inv;
        let mut c = [0.0; 3];
        for (a, ca) in c.iter_mut().enumerate() {
            *ca = (inv[a][0] * d[0] + inv[a][1] * d[1] + inv[a][2] * d[2]) / self.spacing[a];
        }
        c
    }
}

/// Whether `p` lies past the voxel centres' box `bounds` ([`Volume::bounds`]): where the scan
/// ends, beyond which the fields read air. The skin iso-surface closes within a voxel past the
/// last centre; a tenth of a millimetre keeps nodes warped onto the centres' plane inside.
pub fn past_scan_end(bounds: ([f64; 3], [f64; 3]), p: [f64; 3]) -> bool {
    (0..3).any(|k| p[k] < bounds.0[k] - 0.1 || p[k] > bounds.1[k] + 0.1)
}

pub fn sample_field(data: &[f32], dims: [usize; 3], c: [f64; 3], outside: f32) -> f32 {
    let mut i0 = [0usize; 3];
    let mut f = [0.0f64; 3];
    for a in 0..3 {
        let n = dims[a] as f64;
        if !(c[a] > -0.5 && c[a] < n - 0.5) {
            return outside;
        }
        let x = c[a].clamp(0.0, n - 1.0);
        let b = (x.floor() as usize).min(dims[a].saturating_sub(2));
        i0[a] = b;
        f[a] = if dims[a] > 1 { x - b as f64 } else { 0.0 };
    }
    let nx = dims[0];
    let nxy = dims[0] * dims[1];
    let step = [
        usize::from(dims[0] > 1),
        if dims[1] > 1 { nx } else { 0 },
        if dims[2] > 1 { nxy } else { 0 },
    ];
    let base = i0[0] + nx * i0[1] + nxy * i0[2];
    let mut acc = 0.0f64;
    for corner in 0..8 {
        let mut w = 1.0;
        let mut o = base;
        for a in 0..3 {
            if corner & (1 << a) != 0 {
                w *= f[a];
                o += step[a];
            } else {
                w *= 1.0 - f[a];
            }
        }
        if w != 0.0 {
            acc += w * data[o] as f64;
        }
    }
    acc as f32
}

pub(crate) fn det3(m: [[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Inverse of the 3×3 matrix whose *columns* are `m[0], m[1], m[2]`; returned as rows:
/// `inv[a]` is the row that extracts coordinate a.
pub fn inv3(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    // Columns a = m[0], b = m[1], c = m[2]: rows of the inverse are (b×c, c×a, a×b)/det.
    let (a, b, c) = (m[0], m[1], m[2]);
    let cross = |u: [f64; 3], v: [f64; 3]| {
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    };
    let r0 = cross(b, c);
    let det = a[0] * r0[0] + a[1] * r0[1] + a[2] * r0[2];
    let r1 = cross(c, a);
    let r2 = cross(a, b);
    let s = 1.0 / det;
    [
        [r0[0] * s, r0[1] * s, r0[2] * s],
        [r1[0] * s, r1[1] * s, r1[2] * s],
        [r2[0] * s, r2[1] * s, r2[2] * s],
    ]
}

/// The LPS directions of the voxel axes i, j, k named by a three-letter patient-direction code,
/// one letter of L/R, P/A and S/I each (`[ct] axes`; "LPS" is the identity, "LAI" = i to the
/// left, j anterior, k inferior); `None` for anything else.
pub fn axes_code(code: &str) -> Option<[[f64; 3]; 3]> {
    let letters: Vec<char> = code.trim().to_uppercase().chars().collect();
    if letters.len() != 3 {
        return None;
    }
    let mut d = [[0.0; 3]; 3];
    let mut used = [false; 3];
    for (a, c) in letters.iter().enumerate() {
        let (row, sign) = match c {
            'L' => (0, 1.0),
            'R' => (0, -1.0),
            'P' => (1, 1.0),
            'A' => (1, -1.0),
            'S' => (2, 1.0),
            'I' => (2, -1.0),
            _ => return None,
        };
        if std::mem::replace(&mut used[row], true) {
            return None;
        }
        d[a][row] = sign;
    }
    Some(d)
}

//! The paper's simulated cylindrical range scan (Koch 1996 §2.4, docs/design/pipeline.md §2).
//!
//! Rays in horizontal planes (constant LPS z) run from outside the head towards a vertical
//! axis through the head's centroid, at angles φ_k = −π + (k + ½)Δφ measured from the anterior
//! direction (−y) towards the patient's left (+x), so the seam (φ = ±π) is at the back of the
//! head. The first air→tissue crossing of the skin field is the skin; continuing inwards, the
//! first crossing of the bone field (within `max_skull_depth` of the skin) is the skull.
//! Crossings are refined by bisection on the trilinear field. Each grid node keeps its
//! parameter coordinates (u, v) = (R0·φ, z), R0 the mean skin radius.

use crate::mesh::{Column, Mesh};
use crate::volume::{Volume, sample_field};
use rayon::prelude::*;
use std::f64::consts::PI;

pub struct ScanParams {
    pub angle_step_deg: f64,
    /// Vertical step (mm).
    pub z_step: f64,
    pub skin_iso: f32,
    pub bone_iso: f32,
    /// Search depth for the skull below the skin (mm); deeper hits are treated as misses, so a
    /// bone defect leaves a hole instead of a spike to the far side of the skull.
    pub max_skull_depth: f64,
}

pub struct ScanResult {
    pub skin: Mesh,
    pub skull: Mesh,
    /// Axis (x, y) of the scan and the parameter radius R0.
    pub axis: [f64; 2],
    pub r0: f64,
    pub rays: usize,
    pub skin_misses: usize,
    pub skull_misses: usize,
}

/// Find the first crossing of `iso` (from below to above) along p(t) = o + t·d for t in
/// [t0 + skip, t1], stepping by `dt` from t0, refined by bisection.
#[allow(clippy::too_many_arguments)] // a ray, its interval and step, the field and level
fn first_crossing(
    field: &[f32],
    vol: &Volume,
    o: [f64; 3],
    d: [f64; 3],
    t0: f64,
    skip: f64,
    t1: f64,
    dt: f64,
    iso: f32,
) -> Option<f64> {
    let map = vol.voxel_map();
    let at = |t: f64| {
        let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
        sample_field(field, vol.dims, map.to_voxel(p), f32::MIN)
    };
    // Samples at t0 + k·dt (not accumulated), so a ray started further in (`skip`) samples
    // exactly the points a ray from t0 would.
    let mut k = (skip / dt).floor().max(0.0) as usize;
    let mut prev_t = t0 + k as f64 * dt;
    let mut prev = at(prev_t);
    while prev_t < t1 {
        k += 1;
        let t = (t0 + k as f64 * dt).min(t1);
        let v = at(t);
        if prev < iso && v >= iso {
            let (mut lo, mut hi) = (prev_t, t);
            for _ in 0..30 {
                let m = 0.5 * (lo + hi);
                if at(m) >= iso { hi = m } else { lo = m }
            }
            return Some(0.5 * (lo + hi));
        }
        prev_t = t;
        prev = v;
    }
    None
}

/// Count, coordinate sums and bounding box of a set of points.
struct Extent {
    count: usize,
    sum: [f64; 2],
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Extent {
    fn empty() -> Extent {
        Extent {
            count: 0,
            sum: [0.0; 2],
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
        }
    }

    fn add(&mut self, w: [f64; 3]) {
        self.count += 1;
        self.sum[0] += w[0];
        self.sum[1] += w[1];
        for c in 0..3 {
            self.lo[c] = self.lo[c].min(w[c]);
            self.hi[c] = self.hi[c].max(w[c]);
        }
    }

    fn merge(a: Extent, b: Extent) -> Extent {
        Extent {
            count: a.count + b.count,
            sum: [a.sum[0] + b.sum[0], a.sum[1] + b.sum[1]],
            lo: std::array::from_fn(|c| a.lo[c].min(b.lo[c])),
            hi: std::array::from_fn(|c| a.hi[c].max(b.hi[c])),
        }
    }
}

/// Largest horizontal distance from `axis` (x, y) to a corner of the box [lo, hi].
fn corner_radius(lo: [f64; 3], hi: [f64; 3], axis: [f64; 2]) -> f64 {
    [lo[0] - axis[0], hi[0] - axis[0]]
        .iter()
        .flat_map(|dx| [lo[1] - axis[1], hi[1] - axis[1]].map(|dy| (dx * dx + dy * dy).sqrt()))
        .fold(0.0, f64::max)
}

/// The scan's cylindrical grid: rays at `nphi` angles on `nz` planes z = zmin + r·z_step,
/// each from radius `rmax` around `axis` inwards.
struct Grid {
    axis: [f64; 2],
    rmax: f64,
    /// Where a ray's search for the skin starts (just outside the head's bounding box).
    t_start: f64,
    nphi: usize,
    dphi: f64,
    nz: usize,
    zmin: f64,
    z_step: f64,
    /// March step along a ray (half the smallest voxel spacing).
    step: f64,
}

impl Grid {
    fn new(vol: &Volume, head: &[bool], p: &ScanParams) -> Grid {
        // Axis through the centroid of the head, the head's z range and horizontal bounding box
        // (slices in parallel).
        let [nx, ny, _] = vol.dims;
        let ext = head
            .par_chunks((nx * ny).max(1))
            .enumerate()
            .map(|(k, sl)| {
                let mut e = Extent::empty();
                for (a, &h) in sl.iter().enumerate() {
                    if h {
                        e.add(vol.to_world([(a % nx) as f64, (a / nx) as f64, k as f64]));
                    }
                }
                e
            })
            .reduce(Extent::empty, Extent::merge);
        let axis = [
            ext.sum[0] / ext.count.max(1) as f64,
            ext.sum[1] / ext.count.max(1) as f64,
        ];
        let (zmin, zmax) = (ext.lo[2], ext.hi[2]);
        let (lo, hi) = vol.bounds();
        let rmax = corner_radius(lo, hi, axis);
        // Rays start just outside the head's bounding box (the skin field is below the iso level
        // everywhere else): a trilinear sample sees voxels within one spacing per axis.
        let margin = 3.0 * vol.spacing.iter().cloned().fold(0.0, f64::max);
        let rhead = corner_radius(ext.lo, ext.hi, axis) + margin;
        let nphi = (360.0 / p.angle_step_deg).round().max(8.0) as usize;
        Grid {
            axis,
            rmax,
            t_start: (rmax - rhead).max(0.0),
            nphi,
            dphi: 2.0 * PI / nphi as f64,
            nz: ((zmax - zmin) / p.z_step).floor() as usize + 1,
            zmin,
            z_step: p.z_step,
            step: 0.5 * vol.spacing.iter().cloned().fold(f64::INFINITY, f64::min),
        }
    }

    /// φ of angle index k.
    fn phi(&self, k: usize) -> f64 {
        -PI + (k as f64 + 0.5) * self.dphi
    }

    /// z of plane r.
    fn z(&self, r: usize) -> f64 {
        self.zmin + r as f64 * self.z_step
    }
}

/// A ray's skin or skull point.
type Hit = Option<[f64; 3]>;

/// One row per z; each node: (skin point, skull point).
fn cast_rays(
    vol: &Volume,
    skin_field: &[f32],
    bone_field: &[f32],
    p: &ScanParams,
    g: &Grid,
) -> Vec<Vec<(Hit, Hit)>> {
    let (axis, rmax, step) = (g.axis, g.rmax, g.step);
    (0..g.nz)
        .into_par_iter()
        .map(|r| {
            let z = g.z(r);
            (0..g.nphi)
                .map(|k| {
                    let phi = g.phi(k);
                    let o = [axis[0] + rmax * phi.sin(), axis[1] - rmax * phi.cos(), z];
                    let d = [-phi.sin(), phi.cos(), 0.0];
                    let Some(ts) = first_crossing(
                        skin_field, vol, o, d, 0.0, g.t_start, rmax, step, p.skin_iso,
                    ) else {
                        return (None, None);
                    };
                    let skin = [o[0] + ts * d[0], o[1] + ts * d[1], o[2]];
                    let skull = first_crossing(
                        bone_field,
                        vol,
                        o,
                        d,
                        ts,
                        0.0,
                        (ts + p.max_skull_depth).min(rmax),
                        step,
                        p.bone_iso,
                    )
                    .map(|tb| [o[0] + tb * d[0], o[1] + tb * d[1], o[2]]);
                    (Some(skin), skull)
                })
                .collect()
        })
        .collect()
}

/// The mesh of the nodes `pick` selects, with (u, v) = (R0·φ, z) columns: two triangles per
/// grid cell, one when a corner is missing.
fn grid_mesh(
    rows: &[Vec<(Hit, Hit)>],
    pick: impl Fn(&(Hit, Hit)) -> Hit,
    g: &Grid,
    r0: f64,
) -> Mesh {
    let (nphi, nz) = (g.nphi, g.nz);
    let mut index = vec![u32::MAX; nz * nphi];
    let mut verts = Vec::new();
    let mut u = Vec::new();
    let mut v = Vec::new();
    for (r, row) in rows.iter().enumerate() {
        for (k, node) in row.iter().enumerate() {
            if let Some(x) = pick(node) {
                index[r * nphi + k] = verts.len() as u32;
                verts.push(x);
                u.push(r0 * g.phi(k));
                v.push(g.z(r));
            }
        }
    }
    let mut tris = Vec::new();
    for r in 0..nz.saturating_sub(1) {
        // No wrap across the seam at the back (k = nphi−1 → 0): u is discontinuous there.
        for k in 0..nphi - 1 {
            let a = index[r * nphi + k];
            let b = index[r * nphi + k + 1];
            let c = index[(r + 1) * nphi + k];
            let d = index[(r + 1) * nphi + k + 1];
            // φ grows towards +x and z upwards: (a, b, c) winds with the normal outwards.
            match (a != u32::MAX, b != u32::MAX, c != u32::MAX, d != u32::MAX) {
                (true, true, true, true) => {
                    tris.push([a, b, c]);
                    tris.push([b, d, c]);
                }
                (true, true, true, false) => tris.push([a, b, c]),
                (true, true, false, true) => tris.push([a, b, d]),
                (true, false, true, true) => tris.push([a, d, c]),
                (false, true, true, true) => tris.push([b, d, c]),
                _ => {}
            }
        }
    }
    let mut m = Mesh::new(verts, tris);
    m.vertex_columns = vec![
        Column {
            name: "u".into(),
            values: u,
        },
        Column {
            name: "v".into(),
            values: v,
        },
    ];
    m.compact();
    m
}

pub fn scan(
    vol: &Volume,
    skin_field: &[f32],
    bone_field: &[f32],
    head: &[bool],
    p: &ScanParams,
) -> ScanResult {
    let g = Grid::new(vol, head, p);
    let axis = g.axis;
    let rows = cast_rays(vol, skin_field, bone_field, p, &g);
    let hits: Vec<f64> = rows
        .iter()
        .flatten()
        .filter_map(|(s, _)| {
            s.map(|s| ((s[0] - axis[0]).powi(2) + (s[1] - axis[1]).powi(2)).sqrt())
        })
        .collect();
    let r0 = if hits.is_empty() {
        1.0
    } else {
        hits.iter().sum::<f64>() / hits.len() as f64
    };
    let skin_misses = rows.iter().flatten().filter(|(s, _)| s.is_none()).count();
    let skull_misses = rows
        .iter()
        .flatten()
        .filter(|(s, b)| s.is_some() && b.is_none())
        .count();
    ScanResult {
        skin: grid_mesh(&rows, |n| n.0, &g, r0),
        skull: grid_mesh(&rows, |n| n.1, &g, r0),
        axis,
        r0,
        rays: g.nz * g.nphi,
        skin_misses,
        skull_misses,
    }
}

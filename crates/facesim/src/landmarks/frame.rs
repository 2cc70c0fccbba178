//! The head frame (docs/guide/landmarks.md "Frame"): the midsagittal plane from the face's mirror
//! symmetry, the facial vertical and anterior axes, and the midsagittal section of a mesh.
//!
//! All in LPS mm. `lateral` is the plane's unit normal (towards the patient's left, +x-ish),
//! `vertical` the CT's superior axis made orthogonal to it, `anterior = lateral × vertical`
//! (−y-ish). A point's frame coordinates are (s, v, a): lateral offset from the plane, height,
//! anteriority.

use crate::compare::SurfaceIndex;
use crate::mesh::Mesh;
use crate::vec3::{add, cross, dot, norm, scale, sub};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct HeadFrame {
    /// A point on the midsagittal plane (the nose tip's level; LPS mm).
    pub origin: [f64; 3],
    pub lateral: [f64; 3],
    pub vertical: [f64; 3],
    pub anterior: [f64; 3],
    /// Mean mirror mismatch of the facial points used (mm): how symmetric the face is.
    pub symmetry_residual_mm: f64,
}

pub(super) fn unit(a: [f64; 3]) -> [f64; 3] {
    scale(a, 1.0 / norm(a).max(1e-300))
}

impl HeadFrame {
    /// The frame with midsagittal plane through `origin` with normal `lateral`.
    pub(crate) fn from_plane(origin: [f64; 3], lateral: [f64; 3], residual: f64) -> HeadFrame {
        HeadFrame::with_up(origin, unit(lateral), [0.0, 0.0, 1.0], residual)
    }

    /// The frame with midsagittal plane through `origin` with unit normal `lateral`, its
    /// vertical `up` made orthogonal to that normal.
    pub(crate) fn with_up(
        origin: [f64; 3],
        lateral: [f64; 3],
        up: [f64; 3],
        residual: f64,
    ) -> HeadFrame {
        let vertical = unit(sub(up, scale(lateral, dot(up, lateral))));
        HeadFrame {
            origin,
            lateral,
            vertical,
            anterior: cross(lateral, vertical),
            symmetry_residual_mm: residual,
        }
    }

    /// (s, v, a) of an LPS point.
    pub fn coords(&self, p: [f64; 3]) -> [f64; 3] {
        let d = sub(p, self.origin);
        [
            dot(d, self.lateral),
            dot(d, self.vertical),
            dot(d, self.anterior),
        ]
    }

    /// The LPS point of frame coordinates (s, v, a).
    pub fn point(&self, c: [f64; 3]) -> [f64; 3] {
        add(
            self.origin,
            add(
                scale(self.lateral, c[0]),
                add(scale(self.vertical, c[1]), scale(self.anterior, c[2])),
            ),
        )
    }

    /// Reflect p across the midsagittal plane.
    pub fn mirror(&self, p: [f64; 3]) -> [f64; 3] {
        let s = dot(sub(p, self.origin), self.lateral);
        sub(p, scale(self.lateral, 2.0 * s))
    }
}

fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(((v.len().saturating_sub(1)) as f64 * q) as usize)
        .copied()
        .unwrap_or(0.0)
}

/// The head frame of a face: a first plane x = the middle of the skin's x-extent at the nose
/// tip's level (the most anterior point near that middle), then refined by mirror symmetry
/// (mirror ICP): the facial points within 70 mm of the nose tip are reflected, each finds its
/// closest point on the skin, and the plane that bisects those pairs best (normal along the
/// mean pair difference, through the mean pair midpoint) replaces the plane; 12 rounds. None for
/// an empty skin.
pub fn head_frame(skin: &Mesh) -> Option<HeadFrame> {
    let v = &skin.vertices;
    if v.is_empty() || skin.triangles.is_empty() {
        return None;
    }
    let xs: Vec<f64> = v.iter().map(|p| p[0]).collect();
    let x0 = 0.5 * (percentile(xs.clone(), 0.02) + percentile(xs, 0.98));
    let tip = v
        .iter()
        .filter(|p| (p[0] - x0).abs() < 20.0)
        .min_by(|a, b| a[1].total_cmp(&b[1]))?;
    let level: Vec<f64> = v
        .iter()
        .filter(|p| (p[2] - tip[2]).abs() < 10.0)
        .map(|p| p[0])
        .collect();
    let xm = 0.5 * (percentile(level.clone(), 0.02) + percentile(level, 0.98));
    let mut frame = HeadFrame::from_plane([xm, tip[1], tip[2]], [1.0, 0.0, 0.0], f64::NAN);
    // Facial points: within 70 mm of the tip, in front of it by at most 60 mm; every k-th so
    // that about 4000 take part.
    let face: Vec<[f64; 3]> = v
        .iter()
        .filter(|p| norm(sub(**p, *tip)) < 70.0 && p[1] - tip[1] < 60.0)
        .copied()
        .collect();
    let step = (face.len() / 4000).max(1);
    let face: Vec<[f64; 3]> = face.into_iter().step_by(step).collect();
    if face.len() < 20 {
        return Some(frame);
    }
    let index = SurfaceIndex::new(skin);
    for _ in 0..12 {
        let mut pairs: Vec<([f64; 3], [f64; 3], f64)> = face
            .iter()
            .map(|p| {
                let (d, q) = index.closest(frame.mirror(*p));
                (*p, q, d)
            })
            .collect();
        // The better-matched 80 %: a face is not exactly symmetric, and its border is not.
        let cut = percentile(pairs.iter().map(|x| x.2).collect(), 0.8);
        pairs.retain(|x| x.2 <= cut);
        let mut n = [0.0; 3];
        let mut mid = [0.0; 3];
        for (p, q, _) in &pairs {
            let d = sub(*p, *q);
            let d = if dot(d, frame.lateral) < 0.0 {
                scale(d, -1.0)
            } else {
                d
            };
            n = add(n, d);
            mid = add(mid, scale(add(*p, *q), 0.5));
        }
        if norm(n) < 1e-9 {
            break;
        }
        let k = pairs.len().max(1) as f64;
        let mid = scale(mid, 1.0 / k);
        let n = unit(n);
        // Keep the origin at the tip's height and depth, on the new plane.
        let o = frame.origin;
        let shift = dot(sub(mid, o), n);
        let residual = pairs.iter().map(|x| x.2).sum::<f64>() / k;
        frame = HeadFrame::from_plane(add(o, scale(n, shift)), n, residual);
    }
    Some(frame)
}

/// The midsagittal section of a mesh: segments (v, a) of the plane s = 0 through its triangles.
pub fn section(mesh: &Mesh, frame: &HeadFrame) -> Vec<[[f64; 2]; 2]> {
    let c: Vec<[f64; 3]> = mesh.vertices.iter().map(|p| frame.coords(*p)).collect();
    plane_cut(&c, &mesh.triangles, 0, 0.0)
}

/// The section of triangles (vertices `c`) by the plane where coordinate `k` equals `x`, as
/// segments in the other two coordinates (in order).
pub(crate) fn plane_cut(c: &[[f64; 3]], tris: &[[u32; 3]], k: usize, x: f64) -> Vec<[[f64; 2]; 2]> {
    let (i0, i1) = match k {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let mut out = Vec::new();
    for t in tris {
        let q = t.map(|i| c[i as usize]);
        let mut hits: Vec<[f64; 2]> = Vec::with_capacity(2);
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let (di, dj) = (q[i][k] - x, q[j][k] - x);
            if (di < 0.0) != (dj < 0.0) {
                let f = di / (di - dj);
                hits.push([
                    q[i][i0] + f * (q[j][i0] - q[i][i0]),
                    q[i][i1] + f * (q[j][i1] - q[i][i1]),
                ]);
            }
        }
        if hits.len() == 2 {
            out.push([hits[0], hits[1]]);
        }
    }
    out
}

/// A profile: the most anterior section point per height, sampled every `STEP_MM` from `v0`
/// (NaN where the section has nothing at that height, or nothing accepted by `keep`).
#[derive(Clone, Debug)]
pub struct Profile {
    pub v0: f64,
    pub a: Vec<f64>,
}

pub(crate) const STEP_MM: f64 = 0.25;

impl Profile {
    pub fn height(&self, i: usize) -> f64 {
        self.v0 + i as f64 * STEP_MM
    }
    pub fn index(&self, v: f64) -> Option<usize> {
        let i = ((v - self.v0) / STEP_MM).round();
        (i >= 0.0 && (i as usize) < self.a.len()).then_some(i as usize)
    }
    /// The anteriority at height v (NaN outside the profile).
    pub fn at(&self, v: f64) -> f64 {
        self.index(v).map_or(f64::NAN, |i| self.a[i])
    }
}

/// The profile of a section, keeping only points (v, a) for which `keep` holds.
pub fn profile(seg: &[[[f64; 2]; 2]], keep: impl Fn(f64, f64) -> bool) -> Option<Profile> {
    let lo = seg
        .iter()
        .flat_map(|s| [s[0][0], s[1][0]])
        .fold(f64::INFINITY, f64::min);
    let hi = seg
        .iter()
        .flat_map(|s| [s[0][0], s[1][0]])
        .fold(f64::NEG_INFINITY, f64::max);
    if !(hi > lo) {
        return None;
    }
    let n = ((hi - lo) / STEP_MM).floor() as usize + 1;
    let mut a = vec![f64::NEG_INFINITY; n];
    for s in seg {
        let (p, q) = if s[0][0] <= s[1][0] {
            (s[0], s[1])
        } else {
            (s[1], s[0])
        };
        let i0 = ((p[0] - lo) / STEP_MM).ceil() as usize;
        let i1 = (((q[0] - lo) / STEP_MM).floor() as usize).min(n - 1);
        for i in i0..=i1 {
            let v = lo + i as f64 * STEP_MM;
            let f = if q[0] > p[0] {
                (v - p[0]) / (q[0] - p[0])
            } else {
                0.0
            };
            let av = p[1] + f * (q[1] - p[1]);
            if keep(v, av) && av > a[i] {
                a[i] = av;
            }
        }
    }
    let a = a
        .into_iter()
        .map(|x| if x.is_finite() { x } else { f64::NAN })
        .collect();
    Some(Profile { v0: lo, a })
}

//! An estimate of the volumetric model's discretisation error on the face: the
//! same case solved again on a mesh of twice the element size (`[tet] skin_size_mm` and
//! `deep_size_mm` doubled; 1/8 of the unknowns), and Richardson's extrapolation: for a method of
//! order p in h, u_h − u ≈ (u_2h − u_h) / (2^p − 1). Linear tetrahedra converge at order 2 in the
//! displacement where the solution is smooth (Ciarlet 1978, ch. 3); near the saw lines it is
//! rougher, so the figure is an estimate, not a bound (docs/design/crosscheck.md measures it against
//! the 10-node and finer answers).

use crate::landmarks::Ordered;
use crate::landmarks::face_regions::{self, NAMES, NONE, RegionStats};
use serde::{Deserialize, Serialize};

/// The order of convergence assumed (linear tetrahedra, displacement).
const ORDER: f64 = 2.0;
/// Face vertices that move less than this (mm) in both solves are left out of `moving_face`.
const MOVING_MM: f64 = 0.1;

/// report.json `discretisation_error` (mm): per face vertex |u_2h − u_h| / (2^p − 1).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DiscretisationError {
    pub method: String,
    /// The second solve's element size at the skin (mm).
    pub coarse_skin_size_mm: f64,
    /// Over the face vertices that move (> 0.1 mm in either solve).
    pub moving_face: RegionStats,
    /// Per facial region (docs/guide/landmarks.md), as report.json `regions`.
    pub regions: Ordered<RegionStats>,
    /// The second solve's wall time (s).
    pub seconds: f64,
}

fn stats(d: Vec<f64>) -> RegionStats {
    let absent = d
        .is_empty()
        .then(|| "no face vertex of this region moves".into());
    face_regions::stats_of(d, absent, None)
}

/// report.json `nonlinear_vs_linear` (mm): per face vertex, the distance between the
/// hyperelastic model's face and the linear model's under the same holds and mesh.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelDifference {
    pub method: String,
    /// Over the face vertices that move (> 0.1 mm in either solve).
    pub moving_face: RegionStats,
    /// Per facial region (docs/guide/landmarks.md), as report.json `regions`.
    pub regions: Ordered<RegionStats>,
}

/// How far the nonlinear face (`nonlinear`) lies from the linear one (`linear`), from the face
/// before (`pre`).
pub(crate) fn nonlinear_vs_linear(
    pre: &[[f64; 3]],
    nonlinear: &[[f64; 3]],
    linear: &[[f64; 3]],
    region_of: &[u8],
) -> ModelDifference {
    let (moving_face, regions) = differences(pre, nonlinear, linear, region_of, 1.0);
    ModelDifference {
        method: "|u(neo-Hookean) - u(linear)| per face vertex, same mesh and holds".into(),
        moving_face,
        regions,
    }
}

/// Per face vertex that moves, |a − b| / scale: over the moving face and per region.
fn differences(
    pre: &[[f64; 3]],
    a: &[[f64; 3]],
    b: &[[f64; 3]],
    region_of: &[u8],
    scale: f64,
) -> (RegionStats, Ordered<RegionStats>) {
    let moved = |a: [f64; 3], b: [f64; 3]| crate::vec3::norm(crate::vec3::sub(a, b));
    let mut moving = Vec::new();
    let mut per_region: Vec<Vec<f64>> = vec![Vec::new(); NAMES.len()];
    for (i, ((p, f), c)) in pre.iter().zip(a).zip(b).enumerate() {
        if moved(*f, *p).max(moved(*c, *p)) <= MOVING_MM {
            continue;
        }
        let e = moved(*f, *c) / scale;
        moving.push(e);
        if let Some(&r) = region_of.get(i).filter(|r| **r != NONE) {
            per_region[r as usize].push(e);
        }
    }
    (
        stats(moving),
        Ordered(
            NAMES
                .iter()
                .zip(per_region)
                .map(|(n, d)| (n.to_string(), stats(d)))
                .collect(),
        ),
    )
}

/// The estimate from the face before (`pre`), as solved (`fine`) and at twice the element size
/// (`coarse`); `region_of` is each vertex's region index (`face_regions::NONE`: none).
pub(crate) fn estimate(
    pre: &[[f64; 3]],
    fine: &[[f64; 3]],
    coarse: &[[f64; 3]],
    region_of: &[u8],
    coarse_skin_size_mm: f64,
    seconds: f64,
) -> DiscretisationError {
    let scale = 2f64.powf(ORDER) - 1.0;
    let (moving_face, regions) = differences(pre, fine, coarse, region_of, scale);
    DiscretisationError {
        method: format!(
            "Richardson: |u(2h) - u(h)| / (2^{ORDER} - 1), the case solved again at twice the element size"
        ),
        coarse_skin_size_mm,
        moving_face,
        regions,
        seconds,
    }
}

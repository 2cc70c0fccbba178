//! Shape measures of a tetrahedral mesh, for report.json and the mesher's tests.
//!
//! Dihedral angle at edge (i, j): the angle between the two faces that share it, the faces
//! opposite nodes k and l. With ∇N the shape-function gradients (each points from its
//! opposite face towards its node, i.e. inward), cos θ_ij = −∇N_k·∇N_l / (|∇N_k| |∇N_l|).
//! Aspect ratio: longest edge / (2√6 · inradius), with inradius = 3V / (total face area);
//! 1 for the regular tetrahedron, growing without bound for slivers, needles and caps.

use super::gradients;
use rayon::prelude::*;

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Quality {
    pub min_dihedral_deg: f64,
    pub max_dihedral_deg: f64,
    /// Longest edge / (2√6 · inradius); 1 for the regular tetrahedron.
    pub worst_aspect_ratio: f64,
    pub tets: usize,
    pub nodes: usize,
    pub volume_mm3: f64,
    /// Flat or inverted tetrahedra (excluded from the angle and ratio figures).
    pub inverted: usize,
}

/// The six dihedral angles (degrees) and the aspect ratio of a positive tetrahedron.
pub(crate) fn tet_shape(x: [[f64; 3]; 4]) -> Option<([f64; 6], f64, f64)> {
    let (v, g) = gradients(x)?;
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let mut angles = [0.0; 6];
    let mut e = 0;
    for k in 0..4 {
        for l in k + 1..4 {
            let c = -dot(g[k], g[l]) / (dot(g[k], g[k]) * dot(g[l], g[l])).sqrt();
            angles[e] = c.clamp(-1.0, 1.0).acos().to_degrees();
            e += 1;
        }
    }
    // |∇N_k| = area_k / (3V): the face areas without cross products.
    let area: f64 = g.iter().map(|gk| 3.0 * v * dot(*gk, *gk).sqrt()).sum();
    let inradius = 3.0 * v / area;
    let mut longest: f64 = 0.0;
    for a in 0..4 {
        for b in a + 1..4 {
            let d = [0, 1, 2].map(|c| x[a][c] - x[b][c]);
            longest = longest.max(dot(d, d).sqrt());
        }
    }
    Some((angles, longest / (2.0 * 6f64.sqrt() * inradius), v))
}

impl Quality {
    pub fn of(nodes: &[[f64; 3]], tets: &[[u32; 4]]) -> Quality {
        let init = || (f64::INFINITY, f64::NEG_INFINITY, 1.0f64, 0.0f64, 0usize);
        let (lo, hi, ratio, volume, inverted) = tets
            .par_iter()
            .map(|t| match tet_shape(t.map(|n| nodes[n as usize])) {
                Some((a, r, v)) => (
                    a.iter().copied().fold(f64::INFINITY, f64::min),
                    a.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                    r,
                    v,
                    0,
                ),
                None => (f64::INFINITY, f64::NEG_INFINITY, 1.0, 0.0, 1),
            })
            .reduce(init, |a, b| {
                (
                    a.0.min(b.0),
                    a.1.max(b.1),
                    a.2.max(b.2),
                    a.3 + b.3,
                    a.4 + b.4,
                )
            });
        Quality {
            min_dihedral_deg: lo,
            max_dihedral_deg: hi,
            worst_aspect_ratio: ratio,
            tets: tets.len(),
            nodes: nodes.len(),
            volume_mm3: volume,
            inverted,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_tetrahedron_has_ratio_one_and_arccos_one_third() {
        let s = 2.0;
        let x = [[s, s, s], [s, -s, -s], [-s, s, -s], [-s, -s, s]];
        let x = if gradients(x).is_some() {
            x
        } else {
            [x[1], x[0], x[2], x[3]]
        };
        let (a, r, v) = tet_shape(x).unwrap();
        let want = (1.0f64 / 3.0).acos().to_degrees();
        assert!(a.iter().all(|d| (d - want).abs() < 1e-9), "{a:?}");
        assert!((r - 1.0).abs() < 1e-12, "{r}");
        // Edge 2√2 s: V = a³ / (6√2).
        let e = 2.0 * 2f64.sqrt() * s;
        assert!((v - e.powi(3) / (6.0 * 2f64.sqrt())).abs() < 1e-9);
    }

    #[test]
    fn right_corner_tetrahedron_angles() {
        // The corner of a cube: three 90° dihedrals at the corner edges, arccos(1/√3) elsewhere.
        let q = Quality::of(
            &[
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            &[[0, 1, 2, 3]],
        );
        assert!((q.max_dihedral_deg - 90.0).abs() < 1e-9);
        let want = (1.0f64 / 3f64.sqrt()).acos().to_degrees();
        assert!(
            (q.min_dihedral_deg - want).abs() < 1e-9,
            "{}",
            q.min_dihedral_deg
        );
        assert!((q.volume_mm3 - 1.0 / 6.0).abs() < 1e-12 && q.inverted == 0);
    }
}

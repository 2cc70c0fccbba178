//! ITK transform files (`.tfm`, `.txt`) as 3D Slicer's Transforms module saves them
//! (docs/guide/slicer.md "Transform files").
//!
//! Conventions, from Slicer's developer guide (Transforms, "Transform files"):
//! - the file is in LPS (ITK's frame), so its numbers are facesim's frame as they stand;
//! - it holds the *resampling* transform (fixed → moving, Slicer's "from parent"): the inverse of
//!   the move that carries a model (the bone segment) to its new place. A plan move is the
//!   *modelling* transform, so by default the file's transform is inverted; a file written
//!   the other way round is read with `transform_direction = "modelling"`.
//!
//! The linear ITK transforms all map x ↦ M (x − c) + c + t, with c the `FixedParameters` centre;
//! they differ in how `Parameters` spell M and t. Only rigid moves are accepted: a matrix with
//! scaling, shear or a reflection is an error naming the file.

use crate::error::{Error, Result};
use std::path::Path;

/// A rigid move x ↦ R (x − centre) + centre + translation (LPS mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RigidMove {
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
    pub centre: [f64; 3],
}

/// Which way the file's transform maps points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Direction {
    /// Fixed → moving (what ITK and Slicer write): the plan move is its inverse.
    Resampling,
    /// Moving → fixed: the plan move itself.
    Modelling,
}

impl Direction {
    pub fn parse(s: &str) -> Option<Direction> {
        match s {
            "resampling" => Some(Direction::Resampling),
            "modelling" | "modeling" => Some(Direction::Modelling),
            _ => None,
        }
    }
}

impl RigidMove {
    // Only the unit tests use it (a reference the production path does not need).
    #[cfg(test)]
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [0, 1, 2].map(|a| p[a] - self.centre[a]);
        [0, 1, 2].map(|i| {
            (0..3).map(|k| self.rotation[i][k] * d[k]).sum::<f64>()
                + self.centre[i]
                + self.translation[i]
        })
    }

    /// The inverse move, about the same centre: x = Rᵀ (y − c − t) + c.
    pub fn inverse(&self) -> RigidMove {
        let rt = transpose(self.rotation);
        let rt_t: [f64; 3] =
            [0, 1, 2].map(|i| (0..3).map(|k| rt[i][k] * self.translation[k]).sum());
        RigidMove {
            rotation: rt,
            translation: rt_t.map(|v| -v),
            centre: self.centre,
        }
    }

    /// The plan's form (docs/reference/case.md `[[osteotomy]]`): `rotate_deg` (R = Rz·Ry·Rx) and
    /// `translate` about `pivot` = the centre, so that R (p − pivot) + pivot + translate is
    /// this move.
    pub(crate) fn plan_form(&self) -> ([f64; 3], [f64; 3], [f64; 3]) {
        (self.translation, euler_xyz_deg(self.rotation), self.centre)
    }
}

fn transpose(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]))
}

/// Angles (degrees) about x, then y, then z with R = Rz·Ry·Rx (`osteotomy::rotation`'s order).
pub(crate) fn euler_xyz_deg(r: [[f64; 3]; 3]) -> [f64; 3] {
    // R[2][0] = −sin(b); R[2][1] = cos(b) sin(a); R[2][2] = cos(b) cos(a);
    // R[1][0] = cos(b) sin(c); R[0][0] = cos(b) cos(c).
    let sb = (-r[2][0]).clamp(-1.0, 1.0);
    let b = sb.asin();
    let (a, c) = if sb.abs() < 1.0 - 1e-12 {
        (r[2][1].atan2(r[2][2]), r[1][0].atan2(r[0][0]))
    } else {
        // Gimbal lock (b = ±90°): only a ∓ c is determined; take c = 0.
        (r[0][1].atan2(r[1][1]) * sb.signum(), 0.0)
    };
    [a, b, c].map(f64::to_degrees)
}

/// Read a transform file and return the plan move (modelling direction) it describes.
pub fn read(path: &Path, direction: Direction) -> Result<RigidMove> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::input(path, e))?;
    let file_move = parse(&text).map_err(|msg| Error::input(path, msg))?;
    Ok(match direction {
        Direction::Resampling => file_move.inverse(),
        Direction::Modelling => file_move,
    })
}

/// The one linear transform a file holds, as written (no inversion).
pub fn parse(text: &str) -> std::result::Result<RigidMove, String> {
    if !text.trim_start().starts_with("#Insight Transform File") {
        return Err("not an ITK transform file (no '#Insight Transform File' line)".into());
    }
    // Each transform is a `Transform:` line followed by its `Parameters:` and
    // `FixedParameters:` lines; a composite wrapper has none of its own.
    let mut found: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
    for line in text.lines().map(str::trim) {
        let Some((key, value)) = line.split_once(':') else {
            continue;
        };
        let numbers = || -> std::result::Result<Vec<f64>, String> {
            value
                .split_whitespace()
                .map(|w| {
                    w.parse::<f64>()
                        .map_err(|_| format!("{key}: '{w}' is not a number"))
                })
                .collect()
        };
        match key.trim() {
            "Transform" => found.push((value.trim().to_string(), Vec::new(), Vec::new())),
            "Parameters" => match found.last_mut() {
                Some(t) => t.1 = numbers()?,
                None => return Err("Parameters before any Transform line".into()),
            },
            "FixedParameters" => match found.last_mut() {
                Some(t) => t.2 = numbers()?,
                None => return Err("FixedParameters before any Transform line".into()),
            },
            _ => {}
        }
    }
    found.retain(|(kind, ..)| !kind.starts_with("CompositeTransform"));
    let (kind, params, fixed) = match found.as_slice() {
        [one] => one.clone(),
        [] => return Err("no transform in the file".into()),
        more => {
            return Err(format!(
                "{} transforms in one file; facesim takes one rigid transform per osteotomy (harden the transforms in Slicer first)",
                more.len()
            ));
        }
    };
    let class = kind.split('_').next().unwrap_or_default();
    let need = |n: usize| {
        if params.len() == n {
            Ok(())
        } else {
            Err(format!("{kind}: {} parameters, expected {n}", params.len()))
        }
    };
    let centre = match fixed.len() {
        0 => [0.0; 3],
        // Euler3DTransform may add a 4th fixed parameter (its ComputeZYX flag).
        3 | 4 => [fixed[0], fixed[1], fixed[2]],
        n => {
            return Err(format!(
                "{kind}: {n} fixed parameters, expected 3 (the centre)"
            ));
        }
    };
    let (m, t) = match class {
        "AffineTransform" | "MatrixOffsetTransformBase" | "Rigid3DTransform" => {
            need(12)?;
            let m = std::array::from_fn(|i| std::array::from_fn(|j| params[3 * i + j]));
            (m, [params[9], params[10], params[11]])
        }
        "Euler3DTransform" => {
            need(6)?;
            let zyx = fixed.get(3).is_some_and(|f| *f != 0.0);
            (
                euler_itk(params[0], params[1], params[2], zyx),
                [params[3], params[4], params[5]],
            )
        }
        "VersorRigid3DTransform" => {
            need(6)?;
            (
                versor(params[0], params[1], params[2])?,
                [params[3], params[4], params[5]],
            )
        }
        "Similarity3DTransform" => {
            need(7)?;
            if (params[6] - 1.0).abs() > 1e-9 {
                return Err(format!(
                    "{kind} is not rigid: it scales by {} (facesim moves bone rigidly)",
                    params[6]
                ));
            }
            (
                versor(params[0], params[1], params[2])?,
                [params[3], params[4], params[5]],
            )
        }
        "TranslationTransform" => {
            need(3)?;
            (identity(), [params[0], params[1], params[2]])
        }
        _ => {
            return Err(format!(
                "transform type {kind} is not supported (rigid linear transforms only: Affine, Euler3D, VersorRigid3D, Similarity3D with scale 1, Translation)"
            ));
        }
    };
    if m.iter()
        .flatten()
        .chain(&t)
        .chain(&centre)
        .any(|x| !x.is_finite())
    {
        return Err(format!("{kind}: parameters are not finite"));
    }
    check_rigid(&m)
        .map_err(|why| format!("{kind} is not rigid: {why} (facesim moves bone rigidly)"))?;
    Ok(RigidMove {
        rotation: m,
        translation: t,
        centre,
    })
}

fn identity() -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| if i == j { 1.0 } else { 0.0 }))
}

fn mul(p: [[f64; 3]; 3], q: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| p[i][k] * q[k][j]).sum()))
}

/// ITK's Euler3DTransform: R = Rz·Rx·Ry by default ("ZXY"), Rz·Ry·Rx when ComputeZYX is set;
/// angles in radians.
fn euler_itk(ax: f64, ay: f64, az: f64, zyx: bool) -> [[f64; 3]; 3] {
    let (sx, cx) = ax.sin_cos();
    let (sy, cy) = ay.sin_cos();
    let (sz, cz) = az.sin_cos();
    let rx = [[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]];
    let ry = [[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]];
    let rz = [[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]];
    if zyx {
        mul(rz, mul(ry, rx))
    } else {
        mul(rz, mul(rx, ry))
    }
}

/// The rotation of a unit quaternion whose vector part is (x, y, z) (ITK's versor parameters;
/// w = √(1 − |v|²) ≥ 0).
pub(crate) fn versor(x: f64, y: f64, z: f64) -> std::result::Result<[[f64; 3]; 3], String> {
    let n2 = x * x + y * y + z * z;
    if n2 > 1.0 + 1e-9 {
        return Err(format!("versor ({x}, {y}, {z}) has norm > 1"));
    }
    let w = (1.0 - n2).max(0.0).sqrt();
    Ok([
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - z * w),
            2.0 * (x * z + y * w),
        ],
        [
            2.0 * (x * y + z * w),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - x * w),
        ],
        [
            2.0 * (x * z - y * w),
            2.0 * (y * z + x * w),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ])
}

/// Rigid means MᵀM = I and det M = +1 (to 1e-5, what a text file of rounded numbers keeps).
fn check_rigid(m: &[[f64; 3]; 3]) -> std::result::Result<(), String> {
    const TOL: f64 = 1e-5;
    let mtm = mul(transpose(*m), *m);
    let scales: [f64; 3] = std::array::from_fn(|i| mtm[i][i].sqrt());
    let shear = (0..3)
        .flat_map(|i| (0..3).filter(move |j| *j != i).map(move |j| (i, j)))
        .map(|(i, j)| (mtm[i][j] / (scales[i] * scales[j])).abs())
        .fold(0.0, f64::max);
    if scales.iter().any(|s| (s - 1.0).abs() > TOL) {
        return Err(format!(
            "scaling (column lengths {:.6}, {:.6}, {:.6})",
            scales[0], scales[1], scales[2]
        ));
    }
    if shear > TOL {
        return Err(format!("shear (columns at cos {shear:.6} to each other)"));
    }
    if crate::volume::det3(*m) < 0.0 {
        return Err("a reflection (determinant −1)".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::osteotomy::rotation;

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < tol)
    }

    #[test]
    fn euler_angles_round_trip_through_the_plan_rotation() {
        for deg in [
            [10.0, -20.0, 30.0],
            [0.0, 0.0, 0.0],
            [-170.0, 45.0, 100.0],
            [5.0, 89.9, -3.0],
        ] {
            let back = euler_xyz_deg(rotation(deg));
            let (r1, r2) = (rotation(deg), rotation(back));
            for i in 0..3 {
                assert!(close(r1[i], r2[i], 1e-9), "{deg:?} -> {back:?}");
            }
        }
        // Gimbal lock: the rotation is still reproduced.
        let r = rotation([20.0, 90.0, 0.0]);
        let r2 = rotation(euler_xyz_deg(r));
        for i in 0..3 {
            assert!(close(r[i], r2[i], 1e-9));
        }
    }

    #[test]
    fn versor_and_euler_agree_with_axis_rotations() {
        // 90° about z as a versor (sin 45° on z) and as ITK Euler angles: x → y.
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let v = versor(0.0, 0.0, s).unwrap();
        let e = euler_itk(0.0, 0.0, std::f64::consts::FRAC_PI_2, false);
        for m in [v, e] {
            let x = [m[0][0], m[1][0], m[2][0]];
            assert!(close(x, [0.0, 1.0, 0.0], 1e-12), "{m:?}");
        }
        // ZXY differs from ZYX when two angles are non-zero.
        let a = euler_itk(0.3, 0.4, 0.0, false);
        let b = euler_itk(0.3, 0.4, 0.0, true);
        assert!((a[0][1] - b[0][1]).abs() > 1e-3);
    }

    #[test]
    fn non_rigid_matrices_are_named() {
        let text = |p: &str| {
            format!(
                "#Insight Transform File V1.0\nTransform: AffineTransform_double_3_3\nParameters: {p} 0 0 0\nFixedParameters: 0 0 0\n"
            )
        };
        let e = parse(&text("1.1 0 0 0 1 0 0 0 1")).unwrap_err();
        assert!(e.contains("scaling"), "{e}");
        let e = parse(&text("1 0.2 0 0 1 0 0 0 1")).unwrap_err();
        assert!(e.contains("scaling") || e.contains("shear"), "{e}");
        let c = 0.2f64.cos();
        let s = 0.2f64.sin();
        // Unit columns that are not orthogonal: shear without scaling.
        let e = parse(&text(&format!("1 {s} 0 0 {c} 0 0 0 1"))).unwrap_err();
        assert!(e.contains("shear"), "{e}");
        let e = parse(&text("-1 0 0 0 1 0 0 0 1")).unwrap_err();
        assert!(e.contains("reflection"), "{e}");
        let e = parse(
            "#Insight Transform File V1.0\nTransform: BSplineTransform_double_3_3\nParameters: 1\n",
        )
        .unwrap_err();
        assert!(e.contains("not supported"), "{e}");
    }

    #[test]
    fn inverse_undoes_the_move() {
        let m = RigidMove {
            rotation: rotation([10.0, 20.0, -5.0]),
            translation: [1.0, -2.0, 3.0],
            centre: [4.0, 5.0, -6.0],
        };
        let p = [7.0, -8.0, 9.0];
        assert!(close(m.inverse().apply(m.apply(p)), p, 1e-12));
        let (t, deg, pivot) = m.plan_form();
        let r = rotation(deg);
        let d = [0, 1, 2].map(|a| p[a] - pivot[a]);
        let q = [0, 1, 2].map(|i| (0..3).map(|k| r[i][k] * d[k]).sum::<f64>() + pivot[i] + t[i]);
        assert!(close(q, m.apply(p), 1e-9));
    }
}

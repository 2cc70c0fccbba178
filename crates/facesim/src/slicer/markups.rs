//! A cutting plane from a 3D Slicer markups file (`.mrk.json` holding a `Plane` markup;
//! docs/guide/slicer.md "Cutting planes").
//!
//! A `pointNormal` plane is its one control point and the z axis of `baseToNode` (the plane's
//! normal; `objectToBase`, when present, rotates it further); a `threePoints` plane is its three
//! control points, normal (p1 − p0) × (p2 − p0). Coordinates are in the file's
//! `coordinateSystem` (LPS unless it says RAS, then x and y are negated).

use crate::error::{Error, Result};
use serde_json::Value;
use std::path::Path;

/// A plane (LPS mm): the point and the unit normal; its half-space is the side the normal
/// points to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub point: [f64; 3],
    pub normal: [f64; 3],
}

pub(crate) fn read_plane(path: &Path) -> Result<Plane> {
    let bytes = std::fs::read(path).map_err(|e| Error::input(path, e))?;
    let v: Value =
        serde_json::from_slice(&bytes).map_err(|e| Error::input(path, format!("not JSON: {e}")))?;
    parse_plane(&v).map_err(|msg| Error::input(path, msg))
}

fn vec3(v: &Value, what: &str) -> std::result::Result<[f64; 3], String> {
    let a = v
        .as_array()
        .filter(|a| a.len() == 3)
        .ok_or_else(|| format!("{what} is not 3 numbers"))?;
    let mut out = [0.0; 3];
    for (o, x) in out.iter_mut().zip(a) {
        *o = x
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{what} is not 3 finite numbers"))?;
    }
    Ok(out)
}

/// A row-major 4×4 matrix's upper-left 3×3.
fn mat3(v: &Value, what: &str) -> std::result::Result<[[f64; 3]; 3], String> {
    let a = v
        .as_array()
        .filter(|a| a.len() == 16)
        .ok_or_else(|| format!("{what} is not 16 numbers"))?;
    let n: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
    if n.len() != 16 || n.iter().any(|x| !x.is_finite()) {
        return Err(format!("{what} is not 16 finite numbers"));
    }
    Ok(std::array::from_fn(|i| {
        std::array::from_fn(|j| n[4 * i + j])
    }))
}

pub(crate) fn parse_plane(v: &Value) -> std::result::Result<Plane, String> {
    let markups = v
        .get("markups")
        .and_then(Value::as_array)
        .ok_or("no 'markups' list (not a Slicer markups file)")?;
    let planes: Vec<&Value> = markups
        .iter()
        .filter(|m| m.get("type").and_then(Value::as_str) == Some("Plane"))
        .collect();
    let m = match planes.as_slice() {
        [one] => *one,
        [] => return Err("no Plane markup in the file".into()),
        more => return Err(format!("{} Plane markups; give one per file", more.len())),
    };
    let ras = match m.get("coordinateSystem").and_then(Value::as_str) {
        None | Some("LPS") => false,
        Some("RAS") => true,
        Some(other) => return Err(format!("coordinateSystem '{other}' (expected LPS or RAS)")),
    };
    let points: Vec<[f64; 3]> = m
        .get("controlPoints")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .map(|p| vec3(p.get("position").unwrap_or(&Value::Null), "a control point"))
                .collect::<std::result::Result<_, _>>()
        })
        .transpose()?
        .unwrap_or_default();
    let plane_type = m
        .get("planeType")
        .and_then(Value::as_str)
        .unwrap_or("pointNormal")
        .to_ascii_lowercase();
    let (point, normal) = match plane_type.as_str() {
        "pointnormal" => {
            let p = *points.first().ok_or("the plane has no control point")?;
            let base = mat3(
                m.get("baseToNode")
                    .ok_or("the plane has no baseToNode (its normal)")?,
                "baseToNode",
            )?;
            let rot = match m.get("objectToBase") {
                Some(o) => {
                    let ob = mat3(o, "objectToBase")?;
                    std::array::from_fn(|i| {
                        std::array::from_fn(|j| (0..3).map(|k| base[i][k] * ob[k][j]).sum())
                    })
                }
                None => base,
            };
            (p, [rot[0][2], rot[1][2], rot[2][2]])
        }
        "threepoints" => {
            let [p0, p1, p2] = points
                .get(..3)
                .and_then(|s| <[[f64; 3]; 3]>::try_from(s).ok())
                .ok_or("a threePoints plane needs 3 control points")?;
            let (a, b) = (crate::vec3::sub(p1, p0), crate::vec3::sub(p2, p0));
            (p0, crate::vec3::cross(a, b))
        }
        other => return Err(format!("planeType '{other}' is not supported")),
    };
    let n = crate::vec3::norm(normal);
    if !(n > 1e-12) {
        return Err("the plane's normal is zero".into());
    }
    let flip = |p: [f64; 3]| if ras { [-p[0], -p[1], p[2]] } else { p };
    Ok(Plane {
        point: flip(point),
        normal: flip(normal.map(|c| c / n)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_normal_plane_in_lps_and_ras() {
        // baseToNode z column = (0, 0.6, 0.8).
        let text = |cs: &str| {
            format!(
                r#"{{"markups": [{{"type": "Plane", "coordinateSystem": "{cs}", "planeType": "pointNormal",
                "baseToNode": [1,0,0,0, 0,0.8,0.6,0, 0,-0.6,0.8,0, 0,0,0,1],
                "controlPoints": [{{"position": [1.0, 2.0, 3.0]}}]}}]}}"#
            )
        };
        let p = parse_plane(&serde_json::from_str(&text("LPS")).unwrap()).unwrap();
        assert_eq!(p.point, [1.0, 2.0, 3.0]);
        assert!((p.normal[1] - 0.6).abs() < 1e-12 && (p.normal[2] - 0.8).abs() < 1e-12);
        let p = parse_plane(&serde_json::from_str(&text("RAS")).unwrap()).unwrap();
        assert_eq!(p.point, [-1.0, -2.0, 3.0]);
        assert!((p.normal[1] + 0.6).abs() < 1e-12);
    }

    #[test]
    fn three_point_plane_and_refusals() {
        let v: Value = serde_json::from_str(
            r#"{"markups": [{"type": "Plane", "planeType": "threePoints", "controlPoints": [
            {"position": [0,0,5]}, {"position": [1,0,5]}, {"position": [0,1,5]}]}]}"#,
        )
        .unwrap();
        let p = parse_plane(&v).unwrap();
        assert_eq!(p.normal, [0.0, 0.0, 1.0]);
        let v: Value = serde_json::from_str(r#"{"markups": [{"type": "Fiducial"}]}"#).unwrap();
        assert!(parse_plane(&v).unwrap_err().contains("no Plane"));
    }
}

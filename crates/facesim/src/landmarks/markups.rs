//! 3D Slicer markups files (.mrk.json, Slicer's markups schema v1.0.3): one `Fiducial` markup
//! in LPS mm, one control point per landmark (docs/guide/landmarks.md "Files").

use super::landmark::Carried;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use serde_json::{Value, json};
use std::path::Path;

pub(crate) const SCHEMA: &str = "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#";

/// The markups document of labelled points (LPS mm).
pub fn document(name: &str, points: &[(String, [f64; 3])]) -> Value {
    let cps: Vec<Value> = points
        .iter()
        .enumerate()
        .map(|(i, (label, p))| {
            json!({
                "id": (i + 1).to_string(),
                "label": label,
                "description": "",
                "associatedNodeID": "",
                "position": p,
                "orientation": [-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0],
                "selected": true,
                "locked": true,
                "visibility": true,
                "positionStatus": "defined"
            })
        })
        .collect();
    json!({
        "@schema": SCHEMA,
        "markups": [{
            "type": "Fiducial",
            "name": name,
            "coordinateSystem": "LPS",
            "coordinateUnits": "mm",
            "locked": true,
            "fixedNumberOfControlPoints": false,
            "labelFormat": "%N-%d",
            "lastUsedControlPointNumber": points.len(),
            "controlPoints": cps
        }]
    })
}

/// Write `landmarks_pre.mrk.json` and `landmarks_post.mrk.json` into `dir`: the landmarks the
/// scan contains (missing ones are left out; report.json says why).
pub fn write_pre_post(dir: &Path, carried: &[Carried]) -> Result<()> {
    for (file, name, post) in [
        ("landmarks_pre.mrk.json", "landmarks_pre", false),
        ("landmarks_post.mrk.json", "landmarks_post", true),
    ] {
        let pts: Vec<(String, [f64; 3])> = carried
            .iter()
            .filter_map(|c| {
                let p = if post { c.post } else { c.pre };
                p.map(|p| (c.label.clone(), p))
            })
            .collect();
        let text = serde_json::to_string_pretty(&document(name, &pts))
            .map_err(|e| Error::output(dir.join(file), e))?;
        write_bytes_atomic(&dir.join(file), |w| w.write_all(text.as_bytes()))?;
    }
    Ok(())
}

/// The labelled points of a markups file (every markup's defined control points), in LPS mm
/// (RAS files converted: x and y negated). Errors name the file.
pub fn read(path: &Path) -> Result<Vec<(String, [f64; 3])>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::input(path, e))?;
    parse(&text).map_err(|msg| Error::input(path, msg))
}

/// [`read`] on text; the error is the problem without the file name.
pub fn parse(text: &str) -> std::result::Result<Vec<(String, [f64; 3])>, String> {
    let v: Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    let markups = v
        .get("markups")
        .and_then(Value::as_array)
        .ok_or("no `markups` array (not a Slicer markups file)")?;
    let mut out = Vec::new();
    for m in markups {
        let ras = match m.get("coordinateSystem").and_then(Value::as_str) {
            None | Some("LPS") => false,
            Some("RAS") => true,
            Some(other) => return Err(format!("coordinateSystem \"{other}\" is not LPS or RAS")),
        };
        let Some(cps) = m.get("controlPoints").and_then(Value::as_array) else {
            continue;
        };
        for (i, cp) in cps.iter().enumerate() {
            let status = cp.get("positionStatus").and_then(Value::as_str);
            if matches!(status, Some("undefined") | Some("missing")) {
                continue;
            }
            let label = cp
                .get("label")
                .and_then(Value::as_str)
                .filter(|s| !s.is_empty())
                .ok_or(format!("control point {} has no label", i + 1))?;
            let pos: Vec<f64> = cp
                .get("position")
                .and_then(Value::as_array)
                .map(|a| a.iter().filter_map(Value::as_f64).collect())
                .unwrap_or_default();
            if pos.len() != 3 || pos.iter().any(|x| !x.is_finite()) {
                return Err(format!(
                    "control point '{label}' has no position of 3 finite numbers"
                ));
            }
            let s = if ras { -1.0 } else { 1.0 };
            out.push((label.to_string(), [s * pos[0], s * pos[1], pos[2]]));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_points_read_back_and_ras_is_converted() {
        let pts = vec![("Prn".to_string(), [1.5, -90.0, 12.0])];
        let text = document("x", &pts).to_string();
        assert_eq!(parse(&text).unwrap(), pts);
        let ras = text.replace("\"LPS\"", "\"RAS\"");
        assert_eq!(parse(&ras).unwrap()[0].1, [-1.5, 90.0, 12.0]);
        assert!(parse("{}").is_err());
    }
}

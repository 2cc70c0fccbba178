//! 3D Slicer's files in a plan (docs/guide/slicer.md): osteotomy moves as ITK transform files,
//! cutting planes from markups, and the substitution that turns both into the plan's own keys
//! when case.toml (or a replan PLAN.toml) is read.
//!
//! `transform = "maxilla.tfm"` in an `[[osteotomy]]` becomes that entry's `translate`,
//! `rotate_deg` and `pivot`; `region = { plane = "cut.mrk.json" }` becomes
//! `region = { half_space = { point, normal } }`. Doing it on the TOML table keeps the plan's
//! types (and the plan basis, replan and report.html that use them) as they were; report.json's
//! `parameters` show the move as numbers.

pub(crate) mod itk_transform;
pub mod markups;

use crate::error::{Error, Result};
use std::path::Path;

/// Replace every osteotomy's `transform` (with optional `transform_direction`) and every
/// `plane` region (osteotomies and `[surface] movable`) in `table` by the plan's keys, reading
/// the named files relative to `dir`. `file` (case.toml) is named in errors about keys.
pub(crate) fn resolve_plan_files(table: &mut toml::Table, dir: &Path, file: &Path) -> Result<()> {
    if let Some(toml::Value::Table(surface)) = table.get_mut("surface")
        && let Some(region) = surface.get_mut("movable")
    {
        resolve_plane(region, dir, file, "[surface] movable")?;
    }
    let Some(toml::Value::Array(osteotomies)) = table.get_mut("osteotomy") else {
        return Ok(());
    };
    for (i, o) in osteotomies.iter_mut().enumerate() {
        let toml::Value::Table(o) = o else { continue };
        let name = o
            .get("name")
            .and_then(|n| n.as_str())
            .map_or_else(|| format!("#{}", i + 1), |n| format!("'{n}'"));
        if let Some(region) = o.get_mut("region") {
            resolve_plane(region, dir, file, &format!("osteotomy {name}"))?;
        }
        let direction = match o.remove("transform_direction") {
            None => itk_transform::Direction::Resampling,
            Some(v) => v
                .as_str()
                .and_then(itk_transform::Direction::parse)
                .ok_or_else(|| {
                    Error::input(
                        file,
                        format!(
                            "osteotomy {name}: transform_direction must be \"resampling\" (as Slicer saves) or \"modelling\""
                        ),
                    )
                })?,
        };
        let Some(t) = o.remove("transform") else {
            continue;
        };
        let Some(rel) = t.as_str() else {
            return Err(Error::input(
                file,
                format!("osteotomy {name}: transform must be a file name"),
            ));
        };
        if let Some(k) = ["translate", "rotate_deg", "pivot"]
            .iter()
            .find(|k| o.contains_key(**k))
        {
            return Err(Error::input(
                file,
                format!("osteotomy {name}: give either transform or {k}, not both"),
            ));
        }
        let path = dir.join(rel);
        if !path.is_file() {
            return Err(Error::input(&path, "transform file not found"));
        }
        let (translate, rotate_deg, pivot) = itk_transform::read(&path, direction)?.plan_form();
        let arr =
            |v: [f64; 3]| toml::Value::Array(v.iter().map(|x| toml::Value::Float(*x)).collect());
        o.insert("translate".into(), arr(translate));
        o.insert("rotate_deg".into(), arr(rotate_deg));
        o.insert("pivot".into(), arr(pivot));
    }
    Ok(())
}

/// `{ plane = "file.mrk.json" }` → `{ half_space = { point, normal } }`.
fn resolve_plane(region: &mut toml::Value, dir: &Path, file: &Path, what: &str) -> Result<()> {
    let toml::Value::Table(r) = region else {
        return Ok(());
    };
    let Some(p) = r.get("plane") else {
        return Ok(());
    };
    let Some(rel) = p.as_str() else {
        return Err(Error::input(
            file,
            format!("{what}: region plane must be a markups file name (.mrk.json)"),
        ));
    };
    let path = dir.join(rel);
    if !path.is_file() {
        return Err(Error::input(&path, "markups plane file not found"));
    }
    let plane = markups::read_plane(&path)?;
    let arr = |v: [f64; 3]| toml::Value::Array(v.iter().map(|x| toml::Value::Float(*x)).collect());
    let mut hs = toml::Table::new();
    hs.insert("point".into(), arr(plane.point));
    hs.insert("normal".into(), arr(plane.normal));
    r.remove("plane");
    r.insert("half_space".into(), toml::Value::Table(hs));
    Ok(())
}

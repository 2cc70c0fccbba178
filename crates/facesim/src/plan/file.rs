//! `plan_basis.bin` (docs/design/plan-basis.md "File format"), little-endian:
//!
//! ```text
//! magic        8 bytes  "FSPLANB\0"
//! format       u32      FORMAT_VERSION
//! version len  u32, then the facesim version (UTF-8) that wrote it
//! header len   u32, then a JSON header (UTF-8): model, exact, warnings, vertices, triangles,
//!              columns_per_segment, offset, run_plan_error_mm, segments [{name, region, pivot}],
//!              run_plan (the case's [[osteotomy]] list)
//! zero padding to a multiple of 8 bytes
//! face_pre     vertices × 3 f64 (LPS mm)
//! triangles    triangles × 3 u32, zero padding to a multiple of 8 bytes
//! offset       vertices × 3 f64, when the header says `offset: true`
//! columns      per segment, per k = 0..12: vertices × 3 f64 (mm per unit entry of M)
//! ```
//!
//! Reading checks the magic, the format version, the facesim version and every size; any
//! mismatch is one line naming the file.

use super::basis::{COLUMNS, PlanBasis, SegmentBasis};
use crate::case::{Osteotomy, Region};
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use crate::stored;
use serde::{Deserialize, Serialize};
use std::path::Path;

pub(crate) const MAGIC: &[u8; 8] = b"FSPLANB\0";
pub(crate) const FORMAT_VERSION: u32 = 1;
/// The file's name in a run's output directory.
pub const FILE_NAME: &str = "plan_basis.bin";

#[derive(Serialize, Deserialize)]
struct Header {
    model: String,
    exact: bool,
    warnings: Vec<String>,
    vertices: usize,
    triangles: usize,
    columns_per_segment: usize,
    offset: bool,
    run_plan_error_mm: f64,
    segments: Vec<SegmentHeader>,
    run_plan: Vec<Osteotomy>,
}

#[derive(Serialize, Deserialize)]
struct SegmentHeader {
    name: String,
    region: Region,
    pivot: [f64; 3],
}

/// Write `basis` to `path` (temporary name, then renamed).
pub fn write(path: &Path, basis: &PlanBasis) -> Result<()> {
    let header = Header {
        model: basis.model.clone(),
        exact: basis.exact,
        warnings: basis.warnings.clone(),
        vertices: basis.face_pre.len(),
        triangles: basis.triangles.len(),
        columns_per_segment: COLUMNS,
        offset: basis.offset.is_some(),
        run_plan_error_mm: basis.run_plan_error_mm,
        segments: basis
            .segments
            .iter()
            .map(|s| SegmentHeader {
                name: s.name.clone(),
                region: s.region.clone(),
                pivot: s.pivot,
            })
            .collect(),
        run_plan: basis.run_plan.clone(),
    };
    let n = basis.face_pre.len();
    if basis
        .segments
        .iter()
        .any(|s| s.columns.len() != COLUMNS || s.columns.iter().any(|c| c.len() != n))
        || basis.offset.as_ref().is_some_and(|o| o.len() != n)
    {
        return Err(Error::output(
            path,
            "the plan basis's columns do not match its face",
        ));
    }
    let json = serde_json::to_vec(&header).map_err(|e| Error::output(path, e))?;
    write_bytes_atomic(path, |w| {
        w.write_all(&stored::head(
            MAGIC,
            FORMAT_VERSION,
            &basis.facesim_version,
            &json,
        ))?;
        let f64s = |w: &mut dyn std::io::Write, v: &[[f64; 3]]| -> std::io::Result<()> {
            w.write_all(&stored::point_bytes(v))
        };
        f64s(w, &basis.face_pre)?;
        let mut tri = Vec::with_capacity(12 * basis.triangles.len());
        for i in basis.triangles.iter().flatten() {
            tri.extend_from_slice(&i.to_le_bytes());
        }
        tri.resize(tri.len() + stored::pad8(tri.len()), 0);
        w.write_all(&tri)?;
        if let Some(o) = &basis.offset {
            f64s(w, o)?;
        }
        for s in &basis.segments {
            for c in &s.columns {
                f64s(w, c)?;
            }
        }
        Ok(())
    })
}

/// Read a basis written by this facesim version.
pub fn read(path: &Path) -> Result<PlanBasis> {
    let bytes = stored::read_bytes(
        path,
        "no plan basis here (a run of this facesim version writes plan_basis.bin with its outputs)",
    )?;
    let (mut r, version, header) =
        stored::Reader::open(path, "plan basis", &bytes, MAGIC, FORMAT_VERSION)?;
    let header: Header = serde_json::from_slice(header)
        .map_err(|e| Error::input(path, format!("plan basis header: {e}")))?;
    if header.columns_per_segment != COLUMNS {
        return Err(Error::input(
            path,
            format!(
                "plan basis has {} columns per segment, not {COLUMNS}",
                header.columns_per_segment
            ),
        ));
    }
    let n = header.vertices;
    let face_pre = r.points(n, "face_pre")?;
    let tb = r.take(
        header
            .triangles
            .checked_mul(12)
            .ok_or_else(|| Error::input(path, "plan basis: too many triangles"))?,
        "the triangles",
    )?;
    let idx =
        |i: usize| u32::from_le_bytes([tb[4 * i], tb[4 * i + 1], tb[4 * i + 2], tb[4 * i + 3]]);
    let triangles: Vec<[u32; 3]> = (0..header.triangles)
        .map(|t| [idx(3 * t), idx(3 * t + 1), idx(3 * t + 2)])
        .collect();
    if triangles.iter().flatten().any(|v| *v as usize >= n) {
        return Err(Error::input(
            path,
            "plan basis: a triangle names a missing vertex",
        ));
    }
    r.take(stored::pad8(tb.len()), "the padding")?;
    let offset = if header.offset {
        Some(r.points(n, "the offset")?)
    } else {
        None
    };
    let mut segments = Vec::with_capacity(header.segments.len());
    for s in header.segments {
        let columns = (0..COLUMNS)
            .map(|k| r.points(n, &format!("segment '{}' column {k}", s.name)))
            .collect::<Result<Vec<_>>>()?;
        segments.push(SegmentBasis {
            name: s.name,
            region: s.region,
            pivot: s.pivot,
            columns,
        });
    }
    r.finish("the last column")?;
    if face_pre
        .iter()
        .chain(segments.iter().flat_map(|s| s.columns.iter().flatten()))
        .flatten()
        .any(|v| !v.is_finite())
    {
        return Err(Error::input(
            path,
            "plan basis: non-finite values (corrupt)",
        ));
    }
    Ok(PlanBasis {
        model: header.model,
        exact: header.exact,
        warnings: header.warnings,
        segments,
        face_pre,
        triangles,
        run_plan: header.run_plan,
        offset,
        facesim_version: version,
        run_plan_error_mm: header.run_plan_error_mm,
    })
}

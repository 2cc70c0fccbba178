//! InVesalius projects (.inv3): a gzipped tar holding `main.plist` (shape, spacing, dtype) and
//! the raw voxel matrix (C order, shape [slices, rows, columns], native little-endian).
//!
//! Frame: an .inv3 project stores no patient position or orientation. InVesalius keeps axial
//! slices in VTK's bottom-up row order, so the row index grows *anteriorly*; the slice index
//! grows superiorly and the column index to the patient's left. facesim therefore maps voxel
//! (i, j, k) to LPS (i·sx, (ny−1−j)·sy, k·sz). This is checked on the real sample: the CT
//! head-rest arc (behind the head) lies at small row indices, the face at large ones.

use super::grid::Volume;
use crate::error::{Error, Result};
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

pub fn read(path: &Path) -> Result<Volume> {
    let files = read_members(path)?;
    let main = files
        .get("main.plist")
        .ok_or_else(|| Error::input(path, "no main.plist in the project"))?;
    let MainPlist {
        dtype,
        fname,
        shape,
        spacing,
    } = read_main_plist(path, main)?;
    let (dtype, fname) = (dtype.as_str(), fname.as_str());
    if shape.len() != 3 || spacing.len() != 3 {
        return Err(Error::input(
            path,
            "main.plist needs a 3-element matrix shape and spacing",
        ));
    }
    let dims = [shape[2], shape[1], shape[0]];
    let spacing = [spacing[0], spacing[1], spacing[2]];
    let origin = [0.0, (dims[1].saturating_sub(1)) as f64 * spacing[1], 0.0];
    let direction = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
    Volume::check_geometry(path, dims, spacing, origin, direction)?;
    let raw = files.get(fname).ok_or_else(|| {
        Error::input(
            path,
            format!("matrix file {fname} missing from the project"),
        )
    })?;
    let n = dims[0] * dims[1] * dims[2];
    let (kind, width) = match dtype {
        "int16" => ('i', 2),
        "uint16" => ('u', 2),
        "int32" => ('i', 4),
        "float32" => ('f', 4),
        "int8" => ('i', 1),
        "uint8" => ('u', 1),
        other => {
            return Err(Error::input(
                path,
                format!("unsupported matrix dtype {other}"),
            ));
        }
    };
    if raw.len() != n * width {
        return Err(Error::input(
            path,
            format!(
                "matrix {fname} has {} bytes, shape {shape:?} of {dtype} needs {}",
                raw.len(),
                n * width
            ),
        ));
    }
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data: super::samples::decode_samples(raw, kind, width, false),
    })
}

/// The project's members by file name, InVesalius' derived surfaces and masks left out.
fn read_members(path: &Path) -> Result<HashMap<String, Vec<u8>>> {
    let file = std::fs::File::open(path).map_err(|e| Error::input(path, e))?;
    let mut archive =
        tar::Archive::new(flate2::read::GzDecoder::new(std::io::BufReader::new(file)));
    let mut files: HashMap<String, Vec<u8>> = HashMap::new();
    let entries = archive
        .entries()
        .map_err(|e| Error::input(path, format!("not a gzipped tar InVesalius project ({e})")))?;
    for entry in entries {
        let mut entry =
            entry.map_err(|e| Error::input(path, format!("corrupt project archive ({e})")))?;
        let name = entry
            .path()
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().to_string()))
            .unwrap_or_default();
        // Surfaces and masks are InVesalius' own derived data; only the plist and matrix matter.
        if name.ends_with(".vtp") || name.starts_with("mask_") || name.is_empty() {
            continue;
        }
        let size = entry.size();
        if size > (super::grid::MAX_VOXELS as u64) * 8 {
            return Err(Error::input(
                path,
                format!("member {name} is {size} bytes: too large"),
            ));
        }
        // The size is the archive's claim: read at most that much, without reserving it first
        // (a corrupt header must not make us allocate gigabytes).
        let mut buf = Vec::new();
        (&mut entry)
            .take(size)
            .read_to_end(&mut buf)
            .map_err(|e| Error::input(path, format!("corrupt project archive at {name} ({e})")))?;
        files.insert(name, buf);
    }
    Ok(files)
}

/// What main.plist says about the voxel matrix (shape and spacing unchecked).
struct MainPlist {
    dtype: String,
    fname: String,
    shape: Vec<usize>,
    spacing: Vec<f64>,
}

fn read_main_plist(path: &Path, main: &[u8]) -> Result<MainPlist> {
    let plist: plist::Value = plist::from_bytes(main)
        .map_err(|e| Error::input(path, format!("unreadable main.plist ({e})")))?;
    let dict = plist
        .as_dictionary()
        .ok_or_else(|| Error::input(path, "main.plist is not a dictionary"))?;
    let matrix = dict
        .get("matrix")
        .and_then(|m| m.as_dictionary())
        .ok_or_else(|| Error::input(path, "main.plist has no matrix entry"))?;
    let dtype = matrix
        .get("dtype")
        .and_then(|v| v.as_string())
        .unwrap_or("int16");
    let fname = matrix
        .get("filename")
        .and_then(|v| v.as_string())
        .unwrap_or("matrix.dat");
    let shape: Vec<usize> = matrix
        .get("shape")
        .and_then(|v| v.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|x| x.as_signed_integer())
                .map(|x| x.max(0) as usize)
                .collect()
        })
        .unwrap_or_default();
    let spacing: Vec<f64> = dict
        .get("spacing")
        .and_then(|v| v.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|x| x.as_real().or(x.as_signed_integer().map(|i| i as f64)))
                .collect()
        })
        .unwrap_or_default();
    Ok(MainPlist {
        dtype: dtype.to_string(),
        fname: fname.to_string(),
        shape,
        spacing,
    })
}

//! vtk.js dataset folders (`NAME.vti/` holding `index.json` and `data/<id>.gz`), the format
//! vtk.js's `HttpDataSetReader` reads and its examples ship (VTK's `headsq` among them,
//! data-samples/real-mandible): `index.json` is the vtkImageData header (`extent`, `spacing`,
//! `origin`, `direction`, the point-data arrays), each array's values are a separate file
//! `<basepath>/<id>` (gzipped as `<id>.gz`), raw little-endian.
//!
//! Frame: vtk.js's `direction` holds the index axes' world directions (i first, as
//! vtkImageData's `indexToWorld` columns); world = origin + direction · (spacing ∘ index), the
//! index counted from extent 0 (so a non-zero extent start shifts the first voxel). VTK's world
//! has no patient meaning: facesim takes it as LPS mm, and a case whose data lie otherwise says
//! so with `[ct] axes` (docs/reference/case.md; the headsq case does). Values are taken as they are (no
//! rescale is stored): `[ct] intercept` turns stored numbers into HU.

use super::grid::Volume;
use crate::error::{Error, Result};
use serde::Deserialize;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Is `path` a vtk.js dataset folder (a directory with an `index.json`)?
pub(crate) fn is_dataset(path: &Path) -> bool {
    path.is_dir() && path.join("index.json").is_file()
}

#[derive(Deserialize)]
struct Header {
    #[serde(rename = "vtkClass")]
    vtk_class: Option<String>,
    extent: Vec<i64>,
    spacing: Option<Vec<f64>>,
    origin: Option<Vec<f64>>,
    direction: Option<Vec<f64>>,
    #[serde(rename = "pointData")]
    point_data: Option<Attributes>,
}

#[derive(Deserialize)]
struct Attributes {
    #[serde(default)]
    arrays: Vec<ArrayEntry>,
}

#[derive(Deserialize)]
struct ArrayEntry {
    data: ArrayData,
}

#[derive(Deserialize)]
struct ArrayData {
    name: Option<String>,
    #[serde(rename = "numberOfComponents", default = "one")]
    components: usize,
    #[serde(rename = "dataType")]
    data_type: String,
    size: Option<usize>,
    #[serde(rename = "ref")]
    reference: Option<Reference>,
}

fn one() -> usize {
    1
}

#[derive(Deserialize)]
struct Reference {
    registration: Option<String>,
    encode: Option<String>,
    basepath: Option<String>,
    id: String,
}

/// Read a vtk.js dataset folder (`dir` itself, or its `index.json`): the scalars (the array
/// registered with `setScalars`, else the only one) as a volume.
pub fn read(path: &Path) -> Result<Volume> {
    let dir = if path.is_dir() {
        path.to_path_buf()
    } else {
        path.parent().map(Path::to_path_buf).unwrap_or_default()
    };
    let index = dir.join("index.json");
    let text = std::fs::read_to_string(&index).map_err(|e| Error::input(&index, e))?;
    let h: Header = serde_json::from_str(&text)
        .map_err(|e| Error::input(&index, format!("not a vtk.js dataset header ({e})")))?;
    let bad = |m: String| Error::input(&index, m);
    if let Some(c) = &h.vtk_class
        && c != "vtkImageData"
    {
        return Err(bad(format!(
            "vtkClass is {c}: only vtkImageData (a voxel volume) is a CT"
        )));
    }
    let dims = extent_dims(&h.extent).ok_or_else(|| {
        bad(format!(
            "extent {:?} must be 6 integers [i0, i1, j0, j1, k0, k1] with i0 <= i1, ...",
            h.extent
        ))
    })?;
    let triple = |v: &Option<Vec<f64>>, what: &str, default: [f64; 3]| match v {
        None => Ok(default),
        Some(v) => <[f64; 3]>::try_from(v.as_slice())
            .map_err(|_| bad(format!("{what} must have 3 numbers, has {}", v.len()))),
    };
    let spacing = triple(&h.spacing, "spacing", [1.0; 3])?;
    let origin0 = triple(&h.origin, "origin", [0.0; 3])?;
    let direction = match &h.direction {
        None => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        Some(d) if d.len() == 9 => [[d[0], d[1], d[2]], [d[3], d[4], d[5]], [d[6], d[7], d[8]]],
        Some(d) => {
            return Err(bad(format!(
                "direction must have 9 numbers, has {}",
                d.len()
            )));
        }
    };
    // The first voxel is at index (i0, j0, k0).
    let mut origin = origin0;
    for (a, dir_a) in direction.iter().enumerate() {
        for (r, o) in origin.iter_mut().enumerate() {
            *o += dir_a[r] * spacing[a] * h.extent[2 * a] as f64;
        }
    }
    Volume::check_geometry(&index, dims, spacing, origin, direction)?;
    let arrays = h.point_data.map(|p| p.arrays).unwrap_or_default();
    let array = &arrays
        .iter()
        .find(|a| {
            a.data
                .reference
                .as_ref()
                .and_then(|r| r.registration.as_deref())
                == Some("setScalars")
        })
        .or(if arrays.len() == 1 {
            arrays.first()
        } else {
            None
        })
        .ok_or_else(|| {
            bad(format!(
                "no scalar point-data array (registration \"setScalars\") among {}",
                arrays.len()
            ))
        })?
        .data;
    if array.components != 1 {
        return Err(bad(format!(
            "array {} has {} components per voxel: a CT has 1",
            array.name.as_deref().unwrap_or("?"),
            array.components
        )));
    }
    let n = dims[0] * dims[1] * dims[2];
    if let Some(size) = array.size
        && size != n
    {
        return Err(bad(format!(
            "array holds {size} values, extent {:?} needs {n}",
            h.extent
        )));
    }
    let (kind, width) = match array.data_type.as_str() {
        "Int8Array" => ('i', 1),
        "Uint8Array" => ('u', 1),
        "Int16Array" => ('i', 2),
        "Uint16Array" => ('u', 2),
        "Int32Array" => ('i', 4),
        "Uint32Array" => ('u', 4),
        "Float32Array" => ('f', 4),
        "Float64Array" => ('f', 8),
        other => return Err(bad(format!("unsupported dataType {other}"))),
    };
    let reference = array.reference.as_ref().ok_or_else(|| {
        bad("the scalar array has no ref (inline values are not supported)".into())
    })?;
    if let Some(e) = &reference.encode
        && e != "LittleEndian"
    {
        return Err(bad(format!("encode {e}: only LittleEndian is supported")));
    }
    if reference.id.is_empty() || reference.id.contains(['/', '\\']) || reference.id == ".." {
        return Err(bad(format!("bad array id {:?}", reference.id)));
    }
    let base = dir.join(reference.basepath.as_deref().unwrap_or("data"));
    let raw = read_values(&base, &reference.id, n * width)?;
    if raw.1.len() != n * width {
        return Err(Error::input(
            &raw.0,
            format!(
                "{} bytes, {n} values of {} need {}",
                raw.1.len(),
                array.data_type,
                n * width
            ),
        ));
    }
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data: super::samples::decode_samples(&raw.1, kind, width, false),
    })
}

/// Voxel counts from a VTK extent [i0, i1, j0, j1, k0, k1].
fn extent_dims(e: &[i64]) -> Option<[usize; 3]> {
    if e.len() != 6 {
        return None;
    }
    let mut d = [0usize; 3];
    for a in 0..3 {
        let n = e[2 * a + 1].checked_sub(e[2 * a])?.checked_add(1)?;
        d[a] = usize::try_from(n).ok().filter(|&n| n > 0)?;
    }
    Some(d)
}

/// The bytes of array `id` under `base`: `<id>.gz` gunzipped, else `<id>` raw; reads at most
/// one byte more than `want` (a corrupt file must not make us allocate gigabytes).
fn read_values(base: &Path, id: &str, want: usize) -> Result<(PathBuf, Vec<u8>)> {
    let gz = base.join(format!("{id}.gz"));
    let plain = base.join(id);
    let mut buf = Vec::new();
    if gz.is_file() {
        let f = std::fs::File::open(&gz).map_err(|e| Error::input(&gz, e))?;
        flate2::read::GzDecoder::new(std::io::BufReader::new(f))
            .take(want as u64 + 1)
            .read_to_end(&mut buf)
            .map_err(|e| Error::input(&gz, format!("corrupt gzip ({e})")))?;
        Ok((gz, buf))
    } else if plain.is_file() {
        let f = std::fs::File::open(&plain).map_err(|e| Error::input(&plain, e))?;
        f.take(want as u64 + 1)
            .read_to_end(&mut buf)
            .map_err(|e| Error::input(&plain, e))?;
        Ok((plain, buf))
    } else {
        Err(Error::input(
            &gz,
            "the voxel values named by index.json are missing (neither <id>.gz nor <id>)",
        ))
    }
}

/// Write a vtk.js dataset folder (int16 scalars, gzipped): the unit tests' fixtures.
#[cfg(test)]
fn write_int16(
    dir: &Path,
    dims: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    direction: [f64; 9],
    values: &[i16],
) -> std::io::Result<()> {
    use std::io::Write;
    let id = "values";
    std::fs::create_dir_all(dir.join("data"))?;
    let header = serde_json::json!({
        "vtkClass": "vtkImageData",
        "origin": origin,
        "spacing": spacing,
        "direction": direction,
        "extent": [0, dims[0] as i64 - 1, 0, dims[1] as i64 - 1, 0, dims[2] as i64 - 1],
        "pointData": {"vtkClass": "vtkDataSetAttributes", "arrays": [{"data": {
            "numberOfComponents": 1, "name": "ImageFile", "vtkClass": "vtkDataArray",
            "dataType": "Int16Array", "size": values.len(),
            "ref": {"registration": "setScalars", "encode": "LittleEndian",
                    "basepath": "data", "id": id}}}]},
    });
    std::fs::write(dir.join("index.json"), header.to_string())?;
    let f = std::fs::File::create(dir.join("data").join(format!("{id}.gz")))?;
    let mut gz = flate2::write::GzEncoder::new(f, flate2::Compression::fast());
    for v in values {
        gz.write_all(&v.to_le_bytes())?;
    }
    gz.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny(dir: &Path) -> Vec<i16> {
        let values: Vec<i16> = (0..24).map(|i| i * 10 - 5).collect();
        write_int16(
            dir,
            [2, 3, 4],
            [0.5, 1.0, 2.0],
            [10.0, 20.0, 30.0],
            [0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
            &values,
        )
        .unwrap();
        values
    }

    #[test]
    fn reads_a_tiny_dataset() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("tiny.vti");
        let values = tiny(&dir);
        let v = super::super::read_volume(&dir).unwrap();
        assert_eq!(v.dims, [2, 3, 4]);
        assert_eq!(v.spacing, [0.5, 1.0, 2.0]);
        assert_eq!(v.origin, [10.0, 20.0, 30.0]);
        assert_eq!(v.direction[0], [0.0, 1.0, 0.0]);
        assert_eq!(v.direction[1], [-1.0, 0.0, 0.0]);
        // Voxel (1, 2, 3): index 1 + 2 (2 + 3·3) = 23; i runs along +y, j along −x.
        assert_eq!(v.data[v.idx(1, 2, 3)], values[23] as f32);
        assert_eq!(v.to_world([1.0, 2.0, 3.0]), [10.0 - 2.0, 20.0 + 0.5, 36.0]);
        // index.json itself names the dataset too.
        assert_eq!(read(&dir.join("index.json")).unwrap().data, v.data);
    }

    #[test]
    fn extent_start_moves_the_first_voxel() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("shifted.vti");
        tiny(&dir);
        let p = dir.join("index.json");
        let text = std::fs::read_to_string(&p)
            .unwrap()
            .replace("\"extent\":[0,1,0,2,0,3]", "\"extent\":[1,2,0,2,-1,2]");
        std::fs::write(&p, text).unwrap();
        let v = read(&dir).unwrap();
        assert_eq!(v.dims, [2, 3, 4]);
        // i0 = 1 along +y (0.5 mm), k0 = −1 along +z (2 mm).
        assert_eq!(v.origin, [10.0, 20.5, 28.0]);
    }

    /// Each broken dataset is one error naming the file and the problem.
    #[test]
    fn bad_datasets_are_one_line_errors() {
        let t = tempfile::tempdir().unwrap();
        let cases: [(&str, &str, &str); 6] = [
            ("\"extent\":[0,1,0,2,0,3]", "\"extent\":[0,1,0,2]", "extent"),
            ("\"Int16Array\"", "\"Float16Array\"", "unsupported dataType"),
            ("\"size\":24", "\"size\":25", "needs 24"),
            ("\"LittleEndian\"", "\"BigEndian\"", "only LittleEndian"),
            (
                "\"numberOfComponents\":1",
                "\"numberOfComponents\":3",
                "3 components",
            ),
            ("\"vtkImageData\"", "\"vtkPolyData\"", "only vtkImageData"),
        ];
        for (n, (from, to, want)) in cases.iter().enumerate() {
            let dir = t.path().join(format!("bad{n}.vti"));
            tiny(&dir);
            let p = dir.join("index.json");
            let text = std::fs::read_to_string(&p).unwrap();
            assert!(text.contains(from), "{from} not in {text}");
            std::fs::write(&p, text.replace(from, to)).unwrap();
            let e = super::super::read_volume(&dir).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains("index.json"), "{e}");
            assert!(!e.contains('\n'), "{e}");
        }
        // Truncated and missing voxel files.
        let dir = t.path().join("short.vti");
        tiny(&dir);
        let gz = dir.join("data/values.gz");
        let bytes = std::fs::read(&gz).unwrap();
        std::fs::write(&gz, &bytes[..bytes.len() / 2]).unwrap();
        let e = read(&dir).unwrap_err().to_string();
        assert!(e.contains("values.gz"), "{e}");
        std::fs::remove_file(&gz).unwrap();
        let e = read(&dir).unwrap_err().to_string();
        assert!(e.contains("missing"), "{e}");
        // Not JSON.
        std::fs::write(dir.join("index.json"), "{").unwrap();
        let e = read(&dir).unwrap_err().to_string();
        assert!(e.contains("not a vtk.js dataset header"), "{e}");
    }
}

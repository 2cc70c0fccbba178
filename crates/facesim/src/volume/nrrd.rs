//! NRRD volumes (`.nrrd`, `.nhdr` + data file), as 3D Slicer hands a CT to a CLI module: a
//! text header, a blank line, then the voxels raw or gzip-compressed (or as ASCII numbers).
//!
//! Geometry: `space directions` (one vector per axis, fastest first) and `space origin` (the
//! centre of voxel 0) in the header's `space`; RAS (right-anterior-superior) has x and y
//! negated to LPS. Values are taken as they are: Slicer stores a CT in HU.

use super::grid::Volume;
use crate::error::{Error, Result};
use std::io::{Read, Write};
use std::path::Path;

pub fn read(path: &Path) -> Result<Volume> {
    let bytes = std::fs::read(path).map_err(|e| Error::input(path, e))?;
    parse(&bytes, path)
}

fn vector(s: &str) -> Option<[f64; 3]> {
    let inner = s.trim().strip_prefix('(')?.strip_suffix(')')?;
    let v: Vec<f64> = inner
        .split(',')
        .map(|x| x.trim().parse().ok())
        .collect::<Option<_>>()?;
    <[f64; 3]>::try_from(v).ok()
}

fn parse(bytes: &[u8], path: &Path) -> Result<Volume> {
    if !bytes.starts_with(b"NRRD000") {
        return Err(Error::input(path, "not a NRRD file (no NRRD000x magic)"));
    }
    let (header, dstart) = Header::read(bytes, path)?;
    let dims = header.sizes()?;
    let sample = header.sample()?;
    let Geometry {
        spacing,
        origin,
        direction,
    } = header.geometry(dims)?;
    let n = dims[0] * dims[1] * dims[2];
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data: header.voxels(&bytes[dstart..], n, sample)?,
    })
}

/// A NRRD header's fields (keys lower case), read from `path`.
struct Header<'a> {
    path: &'a Path,
    field: std::collections::HashMap<String, String>,
}

/// How one voxel is stored: its width in bytes and its kind ('i' signed, 'u' unsigned, 'f'
/// floating point).
#[derive(Clone, Copy)]
struct Sample {
    size: usize,
    kind: char,
}

/// Where the voxels lie, in LPS: as `Volume`'s fields of the same names.
struct Geometry {
    spacing: [f64; 3],
    origin: [f64; 3],
    direction: [[f64; 3]; 3],
}

impl<'a> Header<'a> {
    /// The header of `bytes` (a NRRD file's, magic checked) and where the data after it start.
    fn read(bytes: &[u8], path: &'a Path) -> Result<(Header<'a>, usize)> {
        // The header ends at the first empty line.
        let mut end = None;
        for i in 0..bytes.len().saturating_sub(1) {
            if bytes[i] == b'\n' && bytes[i + 1] == b'\n' {
                end = Some((i, i + 2));
                break;
            }
            if bytes[i] == b'\n' && bytes.get(i + 1..i + 3) == Some(b"\r\n") {
                end = Some((i, i + 3));
                break;
            }
        }
        let (hend, dstart) = match end {
            Some(e) => e,
            None => (bytes.len(), bytes.len()),
        };
        let header = std::str::from_utf8(&bytes[..hend])
            .map_err(|_| Error::input(path, "the header is not text"))?;
        let mut field = std::collections::HashMap::new();
        for line in header.lines().skip(1) {
            let line = line.trim_end_matches('\r');
            if line.starts_with('#') || line.contains(":=") {
                continue; // comments and key/value pairs
            }
            if let Some((k, v)) = line.split_once(": ") {
                field.insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
            }
        }
        Ok((Header { path, field }, dstart))
    }

    fn get(&self, k: &str) -> Option<&str> {
        self.field.get(k).map(String::as_str)
    }

    /// An error naming the file.
    fn bad(&self, m: String) -> Error {
        Error::input(self.path, m)
    }

    /// The three sizes of a 3-D image.
    fn sizes(&self) -> Result<[usize; 3]> {
        let dim: usize = self
            .get("dimension")
            .and_then(|d| d.parse().ok())
            .ok_or_else(|| self.bad("no dimension field".into()))?;
        if dim != 3 {
            return Err(self.bad(format!(
                "dimension {dim}: a CT volume is a 3-D scalar image"
            )));
        }
        let sizes: Vec<usize> = self
            .get("sizes")
            .map(|s| {
                s.split_whitespace()
                    .filter_map(|x| x.parse().ok())
                    .collect()
            })
            .unwrap_or_default();
        <[usize; 3]>::try_from(sizes).map_err(|_| self.bad("sizes must be 3 numbers".into()))
    }

    /// The voxel type.
    fn sample(&self) -> Result<Sample> {
        let ty = self
            .get("type")
            .ok_or_else(|| self.bad("no type field".into()))?;
        let (size, kind) = match ty {
            "signed char" | "int8" | "int8_t" | "char" => (1, 'i'),
            "uchar" | "unsigned char" | "uint8" | "uint8_t" => (1, 'u'),
            "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
                (2, 'i')
            }
            "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => (2, 'u'),
            "int" | "signed int" | "int32" | "int32_t" => (4, 'i'),
            "uint" | "unsigned int" | "uint32" | "uint32_t" => (4, 'u'),
            "float" => (4, 'f'),
            "double" => (8, 'f'),
            other => return Err(self.bad(format!("voxel type '{other}' is not supported"))),
        };
        Ok(Sample { size, kind })
    }

    /// Spacing, origin and axis directions in LPS, checked for an image of `dims`.
    fn geometry(&self, dims: [usize; 3]) -> Result<Geometry> {
        let ras = match self.get("space").map(|s| s.to_ascii_lowercase()) {
            None => false,
            Some(s) if s == "left-posterior-superior" || s == "lps" => false,
            Some(s) if s == "right-anterior-superior" || s == "ras" => true,
            Some(s) => {
                return Err(self.bad(format!(
                    "space '{s}' (expected left-posterior-superior or right-anterior-superior)"
                )));
            }
        };
        let (spacing, direction) = self.axes()?;
        let origin = match self.get("space origin") {
            Some(o) => {
                vector(o).ok_or_else(|| self.bad(format!("space origin '{o}' is not a vector")))?
            }
            None => [0.0; 3],
        };
        let flip = |v: [f64; 3]| if ras { [-v[0], -v[1], v[2]] } else { v };
        let direction = direction.map(flip);
        let origin = flip(origin);
        Volume::check_geometry(self.path, dims, spacing, origin, direction)?;
        Ok(Geometry {
            spacing,
            origin,
            direction,
        })
    }

    /// The spacing and unit direction of each axis in the header's space: from `space
    /// directions`, else `spacings` along the space's axes (1 mm without them).
    fn axes(&self) -> Result<([f64; 3], [[f64; 3]; 3])> {
        match self.get("space directions") {
            Some(d) => {
                let v: Vec<[f64; 3]> = d
                    .split(')')
                    .filter(|s| !s.trim().is_empty())
                    .map(|s| vector(&format!("{})", s.trim())))
                    .collect::<Option<_>>()
                    .ok_or_else(|| self.bad(format!("space directions '{d}' are not 3 vectors")))?;
                let v = <[[f64; 3]; 3]>::try_from(v)
                    .map_err(|_| self.bad("space directions must be 3 vectors".into()))?;
                let sp = v.map(crate::vec3::norm);
                if sp.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
                    return Err(self.bad("a space direction is zero or not finite".into()));
                }
                Ok((sp, std::array::from_fn(|a| v[a].map(|c| c / sp[a]))))
            }
            None => {
                let sp: Vec<f64> = self
                    .get("spacings")
                    .map(|s| {
                        s.split_whitespace()
                            .filter_map(|x| x.parse().ok())
                            .collect()
                    })
                    .unwrap_or_else(|| vec![1.0; 3]);
                let sp = <[f64; 3]>::try_from(sp)
                    .map_err(|_| self.bad("spacings must be 3 numbers".into()))?;
                Ok((
                    sp,
                    std::array::from_fn(|a| {
                        std::array::from_fn(|c| if a == c { 1.0 } else { 0.0 })
                    }),
                ))
            }
        }
    }

    /// The `n` voxel values: after the header (`inline`, the bytes after its blank line), or
    /// in a detached data file; raw, gzip-compressed or ASCII numbers.
    fn voxels(&self, inline: &[u8], n: usize, sample: Sample) -> Result<Vec<f32>> {
        let Sample { size, kind } = sample;
        // The voxels: after the header, or in a detached data file.
        let detached;
        let raw_bytes: &[u8] = match self.get("data file").or(self.get("datafile")) {
            Some(f) => {
                let p = self.path.parent().unwrap_or(Path::new("")).join(f);
                detached = std::fs::read(&p).map_err(|e| Error::input(&p, e))?;
                &detached
            }
            None => inline,
        };
        let encoding = self.get("encoding").unwrap_or("raw");
        let data: Vec<u8> = match encoding {
            "raw" => raw_bytes.to_vec(),
            "gzip" | "gz" => {
                let mut out = Vec::with_capacity(n * size);
                flate2::read::MultiGzDecoder::new(raw_bytes)
                    .take((n * size) as u64 + 1)
                    .read_to_end(&mut out)
                    .map_err(|e| self.bad(format!("gzip data: {e}")))?;
                out
            }
            "ascii" | "text" | "txt" => return self.ascii(raw_bytes, n),
            other => {
                return Err(self.bad(format!(
                    "encoding '{other}' is not supported (raw, gzip, ascii)"
                )));
            }
        };
        if data.len() < n * size {
            return Err(self.bad(format!(
                "{} bytes of voxel data, {} expected",
                data.len(),
                n * size
            )));
        }
        // Raw data sits at the end of the file (NRRD allows a skipped prefix).
        let data = &data[data.len() - n * size..];
        let big = self.get("endian") == Some("big");
        Ok(super::samples::decode_samples(data, kind, size, big))
    }

    /// The first `n` of the ASCII numbers `raw_bytes` hold.
    fn ascii(&self, raw_bytes: &[u8], n: usize) -> Result<Vec<f32>> {
        let text = std::str::from_utf8(raw_bytes)
            .map_err(|_| self.bad("ascii data is not text".into()))?;
        let v: Vec<f32> = text
            .split_whitespace()
            .map(|w| w.parse::<f64>().map(|x| x as f32))
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| self.bad("ascii data holds a non-number".into()))?;
        if v.len() < n {
            return Err(self.bad(format!("{} values for {n} voxels", v.len())));
        }
        Ok(v[..n].to_vec())
    }
}

/// Write `vol` as a gzip NRRD (int16 HU, LPS), as Slicer writes a CT for a CLI module (used by
/// tests to call `FaceSimPredict` the way Slicer does).
pub fn write(vol: &Volume, dest: &Path) -> Result<()> {
    crate::output::write_bytes_atomic(dest, |w| {
        let v = |a: [f64; 3]| format!("({},{},{})", a[0], a[1], a[2]);
        let dirs: Vec<String> = (0..3)
            .map(|a| v(vol.direction[a].map(|c| c * vol.spacing[a])))
            .collect();
        write!(
            w,
            "NRRD0004\n# written by facesim\ntype: short\ndimension: 3\nspace: left-posterior-superior\nsizes: {} {} {}\nspace directions: {}\nkinds: domain domain domain\nendian: little\nencoding: gzip\nspace origin: {}\n\n",
            vol.dims[0],
            vol.dims[1],
            vol.dims[2],
            dirs.join(" "),
            v(vol.origin)
        )?;
        let mut gz = flate2::write::GzEncoder::new(w, flate2::Compression::fast());
        for x in &vol.data {
            gz.write_all(&(x.round().clamp(-32768.0, 32767.0) as i16).to_le_bytes())?;
        }
        gz.finish()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vol() -> Volume {
        Volume {
            dims: [3, 4, 5],
            spacing: [0.5, 0.75, 2.0],
            origin: [10.0, -20.0, 30.0],
            direction: [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            data: (0..60).map(|i| (i * 37 % 2000) as f32 - 1000.0).collect(),
        }
    }

    #[test]
    fn gzip_round_trip_keeps_geometry_and_values() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ct.nrrd");
        write(&vol(), &p).unwrap();
        let back = read(&p).unwrap();
        let v = vol();
        assert_eq!(back.dims, v.dims);
        assert_eq!(back.data, v.data);
        for a in 0..3 {
            assert!((back.spacing[a] - v.spacing[a]).abs() < 1e-12);
            assert!((back.origin[a] - v.origin[a]).abs() < 1e-12);
            for c in 0..3 {
                assert!((back.direction[a][c] - v.direction[a][c]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn raw_big_endian_ras_header() {
        let mut b = b"NRRD0004\ntype: short\ndimension: 3\nspace: right-anterior-superior\nsizes: 2 1 1\nspace directions: (2,0,0) (0,3,0) (0,0,4)\nendian: big\nencoding: raw\nspace origin: (1,2,3)\n\n".to_vec();
        b.extend((-1000i16).to_be_bytes());
        b.extend(40i16.to_be_bytes());
        let v = parse(&b, Path::new("x.nrrd")).unwrap();
        assert_eq!(v.data, vec![-1000.0, 40.0]);
        assert_eq!(v.origin, [-1.0, -2.0, 3.0]);
        assert_eq!(v.direction[0], [-1.0, 0.0, 0.0]);
        assert_eq!(v.spacing, [2.0, 3.0, 4.0]);
        let e = parse(
            b"NRRD0004\ntype: short\ndimension: 4\n\n",
            Path::new("x.nrrd"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("x.nrrd") && e.contains("dimension 4"), "{e}");
    }
}

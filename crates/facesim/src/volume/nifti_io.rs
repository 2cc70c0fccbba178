//! NIfTI-1 (.nii, .nii.gz) via the `nifti` crate.
//!
//! Frame: the sform when `sform_code > 0`, else the qform when `qform_code > 0`, else a
//! diagonal from pixdim. NIfTI world coordinates are RAS, so x and y are negated to get LPS.
//! Values: scl_slope/scl_inter applied (slope 0 means 1), giving HU.

use super::grid::Volume;
use crate::error::{Context, Error, Result};
use crate::output::write_atomic;
use nifti::{IntoNdArray, NiftiHeader, NiftiObject, NiftiType, NiftiVolume, ReaderOptions};
use std::path::Path;

/// Voxel→RAS affine (3×4, rows) of a header, by the docs/reference/case.md precedence.
pub(crate) fn header_affine(h: &NiftiHeader) -> [[f64; 4]; 3] {
    if h.sform_code > 0 {
        let r = |row: [f32; 4]| row.map(|x| x as f64);
        return [r(h.srow_x), r(h.srow_y), r(h.srow_z)];
    }
    let dx = h.pixdim[1] as f64;
    let dy = h.pixdim[2] as f64;
    let dz = h.pixdim[3] as f64;
    if h.qform_code > 0 {
        // NIfTI-1 standard, method 2: quaternion (b, c, d), a = sqrt(1 - b² - c² - d²),
        // qfac = pixdim[0] (±1) flips the third axis.
        let (b, c, d) = (h.quatern_b as f64, h.quatern_c as f64, h.quatern_d as f64);
        let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let r = [
            [
                a * a + b * b - c * c - d * d,
                2.0 * (b * c - a * d),
                2.0 * (b * d + a * c),
            ],
            [
                2.0 * (b * c + a * d),
                a * a + c * c - b * b - d * d,
                2.0 * (c * d - a * b),
            ],
            [
                2.0 * (b * d - a * c),
                2.0 * (c * d + a * b),
                a * a + d * d - c * c - b * b,
            ],
        ];
        let s = [dx, dy, dz * qfac];
        let o = [h.quatern_x as f64, h.quatern_y as f64, h.quatern_z as f64];
        let mut m = [[0.0; 4]; 3];
        for row in 0..3 {
            for col in 0..3 {
                m[row][col] = r[row][col] * s[col];
            }
            m[row][3] = o[row];
        }
        return m;
    }
    [
        [dx, 0.0, 0.0, 0.0],
        [0.0, dy, 0.0, 0.0],
        [0.0, 0.0, dz, 0.0],
    ]
}

/// dims, spacing, origin, direction of a checked header.
type Geometry = ([usize; 3], [f64; 3], [f64; 3], [[f64; 3]; 3]);

/// Read the header only and check it: dimensions, spacing and type are validated before any
/// voxel memory is allocated.
fn read_checked_header(path: &Path) -> Result<Geometry> {
    let h = NiftiHeader::from_file(path)
        .map_err(|e| Error::input(path, format!("not a readable NIfTI-1 file ({e})")))?;
    let dims = checked_dims(path, &h)?;
    check_type_and_pixdim(path, &h)?;
    let (spacing, origin, direction) = lps_frame(&h);
    Volume::check_geometry(path, dims, spacing, origin, direction)?;
    if !h.scl_slope.is_finite() || !h.scl_inter.is_finite() {
        return Err(Error::input(path, "non-finite scl_slope/scl_inter"));
    }
    check_length(path, &h, dims)?;
    Ok((dims, spacing, origin, direction))
}

/// The volume's dimensions: a 2-D image is one slice; higher dimensions must all be 1.
fn checked_dims(path: &Path, h: &NiftiHeader) -> Result<[usize; 3]> {
    let ndim = h.dim[0] as usize;
    if !(2..=7).contains(&ndim) {
        return Err(Error::input(
            path,
            format!("invalid NIfTI dim[0] = {}", h.dim[0]),
        ));
    }
    let extra: usize = h.dim[4..=ndim.max(3)]
        .iter()
        .map(|&d| d.max(1) as usize)
        .product();
    if ndim > 3 && extra != 1 {
        return Err(Error::input(
            path,
            format!(
                "{ndim}-D image {:?}: facesim needs one 3-D volume",
                &h.dim[1..=ndim]
            ),
        ));
    }
    Ok([
        h.dim[1] as usize,
        h.dim[2] as usize,
        if ndim >= 3 { h.dim[3] as usize } else { 1 },
    ])
}

/// A datatype `read` converts, and (without an sform) a positive voxel size.
fn check_type_and_pixdim(path: &Path, h: &NiftiHeader) -> Result<()> {
    match h.data_type() {
        Ok(
            NiftiType::Uint8
            | NiftiType::Int8
            | NiftiType::Uint16
            | NiftiType::Int16
            | NiftiType::Uint32
            | NiftiType::Int32
            | NiftiType::Float32
            | NiftiType::Float64,
        ) => {}
        Ok(t) => {
            return Err(Error::input(
                path,
                format!("unsupported NIfTI datatype {t:?}"),
            ));
        }
        Err(_) => {
            return Err(Error::input(
                path,
                format!("unknown NIfTI datatype code {}", h.datatype),
            ));
        }
    }
    if h.sform_code <= 0 {
        // pixdim is the spacing only when no sform is used.
        for a in 1..=3 {
            let p = h.pixdim[a];
            if !p.is_finite() || p <= 0.0 {
                return Err(Error::input(
                    path,
                    format!("invalid voxel size pixdim[{a}] = {p}"),
                ));
            }
        }
    }
    Ok(())
}

/// Spacing, origin and direction in LPS from the header's RAS affine.
fn lps_frame(h: &NiftiHeader) -> ([f64; 3], [f64; 3], [[f64; 3]; 3]) {
    let ras = header_affine(h);
    // RAS → LPS: negate rows x and y.
    let sign = [-1.0, -1.0, 1.0];
    let mut spacing = [0.0; 3];
    let mut direction = [[0.0; 3]; 3];
    for c in 0..3 {
        let col = [
            ras[0][c] * sign[0],
            ras[1][c] * sign[1],
            ras[2][c] * sign[2],
        ];
        let n = (col[0] * col[0] + col[1] * col[1] + col[2] * col[2]).sqrt();
        spacing[c] = n;
        direction[c] = if n > 0.0 { col.map(|x| x / n) } else { col };
    }
    let origin = [
        ras[0][3] * sign[0],
        ras[1][3] * sign[1],
        ras[2][3] * sign[2],
    ];
    (spacing, origin, direction)
}

/// An uncompressed file shorter than its header promises is truncated: say so up front.
fn check_length(path: &Path, h: &NiftiHeader, dims: [usize; 3]) -> Result<()> {
    let name = path.to_string_lossy().to_lowercase();
    if name.ends_with(".nii") {
        let need = h.vox_offset.max(352.0) as u64
            + (dims.iter().product::<usize>() as u64) * (h.bitpix.max(8) as u64 / 8);
        let have = std::fs::metadata(path).at(path)?.len();
        if have < need {
            return Err(Error::input(
                path,
                format!("truncated: {have} bytes, the header needs {need}"),
            ));
        }
    }
    Ok(())
}

pub fn read(path: &Path) -> Result<Volume> {
    let (dims, spacing, origin, direction) = read_checked_header(path)?;
    let unreadable = |e: nifti::NiftiError| {
        Error::input(
            path,
            format!("cannot read NIfTI voxels ({e}); truncated or corrupt?"),
        )
    };
    let gz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let obj = if gz {
        // The whole gzip stream is inflated here, so its CRC-32 and length trailer are checked:
        // the nifti crate stops reading once it has the voxels, and a corrupted stream that
        // still inflates would pass unnoticed.
        let file = std::fs::File::open(path).map_err(|e| Error::input(path, e.to_string()))?;
        let mut inflate = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file));
        let obj = nifti::InMemNiftiObject::from_reader(&mut inflate).map_err(unreadable)?;
        std::io::copy(&mut inflate, &mut std::io::sink())
            .map_err(|e| Error::input(path, format!("corrupt gzip stream ({e})")))?;
        obj
    } else {
        ReaderOptions::new().read_file(path).map_err(unreadable)?
    };
    // A .nii.gz whose stream ends early decompresses to fewer bytes than the header promises;
    // the nifti crate would panic converting it (found by crates/facesim-cli/tests/e2e/fuzz.rs), so check first.
    let shape: Vec<u64> = obj.volume().dim().iter().map(|&d| d as u64).collect();
    let n_crate = shape.iter().try_fold(1u64, |a, &d| a.checked_mul(d));
    if n_crate != Some(dims.iter().product::<usize>() as u64) {
        return Err(Error::input(
            path,
            format!("inconsistent NIfTI dimensions {shape:?} (header checked as {dims:?})"),
        ));
    }
    let need = dims.iter().product::<usize>() * obj.volume().data_type().size_of();
    let have = obj.volume().raw_data().len();
    if have < need {
        return Err(Error::input(
            path,
            format!("truncated: {have} bytes of voxel data, the header needs {need}"),
        ));
    }
    // A partial trailing value makes the crate's byte swapping panic (also found by fuzzing).
    let size = obj.volume().data_type().size_of().max(1);
    if have % size != 0 {
        return Err(Error::input(
            path,
            format!("{have} bytes of voxel data are not a whole number of {size}-byte values"),
        ));
    }
    let n = dims.iter().product::<usize>();
    let h = obj.header();
    let big = h.endianness == nifti::Endianness::Big;
    let (slope, inter) = (h.scl_slope, h.scl_inter);
    let data = match decode(obj.volume(), n, big, slope, inter) {
        Some(d) => d,
        None => {
            // Other types through the crate: into_ndarray applies scl_slope/scl_inter (slope
            // 0 → identity).
            let arr = obj
                .into_volume()
                .into_ndarray::<f32>()
                .map_err(|e| Error::input(path, format!("cannot decode NIfTI voxels ({e})")))?;
            if arr.len() != n {
                return Err(Error::input(
                    path,
                    "voxel count does not match the header dimensions",
                ));
            }
            // ndarray index is (i, j, k, ...); reversing the axes makes i the fastest in
            // logical order.
            arr.reversed_axes().iter().copied().collect()
        }
    };
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
    })
}

/// The common CT voxel types decoded straight from the raw bytes, in parallel: the first n
/// values (NIfTI stores i fastest, as `Volume` does), scaled as the nifti crate scales them
/// (value as f32 · slope + intercept in f32 when the slope is not 0), without its three
/// volume-sized intermediate copies. None for other types.
fn decode(
    v: &nifti::InMemNiftiVolume,
    n: usize,
    big: bool,
    slope: f32,
    inter: f32,
) -> Option<Vec<f32>> {
    use rayon::prelude::*;
    fn run<const B: usize>(
        raw: &[u8],
        n: usize,
        f: impl Fn([u8; B]) -> f32 + Sync,
        slope: f32,
        inter: f32,
    ) -> Vec<f32> {
        raw[..n * B]
            .par_chunks_exact(B)
            .map(|b| {
                let x = f(b.try_into().unwrap_or([0; B]));
                if slope == 0.0 { x } else { x * slope + inter }
            })
            .collect()
    }
    let raw = v.raw_data();
    let (s, i) = (slope, inter);
    Some(match v.data_type() {
        NiftiType::Uint8 => run::<1>(raw, n, |b| b[0] as f32, s, i),
        NiftiType::Int8 => run::<1>(raw, n, |b| b[0] as i8 as f32, s, i),
        NiftiType::Int16 if big => run::<2>(raw, n, |b| i16::from_be_bytes(b) as f32, s, i),
        NiftiType::Int16 => run::<2>(raw, n, |b| i16::from_le_bytes(b) as f32, s, i),
        NiftiType::Uint16 if big => run::<2>(raw, n, |b| u16::from_be_bytes(b) as f32, s, i),
        NiftiType::Uint16 => run::<2>(raw, n, |b| u16::from_le_bytes(b) as f32, s, i),
        NiftiType::Float32 if big => run::<4>(raw, n, f32::from_be_bytes, s, i),
        NiftiType::Float32 => run::<4>(raw, n, f32::from_le_bytes, s, i),
        _ => return None,
    })
}

/// The header for an LPS volume written as NIfTI (sform, RAS, mm).
fn header_for(vol: &Volume) -> NiftiHeader {
    let mut h = NiftiHeader::default();
    let sign = [-1.0, -1.0, 1.0];
    let mut rows = [[0.0f32; 4]; 3];
    for (r, row) in rows.iter_mut().enumerate() {
        for c in 0..3 {
            row[c] = (sign[r] * vol.direction[c][r] * vol.spacing[c]) as f32;
        }
        row[3] = (sign[r] * vol.origin[r]) as f32;
    }
    h.srow_x = rows[0];
    h.srow_y = rows[1];
    h.srow_z = rows[2];
    h.sform_code = 1; // scanner anatomical
    h.qform_code = 0;
    h.pixdim = [
        1.0,
        vol.spacing[0] as f32,
        vol.spacing[1] as f32,
        vol.spacing[2] as f32,
        1.0,
        1.0,
        1.0,
        1.0,
    ];
    h.xyzt_units = 2; // mm
    h
}

/// Write HU as int16 (CT) when every value is integral and in range, else float32.
pub fn write(vol: &Volume, dest: &Path) -> Result<()> {
    let integral = vol
        .data
        .iter()
        .all(|v| v.fract() == 0.0 && (-32768.0..=32767.0).contains(v));
    if integral {
        let data: Vec<i16> = vol.data.iter().map(|&v| v as i16).collect();
        write_typed(vol, data, dest)
    } else {
        write_typed(vol, vol.data.clone(), dest)
    }
}

/// Write a label volume (u8) on the geometry of `vol`.
pub(crate) fn write_labels(vol: &Volume, labels: &[u8], dest: &Path) -> Result<()> {
    write_typed(vol, labels.to_vec(), dest)
}

fn write_typed<T: nifti::DataElement + bytemuck::Pod>(
    vol: &Volume,
    data: Vec<T>,
    dest: &Path,
) -> Result<()> {
    let [nx, ny, nz] = vol.dims;
    let arr = ndarray::Array3::from_shape_vec((nz, ny, nx), data)
        .map_err(|e| Error::output(dest, e))?
        .reversed_axes();
    let h = header_for(vol);
    write_atomic(dest, |tmp| {
        nifti::writer::WriterOptions::new(tmp)
            .reference_header(&h)
            .write_nifti(&arr)
            .map_err(|e| Error::output(dest, e))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fast decoder gives exactly what the nifti crate gives, for every type it handles,
    /// both byte orders, with and without scaling.
    #[test]
    fn raw_decoding_equals_the_crate_conversion() {
        let (nx, ny, nz) = (5usize, 4usize, 3usize);
        let n = nx * ny * nz;
        let dim = [3, nx as u16, ny as u16, nz as u16, 1, 1, 1, 1];
        for (ty, size) in [
            (NiftiType::Uint8, 1),
            (NiftiType::Int8, 1),
            (NiftiType::Int16, 2),
            (NiftiType::Uint16, 2),
            (NiftiType::Float32, 4),
        ] {
            for endian in [nifti::Endianness::Little, nifti::Endianness::Big] {
                for (slope, inter) in [(0.0f32, 0.0f32), (1.0, -1024.0), (0.5, 3.25)] {
                    let mut raw: Vec<u8> = (0..n * size)
                        .map(|b| (b * 151 + 7 + size * 13) as u8)
                        .collect();
                    if ty == NiftiType::Float32 {
                        // Finite floats: the top byte's exponent bits kept below all ones.
                        let top = if endian == nifti::Endianness::Big {
                            0
                        } else {
                            3
                        };
                        raw.chunks_mut(4).for_each(|c| c[top] &= 0x3f);
                    }
                    let v = nifti::InMemNiftiVolume::from_raw_fields(
                        dim, ty, slope, inter, raw, endian,
                    )
                    .unwrap();
                    let big = endian == nifti::Endianness::Big;
                    let fast = decode(&v, n, big, slope, inter).unwrap();
                    let arr = v.into_ndarray::<f32>().unwrap();
                    let crate_values: Vec<f32> = arr.reversed_axes().iter().copied().collect();
                    assert_eq!(fast, crate_values, "{ty:?} {endian:?} slope {slope}");
                }
            }
        }
    }
}

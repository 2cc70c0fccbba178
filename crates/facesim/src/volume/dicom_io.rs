//! DICOM series (a directory holding one series) via dicom-object + dicom-pixeldata.
//!
//! Geometry straight from the standard: ImageOrientationPatient gives the row direction (the
//! direction of increasing column index i) and the column direction (increasing row index j),
//! both already LPS; the slice normal is their cross product; slices are sorted by
//! ImagePositionPatient · normal. PixelSpacing is (row spacing, column spacing).
//! Values: stored value × RescaleSlope + RescaleIntercept = HU.

use super::{MAX_VOXELS, Volume};
use crate::error::{Error, Result};
use dicom_core::{DataElement, PrimitiveValue, VR, dicom_value};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject, OpenFileOptions};
use dicom_pixeldata::{ConvertOptions, ModalityLutOption, PixelDecoder};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Transfer syntaxes whose pixel data we read natively (no codec).
const NATIVE_TS: [&str; 3] = [
    uids::IMPLICIT_VR_LITTLE_ENDIAN,
    uids::EXPLICIT_VR_LITTLE_ENDIAN,
    "1.2.840.10008.1.2.2", // explicit VR big endian (retired, still seen)
];

struct SliceHeader {
    path: PathBuf,
    series: String,
    series_desc: String,
    ts: String,
    rows: usize,
    cols: usize,
    spacing: [f64; 2],
    iop: [f64; 6],
    ipp: [f64; 3],
}

fn is_dicom_file(path: &Path) -> bool {
    use std::io::Read;
    let mut buf = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut buf))
        .map(|()| &buf[128..132] == b"DICM")
        .unwrap_or(false)
}

fn floats(
    obj: &InMemDicomObject,
    tag: dicom_core::Tag,
    name: &str,
    n: usize,
    path: &Path,
) -> Result<Vec<f64>> {
    let e = obj
        .element_opt(tag)
        .ok()
        .flatten()
        .ok_or_else(|| Error::input(path, format!("missing {name}")))?;
    let v = e
        .to_multi_float64()
        .map_err(|_| Error::input(path, format!("unreadable {name}")))?;
    if v.len() < n || v.iter().take(n).any(|x| !x.is_finite()) {
        return Err(Error::input(
            path,
            format!("{name} needs {n} finite numbers, got {v:?}"),
        ));
    }
    Ok(v[..n].to_vec())
}

fn read_header(path: &Path) -> Result<SliceHeader> {
    let obj = OpenFileOptions::new()
        .read_until(tags::PIXEL_DATA)
        .open_file(path)
        .map_err(|e| Error::input(path, format!("unreadable DICOM file ({e})")))?;
    let ts = obj
        .meta()
        .transfer_syntax()
        .trim_end_matches('\0')
        .to_string();
    let get_str = |tag| {
        obj.element_opt(tag)
            .ok()
            .flatten()
            .and_then(|e| e.to_str().ok().map(|s| s.trim().to_string()))
            .unwrap_or_default()
    };
    let series = get_str(tags::SERIES_INSTANCE_UID);
    let series_desc = get_str(tags::SERIES_DESCRIPTION);
    let us = |tag, name: &str| -> Result<usize> {
        obj.element_opt(tag)
            .ok()
            .flatten()
            .and_then(|e| e.to_int::<u32>().ok())
            .map(|v| v as usize)
            .ok_or_else(|| Error::input(path, format!("missing {name}")))
    };
    let rows = us(tags::ROWS, "Rows")?;
    let cols = us(tags::COLUMNS, "Columns")?;
    let sp = floats(&obj, tags::PIXEL_SPACING, "PixelSpacing", 2, path)?;
    let iop = floats(
        &obj,
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
        6,
        path,
    )?;
    let ipp = floats(
        &obj,
        tags::IMAGE_POSITION_PATIENT,
        "ImagePositionPatient",
        3,
        path,
    )?;
    if sp.iter().any(|s| *s <= 0.0) {
        return Err(Error::input(
            path,
            format!("PixelSpacing {sp:?} must be positive"),
        ));
    }
    Ok(SliceHeader {
        path: path.to_path_buf(),
        series,
        series_desc,
        ts,
        rows,
        cols,
        spacing: [sp[0], sp[1]],
        iop: [iop[0], iop[1], iop[2], iop[3], iop[4], iop[5]],
        ipp: [ipp[0], ipp[1], ipp[2]],
    })
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / n)
}

pub fn read_series(dir: &Path) -> Result<Volume> {
    let files = dicom_files(dir)?;
    let mut headers = files
        .iter()
        .map(|p| read_header(p))
        .collect::<Result<Vec<_>>>()?;
    check_one_series(dir, &headers)?;
    check_same_frame(&headers)?;
    let first = &headers[0];
    let (rows, cols, pixel_spacing, iop) = (first.rows, first.cols, first.spacing, first.iop);
    let [row_dir, col_dir, normal] = slice_axes(iop);
    let pos = |h: &SliceHeader| h.ipp[0] * normal[0] + h.ipp[1] * normal[1] + h.ipp[2] * normal[2];
    headers.sort_by(|a, b| pos(a).total_cmp(&pos(b)));

    let nz = headers.len();
    let slice_spacing = if nz > 1 {
        slice_spacing(&headers, pos)?
    } else {
        1.0
    };
    let dims = [cols, rows, nz];
    let spacing = [pixel_spacing[1], pixel_spacing[0], slice_spacing];
    let direction = [row_dir, col_dir, normal];
    let origin = headers[0].ipp;
    Volume::check_geometry(dir, dims, spacing, origin, direction)?;
    let per_slice = rows * cols;
    debug_assert!(per_slice * nz <= MAX_VOXELS);

    let mut data = Vec::with_capacity(per_slice * nz);
    for h in &headers {
        read_slice(h, per_slice, &mut data)?;
    }
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
    })
}

/// The DICOM files of `dir` (not hidden, with the DICM preamble), sorted by name.
fn dicom_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| Error::input(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && !p
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with('.'))
        })
        .collect();
    files.sort();
    // Non-DICOM files (README, DICOMDIR without preamble, ...) are passed over; a file with the
    // DICM magic that does not parse is an error.
    let files: Vec<PathBuf> = files.into_iter().filter(|p| is_dicom_file(p)).collect();
    if files.is_empty() {
        return Err(Error::input(
            dir,
            "no DICOM files (with the DICM preamble) in this directory",
        ));
    }
    Ok(files)
}

/// Refuse a directory that mixes series, listing them.
fn check_one_series(dir: &Path, headers: &[SliceHeader]) -> Result<()> {
    let mut series: BTreeMap<&str, (usize, &str)> = BTreeMap::new();
    for h in headers {
        let e = series
            .entry(h.series.as_str())
            .or_insert((0, h.series_desc.as_str()));
        e.0 += 1;
    }
    if series.len() > 1 {
        let list: Vec<String> = series
            .iter()
            .map(|(uid, (n, d))| {
                format!(
                    "{uid} ({n} files{})",
                    if d.is_empty() {
                        String::new()
                    } else {
                        format!(", \"{d}\"")
                    }
                )
            })
            .collect();
        return Err(Error::input(
            dir,
            format!(
                "holds {} DICOM series, expected one: {}",
                series.len(),
                list.join("; ")
            ),
        ));
    }
    Ok(())
}

/// Every slice readable natively and with the first slice's size, spacing and orientation.
fn check_same_frame(headers: &[SliceHeader]) -> Result<()> {
    let first = &headers[0];
    for h in headers {
        if !NATIVE_TS.contains(&h.ts.as_str()) {
            return Err(Error::input(
                &h.path,
                format!(
                    "unsupported transfer syntax {} (compressed pixel data); decompress the series first, e.g. `gdcmconv --raw`",
                    h.ts
                ),
            ));
        }
        if h.rows != first.rows || h.cols != first.cols {
            return Err(Error::input(
                &h.path,
                format!(
                    "slice size {}x{} differs from {}x{} in {}",
                    h.cols,
                    h.rows,
                    first.cols,
                    first.rows,
                    first.path.display()
                ),
            ));
        }
        if (0..2).any(|a| (h.spacing[a] - first.spacing[a]).abs() > 1e-4 * first.spacing[a])
            || (0..6).any(|a| (h.iop[a] - first.iop[a]).abs() > 1e-4)
        {
            return Err(Error::input(
                &h.path,
                "pixel spacing or orientation differs from the rest of the series",
            ));
        }
    }
    Ok(())
}

/// Row direction, column direction and slice normal (their cross product) from
/// ImageOrientationPatient.
fn slice_axes(iop: [f64; 6]) -> [[f64; 3]; 3] {
    let row_dir = normalize([iop[0], iop[1], iop[2]]);
    let col_dir = normalize([iop[3], iop[4], iop[5]]);
    let normal = normalize([
        row_dir[1] * col_dir[2] - row_dir[2] * col_dir[1],
        row_dir[2] * col_dir[0] - row_dir[0] * col_dir[2],
        row_dir[0] * col_dir[1] - row_dir[1] * col_dir[0],
    ]);
    [row_dir, col_dir, normal]
}

/// The spacing of two or more slices sorted by position `pos`: refuses duplicate positions
/// and uneven gaps (a missing slice).
fn slice_spacing(headers: &[SliceHeader], pos: impl Fn(&SliceHeader) -> f64) -> Result<f64> {
    let nz = headers.len();
    let gaps: Vec<f64> = headers
        .windows(2)
        .map(|w| pos(&w[1]) - pos(&w[0]))
        .collect();
    for (w, g) in headers.windows(2).zip(&gaps) {
        if *g < 1e-3 {
            return Err(Error::input(
                &w[1].path,
                format!("duplicate slice position (same as {})", w[0].path.display()),
            ));
        }
    }
    // A missing slice only ever widens a gap, so the smallest gap is the series' spacing.
    let step = gaps.iter().cloned().fold(f64::INFINITY, f64::min);
    for (w, g) in headers.windows(2).zip(&gaps) {
        if (g - step).abs() > 0.05 * step + 1e-3 {
            return Err(Error::input(
                &w[1].path,
                format!(
                    "gap of {g:.3} mm before this slice, {step:.3} mm elsewhere: missing slice or uneven slice spacing"
                ),
            ));
        }
    }
    Ok((pos(&headers[nz - 1]) - pos(&headers[0])) / (nz - 1) as f64)
}

/// Append the HU of slice `h` (stored value × RescaleSlope + RescaleIntercept) to `data`.
fn read_slice(h: &SliceHeader, per_slice: usize, data: &mut Vec<f32>) -> Result<()> {
    let obj = dicom_object::open_file(&h.path)
        .map_err(|e| Error::input(&h.path, format!("unreadable DICOM file ({e})")))?;
    let slope = obj
        .element_opt(tags::RESCALE_SLOPE)
        .ok()
        .flatten()
        .and_then(|e| e.to_float64().ok())
        .unwrap_or(1.0);
    let inter = obj
        .element_opt(tags::RESCALE_INTERCEPT)
        .ok()
        .flatten()
        .and_then(|e| e.to_float64().ok())
        .unwrap_or(0.0);
    if !slope.is_finite() || !inter.is_finite() {
        return Err(Error::input(
            &h.path,
            "non-finite RescaleSlope/RescaleIntercept",
        ));
    }
    let pd = obj
        .decode_pixel_data()
        .map_err(|e| Error::input(&h.path, format!("cannot decode pixel data ({e})")))?;
    if pd.number_of_frames() != 1 || pd.samples_per_pixel() != 1 {
        return Err(Error::input(
            &h.path,
            "expected one greyscale frame per file",
        ));
    }
    let raw: Vec<f32> = pd
        .to_vec_with_options(&ConvertOptions::new().with_modality_lut(ModalityLutOption::None))
        .map_err(|e| Error::input(&h.path, format!("cannot decode pixel data ({e})")))?;
    if raw.len() != per_slice {
        return Err(Error::input(
            &h.path,
            format!(
                "pixel data has {} values, Rows×Columns = {per_slice} (truncated?)",
                raw.len()
            ),
        ));
    }
    data.extend(raw.iter().map(|&v| (v as f64 * slope + inter) as f32));
    Ok(())
}

fn ds(values: &[f64]) -> PrimitiveValue {
    PrimitiveValue::Strs(values.iter().map(|v| format_ds(*v)).collect())
}

/// DS values are at most 16 characters.
fn format_ds(v: f64) -> String {
    for prec in (0..=10).rev() {
        let s = format!("{v:.prec$}");
        if s.len() <= 16 {
            return s;
        }
    }
    format!("{v:.3e}")
}

/// Write `vol` as a DICOM CT series (Explicit VR Little Endian, int16, one file per slice)
/// into directory `dest`, atomically (built in a temporary directory, then renamed).
/// HU are rounded to integers (RescaleSlope 1, RescaleIntercept 0).
pub fn write_series(vol: &Volume, dest: &Path, series_uid_suffix: &str) -> Result<()> {
    let parent = dest.parent().unwrap_or(Path::new("."));
    let tmp = parent.join(format!(".facesim-tmp-dicom-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).map_err(|e| Error::output(&tmp, e))?;
    let ids = SeriesIds::new(vol, series_uid_suffix);
    let ct = uids::CT_IMAGE_STORAGE;
    let result = (|| -> Result<()> {
        for k in 0..vol.dims[2] {
            let sop = format!("{}.4.{series_uid_suffix}.{}", ids.root, k + 1);
            let file = slice_object(vol, k, &ids, &sop)
                .with_meta(
                    FileMetaTableBuilder::new()
                        .transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN)
                        .media_storage_sop_class_uid(ct)
                        .media_storage_sop_instance_uid(sop.as_str()),
                )
                .map_err(|e| Error::output(dest, e))?;
            let p = tmp.join(format!("slice{:04}.dcm", k + 1));
            file.write_to_file(&p).map_err(|e| Error::output(&p, e))?;
        }
        Ok(())
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e);
    }
    replace_dir(&tmp, dest)
}

/// What every slice of a written series shares: its UIDs and ImageOrientationPatient.
struct SeriesIds {
    root: &'static str,
    study: String,
    series: String,
    frame: String,
    iop: [f64; 6],
}

impl SeriesIds {
    fn new(vol: &Volume, series_uid_suffix: &str) -> Self {
        let root = "1.2.826.0.1.3680043.10.1452";
        SeriesIds {
            root,
            study: format!("{root}.1.{series_uid_suffix}"),
            series: format!("{root}.2.{series_uid_suffix}"),
            frame: format!("{root}.3.{series_uid_suffix}"),
            iop: [
                vol.direction[0][0],
                vol.direction[0][1],
                vol.direction[0][2],
                vol.direction[1][0],
                vol.direction[1][1],
                vol.direction[1][2],
            ],
        }
    }
}

/// Slice `k` of `vol` as a CT image (int16 HU, RescaleSlope 1, RescaleIntercept 0).
fn slice_object(vol: &Volume, k: usize, ids: &SeriesIds, sop: &str) -> InMemDicomObject {
    let [nx, ny, _] = vol.dims;
    let ipp = vol.to_world([0.0, 0.0, k as f64]);
    let mut obj = InMemDicomObject::new_empty();
    let mut put = |tag, vr, v: PrimitiveValue| {
        obj.put(DataElement::new(tag, vr, v));
    };
    put(
        tags::SOP_CLASS_UID,
        VR::UI,
        PrimitiveValue::from(uids::CT_IMAGE_STORAGE),
    );
    put(tags::SOP_INSTANCE_UID, VR::UI, PrimitiveValue::from(sop));
    put(
        tags::STUDY_INSTANCE_UID,
        VR::UI,
        PrimitiveValue::from(ids.study.as_str()),
    );
    put(
        tags::SERIES_INSTANCE_UID,
        VR::UI,
        PrimitiveValue::from(ids.series.as_str()),
    );
    put(
        tags::FRAME_OF_REFERENCE_UID,
        VR::UI,
        PrimitiveValue::from(ids.frame.as_str()),
    );
    put(tags::MODALITY, VR::CS, PrimitiveValue::from("CT"));
    put(
        tags::PATIENT_NAME,
        VR::PN,
        PrimitiveValue::from("Phantom^Facesim"),
    );
    put(
        tags::PATIENT_ID,
        VR::LO,
        PrimitiveValue::from("FACESIM-PHANTOM"),
    );
    put(
        tags::SERIES_DESCRIPTION,
        VR::LO,
        PrimitiveValue::from("facesim phantom"),
    );
    put(
        tags::INSTANCE_NUMBER,
        VR::IS,
        PrimitiveValue::from(format!("{}", k + 1).as_str()),
    );
    put(tags::IMAGE_POSITION_PATIENT, VR::DS, ds(&ipp));
    put(tags::IMAGE_ORIENTATION_PATIENT, VR::DS, ds(&ids.iop));
    put(
        tags::PIXEL_SPACING,
        VR::DS,
        ds(&[vol.spacing[1], vol.spacing[0]]),
    );
    put(tags::SLICE_THICKNESS, VR::DS, ds(&[vol.spacing[2]]));
    put(tags::SAMPLES_PER_PIXEL, VR::US, PrimitiveValue::from(1u16));
    put(
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        dicom_value!(Str, "MONOCHROME2"),
    );
    put(tags::ROWS, VR::US, PrimitiveValue::from(ny as u16));
    put(tags::COLUMNS, VR::US, PrimitiveValue::from(nx as u16));
    put(tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(16u16));
    put(tags::BITS_STORED, VR::US, PrimitiveValue::from(16u16));
    put(tags::HIGH_BIT, VR::US, PrimitiveValue::from(15u16));
    put(
        tags::PIXEL_REPRESENTATION,
        VR::US,
        PrimitiveValue::from(1u16),
    );
    put(tags::RESCALE_INTERCEPT, VR::DS, ds(&[0.0]));
    put(tags::RESCALE_SLOPE, VR::DS, ds(&[1.0]));
    let start = k * nx * ny;
    let mut bytes = Vec::with_capacity(nx * ny * 2);
    for &v in &vol.data[start..start + nx * ny] {
        let s = v.round().clamp(-32768.0, 32767.0) as i16;
        bytes.extend_from_slice(&s.to_le_bytes());
    }
    put(tags::PIXEL_DATA, VR::OW, PrimitiveValue::from(bytes));
    obj
}

/// Move a finished directory into place, replacing an older one only after the new one exists.
fn replace_dir(tmp: &Path, dest: &Path) -> Result<()> {
    if dest.exists() {
        let old = dest.with_extension(format!("old-{}", std::process::id()));
        std::fs::rename(dest, &old).map_err(|e| Error::output(dest, e))?;
        std::fs::rename(tmp, dest).map_err(|e| Error::output(dest, e))?;
        let _ = std::fs::remove_dir_all(&old);
    } else {
        std::fs::rename(tmp, dest).map_err(|e| Error::output(dest, e))?;
    }
    Ok(())
}

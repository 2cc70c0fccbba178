//! DICOM series (a directory holding one series) via dicom-object + dicom-pixeldata.
//!
//! What a PACS export or patient CD holds besides the images is passed over: files without the
//! DICM preamble, a DICOMDIR, non-image objects (reports, presentation states). File names do
//! not matter (no `.dcm` needed). A directory with no image of its own is searched below (a CD's
//! `DICOM/…` tree); more than one series found is refused with every series listed, never
//! guessed (two reconstructions of one scan, bone and soft-tissue kernel, have the same size).
//! Compressed pixel data is decoded by the codecs in `dicom_syntax` (docs/guide/dicom.md).
//!
//! Geometry straight from the standard: ImageOrientationPatient gives the row direction (the
//! direction of increasing column index i) and the column direction (increasing row index j),
//! both already LPS; the slice normal is their cross product; slices are sorted by
//! ImagePositionPatient · normal. PixelSpacing is (row spacing, column spacing).
//! Values: stored value × RescaleSlope + RescaleIntercept = HU.
//!
//! Multi-frame objects (Enhanced CT, Legacy Converted Enhanced CT) carry the same attributes per
//! frame in functional groups (PS3.3 C.7.6.16): PlanePositionSequence (ImagePositionPatient),
//! PlaneOrientationSequence (ImageOrientationPatient), PixelMeasuresSequence (PixelSpacing) and
//! PixelValueTransformationSequence (the rescale), each taken from the frame's own item of
//! PerFrameFunctionalGroupsSequence, else from SharedFunctionalGroupsSequence. Each frame is then
//! one slice like a single-frame file's, so sorting, spacing and tilt checks are the same.

use super::grid::{MAX_VOXELS, Volume};
use crate::error::{Error, Result};
use dicom_core::{DataElement, PrimitiveValue, VR, dicom_value};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject, OpenFileOptions};
use dicom_pixeldata::{ConvertOptions, ModalityLutOption, PixelDecoder};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{dicom_syntax, tilt};

/// Media Storage Directory Storage: the SOP class of a DICOMDIR.
const DICOMDIR_SOP_CLASS: &str = "1.2.840.10008.1.3.10";

/// One slice: a single-frame file, or one frame of a multi-frame file.
#[derive(Clone)]
struct SliceHeader {
    path: PathBuf,
    /// The frame's index (from 0) in a multi-frame file; `None` for a single-frame file.
    frame: Option<u32>,
    series: String,
    series_desc: String,
    series_number: String,
    modality: String,
    ts: String,
    rows: usize,
    cols: usize,
    spacing: [f64; 2],
    iop: [f64; 6],
    ipp: [f64; 3],
    /// RescaleSlope and RescaleIntercept.
    rescale: [f64; 2],
}

impl SliceHeader {
    /// An input error about this slice: naming the file, and the frame in a multi-frame file.
    fn error(&self, msg: impl std::fmt::Display) -> Error {
        match self.frame {
            Some(f) => Error::input(&self.path, format!("frame {}: {msg}", f + 1)),
            None => Error::input(&self.path, msg),
        }
    }

    /// The file, and the frame (counted from 1) of a multi-frame file, for messages.
    fn place(&self) -> String {
        match self.frame {
            Some(f) => format!("{} frame {}", self.path.display(), f + 1),
            None => self.path.display().to_string(),
        }
    }
}

/// Whether `path` has the DICOM preamble (`DICM` at byte 128), whatever its name.
pub(crate) fn is_dicom_file(path: &Path) -> bool {
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

/// The slices of an image file: one for a single-frame file, one per frame for a multi-frame
/// (enhanced) one; none for a DICOMDIR or a non-image object (no Rows and no Columns), which a
/// series directory may hold beside its images.
fn read_headers(path: &Path) -> Result<Vec<SliceHeader>> {
    let obj = OpenFileOptions::new()
        .read_until(tags::PIXEL_DATA)
        .open_file(path)
        .map_err(|e| Error::input(path, format!("unreadable DICOM file ({e})")))?;
    let ts = obj
        .meta()
        .transfer_syntax()
        .trim_end_matches('\0')
        .to_string();
    let sop_class = obj.meta().media_storage_sop_class_uid();
    let has = |tag| obj.element_opt(tag).ok().flatten().is_some();
    if sop_class.trim_end_matches('\0') == DICOMDIR_SOP_CLASS
        || (!has(tags::ROWS) && !has(tags::COLUMNS))
    {
        return Ok(Vec::new());
    }
    let get_str = |tag| {
        obj.element_opt(tag)
            .ok()
            .flatten()
            .and_then(|e| e.to_str().ok().map(|s| s.trim().to_string()))
            .unwrap_or_default()
    };
    let us = |tag, name: &str| -> Result<usize> {
        obj.element_opt(tag)
            .ok()
            .flatten()
            .and_then(|e| e.to_int::<u32>().ok())
            .map(|v| v as usize)
            .ok_or_else(|| Error::input(path, format!("missing {name}")))
    };
    let template = SliceHeader {
        path: path.to_path_buf(),
        frame: None,
        series: get_str(tags::SERIES_INSTANCE_UID),
        series_desc: get_str(tags::SERIES_DESCRIPTION),
        series_number: get_str(tags::SERIES_NUMBER),
        modality: get_str(tags::MODALITY),
        ts,
        rows: us(tags::ROWS, "Rows")?,
        cols: us(tags::COLUMNS, "Columns")?,
        spacing: [0.0; 2],
        iop: [0.0; 6],
        ipp: [0.0; 3],
        rescale: [1.0, 0.0],
    };
    let frames = obj
        .element_opt(tags::NUMBER_OF_FRAMES)
        .ok()
        .flatten()
        .map(|e| {
            e.to_int::<i64>()
                .ok()
                .filter(|n| (1..=u32::MAX as i64).contains(n))
                .ok_or_else(|| Error::input(path, "unreadable NumberOfFrames"))
        })
        .transpose()?
        .unwrap_or(1) as usize;
    let per_frame = obj
        .element_opt(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .ok()
        .flatten()
        .map(|e| e.items().unwrap_or(&[]));
    let shared = obj
        .element_opt(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE)
        .ok()
        .flatten()
        .and_then(|e| e.items())
        .and_then(|items| items.first());
    let top: &InMemDicomObject = &obj;
    let Some(per_frame) = per_frame else {
        if frames > 1 {
            return Err(Error::input(
                path,
                format!(
                    "{frames} frames without PerFrameFunctionalGroupsSequence: no position per frame to place them in a volume (an Enhanced CT object has one)"
                ),
            ));
        }
        return Ok(vec![slice_geometry(template, &[], top)?]);
    };
    if per_frame.len() != frames {
        return Err(Error::input(
            path,
            format!(
                "NumberOfFrames {frames} but PerFrameFunctionalGroupsSequence has {} items",
                per_frame.len()
            ),
        ));
    }
    // A frame's attribute: its own functional group, else the shared one, else the top level
    // (where a converter may have left it).
    let groups = |own| {
        let mut g = vec![own];
        g.extend(shared);
        g
    };
    (0..frames)
        .map(|f| {
            let h = SliceHeader {
                frame: Some(f as u32),
                ..template.clone()
            };
            slice_geometry(h, &groups(&per_frame[f]), top)
        })
        .collect()
}

/// Fill in `h`'s spacing, orientation, position and rescale, each attribute taken from the first
/// of the functional group items `groups` (a frame's own, then the shared ones; none for a
/// single-frame file) whose group sequence holds it, else from the data set `top`.
fn slice_geometry(
    mut h: SliceHeader,
    groups: &[&InMemDicomObject],
    top: &InMemDicomObject,
) -> Result<SliceHeader> {
    let holds = |o: &&InMemDicomObject, tag| o.element_opt(tag).ok().flatten().is_some();
    // The item of functional group sequence `group` (PS3.3 C.7.6.16.2) that holds `tag`.
    let find = |group, tag| {
        groups
            .iter()
            .find_map(|g| {
                g.element_opt(group)
                    .ok()
                    .flatten()
                    .and_then(|e| e.items())
                    .and_then(|items| items.first())
                    .filter(|i| holds(i, tag))
            })
            .or(Some(top).filter(|o| holds(o, tag)))
    };
    let floats_in = |group, tag, name: &str, n| -> Result<Vec<f64>> {
        let o = find(group, tag).ok_or_else(|| h.error(format!("missing {name}")))?;
        floats(o, tag, name, n, &h.path).map_err(|e| match e {
            Error::Input { msg, .. } => h.error(msg),
            e => e,
        })
    };
    let sp = floats_in(
        tags::PIXEL_MEASURES_SEQUENCE,
        tags::PIXEL_SPACING,
        "PixelSpacing",
        2,
    )?;
    let iop = floats_in(
        tags::PLANE_ORIENTATION_SEQUENCE,
        tags::IMAGE_ORIENTATION_PATIENT,
        "ImageOrientationPatient",
        6,
    )?;
    let ipp = floats_in(
        tags::PLANE_POSITION_SEQUENCE,
        tags::IMAGE_POSITION_PATIENT,
        "ImagePositionPatient",
        3,
    )?;
    let value = |tag, default: f64| -> Result<f64> {
        match find(tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE, tag) {
            None => Ok(default),
            Some(o) => o
                .element(tag)
                .ok()
                .and_then(|e| e.to_float64().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| h.error("non-finite RescaleSlope/RescaleIntercept")),
        }
    };
    h.rescale = [
        value(tags::RESCALE_SLOPE, 1.0)?,
        value(tags::RESCALE_INTERCEPT, 0.0)?,
    ];
    if sp.iter().any(|s| *s <= 0.0) {
        return Err(h.error(format!("PixelSpacing {sp:?} must be positive")));
    }
    h.spacing = [sp[0], sp[1]];
    h.iop = [iop[0], iop[1], iop[2], iop[3], iop[4], iop[5]];
    h.ipp = [ipp[0], ipp[1], ipp[2]];
    Ok(h)
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / n)
}

/// Read one series of `dir`: the one whose SeriesInstanceUID or SeriesNumber is `series`, else
/// (when the directory holds several) the CT series with the most images. Returns notes for the
/// report: which series was taken and how to choose another; a gantry tilt resampled.
pub fn read_chosen_series(dir: &Path, series: Option<&str>) -> Result<(Volume, Vec<String>)> {
    let files = dicom_files(dir)?;
    let mut headers = Vec::with_capacity(files.len());
    for p in &files {
        headers.extend(read_headers(p)?);
    }
    if headers.is_empty() {
        return Err(Error::input(
            dir,
            format!(
                "no DICOM images here ({} DICOM files, none an image: DICOMDIR or reports only)",
                files.len()
            ),
        ));
    }
    let notes: Vec<String> = choose_series(dir, &mut headers, series)?
        .into_iter()
        .collect();
    assemble(dir, headers, notes)
}

/// Read one DICOM file that holds a whole volume: a multi-frame (enhanced) CT object, which
/// `[ct] path` may name directly. A single-frame file is one slice: its directory is the series.
pub(crate) fn read_multiframe_file(path: &Path) -> Result<(Volume, Vec<String>)> {
    let headers = read_headers(path)?;
    match headers.len() {
        0 => Err(Error::input(path, "a DICOM file without an image")),
        1 => Err(Error::input(
            path,
            "a single-frame DICOM image is one slice: give the directory holding its series",
        )),
        _ => assemble(path, headers, Vec::new()),
    }
}

/// The volume of the slices `headers` (one series; `dir` names its directory or file in
/// messages), with the notes so far and a gantry tilt's.
fn assemble(
    dir: &Path,
    mut headers: Vec<SliceHeader>,
    mut notes: Vec<String>,
) -> Result<(Volume, Vec<String>)> {
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
    // Gantry tilt: slices shifted across their plane (more than a tenth of a pixel over the
    // series) are resampled onto the orthogonal grid through the first slice (`tilt`).
    let ipps: Vec<[f64; 3]> = headers.iter().map(|h| h.ipp).collect();
    let drift = tilt::drift_pixels(
        &ipps,
        row_dir,
        col_dir,
        [pixel_spacing[1], pixel_spacing[0]],
    );
    let drift_mm = |d: &[f64; 2]| (d[0] * pixel_spacing[1]).hypot(d[1] * pixel_spacing[0]);
    let max_drift = drift.iter().map(drift_mm).fold(0.0, f64::max);
    let tilted = max_drift > 0.1 * pixel_spacing[0].min(pixel_spacing[1]);
    let dims = [cols, rows, nz];
    let spacing = [pixel_spacing[1], pixel_spacing[0], slice_spacing];
    let direction = [row_dir, col_dir, normal];
    let origin = headers[0].ipp;
    Volume::check_geometry(dir, dims, spacing, origin, direction)?;
    let per_slice = rows * cols;
    debug_assert!(per_slice * nz <= MAX_VOXELS);

    // Files decode in parallel, and the frames of a multi-frame file too (a compressed series is
    // codec-bound: docs/lab/performance.md); each file in its own guard, so a parser panic on one
    // damaged file names that file.
    let mut data = vec![0.0f32; per_slice * nz];
    let mut by_file: BTreeMap<&Path, Vec<(&SliceHeader, &mut [f32])>> = BTreeMap::new();
    for (h, slice) in headers.iter().zip(data.chunks_mut(per_slice)) {
        by_file.entry(&h.path).or_default().push((h, slice));
    }
    by_file
        .into_par_iter()
        .try_for_each(|(path, slices)| crate::error::guard(path, || decode_file(path, slices)))?;
    if tilted {
        let fill = data.iter().cloned().fold(f32::INFINITY, f32::min);
        tilt::resample(&mut data, [cols, rows, nz], &drift, fill);
        let height = pos(&headers[nz - 1]) - pos(&headers[0]);
        let angle = drift_mm(&drift[nz - 1]).atan2(height).to_degrees();
        notes.push(format!(
            "{}: gantry-tilted series ({angle:.1}°: the slices drift up to {max_drift:.1} mm across their plane); each slice was shifted back in its plane onto an orthogonal grid (bilinear; {fill} HU where no slice data falls)",
            dir.display()
        ));
    }
    Ok((
        Volume {
            dims,
            spacing,
            origin,
            direction,
            data,
        },
        notes,
    ))
}

/// The DICOM files of `dir` (not hidden, with the DICM preamble, whatever their name), sorted
/// by path. When `dir` itself holds none, its subdirectories are searched (a patient CD: a
/// DICOMDIR at the top, the images in `DICOM/…`).
fn dicom_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let (files, subdirs) = list_dir(dir)?;
    // Non-DICOM files (README, ...) are passed over; a file with the DICM magic that does not
    // parse is an error.
    let mut files: Vec<PathBuf> = files.into_iter().filter(|p| is_dicom_file(p)).collect();
    let only_dicomdir = files.iter().all(|p| {
        p.file_name()
            .is_some_and(|n| n.eq_ignore_ascii_case("DICOMDIR"))
    });
    if only_dicomdir {
        let mut stack = subdirs;
        while let Some(d) = stack.pop() {
            let (f, sub) = list_dir(&d)?;
            files.extend(f.into_iter().filter(|p| is_dicom_file(p)));
            stack.extend(sub);
        }
        files.sort();
    }
    if files.is_empty() {
        return Err(Error::input(
            dir,
            "no DICOM files (with the DICM preamble) in this directory or below",
        ));
    }
    Ok(files)
}

/// The files and the subdirectories of `dir`, hidden ones left out, each sorted.
fn list_dir(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let (mut files, mut dirs) = (Vec::new(), Vec::new());
    for e in std::fs::read_dir(dir).map_err(|e| Error::input(dir, e))? {
        let p = e.map_err(|e| Error::input(dir, e))?.path();
        if p.file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'))
        {
            continue;
        }
        if p.is_dir() {
            dirs.push(p);
        } else if p.is_file() {
            files.push(p);
        }
    }
    files.sort();
    dirs.sort();
    Ok((files, dirs))
}

/// Keep the headers of one series: the one `wanted` names (its SeriesInstanceUID or
/// SeriesNumber), else, when `dir` holds several, the CT series with the most images (ties:
/// the first by UID), with a note listing every series with its size, description and (when it
/// lies below `dir`) its folder. A `wanted` series that is not there is an error listing them.
fn choose_series(
    dir: &Path,
    headers: &mut Vec<SliceHeader>,
    wanted: Option<&str>,
) -> Result<Option<String>> {
    struct Series<'a> {
        n: usize,
        desc: &'a str,
        number: &'a str,
        ct: bool,
        folder: &'a Path,
    }
    let mut series: BTreeMap<&str, Series> = BTreeMap::new();
    for h in headers.iter() {
        let e = series.entry(h.series.as_str()).or_insert(Series {
            n: 0,
            desc: &h.series_desc,
            number: &h.series_number,
            ct: h.modality.eq_ignore_ascii_case("CT"),
            folder: h.path.parent().unwrap_or(dir),
        });
        e.n += 1;
    }
    let list = || -> String {
        series
            .iter()
            .map(|(uid, s)| {
                let desc = if s.desc.is_empty() {
                    String::new()
                } else {
                    format!(", \"{}\"", s.desc)
                };
                let number = if s.number.is_empty() {
                    String::new()
                } else {
                    format!(", number {}", s.number)
                };
                let place = match s.folder.strip_prefix(dir) {
                    Ok(rel) if !rel.as_os_str().is_empty() => format!(" in {}", rel.display()),
                    _ => String::new(),
                };
                format!("{uid} ({} images{number}{desc}{place})", s.n)
            })
            .collect::<Vec<_>>()
            .join("; ")
    };
    let (chosen, note) = match wanted {
        Some(w) => {
            let w = w.trim();
            let Some((uid, _)) = series
                .iter()
                .find(|(uid, s)| *uid == &w || (!s.number.is_empty() && s.number == w))
            else {
                return Err(Error::input(
                    dir,
                    format!(
                        "no DICOM series here has [dicom] series = \"{w}\" as its SeriesInstanceUID or SeriesNumber; the series are: {}",
                        list()
                    ),
                ));
            };
            (uid.to_string(), None)
        }
        None if series.len() <= 1 => return Ok(None),
        None => {
            let best = series
                .iter()
                .max_by_key(|(uid, s)| (s.ct, s.n, std::cmp::Reverse(*uid)))
                .map(|(uid, s)| (uid.to_string(), s.n));
            let Some((uid, n)) = best else {
                return Ok(None);
            };
            let note = format!(
                "{} holds {} DICOM series; read the largest CT series {uid} ({n} images); choose another with [dicom] series = \"UID or SeriesNumber\": {}",
                dir.display(),
                series.len(),
                list()
            );
            (uid, Some(note))
        }
    };
    headers.retain(|h| h.series == chosen);
    Ok(note)
}

/// Every slice readable natively and with the first slice's size, spacing and orientation.
fn check_same_frame(headers: &[SliceHeader]) -> Result<()> {
    let first = &headers[0];
    for h in headers {
        dicom_syntax::check_decodable(&h.ts).map_err(|msg| Error::input(&h.path, msg))?;
        if h.rows != first.rows || h.cols != first.cols {
            return Err(h.error(format!(
                "slice size {}x{} differs from {}x{} in {}",
                h.cols,
                h.rows,
                first.cols,
                first.rows,
                first.place()
            )));
        }
        if (0..2).any(|a| (h.spacing[a] - first.spacing[a]).abs() > 1e-4 * first.spacing[a])
            || (0..6).any(|a| (h.iop[a] - first.iop[a]).abs() > 1e-4)
        {
            return Err(h.error("pixel spacing or orientation differs from the rest of the series"));
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
            return Err(w[1].error(format!(
                "duplicate slice position (same as {})",
                w[0].place()
            )));
        }
    }
    // A missing slice only ever widens a gap, so the smallest gap is the series' spacing.
    let step = gaps.iter().cloned().fold(f64::INFINITY, f64::min);
    for (w, g) in headers.windows(2).zip(&gaps) {
        if (g - step).abs() > 0.05 * step + 1e-3 {
            return Err(w[1].error(format!(
                "gap of {g:.3} mm before this slice, {step:.3} mm elsewhere: missing slice or uneven slice spacing"
            )));
        }
    }
    Ok((pos(&headers[nz - 1]) - pos(&headers[0])) / (nz - 1) as f64)
}

/// Write the HU of the slices of file `path` (stored value × RescaleSlope + RescaleIntercept) into
/// their places in the volume: the one image of a single-frame file, or the listed frames of a
/// multi-frame one (decoded frame by frame, in parallel).
fn decode_file(path: &Path, slices: Vec<(&SliceHeader, &mut [f32])>) -> Result<()> {
    let obj = dicom_object::open_file(path)
        .map_err(|e| Error::input(path, format!("unreadable DICOM file ({e})")))?;
    slices.into_par_iter().try_for_each(|(h, out)| {
        let pd = match h.frame {
            None => {
                let pd = decode_guarded(h, || obj.decode_pixel_data())?;
                if pd.number_of_frames() != 1 {
                    return Err(h.error(format!(
                        "{} frames in a file without PerFrameFunctionalGroupsSequence",
                        pd.number_of_frames()
                    )));
                }
                pd
            }
            Some(f) => decode_guarded(h, || obj.decode_pixel_data_frame(f))?,
        };
        if pd.samples_per_pixel() != 1 {
            return Err(h.error(format!(
                "{} samples per pixel: a CT image is greyscale",
                pd.samples_per_pixel()
            )));
        }
        let convert = ConvertOptions::new().with_modality_lut(ModalityLutOption::None);
        let raw: Vec<f32> = decode_guarded(h, || pd.to_vec_with_options(&convert))?;
        if raw.len() != out.len() {
            return Err(h.error(format!(
                "pixel data has {} values, Rows×Columns = {} (truncated?)",
                raw.len(),
                out.len()
            )));
        }
        let [slope, inter] = h.rescale;
        for (o, &v) in out.iter_mut().zip(&raw) {
            *o = (v as f64 * slope + inter) as f32;
        }
        Ok(())
    })
}

/// Run a decoding step of slice `h`; its failure, or a panic of the codec on damaged data
/// (dicom-rs's RLE reader indexes past a bad segment table), becomes one line naming the file
/// and the transfer syntax.
fn decode_guarded<T, E: std::fmt::Display>(
    h: &SliceHeader,
    f: impl FnOnce() -> std::result::Result<T, E>,
) -> Result<T> {
    let undecodable = |e: &dyn std::fmt::Display| {
        h.error(format!(
            "cannot decode pixel data, transfer syntax {} ({e})",
            dicom_syntax::describe(&h.ts)
        ))
    };
    match crate::error::guard(&h.path, || Ok(f())) {
        Ok(r) => r.map_err(|e| undecodable(&e)),
        Err(Error::Input { msg, .. }) => Err(undecodable(&msg)),
        Err(e) => Err(e),
    }
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
    crate::output::create_dir_guarded(parent)?;
    // A directory of this call's own (`mkdir` refuses an existing name): series written at once
    // beside each other, by threads or processes, never share it.
    let tmp = crate::output::fresh_dir(parent, ".facesim-tmp-dicom-")?;
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
    crate::output::replace_dir(&tmp, dest)
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

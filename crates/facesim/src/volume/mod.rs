//! The CT volume: voxels in Hounsfield units with a voxel-to-LPS affine (mm).
//!
//! Readers for NIfTI, NRRD, DICOM series, InVesalius projects and vtk.js dataset folders all produce a [`Volume`]; everything
//! downstream works in the LPS world frame (docs/reference/case.md "Frames and units").

pub(crate) mod blocks;
pub mod dicom_io;
pub(crate) mod dicom_syntax;
mod grid;
pub mod inv3;
pub mod nifti_io;
pub mod nrrd;
mod samples;
pub mod tilt;
pub(crate) mod vtkjs;

pub(crate) use grid::det3;
pub use grid::{Inspect, Volume, VoxelMap, axes_code, inv3, past_scan_end, sample_field};

use crate::error::{Error, Result};
use std::path::Path;

/// Read the case's CT: like [`read_volume`], with a DICOM directory's series chosen by
/// `series` (`[dicom] series`); returns notes for the report (a directory of several series
/// read without a choice, a gantry tilt resampled).
pub fn read_ct(path: &Path, series: Option<&str>) -> Result<(Volume, Vec<String>)> {
    if let Some(s) = series
        && !path.is_dir()
    {
        return Err(Error::input(
            path,
            format!(
                "[dicom] series = \"{s}\" chooses a series of a DICOM directory, but this is not a directory"
            ),
        ));
    }
    if !path.exists() {
        return Err(Error::input(path, "no such file or directory"));
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let none = |v: Volume| (v, Vec::new());
    let (vol, notes) = crate::error::guard(path, || {
        if vtkjs::is_dataset(path) || name == "index.json" {
            vtkjs::read(path).map(none)
        } else if path.is_dir() {
            dicom_io::read_chosen_series(path, series)
        } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
            nifti_io::read(path).map(none)
        } else if name.ends_with(".inv3") {
            inv3::read(path).map(none)
        } else if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
            nrrd::read(path).map(none)
        } else if dicom_io::is_dicom_file(path) {
            dicom_io::read_multiframe_file(path)
        } else {
            Err(Error::input(
                path,
                "unknown volume format (expected .nii, .nii.gz, .nrrd, .inv3, a DICOM series directory, a multi-frame DICOM file or a vtk.js dataset folder)",
            ))
        }
    })?;
    vol.check_finite(path)?;
    Ok((vol, notes))
}

/// Read any supported volume: `.nii`, `.nii.gz`, `.nrrd`, `.inv3`, a directory holding a DICOM
/// series (the largest CT series when it holds several), a multi-frame DICOM file or a vtk.js
/// dataset folder (a directory with an `index.json`, e.g. `headsq.vti/`).
pub fn read_volume(path: &Path) -> Result<Volume> {
    read_ct(path, None).map(|(v, _)| v)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn oblique() -> Volume {
        let (c, s) = (0.6f64, 0.8f64);
        Volume {
            dims: [4, 5, 6],
            spacing: [0.5, 1.0, 2.0],
            origin: [10.0, -3.0, 7.0],
            direction: [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, -1.0]],
            data: (0..120).map(|i| i as f32).collect(),
        }
    }

    #[test]
    fn axes_codes() {
        assert_eq!(
            axes_code("LPS"),
            Some([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        );
        assert_eq!(
            axes_code("lai"),
            Some([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
        );
        assert_eq!(
            axes_code("SRA"),
            Some([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        );
        for bad in ["LL S", "LLS", "LR", "LPX", "", "LPSI"] {
            assert_eq!(axes_code(bad), None, "{bad}");
        }
    }

    #[test]
    fn world_voxel_round_trip() {
        let v = oblique();
        let c = [1.3, 2.7, 4.1];
        let back = v.to_voxel(v.to_world(c));
        for a in 0..3 {
            assert!((back[a] - c[a]).abs() < 1e-12);
        }
    }

    #[test]
    fn trilinear_reproduces_linear_field() {
        // data = i + 4 j + 20 k is linear in the voxel coordinates, so trilinear is exact.
        let v = oblique();
        let c = [1.25, 3.5, 2.75];
        let got = sample_field(&v.data, v.dims, c, f32::NAN) as f64;
        assert!((got - (c[0] + 4.0 * c[1] + 20.0 * c[2])).abs() < 1e-4);
        assert!(sample_field(&v.data, v.dims, [-0.6, 0.0, 0.0], -5.0) == -5.0);
    }
}

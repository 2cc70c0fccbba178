//! Volume readers: the same CT as NIfTI and as a DICOM series inspects the same, geometry
//! round-trips through both writers, and broken files give one clear line.

use crate::cli;
use crate::common;

use cli::{assert_clean_failure, facesim};
use common::phantom_dir;
use facesim::volume::{Volume, dicom_io, nifti_io, read_volume};
use std::path::Path;

fn small_oblique() -> Volume {
    // A rotated, anisotropic volume with a linear HU ramp: every axis and sign matters.
    let (c, s) = (0.8f64, 0.6f64);
    let dims = [7, 5, 4];
    let data = (0..7 * 5 * 4)
        .map(|i| ((i * 37) % 2000) as f32 - 1000.0)
        .collect();
    Volume {
        dims,
        spacing: [0.75, 1.25, 2.5],
        origin: [-12.5, 30.0, 101.0],
        direction: [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]],
        data,
    }
}

fn assert_same(a: &Volume, b: &Volume) {
    assert_eq!(a.dims, b.dims);
    for k in 0..3 {
        assert!(
            (a.spacing[k] - b.spacing[k]).abs() < 1e-5,
            "spacing {:?} vs {:?}",
            a.spacing,
            b.spacing
        );
        assert!(
            (a.origin[k] - b.origin[k]).abs() < 1e-4,
            "origin {:?} vs {:?}",
            a.origin,
            b.origin
        );
        for r in 0..3 {
            assert!(
                (a.direction[k][r] - b.direction[k][r]).abs() < 1e-5,
                "direction {:?} vs {:?}",
                a.direction,
                b.direction
            );
        }
    }
    assert_eq!(a.data, b.data, "voxel values");
}

#[test]
fn nifti_and_dicom_writers_round_trip_an_oblique_volume() {
    let d = tempfile::tempdir().unwrap();
    let v = small_oblique();
    for name in ["v.nii", "v.nii.gz"] {
        nifti_io::write(&v, &d.path().join(name)).unwrap();
        assert_same(&v, &read_volume(&d.path().join(name)).unwrap());
    }
    dicom_io::write_series(&v, &d.path().join("series"), "7").unwrap();
    assert_same(&v, &read_volume(&d.path().join("series")).unwrap());
}

#[test]
fn phantom_nifti_and_dicom_inspect_the_same() {
    let a = facesim(&["inspect", phantom_dir().join("ct.nii.gz").to_str().unwrap()]);
    let b = facesim(&["inspect", phantom_dir().join("ct_dicom").to_str().unwrap()]);
    assert_eq!(a.code, 0, "{}", a.stderr);
    assert_eq!(b.code, 0, "{}", b.stderr);
    let ja: serde_json::Value = serde_json::from_str(&a.stdout).unwrap();
    let jb: serde_json::Value = serde_json::from_str(&b.stdout).unwrap();
    for key in [
        "dims",
        "spacing",
        "origin",
        "direction",
        "hu_min",
        "hu_max",
        "hu_mean",
    ] {
        let (x, y) = (&ja[key], &jb[key]);
        let flat = |v: &serde_json::Value| -> Vec<f64> {
            match v {
                serde_json::Value::Array(a) => a
                    .iter()
                    .flat_map(|e| match e {
                        serde_json::Value::Array(b) => {
                            b.iter().map(|x| x.as_f64().unwrap()).collect::<Vec<_>>()
                        }
                        x => vec![x.as_f64().unwrap()],
                    })
                    .collect(),
                x => vec![x.as_f64().unwrap()],
            }
        };
        for (p, q) in flat(x).iter().zip(flat(y)) {
            assert!((p - q).abs() < 1e-4, "{key}: {x} vs {y}");
        }
    }
    // Frame: the phantom is written in LPS with identity directions; NIfTI stores RAS, so this
    // also checks the sign flips of both readers.
    assert_eq!(
        ja["direction"],
        serde_json::json!([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    );
}

/// Write a small valid uncompressed NIfTI and return its bytes for patching.
fn nifti_bytes(dir: &Path) -> Vec<u8> {
    let p = dir.join("ok.nii");
    nifti_io::write(&small_oblique(), &p).unwrap();
    std::fs::read(p).unwrap()
}

fn patched(dir: &Path, name: &str, bytes: &[u8]) -> String {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn broken_nifti_files_give_one_clear_line() {
    let d = tempfile::tempdir().unwrap();
    let good = nifti_bytes(d.path());
    let set_f32 =
        |b: &mut Vec<u8>, off: usize, v: f32| b[off..off + 4].copy_from_slice(&v.to_le_bytes());
    let set_i16 =
        |b: &mut Vec<u8>, off: usize, v: i16| b[off..off + 2].copy_from_slice(&v.to_le_bytes());

    let p = patched(d.path(), "truncated.nii", &good[..good.len() - 50]);
    assert_clean_failure(&facesim(&["inspect", &p]), "truncated.nii", "truncated");

    let mut gz = Vec::new();
    {
        use std::io::Write;
        let mut e = flate2::write::GzEncoder::new(&mut gz, flate2::Compression::default());
        e.write_all(&good).unwrap();
        e.finish().unwrap();
    }
    let n = gz.len();
    gz[n / 2] ^= 0xFF;
    gz[n / 2 + 1] ^= 0xFF;
    let p = patched(d.path(), "corrupt.nii.gz", &gz);
    assert_clean_failure(&facesim(&["inspect", &p]), "corrupt.nii.gz", "");

    // sform off so pixdim is the spacing: zero, negative and NaN voxel sizes.
    for (name, v) in [
        ("zero.nii", 0.0f32),
        ("negative.nii", -1.0),
        ("nan.nii", f32::NAN),
    ] {
        let mut b = good.clone();
        set_i16(&mut b, 254, 0); // sform_code
        set_f32(&mut b, 80, v); // pixdim[1]
        let p = patched(d.path(), name, &b);
        assert_clean_failure(&facesim(&["inspect", &p]), name, "voxel size");
    }

    let mut b = good.clone();
    for k in 0..3 {
        set_i16(&mut b, 42 + 2 * k, 30000); // dim[1..3] = 30000³ voxels
    }
    let p = patched(d.path(), "bomb.nii", &b);
    assert_clean_failure(&facesim(&["inspect", &p]), "bomb.nii", "exceed");

    let mut b = good.clone();
    set_i16(&mut b, 70, 128); // datatype RGB24
    set_i16(&mut b, 72, 24);
    let p = patched(d.path(), "rgb.nii", &b);
    assert_clean_failure(&facesim(&["inspect", &p]), "rgb.nii", "datatype");

    let p = patched(d.path(), "empty.nii", b"");
    assert_clean_failure(&facesim(&["inspect", &p]), "empty.nii", "NIfTI");
    let r = facesim(&["inspect", d.path().join("missing.nii.gz").to_str().unwrap()]);
    assert_clean_failure(&r, "missing.nii.gz", "no such file");
}

/// A small DICOM series to break.
fn series(dir: &Path) -> std::path::PathBuf {
    let p = dir.join("series");
    dicom_io::write_series(&small_oblique(), &p, "9").unwrap();
    p
}

fn edit_slice(path: &Path, f: impl FnOnce(&mut dicom_object::DefaultDicomObject)) {
    let mut obj = dicom_object::open_file(path).unwrap();
    f(&mut obj);
    obj.write_to_file(path).unwrap();
}

#[test]
fn broken_dicom_series_give_one_clear_line() {
    use dicom_core::{DataElement, PrimitiveValue, VR};
    use dicom_dictionary_std::tags;
    let d = tempfile::tempdir().unwrap();

    let s = series(&d.path().join("missing"));
    std::fs::remove_file(s.join("slice0002.dcm")).unwrap();
    assert_clean_failure(
        &facesim(&["inspect", s.to_str().unwrap()]),
        "slice0003.dcm",
        "missing slice",
    );

    let s = series(&d.path().join("dup"));
    std::fs::copy(s.join("slice0002.dcm"), s.join("slice0002b.dcm")).unwrap();
    assert_clean_failure(
        &facesim(&["inspect", s.to_str().unwrap()]),
        "slice0002",
        "duplicate",
    );

    // A slice of another series in the folder: the largest series is read, and lacks it.
    let s = series(&d.path().join("mixed"));
    edit_slice(&s.join("slice0002.dcm"), |o| {
        o.put(DataElement::new(
            tags::SERIES_INSTANCE_UID,
            VR::UI,
            PrimitiveValue::from("1.2.3.4"),
        ));
    });
    assert_clean_failure(
        &facesim(&["inspect", s.to_str().unwrap()]),
        "slice0003.dcm",
        "missing slice",
    );

    let s = series(&d.path().join("sizes"));
    edit_slice(&s.join("slice0003.dcm"), |o| {
        o.put(DataElement::new(
            tags::ROWS,
            VR::US,
            PrimitiveValue::from(4u16),
        ));
    });
    assert_clean_failure(
        &facesim(&["inspect", s.to_str().unwrap()]),
        "slice0003.dcm",
        "slice size",
    );

    let s = series(&d.path().join("nospacing"));
    edit_slice(&s.join("slice0001.dcm"), |o| {
        o.remove_element(tags::PIXEL_SPACING);
    });
    assert_clean_failure(
        &facesim(&["inspect", s.to_str().unwrap()]),
        "slice0001.dcm",
        "PixelSpacing",
    );

    // A transfer syntax facesim does not decode (JPEG XL): named by UID and name.
    let s = series(&d.path().join("jpegxl"));
    edit_slice(&s.join("slice0004.dcm"), |o| {
        let m = o.meta_mut();
        m.transfer_syntax = "1.2.840.10008.1.2.4.110\0".to_string();
        m.update_information_group_length();
    });
    assert_clean_failure(
        &facesim(&["inspect", s.to_str().unwrap()]),
        "slice0004.dcm",
        "transfer syntax 1.2.840.10008.1.2.4.110 (JPEG XL Lossless) is not decoded",
    );

    let empty = d.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::write(empty.join("README"), "not dicom").unwrap();
    assert_clean_failure(
        &facesim(&["inspect", empty.to_str().unwrap()]),
        "empty",
        "no DICOM files",
    );
}

#[test]
fn inv3_errors_name_the_file() {
    let d = tempfile::tempdir().unwrap();
    let p = patched(d.path(), "broken.inv3", b"\x1f\x8b\x08\x00garbage");
    assert_clean_failure(&facesim(&["inspect", &p]), "broken.inv3", "");
}

#[test]
fn corrupt_compressed_dicom_gives_one_clear_line() {
    // RLE-compressed by dcmtk (scripts/test-setup.sh installs it), then one slice's RLE header
    // (the 64 bytes after the fragment's item header) overwritten.
    let d = tempfile::tempdir().unwrap();
    let raw = series(&d.path().join("raw"));
    let rle = d.path().join("rle");
    std::fs::create_dir_all(&rle).unwrap();
    for i in 1..=4 {
        let name = format!("slice{i:04}.dcm");
        let r = std::process::Command::new("dcmcrle")
            .arg(raw.join(&name))
            .arg(rle.join(&name))
            .output()
            .expect("dcmcrle (run scripts/test-setup.sh)");
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    assert_eq!(facesim(&["inspect", rle.to_str().unwrap()]).code, 0);
    let victim = rle.join("slice0002.dcm");
    let mut bytes = std::fs::read(&victim).unwrap();
    let at = bytes
        .windows(4)
        .rposition(|w| w == [0xFE, 0xFF, 0x00, 0xE0])
        .unwrap()
        + 8;
    bytes[at..at + 64].fill(0xA5);
    std::fs::write(&victim, &bytes).unwrap();
    assert_clean_failure(
        &facesim(&["inspect", rle.to_str().unwrap()]),
        "slice0002.dcm",
        "cannot decode pixel data, transfer syntax 1.2.840.10008.1.2.5 (RLE Lossless)",
    );
}

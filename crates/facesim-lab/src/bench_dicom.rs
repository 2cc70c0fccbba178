//! `facesim-lab bench dicom`: how long reading a CT series takes in each compressed transfer syntax
//! against the uncompressed series (docs/lab/performance.md, docs/guide/dicom.md).
//!
//! The CT (by default the real sample) is written as an uncompressed DICOM series, each file is
//! compressed with Debian's dcmtk and gdcm (scripts/test-setup.sh installs them), and every
//! series is read with `facesim::volume::read_volume` — the same path as `[ct] path` — timing the
//! best of `repeats` reads and checking the HU against the uncompressed series.

use facesim::error::{Error, Result};
use facesim::volume::{Volume, dicom_io, read_volume};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One transfer syntax's row.
#[derive(Serialize, Debug)]
pub struct Row {
    pub syntax: String,
    pub uid: String,
    pub encoder: String,
    /// Bytes of the series on disk.
    pub bytes: u64,
    /// Best of the timed reads (s).
    pub read_s: f64,
    /// Largest |HU| difference from the uncompressed series.
    pub max_abs_hu: f64,
    /// Error text when this syntax could not be written or read here.
    pub error: Option<String>,
}

#[derive(Serialize, Debug)]
pub struct Bench {
    pub ct: String,
    pub dims: [usize; 3],
    pub repeats: usize,
    pub rows: Vec<Row>,
}

/// (name, UID, encoder and its arguments) of each syntax measured.
const SYNTAXES: [(&str, &str, &str, &[&str]); 7] = [
    (
        "Explicit VR Little Endian (uncompressed)",
        "1.2.840.10008.1.2.1",
        "",
        &[],
    ),
    (
        "JPEG Lossless SV1",
        "1.2.840.10008.1.2.4.70",
        "dcmcjpeg",
        &["+e1"],
    ),
    (
        "JPEG Lossless process 14",
        "1.2.840.10008.1.2.4.57",
        "dcmcjpeg",
        &["+el"],
    ),
    ("RLE Lossless", "1.2.840.10008.1.2.5", "dcmcrle", &[]),
    (
        "JPEG 2000 lossless",
        "1.2.840.10008.1.2.4.90",
        "gdcmconv",
        &["--j2k"],
    ),
    (
        "JPEG 2000 lossy (q 80)",
        "1.2.840.10008.1.2.4.91",
        "gdcmconv",
        &["--j2k", "--lossy", "--irreversible", "-q", "80"],
    ),
    (
        "JPEG-LS lossless",
        "1.2.840.10008.1.2.4.80",
        "dcmcjpls",
        &["+el"],
    ),
];

/// Write `ct` as DICOM in every syntax under `out` and time reading each `repeats` times.
pub fn run(ct: &Path, out: &Path, repeats: usize) -> Result<Bench> {
    let vol = read_volume(ct)?;
    std::fs::create_dir_all(out).map_err(|e| Error::output(out, e))?;
    let raw = out.join("uncompressed");
    dicom_io::write_series(&vol, &raw, "90")?;
    let reference = read_volume(&raw)?;
    let mut rows = Vec::new();
    for (name, uid, tool, args) in SYNTAXES {
        let measured = if tool.is_empty() {
            Ok(raw.clone())
        } else {
            encode(&raw, &out.join(uid), tool, args)
        }
        .and_then(|dir| time_read(&dir, &reference, repeats).map(|r| (dir, r)));
        let row = match measured {
            Ok((dir, (read_s, max_abs_hu))) => Row {
                syntax: name.into(),
                uid: uid.into(),
                encoder: format!("{tool} {}", args.join(" ")).trim().to_string(),
                bytes: dir_bytes(&dir),
                read_s,
                max_abs_hu,
                error: None,
            },
            Err(e) => Row {
                syntax: name.into(),
                uid: uid.into(),
                encoder: tool.into(),
                bytes: 0,
                read_s: f64::NAN,
                max_abs_hu: f64::NAN,
                error: Some(e.to_string()),
            },
        };
        rows.push(row);
    }
    let bench = Bench {
        ct: ct.display().to_string(),
        dims: vol.dims,
        repeats,
        rows,
    };
    let json = serde_json::to_string_pretty(&bench).map_err(|e| Error::output(out, e))?;
    facesim::output::write_bytes_atomic(&out.join("bench_dicom.json"), |w| {
        w.write_all(json.as_bytes())
    })?;
    Ok(bench)
}

/// Compress every file of `src` with `tool ARGS IN OUT` into `dst`.
fn encode(src: &Path, dst: &Path, tool: &str, args: &[&str]) -> Result<PathBuf> {
    std::fs::create_dir_all(dst).map_err(|e| Error::output(dst, e))?;
    let mut names: Vec<PathBuf> = std::fs::read_dir(src)
        .map_err(|e| Error::input(src, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    names.sort();
    for f in names {
        let Some(name) = f.file_name() else { continue };
        let r = Command::new(tool)
            .args(args)
            .arg(&f)
            .arg(dst.join(name))
            .output()
            .map_err(|e| Error::config(format!("{tool}: {e} (run scripts/test-setup.sh)")))?;
        if !r.status.success() {
            return Err(Error::input(
                &f,
                format!("{tool} failed: {}", String::from_utf8_lossy(&r.stderr)),
            ));
        }
    }
    Ok(dst.to_path_buf())
}

/// Best read time of `repeats` and the largest HU difference from `reference`.
fn time_read(dir: &Path, reference: &Volume, repeats: usize) -> Result<(f64, f64)> {
    let mut best = f64::INFINITY;
    let mut max = 0.0f64;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let v = read_volume(dir)?;
        best = best.min(t.elapsed().as_secs_f64());
        if v.dims != reference.dims {
            return Err(Error::input(
                dir,
                "dimensions differ from the uncompressed series",
            ));
        }
        max = v
            .data
            .iter()
            .zip(&reference.data)
            .map(|(a, b)| (a - b).abs() as f64)
            .fold(0.0, f64::max);
    }
    Ok((best, max))
}

fn dir_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().and_then(|e| e.metadata().ok()))
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

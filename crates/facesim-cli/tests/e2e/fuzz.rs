//! Mutation fuzzing of every reader with proptest (docs/lab/reliability.md): a valid seed file is
//! damaged by random overwrites, insertions, deletions, "interesting" bytes and truncation, then
//! read. A reader may refuse the file — with one line naming it — but must never panic or hang.
//!
//! Cases per target: FACESIM_FUZZ_CASES (default 200, what CI runs). docs/lab/reliability.md records
//! the long runs (`FACESIM_FUZZ_CASES=20000 cargo test --release -p facesim-cli --test e2e fuzz:: -- --nocapture`).
//! Inputs that once crashed a reader are kept in tests/fuzz-regressions/ and replayed below.

use facesim::case::Case;
use facesim::mesh::{self, Mesh};
use facesim::volume::{self, Volume};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A reproducible runner: the same cases on every CI run; FACESIM_FUZZ_SEED (a number) explores
/// others.
fn runner() -> TestRunner {
    let seed: u64 = std::env::var("FACESIM_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    let mut bytes = [0u8; 32];
    bytes[..8].copy_from_slice(&seed.to_le_bytes());
    TestRunner::new_with_rng(
        Config {
            cases: cases(),
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &bytes),
    )
}

fn cases() -> u32 {
    std::env::var("FACESIM_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200)
}

/// (position, kind, byte): 0 overwrite, 1 insert, 2 delete, 3 an interesting value.
type Edit = (usize, u8, u8);

fn mutate(seed: &[u8], edits: &[Edit], cut: Option<usize>) -> Vec<u8> {
    let mut b = seed.to_vec();
    for &(pos, kind, byte) in edits {
        if b.is_empty() {
            b.push(byte);
            continue;
        }
        let i = pos % b.len();
        match kind {
            0 => b[i] = byte,
            1 => b.insert(i, byte),
            2 => {
                b.remove(i);
            }
            _ => b[i] = [0x00, 0xff, 0x7f, 0x80, b'-', b'9', b'n'][byte as usize % 7],
        }
    }
    if let Some(c) = cut {
        let n = b.len();
        b.truncate(c % (n + 1));
    }
    b
}

fn edits() -> impl Strategy<Value = (Vec<Edit>, Option<usize>)> {
    (
        prop::collection::vec((any::<usize>(), 0u8..4, any::<u8>()), 0..10),
        prop::option::weighted(0.15, any::<usize>()),
    )
}

/// A refusal must be one line naming the file.
fn refusal_ok<T>(name: &str, r: &facesim::Result<T>) -> std::result::Result<(), TestCaseError> {
    if let Err(e) = r {
        let m = e.to_string();
        prop_assert!(!m.contains('\n'), "multi-line error: {m}");
        prop_assert!(m.contains(name), "error does not name {name}: {m}");
        // A third-party parser panic caught by `error::guard` still counts as a finding.
        prop_assert!(!m.contains("parser gave up"), "a parser panicked: {m}");
    }
    Ok(())
}

fn gzip(b: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(b).unwrap();
    e.finish().unwrap()
}

fn small_volume() -> Volume {
    Volume {
        dims: [4, 3, 3],
        spacing: [1.0, 1.5, 2.0],
        origin: [-3.0, 2.0, 5.0],
        direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        data: (0..36).map(|i| i as f32 * 40.0 - 1000.0).collect(),
    }
}

fn tetrahedron() -> Mesh {
    Mesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [10.0, 0.0, 0.0],
            [0.0, 10.0, 0.0],
            [0.0, 0.0, 10.0],
        ],
        vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    )
}

/// Run one fuzz target: `read` gets the path of a mutated copy of `seed` named `name`.
fn fuzz(
    target: &str,
    name: &str,
    seed: Vec<u8>,
    transform: fn(Vec<u8>) -> Vec<u8>,
    read: fn(&Path) -> Result<(), TestCaseError>,
) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    let mut runner = runner();
    let t = std::time::Instant::now();
    let result = runner.run(&edits(), |(e, cut)| {
        std::fs::write(&path, transform(mutate(&seed, &e, cut))).unwrap();
        read(&path)
    });
    println!(
        "fuzz {target}: {} cases in {:.1} s",
        cases(),
        t.elapsed().as_secs_f64()
    );
    if let Err(e) = result {
        panic!("{target}: {e}");
    }
}

fn read_vol(p: &Path) -> Result<(), TestCaseError> {
    let name = p.file_name().unwrap().to_string_lossy().to_string();
    refusal_ok(&name, &volume::read_volume(p))
}

fn read_mesh(p: &Path) -> Result<(), TestCaseError> {
    let name = p.file_name().unwrap().to_string_lossy().to_string();
    refusal_ok(&name, &mesh::read_mesh(p))
}

#[test]
fn fuzz_nifti() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("seed.nii");
    volume::nifti_io::write(&small_volume(), &p).unwrap();
    let seed = std::fs::read(&p).unwrap();
    fuzz("nifti (.nii)", "ct.nii", seed.clone(), |b| b, read_vol);
    // The same damage behind a valid gzip stream reaches the parser through the decompressor.
    fuzz("nifti (.nii.gz)", "ct.nii.gz", seed, |b| gzip(&b), read_vol);
}

#[test]
fn fuzz_dicom_series() {
    let d = tempfile::tempdir().unwrap();
    let s = d.path().join("seed");
    volume::dicom_io::write_series(&small_volume(), &s, "7").unwrap();
    let mut files: Vec<PathBuf> = std::fs::read_dir(&s)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let seed = std::fs::read(&files[1]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let series = dir.path().join("series");
    std::fs::create_dir(&series).unwrap();
    for f in &files {
        std::fs::copy(f, series.join(f.file_name().unwrap())).unwrap();
    }
    let victim = series.join(files[1].file_name().unwrap());
    let mut runner = runner();
    let t = std::time::Instant::now();
    let r = runner.run(&edits(), |(e, cut)| {
        std::fs::write(&victim, mutate(&seed, &e, cut)).unwrap();
        let r = volume::read_volume(&series);
        if let Err(err) = &r {
            let m = err.to_string();
            prop_assert!(!m.contains('\n'), "{m}");
            prop_assert!(m.contains("series") || m.contains(".dcm"), "{m}");
            prop_assert!(!m.contains("parser gave up"), "a parser panicked: {m}");
        }
        Ok(())
    });
    println!(
        "fuzz dicom series: {} cases in {:.1} s",
        cases(),
        t.elapsed().as_secs_f64()
    );
    if let Err(e) = r {
        panic!("dicom: {e}");
    }
}

fn inv3_tar() -> Vec<u8> {
    let plist = br#"<?xml version="1.0" encoding="UTF-8"?>
<!DOCTYPE plist PUBLIC "-//Apple//DTD PLIST 1.0//EN" "http://www.apple.com/DTDs/PropertyList-1.0.dtd">
<plist version="1.0"><dict><key>matrix</key><dict><key>dtype</key><string>int16</string><key>filename</key><string>matrix.dat</string><key>shape</key><array><integer>3</integer><integer>3</integer><integer>4</integer></array></dict><key>spacing</key><array><real>1.0</real><real>1.5</real><real>2.0</real></array></dict></plist>"#;
    let matrix: Vec<u8> = (0..36i16)
        .flat_map(|i| (i * 40 - 1000).to_le_bytes())
        .collect();
    let mut b = tar::Builder::new(Vec::new());
    for (name, data) in [("main.plist", &plist[..]), ("matrix.dat", &matrix[..])] {
        let mut h = tar::Header::new_gnu();
        h.set_size(data.len() as u64);
        h.set_mode(0o644);
        h.set_cksum();
        b.append_data(&mut h, name, data).unwrap();
    }
    b.into_inner().unwrap()
}

#[test]
fn fuzz_inv3() {
    let seed = inv3_tar();
    // The seed itself must read (otherwise the target fuzzes nothing).
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("ok.inv3");
    std::fs::write(&p, gzip(&seed)).unwrap();
    let v = volume::read_volume(&p).unwrap();
    assert_eq!(v.dims, [4, 3, 3]);
    fuzz(
        "inv3 (tar inside)",
        "ct.inv3",
        seed.clone(),
        |b| gzip(&b),
        read_vol,
    );
    fuzz(
        "inv3 (gzip stream)",
        "ct.inv3",
        gzip(&seed),
        |b| b,
        read_vol,
    );
}

#[test]
fn fuzz_obj() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("seed.obj");
    mesh::obj::write(&tetrahedron(), &p).unwrap();
    fuzz(
        "obj",
        "face.obj",
        std::fs::read(&p).unwrap(),
        |b| b,
        read_mesh,
    );
}

#[test]
fn fuzz_ply() {
    let d = tempfile::tempdir().unwrap();
    for (enc, label) in [
        (mesh::ply::Encoding::Ascii, "ply (ascii)"),
        (mesh::ply::Encoding::BinaryLittleEndian, "ply (binary)"),
    ] {
        let p = d.path().join("seed.ply");
        let mut m = tetrahedron();
        m.colors = Some(vec![[200, 150, 120]; 4]);
        mesh::ply::write(&m, &p, enc).unwrap();
        fuzz(
            label,
            "face.ply",
            std::fs::read(&p).unwrap(),
            |b| b,
            read_mesh,
        );
    }
}

/// The tetrahedron as VTK's default XML: appended raw data, zlib-compressed, UInt32 headers.
fn appended_zlib_vtp() -> Vec<u8> {
    let m = tetrahedron();
    let block = |data: Vec<u8>| {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&data).unwrap();
        let z = z.finish().unwrap();
        let mut out = Vec::new();
        for w in [1u32, data.len() as u32, data.len() as u32, z.len() as u32] {
            out.extend(w.to_le_bytes());
        }
        out.extend(z);
        out
    };
    let points: Vec<u8> = m
        .vertices
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let con: Vec<u8> = m
        .triangles
        .iter()
        .flatten()
        .flat_map(|i| (*i as i64).to_le_bytes())
        .collect();
    let off: Vec<u8> = (1..=4i64).flat_map(|k| (3 * k).to_le_bytes()).collect();
    let (a, b, c) = (block(points), block(con), block(off));
    let mut f = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt32\" compressor=\"vtkZLibDataCompressor\">\n<PolyData>\n<Piece NumberOfPoints=\"4\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"4\">\n<Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"appended\" offset=\"0\"/></Points>\n<Polys><DataArray type=\"Int64\" Name=\"connectivity\" format=\"appended\" offset=\"{}\"/><DataArray type=\"Int64\" Name=\"offsets\" format=\"appended\" offset=\"{}\"/></Polys>\n</Piece>\n</PolyData>\n<AppendedData encoding=\"raw\">\n_",
        a.len(),
        a.len() + b.len()
    )
    .into_bytes();
    f.extend(a);
    f.extend(b);
    f.extend(c);
    f.extend(b"\n</AppendedData>\n</VTKFile>\n");
    f
}

#[test]
fn fuzz_model_files() {
    // The formats a region surface or a skin from another program comes in (docs/guide/slicer.md).
    let d = tempfile::tempdir().unwrap();
    let m = tetrahedron();
    let read_model = |p: &Path| -> Result<(), TestCaseError> {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        refusal_ok(&name, &mesh::model_file::read_model(p))
    };
    let mut seeds: Vec<(&str, &str, Vec<u8>)> = Vec::new();
    let p = d.path().join("seed.stl");
    mesh::stl::write(&m, &p, "SPACE=LPS").unwrap();
    seeds.push(("stl (binary)", "segment.stl", std::fs::read(&p).unwrap()));
    let p = d.path().join("seed.vtk");
    mesh::vtk::write_legacy(&m, &[], &p).unwrap();
    seeds.push(("legacy vtk", "segment.vtk", std::fs::read(&p).unwrap()));
    let p = d.path().join("seed.vtp");
    mesh::vtp::write_vtp(&m, &[], &p).unwrap();
    seeds.push(("vtp (ascii)", "segment.vtp", std::fs::read(&p).unwrap()));
    seeds.push(("vtp (appended zlib)", "segment.vtp", appended_zlib_vtp()));
    for (label, name, seed) in seeds {
        // Each seed is a valid model, so the damage is what is refused.
        let p = d.path().join(name);
        std::fs::write(&p, &seed).unwrap();
        let back = mesh::model_file::read_model(&p).unwrap_or_else(|e| panic!("{label}: {e}"));
        assert_eq!(back.triangles.len(), m.triangles.len(), "{label}");
        fuzz(label, name, seed, |b| b, read_model);
    }
}

#[test]
fn fuzz_case_toml() {
    let seed = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/phantom/case.toml"),
    )
    .unwrap();
    fuzz(
        "case.toml",
        "case.toml",
        seed,
        |b| b,
        |p| refusal_ok("case.toml", &Case::load(p).map(|_| ())),
    );
}

/// Inputs that once broke a reader (or the damage its fuzzer makes most), replayed every time:
/// each must be refused with one line naming it, never a caught panic. A missing corpus, or
/// one without a file for each reader, fails (tests/fuzz-regressions/README.md).
#[test]
fn fuzz_regressions_stay_fixed() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz-regressions");
    let rd = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: the regression corpus is missing ({e})", dir.display()));
    let mut replayed = std::collections::BTreeMap::<&str, usize>::new();
    for e in rd.flatten() {
        let p = e.path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        if name.ends_with(".md") {
            continue;
        }
        let (reader, r): (&str, facesim::Result<()>) =
            if name.ends_with(".obj") || name.ends_with(".ply") {
                ("mesh", mesh::read_mesh(&p).map(|_| ()))
            } else if name.ends_with(".toml") {
                ("case.toml", Case::load(&p).map(|_| ()))
            } else {
                ("volume", volume::read_volume(&p).map(|_| ()))
            };
        *replayed.entry(reader).or_default() += 1;
        let m = match r {
            Err(e) => e.to_string(),
            Ok(()) => panic!("{name}: read without complaint, but it is a broken input"),
        };
        assert!(!m.contains('\n') && m.contains(&name), "{name}: {m}");
        assert!(
            !m.contains("parser gave up"),
            "{name} still panics inside: {m}"
        );
    }
    for reader in ["mesh", "case.toml", "volume"] {
        assert!(
            replayed.contains_key(reader),
            "{}: no regression file for the {reader} reader",
            dir.display()
        );
    }
}

/// Found by `fuzz_nifti`: a .nii.gz whose voxel data ends early made the nifti crate panic in
/// `into_ndarray` (128 of 5000 mutated .nii.gz cases). Now refused by facesim's own check.
#[test]
fn nifti_gz_with_short_voxel_data_is_refused_not_caught() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("seed.nii");
    volume::nifti_io::write(&small_volume(), &p).unwrap();
    let mut b = std::fs::read(&p).unwrap();
    b.truncate(b.len() - 20);
    let gz = d.path().join("short.nii.gz");
    std::fs::write(&gz, gzip(&b)).unwrap();
    let e = volume::read_volume(&gz).unwrap_err().to_string();
    assert!(e.contains("short.nii.gz") && e.contains("truncated"), "{e}");
    assert!(!e.contains("parser gave up"), "{e}");
}

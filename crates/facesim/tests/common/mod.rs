//! Shared test fixtures (also used by crates/facesim-cli and crates/facesim-lab tests): one
//! phantom case per test binary, the real CT, snapshots and grids.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A new directory under target/tmp (`CARGO_TARGET_TMPDIR`) that outlives the test, so a failing
/// run's outputs can be inspected; `cargo clean` removes it.
pub fn kept_dir(prefix: &str) -> PathBuf {
    tempfile::Builder::new()
        .prefix(prefix)
        .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
        .unwrap()
        .keep()
}

/// A new output directory for one facesim unit (a run, re-plan, sweep, validation, …): `out`
/// inside a fresh [`kept_dir`], not yet made. The output library keeps a unit's temporaries and
/// lock file in the output's parent and clears there what it takes for a dead run's leftovers;
/// with a parent of its own, a unit never meets another test's, however many tests (and test
/// commands) run at once. Never point a unit at a [`kept_dir`] itself: its parent is
/// target/tmp, which every test shares.
pub fn out_dir(prefix: &str) -> PathBuf {
    kept_dir(prefix).join("out")
}

/// A run's report.json.
pub fn report_json(o: &facesim::commands::Outcome) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(o.out_dir.join("report.json")).unwrap()).unwrap()
}

/// face_band.ply's `mean`, `p05`, `p95` columns.
pub fn band_columns(dir: &Path) -> [Vec<f64>; 3] {
    let m = facesim::mesh::ply::read(&dir.join("face_band.ply")).unwrap();
    ["mean", "p05", "p95"].map(|k| m.column(k).unwrap().to_vec())
}

/// The Python of the tests' venv, target/slicer-venv (scripts/test-setup.sh makes it with the
/// fixture makers and parsers the tests call: ctk-cli, scikit-image, highdicom, ...).
pub fn venv_python() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/slicer-venv/bin/python");
    assert!(
        p.is_file(),
        "{} missing: run scripts/test-setup.sh (it makes the venv)",
        p.display()
    );
    p
}

/// Run the fixture script `crates/facesim/tests/python/NAME` in the venv with `args`; it must
/// succeed (else the test fails with its output). Returns what it printed.
pub fn run_python_script(name: &str, args: &[&std::ffi::OsStr]) -> String {
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../facesim/tests/python")
        .join(name);
    let r = std::process::Command::new(venv_python())
        .arg(&script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", script.display()));
    let out = String::from_utf8_lossy(&r.stdout).into_owned();
    assert!(
        r.status.success(),
        "{name} {args:?}: {out}{}",
        String::from_utf8_lossy(&r.stderr)
    );
    out
}

/// A phantom case (1.5 mm voxels), written once per test binary.
pub fn phantom_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = kept_dir("facesim-phantom");
        facesim_validate::phantom::write_case(
            &d,
            &facesim_validate::phantom::PhantomOptions::default(),
        )
        .unwrap();
        d
    })
}

/// The phantom's mandible below the occlusal plane (LPS mm): the segment its sample case moves.
pub const PHANTOM_MANDIBLE: facesim::case::Region = facesim::case::Region::Box {
    min: [-70.0, -75.0, -125.0],
    max: [70.0, -1.5, -26.5],
};

/// The phantom of [`phantom_dir`] built in memory with one `mandible` segment (`region` moved by
/// `translate` and `rotate_deg` about (0, −40, −60) mm) on the volumetric model with coarse
/// elements (6 mm at the skin, 12 mm deep, 15 mm margin): quick, and what the tests check holds
/// on any mesh.
pub fn coarse_tet_phantom(
    name: &str,
    region: facesim::case::Region,
    translate: [f64; 3],
    rotate_deg: [f64; 3],
) -> facesim::case::Case {
    use facesim::case::{Case, CtSection, Osteotomy, PathSection, SolveModel};
    let mut c = Case {
        name: Some(name.into()),
        ct: CtSection::new(phantom_dir().join("ct.nii.gz")),
        skin: Some(PathSection {
            path: phantom_dir().join("face.ply"),
        }),
        osteotomy: vec![Osteotomy {
            name: "mandible".into(),
            region,
            translate,
            rotate_deg,
            pivot: [0.0, -40.0, -60.0],
        }],
        ..Case::default()
    };
    c.solve.model = SolveModel::Tet;
    c.tet.skin_size_mm = 6.0;
    c.tet.deep_size_mm = 12.0;
    c.tet.margin_mm = 15.0;
    c
}

/// The real CT, fetched by data-samples/fetch-real.sh (the README's test command runs it first).
pub fn real_ct() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/real/Cranium.inv3");
    assert!(
        p.is_file(),
        "{} missing: run data-samples/fetch-real.sh (the README's test command does)",
        p.display()
    );
    p
}

/// The second real sample: VTK's headsq as vtk.js ships it (a dataset folder), fetched by
/// data-samples/fetch-real-mandible.sh (scripts/test-setup.sh runs it).
pub fn real_mandible_ct() -> PathBuf {
    let p =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/real-mandible/headsq.vti");
    assert!(
        p.join("index.json").is_file(),
        "{} missing: run data-samples/fetch-real-mandible.sh (the README's test command does)",
        p.display()
    );
    p
}

/// A real 3D face scan with 68 landmarks placed by people (menpo3d's james.obj and
/// james.ljson), fetched by data-samples/fetch-face-scan.sh (scripts/test-setup.sh runs it).
pub fn face_scan() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/face-scan");
    assert!(
        p.join("james.obj").is_file() && p.join("james.ljson").is_file(),
        "{} missing: run data-samples/fetch-face-scan.sh (the README's test command does)",
        p.display()
    );
    p
}

/// Every file below `dir` with its bytes (to prove nothing changed).
pub fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut v = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                v.extend(snapshot(&p));
            } else {
                v.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    v.sort();
    v
}

/// Triangles of an n×n grid of (n+1)² vertices numbered row by row, two per cell,
/// counter-clockwise in the grid's own (i, j) orientation.
pub fn grid_triangles(n: usize) -> Vec<[u32; 3]> {
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut t = Vec::with_capacity(2 * n * n);
    for j in 0..n {
        for i in 0..n {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    t
}

/// The whole-CT iso-surface at `level` (in the volume's own values) by scikit-image's marching
/// cubes (tests/python/isosurface.py, "a skin from another program"), written to `out` (.stl,
/// or an indexed .obj).
pub fn isosurface(ct: &facesim::volume::Volume, level: f64, out: &Path) {
    let dir = out.parent().unwrap();
    let raw = dir.join("ct.f32");
    let bytes: Vec<u8> = ct.data.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&raw, bytes).unwrap();
    let meta = serde_json::json!({
        "dims": ct.dims, "spacing": ct.spacing, "origin": ct.origin, "direction": ct.direction,
    });
    let meta_path = dir.join("ct.json");
    std::fs::write(&meta_path, meta.to_string()).unwrap();
    let level = level.to_string();
    run_python_script(
        "isosurface.py",
        &[
            raw.as_os_str(),
            meta_path.as_os_str(),
            level.as_ref(),
            out.as_os_str(),
        ],
    );
    std::fs::remove_file(raw).unwrap();
}

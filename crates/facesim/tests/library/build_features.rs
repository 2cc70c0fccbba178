//! One build of the library for the run, the tests and the Python wheel (docs/lab/performance.md
//! "One build for the run, the tests and the wheel"). Cargo builds a dependency once per set of
//! features; if the tests' dev-dependencies turn on a feature of a package the library also uses,
//! `cargo test` builds that package again and every crate above it — the library, validate,
//! charts, the command line — and the wheel's `maturin build` then builds them a third time.
//! Measured when it happened: the test build 4 min 45 s instead of 2 min 23 s, the wheel 1 min
//! 53 s instead of 15 s. `cargo tree` lists each package's resolved features; the lists must agree
//! on every package they share.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

/// `cargo tree --locked -e EDGES ARGS` as package ("name vX.Y.Z") → its feature sets (one, unless
/// the graph builds the package twice).
fn features(edges: &str, args: &[&str]) -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let o = Command::new(cargo)
        .current_dir(root)
        .args([
            "tree", "--locked", "--prefix", "none", "-f", "{p}|{f}", "-e",
        ])
        .arg(edges)
        .args(args)
        .output()
        .expect("cargo tree");
    assert!(
        o.status.success(),
        "cargo tree -e {edges} {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in String::from_utf8_lossy(&o.stdout).lines() {
        let line = line.trim_end_matches(" (*)");
        if let Some((package, features)) = line.split_once('|') {
            // A workspace member's line names its path: the version is the key.
            let package = package.split(" (").next().unwrap().to_string();
            out.entry(package).or_default().insert(features.to_string());
        }
    }
    assert!(out.len() > 50, "cargo tree listed {} packages", out.len());
    out
}

/// The packages both lists hold whose features differ.
fn differing(
    a: &BTreeMap<String, BTreeSet<String>>,
    b: &BTreeMap<String, BTreeSet<String>>,
    skip: impl Fn(&str) -> bool,
) -> Vec<String> {
    a.iter()
        .filter(|(p, _)| !skip(p))
        .filter_map(|(p, fa)| {
            let fb = b.get(p)?;
            (fa != fb).then(|| format!("{p}: {fa:?} against {fb:?}"))
        })
        .collect()
}

#[test]
fn the_tests_and_the_wheel_build_the_library_with_the_runs_features() {
    let run = features("normal", &["--workspace"]);
    let tests = features("normal,dev", &["--workspace"]);
    let diff = differing(&run, &tests, |_| false);
    assert!(
        diff.is_empty(),
        "the tests' build resolves other features than the run's, so `cargo test` rebuilds the \
         library and every crate above it (make the library ask for the feature itself):\n{}",
        diff.join("\n")
    );
    // The wheel adds pyo3's extension-module feature (python/pyproject.toml): pyo3 alone differs.
    let wheel = features(
        "normal",
        &["-p", "facesim-py", "--features", "pyo3/extension-module"],
    );
    let diff = differing(&wheel, &run, |p| p.starts_with("pyo3"));
    assert!(
        diff.is_empty(),
        "the wheel's build resolves other features than the run's, so maturin rebuilds the \
         library:\n{}",
        diff.join("\n")
    );
}

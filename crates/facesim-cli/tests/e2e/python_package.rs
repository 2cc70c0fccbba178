//! The Python package (docs/guide/python.md): the wheel built by maturin from python/pyproject.toml
//! (into target/wheels, on the workspace's target dir, so a warm build only compiles the module
//! crate), installed into the venv scripts/test-setup.sh makes (target/slicer-venv), and tested
//! by pytest (python/tests) against this build's `facesim` binary: run, replan and sweep equal
//! the command line's files, bad input raises FacesimError, the interpreter lock is released.
//!
//! The wheel directory, the package installed in the venv and pytest's kept files are one per
//! checkout, shared by every copy of the test command: the whole test holds a file lock, so a
//! second copy waits instead of removing the first one's wheel, reinstalling the package under
//! its pytest or emptying its files.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn venv_tool(name: &str) -> PathBuf {
    let p = root().join("target/slicer-venv/bin").join(name);
    assert!(
        p.is_file(),
        "{} missing: run scripts/test-setup.sh (it installs maturin, pytest and numpy into the venv)",
        p.display()
    );
    p
}

fn run(cmd: &mut Command, what: &str) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{what} failed:\n{text}");
    text
}

#[test]
fn the_installed_wheel_equals_the_command_line() {
    let python = venv_tool("python");
    let lock_path = Path::new(env!("CARGO_TARGET_TMPDIR")).join("python-package.lock");
    let lock = std::fs::File::create(&lock_path)
        .unwrap_or_else(|e| panic!("{}: {e}", lock_path.display()));
    // Released when `lock` is dropped at the end of the test, or by the kernel if the process
    // dies.
    lock.lock()
        .unwrap_or_else(|e| panic!("{}: {e}", lock_path.display()));
    let wheels = root().join("target/wheels");
    // Only this build's wheel in the directory pip installs from.
    if let Ok(entries) = std::fs::read_dir(&wheels) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with("facesim-") && name.ends_with(".whl") {
                std::fs::remove_file(e.path()).unwrap();
            }
        }
    }
    run(
        Command::new(venv_tool("maturin"))
            .current_dir(root().join("python"))
            .args(["build", "--release", "--quiet", "--interpreter"])
            .arg(&python)
            .arg("--out")
            .arg(&wheels),
        "maturin build",
    );
    let wheel = std::fs::read_dir(&wheels)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            let n = p.file_name().unwrap().to_string_lossy().to_string();
            n.starts_with("facesim-") && n.ends_with(".whl")
        })
        .expect("maturin wrote no facesim wheel");
    assert!(
        wheel.to_string_lossy().contains("-abi3-"),
        "{} is not an abi3 wheel",
        wheel.display()
    );
    run(
        Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--force-reinstall",
                "--no-deps",
            ])
            .arg(&wheel),
        "pip install",
    );
    // Kept for inspection under target/tmp (pytest empties --basetemp first).
    let basetemp = root().join("target/tmp/python-package");
    let report = run(
        // The pytest script, not `python -m pytest` from python/: that would put python/ on
        // sys.path and import the source package (no native module) instead of the wheel.
        Command::new(venv_tool("pytest"))
            .current_dir(root())
            .args(["-q", "-p", "no:cacheprovider", "python/tests", "--basetemp"])
            .arg(&basetemp)
            .env("FACESIM_BIN", env!("CARGO_BIN_EXE_facesim")),
        "pytest python/tests",
    );
    eprintln!("{report}");
}

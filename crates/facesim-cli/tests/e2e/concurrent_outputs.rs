//! Runs beside each other lose no output (docs/reference/case.md "Outputs"): eight `facesim replan`
//! processes at a time, each into its own folder of one shared parent, round after round; every
//! output must hold exactly the files of a replan run alone, byte for byte, and every process
//! must succeed. The output unit's protocol itself is tested with pauses injected at each of
//! its steps in `crates/facesim/src/output.rs`; this test runs the real command.
#![cfg(unix)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Processes at a time.
const AT_ONCE: usize = 8;

/// Rounds of them: 25 in the suite (200 outputs); `FACESIM_STRESS_ROUNDS=100` gives the 800 of
/// docs/reference/case.md's measurement.
fn rounds() -> usize {
    std::env::var("FACESIM_STRESS_ROUNDS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(25)
}

fn facesim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_facesim"))
}

/// Every file of an output directory by name (an absent directory is empty).
fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return BTreeMap::new();
    };
    entries
        .map(|e| e.unwrap().path())
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap_or_default())
        })
        .collect()
}

fn replan(run: &Path, plan: &Path, out: &Path) -> std::process::Output {
    facesim()
        .args(["--threads", "1", "replan"])
        .args([run, plan])
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

#[test]
fn eight_replans_at_a_time_into_one_parent_give_complete_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws");
    let run = tmp.path().join("run");
    let status = facesim()
        .arg("run")
        .arg(&sample)
        .arg("--out")
        .arg(&run)
        .status()
        .unwrap();
    assert!(status.success(), "the run failed");
    let plan = tmp.path().join("plan.toml");
    std::fs::write(&plan, "[[surgery]]\nkind = \"bsso\"\nadvance_mm = 3.0\n").unwrap();
    let alone = tmp.path().join("alone");
    assert!(replan(&run, &plan, &alone).status.success());
    let want = contents(&alone);
    assert!(
        want.contains_key("report.json") && want.len() > 3,
        "{:?}",
        want.keys()
    );

    let parent: PathBuf = tmp.path().join("outs");
    std::fs::create_dir(&parent).unwrap();
    let mut bad = Vec::new();
    for round in 0..rounds() {
        let outs: Vec<PathBuf> = (0..AT_ONCE)
            .map(|i| parent.join(format!("r{round}_{i}")))
            .collect();
        let children: Vec<_> = outs
            .iter()
            .map(|out| {
                facesim()
                    .args(["--threads", "1", "replan"])
                    .args([&run, &plan])
                    .arg("--out")
                    .arg(out)
                    .stdout(std::process::Stdio::null())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for (child, out) in children.into_iter().zip(&outs) {
            let o = child.wait_with_output().unwrap();
            let got = contents(out);
            if !o.status.success() || got != want {
                bad.push(format!(
                    "{}: exit {:?}, {} of {} files equal: {}",
                    out.display(),
                    o.status.code(),
                    want.iter().filter(|(k, v)| got.get(*k) == Some(v)).count(),
                    want.len(),
                    String::from_utf8_lossy(&o.stderr).trim()
                ));
            }
        }
        // The previous round's outputs stay as neighbours of the next; older ones go, to keep
        // the disk small.
        if round > 0 {
            for i in 0..AT_ONCE {
                let _ = std::fs::remove_dir_all(parent.join(format!("r{}_{i}", round - 1)));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "{} of {} outputs incomplete: {:?}",
        bad.len(),
        AT_ONCE * rounds(),
        &bad[..bad.len().min(5)]
    );
    // Nothing of the units is left beside the outputs.
    let left: Vec<String> = std::fs::read_dir(&parent)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

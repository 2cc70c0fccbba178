//! The cohort workflow end to end (docs/guide/cohort.md): `facesim phantom-cohort` writes shaped
//! jaws phantoms whose written CT shows the analytic chin; `workflow/Snakefile` (Snakemake from
//! the venv scripts/test-setup.sh makes) plans the runs (`-n`), then runs two cases × two
//! variants plus a broken case on two cores; cohort.csv is checked row by row against each
//! run's report.json and displacement.csv, the broken case's rows carry facesim's one-line
//! error, and the charts exist. Also `run --set` and the phantom's refusals.

use crate::common;

use facesim_validate::phantom_jaws::Shape;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_facesim"))
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn snakemake() -> PathBuf {
    let p = root().join("target/slicer-venv/bin/snakemake");
    assert!(
        p.is_file(),
        "{} missing: run scripts/test-setup.sh (it installs snakemake into the venv)",
        p.display()
    );
    p
}

/// A new, empty directory under target/tmp (kept for inspection) named after `name`: a fixed
/// name, emptied first, would be emptied under a second copy of the test command still
/// running in it.
fn tmp(name: &str) -> PathBuf {
    common::kept_dir(&format!("facesim-{name}"))
}

fn run_ok(cmd: &mut Command) -> String {
    let o = cmd.output().unwrap();
    assert!(
        o.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr)
}

/// A CSV file as rows of column → value (no quoted commas in facesim's tables except the
/// status column, which is last-resort parsed by the csv writer's quoting).
fn read_csv(path: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = split_csv(lines.next().unwrap());
    lines
        .map(|l| header.iter().cloned().zip(split_csv(l)).collect())
        .collect()
}

/// One CSV line, honouring double quotes.
fn split_csv(line: &str) -> Vec<String> {
    let (mut out, mut cur, mut quoted) = (Vec::new(), String::new(), false);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if quoted && chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            '"' => quoted = !quoted,
            ',' if !quoted => out.push(std::mem::take(&mut cur)),
            _ => cur.push(c),
        }
    }
    out.push(cur);
    out
}

fn num(row: &BTreeMap<String, String>, col: &str) -> f64 {
    row[col]
        .parse()
        .unwrap_or_else(|_| panic!("{col} = {:?}", row[col]))
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The written CT of a shaped phantom shows its pogonion: along the y line through the
/// landmark's (x, z) voxel column, the soft-tissue→bone edge lies at the landmark's y.
fn check_chin_in_written_ct(case: &Path, shape: &Shape) {
    let v = facesim::volume::read_volume(&case.join("ct.nii.gz")).unwrap();
    let pog = shape.landmark("pogonion").unwrap();
    let idx = |a: usize, c: f64| ((c - v.origin[a]) / v.spacing[a]).round() as usize;
    let (i, k) = (idx(0, pog[0]), idx(2, pog[2]));
    let [nx, ny, _] = v.dims;
    let at = |j: usize| v.data[i + nx * (j + ny * k)] as f64;
    let y = |j: usize| v.origin[1] + j as f64 * v.spacing[1];
    // From the front: through the skin into the soft tissue, then the first rise above the
    // soft/bone midpoint (noise 8 HU: far below the 555 HU step).
    let level = 0.5 * (45.0 + 600.0);
    let skin = (0..ny).find(|&j| at(j) > -500.0).unwrap();
    let j = (skin + 1..ny).find(|&j| at(j) >= level).unwrap();
    let edge = y(j - 1) + (level - at(j - 1)) / (at(j) - at(j - 1)) * v.spacing[1];
    // The column sits up to half a voxel off the landmark in x and z, where the chin's face
    // is slanted: a 1 mm tolerance at 2 mm voxels.
    assert!(
        (edge - pog[1]).abs() < 1.0,
        "{}: bone edge {edge:.2} vs pogonion {:.2}",
        case.display(),
        pog[1]
    );
}

#[test]
fn cohort_workflow_runs_cases_variants_and_a_broken_case() {
    let dir = tmp("cohort-workflow");
    let cases = dir.join("cases");
    run_ok(
        Command::new(exe())
            .args(["phantom-cohort"])
            .arg(&cases)
            .args([
                "--cases",
                "2",
                "--seed",
                "3",
                "--spacing",
                "2",
                "--slice",
                "2",
            ]),
    );
    // The parameters table and each case's shape.
    let params = read_csv(&cases.join("phantoms.csv"));
    assert_eq!(params.len(), 2);
    let shapes: Vec<Shape> = params
        .iter()
        .map(|r| {
            Shape::from_values(
                [
                    "scale",
                    "soft_mm",
                    "mandible_mm",
                    "chin_mm",
                    "asymmetry_mm",
                    "vertical_mm",
                ]
                .map(|c| num(r, c)),
            )
        })
        .collect();
    assert_ne!(shapes[0], shapes[1], "two distinct patients");
    for (r, s) in params.iter().zip(&shapes) {
        let case = cases.join(&r["case"]);
        check_chin_in_written_ct(&case, s);
        let toml = std::fs::read_to_string(case.join("phantom.toml")).unwrap();
        assert!(
            toml.contains(&format!("soft_mm = {:?}", s.soft_mm)),
            "{toml}"
        );
    }
    // A broken case: its CT is missing.
    let broken = cases.join("broken");
    std::fs::create_dir_all(&broken).unwrap();
    std::fs::write(
        broken.join("case.toml"),
        "name = \"broken\"\n[ct]\npath = \"missing.nii.gz\"\n",
    )
    .unwrap();
    // Two variants through `run --set`: the C1 model and the paper's, both a few seconds.
    let config = dir.join("variants.yaml");
    std::fs::write(
        &config,
        "variants:\n  c1: {\"solve.model\": \"equilibrium\"}\n  koch: {\"solve.model\": \"koch1996\", \"surface.alpha\": 0.02}\nthreads: 1\n",
    )
    .unwrap();
    let out = dir.join("out");
    let snake = |extra: &[&str]| {
        let mut c = Command::new(snakemake());
        c.current_dir(&dir)
            .arg("-s")
            .arg(root().join("workflow/Snakefile"))
            .args(extra)
            .arg("--configfile")
            .arg(&config)
            .arg("--config")
            .arg(format!("cohort={}", cases.display()))
            .arg(format!("out={}", out.display()))
            .arg(format!("facesim={}", exe().display()));
        c
    };
    // Dry run: six runs (3 cases × 1 plan × 2 variants), the table and the charts; nothing
    // written.
    let plan = run_ok(&mut snake(&["-n", "--cores", "2"]));
    let count = |rule: &str| {
        plan.lines()
            .find_map(|l| {
                let mut w = l.split_whitespace();
                (w.next() == Some(rule)).then(|| w.next().and_then(|n| n.parse::<usize>().ok()))
            })
            .flatten()
    };
    assert_eq!(count("run"), Some(6), "{plan}");
    assert_eq!(count("gather"), Some(1), "{plan}");
    assert!(!out.exists(), "a dry run wrote {}", out.display());
    // The same workflow through the Slurm profile (dry run; crates/facesim-cli/tests/e2e/cluster.rs runs it on a real
    // cluster): each run asks for what `facesim estimate` predicts for its plan and variant
    // (its peak memory plus the job's own 300 MB, rounded up to 100 MB; four times its time, at
    // least 5 minutes), the profile's partition reaches the jobs.
    let profile = root().join("workflow/profiles/slurm");
    let slurm = run_ok(snake(&["-n"]).arg("--workflow-profile").arg(&profile));
    let estimated = Command::new(exe())
        .args(["--threads", "1", "estimate"])
        .arg(cases.join(&params[0]["case"]).join("case.toml"))
        .args(["--set", "solve.model=\"equilibrium\""])
        .output()
        .unwrap();
    assert!(estimated.status.success());
    let estimated = String::from_utf8_lossy(&estimated.stdout);
    let e: serde_json::Value = serde_json::from_str(&estimated).unwrap();
    let mem = ((e["peak_mem_mb"].as_f64().unwrap() + 300.0) / 100.0).ceil() * 100.0;
    let minutes = (4.0 * e["wall_s"].as_f64().unwrap() / 60.0).ceil().max(5.0);
    assert!(
        slurm.contains(&format!("mem_mb={mem},"))
            && slurm.contains(&format!("runtime={minutes},"))
            && slurm.contains("slurm_partition=CHANGE-ME"),
        "{estimated}\n{slurm}"
    );
    // The broken case cannot be estimated, nor its CT sized: the fixed fallback.
    assert!(slurm.contains("mem_mb=4000,"), "{slurm}");
    assert!(!out.exists(), "a dry run wrote {}", out.display());
    // The real run on two cores.
    let t = std::time::Instant::now();
    run_ok(&mut snake(&["--cores", "2"]));
    println!(
        "cohort of 6 runs on 2 cores: {:.1} s",
        t.elapsed().as_secs_f64()
    );

    let rows = read_csv(&out.join("cohort.csv"));
    for variant in ["c1", "koch"] {
        // The broken case: one row per variant, region face, facesim's one-line error.
        let b: Vec<_> = rows
            .iter()
            .filter(|r| r["case"] == "broken" && r["variant"] == variant)
            .collect();
        assert_eq!(b.len(), 1, "{b:?}");
        assert_eq!(b[0]["region"], "face");
        assert!(
            b[0]["status"].starts_with("facesim: ") && b[0]["status"].contains("missing.nii.gz"),
            "{:?}",
            b[0]["status"]
        );
        assert!(b[0]["mean_mm"].is_empty());
        for r in &params {
            let case = &r["case"];
            let run = out.join("runs").join(case).join("case").join(variant);
            let report = json(&run.join("out/report.json"));
            let mine: Vec<_> = rows
                .iter()
                .filter(|x| &x["case"] == case && x["variant"] == variant)
                .collect();
            // The variant's override took effect.
            let model = if variant == "c1" {
                "equilibrium"
            } else {
                "koch1996"
            };
            assert_eq!(report["parameters"]["solve"]["model"], model);
            // Whole face: against displacement.csv read here.
            let disp = std::fs::read_to_string(run.join("out/displacement.csv")).unwrap();
            let mut d: Vec<f64> = disp
                .lines()
                .skip(1)
                .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
                .collect();
            d.sort_by(f64::total_cmp);
            let face = mine.iter().find(|x| x["region"] == "face").unwrap();
            assert_eq!(face["status"], "ok");
            assert_eq!(face["model"], model);
            assert_eq!(num(face, "vertices") as usize, d.len());
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            let p90 = d[(0.9 * (d.len() - 1) as f64).round() as usize];
            assert!((num(face, "mean_mm") - mean).abs() < 2e-6);
            assert!((num(face, "p90_mm") - p90).abs() < 2e-6);
            assert!((num(face, "max_mm") - d[d.len() - 1]).abs() < 2e-6);
            let dm = report["displacement"]["mean"].as_f64().unwrap();
            assert!((num(face, "mean_mm") - dm).abs() < 1e-5, "report mean {dm}");
            assert!(num(face, "seconds") >= report["timings"]["total"].as_f64().unwrap());
            assert!(num(face, "peak_mem_mb") > 10.0);
            let ratio = report["soft_hard_ratios"]["Pog'/Pog"]["ratio"]
                .as_f64()
                .unwrap();
            assert!((num(face, "ratio_Pog_Pog") - ratio).abs() < 1e-4);
            // Every region report.json lists, with its figures.
            let regions = report["regions"].as_object().unwrap();
            assert_eq!(mine.len(), 1 + regions.len());
            for (name, s) in regions {
                let row = mine.iter().find(|x| &x["region"] == name).unwrap();
                for (col, key) in [("mean_mm", "mean"), ("p90_mm", "p90"), ("max_mm", "max")] {
                    let want = s[key].as_f64().unwrap();
                    assert!((num(row, col) - want).abs() < 2e-6, "{case} {name} {col}");
                }
                assert_eq!(num(row, "vertices") as u64, s["vertices"].as_u64().unwrap());
            }
        }
    }
    for chart in ["region_mean_mm", "soft_hard_ratios", "seconds"] {
        let png = std::fs::read(out.join("charts").join(format!("{chart}.png"))).unwrap();
        assert!(png.starts_with(b"\x89PNG") && png.len() > 5_000, "{chart}");
    }
}

#[test]
fn run_set_overrides_case_keys_and_refuses_bad_ones() {
    let dir = tmp("cohort-set");
    // A broken --set: one line, naming the flag, before any work.
    let o = Command::new(exe())
        .args(["run", "nowhere", "--set", "solve.model"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--set solve.model"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    // A value the case refuses is named like a case.toml error.
    let case = dir.join("capsule");
    run_ok(Command::new(exe()).args(["phantom"]).arg(&case).args([
        "--spacing",
        "3",
        "--slice",
        "3",
    ]));
    let o = Command::new(exe())
        .arg("run")
        .arg(&case)
        .args(["--set", "solve.model=nonsense"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("nonsense"), "{err}");
    assert!(!case.join("out").exists(), "a refused run wrote outputs");
}

#[test]
fn phantom_refuses_shapes_out_of_range_or_without_jaws() {
    let dir = tmp("cohort-phantom-refusals");
    let o = Command::new(exe())
        .arg("phantom")
        .arg(dir.join("a"))
        .args(["--anatomy", "jaws", "--soft-mm", "9"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("soft_mm"), "{err}");
    assert!(
        !dir.join("a").exists(),
        "nothing written for a refused shape"
    );
    let o = Command::new(exe())
        .arg("phantom")
        .arg(dir.join("v"))
        .args(["--anatomy", "jaws", "--vertical-mm", "11"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("vertical_mm"), "{err}");
    assert!(
        !dir.join("v").exists(),
        "nothing written for a refused shape"
    );
    let o = Command::new(exe())
        .arg("phantom")
        .arg(dir.join("b"))
        .args(["--scale", "1.1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--anatomy jaws"),
        "{err}"
    );
}

/// A Slurm attempt whose facesim the cgroup's out-of-memory killer ended while run_case.py
/// lived on (the killer takes the largest process, not the whole job step) counts as
/// OUT_OF_MEMORY, so the retry gets more memory: run_case.py's own decision functions, with a
/// fake cgroup tree and a fake `scontrol` that calls the job FAILED.
#[test]
fn an_attempt_whose_facesim_the_oom_killer_ended_is_out_of_memory() {
    let dir = tmp("cohort-oom-attempt");
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let scontrol = bin.join("scontrol");
    std::fs::write(
        &scontrol,
        "#!/bin/sh\necho \"JobId=$4 JobState=FAILED Reason=NonZeroExitCode ExitCode=1:0 \
         RunTime=00:00:03 TimeLimit=00:05:00 MinMemoryNode=300M\"\n",
    )
    .unwrap();
    std::fs::write(bin.join("sacct"), "#!/bin/sh\nexit 1\n").unwrap();
    for f in ["scontrol", "sacct"] {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(bin.join(f), std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    let script = r#"
import json, os, sys
sys.path.insert(0, sys.argv[1])
import run_case as rc
d = sys.argv[2]
job = os.path.join(d, "job_7"); step = os.path.join(job, "step_0")
os.makedirs(step, exist_ok=True)
def counts(jn, sn):
    with open(os.path.join(job, "memory.oom_control"), "w") as f:
        f.write(f"oom_kill_disable 0\nunder_oom 0\noom_kill {jn}\n")
    with open(os.path.join(step, "memory.events"), "w") as f:
        f.write(f"low 0\nhigh 0\nmax 4\noom 1\noom_kill {sn}\n")
    return rc.oom_kill_counts([step, job, os.path.join(d, "none")])
before = counts(0, 0)
assert before == {step: 0, job: 0}, before
after = counts(1, 0)
why = rc.oom_killed(before, after, -9)
assert why and "oom-kill event" in why and "job_7: oom_kill 0 -> 1" in why, why
# No counter grew: a SIGKILL from elsewhere (scancel) is not a memory limit; nor is an exit.
assert rc.oom_killed(before, before, -9) is None
assert rc.oom_killed(before, after, 1) is None
# The attempt's record decides where Slurm only says FAILED.
jobs = os.path.join(d, "v.jobs")
rc.write_json(rc.attempt_record_path(jobs, 1), {"slurm_job": "7", "oom_kill": why})
end = rc.attempt_end(jobs, 1, "7")
assert end[0] == "OUT_OF_MEMORY" and "oom-kill" in end[1] and "FAILED" in end[1], end
rc.write_json(rc.attempt_record_path(jobs, 2), {"slurm_job": "8"})
assert rc.attempt_end(jobs, 2, "8")[0] == "FAILED"
# The status a retry records for the killed attempt.
ea = rc.earlier_attempts(jobs, 2)[0]
assert ea["slurm_state"] == "OUT_OF_MEMORY" and ea["status"].startswith("slurm: job 7 OUT_OF_MEMORY ("), ea
# This process's own memory cgroups: each one a directory, at most the job's under Slurm.
for c in rc.memory_cgroup_dirs():
    assert os.path.isdir(c), c
print("ok")
"#;
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = run_ok(
        Command::new("python3")
            .arg("-c")
            .arg(script)
            .arg(root().join("workflow/scripts"))
            .arg(&dir)
            .env("PATH", path),
    );
    assert!(out.trim().ends_with("ok"), "{out}");
}

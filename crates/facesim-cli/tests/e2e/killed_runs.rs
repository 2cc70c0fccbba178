//! A run's outputs are one unit (docs/reference/case.md "Outputs"): `facesim run` killed with SIGKILL at
//! random points of its write stage leaves the previous complete run or the new complete run
//! (or, off Linux, which swaps the two in one step, no output), never a mix, and the next run
//! removes the temporaries the killed one left.
#![cfg(unix)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The two plans the runs alternate between (the mandible's advance, mm).
const PLANS: [f64; 2] = [-6.0, -3.0];

/// A case on the bundled phantom moving the mandible by `advance`; the C1 equilibrium model,
/// the quickest, so that many runs fit the test's time.
fn write_case(dir: &Path, advance: f64) {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/phantom");
    let sample = sample.canonicalize().unwrap();
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(
        dir.join("case.toml"),
        format!(
            "name = \"killed\"\n[ct]\npath = \"{}\"\n[skin]\npath = \"{}\"\n[solve]\nmodel = \"equilibrium\"\n\
             [surface]\nalpha = 0.01\nbeta = 0.02\nmovable = {{ sphere = {{ center = [0.0, -60.0, -45.0], radius = 70.0 }} }}\n\
             [[osteotomy]]\nname = \"mandible\"\nregion = {{ box = {{ min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] }} }}\n\
             translate = [0.0, {advance}, 0.0]\n",
            sample.join("ct.nii.gz").display(),
            sample.join("face.ply").display(),
        ),
    )
    .unwrap();
}

fn start(case: &Path, out: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_facesim"))
        .args([
            "run",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// The names of the unit temporaries (`output::RunDir`) in `parent`.
fn temporaries(parent: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(parent)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".facesim-run-"))
        .collect();
    v.sort();
    v
}

/// Wait until `child`'s unit directory's `new/` holds an entry (its write stage began) —
/// or, for a build that writes into the output directory itself, a file's temporary appears
/// there — false if the child exited first.
fn wait_for_write_stage(child: &mut Child, parent: &Path, out: &Path) -> bool {
    let tag = format!(".facesim-run-{}-", child.id());
    let file_tmp = format!(".facesim-tmp-{}-", child.id());
    loop {
        if child.try_wait().unwrap().is_some() {
            return false;
        }
        let writing = temporaries(parent).iter().any(|n| {
            n.contains(&tag)
                && std::fs::read_dir(parent.join(n).join("new"))
                    .is_ok_and(|mut d| d.next().is_some())
        }) || std::fs::read_dir(out).is_ok_and(|d| {
            d.filter_map(|e| e.ok())
                .any(|e| e.file_name().to_string_lossy().starts_with(&file_tmp))
        });
        if writing {
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Every file of an output directory by name.
fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            assert!(e.file_type().unwrap().is_file(), "{name}: not a file");
            (name, std::fs::read(e.path()).unwrap())
        })
        .collect()
}

/// The plan report.json says the run used (the mandible's y move).
fn report_plan(report: &[u8]) -> f64 {
    let r: serde_json::Value = serde_json::from_slice(report).expect("report.json parses");
    r["parameters"]["osteotomy"][0]["translate"][1]
        .as_f64()
        .expect("report.json names the plan")
}

/// Which of the complete reference runs `dir` is: the same file set, every file but the
/// timed ones (report.json, report.html) byte-identical, and report.json of the same plan
/// with the same displacement. Panics on a mix.
fn which_run(dir: &Path, refs: &[BTreeMap<String, Vec<u8>>]) -> usize {
    let got = contents(dir);
    let plan = report_plan(got.get("report.json").expect("report.json present"));
    let i = PLANS
        .iter()
        .position(|p| *p == plan)
        .unwrap_or_else(|| panic!("report.json's plan {plan} is neither run's"));
    let want = &refs[i];
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>(),
        "the file set is not the complete run's"
    );
    for (name, bytes) in want {
        match name.as_str() {
            "report.json" => {
                let disp = |b: &[u8]| {
                    serde_json::from_slice::<serde_json::Value>(b).unwrap()["displacement"].clone()
                };
                assert_eq!(disp(&got[name]), disp(bytes), "report.json of another run");
            }
            "report.html" => assert!(
                got[name].ends_with(b"</html>\n") || got[name].ends_with(b"</html>"),
                "report.html incomplete"
            ),
            _ => assert!(got[name] == *bytes, "{name} is not plan {plan}'s"),
        }
    }
    i
}

/// A small xorshift generator: the kill points, reproducible from the printed seed.
struct Rng(u64);
impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn a_killed_run_leaves_one_complete_run_or_none_and_the_next_run_cleans_up() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: Vec<PathBuf> = PLANS
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let d = tmp.path().join(format!("case{i}"));
            write_case(&d, *p);
            d
        })
        .collect();
    let parent = tmp.path().join("outs");
    std::fs::create_dir(&parent).unwrap();
    let out = parent.join("out");

    // The complete runs, and how long their write stage takes.
    let mut refs = Vec::new();
    let mut write_s: f64 = 0.0;
    for case in &cases {
        let mut child = start(case, &out);
        assert!(
            wait_for_write_stage(&mut child, &parent, &out),
            "no write stage seen"
        );
        let t = Instant::now();
        assert!(child.wait().unwrap().success(), "the reference run failed");
        write_s = write_s.max(t.elapsed().as_secs_f64());
        refs.push(contents(&out));
        assert!(
            temporaries(&parent).is_empty(),
            "a complete run left temporaries"
        );
    }
    let seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
        | 1;
    eprintln!("write stage {write_s:.3} s; kill points from seed {seed}");
    let mut rng = Rng(seed);

    // Kill runs at random points from the start of the write stage to a little past its end: at
    // least 6, then as many as 20 s allow, at most 16.
    let began = Instant::now();
    let mut state = Some(1); // the output holds the run of PLANS[1]
    let (mut kills, mut stale_left, mut outcomes) = (0, 0, [0usize; 3]);
    while kills < 16 && (kills < 6 || began.elapsed() < Duration::from_secs(20)) {
        let next = state.map_or(0, |s| 1 - s);
        let mut child = start(&cases[next], &out);
        if !wait_for_write_stage(&mut child, &parent, &out) {
            panic!("the run ended before writing: {:?}", child.wait());
        }
        // The killed run before this one left its temporaries; this run removed them.
        let tag = format!(".facesim-run-{}-", child.id());
        let others: Vec<String> = temporaries(&parent)
            .into_iter()
            .filter(|n| !n.contains(&tag))
            .collect();
        assert!(
            others.is_empty(),
            "stale temporaries not removed: {others:?}"
        );
        std::thread::sleep(Duration::from_secs_f64(rng.unit() * 1.3 * write_s));
        child.kill().unwrap(); // SIGKILL
        child.wait().unwrap();
        kills += 1;
        if !temporaries(&parent).is_empty() {
            stale_left += 1;
        }
        let now = out.exists().then(|| which_run(&out, &refs));
        assert!(
            now.is_none() || now == state || now == Some(next),
            "the output is neither the previous run nor the new one"
        );
        // Linux swaps the two directories in one step: an output, once there, is never absent.
        if cfg!(target_os = "linux") {
            assert!(
                now.is_some() || state.is_none(),
                "a kill left no output where there was one"
            );
        }
        outcomes[match now {
            None => 0,
            Some(s) if Some(s) == state => 1,
            Some(_) => 2,
        }] += 1;
        state = now;
    }
    eprintln!(
        "{kills} kills: output absent {}, previous run {}, new run {}; {stale_left} left temporaries",
        outcomes[0], outcomes[1], outcomes[2]
    );
    assert!(stale_left > 0, "no kill hit the write stage");

    // A run to the end removes what the last kill left and writes its complete output.
    let next = state.map_or(0, |s| 1 - s);
    let mut child = start(&cases[next], &out);
    assert!(child.wait().unwrap().success());
    assert_eq!(which_run(&out, &refs), next);
    assert!(
        temporaries(&parent).is_empty(),
        "{:?} left",
        temporaries(&parent)
    );
}

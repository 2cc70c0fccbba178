//! The cohort workflow on a real Slurm (docs/guide/cohort.md, "A real Slurm on one machine").
//! scripts/slurm-cluster.sh starts a throw-away one-node cluster — munged, slurmctld, slurmd of
//! Debian's slurm-wlm 22.05, run as root, configuration, munge key and state in a temporary
//! directory — and workflow/Snakefile runs through snakemake-executor-plugin-slurm with the
//! repository's profile (workflow/profiles/slurm) on a phantom cohort: four jaws phantoms × two
//! plans, a broken case, a fifth phantom whose jobs get 300 MB (`case_resources`), and a sixth
//! (`slow`: 4096 uncertainty samples, minutes of work) whose job gets one minute.
//!
//! Checked, in order:
//! - the Snakefile refuses a facesim binary outside `shared_storage` with one line, before any
//!   job reaches Slurm;
//! - a job cancelled with scancel while it runs is resubmitted by the profile's retry and its
//!   run gives the same figures;
//! - Snakemake interrupted (SIGINT, as Ctrl-C) once the retry is submitted and three runs are
//!   done: the re-run redoes exactly the runs without a result (Snakemake's own bookkeeping),
//!   leaving the finished ones untouched;
//! - the fifth phantom's runs go over their memory (cgroup limit: slurmstepd's oom-kill, the
//!   step OUT_OF_MEMORY) and its rows and failures.csv say so with Slurm's words; the broken
//!   case is reported, not fatal;
//! - the slow case's job goes over its one-minute limit: Slurm ends it TIMEOUT and its row and
//!   failures.csv carry Slurm's state and reason;
//! - every other row of cohort.csv equals the local (`--cores 2`) run's: same rows, same
//!   figures to 1e-9, same provenance (facesim version and hash, case hash, parameters hash);
//! - job groups (`--groups run=cases --group-components cases=3 --cores 1`, beside the re-run):
//!   five runs go to Slurm as two jobs (the plugin's log, Slurm's job states and each result's
//!   SLURM_JOB_ID), which ran them and gave the local run's rows.
//!
//! Needs root and the packages scripts/test-setup.sh installs; without them it fails with one
//! line saying what is missing. The cluster is stopped by PID and its directory removed when the
//! test ends, and by a watchdog if the test process dies.

use std::collections::{BTreeMap, BTreeSet};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_facesim"))
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

fn snakemake() -> PathBuf {
    root().join("target/slicer-venv/bin/snakemake")
}

/// The Python environment running Snakemake, where it really is (target/slicer-venv may be a
/// link to another checkout's): it must be on shared storage too.
fn venv() -> PathBuf {
    snakemake()
        .canonicalize()
        .unwrap()
        .parent()
        .and_then(Path::parent)
        .unwrap()
        .to_path_buf()
}

/// What the test needs, or one line saying what is missing.
fn preconditions() {
    let uid = Command::new("id").arg("-u").output().unwrap();
    assert!(
        String::from_utf8_lossy(&uid.stdout).trim() == "0",
        "the Slurm test needs root (it runs munged, slurmctld and slurmd): run cargo test as root"
    );
    for tool in [
        "slurmctld",
        "slurmd",
        "munged",
        "sbatch",
        "squeue",
        "scancel",
        "scontrol",
    ] {
        let found = Command::new("sh")
            .args(["-c", &format!("command -v {tool}")])
            .output()
            .unwrap()
            .status
            .success();
        assert!(
            found,
            "the Slurm test needs {tool}: run scripts/test-setup.sh (apt: slurmctld slurmd slurm-client munge)"
        );
    }
    assert!(
        snakemake().is_file(),
        "the Slurm test needs {}: run scripts/test-setup.sh",
        snakemake().display()
    );
}

/// The one-node cluster; stopped (jobs cancelled, daemons by PID, directory removed) when
/// dropped.
struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
    /// What `slurm-cluster.sh start` wrote to stderr (nothing, when all is well).
    start_stderr: String,
}

impl Cluster {
    fn start() -> Cluster {
        let dir = std::env::temp_dir().join(format!("facesim-slurm-{}", std::process::id()));
        let o = Command::new(root().join("scripts/slurm-cluster.sh"))
            .arg("start")
            .arg(&dir)
            .arg(std::process::id().to_string())
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "scripts/slurm-cluster.sh start failed: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let conf = dir.join("slurm.conf");
        let start_stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        Cluster {
            dir,
            conf,
            start_stderr,
        }
    }

    fn stop(&self) -> Output {
        Command::new(root().join("scripts/slurm-cluster.sh"))
            .arg("stop")
            .arg(&self.dir)
            .output()
            .unwrap()
    }

    fn cmd(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        self.env(&mut c);
        c
    }

    /// What `slurm-cluster.sh start` prints for a shell: SLURM_CONF, and DIR/bin (its srun,
    /// which puts back the SLURM_CONF the executor plugin's job step strips) first on PATH.
    fn env<'c>(&self, c: &'c mut Command) -> &'c mut Command {
        let path = std::env::var_os("PATH").unwrap_or_default();
        let path = std::env::join_paths(
            std::iter::once(self.dir.join("bin")).chain(std::env::split_paths(&path)),
        )
        .unwrap();
        c.env("SLURM_CONF", &self.conf).env("PATH", path)
    }

    fn out(&self, program: &str, args: &[&str]) -> String {
        let o = self.cmd(program).args(args).output().unwrap();
        String::from_utf8_lossy(&o.stdout).into_owned()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// A child process killed (by its PID) and reaped if the test ends before it does.
struct Reaped(Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn run_ok(cmd: &mut Command) -> String {
    let o = cmd.output().unwrap();
    let text =
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{cmd:?} failed:\n{text}");
    text
}

fn read_csv(path: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = split_csv(lines.next().unwrap());
    lines
        .map(|l| header.iter().cloned().zip(split_csv(l)).collect())
        .collect()
}

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

/// The count Snakemake's "Job stats" table gives a rule (None when the rule is not listed).
fn job_count(log: &str, rule: &str) -> Option<usize> {
    log.lines().find_map(|l| {
        let mut w = l.split_whitespace();
        if w.next() == Some(rule) {
            w.next().and_then(|n| n.parse().ok())
        } else {
            None
        }
    })
}

fn wait_for(what: &str, limit: Duration, mut done: impl FnMut() -> bool) {
    let t = Instant::now();
    while !done() {
        assert!(t.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The runs' outcomes (the rows of each run's last attempt; an earlier attempt of a retried run
/// has a row of its own) keyed by (case, plan, variant, region).
fn keyed(rows: &[BTreeMap<String, String>]) -> BTreeMap<String, &BTreeMap<String, String>> {
    rows.iter()
        .filter(|r| r["attempt"] == r["attempts"])
        .map(|r| {
            (
                format!(
                    "{}/{}/{}/{}",
                    r["case"], r["plan"], r["variant"], r["region"]
                ),
                r,
            )
        })
        .collect()
}

/// Columns that differ between two runs of the same figures: timings, memory, the job and
/// which attempt gave them and with what request (a retried run's has grown; a group job's is
/// its members' together).
const VARYING: [&str; 8] = [
    "seconds",
    "facesim_seconds",
    "peak_mem_mb",
    "slurm_job",
    "attempt",
    "attempts",
    "requested_mem_mb",
    "requested_runtime_min",
];

/// The rows of `rows` whose case is in `cases` (and plan in `plans`) equal the local run's rows
/// of those: same keys and columns, every figure within 1e-9, everything else (provenance)
/// identical, save VARYING. Returns how many rows were compared.
fn same_as_local(
    local: &[BTreeMap<String, String>],
    rows: &[BTreeMap<String, String>],
    cases: &[&str],
    plans: &[&str],
) -> usize {
    let pick = |rows| {
        keyed(rows)
            .into_iter()
            .filter(|(_, r)| {
                cases.contains(&r["case"].as_str()) && plans.contains(&r["plan"].as_str())
            })
            .collect::<BTreeMap<_, _>>()
    };
    let (lk, sk) = (pick(local), pick(rows));
    assert_eq!(
        lk.keys().collect::<Vec<_>>(),
        sk.keys().collect::<Vec<_>>(),
        "rows differ"
    );
    for (k, l) in &lk {
        let s = sk[k];
        assert_eq!(
            l.keys().collect::<Vec<_>>(),
            s.keys().collect::<Vec<_>>(),
            "columns differ"
        );
        for (col, lv) in l.iter() {
            if VARYING.contains(&col.as_str()) {
                continue;
            }
            let sv = &s[col];
            match (lv.parse::<f64>(), sv.parse::<f64>()) {
                (Ok(a), Ok(b)) => assert!((a - b).abs() <= 1e-9, "{k} {col}: {lv} vs {sv}"),
                _ => assert_eq!(lv, sv, "{k} {col}"),
            }
        }
    }
    lk.len()
}

/// The Slurm job ids the executor plugin's log says it submitted, in order, with the line.
fn submitted_jobs(log: &Path) -> Vec<(String, String)> {
    std::fs::read_to_string(log)
        .unwrap_or_default()
        .lines()
        .filter(|l| l.contains("submitted with SLURM jobid"))
        .map(|l| {
            let id = l
                .split("SLURM jobid ")
                .nth(1)
                .unwrap()
                .split_whitespace()
                .next()
                .unwrap()
                .to_string();
            (id, l.to_string())
        })
        .collect()
}

/// The outputs Snakemake has marked incomplete in the working directory `wd`: a record per
/// output under `.snakemake/incomplete`, named by the output's path in URL-safe base64, split
/// into directories of at most NAME_MAX characters, each but the last prefixed with `@`.
fn incomplete_outputs(wd: &Path) -> BTreeSet<PathBuf> {
    let script = [
        "import base64, os, sys",
        "root = sys.argv[1]",
        "for d, _, names in os.walk(root):",
        "    for n in names:",
        "        parts = os.path.relpath(os.path.join(d, n), root).split(os.sep)",
        "        if parts != ['migration_underway']:",
        "            b64 = ''.join(p.removeprefix('@') for p in parts)",
        "            print(base64.urlsafe_b64decode(b64).decode())",
    ]
    .join("\n");
    let listed = run_ok(
        Command::new(venv().join("bin/python3"))
            .arg("-c")
            .arg(&script)
            .arg(wd.join(".snakemake/incomplete")),
    );
    listed.lines().map(|l| wd.join(l)).collect()
}

fn cohort_on_a_real_slurm_with_faults() {
    preconditions();
    let t0 = Instant::now();
    let work = root().join("target/tmp/slurm-cohort");
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).unwrap();
    let cases = work.join("cases");
    run_ok(Command::new(exe()).arg("phantom-cohort").arg(&cases).args([
        "--cases",
        "5",
        "--seed",
        "3",
        "--spacing",
        "2",
        "--slice",
        "2",
    ]));
    let broken = cases.join("broken");
    std::fs::create_dir_all(&broken).unwrap();
    std::fs::write(
        broken.join("case.toml"),
        "name = \"broken\"\n[ct]\npath = \"missing.nii.gz\"\n",
    )
    .unwrap();
    // Two plans, the C1 model (a few seconds a run), one thread a job; case005's jobs get
    // 300 MB, less than facesim and Snakemake's job step need together: its retries get twice
    // that per OUT_OF_MEMORY (retry_growth 2). The slow case gets a minute, which is also the
    // time maximum: its retry cannot grow and records Slurm's TIMEOUT instead.
    let config = work.join("config.yaml");
    std::fs::write(
        &config,
        format!(
            "plans: [\"case.toml\", \"case_setback.toml\"]\n\
             variants:\n  c1: {{\"solve.model\": \"equilibrium\"}}\n\
             threads: 1\n\
             case_resources:\n  case005: {{mem_mb: 300}}\n  slow: {{runtime_min: 1}}\n\
             retry_growth: 2\n\
             max_runtime_min: 1\n\
             shared_storage: [\"{}\", \"{}\"]\n",
            root().display(),
            venv().display()
        ),
    )
    .unwrap();
    // Slurm's runs: the local run's and the slow case's.
    let runs_total = 5 * 2 + 1 + 1;
    let snake = |cases: &Path, out: &Path, extra: &[&str]| {
        let mut c = Command::new(snakemake());
        c.current_dir(&work)
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

    // The local run, the reference.
    let local = work.join("local");
    run_ok(&mut snake(&cases, &local, &["--cores", "2"]));
    let t_local = t0.elapsed();

    let cluster = Cluster::start();
    let slurm_args = [
        "--workflow-profile",
        root().join("workflow/profiles/slurm").to_str().unwrap(),
        // This cluster's partition, no account (no accounting database); status from
        // squeue — slurmctld keeps finished jobs for MinJobAge = 600 s — polled from 2 s on.
        "--default-resources",
        "slurm_partition=cohort",
        "mem_mb=1000",
        "runtime=10",
        "--slurm-status-command",
        "squeue",
        "--slurm-init-seconds-before-status-checks",
        "2",
    ]
    .map(String::from);
    let slurm_args: Vec<&str> = slurm_args.iter().map(String::as_str).collect();
    let out = work.join("slurm");
    let slurm_snake = |extra: &[&str]| {
        let mut c = snake(&cases, &out, &slurm_args);
        cluster.env(c.args(extra));
        c
    };
    let our_jobs = || cluster.out("squeue", &["--states=all", "--noheader", "--format=%i"]);

    // A binary outside shared_storage: one line, nothing submitted.
    let elsewhere = work.join("elsewhere.yaml");
    std::fs::write(&elsewhere, "shared_storage: [\"/nonexistent-share\"]\n").unwrap();
    let o = slurm_snake(&[])
        .arg("--configfile")
        .arg(&elsewhere)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let last = err.trim().lines().last().unwrap_or("");
    assert!(!o.status.success(), "{err}");
    assert!(
        last.starts_with("workflow/Snakefile: facesim ") && last.contains("shared_storage"),
        "{err}"
    );
    assert_eq!(our_jobs().trim(), "", "a job was submitted");
    assert!(!out.join("runs").exists());

    // The Slurm run, interrupted: case002's first plan is cancelled while it runs (the retry
    // resubmits it), then Snakemake gets SIGINT once three runs have their result. One other
    // job is held in the queue (`scontrol hold`) as soon as it is pending, so the run cannot
    // finish before the SIGINT however fast the others are (the node has the machine's CPUs:
    // with 2, 11 one-core jobs leave most pending for tens of seconds).
    let result = |case: &str, plan: &str| {
        out.join("runs")
            .join(case)
            .join(plan)
            .join("c1/result.json")
    };
    let log1 = std::fs::File::create(work.join("slurm-1.log")).unwrap();
    let mut interrupted = slurm_snake(&[]);
    // A job started in the background (`cmd &`, nohup, some CI runners) has SIGINT ignored,
    // the child inherits that, and Python then installs no KeyboardInterrupt handler: the
    // SIGINT below would be lost and Snakemake run to the end. Its default is restored here.
    // SAFETY: signal() is async-signal-safe, as a pre_exec closure must be.
    unsafe {
        interrupted.pre_exec(|| {
            libc::signal(libc::SIGINT, libc::SIG_DFL);
            Ok(())
        });
    }
    let mut first: Child = interrupted
        .stdout(log1.try_clone().unwrap())
        .stderr(log1)
        .stdin(Stdio::null())
        .spawn()
        .unwrap();
    let mut cancelled = String::new();
    let mut held = String::new();
    wait_for(
        "case002's job running and another job held pending (a node with more CPUs than jobs holds none)",
        Duration::from_secs(240),
        || {
            // Job name is Snakemake's run id; the comment names the rule and wildcards.
            let q = cluster.out(
                "squeue",
                &[
                    "--noheader",
                    "--states=PENDING,RUNNING",
                    "--format=%i %T %k",
                ],
            );
            for l in q.lines() {
                let mut f = l.split_whitespace();
                let (id, state) = (f.next().unwrap(), f.next().unwrap());
                let case002 = l.contains("case002_case_c1");
                if case002 && state == "RUNNING" && cancelled.is_empty() {
                    cancelled = id.to_string();
                }
                // A hold fails on a job that has just started, or arrives as it starts: the next
                // pending one is tried.
                if !case002
                    && state == "PENDING"
                    && held.is_empty()
                    && cluster
                        .cmd("scontrol")
                        .args(["hold", id])
                        .output()
                        .unwrap()
                        .status
                        .success()
                {
                    // A job the scheduler was starting as the hold came in takes the hold's
                    // reason and runs anyway: only a job still pending after it counts.
                    let after = cluster.out(
                        "squeue",
                        &["--noheader", "--states=all", "-j", id, "--format=%T %r"],
                    );
                    if after.trim().starts_with("PENDING") && after.contains("Held") {
                        held = id.to_string();
                    }
                }
            }
            !cancelled.is_empty() && !held.is_empty()
        },
    );
    // Let facesim start inside the job (the job step starts Snakemake first), then cancel.
    std::thread::sleep(Duration::from_secs(3));
    run_ok(cluster.cmd("scancel").arg(&cancelled));
    let count_results = || {
        std::fs::read_dir(out.join("runs"))
            .map(|d| {
                d.flatten()
                    .map(|c| {
                        std::fs::read_dir(c.path())
                            .unwrap()
                            .flatten()
                            .filter(|p| p.path().join("c1/result.json").is_file())
                            .count()
                    })
                    .sum::<usize>()
            })
            .unwrap_or(0)
    };
    // The retry is submitted (a second job for case002/case in the plugin's log) and three runs
    // are done: interrupt.
    let log1_path = work.join("slurm-1.log");
    let case002_jobs = || {
        submitted_jobs(&log1_path)
            .into_iter()
            .filter(|(_, l)| l.contains("/case002_case_c1/"))
            .map(|(id, _)| id)
            .collect::<Vec<String>>()
    };
    wait_for(
        "the cancelled run's retry and three results",
        Duration::from_secs(300),
        || case002_jobs().len() >= 2 && count_results() >= 3,
    );
    let submitted = case002_jobs();
    assert_eq!(submitted[0], cancelled, "{submitted:?}");
    assert_ne!(submitted[1], cancelled, "{submitted:?}");
    let held_state = cluster.out(
        "squeue",
        &["--noheader", "--states=all", "-j", &held, "--format=%T %r"],
    );
    assert!(
        held_state.trim().starts_with("PENDING") && held_state.contains("Held"),
        "job {held}: {held_state}"
    );
    let _ = Command::new("kill")
        .args(["-INT", &first.id().to_string()])
        .status();
    let status = first.wait().unwrap();
    assert!(!status.success(), "the interrupted Snakemake exited 0");
    // Snakemake cancels its running jobs on SIGINT. A cancelled job is COMPLETING until its
    // processes are gone, and may still write its result then: wait for that too, so that what
    // is counted as done below is what the re-run finds.
    wait_for(
        "no job pending, running or completing",
        Duration::from_secs(60),
        || {
            cluster
                .out(
                    "squeue",
                    &[
                        "--noheader",
                        "--states=PENDING,RUNNING,COMPLETING",
                        "--format=%i",
                    ],
                )
                .trim()
                .is_empty()
        },
    );
    let state = cluster.out(
        "squeue",
        &[
            "--noheader",
            "--states=all",
            "-j",
            &cancelled,
            "--format=%T",
        ],
    );
    assert_eq!(state.trim(), "CANCELLED");

    // The slow case, added now so that it runs once, in the re-run (not in the local run nor in
    // the interrupted one, where it would only take a core): case001's CT and face with 4096
    // uncertainty samples (each a re-solve; minutes of work) under a one-minute limit. Slurm's
    // smallest limit is a minute and slurmctld checks limits every 30 s: its job ends TIMEOUT
    // 60–90 s after it starts.
    let slow = cases.join("slow");
    std::fs::create_dir_all(&slow).unwrap();
    for f in std::fs::read_dir(cases.join("case001")).unwrap().flatten() {
        let name = f.file_name().into_string().unwrap();
        if !name.ends_with(".toml") {
            std::fs::copy(f.path(), slow.join(&name)).unwrap();
        }
    }
    let plan = std::fs::read_to_string(cases.join("case001/case.toml")).unwrap();
    assert!(!plan.contains("[uncertainty]"), "{plan}");
    std::fs::write(
        slow.join("case.toml"),
        format!("{plan}\n[uncertainty]\nsamples = 4096\nseed = 1\n"),
    )
    .unwrap();

    // What was done before the interruption, and when. A job cancelled by the SIGINT may have
    // written its result before its processes ended, after Snakemake last asked for its state:
    // Snakemake keeps that output marked incomplete, and the profile's `rerun-incomplete` redoes
    // it. Done is a result without that mark.
    let incomplete = incomplete_outputs(&work);
    let mut present = 0;
    let mut done = BTreeMap::new();
    for case in [
        "case001", "case002", "case003", "case004", "case005", "broken", "slow",
    ] {
        for plan in ["case", "case_setback"] {
            let r = result(case, plan);
            if r.is_file() {
                present += 1;
                if !incomplete.contains(&r) {
                    done.insert(
                        r.clone(),
                        std::fs::metadata(&r).unwrap().modified().unwrap(),
                    );
                }
            }
        }
    }
    assert!(
        present >= 3 && !done.is_empty() && done.len() < runs_total,
        "{present} results, done: {done:?}, incomplete: {incomplete:?}"
    );

    // Job groups, beside the re-run (the slow case's minute leaves a core free): case001–
    // case004 and the broken case (config `cases`), plan `case`: 5 runs, with `--groups
    // run=cases --group-components cases=3 --cores 1` go to Slurm as two jobs of one core each
    // (`--cores` is a group job's width: its runs one after the other inside it, memory their
    // peak, time their sum); its own working directory, so the two Snakemakes share no lock.
    let same = ["case001", "case002", "case003", "case004", "broken"];
    let t_grouped = Instant::now();
    let grouped = work.join("slurm-grouped");
    let grouped_wd = work.join("grouped-wd");
    std::fs::create_dir_all(&grouped_wd).unwrap();
    let grouped_log = std::fs::File::create(work.join("slurm-grouped.log")).unwrap();
    let mut grouped_child = Reaped(
        cluster
            .env(&mut snake(&cases, &grouped, &slurm_args))
            .current_dir(&grouped_wd)
            .arg("plans=[\"case.toml\"]")
            .arg(format!("cases=[{}]", same.join(", ")))
            .args([
                "--groups",
                "run=cases",
                "--group-components",
                "cases=3",
                "--cores",
                "1",
            ])
            .stdout(grouped_log.try_clone().unwrap())
            .stderr(grouped_log)
            .stdin(Stdio::null())
            .spawn()
            .unwrap(),
    );

    // The re-run: exactly the missing runs, then the table.
    let rerun = run_ok(&mut slurm_snake(&[]));
    assert_eq!(
        job_count(&rerun, "run"),
        Some(runs_total - done.len()),
        "re-run after the interruption:\n{rerun}"
    );
    for (r, t) in &done {
        assert_eq!(
            std::fs::metadata(r).unwrap().modified().unwrap(),
            *t,
            "{} redone",
            r.display()
        );
    }

    // case005: over its 300 MB on both plans; each retry asks for twice the memory until one
    // is enough. The cgroup's OOM killer ends either the whole job step (Slurm: OUT_OF_MEMORY)
    // or only its largest process, facesim (run_case.py sees the oom-kill event and fails the
    // job); both are an attempt over its memory. Every attempt has its row: the killed ones with Slurm's state and words, their
    // request and peak, and a row in failures.csv; the last one the local run's figures (below).
    let rows = read_csv(&out.join("cohort.csv"));
    let failures = read_csv(&out.join("failures.csv"));
    let mut case005_attempts = 0;
    for plan in ["case", "case_setback"] {
        let r: Vec<_> = rows
            .iter()
            .filter(|r| r["case"] == "case005" && r["plan"] == plan && r["region"] == "face")
            .collect();
        let last = r.last().unwrap();
        let attempts: usize = last["attempts"].parse().unwrap();
        assert!(attempts >= 2 && r.len() == attempts, "{r:#?}");
        case005_attempts += attempts;
        for (i, a) in r.iter().enumerate() {
            assert_eq!(a["attempt"], (i + 1).to_string(), "{a:?}");
            assert_eq!(a["attempts"], last["attempts"], "{a:?}");
            assert_eq!(a["requested_mem_mb"], (300 << i).to_string(), "{a:?}");
        }
        for a in &r[..attempts - 1] {
            assert!(
                a["status"].starts_with(&format!("slurm: job {} OUT_OF_MEMORY (", a["slurm_job"]))
                    && (a["status"].contains("oom-kill") || a["status"].contains("OutOfMemory")),
                "{a:?}"
            );
            assert_eq!(a["slurm_state"], "OUT_OF_MEMORY", "{a:?}");
            assert!(a["mean_mm"].is_empty());
            // facesim's peak when the cgroup's OOM killer ended it (the job step's Snakemake
            // holds much of the 300 MB, so it may be small), recorded by run_case.py.
            let peak: f64 = a["peak_mem_mb"].parse().unwrap();
            assert!(peak > 0.0, "{a:?}");
            let f = failures
                .iter()
                .find(|f| {
                    f["case"] == "case005" && f["plan"] == plan && f["attempt"] == a["attempt"]
                })
                .unwrap();
            for col in [
                "status",
                "slurm_job",
                "requested_mem_mb",
                "requested_runtime_min",
                "peak_mem_mb",
                "slurm_state",
            ] {
                assert_eq!(f[col], a[col], "{col}");
            }
        }
        assert_eq!(last["status"], "ok", "{last:?}");
        assert_eq!(last["slurm_state"], "", "{last:?}");
    }
    // The broken case: facesim's one-line error, not fatal.
    let b: Vec<_> = rows.iter().filter(|r| r["case"] == "broken").collect();
    assert_eq!(b.len(), 1);
    assert!(
        b[0]["status"].starts_with("facesim: ") && b[0]["status"].contains("missing.nii.gz"),
        "{:?}",
        b[0]["status"]
    );
    assert!(failures.iter().any(|f| f["case"] == "broken"));
    // The slow case: over its one-minute limit, Slurm's TIMEOUT and its reason (TimeLimit) in
    // its row and failures.csv, from the job the retry looked up (the run's .jobs file).
    let r: Vec<_> = rows.iter().filter(|r| r["case"] == "slow").collect();
    assert_eq!(r.len(), 1, "{r:?}");
    let jobs = std::fs::read_to_string(out.join("logs/slow/case/c1.jobs")).unwrap();
    let first_job = jobs.split_whitespace().next().unwrap().to_string();
    assert!(
        r[0]["status"].starts_with(&format!("slurm: job {first_job} TIMEOUT ("))
            && r[0]["status"].contains("TimeLimit")
            && r[0]["status"].contains("of 00:01:00")
            && r[0]["status"].contains("not retried"),
        "{:?} (jobs {jobs:?})",
        r[0]["status"]
    );
    assert!(r[0]["mean_mm"].is_empty());
    // Its one attempt: the retry ran (the .jobs file's second job) but, at the maximum,
    // recorded the first attempt instead of running facesim into the same limit.
    assert_eq!(jobs.lines().count(), 2, "{jobs:?}");
    for (col, want) in [
        ("attempt", "1"),
        ("attempts", "1"),
        ("requested_runtime_min", "1"),
        ("slurm_state", "TIMEOUT"),
    ] {
        assert_eq!(r[0][col], want, "{col}: {:?}", r[0]);
    }
    let slurm_state = cluster.out(
        "squeue",
        &[
            "--noheader",
            "--states=all",
            "-j",
            &first_job,
            "--format=%T %l",
        ],
    );
    assert_eq!(slurm_state.trim(), "TIMEOUT 1:00", "job {first_job}");
    let f = failures.iter().find(|f| f["case"] == "slow").unwrap();
    assert_eq!(f["status"], r[0]["status"]);
    assert_eq!(f["slurm_job"], first_job);
    // failures.csv: every row that is not ok — broken, slow, case005's killed attempts and, if
    // case002's retry finished before the interruption, its cancelled first attempt.
    assert_eq!(
        failures.len(),
        rows.iter().filter(|r| r["status"] != "ok").count(),
        "{failures:#?}"
    );
    for f in &failures {
        let known = f["case"] == "broken"
            || f["case"] == "slow"
            || (f["case"] == "case005" && f["slurm_state"] == "OUT_OF_MEMORY")
            || (f["case"] == "case002"
                && f["plan"] == "case"
                && f["attempt"] == "1"
                && f["slurm_job"] == cancelled
                && f["slurm_state"] == "CANCELLED");
        assert!(known, "{f:?}");
    }
    assert_eq!(
        failures.iter().filter(|f| f["case"] != "case002").count(),
        2 + case005_attempts - 2,
        "{failures:#?}"
    );

    // Everything else equals the local run: same rows, same figures, same provenance.
    let local_rows = read_csv(&local.join("cohort.csv"));
    assert!(same_as_local(&local_rows, &rows, &same, &["case", "case_setback"]) > 8 * 5);
    // case005's last attempts, with twice (or four times) the memory, gave the local figures.
    assert!(same_as_local(&local_rows, &rows, &["case005"], &["case", "case_setback"]) >= 2 * 5);
    // Provenance: every ok row names facesim's version, its build and the case.
    for r in rows.iter().filter(|r| r["status"] == "ok") {
        assert!(r["facesim_version"].starts_with("facesim "), "{r:?}");
        assert_eq!(r["facesim_sha256"].len(), 64);
        assert_eq!(r["case_sha256"].len(), 64);
        assert_eq!(r["parameters_sha256"].len(), 64);
        assert!(
            out.join("parameters")
                .join(format!("{}.json", r["parameters_sha256"]))
                .is_file()
        );
        assert!(!r["slurm_job"].is_empty(), "{r:?}");
    }

    // The grouped run (started beside the re-run): two jobs, both COMPLETED, for five runs.
    let status = grouped_child.0.wait().unwrap();
    let grouped_log = work.join("slurm-grouped.log");
    let log = std::fs::read_to_string(&grouped_log).unwrap();
    assert!(status.success(), "the grouped run failed:\n{log}");
    let grouped_runs = 4 + 1;
    assert_eq!(job_count(&log, "run"), Some(grouped_runs), "{log}");
    let ids: Vec<String> = submitted_jobs(&grouped_log)
        .into_iter()
        .map(|(id, _)| id)
        .collect();
    assert_eq!(ids.len(), grouped_runs.div_ceil(3), "{log}");
    for id in &ids {
        let state = cluster.out(
            "squeue",
            &["--noheader", "--states=all", "-j", id, "--format=%T"],
        );
        assert_eq!(state.trim(), "COMPLETED", "job {id}");
    }
    // Each run ran inside one of those jobs, several to a job.
    let mut per_job = BTreeMap::<String, usize>::new();
    for case in same {
        assert!(
            !grouped
                .join("runs")
                .join(case)
                .join("case_setback")
                .exists()
        );
        let r = grouped.join("runs").join(case).join("case/c1/result.json");
        let result: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&r).unwrap()).unwrap();
        let job = result["slurm_job"].as_str().unwrap_or_default().to_string();
        assert!(
            ids.contains(&job),
            "{}: job {job} not in {ids:?}",
            r.display()
        );
        *per_job.entry(job).or_default() += 1;
    }
    assert_eq!(per_job.len(), ids.len(), "{per_job:?}");
    assert_eq!(per_job.values().sum::<usize>(), grouped_runs);
    let grouped_rows = read_csv(&grouped.join("cohort.csv"));
    assert_eq!(
        same_as_local(&local_rows, &grouped_rows, &same, &["case"]),
        grouped_rows.len()
    );
    println!(
        "slurm test: local run {:.0} s, grouped Slurm run {:.0} s ({} jobs for {grouped_runs} \
         runs), whole test {:.0} s",
        t_local.as_secs_f64(),
        t_grouped.elapsed().as_secs_f64(),
        ids.len(),
        t0.elapsed().as_secs_f64()
    );
    drop(cluster);
    assert!(
        !std::env::temp_dir()
            .join(format!("facesim-slurm-{}", std::process::id()))
            .exists(),
        "the cluster's directory is left"
    );
}

/// A process as /proc shows it: parent, state (R, S, Z, …), start time (clock ticks since boot,
/// which tells a process from a later one given the same PID) and command line.
#[derive(Clone, Debug)]
struct Proc {
    pid: u32,
    ppid: u32,
    state: char,
    start: u64,
    cmdline: String,
}

fn proc_of(pid: u32) -> Option<Proc> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The fields after the parenthesised command name (which may hold spaces and parentheses).
    let rest: Vec<&str> = stat[stat.rfind(')')? + 1..].split_whitespace().collect();
    let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
    Some(Proc {
        pid,
        state: rest.first()?.chars().next()?,
        ppid: rest.get(1)?.parse().ok()?,
        start: rest.get(19)?.parse().ok()?,
        cmdline: String::from_utf8_lossy(&cmdline)
            .replace('\0', " ")
            .trim()
            .to_string(),
    })
}

fn processes() -> Vec<Proc> {
    std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse().ok())
        .filter_map(proc_of)
        .collect()
}

/// Whether the process recorded as `p` still runs: the same PID with the same start time, not
/// a zombie (a dead process its parent has not reaped yet).
fn still_runs(p: &Proc) -> bool {
    proc_of(p.pid).is_some_and(|now| now.start == p.start && now.state != 'Z')
}

/// The cgroup directories under /sys/fs/cgroup that hold `pid`, one per hierarchy, read from
/// /proc/PID/cgroup and /proc/mounts (cgroup v1: one mount per controller set; v2: one
/// unified mount), whatever layout this machine's slurmd uses.
fn cgroup_dirs(pid: u32) -> Vec<PathBuf> {
    let mounts = std::fs::read_to_string("/proc/mounts").unwrap();
    let mounts: Vec<(String, String, Vec<String>)> = mounts
        .lines()
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.len() > 3 && f[2].starts_with("cgroup")).then(|| {
                (
                    f[2].to_string(),
                    f[1].to_string(),
                    f[3].split(',').map(String::from).collect(),
                )
            })
        })
        .collect();
    let text = std::fs::read_to_string(format!("/proc/{pid}/cgroup")).unwrap_or_default();
    text.lines()
        .filter_map(|l| {
            let mut f = l.splitn(3, ':');
            let (_, controllers, path) = (f.next()?, f.next()?, f.next()?);
            let (_, mount, _) = mounts.iter().find(|(kind, _, opts)| {
                if controllers.is_empty() {
                    kind == "cgroup2"
                } else {
                    kind == "cgroup" && controllers.split(',').all(|c| opts.iter().any(|o| o == c))
                }
            })?;
            Some(Path::new(mount).join(path.trim_start_matches('/')))
        })
        .collect()
}

/// Jobs that keep running — a `sleep`, and a job script with a background child and a job
/// step (`srun`) of its own — then `slurm-cluster.sh stop` mid-run: no slurmstepd, no job
/// process and none of the node's Slurm cgroups may be left, checked by the PIDs and cgroup
/// directories recorded before the stop. `start` must print nothing on stderr.
fn stop_ends_running_jobs_and_their_cgroups() {
    preconditions();
    let work = root().join("target/tmp/slurm-stop");
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).unwrap();
    let cluster = Cluster::start();
    assert_eq!(
        cluster.start_stderr.trim(),
        "",
        "slurm-cluster.sh start wrote to stderr"
    );

    let script = work.join("job.sh");
    std::fs::write(&script, "#!/bin/sh\nsleep 300 &\nsrun sleep 300 &\nwait\n").unwrap();
    let mut jobs = Vec::new();
    for args in [
        vec!["--wrap".to_string(), "sleep 300".to_string()],
        vec![script.display().to_string()],
    ] {
        let o = run_ok(
            cluster
                .cmd("sbatch")
                .args(["--parsable", "--mem=50", "--output=/dev/null"])
                .arg(format!("--chdir={}", work.display()))
                .args(&args),
        );
        jobs.push(o.trim().split(';').next().unwrap().to_string());
    }
    // Every slurmstepd of the two jobs (two batch steps, the script's step 0) and its process
    // tree, up to the three sleeps.
    let mut recorded = Vec::new();
    wait_for(
        "both jobs' slurmstepd and their three sleeps",
        Duration::from_secs(60),
        || {
            let all = processes();
            let steps = |p: &Proc| {
                jobs.iter().any(|j| {
                    p.cmdline.starts_with(&format!("slurmstepd: [{j}."))
                        && !p.cmdline.contains(".extern]")
                })
            };
            let mut tree: Vec<Proc> = all.iter().filter(|p| steps(p)).cloned().collect();
            let mut grew = true;
            while grew {
                let more: Vec<Proc> = all
                    .iter()
                    .filter(|p| {
                        tree.iter().any(|t| t.pid == p.ppid) && !tree.iter().any(|t| t.pid == p.pid)
                    })
                    .cloned()
                    .collect();
                grew = !more.is_empty();
                tree.extend(more);
            }
            let sleeps = tree
                .iter()
                .filter(|p| p.cmdline.ends_with("sleep 300") && !p.cmdline.contains("srun"))
                .count();
            let stepds = tree.iter().filter(|p| steps(p)).count();
            recorded = tree;
            stepds == 3 && sleeps == 3
        },
    );
    let stepds: Vec<&Proc> = recorded
        .iter()
        .filter(|p| p.cmdline.starts_with("slurmstepd"))
        .collect();
    // The node's cgroups, as the job processes' /proc/PID/cgroup name them: each job's own
    // directory and the node's root of them (the first component named slurm…).
    let mut cgroups = BTreeSet::new();
    for p in recorded
        .iter()
        .filter(|p| !p.cmdline.starts_with("slurmstepd"))
    {
        for dir in cgroup_dirs(p.pid) {
            let slurm =
                |c: std::path::Component| c.as_os_str().to_string_lossy().starts_with("slurm");
            let Some(i) = dir.components().position(slurm) else {
                continue;
            };
            let node: PathBuf = dir.components().take(i + 1).collect();
            cgroups.insert(node);
            cgroups.insert(dir);
        }
    }
    assert!(
        cgroups.iter().any(|c| c.to_string_lossy().contains("job_")),
        "no job cgroup found for {recorded:?}"
    );
    for c in &cgroups {
        assert!(c.is_dir(), "{}", c.display());
    }
    let state = cluster.out("squeue", &["--noheader", "--format=%i %T"]);
    assert_eq!(
        state.lines().filter(|l| l.ends_with(" RUNNING")).count(),
        2,
        "{state}"
    );

    let t = Instant::now();
    let o = cluster.stop();
    let stop_seconds = t.elapsed().as_secs_f64();
    assert!(
        o.status.success(),
        "stop failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!cluster.dir.exists(), "the cluster's directory is left");
    let left: Vec<&Proc> = recorded.iter().filter(|p| still_runs(p)).collect();
    assert!(
        left.is_empty(),
        "left running after stop ({} processes recorded, {} slurmstepd): {left:#?}",
        recorded.len(),
        stepds.len()
    );
    let left: Vec<&PathBuf> = cgroups.iter().filter(|c| c.exists()).collect();
    assert!(left.is_empty(), "cgroups left after stop: {left:#?}");
    println!(
        "slurm stop: {} processes ({} slurmstepd) and {} cgroup directories before, none after; \
         stop took {stop_seconds:.1} s",
        recorded.len(),
        stepds.len(),
        cgroups.len()
    );
}

/// The default (volumetric) model on the cluster with `auto` resources: two phantoms of a seed
/// no fit saw, each with its translation and its rotation plan, every job sized by `facesim
/// estimate` (docs/guide/cohort.md "Resources from the model"). No job may end OUT_OF_MEMORY, every
/// run completes on its first attempt, and each asked for more memory than it peaked at.
fn the_default_model_on_auto_resources_loses_no_job_to_memory() {
    preconditions();
    let work = root().join("target/tmp/slurm-default-model");
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).unwrap();
    let cases = work.join("cases");
    run_ok(Command::new(exe()).arg("phantom-cohort").arg(&cases).args([
        "--cases",
        "2",
        "--seed",
        "777",
        "--spacing",
        "2.5",
        "--slice",
        "2.5",
    ]));
    let config = work.join("config.yaml");
    std::fs::write(
        &config,
        format!(
            "plans: [\"case.toml\", \"case_rotation.toml\"]\nthreads: 2\nretry_growth: 2\n\
             shared_storage: [\"{}\", \"{}\"]\n",
            root().display(),
            venv().display()
        ),
    )
    .unwrap();
    let cluster = Cluster::start();
    let out = work.join("slurm");
    let mut c = Command::new(snakemake());
    c.current_dir(&work)
        .arg("-s")
        .arg(root().join("workflow/Snakefile"))
        .arg("--workflow-profile")
        .arg(root().join("workflow/profiles/slurm"))
        .args([
            "--default-resources",
            "slurm_partition=cohort",
            "--slurm-status-command",
            "squeue",
            "--slurm-init-seconds-before-status-checks",
            "2",
        ])
        .arg("--configfile")
        .arg(&config)
        .arg("--config")
        .arg(format!("cohort={}", cases.display()))
        .arg(format!("out={}", out.display()))
        .arg(format!("facesim={}", exe().display()));
    run_ok(cluster.env(&mut c));
    let rows = read_csv(&out.join("cohort.csv"));
    let mut runs = 0;
    for r in &rows {
        assert_ne!(r["slurm_state"], "OUT_OF_MEMORY", "{r:?}");
        assert_eq!(r["status"], "ok", "{r:?}");
        assert_eq!(r["attempts"], "1", "a run needed a retry: {r:?}");
        if r["region"] != "face" {
            continue;
        }
        assert!(!r["slurm_job"].is_empty(), "{r:?}");
        let (asked, peak): (f64, f64) = (
            r["requested_mem_mb"].parse().unwrap(),
            r["peak_mem_mb"].parse().unwrap(),
        );
        assert!(
            peak > 500.0 && asked > peak,
            "asked {asked} MB, peaked at {peak}: {r:?}"
        );
        runs += 1;
    }
    assert_eq!(runs, 4, "{rows:?}");
    // Each job was sized by the model's own estimate, kept for the job step.
    for case in ["case001", "case002"] {
        for plan in ["case", "case_rotation"] {
            let e = out
                .join("estimates")
                .join(case)
                .join(plan)
                .join("default.json");
            let e: serde_json::Value = serde_json::from_slice(&std::fs::read(&e).unwrap()).unwrap();
            assert!(e["system"]["factor_nonzeros"].as_u64().unwrap() > 0);
        }
    }
    drop(cluster);
}

/// The three scenarios on a real Slurm, one after the other in one test (one cluster at a time
/// on a host): the binary's other threads run the other tests meanwhile. Each scenario runs even
/// when one before it failed; the test fails naming every one that did.
#[test]
fn on_a_real_slurm_cluster() {
    let scenarios: [(&str, fn()); 3] = [
        (
            "cohort_on_a_real_slurm_with_faults",
            cohort_on_a_real_slurm_with_faults,
        ),
        (
            "the_default_model_on_auto_resources_loses_no_job_to_memory",
            the_default_model_on_auto_resources_loses_no_job_to_memory,
        ),
        (
            "stop_ends_running_jobs_and_their_cgroups",
            stop_ends_running_jobs_and_their_cgroups,
        ),
    ];
    let failed: Vec<&str> = scenarios
        .into_iter()
        .filter(|(_, run)| std::panic::catch_unwind(run).is_err())
        .map(|(name, _)| name)
        .collect();
    assert!(failed.is_empty(), "failed on the cluster: {failed:?}");
}

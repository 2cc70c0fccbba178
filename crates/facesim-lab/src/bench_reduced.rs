//! `facesim-lab bench reduced [--case DIR] --out DIR [--quick]` : what the certified
//! reduced model (docs/design/reduced.md) costs and how close it is, on one case.
//!
//! - **One full solve**: `Prediction::resolve` at the case's own parameters (assembly,
//!   ordering, factorisation, one solve, the carry to the face), median of 3; and the run's own
//!   solve stage.
//! - **Offline**: `Prediction::reduced` for the sliding states `[uncertainty]` draws, as the run
//!   builds it (training: `uncertainty::run::training`; outputs: the run's soft landmarks), its
//!   factorisations and solves, and offline ÷ one full solve.
//! - **Online**: per random θ of the `[uncertainty]` box, the coefficients and bound
//!   (`ReducedModels::solve`) and the whole face (`ReducedTet::face`), medians; against a bare
//!   pass over the face's stored columns (the memory floor of any method that writes the face).
//! - **Bands**: `facesim run` as a child process (this executable) with the many-sample band
//!   (10 000 samples, the reduced method), the 8-sample full band and no band, each with its wall
//!   time and peak resident memory (`wait4`'s rusage of that child).
//! - **Error**: at K random θ of the box (not trained on), the reduced face against a full solve:
//!   the worst vertex's and the Euclidean error over the face against the certified bound (mm).
//!
//! `--quick` meshes coarser (skin 6 / deep 12 mm, no discretisation estimate) and samples less,
//! for the test on data-samples/jaws. Writes bench_reduced.json and bench_reduced.md in OUT.

use facesim::case::Case;
use facesim::error::{Error, Result};
use facesim::model::Prediction;
use facesim::model::reduced::ReducedModels;
use facesim::observe::{Observer, Quiet};
use facesim::output::write_bytes_atomic;
use facesim::pipeline::inputs::{CaseFiles, user_landmarks};
use facesim::pipeline::{Recorder, Scene, Stage, prepare_case};
use facesim::reduced::ReducedReport;
use facesim::vec3::{norm, sub};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The `--set` overrides of `--quick`, given to the child runs; [`quick_case`] applies the same
/// to the case read in this process.
const QUICK_SETS: [&str; 3] = [
    "tet.skin_size_mm=6",
    "tet.deep_size_mm=12",
    "tet.error_estimate=false",
];

fn quick_case(case: &mut Case) {
    case.tet.skin_size_mm = 6.0;
    case.tet.deep_size_mm = 12.0;
    case.tet.error_estimate = false;
}

/// Sample counts and repeats of one bench.
#[derive(Clone, Debug, Serialize)]
pub struct Sizes {
    /// Samples of the many-sample band (the reduced method) and of the full band.
    pub band_samples: usize,
    pub full_band_samples: usize,
    /// Random θ the online times are the medians over.
    pub online_samples: usize,
    /// Random θ solved fully for the error.
    pub error_samples: usize,
    /// Repeats of the nominal full solve.
    pub full_solve_repeats: usize,
}

impl Sizes {
    fn of(quick: bool) -> Sizes {
        Sizes {
            band_samples: if quick { 1_000 } else { 10_000 },
            full_band_samples: if quick { 2 } else { 8 },
            online_samples: 1_000,
            error_samples: if quick { 2 } else { 24 },
            full_solve_repeats: 3,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub cpu: String,
    pub cores: usize,
    pub threads: usize,
    pub memory_gb: f64,
    /// /proc/loadavg's 1-, 5- and 15-minute load averages at the start and the end.
    pub load_start: [f64; 3],
    pub load_end: [f64; 3],
}

fn load_average() -> [f64; 3] {
    let s = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let mut it = s.split_whitespace().map(|x| x.parse().unwrap_or(f64::NAN));
    [
        it.next().unwrap_or(f64::NAN),
        it.next().unwrap_or(f64::NAN),
        it.next().unwrap_or(f64::NAN),
    ]
}

/// The case's model as meshed.
#[derive(Clone, Debug, Serialize)]
pub struct Model {
    pub nodes: usize,
    pub tets: usize,
    pub free_dofs: usize,
    pub face_vertices: usize,
    /// The case's soft landmarks with their own bound (outputs of the offline build).
    pub landmark_outputs: usize,
    /// Whether the mesh has nodes to slide (then one reduced model per sliding state).
    pub sliding_matters: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct FullSolve {
    /// `Prediction::resolve` at the case's own parameters (s), each repeat, and their median.
    pub resolve_s: Vec<f64>,
    pub median_s: f64,
    /// The solve stage of this process's run of the model (mesh holds, assembly,
    /// factorisation, solve, carry: report.json `timings.solve`).
    pub run_solve_stage_s: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Offline {
    /// Wall time of `Prediction::reduced` (every sliding state) (s).
    pub wall_s: f64,
    /// Training points per model.
    pub training_points: usize,
    pub models: Vec<ReducedReport>,
    /// Factorisations and solves with the reference factor, summed over the models.
    pub full_factorisations: usize,
    pub reference_solves: usize,
    /// wall_s ÷ one full solve (median), and per model its offline_seconds ÷ one full solve.
    pub full_solves: f64,
    pub full_solves_per_model: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Online {
    pub samples: usize,
    /// Median and 90th percentile per θ (µs): coefficients and bound (`ReducedModels::solve`,
    /// what a band sample costs before the face) and the whole face (`ReducedTet::face`).
    pub solve_us: f64,
    pub solve_p90_us: f64,
    pub face_us: f64,
    pub face_p90_us: f64,
    /// A bare pass summing one model's stored face fields (lift + N columns; the floor of any
    /// method that writes the face), median (µs), and the bytes it reads.
    pub memory_pass_us: f64,
    pub memory_pass_bytes: usize,
    /// face_us ÷ memory_pass_us.
    pub face_over_memory_pass: f64,
    /// Vertices some face field moves (`LinearFace::moving`): the face's cost is a pass over
    /// their fields and a write of the whole face; the still ones are zero.
    pub moving_vertices: usize,
    /// The largest certified face bound (mm) over these θ (the Euclidean norm over the face,
    /// so every vertex too), and the median.
    pub largest_face_bound_mm: f64,
    pub median_face_bound_mm: f64,
}

/// One `facesim run` child.
#[derive(Clone, Debug, Serialize)]
pub struct BandRun {
    pub label: String,
    pub args: Vec<String>,
    /// The child's wall time (s), as seen from here, and its peak resident set (MB; `wait4`).
    pub wall_s: f64,
    pub max_rss_mb: f64,
    /// From its report.json: `uncertainty.samples`, `method`, `solves`, `seconds` (0 without a
    /// band), the timings of its solve and uncertainty stages and its total, the reduced models'
    /// build (s: the longest model's, since the sliding states build side by side) and the
    /// largest certified face bound (mm).
    pub samples: usize,
    pub method: Option<String>,
    pub solves: usize,
    pub uncertainty_s: f64,
    pub solve_stage_s: f64,
    pub total_s: f64,
    pub reduced_build_s: f64,
    pub largest_bound_mm: Option<f64>,
}

/// The reduced face against a full solve at one θ.
#[derive(Clone, Debug, Serialize)]
pub struct ErrorRow {
    pub draw: facesim::uncertainty::run::Draw,
    pub sliding: bool,
    /// The worst vertex's error and the Euclidean norm of the error over the face (mm).
    pub max_vertex_mm: f64,
    pub euclidean_mm: f64,
    /// The certified bound (mm), and bound ÷ Euclidean error, bound ÷ worst vertex.
    pub bound_mm: f64,
    pub effectivity: f64,
    pub effectivity_vertex: f64,
    /// The largest displacement of the face at θ (mm), for scale.
    pub max_displacement_mm: f64,
    pub full_solve_s: f64,
    /// Per soft landmark: its primal–dual bound against the full solve.
    pub landmarks: Vec<LandmarkError>,
}

/// One landmark's displacement at one θ: the error of the reduced face's value (uncorrected)
/// and of the dual-corrected one, against the full solve, and the certified bound on the
/// corrected one (mm); bound ÷ corrected error.
#[derive(Clone, Debug, Serialize)]
pub struct LandmarkError {
    pub label: String,
    pub uncorrected_mm: f64,
    pub corrected_mm: f64,
    pub bound_mm: f64,
    pub effectivity: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Target {
    pub target: String,
    pub measured: String,
    pub met: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct ReducedBench {
    pub case: String,
    pub quick: bool,
    pub overrides: Vec<String>,
    pub sizes: Sizes,
    pub machine: Machine,
    pub model: Model,
    pub full_solve: FullSolve,
    pub offline: Offline,
    pub online: Online,
    /// The many-sample band, the same band from the models it stored (`facesim replan` with
    /// `[uncertainty]`), the full band and no band (one full run).
    pub band: BandRun,
    pub stored_band: BandRun,
    pub full_band: BandRun,
    pub plain: BandRun,
    /// band.wall_s ÷ plain.wall_s and band.uncertainty_s ÷ plain.wall_s; the full band's.
    pub band_run_over_full_run: f64,
    /// stored_band.wall_s ÷ plain.wall_s.
    pub stored_band_over_full_run: f64,
    pub band_stage_over_full_run: f64,
    pub full_band_run_over_full_run: f64,
    pub errors: Vec<ErrorRow>,
    pub targets: Vec<Target>,
    pub wall_s: f64,
}

fn median(v: &[f64]) -> f64 {
    quantile(v, 0.5)
}

fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// The case directory and its case.toml from `--case` (either).
fn case_paths(case: &Path) -> (PathBuf, PathBuf) {
    if case.is_dir() {
        (case.to_path_buf(), case.join("case.toml"))
    } else {
        let dir = case.parent().unwrap_or(Path::new(".")).to_path_buf();
        (dir, case.to_path_buf())
    }
}

/// Cases with the parameters of `n` draws of `case`'s `[uncertainty]` box from `seed`.
fn draws(case: &Case, n: usize, seed: u64) -> Vec<(facesim::uncertainty::run::Draw, Case)> {
    let mut c = case.clone();
    c.uncertainty.samples = n;
    c.uncertainty.seed = seed;
    facesim::uncertainty::run::draws(&c)
        .into_iter()
        .map(|d| {
            let x = d.apply(case);
            (d, x)
        })
        .collect()
}

/// Seeds of the online and error draws: neither the samples' (the case's seed) nor the
/// training's (`training` offsets it by 1 000 003).
const ONLINE_SEED: u64 = 424_242;
const ERROR_SEED: u64 = 77_777;

pub fn run(
    case_dir: &Path,
    out: &Path,
    quick: bool,
    progress: &dyn Observer,
) -> Result<ReducedBench> {
    let started = Instant::now();
    let load_start = load_average();
    std::fs::create_dir_all(out).map_err(|e| Error::output(out, e))?;
    let sizes = Sizes::of(quick);
    let (dir, case_toml) = case_paths(case_dir);
    let overrides: Vec<String> = if quick {
        QUICK_SETS.iter().map(|s| s.to_string()).collect()
    } else {
        Vec::new()
    };
    // The child runs first, before this process holds the scene (their memory is their own, but
    // the machine is not).
    let exe = facesim_beside_me()?;
    let runs = out.join(format!(".facesim-bench-reduced-{}", std::process::id()));
    std::fs::create_dir_all(&runs).map_err(|e| Error::output(&runs, e))?;
    let child = |label: &str, sets: &[String]| -> Result<BandRun> {
        progress.started(&format!("bench reduced: facesim run ({label})"));
        run_child(&exe, &dir, &runs.join(label), label, &overrides, sets)
    };
    let plain = child("plain", &["uncertainty.samples=0".into()])?;
    let full_band = child(
        "full_band",
        &[
            format!("uncertainty.samples={}", sizes.full_band_samples),
            "uncertainty.method=\"full\"".into(),
        ],
    )?;
    let band = child(
        "band",
        &[format!("uncertainty.samples={}", sizes.band_samples)],
    )?;
    // The same band again from the models that run stored (`facesim replan` with
    // `[uncertainty]`): the online half alone.
    progress.started("bench reduced: facesim replan (stored_band)");
    let stored_band = replan_child(&exe, &runs.join("band"), &runs, sizes.band_samples)?;
    let _ = std::fs::remove_dir_all(&runs);

    // This process: the scene and the model, as `facesim run` builds them.
    progress.started("bench reduced: preparing the case");
    let (mut case, _) = Case::load(&case_toml)?;
    if quick {
        quick_case(&mut case);
    }
    let scene = prepare_case(&case, &Quiet)?;
    let case = &scene.case;
    let mut rec = Recorder::new(&Quiet);
    let p = facesim::model::predict(&scene, case, &CaseFiles::in_memory(case), &mut rec)?;
    let run_solve_stage_s = rec.costs.wall_s(Stage::Solve);
    let tet = p.report(&scene).tet.ok_or_else(|| {
        Error::config("bench reduced: the case's model is not the tetrahedral one")
    })?;

    progress.started("bench reduced: full solves at the nominal parameters");
    let mut resolve_s = Vec::new();
    for _ in 0..sizes.full_solve_repeats {
        let t = Instant::now();
        std::hint::black_box(p.resolve(&scene, case)?);
        resolve_s.push(t.elapsed().as_secs_f64());
    }
    let full = median(&resolve_s);
    let full_solve = FullSolve {
        median_s: full,
        resolve_s,
        run_solve_stage_s,
    };

    progress.started("bench reduced: building the reduced models (offline)");
    let analysis = facesim::landmarks::analyse(
        &p.skin,
        &p.face_post,
        Some(&scene.face.skull),
        &scene.model.plan,
        &user_landmarks(case)?,
        &case_toml,
    )?;
    let outputs = facesim::uncertainty::reduced::landmark_outputs(&analysis, &p.skin);
    let train = facesim::uncertainty::run::training(case);
    let t = Instant::now();
    let models = p
        .reduced(&scene, case, &train, &outputs, &|m: &str| {
            progress.started(&format!("bench reduced: {m}"))
        })
        .ok_or_else(|| {
            Error::config("bench reduced: the case's model has no reduced form (or moves nothing)")
        })??;
    let offline_s = t.elapsed().as_secs_f64();
    let reports: Vec<ReducedReport> = models.models.iter().map(|m| m.report()).collect();
    let offline = Offline {
        wall_s: offline_s,
        training_points: train.len(),
        full_factorisations: reports.iter().map(|r| r.full_factorisations).sum(),
        reference_solves: reports.iter().map(|r| r.reference_solves).sum(),
        full_solves: offline_s / full,
        full_solves_per_model: reports.iter().map(|r| r.offline_seconds / full).collect(),
        models: reports,
    };
    let model = Model {
        nodes: tet.nodes,
        tets: tet.tets,
        free_dofs: tet.free_dofs,
        face_vertices: p.skin.vertices.len(),
        landmark_outputs: outputs.len(),
        sliding_matters: models.sliding_matters,
    };

    progress.started("bench reduced: online solves");
    let online = online(&models, case, sizes.online_samples)?;

    progress.started("bench reduced: reduced against full solves");
    let labels = facesim::uncertainty::reduced::landmark_output_labels(&analysis);
    let errors = errors(
        (&p, &scene, &models),
        (&outputs, &labels),
        case,
        sizes.error_samples,
        progress,
    )?;

    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    let mut b = ReducedBench {
        case: case_dir.display().to_string(),
        quick,
        overrides,
        sizes,
        machine: machine(load_start),
        model,
        full_solve,
        offline,
        online,
        band_run_over_full_run: ratio(band.wall_s, plain.wall_s),
        stored_band_over_full_run: ratio(stored_band.wall_s, plain.wall_s),
        band_stage_over_full_run: ratio(band.uncertainty_s, plain.wall_s),
        full_band_run_over_full_run: ratio(full_band.wall_s, plain.wall_s),
        band,
        stored_band,
        full_band,
        plain,
        errors,
        targets: Vec::new(),
        wall_s: 0.0,
    };
    b.targets = targets(&b);
    b.wall_s = started.elapsed().as_secs_f64();
    write(out, &b)?;
    Ok(b)
}

fn machine(load_start: [f64; 3]) -> Machine {
    let m = crate::study::machine();
    Machine {
        cpu: m.cpu,
        cores: m.cores,
        threads: m.threads,
        memory_gb: m.memory_gb,
        load_start,
        load_end: load_average(),
    }
}

/// The `facesim` command built beside this program (target/release/facesim beside
/// target/release/facesim-lab): the children are the product's own runs.
fn facesim_beside_me() -> Result<PathBuf> {
    let me = std::env::current_exe().map_err(|e| Error::config(format!("bench reduced: {e}")))?;
    let exe = me.with_file_name(format!("facesim{}", std::env::consts::EXE_SUFFIX));
    if !exe.is_file() {
        return Err(Error::config(format!(
            "bench reduced: no facesim command at {} (build it: cargo build --release -p facesim-cli)",
            exe.display()
        )));
    }
    Ok(exe)
}

/// `exe run DIR --out OUT --set …` (the quick overrides, then `sets`), its wall time and peak
/// resident set, and the figures of its report.json (its outputs stay: the stored band reads
/// the band run's).
fn run_child(
    exe: &Path,
    case_dir: &Path,
    out: &Path,
    label: &str,
    overrides: &[String],
    sets: &[String],
) -> Result<BandRun> {
    let mut args: Vec<String> = vec![
        "run".into(),
        case_dir.display().to_string(),
        "--out".into(),
        out.display().to_string(),
    ];
    for s in overrides.iter().chain(sets) {
        args.extend(["--set".into(), s.clone()]);
    }
    let (wall_s, maxrss_kb, r) = measured(exe, &args, out)?;
    Ok(band_run(label, args, wall_s, maxrss_kb, &r, true))
}

/// A child's figures from its report.json. `built`: a run, whose `timings` hold its stages
/// and whose reduced models it built; else a replan from stored models (no stages but its
/// sampling, `uncertainty.seconds`; no build, its whole wall time its total).
fn band_run(
    label: &str,
    args: Vec<String>,
    wall_s: f64,
    maxrss_kb: i64,
    r: &serde_json::Value,
    built: bool,
) -> BandRun {
    let u = &r["uncertainty"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(0.0);
    let build = || {
        u["reduced"].as_array().map_or(0.0, |m| {
            m.iter()
                .map(|x| f(&x["offline_seconds"]))
                .fold(0.0, f64::max)
        })
    };
    BandRun {
        label: label.into(),
        args,
        wall_s,
        max_rss_mb: maxrss_kb as f64 / 1024.0,
        samples: u["samples"].as_u64().unwrap_or(0) as usize,
        method: u["method"].as_str().map(str::to_string),
        solves: u["solves"].as_u64().unwrap_or(0) as usize,
        uncertainty_s: f(if built {
            &r["timings"]["uncertainty"]
        } else {
            &u["seconds"]
        }),
        solve_stage_s: if built {
            f(&r["timings"]["solve"])
        } else {
            0.0
        },
        total_s: if built {
            f(&r["timings"]["total"])
        } else {
            wall_s
        },
        reduced_build_s: if built { build() } else { 0.0 },
        largest_bound_mm: u["largest_bound_mm"].as_f64(),
    }
}

/// `exe replan RUN PLAN.toml --out …` with `[uncertainty] samples` (the run's box and seed):
/// the band from the models RUN stored, its wall time and peak resident set (its uncertainty
/// stage: report.json `uncertainty.seconds`; no mesh, so no solve stage).
fn replan_child(exe: &Path, run: &Path, dir: &Path, samples: usize) -> Result<BandRun> {
    let plan = dir.join("stored_band.toml");
    let text = format!("[uncertainty]\nsamples = {samples}\n");
    std::fs::write(&plan, text).map_err(|e| Error::output(&plan, e))?;
    let out = dir.join("stored_band");
    let args: Vec<String> = vec![
        "replan".into(),
        run.display().to_string(),
        plan.display().to_string(),
        "--out".into(),
        out.display().to_string(),
    ];
    let (wall_s, maxrss_kb, r) = measured(exe, &args, &out)?;
    let _ = std::fs::remove_dir_all(&out);
    Ok(band_run("stored_band", args, wall_s, maxrss_kb, &r, false))
}

/// Run `exe args` (its outputs in `out`): its wall time, peak resident set (KB) and report.json.
fn measured(exe: &Path, args: &[String], out: &Path) -> Result<(f64, i64, serde_json::Value)> {
    let log = out.with_extension("stderr");
    let stderr = std::fs::File::create(&log).map_err(|e| Error::output(&log, e))?;
    let t = Instant::now();
    let child = std::process::Command::new(exe)
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(stderr)
        .spawn()
        .map_err(|e| {
            Error::config(format!(
                "bench reduced: cannot start {}: {e}",
                exe.display()
            ))
        })?;
    // wait4 gives this child's own rusage (RUSAGE_CHILDREN would be the largest over every
    // child waited for so far). The Child is not waited for again.
    let (status, maxrss_kb) = wait4(child.id() as libc::pid_t)
        .map_err(|e| Error::config(format!("bench reduced: waiting for the run: {e}")))?;
    let wall_s = t.elapsed().as_secs_f64();
    if !status {
        let msg = std::fs::read_to_string(&log).unwrap_or_default();
        return Err(Error::config(format!(
            "bench reduced: `facesim {}` failed: {}",
            args.join(" "),
            msg.trim()
        )));
    }
    let report = out.join("report.json");
    let text = std::fs::read_to_string(&report).map_err(|e| Error::output(&report, e))?;
    let r: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::output(&report, e))?;
    let _ = std::fs::remove_file(&log);
    Ok((wall_s, maxrss_kb, r))
}

/// Wait for child `pid`: whether it exited 0, and its peak resident set (KB).
fn wait4(pid: libc::pid_t) -> std::io::Result<(bool, i64)> {
    let mut status: libc::c_int = 0;
    // SAFETY: a zeroed rusage is a valid value for wait4 to fill.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: pid is our child; status and ru are valid for writes.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut ru) };
        if r == pid {
            break;
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
    let ok = libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0;
    Ok((ok, ru.ru_maxrss))
}

/// Online costs over `n` random θ of the box.
fn online(models: &ReducedModels, case: &Case, n: usize) -> Result<Online> {
    let mut solve_us = Vec::with_capacity(n);
    let mut face_us = Vec::with_capacity(n);
    let mut bounds = Vec::with_capacity(n);
    let mut checksum = 0.0;
    for (_, c) in draws(case, n, ONLINE_SEED) {
        let t = Instant::now();
        let (i, coefficients, b) = models.solve(&c)?;
        solve_us.push(t.elapsed().as_secs_f64() * 1e6);
        checksum += coefficients.iter().sum::<f64>();
        let m = &models.models[i];
        bounds.push(b.face_mm);
        let mut c = c;
        c.tet.sliding = m.sliding;
        let t = Instant::now();
        let f = m.face(&c)?;
        face_us.push(t.elapsed().as_secs_f64() * 1e6);
        checksum += f.displacement[0][0];
    }
    // The floor: read every stored face field of the first model once.
    let face = &models.models[0].face;
    let mut pass = Vec::new();
    for _ in 0..n.clamp(3, 200) {
        let t = Instant::now();
        let mut s = 0.0;
        for col in std::iter::once(&face.lift).chain(&face.columns) {
            s += col.iter().map(|v| v[0] + v[1] + v[2]).sum::<f64>();
        }
        pass.push(t.elapsed().as_secs_f64() * 1e6);
        checksum += s;
    }
    std::hint::black_box(checksum);
    let memory_pass_us = median(&pass);
    let face_med = median(&face_us);
    Ok(Online {
        samples: n,
        solve_us: median(&solve_us),
        solve_p90_us: quantile(&solve_us, 0.9),
        face_us: face_med,
        face_p90_us: quantile(&face_us, 0.9),
        memory_pass_us,
        memory_pass_bytes: (face.columns.len() + 1) * face.lift.len() * 24,
        face_over_memory_pass: face_med / memory_pass_us,
        moving_vertices: face.moving(),
        largest_face_bound_mm: bounds.iter().cloned().fold(0.0, f64::max),
        median_face_bound_mm: median(&bounds),
    })
}

/// A soft landmark as weights on face vertices (`uncertainty::reduced::landmark_outputs`).
type Output = Vec<(usize, f64)>;

/// The reduced face against full solves at `k` random θ of the box.
fn errors(
    (p, scene, models): (&Prediction, &Scene, &ReducedModels),
    (outputs, labels): (&[Output], &[String]),
    case: &Case,
    k: usize,
    progress: &dyn Observer,
) -> Result<Vec<ErrorRow>> {
    let mut rows = Vec::new();
    for (j, (draw, c)) in draws(case, k, ERROR_SEED).into_iter().enumerate() {
        progress.started(&format!("bench reduced: full solve {} of {k}", j + 1));
        let t = Instant::now();
        let full = p.resolve(scene, &c)?;
        let full_solve_s = t.elapsed().as_secs_f64();
        let (i, _, _) = models.solve(&c)?;
        let m = &models.models[i];
        let mut c = c;
        c.tet.sliding = m.sliding;
        let ours = m.face(&c)?;
        let mut max: f64 = 0.0;
        let mut sq = 0.0;
        let mut max_disp: f64 = 0.0;
        for ((pre, post), d) in p.skin.vertices.iter().zip(&full).zip(&ours.displacement) {
            let truth = sub(*post, *pre);
            let e = norm(sub(truth, *d));
            max = max.max(e);
            sq += e * e;
            max_disp = max_disp.max(norm(truth));
        }
        let l2 = sq.sqrt();
        let landmarks = outputs
            .iter()
            .zip(labels)
            .enumerate()
            .map(|(k, (w, label))| {
                let at = |d: &dyn Fn(usize) -> [f64; 3]| -> [f64; 3] {
                    let mut y = [0.0; 3];
                    for (v, a) in w {
                        let dv = d(*v);
                        for i in 0..3 {
                            y[i] += a * dv[i];
                        }
                    }
                    y
                };
                let truth = at(&|v| sub(full[v], p.skin.vertices[v]));
                let face = at(&|v| ours.displacement[v]);
                let c = ours.landmark_corrections[k];
                let corrected = [face[0] + c[0], face[1] + c[1], face[2] + c[2]];
                let e = norm(sub(truth, corrected));
                LandmarkError {
                    label: label.clone(),
                    uncorrected_mm: norm(sub(truth, face)),
                    corrected_mm: e,
                    bound_mm: ours.landmark_bounds_mm[k],
                    effectivity: ours.landmark_bounds_mm[k] / e,
                }
            })
            .collect();
        rows.push(ErrorRow {
            landmarks,
            draw,
            sliding: m.sliding,
            max_vertex_mm: max,
            euclidean_mm: l2,
            bound_mm: ours.bound_mm,
            effectivity: ours.bound_mm / l2,
            effectivity_vertex: ours.bound_mm / max,
            max_displacement_mm: max_disp,
            full_solve_s,
        });
    }
    Ok(rows)
}

/// The reduced model's targets (docs/lab/performance.md) against what was measured.
fn targets(b: &ReducedBench) -> Vec<Target> {
    // Over the online θ, the error θ and the many-sample band's samples (its report.json).
    let largest_bound = b
        .errors
        .iter()
        .map(|e| e.bound_mm)
        .chain(b.band.largest_bound_mm)
        .fold(b.online.largest_face_bound_mm, f64::max);
    let worst_vertex = b.errors.iter().map(|e| e.max_vertex_mm).fold(0.0, f64::max);
    vec![
        Target {
            target: "offline ≤ 15 full solves".into(),
            measured: format!(
                "{:.1} full solves ({:.1} s ÷ {:.2} s; per sliding state {})",
                b.offline.full_solves,
                b.offline.wall_s,
                b.full_solve.median_s,
                b.offline
                    .full_solves_per_model
                    .iter()
                    .map(|x| format!("{x:.1}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            met: b.offline.full_solves <= 15.0,
        },
        Target {
            target: "online ≤ 50 µs a sample (coefficients + bound)".into(),
            measured: format!("{:.1} µs (median)", b.online.solve_us),
            met: b.online.solve_us <= 50.0,
        },
        Target {
            target: "online ≤ 50 µs a sample (the whole face)".into(),
            measured: format!(
                "{:.1} µs (median; {} vertices, {} of them moving; {:.2}× a bare pass over every face field)",
                b.online.face_us,
                b.model.face_vertices,
                b.online.moving_vertices,
                b.online.face_over_memory_pass
            ),
            met: b.online.face_us <= 50.0,
        },
        Target {
            target: format!(
                "{}-sample band in less time than one full run",
                b.band.samples
            ),
            measured: format!(
                "from the stored model (`facesim replan` with [uncertainty]): {:.2} s wall, {:.0} MB, against one full run {:.1} s, {:.0} MB; in the run that builds the model: band stage {:.1} s (build {:.1} s, counted offline above)",
                b.stored_band.wall_s,
                b.stored_band.max_rss_mb,
                b.plain.wall_s,
                b.plain.max_rss_mb,
                b.band.uncertainty_s,
                b.band.reduced_build_s
            ),
            met: b.stored_band.wall_s < b.plain.wall_s,
        },
        Target {
            target: "certified face error ≤ 0.01 mm over the default parameter box".into(),
            measured: format!(
                "largest bound {largest_bound:.3} mm over {} θ (the band's, the online and the error θ; true worst vertex {worst_vertex:.2e} mm at the error θ)",
                b.band.samples + b.online.samples + b.errors.len()
            ),
            met: largest_bound <= 0.01,
        },
    ]
}

/// bench_reduced.json and bench_reduced.md (each written to a temporary name and renamed).
fn write(out: &Path, b: &ReducedBench) -> Result<()> {
    let json = serde_json::to_string_pretty(b).map_err(|e| Error::output(out, e))?;
    write_bytes_atomic(&out.join("bench_reduced.json"), |w| {
        w.write_all(json.as_bytes())
    })?;
    let md = summary(b);
    write_bytes_atomic(&out.join("bench_reduced.md"), |w| {
        w.write_all(md.as_bytes())
    })
}

/// The summary as markdown (also what the command prints).
pub fn summary(b: &ReducedBench) -> String {
    let m = &b.machine;
    let mut md = format!(
        "# `facesim-lab bench reduced` — {}{}\n\nMachine: {} ({} cores, {} threads, {:.0} GB); load average {:.2} {:.2} {:.2} at the start, {:.2} {:.2} {:.2} at the end. Whole bench {:.0} s.\n\n",
        b.case,
        if b.quick { " (--quick)" } else { "" },
        m.cpu,
        m.cores,
        m.threads,
        m.memory_gb,
        m.load_start[0],
        m.load_start[1],
        m.load_start[2],
        m.load_end[0],
        m.load_end[1],
        m.load_end[2],
        b.wall_s
    );
    if !b.overrides.is_empty() {
        md += &format!("Overrides: `{}`.\n\n", b.overrides.join("`, `"));
    }
    let d = &b.model;
    md += &format!(
        "Model: {} nodes, {} tetrahedra, {} free DOFs; face {} vertices; {} landmark outputs; sliding {}.\n\n",
        d.nodes,
        d.tets,
        d.free_dofs,
        d.face_vertices,
        d.landmark_outputs,
        if d.sliding_matters {
            "matters (a model per state)"
        } else {
            "holds nothing"
        }
    );
    let f = &b.full_solve;
    let o = &b.offline;
    md += "| what | time | ratio |\n|---|---|---|\n";
    md += &format!(
        "| one full solve (`Prediction::resolve`, median of {}) | {:.2} s | 1 |\n",
        f.resolve_s.len(),
        f.median_s
    );
    md += &format!(
        "| the run's solve stage (this process) | {:.2} s | {:.2} |\n",
        f.run_solve_stage_s,
        f.run_solve_stage_s / f.median_s
    );
    md += &format!(
        "| offline: `Prediction::reduced`, {} model(s) side by side, {} factorisations, {} reference solves, {} conjugate-gradient iterations | {:.1} s | **{:.1} full solves** |\n",
        o.models.len(),
        o.full_factorisations,
        o.reference_solves,
        o.models.iter().map(|m| m.cg_iterations).sum::<usize>(),
        o.wall_s,
        o.full_solves
    );
    for (r, x) in o.models.iter().zip(&o.full_solves_per_model) {
        md += &format!(
            "| — sliding {}: N = {}, {} factorisations, largest relative energy bound {:.1e}, face gain {:.3} | {:.1} s | {:.1} |\n",
            r.sliding,
            r.basis_size,
            r.full_factorisations,
            r.greedy.last().map_or(f64::NAN, |g| g.max_relative_bound),
            r.face_gain,
            r.offline_seconds,
            x
        );
    }
    let on = &b.online;
    md += &format!(
        "| online: coefficients + bound (`ReducedModels::solve`), median (p90) of {} θ | {:.1} µs ({:.1}) | {:.3}× the memory pass |\n",
        on.samples,
        on.solve_us,
        on.solve_p90_us,
        on.solve_us / on.memory_pass_us
    );
    md += &format!(
        "| online: the whole face (`ReducedTet::face`; {} vertices move) | {:.1} µs ({:.1}) | **{:.2}× the memory pass** |\n",
        on.moving_vertices, on.face_us, on.face_p90_us, on.face_over_memory_pass
    );
    md += &format!(
        "| a bare pass over the face fields ({:.1} MB) | {:.1} µs | 1 |\n\n",
        on.memory_pass_bytes as f64 / 1e6,
        on.memory_pass_us
    );
    md += "| `facesim run` | wall | peak RSS | samples, method, solves | uncertainty stage (build) | ÷ one full run |\n|---|---|---|---|---|---|\n";
    for r in [&b.plain, &b.full_band, &b.band, &b.stored_band] {
        md += &format!(
            "| {} | {:.1} s | {:.0} MB | {}, {}, {} | {:.1} s ({:.1} s) | {:.2} |\n",
            r.label,
            r.wall_s,
            r.max_rss_mb,
            r.samples,
            r.method.as_deref().unwrap_or("-"),
            r.solves,
            r.uncertainty_s,
            r.reduced_build_s,
            r.wall_s / b.plain.wall_s
        );
    }
    md += "\n| θ (ν, muscle/fat, skin/fat, sliding) | worst vertex (mm) | Euclidean (mm) | bound (mm) | bound ÷ Euclidean | bound ÷ worst vertex | max move (mm) |\n|---|---|---|---|---|---|---|\n";
    for e in &b.errors {
        let d = &e.draw;
        md += &format!(
            "| {:.3}, {:.2}, {:.2}, {} | {:.2e} | {:.2e} | {:.3} | {:.0} | {:.0} | {:.2} |\n",
            d.poisson.unwrap_or(f64::NAN),
            d.muscle_fat.unwrap_or(f64::NAN),
            d.skin_fat.unwrap_or(f64::NAN),
            e.sliding,
            e.max_vertex_mm,
            e.euclidean_mm,
            e.bound_mm,
            e.effectivity,
            e.effectivity_vertex,
            e.max_displacement_mm
        );
    }
    md += &landmark_summary(&b.errors);
    md += &format!(
        "\nCertified face bound over the {} online θ: median {:.3} mm, largest {:.3} mm.\n\n| target | measured | met |\n|---|---|---|\n",
        on.samples, on.median_face_bound_mm, on.largest_face_bound_mm
    );
    for t in &b.targets {
        md += &format!(
            "| {} | {} | {} |\n",
            t.target,
            t.measured,
            if t.met { "met" } else { "**not met**" }
        );
    }
    md
}

/// Per landmark over the error θ: the primal–dual bound (largest), the corrected and
/// uncorrected errors (largest) and the bound's effectivity (min, median, max).
fn landmark_summary(errors: &[ErrorRow]) -> String {
    let labels: Vec<&str> = errors
        .first()
        .map(|e| e.landmarks.iter().map(|l| l.label.as_str()).collect())
        .unwrap_or_default();
    let mut md = String::from(
        "\n| landmark | largest bound (mm) | largest corrected error (mm) | largest uncorrected error (mm) | effectivity min / median / max |\n|---|---|---|---|---|\n",
    );
    for (k, label) in labels.iter().enumerate() {
        let rows: Vec<&LandmarkError> = errors.iter().filter_map(|e| e.landmarks.get(k)).collect();
        let largest =
            |f: &dyn Fn(&LandmarkError) -> f64| rows.iter().map(|r| f(r)).fold(0.0, f64::max);
        let mut eff: Vec<f64> = rows.iter().map(|r| r.effectivity).collect();
        eff.sort_by(f64::total_cmp);
        md += &format!(
            "| {label} | {:.2e} | {:.2e} | {:.2e} | {:.1} / {:.1} / {:.1} |\n",
            largest(&|r| r.bound_mm),
            largest(&|r| r.corrected_mm),
            largest(&|r| r.uncorrected_mm),
            eff.first().copied().unwrap_or(f64::NAN),
            median(&eff),
            eff.last().copied().unwrap_or(f64::NAN),
        );
    }
    md
}

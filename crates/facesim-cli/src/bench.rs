//! `facesim bench crosscheck`: facesim's whole run of a case, CT to face, timed beside
//! CalculiX's solve of the very mesh that run built (docs/design/crosscheck.md "Speed against
//! CalculiX"). The run is this binary's own `run`, as a user starts it; CalculiX gets the run's
//! tets.vtu with every node facesim held (fixed, moved, sliding, contact) held at facesim's
//! displacement, and solves the free nodes on as many threads as facesim used. Its answer at
//! the free nodes is then compared with facesim's: the speed is only worth stating for the same
//! answer.

use facesim::error::{Error, Result};
use facesim::tet::vtu;
use facesim_calculix::{self as calculix, Dof, Problem, RunCost, Step};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The agreement the cross-check demands: max |u_ccx − u_facesim| ÷ max |u| over free nodes.
const AGREEMENT: f64 = 1e-6;

pub struct Options<'a> {
    pub case_dir: &'a Path,
    pub out: PathBuf,
    pub repeat: usize,
    pub threads: usize,
    pub set: &'a [String],
}

#[derive(serde::Serialize)]
struct Timings {
    /// Every repeat's wall-clock seconds, in order.
    wall_s: Vec<f64>,
    cpu_s: Vec<f64>,
    median_wall_s: f64,
    median_cpu_s: f64,
}

#[derive(serde::Serialize)]
struct Crosscheck {
    case: String,
    threads: usize,
    nodes: usize,
    cells: usize,
    element: &'static str,
    free_nodes: usize,
    facesim_run: Timings,
    calculix_solve: Timings,
    /// facesim's whole run ÷ CalculiX's solve, medians of wall-clock time.
    ratio_wall: f64,
    ratio_cpu: f64,
    /// max |u_ccx − u_facesim| ÷ max |u_facesim| over the free nodes, CalculiX's answer refined
    /// past its 7 printed digits (one pass of iterative refinement, also by CalculiX).
    agreement: f64,
    agreement_limit: f64,
}

fn timings(costs: &[RunCost]) -> Timings {
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let wall_s: Vec<f64> = costs.iter().map(|c| c.wall_s).collect();
    let cpu_s: Vec<f64> = costs.iter().map(|c| c.cpu_s).collect();
    Timings {
        median_wall_s: median(wall_s.clone()),
        median_cpu_s: median(cpu_s.clone()),
        wall_s,
        cpu_s,
    }
}

/// One `facesim run` of the case into `out`, as a child process: what a user waits for.
fn time_run(o: &Options, out: &Path) -> Result<RunCost> {
    let exe = std::env::current_exe().map_err(|e| Error::config(format!("bench: {e}")))?;
    let mut cmd = std::process::Command::new(exe);
    cmd.arg("--threads")
        .arg(o.threads.to_string())
        .arg("run")
        .arg(o.case_dir)
        .arg("--out")
        .arg(out);
    for s in o.set {
        cmd.arg("--set").arg(s);
    }
    let cpu_before = calculix::children_cpu_s();
    let start = Instant::now();
    let done = cmd
        .output()
        .map_err(|e| Error::config(format!("bench: could not start facesim run: {e}")))?;
    let cost = RunCost {
        wall_s: start.elapsed().as_secs_f64(),
        cpu_s: calculix::children_cpu_s() - cpu_before,
    };
    if !done.status.success() {
        let why = String::from_utf8_lossy(&done.stderr);
        return Err(Error::config(format!(
            "bench crosscheck: the run of {} failed: {}",
            o.case_dir.display(),
            why.lines().last().unwrap_or("no message").trim()
        )));
    }
    Ok(cost)
}

/// The run's model as report.json states it: the material must be the small-strain linear one,
/// which a linear CalculiX step reproduces exactly.
fn check_linear(report: &Path) -> Result<()> {
    let text = std::fs::read_to_string(report).map_err(|e| Error::input(report, e))?;
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::input(report, e))?;
    match json["tet"]["material"].as_str() {
        Some("linear") => Ok(()),
        Some(m) => Err(Error::config(format!(
            "bench crosscheck compares the small-strain linear model; this run's [tet] material is \"{m}\" ({})",
            report.display()
        ))),
        None => Err(Error::input(
            report,
            "no tet.material: crosscheck needs the volumetric model ([solve] model = \"volumetric\")",
        )),
    }
}

pub fn crosscheck(o: &Options) -> Result<()> {
    if o.repeat == 0 {
        return Err(Error::config(
            "bench crosscheck: --repeat must be at least 1",
        ));
    }
    facesim::output::create_dir_guarded(&o.out)?;
    let run_dir = o.out.join("run");
    let mut run_costs = Vec::new();
    for k in 0..o.repeat {
        eprintln!(
            "facesim run {} ({} of {})",
            o.case_dir.display(),
            k + 1,
            o.repeat
        );
        run_costs.push(time_run(o, &run_dir)?);
    }
    check_linear(&run_dir.join("report.json"))?;
    let mesh_path = run_dir.join("tets.vtu");
    let f = vtu::read(&mesh_path)?;
    let material = calculix::linear_materials(&f.youngs_kpa, &f.poisson);
    let free = |n: usize| f.constraint[n] == vtu::FREE;
    let held: Vec<Dof> = (0..f.nodes.len())
        .filter(|&n| !free(n))
        .flat_map(|n| {
            let u = f.displacement[n];
            (0..3).map(move |axis| Dof {
                node: n as u32,
                axis,
                value: u[axis],
            })
        })
        .collect();
    let problem = Problem {
        nodes: &f.nodes,
        cells: f.cells.view(),
        material: &material,
        held: &held,
        loads: &[],
        pressure: &[],
        step: Step::LINEAR,
    };
    let deck = calculix::deck(&problem)?;
    let mut ccx_costs = Vec::new();
    for k in 0..o.repeat {
        eprintln!(
            "CalculiX on {} ({} of {})",
            mesh_path.display(),
            k + 1,
            o.repeat
        );
        ccx_costs.push(calculix::run_timed(&deck, f.nodes.len(), o.threads)?.1);
    }
    eprintln!("CalculiX's answer refined for the agreement");
    let precise = calculix::solve_precise(&problem)?.displacement;
    let agreement = calculix::relative_difference(&precise, &f.displacement, free);
    let (run, ccx) = (timings(&run_costs), timings(&ccx_costs));
    let result = Crosscheck {
        case: o.case_dir.display().to_string(),
        threads: o.threads,
        nodes: f.nodes.len(),
        cells: f.cells.view().len(),
        element: match f.cells {
            vtu::CellsOwned::Linear(_) => "C3D4",
            _ => "C3D10",
        },
        free_nodes: (0..f.nodes.len()).filter(|&n| free(n)).count(),
        ratio_wall: run.median_wall_s / ccx.median_wall_s,
        ratio_cpu: run.median_cpu_s / ccx.median_cpu_s,
        facesim_run: run,
        calculix_solve: ccx,
        agreement,
        agreement_limit: AGREEMENT,
    };
    let json_path = o.out.join("crosscheck.json");
    let json = serde_json::to_string_pretty(&result).map_err(|e| Error::output(&json_path, e))?;
    facesim::output::write_bytes_atomic(&json_path, |w| w.write_all(json.as_bytes()))?;
    println!(
        "{}: {} nodes, {} {} cells ({} free nodes), {} threads, median of {}",
        result.case,
        result.nodes,
        result.cells,
        result.element,
        result.free_nodes,
        result.threads,
        o.repeat
    );
    println!(
        "  facesim run, CT to face:       {:7.2} s wall, {:7.2} s CPU",
        result.facesim_run.median_wall_s, result.facesim_run.median_cpu_s
    );
    println!(
        "  CalculiX solve, the same mesh: {:7.2} s wall, {:7.2} s CPU",
        result.calculix_solve.median_wall_s, result.calculix_solve.median_cpu_s
    );
    println!(
        "  ratio (facesim ÷ CalculiX):    {:7.3} wall, {:7.3} CPU",
        result.ratio_wall, result.ratio_cpu
    );
    println!(
        "  agreement at the free nodes:   {:.2e} (limit {:.0e}); {}",
        agreement,
        AGREEMENT,
        json_path.display()
    );
    // NaN (a broken answer) fails too.
    if agreement.is_nan() || agreement > AGREEMENT {
        return Err(Error::numerical(
            facesim::error::NumericalKind::NotConverged,
            format!(
                "bench crosscheck: CalculiX and facesim differ by {agreement:.2e} of the largest displacement at the free nodes of {} (limit {AGREEMENT:.0e})",
                mesh_path.display()
            ),
        ));
    }
    Ok(())
}

//! `facesim-lab`: the laboratory's command line — the benchmarks and the speed-against-accuracy
//! study (docs/lab/performance.md, docs/lab/study.md). They measure the product; they are not
//! part of it, so the `facesim` command does not carry them.

#![deny(clippy::unwrap_used, clippy::expect_used)]

use clap::{Parser, Subcommand};
use facesim::error::{Error, Result};
use facesim::meter::HeapProbe;
use facesim::observe::Observer;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

// Counts heap bytes for the benchmarks' and the study's peak-memory columns.
#[global_allocator]
static ALLOC: facesim::meter::CountingAllocator = facesim::meter::CountingAllocator;

#[derive(Parser)]
#[command(
    name = "facesim-lab",
    version,
    about = "facesim's benchmarks and solver study (what measures the product)"
)]
struct Cli {
    /// Worker threads (default: all cores).
    #[arg(long, global = true)]
    threads: Option<usize>,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// One benchmark (tables and JSON in --out; `facesim-lab bench --help` lists them).
    ///
    /// `fem`: C1 assembly + factorisation + three solves on a planar mesh. `scaling`: every
    /// stage's cost against CT and mesh size. `embed`: a dense face scan solved whole against
    /// coarse models + shell embedding. `replan`: PlanBasis::predict on the real CT face with the
    /// volumetric model (--case: the case.toml, default data-samples/real/case.toml).
    /// `dicom`: reading the real CT in each compressed DICOM transfer syntax.
    /// `linearisation`: the C1 models' plan basis against full solves, per move size (--case).
    /// `reduced`: the certified reduced model's offline and online costs, its band against the
    /// full one and its error against full solves (--case: a case directory, default
    /// data-samples/real).
    Bench {
        #[arg(value_parser = ["fem", "scaling", "embed", "replan", "dicom", "linearisation", "reduced"])]
        what: String,
        /// Output directory for `scaling`, `embed`, `replan`, `dicom` and `reduced`.
        #[arg(long)]
        out: Option<PathBuf>,
        /// `scaling`, `embed`: small sizes only; `dicom`: one read per syntax; `reduced`: a
        /// coarse mesh and fewer samples (< 3 min on data-samples/jaws).
        #[arg(long)]
        quick: bool,
        /// `fem`: triangles in the mesh.
        #[arg(long, default_value_t = 40000)]
        triangles: usize,
        /// `fem`: also write the factored matrix as Matrix Market (benches/cholmod_compare.sh).
        #[arg(long)]
        export: Option<PathBuf>,
        /// `replan`: the case whose run builds the basis; `reduced`, `linearisation`: the case
        /// measured.
        #[arg(long)]
        case: Option<PathBuf>,
    },
    /// Speed against accuracy: integrators, stability, face baselines (summary.md in OUT_DIR).
    Study {
        out_dir: PathBuf,
        /// A reduced study (coarser benchmarks, the phantom only, fewer resolutions): < 2 min.
        #[arg(long)]
        quick: bool,
        /// Face cases (default: data-samples/phantom, plus data-samples/real when fetched).
        #[arg(long = "case")]
        cases: Vec<PathBuf>,
    },
}

/// Progress as one line per stage on stderr (benchmarks run for minutes, often unattended).
struct Lines;

impl Observer for Lines {
    fn started(&self, what: &str) {
        eprintln!("… {what}");
    }
    fn heap(&self) -> Option<&dyn HeapProbe> {
        facesim::meter::counted_heap()
    }
    fn warn(&self, msg: &str) {
        eprintln!("warning: {msg}");
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(n) = cli.threads {
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global();
    }
    let done = match cli.cmd {
        Cmd::Bench {
            what,
            out,
            quick,
            triangles,
            export,
            case,
        } => match what.as_str() {
            "scaling" => bench_scaling(out, quick),
            "replan" => bench_replan(case, out),
            "linearisation" => bench_linearisation(case),
            "embed" => bench_embed(out, quick),
            "dicom" => bench_dicom(out, quick),
            "reduced" => bench_reduced(case, out, quick),
            _ => bench_fem(triangles, export.as_deref()),
        },
        Cmd::Study {
            out_dir,
            quick,
            cases,
        } => study(&out_dir, quick, cases),
    };
    match done {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("facesim-lab: {e}");
            ExitCode::from(1)
        }
    }
}

fn required(out: Option<PathBuf>, what: &str) -> Result<PathBuf> {
    out.ok_or_else(|| Error::config(format!("bench {what}: --out DIR is required")))
}

fn bench_scaling(out: Option<PathBuf>, quick: bool) -> Result<()> {
    let out = required(out, "scaling")?;
    let s = facesim_lab::scaling::run(&out, quick, &Lines)?;
    for f in &s.fits {
        println!(
            "{:5} {:18} exponent {:5.2}  largest {:.3} s",
            f.series, f.stage, f.exponent, f.largest_wall_s
        );
    }
    Ok(())
}

fn bench_embed(out: Option<PathBuf>, quick: bool) -> Result<()> {
    let out = required(out, "embed")?;
    let b = facesim_lab::bench_embed::run(&out, quick, &Lines)?;
    for r in &b.rows {
        let d = r.distance.as_ref();
        println!(
            "{:42} {:>10} {:8.2} s  mean {:.3} mm  p90 {:.3} mm  max {:.3} mm",
            r.method,
            r.resolution,
            r.wall_s,
            d.map_or(f64::NAN, |d| d.mean),
            d.map_or(f64::NAN, |d| d.p90),
            d.map_or(f64::NAN, |d| d.max)
        );
    }
    Ok(())
}

fn bench_replan(case: Option<PathBuf>, out: Option<PathBuf>) -> Result<()> {
    let case = case.unwrap_or_else(|| PathBuf::from("data-samples/real/case.toml"));
    let out = required(out, "replan")?;
    let b = facesim_lab::bench_replan::run(&case, &out, 200)?;
    println!(
        "face {} vertices, {} segments: predict {:.3} ms (median of {}), one pass over the basis {:.3} ms, run {:.1} s (plan basis {:.2} s) = {:.0}x predict",
        b.face_vertices,
        b.segments,
        b.predict_ms,
        b.repeats,
        b.memory_pass_ms,
        b.run_s,
        b.basis_s,
        b.run_s * 1e3 / b.predict_ms
    );
    Ok(())
}

fn bench_reduced(case: Option<PathBuf>, out: Option<PathBuf>, quick: bool) -> Result<()> {
    let case = case.unwrap_or_else(|| PathBuf::from("data-samples/real"));
    let out = required(out, "reduced")?;
    let b = facesim_lab::bench_reduced::run(&case, &out, quick, &Lines)?;
    print!("{}", facesim_lab::bench_reduced::summary(&b));
    println!(
        "written: {}, {}",
        out.join("bench_reduced.json").display(),
        out.join("bench_reduced.md").display()
    );
    Ok(())
}

fn bench_dicom(out: Option<PathBuf>, quick: bool) -> Result<()> {
    let out = required(out, "dicom")?;
    let ct = Path::new("data-samples/real/Cranium.inv3");
    let b = facesim_lab::bench_dicom::run(ct, &out, if quick { 1 } else { 5 })?;
    println!("{} {:?}, best of {} reads", b.ct, b.dims, b.repeats);
    for r in &b.rows {
        match &r.error {
            None => println!(
                "{:42} {:24} {:8.1} MB {:7.3} s  max |dHU| {}",
                r.syntax,
                r.uid,
                r.bytes as f64 / 1e6,
                r.read_s,
                r.max_abs_hu
            ),
            Some(e) => println!("{:42} {:24} not measured: {e}", r.syntax, r.uid),
        }
    }
    Ok(())
}

fn bench_linearisation(case: Option<PathBuf>) -> Result<()> {
    use facesim::case::SolveModel;
    let case = case.unwrap_or_else(|| PathBuf::from("data-samples/phantom/case.toml"));
    let rows = facesim_lab::bench_linearisation::run(
        &case,
        &[SolveModel::Equilibrium, SolveModel::Koch1996],
    )?;
    println!("| model | move | max displacement (mm) | max error (mm) | mean error (mm) |");
    println!("|---|---|---|---|---|");
    for r in rows {
        println!(
            "| {} | {} | {:.3} | {:.3e} | {:.3e} |",
            r.model, r.mv, r.max_displacement_mm, r.max_error_mm, r.mean_error_mm
        );
    }
    Ok(())
}

fn bench_fem(triangles: usize, export: Option<&Path>) -> Result<()> {
    if !(2..=20_000_000).contains(&triangles) {
        return Err(Error::config(
            "bench fem: --triangles must be between 2 and 20000000",
        ));
    }
    let b = facesim_lab::bench_fem::run(triangles, export)?;
    println!(
        "{}",
        serde_json::to_string_pretty(&b).map_err(Error::config)?
    );
    Ok(())
}

fn study(out_dir: &Path, quick: bool, cases: Vec<PathBuf>) -> Result<()> {
    let cases = if cases.is_empty() {
        facesim_lab::study::default_cases(quick)
    } else {
        cases
    };
    let s = facesim_lab::study::run(out_dir, quick, &cases, &Lines)?;
    println!(
        "study written to {} in {:.1} s ({} face rows); see summary.md",
        out_dir.display(),
        s.wall_s,
        s.face.len()
    );
    Ok(())
}

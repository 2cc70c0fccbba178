//! The `facesim` command line (docs/reference/case.md "Commands").

#![deny(clippy::unwrap_used, clippy::expect_used)]

use clap::{Args, Parser, Subcommand};
use facesim::error::{Error, Result};
use progress::Progress;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

mod bench;
mod progress;
mod render;

// Counts heap bytes for report.json's and the study's peak-memory figures (two relaxed atomics
// per allocation).
#[global_allocator]
static ALLOC: facesim::meter::CountingAllocator = facesim::meter::CountingAllocator;

#[derive(Parser)]
#[command(
    name = "facesim",
    version,
    about = "Predict the face after cranio-maxillofacial surgery (Koch et al. 1996, extended)"
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
    /// Predict the face for a case directory (outputs in CASE_DIR/out by default).
    ///
    /// The whole pipeline: the CT's tissues, the skin and skull, the clinical frame and the cuts
    /// of `[[surgery]]`, the model and its solve, the landmarks, report.json and report.html
    /// (docs/reference/case.md "Outputs").
    Run {
        case_dir: PathBuf,
        #[arg(long)]
        out: Option<PathBuf>,
        /// Override a case key without editing case.toml (repeatable; dotted keys, TOML values,
        /// e.g. `--set tet.sliding=false --set solve.model=equilibrium`).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Predict a run's peak memory and wall time before running it (JSON on stdout).
    ///
    /// The volumetric model's mesh and the symbolic analysis of its factor, no numeric work
    /// (docs/guide/cohort.md "Resources from the model").
    Estimate {
        case_dir: PathBuf,
        /// Override a case key as `run --set` does (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Another plan's face from a run's plan basis, without solving again.
    ///
    /// PLAN.toml holds `[[surgery]]` entries (in the run's clinical frame) or `[[osteotomy]]`
    /// entries with the run's segment names and regions (docs/design/plan-basis.md); or, from
    /// the run's reduced_model.bin at its plan, new tissues (`[tet]`) and/or a band over tissue
    /// parameters (`[uncertainty]`: face_band.ply; docs/design/reduced.md).
    Replan {
        /// A `facesim run` output directory (plan_basis.bin, report.json).
        out_dir: PathBuf,
        /// PLAN.toml: `[[osteotomy]]`, `[tet]`, `[uncertainty]` (case.toml's forms).
        plan: PathBuf,
        /// Output directory (default OUT_DIR/replan).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Many plans from a run's plan basis: sweep.csv and sweep.svg in --out.
    ///
    /// SWEEP.toml: `[[plan]]` entries and/or a `[grid]` (docs/reference/case.md).
    Sweep {
        out_dir: PathBuf,
        sweep: PathBuf,
        #[arg(long)]
        out: PathBuf,
    },
    /// The soft-tissue landmarks and measurements of a face mesh alone (a 3D photo).
    ///
    /// Any mesh format facesim reads, no CT (docs/guide/landmarks.md "A face mesh alone"):
    /// landmarks.mrk.json (the mesh file's own coordinates) and measurements.json in --out.
    Landmarks {
        mesh: PathBuf,
        /// Output directory (default: MESH's stem + `_landmarks`, beside it).
        #[arg(long)]
        out: Option<PathBuf>,
        /// `auto`: up, front and the midsagittal plane found from the mesh; `lps`: the file's
        /// axes are LPS (x left, y back, z up), as a CT's skin.
        #[arg(long, value_parser = ["auto", "lps"], default_value = "auto")]
        frame: String,
    },
    /// Every surgery type against the published soft/hard tissue ratios.
    ///
    /// Runs every real sample that has the bone and a phantom cohort with the product's
    /// defaults (docs/guide/validation.md): validation.md, validation.csv and validation.svg in
    /// --out.
    Validate {
        /// Output directory.
        #[arg(long, default_value = "validation")]
        out: PathBuf,
        /// Jaws phantoms in the cohort (soft tissue over -2..+4 mm and the vertical pattern over
        /// -5..+7 mm, one phantom in each of N equal strata of each).
        #[arg(long, default_value_t = 4)]
        phantoms: usize,
        /// Each ratio's band: the tissue parameters sampled this many times over the
        /// `[uncertainty]` box (the reduced model), and the ratio on the mesh of twice the
        /// element size. 0: the ratios alone, without bands (faster).
        #[arg(long, default_value_t = 256)]
        band_samples: usize,
        /// Move the maxilla alone in an impaction, without the mandible's autorotation (to
        /// judge the mechanism by the protocol's rule; docs/guide/validation.md).
        #[arg(long)]
        no_autorotation: bool,
        #[command(flatten)]
        table: TableArgs,
    },
    /// Fit the tissue parameters to one half of the published ratios; check on the other.
    ///
    /// Every validation run at the defaults stores its reduced model; a grid over the
    /// `[uncertainty]` box is answered by the reduced models and the optimum confirmed by full
    /// runs (docs/lab/validation-notes.md "Calibration on the reduced model"). calibration.md,
    /// calibration.csv, calibration_grid.csv, defaults/ and optimum/ in --out.
    Calibrate {
        /// Output directory.
        #[arg(long, default_value = "calibration")]
        out: PathBuf,
        /// Jaws phantoms in the cohort (soft tissue over -2..+4 mm and the vertical pattern over
        /// -5..+7 mm, one phantom in each of N equal strata of each).
        #[arg(long, default_value_t = 0)]
        phantoms: usize,
        #[command(flatten)]
        table: TableArgs,
        /// The half fitted: `maxillary` (Le Fort I moves) or `mandibular` (BSSO, genioplasty,
        /// bimaxillary); the other is held out.
        #[arg(long, value_parser = ["maxillary", "mandibular"], default_value = "maxillary")]
        fit: String,
        /// Grid points per continuous parameter of the box (ν, muscle/fat, skin/fat).
        #[arg(long, default_value_t = 9)]
        grid: usize,
    },
    /// Write a synthetic head case whose geometry is known exactly.
    Phantom {
        dir: PathBuf,
        /// In-plane voxel size (mm).
        #[arg(long, default_value_t = 1.5)]
        spacing: f64,
        /// Slice spacing (mm).
        #[arg(long, default_value_t = 1.5)]
        slice: f64,
        /// Noise standard deviation (HU).
        #[arg(long, default_value_t = 8.0)]
        noise: f64,
        /// Vertex spacing of the face scan (mm): 3 → ~5 k vertices, 0.75 → ~80 k.
        #[arg(long, default_value_t = 3.0)]
        scan_step: f64,
        /// `capsule`: the layered capsule head; `jaws`: a head with mandible, maxilla, teeth,
        /// lips over a vestibule, chin and nose, and four jaw plans (docs/design/phantom.md).
        #[arg(long, value_parser = ["capsule", "jaws"], default_value = "capsule")]
        anatomy: String,
        /// The jaws phantom's nose: `solid` (the standard head and the bundled sample) or
        /// `hollow`, two nasal passages beside a septum as a CT shows a nose, as `facesim
        /// validate` builds its phantoms (docs/design/phantom.md "Nasal passages").
        #[arg(long, value_parser = ["solid", "hollow"], default_value = "solid")]
        nose: String,
        #[command(flatten)]
        shape: ShapeArgs,
    },
    /// Write a cohort of N distinct jaws phantoms for workflow/Snakefile.
    ///
    /// DIR/case001, …, shapes drawn from --seed, and DIR/phantoms.csv (docs/guide/cohort.md).
    PhantomCohort {
        dir: PathBuf,
        /// Number of cases.
        #[arg(long)]
        cases: usize,
        /// In-plane voxel size (mm).
        #[arg(long, default_value_t = 2.0)]
        spacing: f64,
        /// Slice spacing (mm).
        #[arg(long, default_value_t = 2.0)]
        slice: f64,
        /// Noise standard deviation (HU).
        #[arg(long, default_value_t = 8.0)]
        noise: f64,
        /// Vertex spacing of the face scans (mm).
        #[arg(long, default_value_t = 3.0)]
        scan_step: f64,
        /// `[solve] model` written into every plan (default: none, the default model).
        #[arg(long)]
        model: Option<String>,
        /// The phantoms' noses: `solid` or `hollow` (nasal passages, as `facesim phantom --nose`).
        #[arg(long, value_parser = ["solid", "hollow"], default_value = "solid")]
        nose: String,
        #[command(flatten)]
        shape: ShapeArgs,
    },
    /// A volume's geometry and HU as JSON (NIfTI, NRRD, DICOM folder, .inv3, vtk.js).
    Inspect { path: PathBuf },
    /// Render meshes (OBJ, PLY, STL, VTK or VTP; drawn together) to a PNG picture.
    Render {
        #[arg(required = true)]
        meshes: Vec<PathBuf>,
        #[arg(long, short)]
        out: PathBuf,
        #[arg(long, value_enum, default_value = "front")]
        view: render::View,
        /// Image width and height in pixels.
        #[arg(long, default_value_t = 800)]
        size: usize,
    },
    /// Benchmarks of the product against another engine (docs/design/crosscheck.md).
    #[command(subcommand)]
    Bench(BenchCmd),
    /// Distances between two meshes (OBJ, PLY, STL, VTK or VTP).
    Compare {
        a: PathBuf,
        b: PathBuf,
        /// Print the full JSON (default: a short summary).
        #[arg(long)]
        json: bool,
        /// A run's output directory: also the figures per facial region (from its face_pre.ply
        /// and landmarks_pre.mrk.json; docs/guide/landmarks.md).
        #[arg(long, value_name = "OUT_DIR")]
        regions: Option<PathBuf>,
        /// Two faces of one person (any frames and units): register A onto B on the skin
        /// surgery leaves (forehead, eyes, nasal bridge), then per landmark the distance and per
        /// facial region mean / p90 / % within 2 mm (docs/guide/landmarks.md "Two faces of one person").
        #[arg(long, conflicts_with = "regions")]
        landmarks: bool,
        /// With --landmarks: a PNG of A (registered) coloured by its distance to B, from the front.
        #[arg(long, requires = "landmarks", value_name = "PNG")]
        picture: Option<PathBuf>,
    },
}

#[derive(Subcommand)]
enum BenchCmd {
    /// A case's whole run timed beside CalculiX's solve of the mesh it built, with the ratio
    /// and the two engines' agreement at the free nodes (needs `ccx`: scripts/test-setup.sh).
    ///
    /// Writes OUT/run (the run's outputs) and OUT/crosscheck.json; exits non-zero when the
    /// engines differ by more than 1e-6 of the largest displacement.
    Crosscheck {
        case_dir: PathBuf,
        /// Where the run and crosscheck.json go (default CASE_DIR/crosscheck).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Runs of each engine; the medians are compared.
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Override a case key as `run --set` does (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
}

/// The jaws phantom's cohort parameters (docs/design/phantom.md, "Cohort parameters"): each given one
/// is used as is; with --seed the others are drawn from their documented ranges, without it
/// they keep the standard head's values.
#[derive(clap::Args)]
struct ShapeArgs {
    /// Head size factor (everything scales about the origin; standard 1, drawn 0.92–1.08).
    #[arg(long)]
    scale: Option<f64>,
    /// Soft-tissue thickness change (mm; standard 0, drawn −2..4).
    #[arg(long)]
    soft_mm: Option<f64>,
    /// Mandibular prognathism (mm forward; standard 0, drawn −3..3).
    #[arg(long)]
    mandible_mm: Option<f64>,
    /// Chin prominence change (mm; standard 0, drawn −2..3).
    #[arg(long)]
    chin_mm: Option<f64>,
    /// Mandibular midline shift towards the patient's left (mm; standard 0, drawn −2..2).
    #[arg(long)]
    asymmetry_mm: Option<f64>,
    /// Vertical facial pattern: change of the lower anterior face height, ANS to menton (mm;
    /// + a long face, − a short one; standard 0, drawn −5..7).
    #[arg(long)]
    vertical_mm: Option<f64>,
    /// Draw the parameters not given from this seed.
    #[arg(long)]
    seed: Option<u64>,
}

impl ShapeArgs {
    fn given(&self) -> [Option<f64>; 6] {
        [
            self.scale,
            self.soft_mm,
            self.mandible_mm,
            self.chin_mm,
            self.asymmetry_mm,
            self.vertical_mm,
        ]
    }

    fn any(&self) -> bool {
        self.seed.is_some() || self.given().iter().any(Option::is_some)
    }

    fn shape(&self) -> facesim_validate::phantom_jaws::Shape {
        match self.seed {
            Some(s) => facesim_validate::phantom_cohort::draw(s, self.given()),
            None => facesim_validate::phantom_cohort::given_or_default(self.given()),
        }
    }
}

/// What the command works on, for the internal-error message.
static SUBJECT: std::sync::OnceLock<String> = std::sync::OnceLock::new();

fn main() -> ExitCode {
    // Any panic left is a bug: one line, not a backtrace wall.
    std::panic::set_hook(Box::new(|info| {
        // Inside a guarded reader the panic becomes an ordinary one-line input error.
        if facesim::error::in_guard() {
            return;
        }
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        let subject = SUBJECT
            .get()
            .map(|s| format!(" while working on {s}"))
            .unwrap_or_default();
        eprintln!(
            "facesim: internal error{subject}{at}: {} (please report this with the case)",
            msg.replace('\n', " ")
        );
    }));
    let cli = Cli::parse();
    let subject = match &cli.cmd {
        Cmd::Run { case_dir, .. } => Some(case_dir.display().to_string()),
        Cmd::Estimate { case_dir, .. } => Some(case_dir.display().to_string()),
        Cmd::PhantomCohort { dir, .. } => Some(dir.display().to_string()),
        Cmd::Inspect { path } => Some(path.display().to_string()),
        Cmd::Compare { a, b, .. } => Some(format!("{} and {}", a.display(), b.display())),
        Cmd::Render { meshes, .. } => meshes.first().map(|m| m.display().to_string()),
        Cmd::Phantom { dir, .. } => Some(dir.display().to_string()),
        Cmd::Replan { plan, .. } => Some(plan.display().to_string()),
        Cmd::Sweep { sweep, .. } => Some(sweep.display().to_string()),
        Cmd::Validate { out, .. } => Some(format!("the validation into {}", out.display())),
        Cmd::Calibrate { out, .. } => Some(format!("the calibration into {}", out.display())),
        Cmd::Landmarks { mesh, .. } => Some(mesh.display().to_string()),
        Cmd::Bench(BenchCmd::Crosscheck { case_dir, .. }) => Some(case_dir.display().to_string()),
    };
    if let Some(s) = subject {
        let _ = SUBJECT.set(s);
    }
    if let Some(n) = cli.threads {
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global();
    }
    match std::panic::catch_unwind(|| dispatch(cli.cmd, cli.threads)) {
        Ok(Ok(())) => ExitCode::SUCCESS,
        Ok(Err(e)) => {
            eprintln!("facesim: {e}");
            ExitCode::from(1)
        }
        Err(_) => ExitCode::from(2),
    }
}

/// What `validate` and `calibrate` run the published table on, besides their output directory
/// and cohort size.
#[derive(Args)]
struct TableArgs {
    /// The samples directory (each sub-directory with a validation.toml is a case).
    #[arg(long, default_value = "data-samples")]
    samples: PathBuf,
    /// The cohort's seed (the other shape parameters are drawn from it).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The phantoms' voxel size (mm).
    #[arg(long, default_value_t = 2.0)]
    phantom_spacing: f64,
    /// The phantoms' noses: `hollow`, two nasal passages beside a septum under 4 mm walls, as a
    /// CT shows a nose; `solid`, soft tissue throughout, as the standard head (docs/design/phantom.md
    /// "Nasal passages").
    #[arg(long, value_parser = ["hollow", "solid"], default_value = "hollow")]
    phantom_noses: String,
    /// Only this surgery (repeatable): lefort-advance, lefort-impaction, lefort-setback,
    /// bsso-advance, bsso-setback, genioplasty, bimax.
    #[arg(long)]
    surgery: Vec<String>,
    /// Only this case (repeatable): a samples sub-directory's name, or `phantom`.
    #[arg(long = "case")]
    cases: Vec<String>,
    /// Lay KEY=VALUE over every run's case, as `run --set` does (repeatable; e.g.
    /// `--set tet.fat_dark.youngs_kpa=3`): the same table under other tissue parameters.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Keep every output of each run under runs/ (tets.vtu, the meshes, report.html; ~35 MB a
    /// run), not only its report, landmarks and faces.
    #[arg(long)]
    keep_runs: bool,
}

impl TableArgs {
    /// The validation's options into `out` with `phantoms` phantoms; `command` names a bad
    /// `--surgery` key's command.
    fn options(
        self,
        command: &str,
        out: PathBuf,
        phantoms: usize,
    ) -> Result<facesim_validate::validate::Options> {
        let overrides = facesim::case::overrides_table(&self.set)?;
        Ok(facesim_validate::validate::Options {
            out,
            samples: self.samples,
            phantoms,
            seed: self.seed,
            phantom_spacing_mm: self.phantom_spacing,
            phantom_nasal_passages: self.phantom_noses == "hollow",
            surgeries: surgeries_of(command, &self.surgery)?,
            cases: self.cases,
            overrides,
            keep_runs: self.keep_runs,
            band_samples: 0,
            autorotation: true,
            command: std::env::args().collect::<Vec<_>>().join(" "),
        })
    }
}

/// One line per subcommand: the work is in the `cmd_*` functions below.
fn dispatch(cmd: Cmd, threads: Option<usize>) -> Result<()> {
    match cmd {
        Cmd::Run { case_dir, out, set } => cmd_run(&case_dir, out.as_deref(), &set),
        Cmd::Estimate { case_dir, set } => cmd_estimate(&case_dir, &set),
        Cmd::Phantom {
            dir,
            spacing,
            slice,
            noise,
            scan_step,
            anatomy,
            nose,
            shape,
        } => {
            let opts = phantom_options(spacing, slice, noise, scan_step)?;
            cmd_phantom(&dir, opts, &anatomy, &nose, &shape)
        }
        Cmd::PhantomCohort {
            dir,
            cases,
            spacing,
            slice,
            noise,
            scan_step,
            model,
            nose,
            shape,
        } => {
            let jaws = facesim_validate::phantom_jaws::JawsOptions {
                phantom: phantom_options(spacing, slice, noise, scan_step)?,
                solve_model: model,
            };
            let seed = shape.seed.unwrap_or(1);
            let written = facesim_validate::phantom_cohort::write_cohort(
                &dir,
                cases,
                seed,
                &jaws,
                shape.given(),
                nose == "hollow",
            )?;
            println!(
                "{} phantom cases written to {} (parameters in phantoms.csv)",
                written.len(),
                dir.display()
            );
            Ok(())
        }
        Cmd::Inspect { path } => cmd_inspect(&path),
        Cmd::Landmarks { mesh, out, frame } => {
            let from = if frame == "lps" {
                facesim::landmarks::scan::FrameFrom::Lps
            } else {
                facesim::landmarks::scan::FrameFrom::Shape
            };
            let out = out.unwrap_or_else(|| facesim::commands::landmarks::default_out(&mesh));
            let (dir, found) = facesim::commands::landmarks::landmarks(&mesh, &out, from)?;
            let n = found
                .landmarks
                .iter()
                .filter(|l| l.position.is_some())
                .count();
            println!(
                "{n} of {} soft-tissue landmarks found on {} (unit {}; vertical along {}) → {}",
                found.landmarks.len(),
                mesh.display(),
                found.unit.name,
                found.frame.vertical_from,
                dir.display()
            );
            for l in found.landmarks.iter().filter(|l| l.position.is_none()) {
                println!(
                    "  {} missing: {}",
                    l.label,
                    l.missing.as_deref().unwrap_or("")
                );
            }
            Ok(())
        }
        Cmd::Validate {
            out,
            phantoms,
            band_samples,
            no_autorotation,
            table,
        } => {
            let opts = facesim_validate::validate::Options {
                band_samples,
                autorotation: !no_autorotation,
                ..table.options("validate", out, phantoms)?
            };
            let v = facesim_validate::validate::validate(&opts, &Progress::auto())?;
            facesim_charts::validation::write(&v.out_dir.join("validation.svg"), &v)?;
            let [inside, consistent, outside, none] =
                facesim_validate::validate::verdict_counts(&v.rows);
            for k in &v.skipped {
                let what = k
                    .surgery
                    .map(|s| format!(" {}", s.key()))
                    .unwrap_or_default();
                eprintln!("not run: {}{what}: {}", k.case, k.why);
            }
            let consistent = if band_samples > 0 {
                format!(" {consistent} consistent with it (their bands overlap it),")
            } else {
                String::new()
            };
            println!(
                "{inside} landmarks inside their published range,{consistent} {outside} outside, {none} not measured: {}",
                v.out_dir.join("validation.md").display()
            );
            Ok(())
        }
        Cmd::Calibrate {
            out,
            phantoms,
            table,
            fit,
            grid,
        } => {
            use facesim_validate::validate::calibrate::{self, CalibrateOptions, Half};
            let opts = CalibrateOptions {
                validate: table.options("calibrate", out, phantoms)?,
                fit: Half::from_key(&fit).unwrap_or(Half::Maxillary),
                grid,
            };
            let c = calibrate::calibrate(&opts, &Progress::auto())?;
            for v in [&c.defaults, &c.optimum_validation] {
                facesim_charts::validation::write(&v.out_dir.join("validation.svg"), v)?;
            }
            let fitted = c.full(opts.fit, true);
            let k = c.confirmation();
            println!(
                "optimum ν {:.3}, muscle/fat {:.2}, skin/fat {:.2}, sliding {}: fitted {} / {} inside (distance {:.3}); reduced vs full within {:.1e}, {} rows outside their bound ({} of them from another tissue state); held-out half {}: {}",
                c.optimum.poisson,
                c.optimum.muscle_fat,
                c.optimum.skin_fat,
                c.optimum.sliding,
                fitted.inside,
                fitted.measured,
                fitted.distance,
                k.worst,
                k.outside_same_state + k.outside_changed_state,
                k.outside_changed_state,
                if c.held_out_improves() {
                    "improves"
                } else {
                    "does not improve, defaults stay"
                },
                c.out_dir.join("calibration.md").display()
            );
            Ok(())
        }
        Cmd::Replan { out_dir, plan, out } => {
            let r = facesim::commands::replan::replan(&out_dir, &plan, out.as_deref())?;
            eprintln!(
                "replanned from {}: {} (max displacement {:.2} mm)",
                out_dir.display(),
                r.out_dir.display(),
                r.report.displacement.max
            );
            if let Some(t) = r.report.replan.as_ref().and_then(|p| p.tissue.as_ref()) {
                eprintln!(
                    "new tissues from the reduced model: within {:.3} mm of the full model (certified)",
                    t.bound_mm
                );
            }
            Ok(())
        }
        Cmd::Sweep {
            out_dir,
            sweep,
            out,
        } => {
            let rows = facesim::commands::sweep::sweep(&out_dir, &sweep, &out)?;
            facesim_charts::sweep::write(&out.join("sweep.svg"), &rows)?;
            eprintln!("{} plans: {}", rows.len(), out.join("sweep.csv").display());
            Ok(())
        }
        Cmd::Render {
            meshes,
            out,
            view,
            size,
        } => cmd_render(&meshes, &out, view, size),
        Cmd::Bench(BenchCmd::Crosscheck {
            case_dir,
            out,
            repeat,
            set,
        }) => bench::crosscheck(&bench::Options {
            out: out.unwrap_or_else(|| case_dir.join("crosscheck")),
            case_dir: &case_dir,
            repeat,
            threads: threads.unwrap_or_else(rayon::current_num_threads),
            set: &set,
        }),
        Cmd::Compare {
            a,
            b,
            json,
            regions,
            landmarks: false,
            ..
        } => cmd_compare(&a, &b, json, regions.as_deref()),
        Cmd::Compare {
            a,
            b,
            json,
            picture,
            ..
        } => cmd_compare_faces(&a, &b, json, picture.as_deref()),
    }
}

fn cmd_run(case_dir: &Path, out: Option<&Path>, set: &[String]) -> Result<()> {
    let overrides = facesim::case::overrides_table(set)?;
    let o = facesim::commands::run_with(case_dir, out, &overrides, &Progress::auto())?;
    let r = &o.report;
    println!(
        "{}: {} skin vertices, {} skull vertices in {:.2} s; outputs in {}",
        r.name,
        o.skin.vertices.len(),
        o.skull.vertices.len(),
        r.costs.wall_s(facesim::pipeline::Stage::Total),
        o.out_dir.display()
    );
    for w in &r.warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}

fn cmd_estimate(case_dir: &Path, set: &[String]) -> Result<()> {
    let overrides = facesim::case::overrides_table(set)?;
    let e = facesim::commands::estimate::estimate(case_dir, &overrides, &Progress::auto())?;
    println!(
        "{}",
        serde_json::to_string_pretty(&e).map_err(|e| Error::output(case_dir, e))?
    );
    Ok(())
}

fn phantom_options(
    spacing: f64,
    slice: f64,
    noise: f64,
    scan_step: f64,
) -> Result<facesim_validate::phantom::PhantomOptions> {
    if !(spacing > 0.0 && spacing <= 10.0 && slice > 0.0 && slice <= 10.0 && noise >= 0.0) {
        return Err(Error::config(
            "phantom: spacing and slice must be in (0, 10] mm, noise >= 0",
        ));
    }
    Ok(facesim_validate::phantom::PhantomOptions {
        spacing: [spacing, spacing, slice],
        noise_hu: noise,
        scan_step_mm: scan_step,
        ..Default::default()
    })
}

fn cmd_phantom(
    dir: &Path,
    opts: facesim_validate::phantom::PhantomOptions,
    anatomy: &str,
    nose: &str,
    shape: &ShapeArgs,
) -> Result<()> {
    if anatomy == "jaws" {
        let jaws = facesim_validate::phantom_jaws::JawsOptions {
            phantom: opts,
            solve_model: None,
        };
        let shape = facesim_validate::phantom_jaws::Shape {
            nasal_passages: nose == "hollow",
            ..shape.shape()
        };
        facesim_validate::phantom_jaws::write_shaped_case(dir, &jaws, &shape)?;
    } else if nose != "solid" {
        return Err(Error::config(
            "phantom: --nose hollow needs --anatomy jaws (the capsule head has no nose passages to hollow)",
        ));
    } else if shape.any() {
        return Err(Error::config(
            "phantom: the cohort parameters (--scale, --soft-mm, --mandible-mm, --chin-mm, --asymmetry-mm, --vertical-mm, --seed) need --anatomy jaws",
        ));
    } else {
        facesim_validate::phantom::write_case(dir, &opts)?;
    }
    println!("phantom case written to {}", dir.display());
    Ok(())
}

fn cmd_inspect(path: &Path) -> Result<()> {
    // As `run` reads a case's CT: its notes (the series chosen, a gantry tilt resampled) too.
    let (v, notes) = facesim::volume::read_ct(path, None)?;
    for w in notes {
        eprintln!("warning: {w}");
    }
    println!(
        "{}",
        serde_json::to_string_pretty(&v.inspect()).map_err(|e| Error::output(path, e))?
    );
    Ok(())
}

fn cmd_render(meshes: &[PathBuf], out: &Path, view: render::View, size: usize) -> Result<()> {
    if !(16..=8192).contains(&size) {
        return Err(Error::config("render: --size must be between 16 and 8192"));
    }
    let loaded = meshes
        .iter()
        .map(|p| facesim::mesh::read_mesh(p))
        .collect::<Result<Vec<_>>>()?;
    let refs: Vec<&facesim::mesh::Mesh> = loaded.iter().collect();
    let img = render::render(&refs, view, size);
    render::write_png(&img, size, out)?;
    Ok(())
}

fn cmd_compare_faces(a: &Path, b: &Path, json: bool, picture: Option<&Path>) -> Result<()> {
    let ma = facesim::mesh::read_mesh(a)?;
    let mb = facesim::mesh::read_mesh(b)?;
    let o = facesim::landmarks::outcome::compare_faces(&ma, a, &mb, b)?;
    if let Some(png) = picture {
        let coloured = facesim::commands::outputs::coloured_face(&o.a_in_frame, &o.distances);
        let size = 800;
        let rgb = render::render(&[&coloured], render::View::Front, size);
        render::write_png(&rgb, size, png)?;
    }
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&o).map_err(|e| Error::output(a, e))?
        );
        return Ok(());
    }
    println!(
        "registered on {} vertices ({}): rms {:.3} mm after {} iterations",
        o.registration.vertices,
        o.registration.on,
        o.registration.rms_mm,
        o.registration.iterations
    );
    for (label, d) in &o.landmarks.0 {
        match d.distance_mm {
            Some(x) => println!("{label}: {x:.2} mm"),
            None => println!("{label}: {}", d.missing.as_deref().unwrap_or("missing")),
        }
    }
    print_regions(&o.regions);
    Ok(())
}

/// One line per facial region of `compare --regions` / `--landmarks`.
fn print_regions(
    regions: &facesim::landmarks::Ordered<facesim::landmarks::face_regions::RegionDistance>,
) {
    for (name, r) in &regions.0 {
        match &r.stats {
            Some(s) => println!(
                "{name}: {} vertices, mean {:.3} mm, p90 {:.3} mm, within 2 mm {:.1}%",
                r.vertices, s.mean, s.p90, s.pct_within_2mm
            ),
            None => println!("{name}: {}", r.absent.as_deref().unwrap_or("absent")),
        }
    }
}

fn cmd_compare(a: &Path, b: &Path, json: bool, regions: Option<&Path>) -> Result<()> {
    let ma = facesim::mesh::read_mesh(a)?;
    let mb = facesim::mesh::read_mesh(b)?;
    let c = facesim::compare::compare(&ma, &mb);
    let per_region = regions
        .map(|dir| facesim::landmarks::face_regions::compare_regions(&ma, &mb, dir))
        .transpose()?;
    if json {
        let mut v = serde_json::to_value(&c).map_err(|e| Error::output(a, e))?;
        if let (Some(r), Some(obj)) = (&per_region, v.as_object_mut()) {
            obj.insert(
                "regions".into(),
                serde_json::to_value(r).map_err(|e| Error::output(a, e))?,
            );
        }
        println!(
            "{}",
            serde_json::to_string_pretty(&v).map_err(|e| Error::output(a, e))?
        );
    } else {
        if let Some(r) = &per_region {
            print_regions(r);
        }
        println!(
            "mean {:.4} mm, rms {:.4} mm, max (Hausdorff) {:.4} mm, within 1 mm {:.1}%, within 2 mm {:.1}%",
            c.mean, c.rms, c.max, c.pct_within_1mm, c.pct_within_2mm
        );
        if let (Some(m), Some(x)) = (c.vertex_mean, c.vertex_max) {
            println!("per vertex: mean {m:.4} mm, max {x:.4} mm");
        }
    }
    Ok(())
}

/// `--surgery` keys as surgeries; an unknown one is an error naming `command`.
fn surgeries_of(
    command: &str,
    keys: &[String],
) -> Result<Vec<facesim::landmarks::published::Surgery>> {
    keys.iter()
        .map(|s| {
            facesim::landmarks::published::Surgery::from_key(s).ok_or_else(|| {
                Error::config(format!(
                    "{command}: unknown surgery '{s}' (lefort-advance, lefort-impaction, lefort-setback, bsso-advance, bsso-setback, genioplasty, bimax)"
                ))
            })
        })
        .collect()
}

//! `facesim-lab study [--quick] OUT_DIR`: speed against accuracy (docs/lab/study.md).
//!
//! 1. The benchmarks of Alterovitz & Goldberg (2003) — the 2-D block and needle with MP1 and MP2,
//!    the 3-D rod with MP3 — through four integrators, with the relative energy norm, surface and
//!    interior errors per step against implicit Newmark (`benchmarks`, `metrics`).
//! 2. Stability: critical steps from the largest generalised eigenvalue, explicit at 0.9 and
//!    1.1 h_crit, and at the benchmark's h = 1/30 s, where MP2 diverges (reported, not a crash).
//! 3. Baselines on face cases (`face`): C1 at several resolutions under both solve models, a
//!    surface mass-spring, a voxel-lattice mass-spring and a linear tetrahedral FEM, with run
//!    time, peak heap and distances to the reference.
//!
//! Writes results.json, benchmarks.csv, stability.csv, face.csv, summary.md and the charts
//! (SVG + PNG) into OUT_DIR, each file atomically.

pub mod benchmarks;
pub mod chart;
pub mod face;
pub mod mass_spring;
pub mod metrics;
// The facial regions without landmarks live in the product crate (the sweep's fallback too).
pub use facesim::landmarks::face_regions::profile as regions;
pub mod volumetric;

use crate::dynamics::{Block, Integrator, MP1, MP2, relative_energy_error};
use benchmarks::{Benchmark, Series, StabilityRow};
use face::FaceRow;
use facesim::error::{Error, Result};
use facesim::observe::Observer;
use facesim::output::write_bytes_atomic;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Clone, Debug, Serialize)]
pub struct Findings {
    /// Every non-diverged integrator ends within this relative energy norm of the static state.
    pub worst_final_vs_static: f64,
    /// Per benchmark and metric: explicit consistent < explicit lumped < quasi-static (time means).
    pub orderings: Vec<Ordering>,
    /// ‖u_MP1 − u_MP2‖_K / ‖u_MP2‖_K of the static states (same mesh, needle held).
    pub mp1_vs_mp2_steady: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Ordering {
    pub benchmark: String,
    pub metric: String,
    pub explicit_consistent: f64,
    pub explicit_lumped: f64,
    pub quasi_static: f64,
    pub holds: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub cpu: String,
    pub cores: usize,
    pub memory_gb: f64,
    pub threads: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct Study {
    pub quick: bool,
    pub machine: Machine,
    pub wall_s: f64,
    pub benchmarks: Vec<Benchmark>,
    pub stability: Vec<StabilityRow>,
    pub findings: Findings,
    pub face: Vec<FaceRow>,
    /// Per face case: its regions and C1 calibration (its rows are in `face`).
    pub face_cases: Vec<face::CaseStudy>,
}

pub fn machine() -> Machine {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let cpu = cpuinfo
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|| "unknown".into());
    let mem_kb = std::fs::read_to_string("/proc/meminfo")
        .unwrap_or_default()
        .lines()
        .find(|l| l.starts_with("MemTotal"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or(0.0);
    Machine {
        cpu,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        memory_gb: mem_kb / 1024.0 / 1024.0,
        threads: rayon::current_num_threads(),
    }
}

fn findings(benches: &[Benchmark]) -> Findings {
    let mut worst: f64 = 0.0;
    let mut orderings = Vec::new();
    for b in benches {
        for s in &b.series {
            if let Some(f) = s.final_vs_static {
                worst = worst.max(f);
            }
        }
        let by = |i: Integrator| b.series.iter().find(|s| s.integrator == i);
        let (Some(ec), Some(el), Some(qs)) = (
            by(Integrator::ExplicitConsistent),
            by(Integrator::ExplicitLumped),
            by(Integrator::QuasiStatic),
        ) else {
            continue;
        };
        if ec.diverged.is_some() || el.diverged.is_some() {
            continue;
        }
        for (metric, get) in [
            (
                "relative energy norm",
                (|s: &Series| Series::mean(&s.energy)) as fn(&Series) -> f64,
            ),
            ("surface error", |s: &Series| Series::mean(&s.surface)),
            ("interior error", |s: &Series| Series::mean(&s.interior)),
        ] {
            let (a, b2, c) = (get(ec), get(el), get(qs));
            orderings.push(Ordering {
                benchmark: b.name.clone(),
                metric: metric.into(),
                explicit_consistent: a,
                explicit_lumped: b2,
                quasi_static: c,
                holds: a < b2 && b2 < c,
            });
        }
    }
    let n = 8;
    let (b1, b2) = (Block::new(n, MP1), Block::new(n, MP2));
    let stat = |b: &Block| {
        crate::dynamics::integrate(b, Integrator::QuasiStatic, 100.0, 1, benchmarks::RAYLEIGH)
            .history
            .remove(0)
    };
    let (s1, s2) = (stat(&b1), stat(&b2));
    Findings {
        worst_final_vs_static: worst,
        orderings,
        mp1_vs_mp2_steady: relative_energy_error(&b2, &s1, &s2),
    }
}

/// The bundled sample cases: the phantom, and the real CT when its data has been fetched.
pub fn default_cases(quick: bool) -> Vec<PathBuf> {
    let root = |rel: &str| {
        let here = PathBuf::from(rel);
        if here.exists() {
            here
        } else {
            Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
        }
    };
    let mut cases = vec![root("data-samples/phantom")];
    let real = root("data-samples/real");
    if !quick && real.join("Cranium.inv3").is_file() {
        cases.push(real);
    }
    cases
}

pub fn run(out: &Path, quick: bool, cases: &[PathBuf], progress: &dyn Observer) -> Result<Study> {
    let t0 = Instant::now();
    std::fs::create_dir_all(out).map_err(|e| Error::output(out, e))?;
    progress.started("study: benchmarks (block MP1, MP2, rod MP3)");
    let benches = benchmarks::all(quick);
    progress.started("study: stability (critical steps)");
    let stability = benchmarks::stability(quick);
    let found = findings(&benches);
    let mut face = Vec::new();
    let mut face_cases = Vec::new();
    // The first case (the phantom) calibrates C1; its k_c is carried to the others.
    let mut transfer: Option<face::Calibration> = None;
    for c in cases {
        let mut cs = face::study_case(c, quick, transfer.as_ref(), progress)?;
        if transfer.is_none() {
            transfer = cs.calibration.clone();
        }
        face.append(&mut cs.rows);
        face_cases.push(cs);
    }
    let study = Study {
        quick,
        machine: machine(),
        wall_s: t0.elapsed().as_secs_f64(),
        benchmarks: benches,
        stability,
        findings: found,
        face,
        face_cases,
    };
    progress.started("study: writing tables and charts");
    write(out, &study)?;
    progress.done();
    Ok(study)
}

fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect::<String>()
        .split('_')
        .filter(|p| !p.is_empty())
        .collect::<Vec<_>>()
        .join("_")
}

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map_or(String::new(), |v| format!("{v:.digits$}"))
}

fn write(out: &Path, s: &Study) -> Result<()> {
    let json = serde_json::to_string_pretty(s).map_err(|e| Error::output(out, e))?;
    write_bytes_atomic(&out.join("results.json"), |w| w.write_all(json.as_bytes()))?;
    write_bytes_atomic(&out.join("benchmarks.csv"), |w| {
        writeln!(w, "benchmark,integrator,step,t,energy,surface,interior")?;
        for b in &s.benchmarks {
            for sr in &b.series {
                for k in 0..sr.time.len() {
                    writeln!(
                        w,
                        "{},{:?},{},{},{:e},{:e},{:e}",
                        b.name,
                        sr.integrator,
                        k + 1,
                        sr.time[k],
                        sr.energy[k],
                        sr.surface[k],
                        sr.interior[k]
                    )?;
                }
            }
        }
        Ok(())
    })?;
    write_bytes_atomic(&out.join("stability.csv"), |w| {
        writeln!(
            w,
            "problem,integrator,h_crit,at_0.9_h_crit,at_1.1_h_crit,at_h_1/30"
        )?;
        for r in &s.stability {
            writeln!(
                w,
                "{},{:?},{:e},\"{}\",\"{}\",\"{}\"",
                r.problem, r.integrator, r.h_crit, r.at_0_9, r.at_1_1, r.at_benchmark_h
            )?;
        }
        Ok(())
    })?;
    write_bytes_atomic(&out.join("face.csv"), |w| {
        writeln!(
            w,
            "case,method,resolution,unknowns,elements,wall_s,peak_mb,mean_mm,p90_mm,max_mm,within_1mm_pct,within_2mm_pct,mean_displacement_mm,reference,c1_reference_mean_mm,{},note",
            regions::NAMES
                .iter()
                .map(|n| {
                    let n = n.replace(' ', "_");
                    format!("{n}_vertices,{n}_mean_mm,{n}_p90_mm")
                })
                .collect::<Vec<_>>()
                .join(",")
        )?;
        for r in &s.face {
            let d = r.distance.as_ref();
            let per_region = regions::NAMES
                .iter()
                .map(|n| match r.regions.iter().find(|g| g.region == *n) {
                    Some(g) => format!(
                        "{},{:.4},{:.4}",
                        g.vertices, g.distance.mean, g.distance.p90
                    ),
                    None => ",,".into(),
                })
                .collect::<Vec<_>>()
                .join(",");
            writeln!(
                w,
                "\"{}\",\"{}\",\"{}\",{},{},{:.4},{},{},{},{},{},{},{},{},{},{},\"{}\"",
                r.case,
                r.method,
                r.resolution,
                r.unknowns,
                r.elements.map_or(String::new(), |e| e.to_string()),
                r.wall_s,
                opt(r.peak_mb, 1),
                opt(d.map(|d| d.mean), 4),
                opt(d.map(|d| d.p90), 4),
                opt(d.map(|d| d.max), 4),
                opt(d.map(|d| d.pct_within_1mm), 1),
                opt(d.map(|d| d.pct_within_2mm), 1),
                opt(r.mean_displacement_mm, 4),
                r.is_reference,
                opt(r.distance_c1.as_ref().map(|d| d.mean), 4),
                per_region,
                r.note.clone().unwrap_or_default().replace('"', "'")
            )?;
        }
        Ok(())
    })?;
    let mut charts = Vec::new();
    for b in &s.benchmarks {
        let stem = format!("error_over_time_{}", slug(&b.name));
        chart::error_over_time(out, &stem, b)?;
        charts.push(stem);
    }
    let mut cases: Vec<&str> = s.face.iter().map(|r| r.case.as_str()).collect();
    cases.dedup();
    for c in &cases {
        let rows: Vec<FaceRow> = s.face.iter().filter(|r| r.case == *c).cloned().collect();
        let stem = format!("accuracy_vs_time_{}", slug(c));
        chart::accuracy_vs_time(out, &stem, c, &rows)?;
        charts.push(stem);
        let stem = format!("accuracy_vs_unknowns_{}", slug(c));
        chart::accuracy_vs_unknowns(out, &stem, c, &rows)?;
        charts.push(stem);
        let picked = region_chart_rows(&rows);
        if !picked.is_empty() {
            let stem = format!("regions_{}", slug(c));
            chart::regions(out, &stem, c, &picked)?;
            charts.push(stem);
        }
    }
    for cs in &s.face_cases {
        if let Some(cal) = &cs.calibration {
            let stem = format!("calibration_{}", slug(&cs.case));
            chart::calibration(out, &stem, cal)?;
            charts.push(stem);
        }
    }
    let md = summary(s, &charts);
    write_bytes_atomic(&out.join("summary.md"), |w| w.write_all(md.as_bytes()))
}

/// The rows the region chart compares: the coarsest product tet row, both material and
/// element variants, the finest C1 equilibrium row, the calibrated C1 rows, the finest Punak row
/// and the coarsest lab lattice tets.
fn region_chart_rows(rows: &[FaceRow]) -> Vec<&FaceRow> {
    let with = |r: &&FaceRow| !r.is_reference && !r.regions.is_empty();
    let mut out: Vec<&FaceRow> = Vec::new();
    let mut first = |pred: &dyn Fn(&FaceRow) -> bool| {
        if let Some(r) = rows.iter().filter(with).find(|r| pred(r)) {
            out.push(r);
        }
    };
    first(&|r| r.method.starts_with("tet neo-Hookean"));
    first(&|r| r.method.contains("10-node"));
    first(&|r| r.method == "C1 equilibrium");
    first(&|r| r.method == "C1 equilibrium, k_c calibrated here");
    first(&|r| r.method.starts_with("C1 equilibrium, k_c from"));
    first(&|r| r.method == "mass-spring (Punak)");
    first(&|r| r.method.starts_with("linear tetrahedral FEM"));
    out
}

fn summary(s: &Study, charts: &[String]) -> String {
    let mut m = String::new();
    let m_ = &mut m;
    let mut line = |t: String| {
        m_.push_str(&t);
        m_.push('\n');
    };
    line(format!(
        "# facesim-lab study{}\n\nMachine: {} ({} cores, {} threads, {:.0} GB). Whole study: {:.1} s. Command: `facesim-lab study{} OUT_DIR`.\n",
        if s.quick { " (quick)" } else { "" },
        s.machine.cpu,
        s.machine.cores,
        s.machine.threads,
        s.machine.memory_gb,
        s.wall_s,
        if s.quick { " --quick" } else { "" }
    ));
    line(
        "## Benchmarks (Alterovitz & Goldberg 2003), h = 1/30 s, errors against implicit Newmark\n"
            .into(),
    );
    line("| benchmark | integrator | mean energy norm | mean surface | mean interior | final vs static | wall (s) | result |".into());
    line("|---|---|---|---|---|---|---|---|".into());
    for b in &s.benchmarks {
        for sr in &b.series {
            line(format!(
                "| {} ({}) | {:?} | {:.3e} | {:.3e} | {:.3e} | {} | {:.3} | {} |",
                b.name,
                b.mesh,
                sr.integrator,
                Series::mean(&sr.energy),
                Series::mean(&sr.surface),
                Series::mean(&sr.interior),
                sr.final_vs_static
                    .map_or("—".into(), |v| format!("{v:.1e}")),
                sr.wall_s,
                sr.diverged.clone().unwrap_or_else(|| "bounded".into())
            ));
        }
    }
    let f = &s.findings;
    line(format!(
        "\nFindings: every bounded integrator ends within {:.1e} (relative energy norm) of the static state; MP1 and MP2 steady states differ by {:.3} (relative energy norm: same needle move, different ν).\n",
        f.worst_final_vs_static, f.mp1_vs_mp2_steady
    ));
    line("| benchmark | metric | explicit consistent | explicit lumped | quasi-static | consistent < lumped < quasi-static |".into());
    line("|---|---|---|---|---|---|".into());
    for o in &f.orderings {
        line(format!(
            "| {} | {} | {:.3e} | {:.3e} | {:.3e} | {} |",
            o.benchmark,
            o.metric,
            o.explicit_consistent,
            o.explicit_lumped,
            o.quasi_static,
            if o.holds { "yes" } else { "**no**" }
        ));
    }
    line("\n## Stability (explicit central difference, undamped at 0.9/1.1 h_crit)\n".into());
    line(
        "| problem | integrator | h_crit (s) | 0.9 h_crit | 1.1 h_crit | h = 1/30 s (damped) |"
            .into(),
    );
    line("|---|---|---|---|---|---|".into());
    for r in &s.stability {
        line(format!(
            "| {} | {:?} | {:.3e} | {} | {} | {} |",
            r.problem, r.integrator, r.h_crit, r.at_0_9, r.at_1_1, r.at_benchmark_h
        ));
    }
    line("\n## Face models against the volumetric reference (distances on the face's vertices, mm)\n".into());
    line("Reference: the product's tetrahedral model (`[solve] model = \"tet\"`) at its finest size in the table. Over the skin the plan can move (`[surface] movable`). Mean |d|: the method's own mean displacement there. C1-ref mean: mean distance to the finest C1 equilibrium solve (the former reference). Clinical tools against post-operative scans: mean 0.6–0.9 mm, p90 1.5–1.9 mm; 2 mm is what clinicians accept.\n".into());
    line("| case | method | resolution | unknowns | time (s) | peak heap (MB) | mean | p90 | max | ≤1 mm % | ≤2 mm % | mean |d| | C1-ref mean | note |".into());
    line("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|".into());
    for r in &s.face {
        let d = r.distance.as_ref();
        line(format!(
            "| {} | {}{} | {} | {} | {:.2} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.case,
            r.method,
            if r.is_reference { " (reference)" } else { "" },
            r.resolution,
            r.unknowns,
            r.wall_s,
            opt(r.peak_mb, 0),
            opt(d.map(|d| d.mean), 3),
            opt(d.map(|d| d.p90), 3),
            opt(d.map(|d| d.max), 3),
            opt(d.map(|d| d.pct_within_1mm), 1),
            opt(d.map(|d| d.pct_within_2mm), 1),
            opt(r.mean_displacement_mm, 2),
            opt(r.distance_c1.as_ref().map(|d| d.mean), 3),
            r.note.clone().unwrap_or_default()
        ));
    }
    line("\n## Per facial region (mean / p90 distance to the volumetric reference, mm)\n".into());
    line(
        "Regions: `crates/facesim/src/landmarks/face_regions/profile.rs` (docs/lab/study.md §2).\n"
            .into(),
    );
    for cs in &s.face_cases {
        if let Some(rg) = &cs.regions {
            let l = &rg.landmarks;
            let z = |v: Option<f64>| v.map_or("—".into(), |v| format!("{v:.1}"));
            line(format!(
                "{}: landmarks by {:?} rule; midsagittal x {:.1}, nose tip {:.1?}, z of subnasale {}, labrale superius {}, stomion {}, labrale inferius {}, labiomental fold {}, pogonion {}; profile ends at z {:.1}.",
                cs.case,
                l.rule,
                l.midsagittal_x,
                l.pronasale,
                z(l.subnasale_z),
                z(l.labrale_superius_z),
                z(l.stomion_z),
                z(l.labrale_inferius_z),
                z(l.labiomental_z),
                z(l.pogonion_z),
                l.profile_bottom_z
            ));
            for i in &rg.summary {
                line(format!(
                    "- {}: {} vertices{}{}",
                    i.region,
                    i.vertices,
                    i.absent
                        .as_ref()
                        .map_or(String::new(), |a| format!(" — {a}")),
                    i.note.as_ref().map_or(String::new(), |a| format!(" — {a}"))
                ));
            }
            line(String::new());
        }
    }
    line(format!(
        "| case | method | resolution | {} |",
        regions::NAMES.join(" | ")
    ));
    line(format!(
        "|---|---|---|{}",
        "---|".repeat(regions::NAMES.len())
    ));
    for r in s
        .face
        .iter()
        .filter(|r| !r.regions.is_empty() && !r.is_reference)
    {
        let cells: Vec<String> = regions::NAMES
            .iter()
            .map(|n| {
                r.regions
                    .iter()
                    .find(|g| g.region == *n)
                    .map_or("absent".into(), |g| {
                        format!("{:.2} / {:.2}", g.distance.mean, g.distance.p90)
                    })
            })
            .collect();
        line(format!(
            "| {} | {} | {} | {} |",
            r.case,
            r.method,
            r.resolution,
            cells.join(" | ")
        ));
    }
    line("\n## C1 calibrated against the volumetric reference\n".into());
    line("`[solve] k_c` (and `[springs] struts`) of the C1 equilibrium model on the case's skin, fitted to minimise the mean distance to the reference over the movable face (sweep, then golden section in log k_c). The product default is not changed by the study.\n".into());
    line("| case | default k_c | struts | mean (mm) | calibrated k_c | struts | mean (mm) | evaluations |".into());
    line("|---|---|---|---|---|---|---|---|".into());
    for c in s.face_cases.iter().filter_map(|c| c.calibration.as_ref()) {
        line(format!(
            "| {} | {:.3e} | {} | {:.3} | {:.3e} | {} | {:.3} | {} |",
            c.case,
            c.k_c_default,
            if c.struts_default { "on" } else { "off" },
            c.mean_default_mm,
            c.k_c,
            if c.struts { "on" } else { "off" },
            c.mean_mm,
            c.evaluations.len()
        ));
    }
    line("\n## Charts\n".into());
    for c in charts {
        line(format!("![{c}]({c}.png)"));
    }
    m
}

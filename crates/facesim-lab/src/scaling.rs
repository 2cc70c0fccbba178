//! `facesim-lab bench scaling [--quick] OUT_DIR` : how each stage's cost grows.
//!
//! - CT series: the analytic phantom head at growing resolution (2 mm → 0.45 mm voxels, 1.2 M →
//!   108 M voxels; the last is the size of a 512×512×400 clinical CT), each with a 1.5 mm face scan
//!   (≈ 40 k triangles), through the whole `facesim run`; per stage wall, CPU and peak heap
//!   (`report.json`'s `stage_costs`).
//! - Mesh series: the C1 assembly + factorisation + solves on planar meshes of 2 k → 200 k
//!   triangles (`fem::bench`).
//!
//! Exponents are least-squares slopes of log(cost) on log(size). Writes scaling.json,
//! scaling.csv, summary.md and log-log charts (SVG + PNG).

use facesim::error::{Error, Result};
use facesim::observe::Observer;
use facesim::output::write_bytes_atomic;
use serde::Serialize;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Serialize)]
pub struct Point {
    pub series: String,
    pub stage: String,
    /// Voxels (CT series) or triangles (mesh series).
    pub size: f64,
    pub wall_s: f64,
    pub cpu_s: f64,
    pub peak_heap_mb: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Fit {
    pub series: String,
    pub stage: String,
    pub exponent: f64,
    /// Wall time at the largest size.
    pub largest_wall_s: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Scaling {
    pub machine: crate::study::Machine,
    pub points: Vec<Point>,
    pub fits: Vec<Fit>,
    /// Per CT size: max resident set of the process after the run (MB, cumulative maximum).
    pub max_rss_mb: Vec<(f64, f64)>,
    /// A single pass over the voxels (read every f32 once and sum) at each CT size: the memory
    /// bandwidth floor every voxel stage is compared with.
    pub voxel_pass_s: Vec<(f64, f64)>,
}

/// Least-squares slope of log y on log x.
pub fn exponent(pts: &[(f64, f64)]) -> f64 {
    let v: Vec<(f64, f64)> = pts
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    let n = v.len() as f64;
    if v.len() < 2 {
        return f64::NAN;
    }
    let (mx, my) = (
        v.iter().map(|p| p.0).sum::<f64>() / n,
        v.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = v.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = v.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

pub fn run(out: &Path, quick: bool, progress: &dyn Observer) -> Result<Scaling> {
    std::fs::create_dir_all(out).map_err(|e| Error::output(out, e))?;
    let spacings: &[f64] = if quick {
        &[2.0, 1.5]
    } else {
        &[2.0, 1.0, 0.7, 0.5, 0.45]
    };
    let mut points = Vec::new();
    let mut rss = Vec::new();
    let mut pass = Vec::new();
    let work_dir = out.join(format!(".facesim-scaling-{}", std::process::id()));
    std::fs::create_dir_all(&work_dir).map_err(|e| Error::output(&work_dir, e))?;
    for &s in spacings {
        let ct = ct_size(&work_dir, s, progress)?;
        points.extend(ct.points);
        rss.push((ct.voxels, ct.max_rss_mb));
        pass.push((ct.voxels, ct.voxel_pass_s));
    }
    let _ = std::fs::remove_dir_all(&work_dir);
    let tris: &[usize] = if quick {
        &[2_000, 8_000]
    } else {
        &[2_000, 5_000, 10_000, 20_000, 40_000, 100_000, 200_000]
    };
    for &n in tris {
        points.extend(mesh_size(n, progress)?);
    }
    let fits = fits(&points);
    let sc = Scaling {
        machine: crate::study::machine(),
        points,
        fits,
        max_rss_mb: rss,
        voxel_pass_s: pass,
    };
    write(out, &sc)?;
    progress.done();
    Ok(sc)
}

/// One CT size's measurements.
struct CtSize {
    voxels: f64,
    points: Vec<Point>,
    voxel_pass_s: f64,
    max_rss_mb: f64,
}

/// The phantom CT at spacing `s` mm through the whole pipeline, in `work_dir/ct_{s}`.
fn ct_size(work_dir: &Path, s: f64, progress: &dyn Observer) -> Result<CtSize> {
    progress.started(&format!("scaling: phantom CT at {s} mm"));
    let dir = work_dir.join(format!("ct_{s}"));
    std::fs::create_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
    let vol = facesim_validate::phantom::ct(&facesim_validate::phantom::PhantomOptions {
        spacing: [s; 3],
        // Partial-volume supersampling is for accuracy tests; it would dominate here.
        supersample: 1,
        noise_hu: 8.0,
        scan_step_mm: 1.5,
    });
    let voxels = vol.len() as f64;
    let t = std::time::Instant::now();
    let sum: f64 = vol.data.iter().map(|&x| x as f64).sum();
    let voxel_pass_s = t.elapsed().as_secs_f64();
    std::hint::black_box(sum);
    facesim::volume::nifti_io::write(&vol, &dir.join("ct.nii.gz"))?;
    drop(vol);
    facesim::mesh::ply::write(
        &facesim_validate::phantom::face_scan(1.5),
        &dir.join("face.ply"),
        facesim::mesh::ply::Encoding::BinaryLittleEndian,
    )?;
    // The C1 model's scaling (docs/lab/performance.md); the volumetric model's is measured apart.
    let text = facesim_validate::phantom::case_toml("ct.nii.gz", true)
        + "\n[solve]\nmodel = \"equilibrium\"\n";
    write_bytes_atomic(&dir.join("case.toml"), |w| w.write_all(text.as_bytes()))?;
    progress.started(&format!(
        "scaling: facesim run at {s} mm ({voxels:.0} voxels)"
    ));
    let o = run_case(dir.clone())?;
    let points = stage_points(&o, voxels);
    let max_rss_mb = facesim::meter::max_rss_mb();
    let _ = std::fs::remove_dir_all(&dir);
    Ok(CtSize {
        voxels,
        points,
        voxel_pass_s,
        max_rss_mb,
    })
}

/// The one call into the pipeline, kept alone so that it is easy to re-point.
fn run_case(dir: PathBuf) -> Result<facesim::commands::Outcome> {
    let o = facesim::commands::run(&dir, None, &facesim::observe::Quiet)?;
    Ok(o)
}

/// A CT-series point per stage in report.json's `stage_costs`.
fn stage_points(o: &facesim::commands::Outcome, voxels: f64) -> Vec<Point> {
    let mut points = Vec::new();
    for (stage, c) in &o.report.costs.0 {
        points.push(Point {
            series: "ct".into(),
            stage: stage.key().into(),
            size: voxels,
            wall_s: c.wall_s,
            cpu_s: c.cpu_s,
            peak_heap_mb: c.peak_heap_mb,
        });
    }
    points
}

/// The C1 FEM benchmark on about n triangles: a point per phase (CPU and heap for the total).
fn mesh_size(n: usize, progress: &dyn Observer) -> Result<Vec<Point>> {
    progress.started(&format!("scaling: C1 FEM on {n} triangles"));
    let m = facesim::meter::Meter::start(facesim::meter::counted_heap());
    let b = crate::bench_fem::run(n, None)?;
    let c = m.stop();
    let mut points = Vec::new();
    for (stage, wall) in [
        ("fem elements", b.seconds_elements),
        ("fem assembly", b.seconds_assembly),
        ("fem factor", b.seconds_factor),
        ("fem three solves", b.seconds_three_solves),
        ("fem total", b.seconds_total),
    ] {
        points.push(Point {
            series: "mesh".into(),
            stage: stage.into(),
            size: b.triangles as f64,
            wall_s: wall,
            cpu_s: if stage == "fem total" {
                c.cpu_s
            } else {
                f64::NAN
            },
            peak_heap_mb: if stage == "fem total" {
                c.peak_heap_mb
            } else {
                None
            },
        });
    }
    Ok(points)
}

/// A fit per (series, stage), in order of first appearance.
fn fits(points: &[Point]) -> Vec<Fit> {
    let mut fits = Vec::new();
    let mut keys: Vec<(String, String)> = points
        .iter()
        .map(|p| (p.series.clone(), p.stage.clone()))
        .collect();
    keys.dedup();
    let mut seen = Vec::new();
    for k in keys {
        if seen.contains(&k) {
            continue;
        }
        seen.push(k.clone());
        let pts: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.series == k.0 && p.stage == k.1)
            .map(|p| (p.size, p.wall_s))
            .collect();
        fits.push(Fit {
            series: k.0.clone(),
            stage: k.1.clone(),
            exponent: exponent(&pts),
            largest_wall_s: pts.last().map_or(f64::NAN, |p| p.1),
        });
    }
    fits
}

fn write(out: &Path, s: &Scaling) -> Result<()> {
    let json = serde_json::to_string_pretty(s).map_err(|e| Error::output(out, e))?;
    write_bytes_atomic(&out.join("scaling.json"), |w| w.write_all(json.as_bytes()))?;
    write_bytes_atomic(&out.join("scaling.csv"), |w| {
        writeln!(w, "series,stage,size,wall_s,cpu_s,peak_heap_mb")?;
        for p in &s.points {
            writeln!(
                w,
                "{},{},{},{},{},{}",
                p.series,
                p.stage,
                p.size,
                p.wall_s,
                p.cpu_s,
                p.peak_heap_mb.map_or(String::new(), |m| format!("{m:.1}"))
            )?;
        }
        Ok(())
    })?;
    for (series, xlabel) in [("ct", "CT voxels"), ("mesh", "skin triangles")] {
        let lines: Vec<(String, Vec<(f64, f64)>)> = s
            .fits
            .iter()
            .filter(|f| f.series == series && f.stage != "total" && f.stage != "fem total")
            .map(|f| {
                (
                    format!("{} (exponent {:.2})", f.stage, f.exponent),
                    s.points
                        .iter()
                        .filter(|p| p.series == series && p.stage == f.stage)
                        .map(|p| (p.size, p.wall_s))
                        .collect(),
                )
            })
            .collect();
        crate::study::chart::loglog(
            out,
            &format!("scaling_{series}"),
            &format!("cost against size ({xlabel}), wall time"),
            xlabel,
            &lines,
        )?;
    }
    let mut md = format!(
        "# facesim-lab bench scaling\n\nMachine: {} ({} cores, {} threads, {:.0} GB).\n\n| series | stage | exponent | wall at the largest size (s) |\n|---|---|---|---|\n",
        s.machine.cpu, s.machine.cores, s.machine.threads, s.machine.memory_gb
    );
    for f in &s.fits {
        md.push_str(&format!(
            "| {} | {} | {:.2} | {:.3} |\n",
            f.series, f.stage, f.exponent, f.largest_wall_s
        ));
    }
    md.push_str("\n| voxels | single pass over the voxels (s) | max RSS after the run (MB) |\n|---|---|---|\n");
    for ((v, p), (_, r)) in s.voxel_pass_s.iter().zip(&s.max_rss_mb) {
        md.push_str(&format!("| {v:.0} | {p:.4} | {r:.0} |\n"));
    }
    md.push_str("\n![ct](scaling_ct.png)\n![mesh](scaling_mesh.png)\n");
    write_bytes_atomic(&out.join("summary.md"), |w| w.write_all(md.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponent_of_a_power_law_is_exact() {
        let pts: Vec<(f64, f64)> = [1e3, 1e4, 1e5, 1e6]
            .iter()
            .map(|&x| (x, 3.0 * f64::powf(x, 1.37)))
            .collect();
        assert!((exponent(&pts) - 1.37).abs() < 1e-12);
        // x log x between 1e3 and 1e6 reads as an exponent a little above 1.
        let nlogn: Vec<(f64, f64)> = [1e3, 1e6].iter().map(|&x| (x, x * f64::ln(x))).collect();
        let e = exponent(&nlogn);
        assert!(e > 1.0 && e < 1.15, "{e}");
        assert!(exponent(&pts[..1]).is_nan());
    }
}

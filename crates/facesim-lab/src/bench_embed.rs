//! `facesim bench embed [--quick] --out DIR` (issue 6 §3): what solving a coarse model and
//! carrying a dense face scan along by shell embedding costs in accuracy, and what it saves.
//!
//! The phantom head with a dense face scan (0.75 mm vertex spacing, ~160 k triangles; 1.5 mm,
//! ~40 k, with --quick) and the sample plan (6 mm mandible advancement) is run through
//! `facesim run` on the full scan (the reference) and with `[solve] coarse_triangles` at several
//! sizes; each carried scan is compared with the reference vertex by vertex over the movable
//! skin (mean / 90th percentile / max distance, mm). A scan of ~500 k vertices (0.3 mm) is run
//! with the coarse model only (solving it whole is out of reach: the 160 k-triangle scan
//! already takes minutes and 6.6 GB). Writes embed.json, embed.csv, summary.md and the
//! accuracy-vs-time chart.

use crate::study::face::FaceRow;
use facesim::compare::stats;
use facesim::error::{Error, Result};
use facesim::mesh::{norm, sub};
use facesim::observe::Observer;
use facesim::output::write_bytes_atomic;
use serde::Serialize;
use std::path::Path;

#[derive(Serialize)]
pub struct EmbedBench {
    pub machine: crate::study::Machine,
    pub rows: Vec<FaceRow>,
    /// Per row: (scan vertices, solved coarse triangles, total wall s, max RSS MB so far).
    pub runs: Vec<(usize, usize, f64, f64)>,
}

const MOVABLE: ([f64; 3], f64) = ([0.0, -60.0, -45.0], 70.0);

pub fn run(out: &Path, quick: bool, progress: &dyn Observer) -> Result<EmbedBench> {
    std::fs::create_dir_all(out).map_err(|e| Error::output(out, e))?;
    let work = out.join(format!(".facesim-embed-{}", std::process::id()));
    std::fs::create_dir_all(&work).map_err(|e| Error::output(&work, e))?;
    // The case files name the CT and scan by absolute path (a relative one would be taken
    // relative to the case directory).
    let work = std::path::absolute(&work).map_err(|e| Error::output(&work, e))?;
    let ct = work.join("ct.nii.gz");
    facesim::volume::nifti_io::write(
        &facesim::phantom::ct(&facesim::phantom::PhantomOptions::default()),
        &ct,
    )?;
    let (step, coarse): (f64, &[usize]) = if quick {
        (1.5, &[4_000, 10_000])
    } else {
        (0.75, &[5_000, 10_000, 20_000, 40_000])
    };
    let mut rows = Vec::new();
    let mut runs = Vec::new();
    let one = |scan_step: f64, target: usize, struts: bool| -> Result<facesim::pipeline::Outcome> {
        let dir = work.join(format!("scan_{scan_step}_{target}_{struts}"));
        std::fs::create_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
        let scan = work.join(format!("face_{scan_step}.ply"));
        if !scan.is_file() {
            facesim::mesh::ply::write(
                &facesim::phantom::face_scan(scan_step),
                &scan,
                facesim::mesh::ply::Encoding::BinaryLittleEndian,
            )?;
        }
        let text = format!(
            "name = \"embed-bench\"\n[ct]\npath = \"{}\"\n[skin]\npath = \"{}\"\n[springs]\nstruts = {struts}\n\
             [surface]\nmovable = {{ sphere = {{ center = [{}, {}, {}], radius = {} }} }}\n\
             [[osteotomy]]\nname = \"mandible\"\nregion = {{ box = {{ min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] }} }}\n\
             translate = [0.0, -6.0, 0.0]\n[solve]\ncoarse_triangles = {target}\n",
            ct.display(),
            scan.display(),
            MOVABLE.0[0],
            MOVABLE.0[1],
            MOVABLE.0[2],
            MOVABLE.1
        );
        write_bytes_atomic(&dir.join("case.toml"), |w| w.write_all(text.as_bytes()))?;
        progress.started(&format!(
            "bench embed: {scan_step} mm scan, struts {struts}, {}",
            if target == 0 {
                "full mesh".to_string()
            } else {
                format!("coarse {target}")
            }
        ));
        let o = facesim::pipeline::run(&dir, None, &facesim::observe::Quiet)?;
        let _ = std::fs::remove_dir_all(dir.join("out"));
        Ok(o)
    };
    let wall = |o: &facesim::pipeline::Outcome| {
        o.report
            .costs
            .get(facesim::report::Stage::Total)
            .map_or(f64::NAN, |c| c.wall_s)
    };
    let movable = |p: &[f64; 3]| norm(sub(*p, MOVABLE.0)) <= MOVABLE.1;
    for struts in [true, false] {
        let tag = if struts { "struts" } else { "no struts" };
        let full = one(step, 0, struts)?;
        let ref_d: Vec<([f64; 3], bool)> = full
            .skin
            .vertices
            .iter()
            .zip(&full.face_post.vertices)
            .map(|(a, b)| (sub(*b, *a), movable(a)))
            .collect();
        let mean_move = {
            let v: Vec<f64> = ref_d.iter().filter(|d| d.1).map(|d| norm(d.0)).collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        };
        let nt = full.skin.triangles.len();
        let row = |method: String,
                   res: String,
                   o: &facesim::pipeline::Outcome,
                   dist: Vec<f64>,
                   reference: bool| FaceRow {
            case: format!("phantom, {step} mm scan ({nt} tri)"),
            method,
            family: "C1 surface FEM".into(),
            resolution: res,
            unknowns: o.report.counts.unknowns,
            wall_s: wall(o),
            peak_mb: Some(facesim::meter::max_rss_mb()),
            distance: Some(stats(&dist)),
            // Each full-scan solve is the reference of its own spring set (not a plotted point).
            is_reference: reference,
            mean_displacement_mm: Some(mean_move),
            note: Some(format!("reference mean displacement {mean_move:.3} mm")),
        };
        runs.push((
            full.skin.vertices.len(),
            0,
            wall(&full),
            facesim::meter::max_rss_mb(),
        ));
        rows.push(row(
            format!("full scan ({tag})"),
            format!("{nt} tri"),
            &full,
            vec![0.0],
            true,
        ));
        for &c in coarse {
            let o = one(step, c, struts)?;
            let solved = o.report.surfaces.coarse.as_ref().map_or(0, |c| c.triangles);
            let dist: Vec<f64> = o
                .skin
                .vertices
                .iter()
                .zip(&o.face_post.vertices)
                .zip(&ref_d)
                .filter(|(_, r)| r.1)
                .map(|((a, b), r)| norm(sub(sub(*b, *a), r.0)))
                .collect();
            runs.push((
                o.skin.vertices.len(),
                solved,
                wall(&o),
                facesim::meter::max_rss_mb(),
            ));
            rows.push(row(
                format!("coarse + shell embedding ({tag})"),
                format!("{solved} tri"),
                &o,
                dist,
                false,
            ));
        }
    }
    if !quick {
        // ~500 k scan vertices on a 20 k model: cost only.
        let o = one(0.3, 20_000, true)?;
        let solved = o.report.surfaces.coarse.as_ref().map_or(0, |c| c.triangles);
        runs.push((
            o.skin.vertices.len(),
            solved,
            wall(&o),
            facesim::meter::max_rss_mb(),
        ));
    }
    let _ = std::fs::remove_dir_all(&work);
    let b = EmbedBench {
        machine: crate::study::machine(),
        rows,
        runs,
    };
    let json = serde_json::to_string_pretty(&b).map_err(|e| Error::output(out, e))?;
    write_bytes_atomic(&out.join("embed.json"), |w| w.write_all(json.as_bytes()))?;
    write_bytes_atomic(&out.join("embed.csv"), |w| {
        writeln!(w, "scan_vertices,coarse_triangles,wall_s,max_rss_mb")?;
        for r in &b.runs {
            writeln!(w, "{},{},{:.3},{:.0}", r.0, r.1, r.2, r.3)?;
        }
        Ok(())
    })?;
    let mut md = String::from(
        "Distances to the full-scan solve with the same spring set, over the movable scan vertices.\n\n| model | solved | wall (s) | speedup | mean (mm) | p90 (mm) | max (mm) |\n|---|---|---|---|---|---|---|\n",
    );
    let mut t_full = f64::NAN;
    for r in &b.rows {
        if r.method.starts_with("full") {
            t_full = r.wall_s;
        }
        let d = r.distance.as_ref();
        md += &format!(
            "| {} | {} | {:.2} | {:.1}× | {:.3} | {:.3} | {:.3} |\n",
            r.method,
            r.resolution,
            r.wall_s,
            t_full / r.wall_s,
            d.map_or(f64::NAN, |d| d.mean),
            d.map_or(f64::NAN, |d| d.p90),
            d.map_or(f64::NAN, |d| d.max)
        );
    }
    md += "\n| scan vertices | coarse triangles (0 = full) | wall (s) | max RSS so far (MB) |\n|---|---|---|---|\n";
    for r in &b.runs {
        md += &format!("| {} | {} | {:.2} | {:.0} |\n", r.0, r.1, r.2, r.3);
    }
    write_bytes_atomic(&out.join("summary.md"), |w| w.write_all(md.as_bytes()))?;
    let title = format!("{}, each vs the full scan with its springs", b.rows[0].case);
    crate::study::chart::accuracy_vs_time(out, "embed_accuracy_vs_time", &title, &b.rows)?;
    Ok(b)
}

//! `facesim-lab bench embed [--quick] --out DIR`: what solving a coarse model and
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
use facesim::commands::Outcome;
use facesim::compare::stats;
use facesim::error::{Error, Result};
use facesim::observe::Observer;
use facesim::output::write_bytes_atomic;
use facesim::vec3::{norm, sub};
use serde::Serialize;
use std::path::{Path, PathBuf};

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
    let bench = Workspace::new(out, progress)?;
    let (step, coarse): (f64, &[usize]) = if quick {
        (1.5, &[4_000, 10_000])
    } else {
        (0.75, &[5_000, 10_000, 20_000, 40_000])
    };
    let mut rows = Vec::new();
    let mut runs = Vec::new();
    for struts in [true, false] {
        bench.spring_set(step, coarse, struts, &mut rows, &mut runs)?;
    }
    if !quick {
        // ~500 k scan vertices on a 20 k model: cost only.
        let o = bench.one(0.3, 20_000, true)?;
        runs.push(run_row(&o, coarse_triangles(&o)));
    }
    let _ = std::fs::remove_dir_all(&bench.work);
    let b = EmbedBench {
        machine: crate::study::machine(),
        rows,
        runs,
    };
    write(out, &b)?;
    Ok(b)
}

/// The scratch directory with the phantom CT every case shares.
struct Workspace<'a> {
    work: PathBuf,
    ct: PathBuf,
    progress: &'a dyn Observer,
}

impl<'a> Workspace<'a> {
    fn new(out: &Path, progress: &'a dyn Observer) -> Result<Workspace<'a>> {
        let work = out.join(format!(".facesim-embed-{}", std::process::id()));
        std::fs::create_dir_all(&work).map_err(|e| Error::output(&work, e))?;
        // The case files name the CT and scan by absolute path (a relative one would be taken
        // relative to the case directory).
        let work = std::path::absolute(&work).map_err(|e| Error::output(&work, e))?;
        let ct = work.join("ct.nii.gz");
        facesim::volume::nifti_io::write(
            &facesim_validate::phantom::ct(&facesim_validate::phantom::PhantomOptions::default()),
            &ct,
        )?;
        Ok(Workspace { work, ct, progress })
    }

    /// Runs the pipeline on a scan of `scan_step` mm (written once), solving the full scan
    /// (`target` 0) or a coarse model of `target` triangles.
    fn one(&self, scan_step: f64, target: usize, struts: bool) -> Result<Outcome> {
        let dir = self
            .work
            .join(format!("scan_{scan_step}_{target}_{struts}"));
        std::fs::create_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
        let scan = self.work.join(format!("face_{scan_step}.ply"));
        if !scan.is_file() {
            facesim::mesh::ply::write(
                &facesim_validate::phantom::face_scan(scan_step),
                &scan,
                facesim::mesh::ply::Encoding::BinaryLittleEndian,
            )?;
        }
        let text = case_toml(&self.ct, &scan, target, struts);
        write_bytes_atomic(&dir.join("case.toml"), |w| w.write_all(text.as_bytes()))?;
        self.progress.started(&format!(
            "bench embed: {scan_step} mm scan, struts {struts}, {}",
            if target == 0 {
                "full mesh".to_string()
            } else {
                format!("coarse {target}")
            }
        ));
        run_case(dir)
    }

    /// The full-scan reference and every coarse model for one spring set (struts or not).
    fn spring_set(
        &self,
        step: f64,
        coarse: &[usize],
        struts: bool,
        rows: &mut Vec<FaceRow>,
        runs: &mut Vec<RunRow>,
    ) -> Result<()> {
        let tag = if struts { "struts" } else { "no struts" };
        let full = self.one(step, 0, struts)?;
        let reference = Reference::new(&full, step);
        runs.push(run_row(&full, 0));
        rows.push(reference.row(
            format!("full scan ({tag})"),
            format!("{} tri", full.skin.triangles.len()),
            &full,
            vec![0.0],
            true,
        ));
        for &c in coarse {
            let o = self.one(step, c, struts)?;
            let solved = coarse_triangles(&o);
            let dist = reference.distances(&o);
            runs.push(run_row(&o, solved));
            rows.push(reference.row(
                format!("coarse + shell embedding ({tag})"),
                format!("{solved} tri"),
                &o,
                dist,
                false,
            ));
        }
        Ok(())
    }
}

/// The one call into the pipeline, kept alone so that it is easy to re-point.
fn run_case(dir: PathBuf) -> Result<Outcome> {
    let o = facesim::commands::run(&dir, None, &facesim::observe::Quiet)?;
    let _ = std::fs::remove_dir_all(dir.join("out"));
    Ok(o)
}

fn case_toml(ct: &Path, scan: &Path, target: usize, struts: bool) -> String {
    format!(
        "name = \"embed-bench\"\n[ct]\npath = \"{}\"\n[skin]\npath = \"{}\"\n[springs]\nstruts = {struts}\n\
         [surface]\nmovable = {{ sphere = {{ center = [{}, {}, {}], radius = {} }} }}\n\
         [[osteotomy]]\nname = \"mandible\"\nregion = {{ box = {{ min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] }} }}\n\
         translate = [0.0, -6.0, 0.0]\n[solve]\nmodel = \"equilibrium\"\ncoarse_triangles = {target}\n",
        ct.display(),
        scan.display(),
        MOVABLE.0[0],
        MOVABLE.0[1],
        MOVABLE.0[2],
        MOVABLE.1
    )
}

/// (scan vertices, solved coarse triangles, total wall s, max RSS MB so far).
type RunRow = (usize, usize, f64, f64);

fn run_row(o: &Outcome, solved: usize) -> RunRow {
    (
        o.skin.vertices.len(),
        solved,
        wall(o),
        facesim::meter::max_rss_mb(),
    )
}

fn wall(o: &Outcome) -> f64 {
    o.report
        .costs
        .get(facesim::pipeline::Stage::Total)
        .map_or(f64::NAN, |c| c.wall_s)
}

fn coarse_triangles(o: &Outcome) -> usize {
    o.report.surfaces.coarse.as_ref().map_or(0, |c| c.triangles)
}

fn movable(p: &[f64; 3]) -> bool {
    norm(sub(*p, MOVABLE.0)) <= MOVABLE.1
}

/// A full-scan solve: each vertex's displacement and whether it is movable.
struct Reference {
    displacement: Vec<([f64; 3], bool)>,
    mean_move: f64,
    case: String,
}

impl Reference {
    fn new(full: &Outcome, step: f64) -> Reference {
        let displacement: Vec<([f64; 3], bool)> = full
            .skin
            .vertices
            .iter()
            .zip(&full.face_post.vertices)
            .map(|(a, b)| (sub(*b, *a), movable(a)))
            .collect();
        let mean_move = {
            let v: Vec<f64> = displacement
                .iter()
                .filter(|d| d.1)
                .map(|d| norm(d.0))
                .collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        };
        let nt = full.skin.triangles.len();
        Reference {
            displacement,
            mean_move,
            case: format!("phantom, {step} mm scan ({nt} tri)"),
        }
    }

    /// Per movable vertex, the distance between a carried scan's displacement and this one's.
    fn distances(&self, o: &Outcome) -> Vec<f64> {
        o.skin
            .vertices
            .iter()
            .zip(&o.face_post.vertices)
            .zip(&self.displacement)
            .filter(|(_, r)| r.1)
            .map(|((a, b), r)| norm(sub(sub(*b, *a), r.0)))
            .collect()
    }

    fn row(
        &self,
        method: String,
        res: String,
        o: &Outcome,
        dist: Vec<f64>,
        reference: bool,
    ) -> FaceRow {
        let mean_move = self.mean_move;
        FaceRow {
            case: self.case.clone(),
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
            elements: None,
            regions: Vec::new(),
            distance_c1: None,
            note: Some(format!("reference mean displacement {mean_move:.3} mm")),
        }
    }
}

/// embed.json, embed.csv, summary.md and the accuracy-vs-time chart.
fn write(out: &Path, b: &EmbedBench) -> Result<()> {
    let json = serde_json::to_string_pretty(b).map_err(|e| Error::output(out, e))?;
    write_bytes_atomic(&out.join("embed.json"), |w| w.write_all(json.as_bytes()))?;
    write_bytes_atomic(&out.join("embed.csv"), |w| {
        writeln!(w, "scan_vertices,coarse_triangles,wall_s,max_rss_mb")?;
        for r in &b.runs {
            writeln!(w, "{},{},{:.3},{:.0}", r.0, r.1, r.2, r.3)?;
        }
        Ok(())
    })?;
    let md = summary(b);
    write_bytes_atomic(&out.join("summary.md"), |w| w.write_all(md.as_bytes()))?;
    let title = format!("{}, each vs the full scan with its springs", b.rows[0].case);
    crate::study::chart::accuracy_vs_time(out, "embed_accuracy_vs_time", &title, &b.rows)
}

fn summary(b: &EmbedBench) -> String {
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
    md
}

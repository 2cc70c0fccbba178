//! `facesim-lab bench replan`: the cost of `PlanBasis::predict` (one plan's face from the stored basis)
//! on the real CT face with the volumetric model, against a bare pass over the basis's memory and
//! against the full run that built it (docs/lab/performance.md "Re-planning").

use facesim::case::{Case, Osteotomy, SolveModel};
use facesim::error::{Error, Result};
use facesim::plan::{PlanBasis, file};
use std::path::Path;
use std::time::Instant;

pub struct ReplanBench {
    pub face_vertices: usize,
    pub segments: usize,
    /// The run that built the basis (s), and its plan_basis stage (s).
    pub run_s: f64,
    pub basis_s: f64,
    /// Median over the repeats (ms): predict with every entry of M non-zero; a bare sum over the
    /// same columns' memory (the floor for any method reading the basis).
    pub predict_ms: f64,
    pub memory_pass_ms: f64,
    pub repeats: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Run `case_toml` (its model set to "tet") into `out`, read its basis back and time predict.
pub fn run(case_toml: &Path, out: &Path, repeats: usize) -> Result<ReplanBench> {
    // Case::load resolves the case's paths against its directory.
    let (mut case, _) = Case::load(case_toml)?;
    case.solve.model = SolveModel::Tet;
    let outcome = facesim::commands::run_case(case, out, &facesim::observe::Quiet)?;
    let run_s = outcome.report.costs.wall_s(facesim::pipeline::Stage::Total);
    let basis_s = outcome
        .report
        .costs
        .wall_s(facesim::pipeline::Stage::PlanBasis);
    let basis: PlanBasis = file::read(&out.join(file::FILE_NAME))?;
    // A plan with rotation and translation on every segment: no entry of M is zero.
    let plan: Vec<Osteotomy> = basis
        .segments
        .iter()
        .map(|s| Osteotomy {
            name: s.name.clone(),
            region: s.region.clone(),
            translate: [0.5, -4.0, 1.0],
            rotate_deg: [2.0, -1.5, 1.0],
            pivot: s.pivot,
        })
        .collect();
    if basis.segments.is_empty() {
        return Err(Error::config("bench replan: the run built no plan basis"));
    }
    let repeats = repeats.max(3);
    let mut predict = Vec::with_capacity(repeats);
    let mut checksum = 0.0;
    for _ in 0..repeats {
        let t = Instant::now();
        let f = basis.predict(&plan)?;
        predict.push(t.elapsed().as_secs_f64() * 1e3);
        checksum += f[0][0];
    }
    let mut pass = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t = Instant::now();
        let mut s = 0.0;
        for seg in &basis.segments {
            for c in &seg.columns {
                s += c.iter().map(|v| v[0] + v[1] + v[2]).sum::<f64>();
            }
        }
        pass.push(t.elapsed().as_secs_f64() * 1e3);
        checksum += s;
    }
    std::hint::black_box(checksum);
    Ok(ReplanBench {
        face_vertices: basis.face_pre.len(),
        segments: basis.segments.len(),
        run_s,
        basis_s,
        predict_ms: median(predict),
        memory_pass_ms: median(pass),
        repeats,
    })
}

//! The paper's benchmarks (Alterovitz & Goldberg 2003; docs/lab/study.md) run through every
//! integrator, with the three error metrics per step against the implicit reference, and the
//! stability table (critical steps, explicit at 0.9 and 1.1 h_crit).

use super::metrics::{
    Closed, enclosed_volume, interior_error, polygon_area, symmetric_difference_area,
    symmetric_difference_volume,
};
use crate::dynamics::{
    Block, Integrator, MP1, MP2, MP3, MaterialSi, critical_step, integrate, relative_energy_error,
};
use serde::Serialize;
use std::time::Instant;

pub const H: f64 = 1.0 / 30.0;
pub const RAYLEIGH: (f64, f64) = (1.0, 0.1);
/// Rod gravity (docs/lab/study.md: 5 cm/s²).
pub const ROD_G: f64 = 0.05;
/// Rays per side for the 3-D surface error.
const RAY_GRID: usize = 96;

#[derive(Clone, Debug, Serialize)]
pub struct Series {
    pub integrator: Integrator,
    /// "diverged at step N (t = … s)" — the series stops there.
    pub diverged: Option<String>,
    pub wall_s: f64,
    pub time: Vec<f64>,
    pub energy: Vec<f64>,
    pub surface: Vec<f64>,
    pub interior: Vec<f64>,
    /// Relative energy-norm distance of the last state from the static solution.
    pub final_vs_static: Option<f64>,
}

impl Series {
    pub fn mean(v: &[f64]) -> f64 {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Benchmark {
    pub name: String,
    pub material: MaterialSi,
    pub dim: usize,
    pub mesh: String,
    pub free_dofs: usize,
    pub h: f64,
    pub steps: usize,
    pub series: Vec<Series>,
}

fn static_solution(b: &Block) -> Vec<f64> {
    // Quasi-static at a time after the needle stopped is the static state.
    integrate(b, Integrator::QuasiStatic, 100.0, 1, RAYLEIGH)
        .history
        .remove(0)
}

/// Surface error of u against the reference state (2-D exact, 3-D ray-integrated).
fn surface_error(b: &Block, u: &[f64], reference: &[f64]) -> f64 {
    let (p, q) = (b.deformed(u), b.deformed(reference));
    if b.dim == 2 {
        let poly = |x: &[[f64; 3]]| {
            b.outline
                .iter()
                .map(|&v| [x[v][0], x[v][1]])
                .collect::<Vec<_>>()
        };
        let (a, r) = (poly(&p), poly(&q));
        symmetric_difference_area(&a, &r) / polygon_area(&r).abs()
    } else {
        let a = Closed {
            points: &p,
            triangles: &b.boundary_triangles,
        };
        let r = Closed {
            points: &q,
            triangles: &b.boundary_triangles,
        };
        symmetric_difference_volume(&a, &r, RAY_GRID).0 / enclosed_volume(&r).abs()
    }
}

pub fn run_benchmark(
    name: &str,
    b: &Block,
    mat: MaterialSi,
    mesh: String,
    steps: usize,
) -> Benchmark {
    let runs: Vec<(crate::dynamics::Run, f64)> = Integrator::ALL
        .iter()
        .map(|&i| {
            let t = Instant::now();
            let r = integrate(b, i, H, steps, RAYLEIGH);
            (r, t.elapsed().as_secs_f64())
        })
        .collect();
    let reference = &runs[0].0.history;
    let stat = static_solution(b);
    let series = runs
        .iter()
        .map(|(r, wall)| {
            let n = r.history.len();
            let mut s = Series {
                integrator: r.integrator,
                diverged: r.diverged.clone(),
                wall_s: *wall,
                time: (1..=n).map(|k| k as f64 * H).collect(),
                energy: Vec::with_capacity(n),
                surface: Vec::with_capacity(n),
                interior: Vec::with_capacity(n),
                final_vs_static: r
                    .history
                    .last()
                    .filter(|_| r.diverged.is_none())
                    .map(|u| relative_energy_error(b, u, &stat)),
            };
            for (u, uref) in r.history.iter().zip(reference) {
                s.energy.push(relative_energy_error(b, u, uref));
                s.surface.push(surface_error(b, u, uref));
                s.interior
                    .push(interior_error(&b.node_weights, b.dim, u, uref));
            }
            s
        })
        .collect();
    Benchmark {
        name: name.into(),
        material: mat,
        dim: b.dim,
        mesh,
        free_dofs: b.free.len(),
        h: H,
        steps,
        series,
    }
}

/// The three benchmarks: block MP1, block MP2 (n×n quads) and the rod (MP3).
pub fn all(quick: bool) -> Vec<Benchmark> {
    // The block stays 8×8 in both modes: on 16×16 explicit integration of MP1 at h = 1/30 s
    // already diverges (the explicit βK damping bound; see `stability`), which would leave no
    // ordering to compare.
    let (n, steps_block, rod, steps_rod) = if quick {
        (8, 300, [2, 4, 2], 450)
    } else {
        (8, 600, [4, 8, 4], 900)
    };
    let mut out = Vec::new();
    for (name, mat) in [("block MP1", MP1), ("block MP2", MP2)] {
        let b = Block::new(n, mat);
        out.push(run_benchmark(
            name,
            &b,
            mat,
            format!("{n}×{n} bilinear quads, plane strain"),
            steps_block,
        ));
    }
    let r = Block::rod(rod[0], rod[1], rod[2], MP3, ROD_G);
    out.push(run_benchmark(
        "rod MP3",
        &r,
        MP3,
        format!("{}×{}×{} trilinear hexes", rod[0], rod[1], rod[2]),
        steps_rod,
    ));
    out
}

#[derive(Clone, Debug, Serialize)]
pub struct StabilityRow {
    pub problem: String,
    pub integrator: Integrator,
    /// Undamped central-difference limit 2/ω_max from the largest generalised eigenvalue.
    pub h_crit: f64,
    pub at_0_9: String,
    pub at_1_1: String,
    pub at_benchmark_h: String,
}

/// Explicit integration at 0.9 h_crit and 1.1 h_crit (undamped, as the eigenvalue bound
/// assumes) and at the benchmark's h = 1/30 s (damped): MP2 on the block, and MP1 on the 8×8 and
/// (full study) 16×16 blocks, where refinement alone makes h = 1/30 s unstable.
pub fn stability(quick: bool) -> Vec<StabilityRow> {
    let steps = if quick { 1500 } else { 3000 };
    let mut problems = vec![("MP2", MP2, if quick { 6 } else { 8 }), ("MP1", MP1, 8)];
    if !quick {
        problems.push(("MP1", MP1, 16));
    }
    let verdict = |r: &crate::dynamics::Run| match &r.diverged {
        Some(d) => d.clone(),
        None => {
            let peak = r
                .history
                .iter()
                .flatten()
                .fold(0.0f64, |m, x| m.max(x.abs()));
            format!(
                "bounded over {} steps (peak |u| {peak:.3} m)",
                r.history.len()
            )
        }
    };
    let mut rows = Vec::new();
    for (name, mat, n) in problems {
        let b = Block::new(n, mat);
        for integ in [Integrator::ExplicitLumped, Integrator::ExplicitConsistent] {
            let hc = critical_step(&b, integ == Integrator::ExplicitLumped);
            rows.push(StabilityRow {
                problem: format!("block {name}, {n}×{n}"),
                integrator: integ,
                h_crit: hc,
                at_0_9: verdict(&integrate(&b, integ, 0.9 * hc, steps, (0.0, 0.0))),
                at_1_1: verdict(&integrate(&b, integ, 1.1 * hc, steps, (0.0, 0.0))),
                at_benchmark_h: verdict(&integrate(&b, integ, H, 120, RAYLEIGH)),
            });
        }
    }
    rows
}

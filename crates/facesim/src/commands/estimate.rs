//! `facesim estimate` (docs/guide/cohort.md "Resources from the model"): a run's peak memory and wall
//! time, predicted before it runs from what sets them. For the volumetric model that is the
//! Cholesky factor: the run's own mesh is built and its stiffness analysed symbolically (no
//! value is computed), giving the factor's nonzeros and operations. The C1 models' cost is small
//! and nearly constant.
//!
//! The coefficients below were fitted to measured peaks (resident set, `/usr/bin/time`) and wall
//! times of `facesim run` on the bundled samples and 2.5 mm phantom cohorts, then raised so
//! that no fitted case is under-predicted; docs/guide/cohort.md has the table of predicted against
//! measured, on cases the fit did not see too.

use crate::error::Result;
use crate::observe::Observer;
use crate::pipeline::{Recorder, inputs, prepare};
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// What `facesim estimate` prints (JSON).
#[derive(Serialize, Debug, Clone)]
pub struct Estimate {
    /// `tet` or the C1 model's name.
    pub model: String,
    /// Worker threads the run would use (`--threads`, default all cores).
    pub threads: usize,
    pub ct_voxels: usize,
    pub scan_vertices: usize,
    /// The volumetric model's system (absent for the C1 models, or when no bone moves).
    pub system: Option<System>,
    /// Predicted peak resident memory of the run (MB, 10⁶ bytes).
    pub peak_mem_mb: f64,
    /// Predicted wall time of the run (s) on a machine like docs/guide/cohort.md's.
    pub wall_s: f64,
    /// What the estimate itself took (s).
    pub seconds: f64,
}

/// The factor a volumetric run makes.
#[derive(Serialize, Debug, Clone)]
pub struct System {
    pub nodes: usize,
    pub elements: usize,
    pub unknowns: usize,
    /// `direct`, or `pcg-pmultigrid` for a 10-node system whose factor would exceed 2 GB (as
    /// report.json `tet.solver`).
    pub solver: String,
    /// The factor's nonzeros: the run's, or with `pcg-pmultigrid` its coarse level's.
    pub factor_nonzeros: usize,
    /// Floating-point operations of one numeric factorisation (10⁹).
    pub factor_gflop: f64,
    /// With `pcg-pmultigrid`: the 10-node operator's 3 × 3 blocks (lower triangle).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub operator_blocks: Option<usize>,
}

/// The fitted memory model, times [`MEMORY_MARGIN`]: a fixed part (the program, the landmarks, the
/// face), the CT (its HU as f32, the labels and masks: bytes per voxel) and the factor (its
/// values, 8 bytes per nonzero of the run's factor, which the estimate's slightly larger system
/// over-counts, and the workspace beside it). Fitted by least squares on 16 runs (docs/guide/cohort.md
/// "Resources from the model"): 239 MB + 9.28 bytes per estimated nonzero, the CT at 8 bytes a
/// voxel; measured / fitted from 0.85 to 1.12.
const BASE_MB: f64 = 239.0;
const BYTES_PER_VOXEL: f64 = 8.0;
const BYTES_PER_FACTOR_NONZERO: f64 = 9.28;
/// A 10-node system solved iteratively (`pcg-pmultigrid`): its memory is the operator, not a
/// factor. Per 3 × 3 lower block: the assembled stiffness's nine (at the diagonal six) triplets
/// of 24 bytes, the block in f64 and its index (80), its f32 copy for the cycle (36) and the
/// conjugate-gradient batches' vectors (about 70 per block at 13 blocks a node): 400 bytes;
/// the coarse level's factor as a direct factor. Against the two runs measured (jaws and the
/// real CT at the default size, peak resident 2.92 and 2.20 GB) the fit without the margin
/// gives 1.05 and 0.99 of them.
const BYTES_PER_OPERATOR_BLOCK: f64 = 400.0;
/// Its wall time per 3 × 3 block: the conjugate-gradient products and the cycle over the run's
/// solves and the plan basis's; measured 16.0 µs (jaws, 4.94 M blocks, 79 s) and 13.2 µs (real
/// CT, 3.80 M blocks, 50 s) on the 2-core machine of docs/guide/cohort.md: the larger.
const SECONDS_PER_OPERATOR_BLOCK: f64 = 16.0e-6;
/// The C1 models: their factor is the face's (tens of MB), their peak 100–330 MB on every
/// sample and phantom measured (docs/guide/cohort.md): the largest per model, with no size term.
const EQUILIBRIUM_MB: f64 = 290.0;
const KOCH1996_MB: f64 = 200.0;
/// Wall time: a fixed part and the factorisation's operations (one factorisation and the solves
/// and plan basis around it), fitted on the same runs: 3.4 s + 0.0334 s per 10⁹ operations
/// on the 2-core machine of docs/guide/cohort.md.
const SECONDS_BASE: f64 = 3.4;
const SECONDS_PER_GFLOP: f64 = 0.0334;
/// The C1 models' wall time: 1.9–3.6 s (equilibrium) and 0.7–1.9 s (koch1996) measured.
const EQUILIBRIUM_S: f64 = 3.2;
const KOCH1996_S: f64 = 1.7;
/// The predictions are the fit times these, so that no run measured is under-predicted: the
/// memory fit's largest measured / fitted was 1.12 on the runs it was fitted to, and 1.15 left a
/// held-out 2 mm phantom's Le Fort I 4 % under (docs/guide/cohort.md), so memory has 1.2.
const MEMORY_MARGIN: f64 = 1.2;
const TIME_MARGIN: f64 = 1.15;

/// `facesim estimate CASE`: read the case and its inputs, run the stages before the model, and
/// for the volumetric model build its mesh and analyse its factor.
pub fn estimate(case_path: &Path, overrides: &toml::Table, obs: &dyn Observer) -> Result<Estimate> {
    let start = Instant::now();
    let mut rec = Recorder::new(obs);
    let (inputs, _) = inputs::read_with(case_path, overrides, &mut rec)?;
    let scene = prepare(inputs, &mut rec)?;
    let case = &scene.case;
    let ct_voxels = scene.vol.data.len();
    let scan_vertices = scene
        .face
        .fine
        .as_ref()
        .unwrap_or(&scene.face.skin)
        .vertices
        .len();
    let threads = rayon::current_num_threads();
    let c1 = case.solve.model.on_springs();
    let system = if c1 {
        None
    } else {
        crate::model::volumetric::system_size(&scene, case)?.map(|s| System {
            nodes: s.nodes,
            elements: s.elements,
            unknowns: s.unknowns,
            solver: if s.iterative_blocks.is_some() {
                "pcg-pmultigrid"
            } else {
                "direct"
            }
            .into(),
            factor_nonzeros: s.factor_nonzeros,
            factor_gflop: s.factor_flops / 1e9,
            operator_blocks: s.iterative_blocks,
        })
    };
    let vox = ct_voxels as f64;
    let (mem_mb, wall_s) = match &system {
        Some(
            sys @ System {
                operator_blocks: Some(blocks),
                ..
            },
        ) => {
            // The 10-node system solved iteratively. `[uncertainty] samples` re-solve it one at
            // a time beside the run (`Volumetric::solves_at_once`). Not measured: a bound that
            // counts each sample as a second operator in memory and a whole run in time.
            let blocks = *blocks as f64;
            let samples = case.uncertainty.samples as f64;
            let operators = if samples > 0.0 { 2.0 } else { 1.0 };
            let run_s = blocks * SECONDS_PER_OPERATOR_BLOCK;
            (
                BASE_MB
                    + vox * BYTES_PER_VOXEL / 1e6
                    + sys.factor_nonzeros as f64 * BYTES_PER_FACTOR_NONZERO / 1e6
                    + operators * blocks * BYTES_PER_OPERATOR_BLOCK / 1e6,
                SECONDS_BASE + (1.0 + samples) * run_s,
            )
        }
        Some(sys) => {
            // `[uncertainty] samples` re-solve the model, several factors side by side (as many
            // as `fem::cholesky::factorisations_at_once`), each beside the run's own. Not
            // measured: a bound from the same coefficients.
            let samples = case.uncertainty.samples as f64;
            let at_once = crate::fem::cholesky::factorisations_at_once(sys.factor_nonzeros) as f64;
            let factors = if samples > 0.0 { 1.0 + at_once } else { 1.0 };
            let factor_mb = sys.factor_nonzeros as f64 * BYTES_PER_FACTOR_NONZERO / 1e6;
            (
                BASE_MB + vox * BYTES_PER_VOXEL / 1e6 + factors * factor_mb,
                SECONDS_BASE + (1.0 + samples / at_once) * sys.factor_gflop * SECONDS_PER_GFLOP,
            )
        }
        // A C1 model (or no bone moves: the run stops before its mesh).
        None => match case.solve.model {
            crate::case::SolveModel::Koch1996 => (KOCH1996_MB, KOCH1996_S),
            _ => (EQUILIBRIUM_MB, EQUILIBRIUM_S),
        },
    };
    Ok(Estimate {
        model: case.solve.model.name().into(),
        threads,
        ct_voxels,
        scan_vertices,
        system,
        peak_mem_mb: MEMORY_MARGIN * mem_mb,
        wall_s: TIME_MARGIN * wall_s,
        seconds: start.elapsed().as_secs_f64(),
    })
}

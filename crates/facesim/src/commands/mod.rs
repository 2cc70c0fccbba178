//! Commands above the library's stages and models: each reads its inputs, calls the stages, the
//! model or a run's stored plan basis, and writes its own outputs as one unit.
//!
//! - [`mod@run`]: `facesim run` (the pipeline, the model, landmarks, uncertainty; every output file and
//!   report.json, written by [`outputs`]);
//! - [`estimate`]: `facesim estimate` (a run's peak memory and time predicted from its mesh and
//!   the symbolic analysis of its factor, before any numeric work);
//! - [`replan`]: `facesim replan` (a run's face outputs for a new plan, docs/design/plan-basis.md);
//! - [`sweep`]: `facesim sweep` (many plans, a table; per facial region). Its chart,
//!   sweep.svg, is drawn by the caller (crates/facesim-lab `sweep_chart`), so the product
//!   library carries no chart crate;
//! - [`landmarks`]: `facesim landmarks` (the soft landmarks and measurements of a face mesh
//!   alone, a 3D photo with no CT).
//!
//! `facesim validate` and `facesim calibrate` are not product commands: they live in
//! crates/facesim-validate, above this library.

pub mod estimate;
pub mod landmarks;
pub mod outputs;
pub mod replan;
pub mod run;
pub mod sweep;

pub use run::{Outcome, run, run_case, run_parsed, run_with};

//! Commands above the library's stages: they read a run's stored outputs (its plan basis and
//! report.json), call the plan basis and write their own outputs, without running a stage.
//!
//! - [`replan`]: `facesim replan` (a run's face outputs for a new plan, docs/plan-basis.md);
//! - [`sweep`]: `facesim sweep` (many plans, a table; per facial region). Its chart,
//!   sweep.svg, is drawn by the caller (crates/facesim-lab `sweep_chart`), so the product
//!   library carries no chart crate.

pub mod replan;
pub mod sweep;

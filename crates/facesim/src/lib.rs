//! facesim — predicting a patient's face after cranio-maxillofacial surgery, after
//! Koch, Gross et al. 1996 ("Simulating Facial Surgery Using Finite Element Models").
//!
//! `pipeline` runs the stages in order, as typed functions (docs/architecture.md): `case` reads
//! case.toml over pipeline/defaults.toml; `volume` reads the CT; `segment` finds the tissues;
//! `surface` makes skin and skull meshes; `springs`, `fem`, `osteotomy` and `solve` make and solve
//! the C1 model (docs/pipeline.md); `embed` carries a dense skin along a coarse model;
//! `pipeline::outputs` writes every file, `report` is report.json. `mesh` reads and writes
//! OBJ/PLY, `phantom` makes the analytic test head, `compare` measures mesh distances,
//! `observe` and `meter` report progress and cost.

// `!(x > 0.0)` is deliberate: it rejects NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Numerics index arrays by axis and node; iterator rewrites would hide the maths.
#![allow(clippy::needless_range_loop)]
// No unwrap/expect outside tests: input-dependent failures are errors, not panics (issue 7).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod case;
pub mod compare;
pub mod embed;
pub mod error;
pub mod fem;
pub mod labels;
pub mod landmarks;
pub mod mesh;
pub mod meter;
pub mod observe;
pub mod osteotomy;
pub mod output;
pub mod phantom;
pub mod phantom_cohort;
pub mod phantom_jaws;
pub mod pipeline;
pub mod plan;
pub mod regions;
pub mod report;
pub mod report_page;
pub mod segment;
pub mod slicer;
pub mod solve;
pub mod springs;
pub mod surface;
pub mod tet;
pub mod uncertainty;
pub mod union_find;
pub mod volume;

pub use error::{Error, Result};

//! facesim — predicting a patient's face after cranio-maxillofacial surgery, after
//! Koch, Gross et al. 1996 ("Simulating Facial Surgery Using Finite Element Models").
//!
//! The modules follow the pipeline's stages (docs/pipeline.md):
//! `volume` (read CT) → `segment` (tissues) → `surface` (skin and skull meshes) → `run`.
//! `mesh` reads and writes OBJ/PLY, `phantom` makes the analytic test head, `compare`
//! measures mesh distances, `case` reads case.toml over `pipeline/defaults.toml`.

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
pub mod mesh;
pub mod meter;
pub mod observe;
pub mod osteotomy;
pub mod output;
pub mod phantom;
pub mod run;
pub mod segment;
pub mod solve;
pub mod springs;
pub mod surface;
pub mod union_find;
pub mod volume;

pub use error::{Error, Result};

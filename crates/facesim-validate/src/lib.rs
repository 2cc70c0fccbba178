//! facesim-validate — how the product library is checked and tuned, kept out of it: the
//! validation of every surgery type against the published soft/hard ratios on the real samples
//! and a seeded phantom cohort ([`validate`], `facesim validate`), the calibration of the tissue
//! parameters on those ratios through the reduced model ([`validate::calibrate`], `facesim
//! calibrate`), and the synthetic heads with analytic ground truth they and the tests are built
//! on: the capsule head ([`phantom`]), the head with jaws ([`phantom_jaws`]) and cohorts of jaws
//! phantoms drawn from documented shape ranges ([`phantom_cohort`]; `facesim phantom`,
//! `facesim phantom-cohort`). It depends on the product library `facesim` and nothing depends
//! on it but the command line, the charts, the lab and the tests (docs/design/architecture.md).

// `!(x > 0.0)` is deliberate: it rejects NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Geometry indexes arrays by axis and voxel; iterator rewrites would hide the maths.
#![allow(clippy::needless_range_loop)]
// No unwrap/expect outside tests: input-dependent failures are errors, not panics
// (docs/lab/reliability.md).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod phantom;
pub mod phantom_cohort;
pub mod phantom_jaws;
pub mod validate;

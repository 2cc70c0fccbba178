//! The facesim laboratory: what measures the product rather than being it — the solver study
//! (integrators, stability, face baselines, charts), the benchmarks (`bench fem`, `scaling`,
//! `embed`, …) and linear elastodynamics. Its own command, `facesim-lab`, runs them.

// `!(x > 0.0)` is deliberate: it rejects NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Numerics index arrays by axis and node; iterator rewrites would hide the maths.
#![allow(clippy::needless_range_loop)]

pub mod bench_dicom;
pub mod bench_embed;
pub mod bench_fem;
pub mod bench_linearisation;
pub mod bench_reduced;
pub mod bench_replan;
pub use facesim_calculix as calculix;
pub mod dynamics;
pub mod scaling;
pub mod study;

//! Uncertainty of the prediction (docs/guide/uncertainty.md): the tissue parameters are known only as
//! ranges, so `[uncertainty] samples = N` draws N parameter sets from a seeded quasi-random
//! sequence, solves each on the run's mesh and face embedding, and reports the mean and 5–95 %
//! band of the displacement magnitude per face vertex (face_band.ply), landmark and region
//! (report.json `uncertainty`). The deterministic prediction stays the nominal parameters'.
//!
//! - `[uncertainty]` in case.toml, its literature defaults and validation are the case schema's
//!   (`crate::case::uncertainty`);
//! - `sample`: the scrambled Halton sequence;
//! - `band`: mean and percentiles, face_band.ply;
//! - `run`: drawing, solving and reducing the samples;
//! - `sensitivity`: Sobol indices (Saltelli / Jansen estimators) on the reduced model;
//! - `reduced`: the same with the certified reduced model (docs/design/reduced.md), the band reduced in
//!   chunks of vertices.

pub mod band;
pub mod reduced;
pub mod run;
pub mod sample;
pub mod sensitivity;

pub use band::Band;
pub use run::{Nominal, Sampled, UncertaintyReport, sample};

/// face_band.ply in `dir`: the nominal predicted face with the band per vertex.
pub(crate) fn write_band(
    dir: &std::path::Path,
    face_post: &crate::mesh::Mesh,
    s: &Sampled,
) -> crate::error::Result<()> {
    band::write_ply(face_post, &s.bands, &dir.join("face_band.ply"))
}

//! facesim — predicting a patient's face after cranio-maxillofacial surgery (a jaw advancement,
//! a Le Fort I, a genioplasty) from a CT, an optional face scan and a plan of bone moves, after
//! Koch, Gross et al. 1996 ("Simulating Facial Surgery Using Finite Element Models").
//!
//! The library is built in layers (docs/design/architecture.md), each importing only from below:
//!
//! - **formats**: [`mesh`] (OBJ, PLY, STL, VTK, VTP), [`volume`] (NIfTI, NRRD, DICOM, InVesalius),
//!   [`slicer`] (3D Slicer's plan files), [`output`] (atomic files; a run's directory as one unit);
//! - **numerics**: [`case`] (case.toml), [`segment`], [`surface`], [`springs`], [`fem`] and
//!   [`solve`] (Koch's C1 surface model), [`tet`] (the volumetric model's elements, meshing and
//!   boundary conditions), [`embed`], [`osteotomy`], [`landmarks`], [`plan`] (the plan basis),
//!   [`uncertainty`];
//! - **stages**: [`pipeline`] — inputs, tissues, surfaces, face, springs and plan, giving a
//!   [`pipeline::Scene`]; progress and cost through one [`pipeline::Recorder`];
//! - **models**: [`model`] — the three soft-tissue models behind one type: [`model::predict`]
//!   gives a [`model::Prediction`] that also re-solves with other tissue parameters
//!   ([`model::Prediction::resolve`]) and carries the plan basis;
//! - **commands**: [`report`] (report.json as types, both ways) and [`commands`] — `run`,
//!   `replan`, `sweep`, each writing its outputs as one unit.
//!
//! Lengths are millimetres in the LPS frame of the CT (x to the patient's left, y to the back, z
//! up); moduli are kPa. Every failure is an [`Error`] that names the file or the parameter.
//!
//! Running a case from Rust, as `facesim run` does (`examples/run_case.rs`):
//!
//! ```no_run
//! use facesim::{commands, observe::Quiet};
//! use std::path::Path;
//!
//! fn main() -> facesim::Result<()> {
//!     let run = commands::run(Path::new("data-samples/phantom"), None, &Quiet)?;
//!     println!(
//!         "{} vertices, up to {:.2} mm; outputs in {}",
//!         run.face_post.vertices.len(),
//!         run.report.displacement.max,
//!         run.out_dir.display()
//!     );
//!     Ok(())
//! }
//! ```
//!
//! A case built in memory (`Case { ct, ..Case::default() }`) runs with [`commands::run_case`];
//! the stages alone with [`pipeline::prepare_case`] and [`model::predict`].

// `!(x > 0.0)` is deliberate: it rejects NaN, which `x <= 0.0` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Numerics index arrays by axis and node; iterator rewrites would hide the maths.
#![allow(clippy::needless_range_loop)]
// No unwrap/expect outside tests: input-dependent failures are errors, not panics
// (docs/lab/reliability.md).
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod anatomy;
pub mod case;
pub mod commands;
pub mod compare;
pub mod embed;
pub mod error;
pub mod fem;
pub mod labels;
pub mod landmarks;
pub mod mesh;
pub mod meter;
pub mod model;
pub mod observe;
pub mod osteotomy;
pub mod output;
pub mod pipeline;
pub mod plan;
pub mod reduced;
pub mod report;
pub mod report_page;
pub mod segment;
pub mod skin_jump;
pub mod slicer;
pub mod solve;
pub mod springs;
mod stored;
pub mod surface;
#[cfg(test)]
mod test_phantoms;
pub mod tet;
pub mod uncertainty;
pub mod union_find;
pub mod vec3;
pub mod volume;

pub use error::{Error, Result};

// What a library user needs, at the crate root: a case, a run, a prediction and the formats.
// The modules above stay reachable for facesim's own crates (the command line, validation,
// the lab, the Python package) and for tests of the numerics.

/// A case: case.toml as types, over pipeline/defaults.toml.
///
/// ```
/// use facesim::Case;
/// use std::path::Path;
///
/// let text = "[ct]\npath = \"ct.nii.gz\"\n[[surgery]]\nkind = \"bsso\"\nadvance_mm = 5\n";
/// let case = Case::parse(text, Path::new("case.toml"))?;
/// assert_eq!(case.surgery.len(), 1);
/// assert_eq!(case.tet.skin_size_mm, 4.0); // the documented default
/// # Ok::<(), facesim::Error>(())
/// ```
pub use case::Case;
/// `facesim run` from Rust: every stage, every output written as one unit, and what the run
/// produced ([`Outcome`]); [`run_case`] for a [`Case`] built in memory.
pub use commands::{Outcome, run, run_case};
/// Surface meshes (OBJ, PLY, STL, VTK, VTP in; OBJ, PLY out), in millimetres.
///
/// ```
/// use facesim::{Mesh, read_mesh, write_mesh};
///
/// let dir = std::env::temp_dir().join(format!("facesim-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let path = dir.join("triangle.ply");
/// let mesh = Mesh::new(vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], vec![[0, 1, 2]]);
/// write_mesh(&mesh, &path)?;
/// let back = read_mesh(&path)?;
/// assert_eq!((back.vertices, back.triangles), (mesh.vertices, mesh.triangles));
/// std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub use mesh::{Mesh, read_mesh, write_mesh};
/// The stages alone: the scene a case prepares, and the soft-tissue model's prediction on it.
pub use model::{Prediction, predict};
/// Progress reports: [`Quiet`] says nothing; implement [`Observer`] to show them.
pub use observe::{Observer, Quiet};
pub use pipeline::{Scene, prepare_case};
/// report.json as types, both ways.
pub use report::Report;
/// CT volumes (NIfTI, NRRD, DICOM, InVesalius, vtk.js) in HU on the LPS frame.
pub use volume::{Volume, read_ct, read_volume};

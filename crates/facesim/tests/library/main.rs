//! The product library's tests, in one binary: each module is one part of the pipeline or
//! one property of the repository (its import graph, its cited paths, its documented keys).
//! One binary, so a test that waits on a child process (Chromium, CalculiX, Python) leaves the
//! cores to the others, and the library is linked once.

#[path = "../common/browser.rs"]
mod browser;
#[path = "../common/mod.rs"]
mod common;
#[path = "../common/tet_grid.rs"]
mod tet_grid;

mod build_features;
mod c1_plates;
mod c1_preload;
mod dicom_codecs;
mod embed;
mod face_scan;
mod foreign_skin;
mod import_graph;
mod landmarks;
mod pipeline;
mod planning;
mod plate_over_slab;
mod predict;
mod real_ct;
mod real_mandible_ct;
mod reduced;
mod reference_keys;
mod references;
mod replan;
mod replan_c1;
mod report_page;
mod slicer_plan;
mod tet_linear;
mod tet_mesh;
mod tet_physics;
mod uncertainty;
mod volumetric;
mod volumetric_jaws;
mod vtk_files;

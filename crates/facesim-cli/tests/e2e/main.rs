//! The `facesim` command line end to end, in one test binary: each module is one command or
//! workflow, run through the real binary (`CARGO_BIN_EXE_facesim`). One binary, so its tests
//! share the machine: a test that waits on a child process (Slurm, Snakemake, Chromium,
//! CalculiX) leaves the cores to the others.

mod cli;
#[path = "../../../facesim/tests/common/mod.rs"]
mod common;

mod bench;
mod calibrate;
mod cli_run;
mod cluster;
mod cohort;
mod concurrent_outputs;
mod estimate;
mod fuzz;
mod help;
mod killed_runs;
mod phantom_jaws;
mod planning;
mod python_package;
mod real_mandible;
mod scan_end;
mod slicer_module;
mod sliding;
mod tet_options;
mod validate;
mod volume_io;

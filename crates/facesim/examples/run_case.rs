//! Running a case from Rust, as `facesim run` does (the example of the library's front page,
//! compiled with the tests): `cargo run --release -p facesim --example run_case -- CASE_DIR`.

use facesim::{commands, observe::Quiet};
use std::path::PathBuf;

fn main() -> facesim::Result<()> {
    let case = std::env::args()
        .nth(1)
        .map_or_else(|| PathBuf::from("data-samples/phantom"), PathBuf::from);
    let run = commands::run(&case, None, &Quiet)?;
    println!(
        "{} vertices, up to {:.2} mm; outputs in {}",
        run.face_post.vertices.len(),
        run.report.displacement.max,
        run.out_dir.display()
    );
    Ok(())
}

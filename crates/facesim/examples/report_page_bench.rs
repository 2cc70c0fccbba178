//! The page for web/bench/rate.mjs (docs/lab/performance.md, "report.html update rate"): the real CT
//! run (data-samples/real), its report.html rewritten with two segments — the maxilla split at
//! the mid-sagittal plane into left and right halves — whose 12 columns each carry the face
//! rigidly with a smooth fall-off. The columns are not a solved basis: they have the size and
//! density of one (12 × face vertices per segment), which is what the update rate depends on.
//!
//!   cargo run --release -p facesim --example report_page_bench -- OUT_DIR
use facesim::observe::Quiet;
use facesim::report_page::{PageBasis, PageData, PageSegment, write_report_html};
use std::path::{Path, PathBuf};

fn main() -> facesim::Result<()> {
    let out: PathBuf = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("target/report-page-bench"));
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/real/case.toml");
    let o = facesim::commands::run(&case, Some(&out), &Quiet)?;
    let face = &o.skin.vertices;
    let osteotomy = &o
        .report
        .parameters
        .as_ref()
        .map(|c| c.osteotomy.clone())
        .unwrap_or_default();
    let Some(maxilla) = osteotomy.first() else {
        return Err(facesim::Error::config("the real case has no osteotomy"));
    };
    let facesim::case::Region::Box { min, max } = maxilla.region else {
        return Err(facesim::Error::config(
            "the real case's maxilla is not a box",
        ));
    };
    let mid = 0.5 * (min[0] + max[0]);
    let centre = [mid, 0.5 * (min[1] + max[1]), 0.5 * (min[2] + max[2])];
    // Weight of a face vertex for one half: 1 near the bone, fading over 40 mm.
    let weight = |x: &[f64; 3], left: bool| {
        let side = if (x[0] > mid) == left { 1.0 } else { 0.0 };
        let r = facesim::vec3::norm(facesim::vec3::sub(*x, centre));
        side * (-(r / 40.0).powi(2)).exp()
    };
    let columns = |left: bool| -> Vec<Vec<[f64; 3]>> {
        (0..12)
            .map(|k| {
                face.iter()
                    .map(|x| {
                        let mut c = [0.0; 3];
                        c[k / 4] = weight(x, left) * if k % 4 < 3 { x[k % 4] } else { 1.0 };
                        c
                    })
                    .collect()
            })
            .collect()
    };
    let segment = |name: &str, left: bool| PageSegment {
        name: name.into(),
        pivot: centre,
        translate: maxilla.translate,
        rotate_deg: maxilla.rotate_deg,
        columns: columns(left),
    };
    let skull_post = facesim::mesh::read_mesh(&out.join("skull_post.ply"))?.vertices;
    let skull_segment = o
        .skull
        .vertices
        .iter()
        .map(|v| match maxilla.region.contains(*v) {
            true if v[0] > mid => 0,
            true => 1,
            false => 255,
        })
        .collect();
    let data = PageData {
        title: format!("{} (two-segment bench)", o.report.name),
        model: "bench".into(),
        face_pre: face,
        face_post: &o.face_post.vertices,
        face_triangles: &o.skin.triangles,
        skull_pre: &o.skull.vertices,
        skull_post: &skull_post,
        skull_triangles: &o.skull.triangles,
        segments: vec!["maxilla_left".into(), "maxilla_right".into()],
        skull_segment,
        colour_scale_mm: o.report.displacement.colour_scale_mm,
        figures: vec![],
        warnings: o.report.warnings.clone(),
        basis: Some(PageBasis {
            label: "bench columns (not a solved basis)".into(),
            segments: vec![
                segment("maxilla_left", true),
                segment("maxilla_right", false),
            ],
        }),
        head_frame: o.report.head_frame.as_ref().map(Into::into),
        ..Default::default()
    };
    write_report_html(&out, &data)?;
    println!(
        "{}: {} face vertices, {} skull vertices, two segments",
        out.join("report.html").display(),
        face.len(),
        o.skull.vertices.len()
    );
    Ok(())
}

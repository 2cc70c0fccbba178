//! Lip and cheek slide where they rest on the teeth, found by contact (no air
//! between), through the real `facesim run` on the real CT (a 5 mm Le Fort I advance).

use crate::cli;
use crate::common;

use facesim::landmarks::face_regions::{NAMES, regions};
use std::path::PathBuf;

/// `facesim run data-samples/real --out <fresh> --set …`, which must exit 0: the output
/// directory and report.json.
fn run_real(name: &str, sets: &[&str]) -> (PathBuf, serde_json::Value) {
    let ct = common::real_ct();
    let out = common::out_dir(name);
    let report = cli::run_ok(ct.parent().unwrap(), &out, sets);
    (out, report)
}

fn count(r: &serde_json::Value, key: &str) -> u64 {
    r["tet"][key]
        .as_u64()
        .unwrap_or_else(|| panic!("report.json tet.{key}"))
}

#[test]
fn lips_slide_on_the_teeth_of_the_real_ct() {
    let (on_dir, on) = run_real("facesim-sliding-on", &[]);
    let (off_dir, off) = run_real("facesim-sliding-off", &["tet.sliding=false"]);
    for (r, what) in [(&on, "sliding"), (&off, "attached")] {
        assert_eq!(count(r, "inverted_elements"), 0, "{what}: {}", r["tet"]);
    }
    // The contact is found from the anatomy at rest, whether or not it slides.
    let found = count(&on, "contact_nodes");
    assert_eq!(found, count(&off, "contact_nodes"));
    assert_eq!(count(&off, "contact_sliding_nodes"), 0);
    let sliding = count(&on, "contact_sliding_nodes");
    println!(
        "contact nodes {found}, sliding {sliding}; mucosa {}; sliding nodes on {} off {}",
        count(&on, "mucosa_nodes"),
        count(&on, "sliding_nodes"),
        count(&off, "sliding_nodes")
    );
    assert!(sliding > 0 && sliding <= found);
    // The face on vs off, vertex by vertex, per region of the run (its landmarks).
    let (pre, post_on) = cli::face_positions(&on_dir);
    let (pre_off, post_off) = cli::face_positions(&off_dir);
    assert_eq!(pre, pre_off);
    let skin = facesim::mesh::read_mesh(&on_dir.join("face_pre.ply")).unwrap();
    let frame = facesim::landmarks::frame::head_frame(&skin).unwrap();
    let lms = facesim::landmarks::markups::read(&on_dir.join("landmarks_pre.mrk.json")).unwrap();
    let r = regions(&skin.vertices, &frame, &lms);
    let diff: Vec<f64> = post_on
        .iter()
        .zip(&post_off)
        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*a, *b)))
        .collect();
    let mut figures = Vec::new();
    for (k, name) in NAMES.iter().enumerate() {
        let Some(m) = &r.members[k] else {
            continue;
        };
        let mut d: Vec<f64> = diff
            .iter()
            .zip(m)
            .filter(|(_, b)| **b)
            .map(|(d, _)| *d)
            .collect();
        d.sort_by(f64::total_cmp);
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let p90 = d[((0.9 * (d.len() - 1) as f64).round()) as usize];
        println!(
            "{name}: {} vertices, on vs off mean {mean:.3} p90 {p90:.3} max {:.3} mm",
            d.len(),
            d[d.len() - 1]
        );
        figures.push((name.to_string(), mean, p90));
    }
    let upper = figures
        .iter()
        .find(|f| f.0 == "upper lip")
        .expect("upper lip region");
    // Measured: upper lip 0.143 mm mean, p90 0.246 (nose 0.160, cheeks 0.060). Of this, the
    // lip–tooth contact itself is 0.018 mm mean within 15 mm of labrale superius (against the build
    // without it); the rest is the saw line's release, which `sliding = false` also attaches. The
    // Le Fort I advance is nearly normal to the incisors' labial faces, so sliding releases little
    // there: only the tangential part of the move is not passed on (docs/design/pipeline.md).
    assert!(upper.1 >= 0.05, "upper lip on vs off: {upper:?}");
}

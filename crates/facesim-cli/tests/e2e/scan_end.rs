//! `[tet] scan_end` through the real `facesim run`: a truncation study with an exact reference.
//! ProMED CT 0051's field of view ends 5 mm below labrale superius, through the upper lip and
//! the upper incisors' crowns. The jaws phantom's CT cut there is the same head with the same
//! Le Fort I advance, so the uncut phantom's answer is what the cut one should give: with the
//! tissue sliding on the scan's end plane (`"slides"`) the nose and lip must come much nearer
//! it than with a free end (docs/lab/validation-notes.md "Where the scan ends: a truncation study").

use crate::cli;
use crate::common;

use std::path::Path;

/// The landmarks compared: the Le Fort I advance's soft rows (docs/guide/validation.md).
const SOFT: [&str; 3] = ["Prn", "Sn", "Ls"];

/// A Le Fort I advance of 5 mm on the phantom's maxilla box (`Shape::boxes`), the skin from the
/// CT, the face movable as `facesim validate` takes it.
fn write_case(dir: &Path) {
    std::fs::write(
        dir.join("case.toml"),
        r#"name = "jaws-le-fort-i-advance-5mm"
[ct]
path = "ct.nii.gz"
[surface]
movable = { sphere = { center = [0.0, -30.0, -35.0], radius = 95.0 } }
[[osteotomy]]
name = "maxilla"
region = { box = { min = [-90.0, -120.0, -25.0], max = [90.0, -11.0, 3.0] } }
translate = [0.0, -5.0, 0.0]
"#,
    )
    .unwrap();
}

/// Per landmark of `SOFT`: its position before and its displacement (report.json, LPS mm).
fn moves(report: &serde_json::Value) -> Vec<([f64; 3], [f64; 3])> {
    let v3 = |v: &serde_json::Value| -> [f64; 3] {
        std::array::from_fn(|c| v[c].as_f64().expect("a coordinate"))
    };
    SOFT.iter()
        .map(|l| {
            let m = &report["landmarks"][l];
            let (pre, post) = (v3(&m["pre"]), v3(&m["post"]));
            (pre, std::array::from_fn(|c| post[c] - pre[c]))
        })
        .collect()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
}

#[test]
fn a_scan_cut_through_the_lip_slides_on_its_end_plane_and_comes_near_the_uncut_head() {
    let root = common::kept_dir("scan-end");
    let (full, cut) = (root.join("full"), root.join("cut"));
    cli::hollow_jaws_phantom(&full, &[]);
    // Cut the CT 5 mm below labrale superius: keep the slices at or above it.
    let shape: toml::Table =
        toml::from_str(&std::fs::read_to_string(full.join("phantom.toml")).unwrap()).unwrap();
    let ls_z = shape["landmarks"]["labrale superius"][2]
        .as_float()
        .unwrap();
    let vol = facesim::volume::read_volume(&full.join("ct.nii.gz")).unwrap();
    assert_eq!(
        vol.direction[2],
        [0.0, 0.0, 1.0],
        "the phantom's slices run up"
    );
    let k0 = ((ls_z - 5.0 - vol.origin[2]) / vol.spacing[2]).ceil() as usize;
    let slice = vol.dims[0] * vol.dims[1];
    let mut top = vol.clone();
    top.dims[2] -= k0;
    top.origin[2] += k0 as f64 * vol.spacing[2];
    top.data = vol.data[k0 * slice..].to_vec();
    std::fs::create_dir_all(&cut).unwrap();
    facesim::volume::nifti_io::write(&top, &cut.join("ct.nii.gz")).unwrap();
    write_case(&full);
    write_case(&cut);

    let quick = "tet.error_estimate=false";
    let run = |case: &Path, name: &str, sets: &[&str]| {
        cli::run_ok(case, &common::out_dir(name), &[&[quick], sets].concat())
    };
    let uncut = run(&full, "scan-end-uncut", &[]);
    let slides = run(&cut, "scan-end-slides", &["tet.scan_end=\"slides\""]);
    let free = run(&cut, "scan-end-free", &[]);

    // The Le Fort I advance's mesh does not reach the uncut phantom's neck; the cut one ends
    // in the lip, and there it is free by default and slides on request.
    assert!(uncut["tet"]["scan_end"].is_null(), "{}", uncut["tet"]);
    let end = |r: &serde_json::Value, k: &str| r["tet"]["scan_end"][k].as_u64().unwrap();
    assert!(end(&slides, "sliding_nodes") > 100, "{}", slides["tet"]);
    assert_eq!(end(&slides, "free_nodes"), 0, "{}", slides["tet"]);
    assert_eq!(end(&free, "sliding_nodes"), 0, "{}", free["tet"]);
    assert_eq!(end(&free, "free_nodes"), end(&slides, "sliding_nodes"));

    let (truth, s, f) = (moves(&uncut), moves(&slides), moves(&free));
    let (mut err_slides, mut err_free) = (0.0, 0.0);
    for (i, l) in SOFT.iter().enumerate() {
        // The cut leaves the landmarks where they were.
        assert!(
            dist(truth[i].0, s[i].0) < 1.0,
            "{l} found elsewhere on the cut CT"
        );
        let (es, ef) = (dist(s[i].1, truth[i].1), dist(f[i].1, truth[i].1));
        println!(
            "{l}: uncut {:.2?}, slides {:.2?} (off {es:.2} mm), free {:.2?} (off {ef:.2} mm)",
            truth[i].1, s[i].1, f[i].1
        );
        assert!(
            es < ef,
            "{l}: the sliding end is further off the uncut head than the free one"
        );
        err_slides += es;
        err_free += ef;
    }
    // Measured: 0.9 mm against 3.7 mm summed over the three.
    assert!(
        err_slides < 0.5 * err_free,
        "the sliding end's error {err_slides:.2} mm is not under half the free end's {err_free:.2} mm"
    );
    // The free end lets the cut lip rise with the bone (1.8 mm under a 5 mm advance, against
    // the uncut lip's 0.0): the artefact the sliding end removes.
    let ls_up = |m: &[([f64; 3], [f64; 3])]| m[2].1[2];
    assert!(
        ls_up(&f) > ls_up(&truth) + 1.0,
        "the free end's lip rose {:.2}",
        ls_up(&f)
    );
    assert!(
        (ls_up(&s) - ls_up(&truth)).abs() < 0.6,
        "the sliding end's lip rose {:.2} mm, the uncut one's {:.2}",
        ls_up(&s),
        ls_up(&truth)
    );
}

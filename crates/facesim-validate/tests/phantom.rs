//! The phantom is the ground truth: segmentation volumes and extracted surfaces are checked
//! against its analytic geometry (docs/design/phantom.md).

#[path = "../../facesim/tests/common/mod.rs"]
mod common;

use common::phantom_dir;
use facesim::case::{Case, ExtractMethod, TissueMethod};
use facesim::segment::{self, BONE, FAT_BRIGHT, FAT_DARK, MUSCLE, SKIN};
use facesim::volume::read_volume;
use facesim_validate::phantom::{self, analytic_volumes};
use std::path::Path;

fn defaults() -> Case {
    Case::parse("[ct]\npath = \"ct.nii.gz\"\n", Path::new("case.toml")).unwrap()
}

fn check_volumes(method: TissueMethod, tol: f64) {
    let vol = read_volume(&phantom_dir().join("ct.nii.gz")).unwrap();
    let mut case = defaults();
    case.tissue.method = method;
    let seg = segment::segment(&vol, &case.tissue, Path::new("ct.nii.gz")).unwrap();
    let vv = vol.voxel_volume();
    let got = |labels: &[u8]| labels.iter().map(|&l| seg.count(l)).sum::<usize>() as f64 * vv;
    let truth = analytic_volumes();
    let rows = [
        ("skin", got(&[SKIN]), truth.skin),
        ("fat", got(&[FAT_DARK, FAT_BRIGHT]), truth.fat),
        (
            "soft (muscle, brain, nose, bone cuts)",
            got(&[MUSCLE]),
            truth.soft,
        ),
        ("bone", got(&[BONE]), truth.bone),
    ];
    for (name, g, t) in &rows {
        println!(
            "{method:?} {name}: segmented {g:.0} mm³, analytic {t:.0} mm³, {:+.2}%",
            100.0 * (g / t - 1.0)
        );
    }
    println!("windows used: {:?}", seg.windows);
    for (name, g, t) in rows {
        let rel = g / t - 1.0;
        assert!(
            rel.abs() < tol,
            "{method:?} {name}: {g:.0} vs analytic {t:.0} ({:+.2}%)",
            100.0 * rel
        );
    }
    // The mandible and maxilla are bone pieces of their own.
    assert_eq!(
        seg.report.bone_components_kept, 3,
        "cranium, maxilla, mandible"
    );
}

#[test]
fn segmentation_volumes_match_the_analytic_phantom_windows() {
    check_volumes(TissueMethod::Windows, 0.03);
}

#[test]
fn segmentation_volumes_match_the_analytic_phantom_fit() {
    check_volumes(TissueMethod::Fit, 0.03);
}

/// Run the pipeline on the phantom with the skin extracted from the CT (no scan).
fn extracted_skin(method: ExtractMethod, ct: &str) -> facesim::commands::Outcome {
    let dir = common::kept_dir("facesim-run");
    let dir = &dir;
    let m = if method == ExtractMethod::Marching {
        "marching"
    } else {
        "rangescan"
    };
    let ct_path = phantom_dir().join(ct);
    std::fs::write(
        dir.as_path().join("case.toml"),
        format!(
            "[ct]\npath = \"{}\"\n[extract]\nmethod = \"{m}\"\n",
            ct_path.display()
        ),
    )
    .unwrap();
    facesim::commands::run(dir.as_path(), None, &facesim::observe::Quiet).unwrap()
}

fn rms_radial(points: &[[f64; 3]]) -> (f64, f64) {
    let d: Vec<f64> = points
        .iter()
        .map(|p| phantom::radial_skin_distance(*p))
        .collect();
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
    (rms, d.iter().cloned().fold(0.0, f64::max))
}

#[test]
fn range_scan_skin_is_within_half_a_voxel_of_the_analytic_surface() {
    let o = extracted_skin(ExtractMethod::Rangescan, "ct.nii.gz");
    let (rms, max) = rms_radial(&o.skin.vertices);
    println!(
        "range scan: {} vertices, RMS {rms:.3} mm, max {max:.3} mm",
        o.skin.vertices.len()
    );
    assert!(
        rms < 0.5 * 1.5,
        "RMS {rms} mm exceeds half a voxel (0.75 mm)"
    );
    assert_eq!(o.skin.components().1, 1);
    // (u, v) parameterisation is kept with the mesh.
    let names: Vec<&str> = o
        .skin
        .vertex_columns
        .iter()
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(names, ["u", "v"]);
    // Every output file is there.
    for f in [
        "face_pre.obj",
        "face_pre.ply",
        "skull_pre.ply",
        "labels.nii.gz",
        "report.json",
    ] {
        assert!(o.out_dir.join(f).is_file(), "{f}");
    }
}

#[test]
fn marching_skin_from_the_dicom_series_is_within_half_a_voxel() {
    let o = extracted_skin(ExtractMethod::Marching, "ct_dicom");
    // Marching tetrahedra sees the whole head, caps included; compare the cylinder part only
    // (the radial distance is the normal distance there).
    let pts: Vec<[f64; 3]> = o
        .skin
        .vertices
        .iter()
        .filter(|p| p[2].abs() < phantom::Z_HALF)
        .copied()
        .collect();
    let (rms, max) = rms_radial(&pts);
    println!(
        "marching: {} vertices, RMS {rms:.3} mm, max {max:.3} mm",
        o.skin.vertices.len()
    );
    assert!(rms < 0.5 * 1.5, "RMS {rms} mm");
    assert_eq!(o.skin.components().1, 1);
    let stats = o.skin.check(Path::new("skin")).unwrap();
    assert_eq!(stats.boundary_edges, 0, "a closed head surface");
}

#[test]
fn skull_range_scan_lies_on_the_outer_bone_surface() {
    let o = extracted_skin(ExtractMethod::Rangescan, "ct.nii.gz");
    // Away from the nose and the cuts, the outer skull is the cylinder ρ = R_BONE.
    let d: Vec<f64> = o
        .skull
        .vertices
        .iter()
        .filter(|p| p[2].abs() < phantom::Z_HALF && p[1] > 10.0)
        .map(|p| ((p[0] * p[0] + p[1] * p[1]).sqrt() - phantom::R_BONE).abs())
        .collect();
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
    println!("skull: {} vertices checked, RMS {rms:.3} mm", d.len());
    assert!(d.len() > 1000 && rms < 0.75, "RMS {rms}");
}

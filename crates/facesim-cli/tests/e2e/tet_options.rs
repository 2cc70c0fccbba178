//! `[tet]` options through the real `facesim run` on the bundled sample: the face
//! must follow the bone whatever element is chosen.

use crate::cli;
use crate::common;

use std::path::Path;

/// A face before and after (displacement.csv: x_pre.. and x_post.. per vertex).
struct Face {
    pre: Vec<[f64; 3]>,
    post: Vec<[f64; 3]>,
}

/// The discretisation-error estimate off, for tests that compare the face alone: it is a
/// second solve on a coarser mesh and does not change the face (`model::discretisation`).
const NO_ESTIMATE: &str = "tet.error_estimate=false";

/// `facesim run CASE --out <fresh> --set …`, which must exit 0; the face and report.json.
fn run_case(case: &Path, name: &str, sets: &[&str]) -> (Face, serde_json::Value) {
    let out = common::out_dir(name);
    let report = cli::run_ok(case, &out, sets);
    let (pre, post) = cli::face_positions(&out);
    (Face { pre, post }, report)
}

fn mean_distance(a: &Face, b: &Face) -> f64 {
    assert_eq!(a.pre, b.pre);
    a.post
        .iter()
        .zip(&b.post)
        .map(|(p, q)| dist(*p, *q))
        .sum::<f64>()
        / a.post.len() as f64
}

fn largest_move(f: &Face) -> f64 {
    f.pre
        .iter()
        .zip(&f.post)
        .map(|(a, b)| dist(*a, *b))
        .fold(0.0, f64::max)
}

/// The real CT's case with its whole skull as one segment moved by `translate`, `rotate_deg`
/// about `pivot`, every skin node movable: the exact answer is the same rigid motion of the face.
fn whole_skull_case(
    name: &str,
    translate: [f64; 3],
    rotate: [f64; 3],
    pivot: [f64; 3],
) -> std::path::PathBuf {
    let dir = common::kept_dir(name);
    std::fs::create_dir_all(&dir).unwrap();
    let ct = common::real_ct();
    std::fs::write(
        dir.join("case.toml"),
        format!(
            r#"name = "{name}"
[ct]
path = "{}"
[surface]
movable = {{ sphere = {{ center = [125.0, 30.0, 15.0], radius = 500.0 }} }}
[[osteotomy]]
name = "skull"
region = {{ box = {{ min = [-1000.0, -1000.0, -1000.0], max = [1000.0, 1000.0, 1000.0] }} }}
translate = {translate:?}
rotate_deg = {rotate:?}
pivot = {pivot:?}
"#,
            ct.display()
        ),
    )
    .unwrap();
    dir
}

/// A rigid move of all bone on the real CT gives the rigid face. The tissue
/// mesher leaves pieces hinged by a node or an edge; held still, they put the face of a
/// translated skull 23.6 % of the move off the rigid translation, so each follows its
/// bone. Translation: every element and material is exact (0 strain). Rotation: the linear
/// material's small-strain error is of order θ × the move (3° ≈ 5 %; 1.2 % measured on the
/// default mesh); the neo-Hookean material is exact for it (through the Newton–Krylov solve and
/// the stable energy; without them it failed after 14 minutes).
#[test]
fn rigid_moves_of_all_bone_give_the_rigid_face_on_the_real_ct() {
    const COARSE_SKIN: &str = "tet.skin_size_mm=6";
    const COARSE_DEEP: &str = "tet.deep_size_mm=12";
    let pivot = [125.0, 60.0, 20.0];
    let t = [1.5, -2.0, 1.0];
    for (name, rotate, sets, bound) in [
        (
            "rigid-translate-linear",
            [0.0; 3],
            &["tet.sliding=false"][..],
            1e-6,
        ),
        // The 10-node element on a 10/20 mm mesh (the 4 mm one needs 10 GB): the vertices a
        // coarse mesh does not reach at the scan's top (6 at 6 mm) stayed still before they
        // were carried by extrapolation.
        (
            "rigid-translate-quadratic",
            [0.0; 3],
            &[
                "tet.sliding=false",
                "tet.element=quadratic",
                "tet.skin_size_mm=10",
                "tet.deep_size_mm=20",
            ][..],
            1e-6,
        ),
        // The rotations on a 6/12 mm mesh: rigid motion is exact (or, for the linear material,
        // of order θ) on any mesh, and the neo-Hookean solve costs a quarter of the default
        // mesh's there (its convergence at the default mesh is
        // `neo_hookean_converges_on_the_real_ct_near_the_linear_face`).
        (
            "rigid-rotate-linear",
            [2.0, -3.0, 1.5],
            &["tet.sliding=false", COARSE_SKIN, COARSE_DEEP][..],
            0.05,
        ),
        // The hyperelastic material is exact for any rigid motion: held to the Newton–Krylov
        // displacement tolerance (1e-3 mm over this 12.6 mm move; measured 1.2e-5 mm). It was
        // 0.039 mm off while the mucosa followed its bone point's displacement, not its own
        // position's (tet::conditions::mucosa).
        (
            "rigid-rotate-neo-hookean",
            [2.0, -3.0, 1.5],
            &[
                "tet.sliding=false",
                "tet.material=neo-hookean",
                COARSE_SKIN,
                COARSE_DEEP,
            ][..],
            1e-4,
        ),
        // And with the lips sliding on the bone (n · u = n · u_bone at each sliding node).
        (
            "rigid-rotate-neo-hookean-sliding",
            [2.0, -3.0, 1.5],
            &[
                "tet.sliding=true",
                "tet.material=neo-hookean",
                COARSE_SKIN,
                COARSE_DEEP,
            ][..],
            1e-4,
        ),
    ] {
        let case = whole_skull_case(&format!("facesim-{name}-case"), t, rotate, pivot);
        // The face alone is compared: the discretisation-error estimate (a second, coarse
        // solve that does not change the face) is left out.
        let sets: Vec<&str> = sets.iter().copied().chain([NO_ESTIMATE]).collect();
        let (face, report) = run_case(&case, &format!("facesim-{name}"), &sets);
        assert_eq!(
            report["tet"]["fixed_nodes"], 0,
            "{name}: nothing is held still"
        );
        assert_eq!(report["tet"]["inverted_elements"], 0, "{name}");
        let r = facesim::osteotomy::rotation(rotate);
        let mut worst: f64 = 0.0;
        let mut moved: f64 = 0.0;
        for (p, q) in face.pre.iter().zip(&face.post) {
            let exact: [f64; 3] = std::array::from_fn(|i| {
                (0..3).map(|j| r[i][j] * (p[j] - pivot[j])).sum::<f64>() + pivot[i] + t[i]
            });
            worst = worst.max(dist(exact, *q));
            moved = moved.max(dist(exact, *p));
        }
        assert!(
            worst <= bound * moved,
            "{name}: the face is {worst:.4} mm off the rigid move (largest move {moved:.2} mm)"
        );
    }
}

/// Every [tet] option through `facesim run` on both bundled samples, on a 9/18 mm mesh (the
/// 10-node runs take seconds; at 10/20 mm the capsule's 10-node run turns one element inside
/// out and is refused): the capsule with its 6 mm advance and the jaws phantom (README's first
/// command) with its 5 mm BSSO advance. Each option follows the move (the face
/// moves 5/6–13/12 of it at most), exits 0, turns no element inside out, and agrees with the
/// default combination within what the model difference explains — element order and material
/// (0.5 mm mean at a 6 mm move, the required bound), and sliding (a few tenths of a millimetre on
/// the face: only the inner lips slide); the 10-node element with the other defaults within
/// 0.25 mm of the 4-node one.
#[test]
fn every_tet_option_follows_the_bone_on_the_bundled_samples() {
    let mesh = [
        "tet.skin_size_mm=9",
        "tet.deep_size_mm=18",
        "tet.release_cuts=true",
        "tet.accept_inverted=false",
        NO_ESTIMATE,
    ];
    for (sample, advance) in [("phantom", 6.0), ("jaws", 5.0)] {
        let case = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../data-samples")
            .join(sample);
        let mut faces = Vec::new();
        for element in ["linear", "quadratic"] {
            for material in ["linear", "neo-hookean"] {
                if element == "quadratic" && material == "neo-hookean" {
                    // The nonlinear material is solved on 4-node elements only: refused, not
                    // silently solved on another element.
                    continue;
                }
                for sliding in ["true", "false"] {
                    let sets = [
                        format!("tet.element={element}"),
                        format!("tet.material={material}"),
                        format!("tet.sliding={sliding}"),
                    ];
                    let sets: Vec<&str> = sets.iter().map(String::as_str).chain(mesh).collect();
                    let name = format!("facesim-opt-{sample}-{element}-{material}-{sliding}");
                    let (face, report) = run_case(&case, &name, &sets);
                    let max = largest_move(&face);
                    assert!(
                        (advance * 5.0 / 6.0..=advance * 13.0 / 12.0).contains(&max),
                        "{name}: the face moves {max:.3} mm at most for a {advance} mm advance"
                    );
                    assert_eq!(report["tet"]["inverted_elements"], 0, "{name}");
                    faces.push((name, face));
                }
            }
        }
        let (base_name, base) = &faces[0];
        for (name, face) in &faces[1..] {
            let mean = mean_distance(base, face);
            assert!(mean < 0.5, "{name} vs {base_name}: mean {mean:.3} mm");
        }
        // The 10-node element once moved the face 0.004 mm for a 6 mm advance: every midpoint
        // node was held still as "used by no tetrahedron" (the floating-piece check looked at the
        // corner cells only). With the defaults otherwise it agrees with the 4-node element on the
        // same mesh within what the element order explains (mean 0.117 mm measured on the
        // capsule, 0.073 mm on the jaws phantom at 9/18 mm; bound 0.25).
        let by_name = |element: &str| {
            let name = format!("facesim-opt-{sample}-{element}-linear-true");
            &faces.iter().find(|(n, _)| *n == name).unwrap().1
        };
        let mean = mean_distance(by_name("linear"), by_name("quadratic"));
        println!("{sample}: quadratic vs linear: mean {mean:.3} mm");
        assert!(
            mean < 0.25,
            "{sample}: quadratic vs linear: mean {mean:.3} mm"
        );
    }
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
}

/// The neo-Hookean material converges through `facesim run` on the real CT at
/// the full 5 mm Le Fort I advance with the default mesh, turns no element inside out, and its
/// face lies within the required bound of the linear one (0.5 mm mean; 0.09 mm measured, which
/// report.json's `nonlinear_vs_linear` states per region and this test recomputes).
#[test]
fn neo_hookean_converges_on_the_real_ct_near_the_linear_face() {
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/real");
    let off = ["tet.error_estimate=false"];
    let (linear, _) = run_case(&case, "facesim-real-linear", &off);
    let (nh, report) = run_case(
        &case,
        "facesim-real-neo-hookean",
        &["tet.error_estimate=false", "tet.material=neo-hookean"],
    );
    assert_eq!(report["tet"]["inverted_elements"], 0);
    let newton = &report["tet"]["newton"][0];
    assert_eq!(newton["load"], 1.0);
    let mean = mean_distance(&nh, &linear);
    let reported = report["nonlinear_vs_linear"]["moving_face"]["mean"]
        .as_f64()
        .unwrap();
    println!(
        "real CT: neo-Hookean vs linear face {mean:.3} mm mean over all vertices, {reported:.3} mm over the moving face; Newton {newton}"
    );
    assert!(mean > 0.0 && mean < 0.5, "{mean}");
    assert!(reported > 0.01 && reported < 0.5, "{reported}");
    let max = largest_move(&nh);
    assert!((4.0..=6.0).contains(&max), "the face moves {max} mm");
}

/// The largest orthognathic move, the real CT's maxilla advanced 25 mm (five
/// times the sample's plan). Where it would drag tissue through bone, the tissue lifts off its
/// bone; what is still turned inside out after that is free tissue in the osteotomy gap behind and
/// above the segment (34 of 207 475 elements, stretched several-fold), and it tears (`[tet]
/// tear_gap`): its stiffness falls to a trace and the model is solved again. With the defaults
/// the run succeeds with no inverted element; with every element kept it is refused, naming the
/// count. Tearing tissue behind the maxilla must barely change the face: the kept solve's face
/// (written for inspection) and the torn one agree within 0.35 mm at every vertex and 0.01 mm on
/// average (measured 0.28 and 0.004 mm, with the face moving 23.6 mm; 0.06 mm worst with the
/// scan's end free; docs/design/pipeline.md "Large moves").
#[test]
fn the_largest_advance_tears_the_gap_tissue_and_leaves_no_element_inverted() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/real");
    let text = std::fs::read_to_string(sample.join("case.toml")).unwrap();
    let dir = common::kept_dir("facesim-real-advance-25");
    std::fs::create_dir_all(&dir).unwrap();
    let ct = common::real_ct();
    let text = text
        .replace(
            "path = \"Cranium.inv3\"",
            &format!("path = \"{}\"", ct.display()),
        )
        .replace(
            "translate = [0.0, -5.0, 0.0]",
            "translate = [0.0, -25.0, 0.0]",
        );
    assert!(
        text.contains("-25.0"),
        "the sample's plan changed: update this test"
    );
    std::fs::write(dir.join("case.toml"), text).unwrap();
    let (face, report) = run_case(
        &dir,
        "facesim-real-advance-25-torn",
        &["tet.error_estimate=false"],
    );
    let tet = &report["tet"];
    let torn = tet["torn_elements"].as_u64().unwrap();
    println!(
        "25 mm advance: {torn} torn ({} mm³), {} nodes lifted off",
        tet["torn_volume_mm3"], tet["lifted_off"]
    );
    assert_eq!(tet["inverted_elements"], 0);
    assert!(torn > 0, "nothing torn: the test no longer tests tearing");
    assert!(tet["lifted_off"].as_u64().unwrap() > 0);
    // Without tearing, the inverted elements fail the run, naming the count; the outputs are
    // written for inspection.
    let kept = dir.join("kept");
    let r = cli::facesim(&[
        "run",
        dir.to_str().unwrap(),
        "--out",
        kept.to_str().unwrap(),
        "--set",
        "tet.error_estimate=false",
        "--set",
        "tet.tear_gap=false",
    ]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains("inside out: not a valid prediction"),
        "{}",
        r.stderr
    );
    let (pre, post) = cli::face_positions(&kept);
    let kept = Face { pre, post };
    let worst = face
        .post
        .iter()
        .zip(&kept.post)
        .map(|(p, q)| dist(*p, *q))
        .fold(0.0, f64::max);
    println!("torn vs kept face: {worst:.3} mm at the worst vertex");
    // Measured 0.47 mm (2 % of the 25 mm advance) beside the nose, just above the cut, with the
    // scan's end free; 0.28 mm with it sliding.
    assert!(worst < 0.5, "tearing moved the face {worst} mm");
    assert!(mean_distance(&face, &kept) < 0.01);
    let ls = report["soft_hard_ratios"]["Ls/A"]["ratio"]
        .as_f64()
        .unwrap();
    assert!((0.8..=1.0).contains(&ls), "Ls/A {ls}");
    // The face follows the 25 mm advance (the face at small y) and no further. The lip's edge
    // where the scan ends, 5 mm below labrale superius, is free (docs/design/pipeline.md "Region") and
    // rises 6–8 mm as the teeth carry it forward, so the largest move's length is up to a tenth
    // over the advance.
    let forward = face
        .pre
        .iter()
        .zip(&face.post)
        .map(|(a, b)| a[1] - b[1])
        .fold(0.0, f64::max);
    assert!((22.0..=26.0).contains(&forward), "forward {forward} mm");
    let largest = largest_move(&face);
    assert!(
        (22.0..=27.5).contains(&largest),
        "largest move {largest} mm"
    );
}

/// The retired `[tet]` mechanisms (docs/lab/retired-mechanisms.md): a case.toml that still sets
/// one of their keys is refused by `facesim run` in one line naming case.toml and the key, before
/// anything is read or written.
#[test]
fn a_case_setting_a_retired_key_is_refused_in_one_line_naming_it() {
    for (key, value) in [
        ("nose_youngs_kpa", "3000.0"),
        ("nose_base_above_sn_mm", "10.0"),
        ("septum_detached", "true"),
    ] {
        let dir = common::kept_dir("facesim-retired-key");
        std::fs::write(
            dir.join("case.toml"),
            format!("[ct]\npath = \"ct.nii.gz\"\n\n[tet]\n{key} = {value}\n"),
        )
        .unwrap();
        let out = dir.join("out");
        let r = cli::facesim(&["run", dir.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        cli::assert_clean_failure(&r, "case.toml", &format!("[tet] {key} is no longer a key"));
        assert!(!out.exists(), "{key}: nothing is written");
    }
}

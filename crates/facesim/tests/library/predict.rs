//! Springs, bone moves and the predicted face of the C1 model on the phantom:
//! the cases name `model = "equilibrium"` unless they choose a model themselves.

use crate::common;

use common::phantom_dir;
use std::path::PathBuf;

fn case(extra: &str) -> PathBuf {
    let d = common::kept_dir("facesim-predict");
    let model = if extra.contains("[solve]") {
        ""
    } else {
        "[solve]\nmodel = \"equilibrium\"\n"
    };
    let ct = phantom_dir().join("ct.nii.gz");
    let scan = phantom_dir().join("face.ply");
    std::fs::write(
        d.join("case.toml"),
        format!(
            "name = \"p\"\n[ct]\npath = \"{}\"\n[skin]\npath = \"{}\"\n{model}{extra}",
            ct.display(),
            scan.display()
        ),
    )
    .unwrap();
    d
}

fn run(extra: &str) -> facesim::commands::Outcome {
    facesim::commands::run(&case(extra), None, &facesim::observe::Quiet).unwrap()
}

#[test]
fn main_springs_span_the_analytic_soft_tissue_thickness() {
    // Away from the nose and the bone cuts the skin is 13 mm (80 − 67) from the outer skull.
    let o = run("");
    let springs = facesim::springs::trace(
        &o.skin,
        &o.volume,
        &o.segmentation,
        &o.segmentation.bone_field(&o.volume),
        &facesim::case::Case::parse("[ct]\npath = \"x.nii\"\n", std::path::Path::new("c"))
            .unwrap()
            .springs,
        &facesim::case::Case::parse("[ct]\npath = \"x.nii\"\n", std::path::Path::new("c"))
            .unwrap()
            .tissue
            .stiffness,
        None,
    );
    let lens: Vec<f64> = springs
        .springs
        .iter()
        .filter(|s| s.kind == facesim::springs::Kind::Main)
        .filter(|s| {
            let p = o.skin.vertices[s.skin];
            p[2] > 10.0
                && p[2] < 35.0
                && facesim_validate::phantom::nose(facesim_validate::phantom::phi_of(p), p[2])
                    < 0.01
        })
        .map(|s| s.rest)
        .collect();
    let mean = lens.iter().sum::<f64>() / lens.len() as f64;
    let worst = lens.iter().map(|l| (l - 13.0).abs()).fold(0.0, f64::max);
    println!(
        "{} main springs: mean length {mean:.3} mm, worst deviation {worst:.3} mm (analytic 13)",
        lens.len()
    );
    assert!(lens.len() > 100);
    assert!((mean - 13.0).abs() < 0.3 && worst < 1.0);
}

#[test]
fn no_bone_move_leaves_the_face_unchanged_in_both_models() {
    for model in ["equilibrium", "koch1996"] {
        let o = run(&format!(
            "[surface]\nmovable = {{ sphere = {{ center = [0.0, -60.0, -45.0], radius = 70.0 }} }}\n[solve]\nmodel = \"{model}\"\n[[osteotomy]]\nname = \"none\"\nregion = {{ box = {{ min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] }} }}\ntranslate = [0.0, 0.0, 0.0]\n"
        ));
        let worst = o
            .skin
            .vertices
            .iter()
            .zip(&o.face_post.vertices)
            .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*a, *b)))
            .fold(0.0, f64::max);
        println!("{model}: max |post − pre| = {worst:.2e} mm");
        assert!(worst < 1e-6, "{model}: {worst}");
    }
}

/// An osteotomy moving all bone by `t`.
fn whole_skull(t: [f64; 3]) -> String {
    format!(
        "[[osteotomy]]\nname = \"skull\"\nregion = {{ box = {{ min = [-500.0, -500.0, -500.0], max = [500.0, 500.0, 500.0] }} }}\ntranslate = [{}, {}, {}]\n",
        t[0], t[1], t[2]
    )
}

/// Worst |(x_post − x_pre) − t| over the skin (mm).
fn translation_error(o: &facesim::commands::Outcome, t: [f64; 3]) -> f64 {
    o.skin
        .vertices
        .iter()
        .zip(&o.face_post.vertices)
        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(facesim::vec3::sub(*b, *a), t)))
        .fold(0.0, f64::max)
}

#[test]
fn whole_skull_translated_moves_the_skin_rigidly() {
    // Every skin node movable (no [surface] movable), every attachment moved by t.
    let t = [1.0, -2.0, 0.5];
    let o = run(&whole_skull(t));
    let tn = facesim::vec3::norm(t);
    let worst = translation_error(&o, t);
    println!("rigid translation: worst deviation {worst:.2e} mm of a {tn:.3} mm move");
    assert!(worst < 1e-3 * tn, "{worst}");
}

fn displacement(o: &facesim::commands::Outcome) -> Vec<[f64; 3]> {
    o.skin
        .vertices
        .iter()
        .zip(&o.face_post.vertices)
        .map(|(a, b)| facesim::vec3::sub(*b, *a))
        .collect()
}

const MANDIBLE: &str = "[surface]\nmovable = { sphere = { center = [0.0, -60.0, -45.0], radius = 70.0 } }\n[[osteotomy]]\nname = \"mandible\"\nregion = { box = { min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] } }\n";

#[test]
fn small_moves_give_displacements_linear_in_the_move() {
    for model in ["equilibrium", "koch1996"] {
        let m = format!("[solve]\nmodel = \"{model}\"\n");
        let a = run(&format!("{m}{MANDIBLE}translate = [0.0, -0.05, 0.0]\n"));
        let b = run(&format!("{m}{MANDIBLE}translate = [0.0, -0.1, 0.0]\n"));
        let (da, db) = (displacement(&a), displacement(&b));
        let scale = db
            .iter()
            .map(|d| facesim::vec3::norm(*d))
            .fold(0.0, f64::max);
        let worst = da
            .iter()
            .zip(&db)
            .map(|(x, y)| {
                facesim::vec3::norm(facesim::vec3::sub(*y, facesim::vec3::scale(*x, 2.0)))
            })
            .fold(0.0, f64::max);
        println!(
            "{model}, 0.05 → 0.1 mm: max |d(2m) − 2 d(m)| = {worst:.2e} mm of max |d| {scale:.3e} mm ({:.3}%)",
            100.0 * worst / scale
        );
        assert!(scale > 0.0 && worst < 0.01 * scale, "{model}");
    }
}

#[test]
fn the_mirror_symmetric_phantom_gives_a_mirror_symmetric_prediction() {
    // A noise-free phantom on a grid symmetric about x = 0 (2 mm: x from −92 to 92).
    let dir = common::kept_dir("facesim-sym");
    let opts = facesim_validate::phantom::PhantomOptions {
        spacing: [2.0, 2.0, 2.0],
        noise_hu: 0.0,
        ..Default::default()
    };
    facesim_validate::phantom::write_case(&dir, &opts).unwrap();
    for model in ["equilibrium", "koch1996"] {
        let text = std::fs::read_to_string(dir.join("case.toml")).unwrap();
        let case_dir = dir.join(model);
        std::fs::create_dir_all(&case_dir).unwrap();
        let text = text
            .replace(
                "path = \"ct.nii.gz\"",
                &format!("path = \"{}\"", dir.join("ct.nii.gz").display()),
            )
            .replace(
                "path = \"face.ply\"",
                &format!("path = \"{}\"", dir.join("face.ply").display()),
            );
        std::fs::write(
            case_dir.join("case.toml"),
            format!("{text}[solve]\nmodel = \"{model}\"\n"),
        )
        .unwrap();
        let o = facesim::commands::run(&case_dir, None, &facesim::observe::Quiet).unwrap();
        let d = displacement(&o);
        let v = &o.skin.vertices;
        let scale = d
            .iter()
            .map(|x| facesim::vec3::norm(*x))
            .fold(0.0, f64::max);
        let mut worst = 0.0f64;
        for i in 0..v.len() {
            let m = [-v[i][0], v[i][1], v[i][2]];
            let j = (0..v.len())
                .min_by(|&a, &b| {
                    facesim::vec3::norm(facesim::vec3::sub(v[a], m))
                        .total_cmp(&facesim::vec3::norm(facesim::vec3::sub(v[b], m)))
                })
                .unwrap();
            assert!(
                facesim::vec3::norm(facesim::vec3::sub(v[j], m)) < 1e-6,
                "scan not symmetric at {i}"
            );
            let mirrored = [-d[j][0], d[j][1], d[j][2]];
            worst = worst.max(facesim::vec3::norm(facesim::vec3::sub(d[i], mirrored)));
        }
        println!(
            "{model} mirror symmetry: worst |d_i − M d_mirror(i)| = {worst:.3e} mm of max |d| {scale:.3} mm ({:.2}%)",
            100.0 * worst / scale
        );
        assert!(scale > 1.0 && worst < 0.05 * scale, "{model}");
    }
}

#[test]
fn two_mesh_densities_give_the_same_displacement_field() {
    // The same head with face scans at 3 mm and 2 mm: k_i (eq. 21) makes the spring forces per
    // area independent of the mesh, so the displacement fields agree where they overlap.
    for model in ["equilibrium", "koch1996"] {
        let run_scan = |step: f64| {
            let d = common::kept_dir("facesim-density");
            facesim::mesh::ply::write(
                &facesim_validate::phantom::face_scan(step),
                &d.join("scan.ply"),
                facesim::mesh::ply::Encoding::BinaryLittleEndian,
            )
            .unwrap();
            let ct = phantom_dir().join("ct.nii.gz");
            std::fs::write(
            d.join("case.toml"),
            format!("[ct]\npath = \"{}\"\n[skin]\npath = \"scan.ply\"\n[solve]\nmodel = \"{model}\"\n{MANDIBLE}translate = [0.0, -3.0, 0.0]\n", ct.display()),
        )
        .unwrap();
            facesim::commands::run(&d, None, &facesim::observe::Quiet).unwrap()
        };
        let coarse = run_scan(3.0);
        let fine = run_scan(2.0);
        let (dc, df) = (displacement(&coarse), displacement(&fine));
        let scale = dc
            .iter()
            .map(|d| facesim::vec3::norm(*d))
            .fold(0.0, f64::max);
        let (mut worst, mut sum, mut n) = (0.0f64, 0.0, 0usize);
        for (i, p) in coarse.skin.vertices.iter().enumerate() {
            let j = (0..fine.skin.vertices.len())
                .min_by(|&a, &b| {
                    facesim::vec3::norm(facesim::vec3::sub(fine.skin.vertices[a], *p)).total_cmp(
                        &facesim::vec3::norm(facesim::vec3::sub(fine.skin.vertices[b], *p)),
                    )
                })
                .unwrap();
            // Points of the two meshes within 0.5 mm of each other (the field's gradient is below
            // 0.3, so the offset itself accounts for at most ~0.15 mm).
            if facesim::vec3::norm(facesim::vec3::sub(fine.skin.vertices[j], *p)) < 0.5 {
                let e = facesim::vec3::norm(facesim::vec3::sub(dc[i], df[j]));
                worst = worst.max(e);
                sum += e;
                n += 1;
            }
        }
        println!(
            "{model}, 3 mm vs 2 mm scan: {n} point pairs within 0.5 mm, mean |Δd| {:.3} mm, max {worst:.3} mm, of a {scale:.3} mm peak ({:.1}% / {:.1}%)",
            sum / n as f64,
            100.0 * sum / n as f64 / scale,
            100.0 * worst / scale
        );
        assert!(n > 100);
        let mean = sum / n as f64;
        assert!(mean < 0.05 * scale && worst < 0.25 * scale, "{model}");
    }
}

#[test]
fn the_restricted_solve_equals_the_whole_mesh_solve() {
    // [solve] restrict solves only the movable skin plus a rigid ring and traces springs only
    // from the movable vertices. Triangles and springs whose DOFs are all fixed add
    // nothing to the free equations, so both must give the same face — to the Newton tolerance.
    let plan = "[surface]\nmovable = { sphere = { center = [0.0, -60.0, -45.0], radius = 70.0 } }\n\
                [[osteotomy]]\nname = \"m\"\nregion = { box = { min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] } }\n\
                translate = [0.0, -6.0, 0.0]\n";
    let on = run(&format!(
        "{plan}[solve]\nmodel = \"equilibrium\"\nrestrict = true\n"
    ));
    let off = run(&format!(
        "{plan}[solve]\nmodel = \"equilibrium\"\nrestrict = false\n"
    ));
    assert_eq!(on.face_post.vertices.len(), off.face_post.vertices.len());
    let worst = on
        .face_post
        .vertices
        .iter()
        .zip(&off.face_post.vertices)
        .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max);
    let moved = displacement(&off)
        .iter()
        .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
        .fold(0.0, f64::max);
    assert!(moved > 1.0, "the plan must move the face ({moved} mm)");
    assert!(
        worst < 1e-4 * moved,
        "restricted vs whole mesh differ by {worst} mm (max move {moved} mm)"
    );
    // Fewer unknowns and fewer springs traced.
    let (on, off) = (&on.report.counts, &off.report.counts);
    assert_eq!(on.unknowns, off.unknowns);
    assert!(on.solved_vertices < off.solved_vertices);
    assert!(on.springs_main < off.springs_main);
}

#[test]
fn the_predicted_face_does_not_depend_on_the_load_increments() {
    // The equilibrium energy is conservative, so the answer at full load does not depend on the
    // path; the solver therefore converges only the last increment to the tolerance (earlier
    // ones stop at 1e-2, src/solve.rs). One increment, two and four must give the same face.
    let plan = format!("{MANDIBLE}translate = [0.0, -6.0, 0.0]\n");
    let faces: Vec<facesim::commands::Outcome> = [1, 2, 4]
        .iter()
        .map(|n| {
            run(&format!(
                "{plan}[solve]\nmodel = \"equilibrium\"\nsteps = {n}\n"
            ))
        })
        .collect();
    let moved = displacement(&faces[0])
        .iter()
        .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
        .fold(0.0, f64::max);
    assert!(moved > 1.0, "the plan must move the face ({moved} mm)");
    for (n, o) in [2, 4].iter().zip(&faces[1..]) {
        let worst = o
            .face_post
            .vertices
            .iter()
            .zip(&faces[0].face_post.vertices)
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        assert!(
            worst < 2e-5 * moved,
            "{n} increments vs 1 differ by {worst} mm (max move {moved} mm)"
        );
        assert_eq!(o.report.solve.as_ref().map(|s| s.len()), Some(*n));
    }
}

/// A phantom case with a 1.5 mm face scan (~40 k triangles) and `extra` case.toml lines.
fn dense_case(extra: &str) -> PathBuf {
    let d = common::kept_dir("facesim-dense");
    facesim::mesh::ply::write(
        &facesim_validate::phantom::face_scan(1.5),
        &d.join("face.ply"),
        facesim::mesh::ply::Encoding::BinaryLittleEndian,
    )
    .unwrap();
    std::fs::write(
        d.join("case.toml"),
        format!(
            "name = \"dense\"\n[ct]\npath = \"{}\"\n[skin]\npath = \"face.ply\"\n{extra}",
            phantom_dir().join("ct.nii.gz").display()
        ),
    )
    .unwrap();
    d
}

#[test]
fn a_coarse_model_carries_the_full_scan_rigidly_and_keeps_rigid_skin_exact() {
    // [solve] coarse_triangles: solve on a (u, v) resampling of the scan and carry every scan
    // vertex along in the embedding shell (paper 002). Exact invariants of the whole chain: a
    // translation of all bone moves the full scan by that translation (a rigid motion of the
    // coarse skin moves the shell rigidly), and outside [surface] movable nothing moves.
    let t = [1.0, -2.0, 0.5];
    let skull = whole_skull(t);
    let dir = dense_case(&format!(
        "{skull}[solve]\nmodel = \"equilibrium\"\ncoarse_triangles = 4000\n"
    ));
    let o = facesim::commands::run(&dir, None, &facesim::observe::Quiet).unwrap();
    let coarse = o.report.surfaces.coarse.as_ref().unwrap();
    let (nc, nf) = (coarse.triangles, coarse.fine_triangles);
    assert!(
        nf > 30_000 && (3_000..6_000).contains(&nc),
        "coarse {nc} of {nf}"
    );
    assert_eq!(
        o.face_post.triangles.len(),
        nf,
        "the output is the full scan"
    );
    assert!(dir.join("out/face_post_coarse.ply").is_file());
    let tn = facesim::vec3::norm(t);
    let worst = translation_error(&o, t);
    assert!(
        worst < 1e-3 * tn,
        "coarse + embedding, rigid translation: {worst} mm"
    );

    // A jaw advancement with a movable region: rigid scan vertices stay bit-identical, and the
    // scan follows the chin forwards.
    let plan = "[surface]\nmovable = { sphere = { center = [0.0, -60.0, -45.0], radius = 70.0 } }\n\
                [[osteotomy]]\nname = \"m\"\nregion = { box = { min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] } }\n\
                translate = [0.0, -6.0, 0.0]\n[solve]\nmodel = \"equilibrium\"\ncoarse_triangles = 4000\n";
    let o = facesim::commands::run(&dense_case(plan), None, &facesim::observe::Quiet).unwrap();
    let inside = |p: &[f64; 3]| {
        (p[0]).powi(2) + (p[1] + 60.0).powi(2) + (p[2] + 45.0).powi(2) <= 70.0f64.powi(2)
    };
    let mut forward = 0;
    for (a, b) in o.skin.vertices.iter().zip(&o.face_post.vertices) {
        if !inside(a) {
            assert_eq!(a, b, "a rigid scan vertex moved");
        } else if b[1] < a[1] - 1.0 {
            forward += 1;
        }
    }
    assert!(
        forward > 1000,
        "only {forward} scan vertices moved forwards by more than 1 mm"
    );
}

//! The volumetric model through the pipeline (`[solve] model = "tet"`) on the phantom:
//! every output written, and the invariants of linear elasticity with the bone as the only load —
//! no move, no change; all bone translated, the face translates exactly; the face exactly linear
//! in the move.

use crate::common;

use facesim::case::{Case, Region};
use facesim::commands::{self, Outcome};
use facesim::observe::Quiet;

fn case(region: Region, translate: [f64; 3], rotate_deg: [f64; 3]) -> Case {
    common::coarse_tet_phantom("volumetric", region, translate, rotate_deg)
}

const MANDIBLE: Region = common::PHANTOM_MANDIBLE;

/// Every bone voxel of the phantom, with a region around it that holds the whole head (no cut
/// faces) and coarse elements (the invariants hold on any mesh).
fn whole_skull(translate: [f64; 3], rotate_deg: [f64; 3]) -> Case {
    let mut c = case(
        Region::Box {
            min: [-500.0; 3],
            max: [500.0; 3],
        },
        translate,
        rotate_deg,
    );
    c.tet.skin_size_mm = 10.0;
    c.tet.deep_size_mm = 20.0;
    c.tet.margin_mm = 200.0;
    c
}

fn run(c: Case, name: &str) -> Outcome {
    commands::run_case(c, &common::out_dir(name), &Quiet).unwrap()
}

fn moves(o: &Outcome) -> Vec<[f64; 3]> {
    o.skin
        .vertices
        .iter()
        .zip(&o.face_post.vertices)
        .map(|(a, b)| facesim::vec3::sub(*b, *a))
        .collect()
}

#[test]
fn mandibular_advance_writes_every_output_and_moves_the_lower_face() {
    let o = run(
        case(MANDIBLE, [0.0, -6.0, 0.0], [0.0; 3]),
        "facesim-tet-run",
    );
    for f in [
        "face_pre.ply",
        "face_post.obj",
        "face_post.ply",
        "face_displacement.ply",
        "displacement.csv",
        "skull_post.ply",
        "report.json",
        "tets.vtu",
    ] {
        assert!(o.out_dir.join(f).is_file(), "{f} missing");
    }
    assert!(
        !o.out_dir.join("springs.ply").exists(),
        "no springs in the volumetric model"
    );
    assert_eq!(o.face_post.vertices.len(), o.skin.vertices.len());
    let t = o
        .report
        .tet
        .as_ref()
        .expect("report.json has the tet section");
    assert!(
        t.moved_nodes > 0 && t.fixed_nodes > 0 && t.skin_nodes > 0,
        "{t:?}"
    );
    assert!(t.quality.min_dihedral_deg > 5.0, "{:?}", t.quality);
    // The chin (below the mouth, in front) comes forward by a good part of the 6 mm; the
    // forehead past the tissue mesh's box, where the tissue is held, does not move at all
    // (between the region the plan reaches and the mesh's box the face fades with the mesh).
    let d = moves(&o);
    let chin: Vec<f64> = o
        .skin
        .vertices
        .iter()
        .zip(&d)
        .filter(|(p, _)| p[2] < -70.0 && p[1] < -60.0)
        .map(|(_, v)| -v[1])
        .collect();
    assert!(!chin.is_empty());
    let chin_mean = chin.iter().sum::<f64>() / chin.len() as f64;
    assert!(
        chin_mean > 2.0 && chin_mean < 6.5,
        "chin moves {chin_mean} mm"
    );
    let (_, mesh_top) = t.mesh_box.expect("report.json tet.mesh_box");
    let forehead: Vec<f64> = o
        .skin
        .vertices
        .iter()
        .zip(&d)
        .filter(|(p, _)| p[2] > mesh_top[2])
        .map(|(_, v)| facesim::vec3::norm(*v))
        .collect();
    assert!(!forehead.is_empty(), "no face above the mesh's box");
    assert_eq!(forehead.iter().fold(0.0, |a: f64, b| a.max(*b)), 0.0);
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(o.out_dir.join("report.json")).unwrap()).unwrap();
    assert!(json["timings"]["tet_mesh"].as_f64().is_some());
    assert_eq!(json["tet"]["nodes"].as_u64().unwrap() as usize, t.nodes);
}

#[test]
fn all_bone_translated_translates_the_face_exactly() {
    let t = [1.5, -2.0, 0.7];
    let o = run(whole_skull(t, [0.0; 3]), "facesim-tet-translate");
    let r = o.report.tet.as_ref().unwrap();
    assert_eq!(r.fixed_nodes, 0, "the region holds the whole head: {r:?}");
    assert_eq!(r.face_vertices_unreached, 0);
    for (i, v) in moves(&o).iter().enumerate() {
        for c in 0..3 {
            assert!((v[c] - t[c]).abs() < 1e-9, "vertex {i}: {v:?}");
        }
    }
    // Any mesh carries a translation exactly: the discretisation-error estimate is zero.
    let e = o.report.discretisation_error.as_ref().unwrap();
    assert!(
        e.moving_face.vertices > 0 && e.moving_face.max.unwrap() < 1e-9,
        "{e:?}"
    );
}

/// The discretisation-error estimate (the case again at twice the element size, Richardson for
/// order 2) against the error it estimates: the distance from the run's face to the face at half
/// the element size, on the face vertices that move, agree within a factor of 3 on the mean.
#[test]
fn the_discretisation_error_estimate_is_the_size_of_the_error() {
    let o = run(
        case(MANDIBLE, [0.0, -5.0, 0.0], [0.0; 3]),
        "facesim-tet-estimate",
    );
    let mut fine = case(MANDIBLE, [0.0, -5.0, 0.0], [0.0; 3]);
    fine.tet.skin_size_mm /= 2.0;
    fine.tet.deep_size_mm /= 2.0;
    fine.tet.error_estimate = false;
    let f = run(fine, "facesim-tet-estimate-fine");
    assert!(f.report.discretisation_error.is_none());
    let (a, b) = (moves(&o), moves(&f));
    let d: Vec<f64> = a
        .iter()
        .zip(&b)
        .filter(|(a, b)| facesim::vec3::norm(**a).max(facesim::vec3::norm(**b)) > 0.1)
        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*a, *b)))
        .collect();
    let observed = d.iter().sum::<f64>() / d.len() as f64;
    let e = o.report.discretisation_error.as_ref().unwrap();
    let estimated = e.moving_face.mean.unwrap();
    println!(
        "estimated {estimated:.3} mm (coarse {} mm), observed against half the size {observed:.3} mm over {} vertices",
        e.coarse_skin_size_mm,
        d.len()
    );
    assert!(estimated > observed / 3.0 && estimated < 3.0 * observed);
}

/// With nothing sliding, every node released at the saw line is free whatever the plan: one
/// contact state, so the face is exactly linear in the move. With sliding (the default), tissue
/// the solution would turn inside out lifts off the bone (`lifted_off`), a state the move's size
/// chooses: linear within a state, and close to linear across them.
#[test]
fn the_face_is_exactly_linear_in_the_move_and_still_without_it() {
    let unsliding = |translate| {
        let mut c = case(MANDIBLE, translate, [0.0; 3]);
        c.tet.sliding = false;
        c
    };
    let one = moves(&run(unsliding([0.4, -3.0, 1.0]), "facesim-tet-lin1"));
    let two = moves(&run(unsliding([0.8, -6.0, 2.0]), "facesim-tet-lin2"));
    let sliding = [[0.4, -3.0, 1.0], [0.8, -6.0, 2.0]].map(|t| {
        let o = run(case(MANDIBLE, t, [0.0; 3]), "facesim-tet-lin-sliding");
        (moves(&o), o.report.tet.unwrap().lifted_off)
    });
    let nonlinear = sliding[0]
        .0
        .iter()
        .zip(&sliding[1].0)
        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(facesim::vec3::scale(*a, 2.0), *b)))
        .fold(0.0, f64::max);
    let largest = sliding[1]
        .0
        .iter()
        .map(|v| facesim::vec3::norm(*v))
        .fold(0.0, f64::max);
    println!(
        "sliding: lifted off {} and {} nodes; |2 u(t) - u(2t)| at most {nonlinear:.2e} mm of {largest:.2} mm",
        sliding[0].1, sliding[1].1
    );
    if sliding[0].1 == sliding[1].1 && sliding[0].1 == 0 {
        assert!(nonlinear < 1e-9 * largest);
    } else {
        assert!(nonlinear < 0.02 * largest);
    }
    let scale = one
        .iter()
        .map(|v| facesim::vec3::norm(*v))
        .fold(0.0, f64::max);
    assert!(scale > 1.0);
    for (a, b) in one.iter().zip(&two) {
        for c in 0..3 {
            assert!((2.0 * a[c] - b[c]).abs() < 1e-9 * scale, "{a:?} {b:?}");
        }
    }
    let none = moves(&run(
        case(MANDIBLE, [0.0; 3], [0.0; 3]),
        "facesim-tet-still",
    ));
    assert!(none.iter().all(|v| *v == [0.0; 3]));
}

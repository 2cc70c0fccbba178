//! The volumetric model on the phantom with jaws (docs/phantom.md, "Jaws"): mandibular advance and
//! setback move the soft-tissue chin with the bone, a counter-clockwise rotation brings it up and
//! forward, and the inner lip across the vestibule slides on the teeth (or, attached, moves with
//! them). The real CT has no mandible, so these moves are shown here.

mod common;

use facesim::case::{Case, SolveModel};
use facesim::commands::{self, Outcome};
use facesim::observe::Quiet;
use facesim::phantom::PhantomOptions;
use facesim::phantom_jaws::{self, JawsOptions};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn jaws_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = common::kept_dir("facesim-jaws");
        let opts = JawsOptions {
            phantom: PhantomOptions {
                spacing: [2.0; 3],
                ..PhantomOptions::default()
            },
            solve_model: Some("tet".into()),
        };
        phantom_jaws::write_case(&d, &opts).unwrap();
        d
    })
}

fn run(file: &str, sliding: bool) -> Outcome {
    let (mut case, _) = Case::load(&jaws_dir().join(file)).unwrap();
    assert_eq!(case.solve.model, SolveModel::Tet);
    case.tet.skin_size_mm = 6.0;
    case.tet.deep_size_mm = 12.0;
    case.tet.sliding = sliding;
    commands::run_case(case, &common::kept_dir("facesim-jaws-run"), &Quiet).unwrap()
}

/// The displacement of the face vertex nearest the named landmark.
fn moved(o: &Outcome, landmark: &str) -> [f64; 3] {
    let at = phantom_jaws::landmark(landmark).unwrap();
    let d = |p: &[f64; 3]| facesim::vec3::norm(facesim::vec3::sub(*p, at));
    let i = (0..o.skin.vertices.len())
        .min_by(|&a, &b| d(&o.skin.vertices[a]).total_cmp(&d(&o.skin.vertices[b])))
        .unwrap();
    assert!(
        d(&o.skin.vertices[i]) < 3.0,
        "{landmark}: no face vertex near it"
    );
    facesim::vec3::sub(o.face_post.vertices[i], o.skin.vertices[i])
}

#[test]
fn the_chin_follows_advance_setback_and_rotation_of_the_mandible() {
    let advance = moved(&run("case.toml", true), "soft tissue pogonion");
    let setback = moved(&run("case_setback.toml", true), "soft tissue pogonion");
    let rotation = moved(&run("case_rotation.toml", true), "soft tissue pogonion");
    println!(
        "soft pogonion: advance 5 → {advance:.2?}, setback 4 → {setback:.2?}, CCW 5° → {rotation:.2?}"
    );
    // Soft tissue over the chin follows its bone closely (clinical ratios ~0.9–1.0).
    assert!(advance[1] < -3.5 && advance[1] > -5.5, "{advance:?}");
    assert!(setback[1] > 2.8 && setback[1] < 4.4, "{setback:?}");
    // Counter-clockwise (seen from the patient's right): the chin comes forward and up.
    assert!(rotation[1] < -1.0 && rotation[2] > 1.0, "{rotation:?}");
}

#[test]
fn the_inner_lip_slides_on_the_teeth_or_moves_with_them() {
    let sliding = run("case.toml", true);
    let attached = run("case.toml", false);
    let (s, a) = (
        sliding.report.tet.as_ref().unwrap(),
        attached.report.tet.as_ref().unwrap(),
    );
    // The vestibule's mucosa faces the teeth across 2 mm of air: found, and sliding or attached.
    assert!(s.mucosa_nodes > 20, "{s:?}");
    // (a piece of tissue held by fewer than three nodes follows its bone, mucosa and all); the
    // bone at the saw lines slides too (released, not lifted off).
    assert!(
        s.sliding_nodes <= s.mucosa_nodes + s.released_at_cuts - s.lifted_off
            && 10 * s.sliding_nodes >= 9 * s.mucosa_nodes,
        "{s:?}"
    );
    assert_eq!(a.sliding_nodes, 0);
    assert_eq!(a.mucosa_nodes, s.mucosa_nodes);
    let (ls, la) = (
        moved(&sliding, "labrale inferius"),
        moved(&attached, "labrale inferius"),
    );
    println!("labrale inferius: sliding {ls:.3?}, attached {la:.3?}");
    assert!(facesim::vec3::norm(facesim::vec3::sub(ls, la)) > 1e-3);
    // The lower lip comes forward with the teeth either way.
    assert!(ls[1] < -2.0 && la[1] < -2.0);
}

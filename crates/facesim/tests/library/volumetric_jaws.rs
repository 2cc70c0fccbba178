//! The volumetric model on the phantom with jaws (docs/design/phantom.md, "Jaws"): mandibular advance and
//! setback move the soft-tissue chin with the bone, a counter-clockwise rotation brings it up and
//! forward, and the inner lip across the vestibule slides on the teeth (or, attached, moves with
//! them). The real CT has no mandible, so these moves are shown here.

use crate::common;

use facesim::case::{Case, SolveModel};
use facesim::commands::{self, Outcome};
use facesim::observe::Quiet;
use facesim::tet::vtu;
use facesim::vec3::{dot, norm, sub};
use facesim_validate::phantom::PhantomOptions;
use facesim_validate::phantom_jaws::{self, JawsOptions, Shape, Tissue};
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

/// The jaws phantom with its lips closed on the teeth (`Shape::closed_lips`: no vestibule air).
fn closed_lips_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = common::kept_dir("facesim-jaws-closed");
        let opts = JawsOptions {
            phantom: PhantomOptions {
                spacing: [2.0; 3],
                ..PhantomOptions::default()
            },
            solve_model: Some("tet".into()),
        };
        let shape = Shape {
            closed_lips: true,
            ..Shape::default()
        };
        phantom_jaws::write_shaped_case(&d, &opts, &shape).unwrap();
        d
    })
}

fn run(file: &str, sliding: bool) -> Outcome {
    run_in(jaws_dir(), file, sliding)
}

fn run_in(dir: &Path, file: &str, sliding: bool) -> Outcome {
    run_sized(dir, file, sliding, 6.0)
}

/// `run_in` with the element edge `skin_mm` at the skin (twice it deep).
fn run_sized(dir: &Path, file: &str, sliding: bool, skin_mm: f64) -> Outcome {
    let (mut case, _) = Case::load(&dir.join(file)).unwrap();
    assert_eq!(case.solve.model, SolveModel::Tet);
    case.tet.skin_size_mm = skin_mm;
    case.tet.deep_size_mm = 2.0 * skin_mm;
    case.tet.sliding = sliding;
    commands::run_case(case, &common::out_dir("facesim-jaws-run"), &Quiet).unwrap()
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
    // A BSSO's distal segment carries the lower teeth and B point: no chin, nothing raised,
    // though the open vestibule leaves few of its teeth under the lip (`model::degloved`).
    assert_eq!((s.degloved_nodes, s.degloved_chin_nodes), (0, 0), "{s:?}");
    // (a piece of tissue held by fewer than three nodes follows its bone, mucosa and all); the
    // bone at the saw lines slides too (released, not lifted off), and so does the bone where
    // lip or cheek lies on a tooth with no air between (`contact_nodes`, here the
    // cheeks on the molars behind the vestibule's ends). The tissue where the scan ends (the
    // neck) is free by default (`[tet] scan_end = "free"`, counted apart in `scan_end`).
    let end = s
        .scan_end
        .as_ref()
        .expect("the mesh reaches the scan's end");
    assert!(end.sliding_nodes == 0 && end.free_nodes > 0, "{end:?}");
    assert!(
        s.sliding_nodes <= s.mucosa_nodes + s.contact_nodes + s.released_at_cuts - s.lifted_off
            && 10 * s.sliding_nodes >= 9 * s.mucosa_nodes,
        "{s:?}"
    );
    // Bonded to its bone, nothing slides.
    assert_eq!(a.sliding_nodes, 0);
    assert_eq!(a.mucosa_nodes, s.mucosa_nodes);
    assert_eq!(a.contact_nodes, s.contact_nodes);
    assert_eq!(a.contact_sliding_nodes, 0);
    let (ls, la) = (
        moved(&sliding, "labrale inferius"),
        moved(&attached, "labrale inferius"),
    );
    println!("labrale inferius: sliding {ls:.3?}, attached {la:.3?}");
    assert!(facesim::vec3::norm(facesim::vec3::sub(ls, la)) > 1e-3);
    // The lower lip comes forward with the teeth either way.
    assert!(ls[1] < -2.0 && la[1] < -2.0);
}

/// Into the tissue from each node: the mean direction to its cells' centroids (the normal
/// `tet::conditions::contact` slides the node along).
fn inward(v: &vtu::TetsVtuOwned) -> Vec<[f64; 3]> {
    let cells = v.cells.view();
    let mut w = vec![[0.0; 3]; v.nodes.len()];
    for c in 0..cells.len() {
        let q = &cells.cell(c)[..4];
        let centroid: [f64; 3] =
            std::array::from_fn(|k| q.iter().map(|n| v.nodes[*n as usize][k]).sum::<f64>() / 4.0);
        for n in q {
            let n = *n as usize;
            w[n] = facesim::vec3::add(w[n], sub(centroid, v.nodes[n]));
        }
    }
    w.into_iter()
        .map(|d| {
            let l = norm(d);
            d.map(|c| c / l)
        })
        .collect()
}

/// The bone surface's normal a node slides on (docs/design/pipeline.md "Lip–tooth contact"): the
/// area-weighted mean normal of the skull's facets within `r` of p that face the side `toward`
/// points to, written out here again by brute force.
fn bone_normal(skull: &facesim::mesh::Mesh, p: [f64; 3], toward: [f64; 3], r: f64) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for t in &skull.triangles {
        let v = t.map(|i| skull.vertices[i as usize]);
        let c: [f64; 3] = std::array::from_fn(|k| (v[0][k] + v[1][k] + v[2][k]) / 3.0);
        let a = facesim::vec3::cross(sub(v[1], v[0]), sub(v[2], v[0]));
        if norm(sub(c, p)) <= r && dot(a, toward) > 0.0 {
            sum = facesim::vec3::add(sum, a);
        }
    }
    let l = norm(sum);
    assert!(l > 0.0, "no skull facet within {r} mm of {p:?}");
    sum.map(|c| c / l)
}

/// Is a tooth within `r` mm of p (the phantom's exact tissue on a small grid around it)?
fn near_tooth(p: [f64; 3], r: f64) -> bool {
    let k = 3;
    (-k..=k).any(|a| {
        (-k..=k).any(|b| {
            (-k..=k).any(|c| {
                let q = [a, b, c].map(|i| i as f64 * r / k as f64);
                norm(q) <= r
                    && phantom_jaws::tissue_at([p[0] + q[0], p[1] + q[1], p[2] + q[2]])
                        == Tissue::Tooth
            })
        })
    })
}

/// Lips closed on the teeth (no vestibule air, `Shape::closed_lips`) under a
/// 5 mm mandibular advance (−y). The lip–tooth contact is found from the anatomy
/// (`tet::conditions::contact`: bone ≥ 1450 HU 3 mm deep, the face's air reached through soft
/// tissue) and slides with `[tet] sliding`, is attached without.
///
/// The bound: the attached solution is the energy minimum with u = u_bone on the contact; the
/// sliding one minimises the same energy with only n · u = n · u_bone there, a larger set. Its
/// contact nodes keep the bone's normal move exactly, and the tissue around them, held above by
/// the maxilla and cranium that stay, holds them back along the tooth: the tangential move along
/// the bone's tangential move is less than the bone's (ratio < 1; attached it is exactly 1).
#[test]
fn lips_closed_on_the_teeth_slide_on_them() {
    let on = run_sized(closed_lips_dir(), "case.toml", true, 6.0);
    let off = run_sized(closed_lips_dir(), "case.toml", false, 6.0);
    let (s, a) = (
        on.report.tet.as_ref().unwrap(),
        off.report.tet.as_ref().unwrap(),
    );
    println!(
        "closed lips: contact {} (sliding {}), mucosa {}, sliding {}, released {}, lifted {}; off: contact {} sliding {}",
        s.contact_nodes,
        s.contact_sliding_nodes,
        s.mucosa_nodes,
        s.sliding_nodes,
        s.released_at_cuts,
        s.lifted_off,
        a.contact_nodes,
        a.contact_sliding_nodes
    );
    // Found from the anatomy at rest, sliding or not.
    assert!(s.contact_nodes > 0);
    assert_eq!(a.contact_nodes, s.contact_nodes);
    assert!(s.contact_sliding_nodes > 0);
    assert_eq!(a.contact_sliding_nodes, 0);
    assert_eq!(s.inverted_elements, 0);
    let vs = vtu::read(&on.out_dir.join("tets.vtu")).unwrap();
    let va = vtu::read(&off.out_dir.join("tets.vtu")).unwrap();
    assert_eq!(vs.nodes, va.nodes);
    let normal = inward(&vs);
    let advance = [0.0, -5.0, 0.0];
    // Sliding with sliding on and held by their bone with it off: the contact (and mucosa) nodes.
    let picked: Vec<usize> = (0..vs.nodes.len())
        .filter(|n| vs.constraint[*n] == 3 && [vtu::MOVED, vtu::FIXED].contains(&va.constraint[*n]))
        .collect();
    assert!(
        picked.len() + s.mucosa_nodes >= s.contact_sliding_nodes,
        "{}",
        picked.len()
    );
    // Each on a tooth, facing out of the dental arch (centre (0, −24)) into lip or cheek.
    for &n in &picked {
        let p = vs.nodes[n];
        let out = [p[0], p[1] + 24.0, 0.0];
        assert!(
            near_tooth(p, 2.5) && dot(normal[n], out) > 0.0,
            "contact node at {p:?} (normal {:?}) is not on the lip or cheek side of a tooth",
            normal[n]
        );
    }
    let mut ratio = Vec::new();
    let mut lag = Vec::new();
    let mut normal_err: f64 = 0.0;
    let mut tied_err: f64 = 0.0;
    for &n in picked.iter().filter(|n| va.constraint[**n] == vtu::MOVED) {
        let (us, ua) = (vs.displacement[n], va.displacement[n]);
        tied_err = tied_err.max(norm(sub(ua, advance)));
        let nn = bone_normal(&on.skull, vs.nodes[n], normal[n], 6.0);
        normal_err = normal_err.max(dot(nn, sub(us, advance)).abs());
        let bt = sub(advance, nn.map(|c| c * dot(nn, advance)));
        let ut = sub(us, nn.map(|c| c * dot(nn, us)));
        if norm(bt) > 0.5 {
            ratio.push(dot(ut, bt) / dot(bt, bt));
        }
        lag.push(norm(sub(us, advance)));
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    println!(
        "picked {} ({} on the mandible); normal err {normal_err:.2e}, attached err {tied_err:.2e}; tangential ratio mean {:.3} (n {}), lag mean {:.3} max {:.3}",
        picked.len(),
        lag.len(),
        mean(&ratio),
        ratio.len(),
        mean(&lag),
        lag.iter().cloned().fold(0.0, f64::max)
    );
    for lm in [
        "labrale inferius",
        "stomion",
        "labrale superius",
        "soft tissue pogonion",
    ] {
        let (ms, ma) = (moved(&on, lm), moved(&off, lm));
        println!("{lm}: sliding {ms:.3?}, attached {ma:.3?}");
    }
    assert!(!ratio.is_empty());
    // Attached: the bone's move exactly; sliding: the bone's normal move exactly, and dragged
    // less along the tooth than the bone moves.
    assert!(
        tied_err < 1e-9 && normal_err < 1e-9,
        "{tied_err} {normal_err}"
    );
    assert!(mean(&ratio) < 1.0, "{ratio:?}");
    assert!(mean(&lag) > 0.0);
}

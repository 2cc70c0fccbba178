//! Landmarks, measurements and regions (docs/landmarks.md): on the jaws phantom against its
//! analytic landmarks and angles, on the real CT where they are plausible and where the scan
//! lacks the mandible; user landmarks override; the markups files follow Slicer's schema; a
//! zero move leaves every landmark in place.

mod common;

use common::kept_dir;
use facesim::case::Case;
use facesim::landmarks::{self, Kind, Source, measure};
use facesim::mesh::{norm, sub};
use facesim::observe::Quiet;
use facesim::osteotomy::Plan;
use facesim::phantom::PhantomOptions;
use facesim::phantom_jaws::{self as pj};
use facesim::pipeline::{self, Scene};
use std::path::Path;
use std::sync::OnceLock;

/// The jaws phantom's case (1.5 mm voxels, 1 mm face scan), prepared once.
fn jaws() -> &'static (std::path::PathBuf, Scene) {
    static S: OnceLock<(std::path::PathBuf, Scene)> = OnceLock::new();
    S.get_or_init(|| {
        let dir = kept_dir("facesim-landmarks-jaws");
        let opts = pj::JawsOptions {
            phantom: PhantomOptions {
                spacing: [1.5; 3],
                supersample: 2,
                scan_step_mm: 1.0,
                ..Default::default()
            },
            solve_model: None,
        };
        pj::write_case(&dir, &opts).unwrap();
        let (case, _) = Case::load(&dir.join("case.toml")).unwrap();
        let scene = pipeline::prepare_case(&case, &Quiet).unwrap();
        (dir, scene)
    })
}

fn position(lms: &[landmarks::Landmark], label: &str) -> Option<[f64; 3]> {
    lms.iter()
        .find(|l| l.label == label)
        .and_then(|l| l.position)
}

/// Golden-section search for the maximum of f on [a, b].
fn argmax(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..200 {
        let (c, d) = (b - g * (b - a), a + g * (b - a));
        if f(c) > f(d) {
            b = d;
        } else {
            a = c;
        }
    }
    0.5 * (a + b)
}

/// Subnasale by its definition (docs/landmarks.md) on the analytic midline profile: the point
/// between pronasale and labrale superius farthest behind their chord.
fn analytic_subnasale() -> [f64; 3] {
    let r = |z: f64| pj::skin_radius(0.0, z);
    let prn = pj::landmark("pronasale").unwrap();
    let ls = pj::landmark("labrale superius").unwrap();
    let (v1, a1, v2, a2) = (prn[2], -prn[1], ls[2], -ls[1]);
    let behind = |z: f64| ((r(z) - a1) * (v2 - v1) - (z - v1) * (a2 - a1));
    let z = argmax(behind, ls[2], prn[2]);
    pj::skin_point(0.0, z)
}

#[test]
fn phantom_landmarks_are_where_the_analytic_definitions_put_them() {
    let (_, scene) = jaws();
    let (frame, lms) = landmarks::locate(
        &scene.face.skin,
        Some(&scene.face.skull),
        &[],
        Path::new("case.toml"),
    )
    .unwrap();
    let frame = frame.unwrap();
    for l in &lms {
        println!("{} {:?} {:?}", l.label, l.position, l.missing);
    }
    // The phantom is mirror-symmetric about x = 0.
    assert!(
        frame.lateral[0] > 0.9999 && frame.origin[0].abs() < 0.05,
        "{frame:?}"
    );
    // Soft tissue on the 1 mm face scan: within 1 mm (the profile is sampled every 0.25 mm on
    // the scan's 1 mm facets); bone on the 1.5 mm CT's skull surface: within 2 mm.
    let pairs = [
        ("Prn", "pronasale", 1.0),
        ("Ls", "labrale superius", 1.0),
        ("Sto", "stomion", 1.0),
        ("Li", "labrale inferius", 1.0),
        ("Pog'", "soft tissue pogonion", 1.0),
        ("A", "A point", 2.0),
        ("B", "B point", 2.0),
        ("Pog", "pogonion", 2.0),
    ];
    for (label, name, tol) in pairs {
        let got = position(&lms, label).unwrap_or_else(|| panic!("{label} missing"));
        let want = pj::landmark(name).unwrap();
        let d = norm(sub(got, want));
        println!("{label}: {d:.2} mm from the analytic {name}");
        assert!(d < tol, "{label} {got:?} vs {want:?}: {d:.2} mm");
    }
    let sn = position(&lms, "Sn").unwrap();
    let d = norm(sub(sn, analytic_subnasale()));
    assert!(d < 1.0, "Sn {sn:?} vs {:?}", analytic_subnasale());
    // Menton: the lowest bone of the symphysis, whose lower border is flat across (it may be
    // found anywhere along its 5 mm flat middle) — its height within 1.5 mm.
    let me = position(&lms, "Me").unwrap();
    assert!((me[2] - pj::Z_MENTON).abs() < 1.5, "Me {me:?}");
    // Soft menton is the skin directly below the detected menton: the analytic skin there.
    let me_s = position(&lms, "Me'").unwrap();
    let rho = -me[1];
    let (mut lo, mut hi) = (-110.0, me[2]);
    for _ in 0..100 {
        let m = 0.5 * (lo + hi);
        if pj::skin_radius(0.0, m) > rho {
            hi = m;
        } else {
            lo = m;
        }
    }
    assert!((me_s[2] - lo).abs() < 1.0, "Me' {me_s:?} vs z {lo}");
    // The phantom's forehead is a cylinder: no soft nasion or glabella, so no bony nasion — all
    // reported missing, with a reason, never placed.
    for l in ["N'", "G'", "N"] {
        let lm = lms.iter().find(|x| x.label == l).unwrap();
        assert!(lm.position.is_none() && lm.missing.is_some(), "{lm:?}");
    }
    // Measurements: the angles from the analytic landmarks.
    let carried = landmarks::carry(&lms, &scene.face.skin, &scene.face.skin, &Plan::new(&[]));
    let (m, _) = measure::measure(&carried, &frame);
    let va = |p: [f64; 3]| [p[2], -p[1]];
    let want_nl = measure::angle_deg(
        va(pj::landmark("pronasale").unwrap()),
        va(analytic_subnasale()),
        va(pj::landmark("labrale superius").unwrap()),
    );
    let get = |k: &str| m.0.iter().find(|(n, _)| n == k).unwrap().1.clone();
    let nl = get("nasolabial_angle").before.unwrap();
    println!("nasolabial {nl:.1}° (analytic {want_nl:.1}°)");
    assert!((nl - want_nl).abs() < 3.0, "{nl} vs {want_nl}");
    let el = get("lower_lip_to_e_line").before.unwrap();
    let want_el = measure::to_line(
        va(pj::landmark("labrale inferius").unwrap()),
        va(pj::landmark("pronasale").unwrap()),
        va(pj::landmark("soft tissue pogonion").unwrap()),
    );
    assert!((el - want_el).abs() < 0.5, "{el} vs {want_el}");
}

//! The jaw landmarks on the jaws phantom (against its analytic anatomy) and on the two real
//! CTs (against positions placed by hand, `REAL` and `REAL_MANDIBLE`).

use super::*;
use crate::landmarks::HeadFrame;
use crate::volume::Volume;
use std::path::Path;
use std::sync::OnceLock;

/// A CT, its tissue labels and its frame.
struct Case {
    vol: Volume,
    labels: Vec<u8>,
    frame: HeadFrame,
}

impl Case {
    fn landmarks(&self) -> (Vec<Landmark>, f64) {
        let bone = Bone {
            vol: &self.vol,
            labels: &self.labels,
        };
        let t = std::time::Instant::now();
        let l = jaw_landmarks(&bone, &self.frame);
        (l, t.elapsed().as_secs_f64())
    }
}

/// The jaws phantom at 1.5 mm, segmented with the default tissue windows, in its upright
/// frame (lateral +x, up +z, forward −y) through pronasale.
fn phantom() -> &'static Case {
    static C: OnceLock<Case> = OnceLock::new();
    C.get_or_init(|| {
        let vol = crate::test_phantoms::jaws_ct();
        let case = crate::case::Case::default();
        let seg = crate::segment::segment(&vol, &case.tissue, Path::new("phantom")).unwrap();
        let prn = facesim_validate::phantom_jaws::landmark("pronasale").unwrap();
        let frame = HeadFrame::from_plane([0.0, prn[1], prn[2]], [1.0, 0.0, 0.0], 0.0);
        Case {
            vol,
            labels: seg.labels,
            frame,
        }
    })
}

/// A real sample's CT, tissue labels and skin frame turned face-down by `pitch_deg`, read the
/// way the pipeline reads them (its stages up to the face). None, with a line saying so, when
/// its CT has not been fetched.
fn real_case(dir: &str, pitch_deg: f64) -> Option<Case> {
    let s = crate::anatomy::sample::read(dir)?;
    let frame = crate::landmarks::head_frame(&s.skin).unwrap();
    Some(Case {
        vol: s.vol,
        labels: s.labels,
        frame: crate::anatomy::bone::turned(&frame, pitch_deg),
    })
}

fn real() -> Option<&'static Case> {
    static C: OnceLock<Option<Case>> = OnceLock::new();
    C.get_or_init(|| real_case("real", 0.0)).as_ref()
}

fn real_mandible() -> Option<&'static Case> {
    static C: OnceLock<Option<Case>> = OnceLock::new();
    C.get_or_init(|| real_case("real-mandible", 16.0)).as_ref()
}

fn dist(p: [f64; 3], q: [f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

fn position(l: &[Landmark], label: &str) -> [f64; 3] {
    let m = l.iter().find(|x| x.label == label).unwrap();
    m.position
        .unwrap_or_else(|| panic!("{label} missing: {}", m.missing.clone().unwrap_or_default()))
}

fn missing(l: &[Landmark], label: &str) -> String {
    let m = l.iter().find(|x| x.label == label).unwrap();
    assert!(m.position.is_none(), "{label} found at {:?}", m.position);
    m.missing.clone().unwrap()
}

/// Every label of `LANDMARKS[4..]`, in order, each a bone landmark found or missing with a
/// one-line reason.
fn well_formed(l: &[Landmark]) {
    let labels: Vec<&str> = l.iter().map(|x| x.label.as_str()).collect();
    assert_eq!(labels, crate::anatomy::bone::LANDMARKS[4..].to_vec());
    for x in l {
        assert_eq!(x.kind, Kind::Bone);
        assert_eq!(x.source, Source::Detected);
        match (&x.position, &x.missing) {
            (Some(p), None) => assert!(p.iter().all(|c| c.is_finite()), "{}", x.label),
            (None, Some(why)) => assert!(!why.is_empty() && !why.contains('\n'), "{why}"),
            _ => panic!(
                "{}: position and reason {:?} {:?}",
                x.label, x.position, x.missing
            ),
        }
    }
}

/// Hand-placed landmarks (LPS mm), each with the tolerance it is held to and how it was placed.
type Fixture = [(&'static str, [f64; 3], f64, &'static str)];

fn check(name: &str, l: &[Landmark], fixture: &Fixture) {
    let mut bad = Vec::new();
    for (label, want, tol, _) in fixture {
        let got = position(l, label);
        let d = dist(got, *want);
        println!("{name} {label:8} {d:5.1} mm (tolerance {tol})");
        if d > *tol {
            bad.push(format!("{label} at {got:.1?}, {d:.1} mm from {want:?}"));
        }
    }
    assert!(bad.is_empty(), "{name}: {bad:#?}");
}

/// The phantom's jaw landmarks against its analytic anatomy (phantom_jaws.rs's table; voxels
/// 1.5 mm). Tolerances: about a voxel plus what the definition leaves open.
#[test]
fn phantom_jaw_landmarks_lie_on_its_analytic_anatomy() {
    let c = phantom();
    let (l, _) = c.landmarks();
    well_formed(&l);
    for x in &l {
        println!("phantom {} {:?} {:?}", x.label, x.position, x.missing);
    }
    let truth = |n: &str| facesim_validate::phantom_jaws::landmark(n).unwrap();
    let mirror = |p: [f64; 3]| [-p[0], p[1], p[2]];
    // Either central incisor: the phantom's are mirror images (its tip is the right one's).
    let either = |got: [f64; 3], p: [f64; 3]| dist(got, p).min(dist(got, mirror(p)));
    let u1 = position(&l, "U1");
    println!(
        "phantom U1 {:.1} mm",
        either(u1, truth("upper incisor tip"))
    );
    assert!(either(u1, truth("upper incisor tip")) < 2.5, "U1 {u1:?}");
    let l1 = position(&l, "L1");
    println!(
        "phantom L1 {:.1} mm",
        either(l1, truth("lower incisor tip"))
    );
    assert!(either(l1, truth("lower incisor tip")) < 3.0, "L1 {l1:?}");
    let fixture: &Fixture = &[
        (
            "A",
            truth("A point"),
            2.5,
            "deepest point of the maxilla's labial dip (z = -4)",
        ),
        (
            "B",
            truth("B point"),
            2.5,
            "deepest point of the symphysis' labial dip",
        ),
        (
            "Pog",
            truth("pogonion"),
            2.5,
            "the chin's most anterior point (z = -55)",
        ),
        (
            "Me",
            truth("menton"),
            2.0,
            "the symphysis' lowest point (z = -66)",
        ),
        // The top of each condylar ellipsoid: centre z -3 + semi-axis 4.
        (
            "Co-R",
            [-48.0, 7.0, 1.0],
            2.0,
            "condyle centre (-48, 7, -3) + 4 mm up",
        ),
        (
            "Co-L",
            [48.0, 7.0, 1.0],
            2.0,
            "condyle centre (48, 7, -3) + 4 mm up",
        ),
        // The rami are boxes |x| 38-47, y -8..18, z -56..-10: the angle is their lower back
        // edge, x anywhere across the ramus' 9 mm (its middle here).
        (
            "Go-R",
            [-42.5, 18.0, -56.0],
            3.0,
            "ramus box's posterior-inferior edge",
        ),
        (
            "Go-L",
            [42.5, 18.0, -56.0],
            3.0,
            "ramus box's posterior-inferior edge",
        ),
        // The palate (z -6..-2) ends on the midline at the arch centre (y -24), where the
        // maxilla's arch angle passes 90°.
        (
            "PNS",
            [0.0, -24.0, -4.0],
            2.0,
            "posterior end of the palate on the midline",
        ),
        // The phantom's maxilla has no spine: ANS is the top of its labial face (z 1.5).
        (
            "ANS",
            [0.0, -72.0, 1.5],
            2.5,
            "top of the maxilla's labial face on the midline",
        ),
    ];
    check("phantom", &l, fixture);
    // Its maxilla is a closed band under a soft nose: no piriform aperture.
    for label in ["Pir-R", "Pir-L"] {
        assert_eq!(missing(&l, label), "no piriform aperture above ANS");
    }
    // Gnathion: on the chin's outline between pogonion and menton.
    let (gn, pog, me) = (position(&l, "Gn"), position(&l, "Pog"), position(&l, "Me"));
    assert!(gn[2] < pog[2] && gn[2] > me[2] - 1.0, "Gn {gn:?}");
    assert!(gn[1] > pog[1] - 1.0 && gn[1] < me[1] + 1.0, "Gn {gn:?}");
    let bone = |p: [f64; 3]| facesim_validate::phantom_jaws::piece_at(p).is_some();
    let near = |p: [f64; 3], want: bool| {
        (-3..=3).any(|i| {
            (-3..=3).any(|k| bone([p[0], p[1] + i as f64 * 0.5, p[2] + k as f64 * 0.5]) == want)
        })
    };
    assert!(
        near(gn, true) && near(gn, false),
        "Gn {gn:?} is not on the outline"
    );
    // Apices, estimated: 23.5 / 21 mm from the edge, up / down the crown's axis (the phantom's
    // crowns have a vertical labial face and taper lingually: the axis through their sections' middles leans back ≤ 30°).
    for (tip, apex, len, up) in [("U1", "U1-apex", 23.5, 1.0), ("L1", "L1-apex", 21.0, -1.0)] {
        let (t, a) = (position(&l, tip), position(&l, apex));
        assert!((dist(t, a) - len).abs() < 1e-6, "{apex} {a:?}");
        let cos = up * (a[2] - t[2]) / len;
        assert!(
            cos > 30f64.to_radians().cos(),
            "{apex} {a:?} leans {:.0}°",
            cos.acos().to_degrees()
        );
        assert!(a[1] >= t[1] - 0.5, "{apex} {a:?} leans forward");
    }
    // Upper molars: the occlusal edge (z -23) 25-35 mm behind U1, on a crown of the arch.
    for label in ["U6-R", "U6-L"] {
        let p = position(&l, label);
        assert!((p[2] + 23.0).abs() < 1.5, "{label} {p:?}");
        assert!((24.0..=36.0).contains(&(p[1] - u1[1])), "{label} {p:?}");
        let tooth = (0..=4).any(|k| {
            facesim_validate::phantom_jaws::tissue_at([p[0], p[1], p[2] + 0.5 * k as f64])
                == facesim_validate::phantom_jaws::Tissue::Tooth
        });
        assert!(tooth, "{label} {p:?} is not on an upper crown");
    }
    // Mental foramina, estimated: on the body's outer face, 22 mm behind L1's face, between
    // the alveolar crest (z -36) and the lower border.
    for label in ["MF-R", "MF-L"] {
        let p = position(&l, label);
        let out = p[0].signum();
        assert!(
            bone([p[0] - out * 1.5, p[1], p[2]]),
            "{label} {p:?} not on the body"
        );
        assert!(
            !bone([p[0] + out * 1.5, p[1], p[2]]),
            "{label} {p:?} inside the body"
        );
        assert!(p[2] < -40.0 && p[2] > -58.0, "{label} {p:?}");
        assert!((p[1] - l1[1] - 22.0).abs() < 2.0, "{label} {p:?}");
    }
}

/// ProMED CT 0051 (data-samples/real): the skull down to the upper incisor crowns, no
/// mandible. Placed by hand on the midsagittal section of the skin's frame (HU > 400 profile,
/// 0.25 mm steps, 3 mm slab).
const REAL: &Fixture = &[
    (
        "ANS",
        [126.4, 38.6, 21.0],
        3.0,
        "most anterior bone at the nasal floor (v -13.5, a -27.75); above it the front steps back 6 mm into the aperture",
    ),
    (
        "A",
        [126.5, 40.9, 15.0],
        3.0,
        "most posterior point of the front profile between ANS and the crowns (a -30 at v -19..-20)",
    ),
    (
        "PNS",
        [126.5, 84.9, 17.0],
        3.0,
        "the palate's back end (a -74 at v -17..-18)",
    ),
    (
        "Pir-R",
        [122.6, 37.9, 22.4],
        4.0,
        "frontal view, lines of sight with no bone over 400 HU from 5 mm before ANS to 25 mm behind: the aperture's lowest row right of the septum (v -11.5, s -2..-6.5), the bone's front below (it slopes back about 1 mm per mm from the septum: 4 mm)",
    ),
    (
        "Pir-L",
        [130.2, 43.6, 21.6],
        3.0,
        "as Pir-R, left of the septum (v -12.5, s 2.5..5)",
    ),
];

#[test]
fn real_ct_without_mandible_finds_the_maxilla_and_says_why_the_rest_is_missing() {
    let Some(c) = real() else { return };
    let (l, t) = c.landmarks();
    println!("real: {t:.3} s");
    for x in &l {
        println!(
            "{} {:?} {:?}",
            x.label,
            x.position.map(|p| c.frame.coords(p)),
            x.missing
        );
    }
    well_formed(&l);
    check("real", &l, REAL);
    for label in ["U1", "U1-apex"] {
        assert!(missing(&l, label).contains("field of view ends within the upper incisor"));
    }
    for label in ["U6-R", "U6-L"] {
        assert!(missing(&l, label).contains("field of view"), "{label}");
    }
    for label in [
        "L1", "L1-apex", "B", "Pog", "Gn", "Me", "MF-R", "MF-L", "Go-R", "Go-L", "Co-R", "Co-L",
    ] {
        assert_eq!(
            missing(&l, label),
            "the CT's field of view ends above the mandible"
        );
    }
}

/// VTK's headsq (data-samples/real-mandible, 3.2 × 3.2 × 1.5 mm voxels, pitched 16° face-down:
/// the skin's frame turned 16°). Placed by hand on sections of the turned frame: midline
/// profiles are the most anterior point per 1 mm row with HU > 400 in a 3 mm slab (0.25 mm
/// steps); tolerances 3–5 mm (a voxel is 3.2 mm across).
const REAL_MANDIBLE: &Fixture = &[
    (
        "U1",
        [94.0, -159.6, -95.6],
        3.0,
        "lowest point over 800 HU of the upper incisor crowns, 8 mm slab (validation.toml: z -96, y -160)",
    ),
    (
        "L1",
        [96.0, -153.8, -103.3],
        4.0,
        "highest point over 800 HU of the lower incisor crowns, 8 mm slab (validation.toml: z -103.5, y -154); which incisor is not resolved",
    ),
    (
        "Me",
        [96.5, -130.2, -133.9],
        3.0,
        "lowest point over 400 HU of the symphysis, 2 mm slab (validation.toml: z -133.5)",
    ),
    (
        "Pog",
        [96.6, -139.1, -130.1],
        4.0,
        "profile point farthest in front of the line menton-L1 (v -99, a -20.3; the front is flat, a -20.25..-20.5, from v -97 to -100)",
    ),
    (
        "B",
        [96.6, -142.0, -123.6],
        4.0,
        "middle of the profile's concavity behind the line L1-Pog: flat (0.75-1.1 mm deep) from v -88 to -96, placed at v -92, a -19.3 (validation.toml reads z -121.5, v -89.5)",
    ),
    (
        "Gn",
        [96.5, -135.5, -133.4],
        3.0,
        "most anterior-inferior point over 400 HU (45° tangent) between Pog and Me",
    ),
    (
        "ANS",
        [97.1, -161.8, -72.1],
        4.0,
        "where the nasal floor (top v -35..-36) meets the front profile (a -14.5 at v -37); no spine projects at this resolution",
    ),
    (
        "A",
        [97.1, -162.0, -78.4],
        4.0,
        "profile point deepest (0.65 mm) behind the line ANS to the alveolar crest (v -50): v -43, a -12.5; shallow, placed to within a few mm along the profile",
    ),
    (
        "PNS",
        [97.0, -122.2, -61.3],
        3.0,
        "the hard palate's end along its midline row v -37.5 (HU falls through 300 at a -55.5; the soft palate goes on below)",
    ),
    (
        "Pir-R",
        [90.6, -158.6, -69.5],
        3.0,
        "frontal view as on the other CT: the aperture's lowest row right of the septum (v -35, s -4..-9), the bone's front below",
    ),
    (
        "Pir-L",
        [101.9, -158.1, -69.5],
        3.0,
        "as Pir-R, left of the septum (v -35, s 2..8)",
    ),
    (
        "U6-R",
        [71.9, -133.0, -83.7],
        3.0,
        "sagittal section 25 mm right (6 mm MIP), the upper teeth's occlusal outline 28 mm behind U1 (v -56.3)",
    ),
    (
        "U6-L",
        [119.9, -133.3, -85.8],
        3.0,
        "sagittal section 23 mm left (6 mm MIP), the upper teeth's occlusal outline 27 mm behind U1 (v -57.8)",
    ),
    (
        "Co-R",
        [49.5, -99.5, -31.75],
        3.0,
        "CT columns (1 mm apart) through the head: the highest top of a column over 550 HU with the joint space (~300 HU) above",
    ),
    ("Co-L", [147.5, -98.5, -33.75], 3.0, "as Co-R"),
    (
        "Go-R",
        [54.0, -86.5, -86.0],
        5.0,
        "lateral MIP over x 35-70 (CT y-z): the angle's outline where the bisector of the posterior border's and the lower border's tangents meets it",
    ),
    (
        "Go-L",
        [141.0, -85.0, -87.0],
        5.0,
        "as Go-R, MIP over x 125-162",
    ),
];

#[test]
fn real_ct_with_mandible_matches_the_hand_placed_landmarks() {
    let Some(c) = real_mandible() else { return };
    let (l, t) = c.landmarks();
    println!("real-mandible: {t:.3} s");
    for x in &l {
        println!(
            "{} {:?} {:?}",
            x.label,
            x.position.map(|p| c.frame.coords(p)),
            x.missing
        );
    }
    well_formed(&l);
    check("real-mandible", &l, REAL_MANDIBLE);
    // The estimates: apices along the crowns' axes, foramina on the body's outer face.
    for (tip, apex, len) in [("U1", "U1-apex", 23.5), ("L1", "L1-apex", 21.0)] {
        let d = dist(position(&l, tip), position(&l, apex));
        assert!((d - len).abs() < 1e-6, "{apex}");
    }
    let bone = Bone {
        vol: &c.vol,
        labels: &c.labels,
    };
    for label in ["MF-R", "MF-L"] {
        let p = c.frame.coords(position(&l, label));
        let out = p[0].signum();
        let at = |ds: f64| bone.is_bone(c.frame.point([p[0] + ds, p[1], p[2]]));
        assert!(
            (-4..=0).any(|k| at(k as f64 * out)),
            "{label} {p:?} not at the body"
        );
        assert!(!at(4.0 * out), "{label} {p:?} inside the body");
    }
}

/// Input no head gives: air everywhere, a volume of one voxel, a frame pointing nowhere.
#[test]
fn odd_input_gives_every_landmark_missing_without_panicking() {
    let vol = Volume {
        dims: [4, 4, 4],
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        data: vec![-1000.0; 64],
    };
    let labels = vec![0u8; 64];
    let bone = Bone {
        vol: &vol,
        labels: &labels,
    };
    for frame in [
        HeadFrame::from_plane([0.0; 3], [1.0, 0.0, 0.0], 0.0),
        HeadFrame::from_plane([1e9, -1e9, 0.0], [0.0, 0.0, 1.0], 0.0),
    ] {
        let l = jaw_landmarks(&bone, &frame);
        well_formed(&l);
        assert!(l.iter().all(|x| x.position.is_none()));
    }
    // All bone: a block of bone is no jaw either.
    let labels = vec![crate::labels::BONE; 64];
    let bone = Bone {
        vol: &vol,
        labels: &labels,
    };
    let l = jaw_landmarks(
        &bone,
        &HeadFrame::from_plane([2.0; 3], [1.0, 0.0, 0.0], 0.0),
    );
    well_formed(&l);
}

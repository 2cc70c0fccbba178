//! Landmarks on a face mesh alone, no CT (docs/guide/landmarks.md "A face mesh
//! alone"): a real head's skin made by another program (scikit-image's marching cubes of
//! VTK's headsq CT, tests/python/isosurface.py), cut to its outer face, and the same mesh as a
//! scanner would hand it over — turned into a y-up frame, yawed, in metres. The landmarks must
//! come back rotated and scaled with the mesh.

use crate::common;

use facesim::landmarks::scan::{FaceLandmarks, FrameFrom, landmarks_of};
use facesim::mesh::Mesh;
use std::sync::OnceLock;

/// headsq's whole iso-surface at −500 HU by scikit-image, cut to what a range scan sees.
fn headsq_face() -> &'static Mesh {
    static FACE: OnceLock<Mesh> = OnceLock::new();
    FACE.get_or_init(|| {
        let ct = facesim::volume::read_volume(&common::real_mandible_ct()).unwrap();
        let dir = common::kept_dir("facesim-face-scan");
        let out = dir.join("iso.obj");
        // −500 HU; headsq's voxels are HU + 1024 as vtk.js ships them.
        let lowest = ct.data.iter().copied().fold(f32::INFINITY, f32::min);
        let level = if lowest >= -1.0 { 524.0 } else { -500.0 };
        common::isosurface(&ct, level, &out);
        let iso = facesim::mesh::model_file::read_model(&out).unwrap();
        let (lo, hi) = iso.bounds();
        let axis = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        facesim::surface::outer::outer_face(&iso, axis, &out)
            .unwrap()
            .0
    })
}

/// A rotation about a unit axis by `deg`.
fn rotation(axis: [f64; 3], deg: f64) -> [[f64; 3]; 3] {
    let (s, c) = deg.to_radians().sin_cos();
    let [x, y, z] = axis;
    [
        [
            c + x * x * (1.0 - c),
            x * y * (1.0 - c) - z * s,
            x * z * (1.0 - c) + y * s,
        ],
        [
            y * x * (1.0 - c) + z * s,
            c + y * y * (1.0 - c),
            y * z * (1.0 - c) - x * s,
        ],
        [
            z * x * (1.0 - c) - y * s,
            z * y * (1.0 - c) + x * s,
            c + z * z * (1.0 - c),
        ],
    ]
}

fn apply(r: &[[f64; 3]; 3], k: f64, p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| k * (r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2]))
}

fn moved(m: &Mesh, r: &[[f64; 3]; 3], k: f64) -> Mesh {
    Mesh::new(
        m.vertices.iter().map(|p| apply(r, k, *p)).collect(),
        m.triangles.clone(),
    )
}

fn position(f: &FaceLandmarks, label: &str) -> Option<[f64; 3]> {
    f.landmarks
        .iter()
        .find(|l| l.label == label)
        .and_then(|l| l.position)
}

#[test]
fn a_real_face_by_another_program_has_its_landmarks_in_face_order() {
    let face = headsq_face();
    let f = landmarks_of(face, FrameFrom::Shape).unwrap();
    assert_eq!(f.unit.name, "mm");
    let height = |l: &str| {
        let p = position(&f, l).unwrap_or_else(|| panic!("{l} missing: {:?}", f.landmarks));
        facesim::vec3::dot(p, f.frame.vertical)
    };
    // The nose and lips, top to bottom, spaced as a face's (the search's own rules are wider).
    let order = ["Prn", "Sn", "Ls", "Sto", "Li"];
    for w in order.windows(2) {
        let drop = height(w[0]) - height(w[1]);
        assert!(
            (1.0..30.0).contains(&drop),
            "{} above {} by {drop:.1} mm",
            w[0],
            w[1]
        );
    }
    // The frame's front is the face's: pronasale in front of subnasale and the lips.
    let front = |l: &str| facesim::vec3::dot(position(&f, l).unwrap(), f.frame.anterior);
    for (l, by) in [("Sn", 5.0), ("Ls", 2.0), ("Li", 2.0)] {
        let d = front("Prn") - front(l);
        assert!(d > by, "Prn only {d:.1} mm in front of {l}");
    }
    assert!(
        f.measurements
            .0
            .iter()
            .any(|(k, m)| k == "nasolabial_angle" && m.before.is_some())
    );
}

#[test]
fn a_scan_in_another_frame_or_in_metres_gives_the_same_landmarks_moved_with_it() {
    let face = headsq_face();
    let base = landmarks_of(face, FrameFrom::Shape).unwrap();
    // A scanner's y-up, z-forward frame (LPS turned about x); a 30° yaw; the y-up frame in
    // metres; an oblique turn (37° about (1, 2, 3)/√14 then 20° about y). Measured: at most
    // 0.21, 0.33, 0.21 and 0.18 mm.
    let n = 14f64.sqrt();
    let oblique = {
        let a = rotation([1.0 / n, 2.0 / n, 3.0 / n], 37.0);
        let b = rotation([0.0, 1.0, 0.0], 20.0);
        [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| b[i][k] * a[k][j]).sum::<f64>()))
    };
    let cases = [
        (rotation([1.0, 0.0, 0.0], -90.0), 1.0, "mm", 1.0),
        (rotation([0.0, 0.0, 1.0], 30.0), 1.0, "mm", 1.0),
        (rotation([1.0, 0.0, 0.0], -90.0), 0.001, "m", 1.0),
        (oblique, 1.0, "mm", 1.0),
    ];
    for (r, k, unit, tol) in cases {
        let f = landmarks_of(&moved(face, &r, k), FrameFrom::Shape).unwrap();
        assert_eq!(f.unit.name, unit);
        let mut worst = 0.0f64;
        for label in ["Prn", "Sn", "Ls", "Sto", "Li"] {
            let want = apply(&r, k, position(&base, label).unwrap());
            let got = position(&f, label).unwrap_or_else(|| panic!("{label} missing ({unit})"));
            let d = facesim::vec3::norm(facesim::vec3::sub(got, want)) / k;
            assert!(
                d < tol,
                "{label}: {d:.2} mm off the moved landmark ({unit})"
            );
            worst = worst.max(d);
        }
        eprintln!("{unit}, {r:.2?}: at most {worst:.2} mm off");
    }
}

/// `facesim landmarks` (the command's body): a face in metres written as PLY gives
/// landmarks.mrk.json in the file's own metres (read back equal to the landmarks found) and
/// measurements.json stating the unit; a sphere gets one line naming the file, and no output.
#[test]
fn the_command_writes_markups_in_the_files_units_and_refuses_a_sphere() {
    let dir = common::kept_dir("facesim-landmarks-cmd");
    let face = moved(headsq_face(), &rotation([1.0, 0.0, 0.0], -90.0), 0.001);
    let mesh = dir.join("photo.ply");
    facesim::mesh::write_mesh(&face, &mesh).unwrap();
    let out = dir.join("lm");
    let (written, found) =
        facesim::commands::landmarks::landmarks(&mesh, &out, FrameFrom::Shape).unwrap();
    assert_eq!(written, out);
    let back = facesim::landmarks::markups::read(&out.join("landmarks.mrk.json")).unwrap();
    let want = facesim::landmarks::positions(&found.landmarks);
    assert_eq!(back.len(), want.len());
    for ((l1, p1), (l2, p2)) in back.iter().zip(&want) {
        assert_eq!(l1, l2);
        assert!(facesim::vec3::norm(facesim::vec3::sub(*p1, *p2)) < 1e-9);
        // Metres: a face's landmarks lie within 0.3 of each other, not 300.
        assert!(facesim::vec3::norm(facesim::vec3::sub(*p1, want[0].1)) < 0.3);
    }
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("measurements.json")).unwrap())
            .unwrap();
    assert_eq!(m["unit"]["name"], "m");
    assert_eq!(m["unit"]["mm_per_unit"], 1000.0);

    // A sphere: not a face, nothing written.
    let mut v = Vec::new();
    let mut t = Vec::new();
    let (nu, nv) = (24u32, 12u32);
    for j in 0..=nv {
        // A sphere without its pole caps (no degenerate triangles there).
        let th = 0.2 + (std::f64::consts::PI - 0.4) * j as f64 / nv as f64;
        for i in 0..nu {
            let ph = 2.0 * std::f64::consts::PI * i as f64 / nu as f64;
            v.push([
                90.0 * th.sin() * ph.cos(),
                90.0 * th.sin() * ph.sin(),
                90.0 * th.cos(),
            ]);
        }
    }
    for j in 0..nv {
        for i in 0..nu {
            let (a, b) = (j * nu + i, j * nu + (i + 1) % nu);
            t.push([a, a + nu, b]);
            t.push([b, a + nu, b + nu]);
        }
    }
    let ball = dir.join("ball.obj");
    facesim::mesh::write_mesh(&Mesh::new(v, t), &ball).unwrap();
    let none = dir.join("ball_out");
    let e = facesim::commands::landmarks::landmarks(&ball, &none, FrameFrom::Shape)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with(&ball.display().to_string()), "{e}");
    assert!(e.contains("not a face"), "{e}");
    assert!(!e.contains('\n'), "{e}");
    assert!(!none.exists());
}

/// `compare --landmarks`: B is A after a known "operation" — the skin below
/// subnasale moved 4 mm forward, fading out over the 10 mm above it — then turned into a
/// scanner's frame and written in metres. Registered on the skin surgery leaves, the forehead
/// and nose come back where they were (the known motion recovered, the nose tip < 1 mm), the lips
/// ≈ 4 mm, and the lips' region is the one that moved.
#[test]
fn two_faces_of_one_person_are_registered_on_what_surgery_leaves_and_measured_per_landmark() {
    let a = headsq_face();
    let fa = landmarks_of(a, FrameFrom::Shape).unwrap();
    let (up, fwd) = (fa.frame.vertical, fa.frame.anterior);
    let sn = facesim::vec3::dot(position(&fa, "Sn").unwrap(), up);
    let post: Vec<[f64; 3]> = a
        .vertices
        .iter()
        .map(|p| {
            let h = facesim::vec3::dot(*p, up);
            let w = ((sn + 10.0 - h) / 10.0).clamp(0.0, 1.0);
            facesim::vec3::add(*p, facesim::vec3::scale(fwd, 4.0 * w))
        })
        .collect();
    let r = rotation([1.0, 0.0, 0.0], -90.0);
    let b = moved(&Mesh::new(post, a.triangles.clone()), &r, 0.001);
    let o = facesim::landmarks::outcome::compare_faces(
        a,
        std::path::Path::new("pre.ply"),
        &b,
        std::path::Path::new("post.ply"),
    )
    .unwrap();
    assert_eq!(o.b.unit.name, "m");
    // The recovered motion is the scanner turn (A in mm onto B in mm).
    for (i, row) in o.registration.motion.rotation.iter().enumerate() {
        for (j, x) in row.iter().enumerate() {
            assert!(
                (x - r[i][j]).abs() < 0.01,
                "rotation {i},{j}: {x} vs {}",
                r[i][j]
            );
        }
    }
    assert!(o.registration.rms_mm < 0.2, "{:?}", o.registration);
    let d = |l: &str| {
        o.landmarks
            .0
            .iter()
            .find(|(k, _)| k == l)
            .and_then(|(_, x)| x.distance_mm)
            .unwrap_or_else(|| panic!("{l}: {:?}", o.landmarks.0))
    };
    // The tip itself stays (w = 0 there); its detected point shifts a little as the columella
    // below it moves.
    assert!(d("Prn") < 1.0, "Prn {:.2}", d("Prn"));
    for l in ["Ls", "Sto", "Li"] {
        assert!((3.0..5.0).contains(&d(l)), "{l} {:.2}", d(l));
    }
    let region = |name: &str| {
        o.regions
            .0
            .iter()
            .find(|(k, _)| k == name)
            .and_then(|(_, r)| r.stats.clone())
            .unwrap_or_else(|| panic!("{name}: {:?}", o.regions.0))
    };
    // A's upper lip lies up to 4 mm behind B's surface; the nose is where it was. (This skin
    // has no soft B point, so no lower-lip region.)
    assert!(region("nose").mean < 0.5, "{:?}", region("nose"));
    assert!(region("upper lip").mean > 1.5, "{:?}", region("upper lip"));
}

/// A real scanner's face (menpo3d's "james", a textured face scan in its own frame, in mm) with
/// 68 landmarks placed by people (iBUG layout, james.ljson): facesim's landmarks, found with
/// the frame and unit from the mesh alone, lie where the people put theirs. The pairs are the
/// same anatomical points (nose tip, subnasale, the upper lip's vermilion top, the lower lip's
/// bottom, the lips' meeting point); the bound allows for where a person clicks on a 1–2 mm
/// facet and for the definitions' differences (docs/guide/landmarks.md gives the distances).
#[test]
fn a_real_scanners_face_has_its_landmarks_where_people_put_them() {
    let dir = common::face_scan();
    let mesh = facesim::mesh::read_mesh(&dir.join("james.obj")).unwrap();
    let lj: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("james.ljson")).unwrap()).unwrap();
    let group = &lj["groups"]["LJSON"];
    let points: Vec<[f64; 3]> = group["landmarks"]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| [0, 1, 2].map(|k| p[k].as_f64().unwrap()))
        .collect();
    // The groups' own point lists: the nose's 9 (bridge top to tip, then the lower border from
    // the right ala through subnasale to the left), the mouth's 20 (outer lip from the right
    // corner, then the inner lip).
    let mask = |label: &str| -> Vec<usize> {
        group["labels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["label"] == label)
            .unwrap()["mask"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| i.as_u64().unwrap() as usize)
            .collect()
    };
    let (nose, mouth) = (mask("nose"), mask("mouth"));
    assert_eq!((nose.len(), mouth.len()), (9, 20));
    let mean = |idx: &[usize]| {
        let k = idx.len() as f64;
        [0, 1, 2].map(|c| idx.iter().map(|i| points[*i][c]).sum::<f64>() / k)
    };
    let people = [
        ("Prn", mean(&[nose[3]]), 2.0),
        ("Sn", mean(&[nose[6]]), 4.0),
        ("Ls", mean(&[mouth[3]]), 4.0),
        ("Sto", mean(&[mouth[14], mouth[18]]), 3.0),
        ("Li", mean(&[mouth[9]]), 4.0),
    ];
    let f = landmarks_of(&mesh, FrameFrom::Shape).unwrap();
    assert_eq!(f.unit.name, "mm");
    for (label, want, tol) in people {
        let got =
            position(&f, label).unwrap_or_else(|| panic!("{label} missing: {:?}", f.landmarks));
        let d = facesim::vec3::norm(facesim::vec3::sub(got, want));
        eprintln!("james {label}: {d:.2} mm from the people's");
        assert!(
            d < tol,
            "{label} {got:?}: {d:.2} mm from the people's {want:?}"
        );
    }
    // The mouth's corners: the people's outer-lip corners.
    for (label, want) in [("Ch-R", mean(&[mouth[0]])), ("Ch-L", mean(&[mouth[6]]))] {
        let got =
            position(&f, label).unwrap_or_else(|| panic!("{label} missing: {:?}", f.landmarks));
        let d = facesim::vec3::norm(facesim::vec3::sub(got, want));
        eprintln!("james {label}: {d:.2} mm from the people's");
        assert!(
            d < 4.0,
            "{label} {got:?}: {d:.2} mm from the people's {want:?}"
        );
    }
    // Alare: the people's iBUG points are the nostrils' outer ends at the base, not alare (the
    // most lateral points of the alae, above and outside them): each alare lies outside its
    // nostril point by 0–8 mm, the two mirror each other about the midsagittal plane within
    // 3 mm, and the alar width is an adult's (31–42 mm; Farkas 1994: 35 ± 3 in men).
    let lateral =
        |p: [f64; 3]| facesim::vec3::dot(facesim::vec3::sub(p, f.frame.origin), f.frame.lateral);
    let (al_r, al_l) = (position(&f, "Al-R").unwrap(), position(&f, "Al-L").unwrap());
    let (nr, nl) = (lateral(mean(&[nose[4]])), lateral(mean(&[nose[8]])));
    let (sr, sl) = (lateral(al_r), lateral(al_l));
    eprintln!(
        "james alare at {sr:.1} / {sl:.1} mm, nostril ends at {nr:.1} / {nl:.1} mm from the midline"
    );
    assert!((0.0..8.0).contains(&(nr - sr)) && (0.0..8.0).contains(&(sl - nl)));
    assert!((sr + sl).abs() < 3.0);
    let width = facesim::vec3::norm(facesim::vec3::sub(al_r, al_l));
    assert!((31.0..42.0).contains(&width), "alar width {width:.1} mm");
    // The same scan turned obliquely and in metres: the same landmarks, turned and scaled.
    let r = rotation([0.6, 0.0, 0.8], 50.0);
    let turned = landmarks_of(&moved(&mesh, &r, 0.001), FrameFrom::Shape).unwrap();
    assert_eq!(turned.unit.name, "m");
    let labels = people
        .iter()
        .map(|p| p.0)
        .chain(["Ch-R", "Ch-L", "Al-R", "Al-L"]);
    for label in labels {
        let want = apply(&r, 0.001, position(&f, label).unwrap());
        let got = position(&turned, label).unwrap_or_else(|| panic!("{label} missing (turned)"));
        let d = facesim::vec3::norm(facesim::vec3::sub(got, want)) / 0.001;
        eprintln!("james turned, in metres, {label}: {d:.2} mm off");
        // Alare is the most lateral of the sharpest turns of sections 0.5 mm apart in height: a
        // turned mesh's facets cross them elsewhere, and the widest section may be another
        // (measured 0.9 and 2.0 mm).
        let tol = if label.starts_with("Al") { 2.5 } else { 0.5 };
        assert!(d < tol, "{label}: {d:.2} mm off the turned landmark");
    }
}

/// The real CT's (data-samples/real) whole iso-surface at −500 HU by scikit-image, cut to its
/// outer face as a range scan sees it, handed over as a scanner would: turned into a y-up,
/// z-forward frame and in metres. The face ends at the upper lip, its nose droops (the columella
/// lies ahead of the dorsum 10 mm from the tip), and read upside down it still looks like a
/// face. The nose and upper lip must come back the right way up, and move with the mesh.
#[test]
fn the_real_cts_face_by_another_program_is_read_the_right_way_up_in_any_frame() {
    let ct = facesim::volume::read_volume(&common::real_ct()).unwrap();
    let dir = common::kept_dir("facesim-face-scan-real");
    let out = dir.join("iso.obj");
    common::isosurface(&ct, -500.0, &out);
    let iso = facesim::mesh::model_file::read_model(&out).unwrap();
    let (lo, hi) = iso.bounds();
    let axis = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    let face = facesim::surface::outer::outer_face(&iso, axis, &out)
        .unwrap()
        .0;
    let base = landmarks_of(&face, FrameFrom::Shape).unwrap();
    // Right way up in the CT's own axes (LPS: z up, −y the face's front): the nose tip in front,
    // subnasale and labrale superius below it and behind it, the soft nasion above it.
    let c = |f: &FaceLandmarks, l: &str| {
        position(f, l).unwrap_or_else(|| panic!("{l} missing: {:?}", f.landmarks))
    };
    let (prn, sn, ls, n) = (
        c(&base, "Prn"),
        c(&base, "Sn"),
        c(&base, "Ls"),
        c(&base, "N'"),
    );
    eprintln!("real CT face: Prn {prn:?} Sn {sn:?} Ls {ls:?} N' {n:?}");
    assert!(sn[2] < prn[2] - 8.0 && sn[1] > prn[1] + 6.0, "Sn {sn:?}");
    assert!(ls[2] < sn[2] - 5.0, "Ls {ls:?}");
    assert!(n[2] > prn[2] + 15.0 && n[1] > prn[1] + 8.0, "N' {n:?}");
    // A scanner's y-up frame, and the same in metres: the same landmarks, moved.
    let r = rotation([1.0, 0.0, 0.0], -90.0);
    for k in [1.0, 0.001] {
        let f = landmarks_of(&moved(&face, &r, k), FrameFrom::Shape).unwrap();
        for label in ["N'", "Prn", "Sn", "Ls"] {
            let want = apply(&r, k, c(&base, label));
            let d = facesim::vec3::norm(facesim::vec3::sub(c(&f, label), want)) / k;
            eprintln!("real CT face, y-up ×{k}: {label} {d:.2} mm off the moved landmark");
            assert!(d < 1.0, "{label}: {d:.2} mm off the moved landmark (×{k})");
        }
    }
}

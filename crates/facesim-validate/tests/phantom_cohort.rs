//! Shaped jaws phantoms keep their geometry known (docs/design/phantom.md, "Cohort parameters"): the
//! landmarks move by what the parameters say (exact arithmetic on the standard head's
//! numbers, the vertical pattern stretching the heights below the maxilla's top), the CT shows the bone and skin edges and the soft-tissue thickness where the
//! analytic surfaces are, the face scan follows the skin, and the plans' boxes still select
//! exactly their segment at the extremes of the accepted ranges.

use facesim::volume::Volume;
use facesim_validate::phantom::PhantomOptions;
use facesim_validate::phantom_jaws::{self as pj, Piece, Shape};
use rayon::prelude::*;

fn shape(v: [f64; 6]) -> Shape {
    Shape::from_values(v)
}

/// Three patients besides the standard one: thicker, prognathic and long-faced, large with a
/// strong chin, a midline shift and a short face, small and thin with a retruded mandible and
/// a long face.
fn patients() -> Vec<Shape> {
    vec![
        shape([1.0, 3.0, 2.0, 0.0, 0.0, 4.0]),
        shape([1.08, 0.0, 0.0, 2.5, 1.5, -5.0]),
        shape([0.92, -2.0, -3.0, -1.0, -2.0, 7.0]),
    ]
}

/// A standard-frame height z in the world of a head with scale k and vertical pattern v: below
/// the maxilla's top (z = 1.5) stretched so that ANS–menton (67.5 mm) grows by v, then scaled.
fn wz(z: f64, k: f64, v: f64) -> f64 {
    let z0 = pj::Z_MAXILLA_TOP;
    let z = if z < z0 && v != 0.0 {
        z0 + (z - z0) * (1.0 + v / 67.5)
    } else {
        z
    };
    z * k
}

fn lm(s: &Shape, name: &str) -> [f64; 3] {
    s.landmark(name).unwrap()
}

fn close(a: [f64; 3], b: [f64; 3], tol: f64, what: &str) {
    let d = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max);
    assert!(d <= tol, "{what}: {a:?} vs {b:?} ({d:.4} mm)");
}

#[test]
fn landmarks_move_as_the_parameters_say() {
    for s in patients() {
        let [k, soft, d, c, a, v] = s.values();
        // Bony landmarks: the maxilla's only scale (and stretch); the mandible's move by
        // (a, −d) and the chin's projection by c (pogonion, 4 mm proud in the standard head, is
        // at −73.5).
        close(
            lm(&s, "A point"),
            [0.0, -70.5 * k, wz(-4.0, k, v)],
            1e-9,
            "A point",
        );
        let ui = pj::landmark("upper incisor tip").unwrap();
        close(
            lm(&s, "upper incisor tip"),
            [ui[0] * k, ui[1] * k, wz(ui[2], k, v)],
            1e-9,
            "upper incisor",
        );
        let li = pj::landmark("lower incisor tip").unwrap();
        let li_s = [(li[0] + a) * k, (li[1] - d) * k, wz(li[2], k, v)];
        close(lm(&s, "lower incisor tip"), li_s, 1e-9, "lower incisor");
        let pog = [a * k, (-73.5 - d - c) * k, wz(-55.0, k, v)];
        close(lm(&s, "pogonion"), pog, 1e-3, "pogonion");
        close(
            lm(&s, "menton"),
            [a * k, (-64.5 - d) * k, wz(-66.0, k, v)],
            1e-9,
            "menton",
        );
        // ANS (the maxilla's top, z = 1.5) to menton: 67.5 mm + v, scaled.
        let me_z = lm(&s, "menton")[2];
        assert!(
            (1.5 * k - me_z - (67.5 + v) * k).abs() < 1e-9,
            "{s:?}: ANS–Me {}",
            1.5 * k - me_z
        );
        let cl = [(48.0 + a) * k, (7.0 - d) * k, wz(-3.0, k, v)];
        close(lm(&s, "condyle left"), cl, 1e-9, "condyle left");
        // Soft tissue above the lip line: only the thickness change and the scale.
        let prn = [0.0, (-103.5 - soft) * k, 13.0 * k];
        close(lm(&s, "pronasale"), prn, 1e-3, "pronasale");
        // Soft menton: below bony menton, as far below as in the standard head when only the
        // mandible moves (the skin under the chin moves with it).
        let me = lm(&s, "soft tissue menton");
        close(
            [me[0], me[1], 0.0],
            [pog[0], (-64.5 - d) * k, 0.0],
            1e-9,
            "soft menton",
        );
    }
    // Prognathism alone moves the soft chin and lower lip forward by the same amount.
    let s = shape([1.0, 0.0, 2.0, 0.0, 0.0, 0.0]);
    for name in [
        "soft tissue pogonion",
        "labrale inferius",
        "soft tissue menton",
    ] {
        let p = pj::landmark(name).unwrap();
        close(lm(&s, name), [p[0], p[1] - 2.0, p[2]], 2e-3, name);
    }
}

/// The CT of a thin slab along y through (x, z) (world mm), 0.5 mm voxels, no noise; the
/// line runs through voxel centres.
fn line_ct(s: &Shape, x: f64, z: f64, y: [f64; 2]) -> Volume {
    let h = 0.5;
    let opts = PhantomOptions {
        spacing: [h; 3],
        noise_hu: 0.0,
        ..Default::default()
    };
    s.ct_box(&opts, [x - h, y[0], z - h], [x + h, y[1], z + h])
}

/// Where the HU along the CT's middle line first rises through `level` after `from` (mm),
/// by linear interpolation between voxel centres.
fn edge(v: &Volume, level: f64, from: f64) -> f64 {
    let [nx, ny, _] = v.dims;
    let at = |j: usize| v.data[1 + nx * (j + ny)] as f64;
    let y = |j: usize| v.origin[1] + j as f64 * v.spacing[1];
    for j in 1..ny {
        if y(j - 1) >= from && at(j - 1) < level && at(j) >= level {
            let t = (level - at(j - 1)) / (at(j) - at(j - 1));
            return y(j - 1) + t * v.spacing[1];
        }
    }
    panic!("no edge at {level} HU after y = {from}");
}

/// The skin's crossing of the line (x, ·, z) in front of the face, by bisection on the
/// analytic skin radius (not the CT sampler's tissue function).
fn skin_crossing(s: &Shape, x: f64, z: f64) -> f64 {
    let inside = |y: f64| (x * x + y * y).sqrt() < s.skin_radius(x.atan2(-y), z);
    let (mut lo, mut hi) = (-140.0, -40.0);
    for _ in 0..80 {
        let m = 0.5 * (lo + hi);
        if inside(m) {
            hi = m;
        } else {
            lo = m;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn ct_shows_the_chin_and_nose_where_the_shape_puts_them() {
    let air_skin = 0.5 * (-1000.0 + 45.0);
    let soft_bone = 0.5 * (45.0 + 600.0);
    let chin = |s: &Shape| {
        let pog = lm(s, "pogonion");
        let v = line_ct(s, pog[0], pog[2], [-130.0, -40.0]);
        let skin = edge(&v, air_skin, -140.0);
        let bone = edge(&v, soft_bone, skin);
        // The skin edge where the analytic skin is, the bone edge at pogonion.
        assert!(
            (skin - skin_crossing(s, pog[0], pog[2])).abs() < 0.25,
            "{s:?}"
        );
        assert!(
            (bone - pog[1]).abs() < 0.25,
            "{s:?}: bone {bone} vs {}",
            pog[1]
        );
        bone - skin
    };
    let standard = chin(&Shape::default());
    println!("chin soft tissue at pogonion, standard head: {standard:.2} mm");
    // Thickening by 3 mm with a 2 mm advancement: the chin's soft tissue is 3 mm thicker.
    let t = chin(&shape([1.0, 3.0, 2.0, 0.0, 0.0, 0.0]));
    assert!((t - standard - 3.0).abs() < 0.3, "{t} vs {standard} + 3");
    // Scaling the head by 1.08 scales the thickness.
    let t = chin(&shape([1.08, 0.0, 0.0, 0.0, 0.0, 0.0]));
    assert!(
        (t - 1.08 * standard).abs() < 0.3,
        "{t} vs 1.08 × {standard}"
    );
    for s in patients() {
        chin(&s);
        // The nose tip: the skin edge on the midline at pronasale's height.
        let prn = lm(&s, "pronasale");
        let v = line_ct(&s, 0.0, prn[2], [-140.0, -60.0]);
        let skin = edge(&v, air_skin, -150.0);
        assert!(
            (skin - prn[1]).abs() < 0.25,
            "{s:?}: nose {skin} vs {}",
            prn[1]
        );
    }
}

#[test]
fn face_scan_follows_the_shaped_skin() {
    for s in patients() {
        let scan = s.face_scan(1.0);
        let nearest = |p: [f64; 3]| {
            scan.vertices
                .iter()
                .map(|v| (0..3).map(|k| (v[k] - p[k]).powi(2)).sum::<f64>().sqrt())
                .fold(f64::INFINITY, f64::min)
        };
        // No skin point is in front of pronasale; the scan's front vertex is next to it: at most
        // half a 1 mm grid step from the tip in height, where the nose's profile (curvature
        // 23.5 / 5² below the tip) falls back by ½ · 0.94 · 0.5² = 0.12 mm.
        let prn = lm(&s, "pronasale");
        let front = scan
            .vertices
            .iter()
            .map(|v| v[1])
            .fold(f64::INFINITY, f64::min);
        assert!(
            front >= prn[1] - 1e-6 && front - prn[1] < 0.12,
            "{front} {prn:?}"
        );
        // The soft chin of this patient is on its scan (within half a grid step) and not on
        // the standard head's.
        let pg = lm(&s, "soft tissue pogonion");
        assert!(nearest(pg) < 0.75, "{s:?}: {}", nearest(pg));
        let standard = pj::face_scan(1.0);
        let off = standard
            .vertices
            .iter()
            .map(|v| (0..3).map(|k| (v[k] - pg[k]).powi(2)).sum::<f64>().sqrt())
            .fold(f64::INFINITY, f64::min);
        assert!(
            off > 1.5,
            "{s:?}: the standard scan is {off} mm from this chin"
        );
    }
}

#[test]
fn plan_boxes_select_their_segment_at_the_range_extremes() {
    let extremes = [
        shape([0.8, -3.0, 4.0, 4.0, 4.0, -8.0]),
        shape([1.2, 5.0, -4.0, -3.0, -4.0, 10.0]),
        shape([1.0, 0.0, 4.0, -3.0, -4.0, -8.0]),
    ];
    for s in extremes {
        s.validate().unwrap();
        let [front, back, maxilla] = s.boxes();
        let inside =
            |b: &[[f64; 3]; 2], p: [f64; 3]| (0..3).all(|k| p[k] >= b[0][k] && p[k] <= b[1][k]);
        let [lo, hi] = s.fov();
        let h = s.scale;
        let n = [0, 1, 2].map(|k| ((hi[k] - lo[k]) / h) as usize);
        // (mandible points, maxilla points, misplaced points)
        let counts = (0..n[2])
            .into_par_iter()
            .map(|kz| {
                let mut c = [0usize; 3];
                let z = lo[2] + (kz as f64 + 0.5) * h;
                for j in 0..n[1] {
                    for i in 0..n[0] {
                        let p = [
                            lo[0] + (i as f64 + 0.5) * h,
                            lo[1] + (j as f64 + 0.5) * h,
                            z,
                        ];
                        let mandible_box = inside(&front, p) || inside(&back, p);
                        match s.piece_at(p) {
                            Some(Piece::Mandible) => {
                                c[0] += 1;
                                c[2] += usize::from(!mandible_box || inside(&maxilla, p));
                            }
                            Some(Piece::Maxilla) => {
                                c[1] += 1;
                                c[2] += usize::from(mandible_box || !inside(&maxilla, p));
                            }
                            Some(Piece::Cranium) => {
                                c[2] += usize::from(mandible_box || inside(&maxilla, p));
                            }
                            None => {}
                        }
                    }
                }
                c
            })
            .reduce(|| [0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
        assert!(counts[0] > 10_000 && counts[1] > 3_000, "{s:?}: {counts:?}");
        assert_eq!(counts[2], 0, "{s:?}: bone in the wrong box");
    }
}

#[test]
fn out_of_range_shapes_are_refused_naming_the_parameter() {
    let e = shape([1.0, 9.0, 0.0, 0.0, 0.0, 0.0])
        .validate()
        .unwrap_err();
    assert!(e.to_string().contains("soft_mm"), "{e}");
    let e = shape([1.0, 0.0, 0.0, 0.0, 0.0, 11.0])
        .validate()
        .unwrap_err();
    assert!(e.to_string().contains("vertical_mm"), "{e}");
    let e = shape([f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0])
        .validate()
        .unwrap_err();
    assert!(e.to_string().contains("scale"), "{e}");
}

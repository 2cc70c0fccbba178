//! The second real sample (data-samples/real-mandible: VTK's headsq, with the mandible) through
//! the real `facesim run`: a 5 mm BSSO advancement must run with the defaults, invert nothing,
//! and carry the chin and lower lip forward.

use crate::cli;
use crate::common;

use cli::facesim;
use serde_json::Value;
use std::path::Path;

/// `facesim run data-samples/real-mandible --out <fresh>` (must exit 0) and its report.json.
fn run() -> Value {
    run_in().0
}

/// The same, with the output folder.
fn run_in() -> (Value, std::path::PathBuf) {
    common::real_mandible_ct();
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/real-mandible");
    let out = common::out_dir("facesim-real-mandible");
    let r = facesim(&[
        "run",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 0, "facesim run failed: {}", r.stderr);
    let r = serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap());
    (r.unwrap(), out)
}

fn landmark(report: &Value, label: &str) -> Option<([f64; 3], [f64; 3])> {
    let l = &report["landmarks"][label];
    let p = |v: &Value| -> Option<[f64; 3]> {
        let a = v.as_array()?;
        Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?])
    };
    Some((p(&l["pre"])?, p(&l["post"])?))
}

#[test]
fn bsso_advance_runs_and_moves_the_lower_lip() {
    let r = run();
    assert_eq!(r["tet"]["inverted_elements"], 0);
    // The lips are found on the face; the upper lip stays, the lower lip follows the mandible
    // forward (−y) by a good part of the 5 mm.
    for l in ["Prn", "Sn", "Ls", "Sto", "Li"] {
        assert!(landmark(&r, l).is_some(), "{l}: {}", r["landmarks"][l]);
    }
    let (ls0, ls1) = landmark(&r, "Ls").unwrap();
    let (li0, li1) = landmark(&r, "Li").unwrap();
    assert!((ls1[1] - ls0[1]).abs() < 1.0, "Ls moved {:?}", ls1);
    let li_forward = li0[1] - li1[1];
    assert!((2.5..=6.0).contains(&li_forward), "Li forward {li_forward}");
    // Stomion between the lips.
    let (sto, _) = landmark(&r, "Sto").unwrap();
    assert!(ls0[2] > sto[2] && sto[2] > li0[2]);
}

/// The nose tip on a head pitched face-down (docs/guide/landmarks.md, Prn): headsq's dorsum runs
/// within 2.3 mm of the CT's vertical for 60 mm, so its most anterior skin point lies on the
/// dorsum, 30 mm above the tip. Pronasale must be the most protruded point of the nose: checked
/// here on the run's face_pre.ply itself, as the midsagittal skin vertex (within 2 mm of the
/// plane) between subnasale and soft nasion farthest in front of the line N'–Sn, and by the
/// nose's proportions (adult sn–prn 20 ± 2 mm, Farkas 1994; this 3.2 mm CT's nose is coarse).
/// Its alae, which horizontal sections do not find on this nose, are reported missing.
#[test]
fn the_nose_tip_of_a_head_pitched_face_down_is_its_tip() {
    let (r, out) = run_in();
    let at = |l: &str| {
        landmark(&r, l)
            .unwrap_or_else(|| panic!("{l}: {}", r["landmarks"][l]))
            .0
    };
    let (prn, sn, n) = (at("Prn"), at("Sn"), at("N'"));
    let axis = |k: &str| -> [f64; 3] {
        let a = r["head_frame"][k].as_array().unwrap();
        [0, 1, 2].map(|i| a[i].as_f64().unwrap())
    };
    let (origin, lateral, up, ant) = (
        axis("origin"),
        axis("lateral"),
        axis("vertical"),
        axis("anterior"),
    );
    let dot = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| a[k] * b[k]).sum::<f64>();
    let rel = |p: [f64; 3]| [0, 1, 2].map(|k| p[k] - origin[k]);
    // (height, depth forward) in the midsagittal plane.
    let plane = |p: [f64; 3]| (dot(rel(p), up), dot(rel(p), ant));
    let ((hn, an), (hs, as_)) = (plane(n), plane(sn));
    let front = |p: [f64; 3]| {
        let (h, a) = plane(p);
        let (dh, da) = (hs - hn, as_ - an);
        (da * (h - hn) - dh * (a - an)) / (dh * dh + da * da).sqrt()
    };
    let face = facesim::mesh::ply::read(&out.join("face_pre.ply")).unwrap();
    let tip = face
        .vertices
        .iter()
        .filter(|v| dot(rel(**v), lateral).abs() < 2.0)
        .filter(|v| (hs..hn).contains(&plane(**v).0))
        .max_by(|a, b| front(**a).total_cmp(&front(**b)))
        .copied()
        .unwrap();
    let d = (0..3)
        .map(|k| (tip[k] - prn[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    println!("Prn {prn:?}, the profile's most protruded vertex {tip:?}: {d:.2} mm");
    assert!(
        d < 3.2,
        "Prn {prn:?} is {d:.2} mm from the nose's most protruded point {tip:?}"
    );
    let sn_prn = (0..3).map(|k| (sn[k] - prn[k]).powi(2)).sum::<f64>().sqrt();
    assert!((10.0..=30.0).contains(&sn_prn), "Sn–Prn {sn_prn:.1} mm");
    assert!(
        front(prn) > 8.0,
        "Prn {:.1} mm in front of N'–Sn",
        front(prn)
    );
    // The alae of this coarse, pitched nose: the grooves its horizontal sections find are not a
    // nose's width apart (docs/guide/landmarks.md, Al), so both are missing, saying why, not placed.
    for side in ["Al-R", "Al-L"] {
        let why = r["landmarks"][side]["missing"].as_str().unwrap_or_default();
        assert!(
            landmark(&r, side).is_none() && why.contains("apart"),
            "{side}: {}",
            r["landmarks"][side]
        );
    }
}

/// The chin landmarks found where they belong (docs/guide/landmarks.md "The chin": chord definitions
/// that hold on this head, which lies some 25° face-down), and the soft/hard ratio at the chin
/// within a broad physical range. Soft menton is not in this scan: the CT's last slice is 4.5 mm
/// under bony menton, and the soft tissue under the chin runs on past it (docs/guide/real-ct.md); it
/// must be reported missing with that reason, never placed at the scan's edge.
#[test]
fn chin_landmarks_and_ratios() {
    let (r, out) = run_in();
    for l in ["Pog", "B", "Me", "Pog'", "B'", "Li", "Sto"] {
        assert!(landmark(&r, l).is_some(), "{l}: {}", r["landmarks"][l]);
    }
    let (li, _) = landmark(&r, "Li").unwrap();
    let (b_s, _) = landmark(&r, "B'").unwrap();
    let (pog, _) = landmark(&r, "Pog").unwrap();
    let (pog_s, _) = landmark(&r, "Pog'").unwrap();
    let (me, _) = landmark(&r, "Me").unwrap();
    let (b, _) = landmark(&r, "B").unwrap();
    // In order down the chin: Li, B', Pog' on the skin; B, Pog, Me on the bone.
    assert!(
        li[2] > b_s[2] && b_s[2] > pog_s[2],
        "Li {li:?} B' {b_s:?} Pog' {pog_s:?}"
    );
    assert!(b[2] > pog[2], "B {b:?} Pog {pog:?}");
    // Soft pogonion in front of bony pogonion (−y) by a soft-tissue thickness, at about its
    // height.
    let t = pog[1] - pog_s[1];
    assert!((5.0..=20.0).contains(&t), "chin soft tissue {t} mm");
    assert!(
        (pog[2] - pog_s[2]).abs() < 10.0,
        "Pog {pog:?} Pog' {pog_s:?}"
    );
    // Menton lowest of the chin; the CT's last slice (z = -1.5 * 92 = -138) is below it.
    assert!(me[2] < pog[2] && me[2] < b[2], "Me {me:?}");
    assert!(me[2] > -138.0);
    // The soft landmarks lie on the face mesh (face_pre.ply): within one 3.2 mm voxel of a
    // vertex, and on the skin's midline (x of Li).
    let face = facesim::mesh::ply::read(&out.join("face_pre.ply")).unwrap();
    for p in [b_s, pog_s, li] {
        let d = face
            .vertices
            .iter()
            .map(|v| (0..3).map(|k| (v[k] - p[k]).powi(2)).sum::<f64>().sqrt())
            .fold(f64::INFINITY, f64::min);
        assert!(d < 3.2, "{p:?} is {d:.2} mm from the face mesh");
        assert!((p[0] - li[0]).abs() < 2.0, "{p:?} off the midline");
    }
    // Soft menton: missing, because the scan stops under the chin.
    let why = r["landmarks"]["Me'"]["missing"]
        .as_str()
        .unwrap_or_default();
    assert!(
        landmark(&r, "Me'").is_none() && why.contains("section ends"),
        "Me': {}",
        r["landmarks"]["Me'"]
    );
    let ratio = r["soft_hard_ratios"]["Pog'/Pog"]["ratio"].as_f64().unwrap();
    println!(
        "Pog'/Pog {ratio:.3}, Li/B {}",
        r["soft_hard_ratios"]["Li/B"]["ratio"]
    );
    assert!((0.5..=1.2).contains(&ratio), "Pog'/Pog {ratio}");
    assert!(r["soft_hard_ratios"]["Li/B"]["ratio"].as_f64().is_some());
    published_ratios_are_the_runs_moves_over_the_plans(&r, &out);
}

/// report.json's `published_ratios`: the plan (segment "mandible", 5 mm along
/// −y) read as a BSSO advancement, and each of its four published rows recomputed here from the
/// report's own landmarks and head frame: the soft landmark's move along the anterior axis over
/// the translation's (a pure translation moves every bone point alike), beside the range
/// docs/guide/validation.md publishes; soft menton, not in this scan, reported missing. The page
/// carries the same section.
fn published_ratios_are_the_runs_moves_over_the_plans(r: &Value, out: &Path) {
    let c = &r["published_ratios"];
    assert_eq!(c["surgery"], "bsso-advance", "{c}");
    let a: Vec<f64> = r["head_frame"]["anterior"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let dot = |u: [f64; 3]| u[0] * a[0] + u[1] * a[1] + u[2] * a[2];
    let hard = dot([0.0, -5.0, 0.0]);
    let rows = c["rows"].as_array().unwrap();
    let softs: Vec<&str> = rows.iter().map(|x| x["soft"].as_str().unwrap()).collect();
    assert_eq!(softs, ["Li", "B'", "Pog'", "Me'"]);
    for row in rows {
        let soft = row["soft"].as_str().unwrap();
        assert_eq!(row["axis"], "horizontal");
        assert!(!row["source"].as_str().unwrap().is_empty());
        let Some((pre, post)) = landmark(r, soft) else {
            assert!(
                row["predicted"].is_null() && row["missing"].is_string(),
                "{row}"
            );
            continue;
        };
        let want = dot([post[0] - pre[0], post[1] - pre[1], post[2] - pre[2]]) / hard;
        let got = row["predicted"].as_f64().unwrap();
        assert!((got - want).abs() < 1e-9, "{soft}: {got} against {want}");
        assert!(
            (row["hard_mm"].as_f64().unwrap() - hard).abs() < 1e-9,
            "{row}"
        );
        let (lo, hi) = (row["low"].as_f64().unwrap(), row["high"].as_f64().unwrap());
        let inside = got >= lo - 5e-3 && got <= hi + 5e-3;
        assert_eq!(row["inside"].as_bool(), Some(inside), "{row}");
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains(r#""published":{"#) && html.contains(r#""surgery":"bsso-advance""#));
}

/// The skin does not tear where `[surface] movable` ends (its sphere crosses the cheek here,
/// which the BSSO advance still moves): across the sphere's edge, and wherever a face vertex
/// moves beside one held still, the displacement changes by at most 0.5 mm per mm of edge.
/// Holding every face vertex outside the sphere still while the tissue mesh moved it gave
/// 0.93 per mm across the edge (a vertex moving 1.30 mm beside a still one 1.85 mm away).
/// report.json `displacement.largest_jump` is the largest over every edge, as recomputed here
/// from face_pre.ply and face_post.ply.
#[test]
fn the_skin_does_not_tear_where_the_movable_region_ends() {
    let (r, out) = run_in();
    let pre = facesim::mesh::read_mesh(&out.join("face_pre.ply")).unwrap();
    let post = facesim::mesh::read_mesh(&out.join("face_post.ply")).unwrap();
    let (centre, radius) = ([100.0, -150.0, -115.0], 60.0);
    let dist = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
    let moved = |v: usize| dist(pre.vertices[v], post.vertices[v]);
    let mut edges: Vec<(usize, usize)> = pre
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k] as usize, t[(k + 1) % 3] as usize)))
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let jump = |(a, b): (usize, usize)| {
        let u =
            |v: usize| -> [f64; 3] { [0, 1, 2].map(|k| post.vertices[v][k] - pre.vertices[v][k]) };
        dist(u(a), u(b)) / dist(pre.vertices[a], pre.vertices[b])
    };
    let inside = |v: usize| dist(pre.vertices[v], centre) <= radius;
    // The CT's last slice (the face's lowest vertices) and the one above it: there the sphere's
    // edge meets the scan's end, where the tissue's free end moves on its own (0.54 per mm
    // measured with `[tet] scan_end = "free"`, 0.47 sliding; docs/lab/skin-continuity.md), a
    // cause of its own, left out of the sphere's figure.
    let bottom = pre
        .vertices
        .iter()
        .map(|p| p[2])
        .fold(f64::INFINITY, f64::min);
    let at_scan_end = |v: usize| pre.vertices[v][2] < bottom + 1.6;
    let (mut crossing, mut worst_across, mut tears) = (0, 0.0f64, Vec::new());
    let (mut largest, mut at_end) = (0.0f64, 0.0f64);
    for &(a, b) in &edges {
        let j = jump((a, b));
        largest = largest.max(j);
        if inside(a) != inside(b) {
            crossing += 1;
            if at_scan_end(a) || at_scan_end(b) {
                at_end = at_end.max(j);
            } else {
                worst_across = worst_across.max(j);
            }
        }
        let (ma, mb) = (moved(a), moved(b));
        if j > 0.5 && ma.min(mb) < 1e-9 {
            tears.push((pre.vertices[a], ma, mb));
        }
    }
    println!("across the sphere's edge: {worst_across:.3} per mm, at the scan's end {at_end:.3}");
    assert!(crossing > 100, "only {crossing} edges cross the sphere");
    assert!(
        tears.is_empty(),
        "{} edges torn from a still vertex, e.g. {:?}",
        tears.len(),
        tears.first()
    );
    assert!(
        worst_across <= 0.5,
        "{worst_across} per mm across the sphere's edge"
    );
    let reported = r["displacement"]["largest_jump"]["per_mm"]
        .as_f64()
        .unwrap();
    assert!(
        (reported - largest).abs() < 1e-6 * largest.max(1.0),
        "report.json {reported}, the faces {largest}"
    );
}

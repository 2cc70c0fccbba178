//! report.html in a real browser (docs/guide/report-page.md): Debian's chromium, driven by
//! puppeteer-core from web/ (web/test/page.test.mjs), opens the page from disk. Checked: no
//! console or page errors, no request leaving the file, a drawn canvas, and `setPlan` → the face
//! against two independent paths: the rigid motion of the osteotomy module (an analytic basis), and
//! full runs of the linear volumetric model. Screenshots go to target/test-artefacts/.

use crate::browser;
use crate::common;

use browser::{drive, flat, max_diff, web_dir};

use facesim::case::{Case, Osteotomy, Region, SolveModel};
use facesim::observe::Quiet;
use facesim::osteotomy::Plan;
use facesim::report_page::{PageBasis, PageData, PageSegment, write_report_html};
use serde_json::json;
use std::path::Path;
use std::process::Command;

/// The committed bundle is what `npm run build` makes from web/src and the lockfile.
#[test]
fn the_committed_bundle_equals_a_fresh_build() {
    assert!(
        web_dir().join("node_modules").is_dir(),
        "web/node_modules missing: run scripts/test-setup.sh"
    );
    let run = Command::new("node")
        .current_dir(web_dir())
        .args(["build.mjs", "--check"])
        .output()
        .expect("node missing: run scripts/test-setup.sh");
    assert!(
        run.status.success(),
        "{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
}

/// The page holds no address it could load: no src/href attributes, no url(), and the only
/// "http" strings are XML namespace names inside three.js.
fn assert_self_contained(html: &str) {
    let lower = html.to_ascii_lowercase();
    for bad in [" src=", " href=", "@import", "<link"] {
        assert!(!lower.contains(bad), "report.html contains '{bad}'");
    }
    // CSS url(…), not an identifier ending in "url" (three.js has getDataURL).
    for (i, _) in lower.match_indices("url(") {
        let before = lower[..i].chars().last().unwrap_or(' ');
        assert!(
            before.is_ascii_alphanumeric() || before == '_' || before == '$',
            "report.html contains url( at byte {i}"
        );
    }
    // The data block's base64 may spell "http" by chance, never "http:" (no ':' in base64).
    let start = lower
        .find("<script id=\"facesim-data\"")
        .expect("no data block");
    let end = start + lower[start..].find("</script>").unwrap();
    assert!(
        !lower[start..end].contains("http:") && !lower[start..end].contains("https:"),
        "the data block names an address"
    );
    let outside = format!("{}{}", &lower[..start], &lower[end..]);
    let mut rest = outside.as_str();
    while let Some(i) = rest.find("http") {
        let tail = &rest[i..];
        assert!(
            tail.starts_with("http://www.w3.org/"),
            "report.html names an address: {}",
            &tail[..tail.len().min(60)]
        );
        rest = &rest[i + 4..];
    }
}

fn osteotomy(name: &str, translate: [f64; 3], rotate_deg: [f64; 3], pivot: [f64; 3]) -> Osteotomy {
    Osteotomy {
        name: name.into(),
        region: Region::Box {
            min: [-1e9; 3],
            max: [1e9; 3],
        },
        translate,
        rotate_deg,
        pivot,
    }
}

/// A curved sheet (a piece of a cylinder about z), n × n cells, LPS mm.
fn sheet(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut v = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let phi = -1.2 + 2.4 * i as f64 / n as f64;
            v.push([
                80.0 * phi.sin(),
                -80.0 * phi.cos(),
                -60.0 + 120.0 * j as f64 / n as f64,
            ]);
        }
    }
    (v, common::grid_triangles(n))
}

/// The basis of a face that moves rigidly with its segment: for vertex x the column of
/// m_k (k = 4·i + j) is e_i · [x; 1]_j, so d = M·[x; 1] = (R − I)·x + t′ exactly.
fn rigid_columns(face: &[[f64; 3]], mine: impl Fn(&[f64; 3]) -> bool) -> Vec<Vec<[f64; 3]>> {
    (0..12)
        .map(|k| {
            let (i, j) = (k / 4, k % 4);
            face.iter()
                .map(|x| {
                    let mut c = [0.0; 3];
                    if mine(x) {
                        c[i] = if j < 3 { x[j] } else { 1.0 };
                    }
                    c
                })
                .collect()
        })
        .collect()
}

#[test]
fn set_plan_moves_an_analytic_basis_as_the_osteotomy_module_moves_bone() {
    let (face, tris) = sheet(40);
    let face_post: Vec<[f64; 3]> = face.iter().map(|p| [p[0], p[1] - 2.0, p[2]]).collect();
    let left = |p: &[f64; 3]| p[0] > 0.0; // LPS +x: the patient's left
    let pivots = [[20.0, -70.0, -30.0], [-25.0, -60.0, 10.0]];
    let segment = |name: &str, pivot: [f64; 3], mine: &dyn Fn(&[f64; 3]) -> bool| PageSegment {
        name: name.into(),
        pivot,
        translate: [0.0, -2.0, 0.0],
        rotate_deg: [0.0; 3],
        columns: rigid_columns(&face, mine),
    };
    let skull_segment = face.iter().map(|p| if left(p) { 0 } else { 1 }).collect();
    let data = PageData {
        title: "analytic basis <&>".into(),
        model: "tet".into(),
        face_pre: &face,
        face_post: &face_post,
        face_triangles: &tris,
        skull_pre: &face,
        skull_post: &face_post,
        skull_triangles: &tris,
        segments: vec!["left".into(), "right".into()],
        skull_segment,
        colour_scale_mm: [0.0, 2.0],
        figures: vec![("figure".into(), "1 mm".into())],
        warnings: vec!["a warning </script> that must stay text".into()],
        basis: Some(PageBasis {
            label: "exact".into(),
            segments: vec![
                segment("left", pivots[0], &left),
                segment("right", pivots[1], &|p| !left(p)),
            ],
        }),
        band_width: Some(face.iter().map(|p| p[0].abs() * 0.01).collect()),
        published: json!({
            "surgery": "lefort-advance", "title": "Le Fort I advancement",
            "reading": "'maxilla' (maxilla) moves +5.0 mm forward, +0.0 mm up at A",
            "rows": [
                {"soft": "Ls", "axis": "horizontal", "segment": "maxilla", "hard": "U1",
                 "hard_at": "Ls", "soft_mm": 4.8, "hard_mm": 5.0, "predicted": 0.96,
                 "low": 0.5, "high": 0.9, "inside": false, "source": "a source <b>"},
                {"soft": "Sn", "axis": "horizontal", "segment": "maxilla", "hard": "A",
                 "hard_at": "A", "soft_mm": 4.0, "hard_mm": 5.0, "predicted": 0.8,
                 "low": 0.5, "high": 0.9, "inside": true, "source": "a source",
                 "tissue_band": [0.78, 0.93], "coarse_mesh": 0.79, "band": [0.77, 0.94],
                 "verdict": "consistent"},
                {"soft": "Prn", "axis": "horizontal", "segment": "maxilla", "hard": "A / U1",
                 "hard_at": "", "soft_mm": null, "hard_mm": null, "predicted": null,
                 "low": 0.17, "high": 0.36, "inside": null, "source": "another",
                 "missing": "Prn not found"}
            ]
        }),
        // The reduced method's report: the certificate and the Sobol table.
        uncertainty: json!({
            "samples": 100, "method": "reduced", "largest_bound_mm": 7.24,
            "landmark_bounds_mm": {"Prn": 0.0, "Sn": 1.25},
            "landmarks": {"Sn": {"mean": 1.0, "p05": 0.9, "p95": 1.1}},
            "regions": {"upper lip": {"mean": 2.0, "p05": 1.8, "p95": 2.2}},
            "sensitivity": {
                "landmarks": {"Sn": {"poisson": {"first": 0.1, "total": 0.12},
                                     "muscle_fat": {"first": 0.6, "total": 0.65},
                                     "skin_fat": {"first": 0.2, "total": 0.22}}},
                "regions": {"upper lip": {"poisson": {"first": 0.05, "total": 0.06},
                                          "muscle_fat": {"first": 0.3, "total": 0.31},
                                          "skin_fat": {"first": 0.55, "total": 0.6}}}
            }
        }),
        ..Default::default()
    };
    let dir = common::kept_dir("facesim-page-analytic");
    write_report_html(&dir, &data).unwrap();
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert_self_contained(&html);

    let plans = json!([
        {"left": {"translate": [1.0, -2.0, 3.0], "rotate_deg": [10.0, -20.0, 30.0]},
         "right": {"translate": [0.0, -5.0, 0.0], "rotate_deg": [0.0, 0.0, -15.0]}},
        {"right": {"translate": [2.0, 0.0, -1.0], "rotate_deg": [-45.0, 5.0, 0.0]}},
        {"maxilla": {"translate": [0.0, -5.0, 0.0], "rotate_deg": [0.0, 0.0, 0.0]}},
    ]);
    let r = drive(&dir.join("report.html"), &plans, "report-analytic.png");
    // The uncertainty band can colour the face (no console error while it does).
    assert!(
        r["band_shown"]
            .as_str()
            .is_some_and(|t| t.contains("band width")),
        "{}",
        r["band_shown"]
    );
    // The Sobol table: a row per landmark and region, "first (total)" per parameter, the
    // largest first-order index in bold; the certificate names the largest landmark bound.
    let sens = r["sensitivity"].as_array().unwrap();
    assert_eq!(sens.len(), 2, "{sens:?}");
    assert_eq!(sens[0][0], "Sn");
    // Columns in the report's order of parameters (json! sorts keys: muscle_fat, poisson, skin_fat).
    assert_eq!(
        sens[0][1],
        json!(["0.60 (0.65)", "0.10 (0.12)", "0.20 (0.22)"])
    );
    assert_eq!(sens[0][2], 1, "muscle/fat is the largest for Sn");
    assert_eq!((&sens[1][0], &sens[1][2]), (&json!("upper lip"), &json!(3)));
    let cert = r["certified"].as_str().unwrap();
    assert!(
        cert.contains("1.25 mm") && cert.contains("7.2 mm"),
        "{cert}"
    );
    // The plan against the clinic: a row outside its range marked so, one not measured.
    let clinic: Vec<(String, String)> = r["clinic"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| (x[0].as_str().unwrap().into(), x[1].as_str().unwrap().into()))
        .collect();
    // A row with a band shows it and its verdict, which overrides the ratio's own.
    assert_eq!(clinic.len(), 4, "{clinic:?}");
    assert!(
        clinic[1].0 == "outside"
            && clinic[1].1.contains("0.96")
            && clinic[1].1.contains("0.50–0.90"),
        "{clinic:?}"
    );
    assert!(
        clinic[2].0 == "consistent"
            && clinic[2].1.contains("0.77–0.94")
            && clinic[2].1.ends_with("consistent"),
        "{clinic:?}"
    );
    assert!(
        clinic[3].0 == "unmeasured" && clinic[3].1.contains("not measured"),
        "{clinic:?}"
    );
    // Before any plan: the run's face_post (float32 in the page).
    assert!(max_diff(&flat(&r["vertices_initial"]), &face_post) < 1e-4);
    // No head frame: the views fall back to the CT's axes.
    assert_eq!(flat(&r["frame"]["front"]), [0.0, -1.0, 0.0]);
    assert_eq!(flat(&r["frame"]["up"]), [0.0, 0.0, 1.0]);
    assert!(
        r["frame"]["source"]
            .as_str()
            .unwrap()
            .contains("no head frame")
    );
    // After each plan: each vertex moved by its segment's rigid map, as osteotomy.rs moves bone.
    for (p, got) in plans.as_array().unwrap()[..2]
        .iter()
        .zip(r["vertices"].as_array().unwrap())
    {
        let expected: Vec<[f64; 3]> = face
            .iter()
            .map(|x| {
                let (name, pivot) = if left(x) {
                    ("left", pivots[0])
                } else {
                    ("right", pivots[1])
                };
                match p.get(name) {
                    None => *x,
                    Some(m) => {
                        let v3 = |k: &str| {
                            let a = flat(&m[k]);
                            [a[0], a[1], a[2]]
                        };
                        Plan::new(&[osteotomy(name, v3("translate"), v3("rotate_deg"), pivot)])
                            .apply(&[*x], 1.0)
                            .0[0]
                    }
                }
            })
            .collect();
        let d = max_diff(&flat(got), &expected);
        assert!(
            d < 1e-3,
            "plan {p}: the page is {d} mm off the rigid motion"
        );
    }
    // A plan naming an unknown segment is refused, and the face keeps the previous plan.
    let errors = r["set_plan_errors"].as_array().unwrap();
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert!(
        errors[0]
            .as_str()
            .unwrap()
            .contains("unknown segment 'maxilla'")
    );
    assert_eq!(r["vertices"][2], r["vertices"][1]);
}

/// Run the capsule phantom with the linear volumetric model, the mandible moved by `translate`.
fn tet_run(translate: [f64; 3], out: &Path) -> facesim::commands::Outcome {
    let (mut case, _) = Case::load(&common::phantom_dir().join("case.toml")).unwrap();
    case.solve.model = SolveModel::Tet;
    case.tet.sliding = false;
    case.tet.skin_size_mm = 8.0;
    case.tet.deep_size_mm = 16.0;
    case.osteotomy.truncate(1);
    case.osteotomy[0].translate = translate;
    case.osteotomy[0].rotate_deg = [0.0; 3];
    facesim::commands::run_case(case, out, &Quiet).unwrap()
}

#[test]
fn set_plan_equals_a_full_run_of_the_linear_volumetric_model() {
    // The face displacement of the linear model is linear in M = [R − I | t′]; for translations
    // only the columns of t′ (k = 3, 7, 11) act. Two runs give the columns of t′_y and t′_z; a third,
    // independent run of another plan is what the page must reproduce.
    let dir = common::kept_dir("facesim-page-tet");
    let y = tet_run([0.0, -4.0, 0.0], &dir.join("y"));
    let z = tet_run([0.0, 0.0, 3.0], &dir.join("z"));
    let x_plan = [0.0, -3.0, 2.0];
    let x = tet_run(x_plan, &dir.join("x"));
    assert_eq!(y.skin.vertices, x.skin.vertices);
    let column = |o: &facesim::commands::Outcome, per: f64| -> Vec<[f64; 3]> {
        o.face_post
            .vertices
            .iter()
            .zip(&o.skin.vertices)
            .map(|(a, b)| [0, 1, 2].map(|c| (a[c] - b[c]) / per))
            .collect()
    };
    let zero = vec![[0.0; 3]; y.skin.vertices.len()];
    let mut columns = vec![zero; 12];
    columns[7] = column(&y, -4.0);
    columns[11] = column(&z, 3.0);
    // The page of run y: written by the pipeline itself, then again with the basis.
    let html = std::fs::read_to_string(y.out_dir.join("report.html")).unwrap();
    assert_self_contained(&html);
    assert!(html.contains("No plan basis"));
    let skull_post = Plan::new(&[osteotomy("mandible", [0.0, -4.0, 0.0], [0.0; 3], [0.0; 3])])
        .apply(&y.skull.vertices, 1.0)
        .0;
    let page = dir.join("page");
    write_report_html(
        &page,
        &PageData {
            title: "tet phantom".into(),
            model: "tet".into(),
            face_pre: &y.skin.vertices,
            face_post: &y.face_post.vertices,
            face_triangles: &y.skin.triangles,
            skull_pre: &y.skull.vertices,
            skull_post: &skull_post,
            skull_triangles: &y.skull.triangles,
            segments: vec!["mandible".into()],
            skull_segment: vec![255; y.skull.vertices.len()],
            colour_scale_mm: [0.0, y.report.displacement.max],
            figures: vec![],
            warnings: y.report.warnings.clone(),
            basis: Some(PageBasis {
                label: "exact".into(),
                segments: vec![PageSegment {
                    name: "mandible".into(),
                    pivot: [10.0, -50.0, -40.0],
                    translate: [0.0, -4.0, 0.0],
                    rotate_deg: [0.0; 3],
                    columns,
                }],
            }),
            ..Default::default()
        },
    )
    .unwrap();
    let plans = json!([{"mandible": {"translate": x_plan, "rotate_deg": [0.0, 0.0, 0.0]}}]);
    let r = drive(&page.join("report.html"), &plans, "report.png");
    assert!(max_diff(&flat(&r["vertices_initial"]), &y.face_post.vertices) < 1e-3);
    let d = max_diff(&flat(&r["vertices"][0]), &x.face_post.vertices);
    let moved = x.report.displacement.max;
    println!(
        "setPlan vs a full run of the same plan: max |Δ| = {d:.2e} mm (face moved up to {moved:.2} mm)"
    );
    assert!(moved > 1.0, "the plan hardly moved the face: {moved} mm");
    assert!(d < 1e-3, "setPlan is {d} mm off the full run");
}

// ---- the page as a surgeon shows it: views, tracing, labels, export, keyboard, print ----

/// The pinhole camera the page reports (`facesim.camera()`), projecting LPS points to CSS pixels
/// of the picture on its own (no three.js).
struct Camera {
    pos: [f64; 3],
    fwd: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    focal: f64,
    size: [f64; 2],
}

fn v3(v: &serde_json::Value) -> [f64; 3] {
    let a = flat(v);
    [a[0], a[1], a[2]]
}

impl Camera {
    fn new(c: &serde_json::Value) -> Camera {
        use facesim::vec3::{cross, norm, scale, sub};
        let unit = |a: [f64; 3]| scale(a, 1.0 / norm(a));
        let pos = v3(&c["position"]);
        let fwd = unit(sub(v3(&c["target"]), pos));
        let right = unit(cross(fwd, v3(&c["up"])));
        let size = [c["width"].as_f64().unwrap(), c["height"].as_f64().unwrap()];
        let half = c["fov"].as_f64().unwrap().to_radians() / 2.0;
        Camera {
            pos,
            fwd,
            right,
            up: cross(right, fwd),
            focal: size[1] / 2.0 / half.tan(),
            size,
        }
    }

    fn project(&self, p: [f64; 3]) -> [f64; 2] {
        use facesim::vec3::{dot, sub};
        let d = sub(p, self.pos);
        let z = dot(d, self.fwd);
        [
            self.size[0] / 2.0 + self.focal * dot(d, self.right) / z,
            self.size[1] / 2.0 - self.focal * dot(d, self.up) / z,
        ]
    }
}

/// A picture's mask (1: drawn, 0: the background), from the page script's base64.
struct Mask {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

impl Mask {
    fn new(shot: &serde_json::Value) -> Mask {
        let w = shot["width"].as_u64().unwrap() as usize;
        let h = shot["height"].as_u64().unwrap() as usize;
        let px = unbase64(shot["mask"].as_str().unwrap());
        assert_eq!(px.len(), w * h);
        Mask { w, h, px }
    }

    /// Drawn pixels in the 3 × 3 square around CSS pixel `p` (the canvas has the CSS size).
    fn drawn_near(&self, p: [f64; 2]) -> usize {
        let (x, y) = (p[0].round() as i64, p[1].round() as i64);
        let mut k = 0;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (i, j) = (x + dx, y + dy);
                if i >= 0 && j >= 0 && (i as usize) < self.w && (j as usize) < self.h {
                    k += self.px[j as usize * self.w + i as usize] as usize;
                }
            }
        }
        k
    }
}

fn unbase64(s: &str) -> Vec<u8> {
    let val = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let b: Vec<u8> = s.bytes().filter(|c| *c != b'=').collect();
    let mut out = Vec::with_capacity(b.len() * 3 / 4);
    for c in b.chunks(4) {
        let n = c
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, x)| n | u32::from(val(*x)) << (18 - 6 * i));
        for k in 0..c.len() - 1 {
            out.push((n >> (16 - 8 * k)) as u8);
        }
    }
    out
}

/// The head frame of report.json: origin, front, up, left.
#[derive(Clone, Copy)]
struct Frame {
    origin: [f64; 3],
    front: [f64; 3],
    up: [f64; 3],
    left: [f64; 3],
}

/// The face cut by the midsagittal plane, computed here from the mesh: every edge crossing as
/// (front, up) mm from the frame's origin, the segments as pairs, only the facial part (within
/// 90 mm of the most anterior point, as the page draws it).
fn midsagittal_cut(v: &[[f64; 3]], tris: &[[u32; 3]], f: &Frame) -> Vec<[[f64; 2]; 2]> {
    use facesim::vec3::{add, dot, scale, sub};
    let side: Vec<f64> = v.iter().map(|p| dot(sub(*p, f.origin), f.left)).collect();
    let mut segs = Vec::new();
    for t in tris {
        let mut pts = Vec::new();
        for e in 0..3 {
            let (a, b) = (t[e] as usize, t[(e + 1) % 3] as usize);
            if (side[a] >= 0.0) != (side[b] >= 0.0) {
                let p = add(v[a], scale(sub(v[b], v[a]), side[a] / (side[a] - side[b])));
                let d = sub(p, f.origin);
                pts.push([dot(d, f.front), dot(d, f.up)]);
            }
        }
        if pts.len() == 2 {
            segs.push([pts[0], pts[1]]);
        }
    }
    let front = segs
        .iter()
        .flatten()
        .map(|p| p[0])
        .fold(f64::NEG_INFINITY, f64::max);
    segs.retain(|s| s.iter().all(|p| p[0] >= front - 90.0));
    segs
}

/// (front, up) points of SVG path data "Mx yLx y…" (x = front, y = −up).
fn path_points(d: &str) -> Vec<[f64; 2]> {
    let nums: Vec<f64> = d
        .split(['M', 'L', ' '])
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    nums.chunks(2).map(|c| [c[0], -c[1]]).collect()
}

fn dist_to_segment(p: [f64; 2], s: [[f64; 2]; 2]) -> f64 {
    let d = [s[1][0] - s[0][0], s[1][1] - s[0][1]];
    let l2 = d[0] * d[0] + d[1] * d[1];
    let t = if l2 > 0.0 {
        (((p[0] - s[0][0]) * d[0] + (p[1] - s[0][1]) * d[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - s[0][0] - t * d[0]).hypot(p[1] - s[0][1] - t * d[1])
}

/// The tracing drawn (`d`) against the cut of the mesh: every drawn point on the cut, every
/// point of the cut drawn (mm, both ways).
fn assert_tracing(d: &str, cut: &[[[f64; 2]; 2]], what: &str) {
    let drawn = path_points(d);
    assert!(
        drawn.len() > 30 && cut.len() > 30,
        "{what}: {} points drawn, {} segments cut",
        drawn.len(),
        cut.len()
    );
    let off = drawn
        .iter()
        .map(|p| {
            cut.iter()
                .map(|s| dist_to_segment(*p, *s))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    let missed = cut
        .iter()
        .flatten()
        .map(|q| {
            drawn
                .iter()
                .map(|p| (p[0] - q[0]).hypot(p[1] - q[1]))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    println!(
        "tracing {what}: {} points, off the cut ≤ {off:.4} mm, cut points missed ≤ {missed:.4} mm",
        drawn.len()
    );
    assert!(
        off < 0.02,
        "{what}: a drawn point is {off} mm off the mesh's cut"
    );
    assert!(
        missed < 0.02,
        "{what}: a point of the cut is {missed} mm from the drawing"
    );
}

/// Run the node script views.test.mjs on `html`; its screenshots go to `shots`.
fn drive_views(html: &Path, plan: &serde_json::Value, shots: &Path) -> serde_json::Value {
    let dir = html.parent().unwrap();
    let plan_file = dir.join("views-plan.json");
    std::fs::write(&plan_file, plan.to_string()).unwrap();
    let out = dir.join("views.json");
    let run = Command::new("node")
        .current_dir(web_dir())
        .arg("test/views.test.mjs")
        .args([html, &plan_file, &out, shots])
        .output()
        .expect("node missing: run scripts/test-setup.sh");
    assert!(
        run.status.success(),
        "views.test.mjs failed: {}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap()
}

#[test]
fn the_page_shows_the_jaws_phantom_in_every_view_with_tracing_labels_export_and_print() {
    use facesim::vec3::{add, dot, norm, scale, sub};
    use facesim_validate::phantom::PhantomOptions;
    use facesim_validate::phantom_jaws::{JawsOptions, write_case};
    // The jaws phantom (a face with nose, lips and chin; the mandible advanced 5 mm), run by the
    // pipeline, which writes report.html with the head frame and a plan basis.
    let dir = common::kept_dir("facesim-page-views");
    let opts = JawsOptions {
        phantom: PhantomOptions {
            spacing: [2.0; 3],
            ..PhantomOptions::default()
        },
        solve_model: None,
    };
    write_case(&dir, &opts).unwrap();
    let o = facesim::commands::run(&dir.join("case.toml"), Some(&dir.join("out")), &Quiet).unwrap();
    let html_path = o.out_dir.join("report.html");
    assert_self_contained(&std::fs::read_to_string(&html_path).unwrap());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(o.out_dir.join("report.json")).unwrap())
            .unwrap();
    let hf = &report["head_frame"];
    let frame = Frame {
        origin: v3(&hf["origin"]),
        front: v3(&hf["anterior"]),
        up: v3(&hf["vertical"]),
        left: v3(&hf["lateral"]),
    };
    let segment = o.report.parameters.as_ref().unwrap().osteotomy[0]
        .name
        .clone();
    let plan =
        json!({ segment.clone(): {"translate": [0.0, -9.0, 2.0], "rotate_deg": [4.0, 0.0, 0.0]} });
    let shots = Path::new(env!("CARGO_TARGET_TMPDIR")).join("../test-artefacts/views");
    let r = drive_views(&html_path, &plan, &shots);
    for k in ["console_errors", "page_errors", "outside_requests"] {
        assert_eq!(r[k], json!([]), "{k}");
    }
    assert_eq!(r["plan_error"], json!(null));
    // The page uses report.json's head frame, and opens in profile.
    let pf = &r["frame"];
    for (page, ours) in [
        ("origin", frame.origin),
        ("front", frame.front),
        ("up", frame.up),
        ("left", frame.left),
    ] {
        let d = norm(sub(v3(&pf[page]), ours));
        assert!(d < 1e-9, "frame {page}: {} vs {ours:?}", pf[page]);
    }
    assert_eq!(r["default_view"], json!("profile-right"));
    // The views stand in the clinical frame (report.json clinical_frame) when the run has one.
    let cf = &report["clinical_frame"];
    let vframe = if cf.is_object() {
        Frame {
            origin: v3(&cf["origin"]),
            front: v3(&cf["forward"]),
            up: v3(&cf["up"]),
            left: v3(&cf["left"]),
        }
    } else {
        frame
    };
    let vf = &r["view_frame"];
    for (page, ours) in [
        ("origin", vframe.origin),
        ("front", vframe.front),
        ("up", vframe.up),
        ("left", vframe.left),
    ] {
        let d = norm(sub(v3(&vf[page]), ours));
        assert!(d < 1e-9, "view frame {page}: {} vs {ours:?}", vf[page]);
    }

    // ---- every view and face: drawn, silhouette where it belongs, labels at their landmarks ----
    let lm_report = &report["landmarks"];
    let pre = |label: &str| {
        lm_report[label]["pre"]
            .as_array()
            .map(|_| v3(&lm_report[label]["pre"]))
    };
    let views = r["views"].as_array().unwrap();
    assert_eq!(views.len(), 12);
    let mut checked_labels = 0;
    for s in views {
        let (view, mode) = (s["view"].as_str().unwrap(), s["mode"].as_str().unwrap());
        let what = format!("{view}/{mode} (target/test-artefacts/views/{view}-{mode}.png)");
        assert_eq!(s["info"]["view"], json!(view), "{what}");
        assert_eq!(s["info"]["mode"], json!(mode), "{what}");
        let mask = Mask::new(s);
        let drawn = mask.px.iter().filter(|x| **x == 1).count();
        assert!(
            drawn as f64 > 0.05 * (mask.w * mask.h) as f64 && s["colours"].as_u64().unwrap() > 100,
            "{what}: blank? {drawn} of {} pixels drawn, {} colours",
            mask.w * mask.h,
            s["colours"]
        );
        let cam = Camera::new(&s["camera"]);
        assert_eq!(
            [mask.w as f64, mask.h as f64],
            cam.size,
            "{what}: canvas ≠ CSS size"
        );
        // Where the face is: the soft landmarks of the face shown.
        let shown_at = |label: &str| -> Option<[f64; 3]> {
            if mode == "before" {
                pre(label)
            } else {
                s["landmarks"].get(label).map(v3)
            }
        };
        let prn = shown_at("Prn").expect("no Prn on the jaws phantom");
        let toward = sub(cam.pos, prn);
        let side_on = dot(toward, vframe.left).abs() / norm(toward) > 0.99;
        if view.starts_with("profile") {
            assert!(side_on, "{what}: the camera is not at the side");
            // The nose tip is skin; a few mm in front of it (of the more anterior of before and
            // after) is background.
            assert!(
                mask.drawn_near(cam.project(prn)) >= 5,
                "{what}: no skin at the nose tip"
            );
            let tips = [pre("Prn").unwrap(), v3(&s["landmarks"]["Prn"])];
            let tip = tips
                .into_iter()
                .max_by(|a, b| dot(*a, frame.front).total_cmp(&dot(*b, frame.front)))
                .unwrap();
            let ahead = cam.project(add(tip, scale(frame.front, 5.0)));
            assert_eq!(
                mask.drawn_near(ahead),
                0,
                "{what}: not background 5 mm before the nose tip"
            );
            // The chin: 2.5 mm in front of soft pogonion before is background before surgery and
            // skin after it (the mandible comes 5 mm forward).
            let pog = cam.project(add(pre("Pog'").unwrap(), scale(frame.front, 2.5)));
            match mode {
                "before" => assert_eq!(mask.drawn_near(pog), 0, "{what}: chin 2.5 mm ahead"),
                "after" => assert_eq!(mask.drawn_near(pog), 9, "{what}: the advanced chin"),
                _ => {}
            }
        }
        if view == "front" {
            // Left-right symmetric coverage about the projected midsagittal line.
            let a = cam.project(add(vframe.origin, scale(vframe.up, 60.0)));
            let b = cam.project(sub(vframe.origin, scale(vframe.up, 60.0)));
            let (mut left, mut right) = (0usize, 0usize);
            for y in 0..mask.h {
                let xm = a[0] + (b[0] - a[0]) * (y as f64 - a[1]) / (b[1] - a[1]);
                for x in 0..mask.w {
                    if mask.px[y * mask.w + x] == 1 {
                        if (x as f64) < xm {
                            left += 1
                        } else {
                            right += 1
                        }
                    }
                }
            }
            let ratio = left.min(right) as f64 / left.max(right) as f64;
            println!("{what}: left/right coverage {left} / {right}");
            assert!(
                ratio > 0.9,
                "{what}: asymmetric front view {left} vs {right}"
            );
        }
        // Labels: every shown one next to its landmark's projection; the midline ones shown in
        // the profiles and the front view.
        let labels = s["labels"].as_array().unwrap();
        for l in labels {
            let label = l["label"].as_str().unwrap();
            assert_eq!(l["text"], json!(label));
            if l["shown"] != json!(true) {
                continue;
            }
            let p = cam.project(shown_at(label).unwrap());
            let b = flat(&l["box"]);
            let dx = (b[0] - p[0]).max(p[0] - b[0] - b[2]).max(0.0);
            let dy = (b[1] - p[1]).max(p[1] - b[1] - b[3]).max(0.0);
            assert!(
                dx.hypot(dy) < 10.0,
                "{what}: label {label} at {b:?}, its landmark at {p:?}"
            );
            assert!(
                b[0] > -b[2] && b[0] < cam.size[0] && b[1] > 0.0 && b[1] < cam.size[1],
                "{what}: label {label} off the picture"
            );
            checked_labels += 1;
        }
        if view != "three-quarter" {
            for label in ["Prn", "Sn", "Ls", "Li", "Pog'"] {
                let l = labels.iter().find(|l| l["label"] == json!(label));
                assert!(
                    l.is_some_and(|l| l["shown"] == json!(true)),
                    "{what}: label {label} not shown"
                );
            }
        }
        // Bony labels only with the skull, which is hidden by default.
        assert!(
            labels
                .iter()
                .filter(|l| l["label"] == json!("Pog") || l["label"] == json!("B"))
                .all(|l| l["shown"] == json!(false)),
            "{what}: bony labels over the opaque skin"
        );
        // The text alternative says what the picture shows.
        let aria = s["aria"].as_str().unwrap();
        let says = match view {
            "front" => "from the front",
            "profile-right" => "profile from the patient's right",
            "profile-left" => "profile from the patient's left",
            _ => "three-quarter",
        };
        assert!(aria.contains(says), "{what}: aria-label {aria}");
        let face = match mode {
            "before" => "the face before surgery",
            "after" => "predicted face after surgery,",
            _ => "ghost of the face before",
        };
        assert!(aria.contains(face), "{what}: aria-label {aria}");
    }
    println!("{checked_labels} shown labels checked against their landmarks");

    // ---- the profile tracing against the mesh's own cut ----
    let t = &r["tracing_run"];
    assert_eq!(t["role"], json!("img"));
    assert!(
        t["title"].as_str().unwrap().contains("profile") && t["desc"].as_str().unwrap().len() > 40
    );
    assert_eq!(t["shown"], json!(true));
    let cut_pre = midsagittal_cut(&o.skin.vertices, &o.skin.triangles, &frame);
    assert_tracing(t["before"].as_str().unwrap(), &cut_pre, "before");
    assert_tracing(
        t["after"].as_str().unwrap(),
        &midsagittal_cut(&o.face_post.vertices, &o.skin.triangles, &frame),
        "after (the run's plan)",
    );
    // Re-planned: the after line follows the page's face, and has moved.
    let page_face: Vec<[f64; 3]> = flat(&r["vertices_plan"])
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let planned = &r["tracing_plan"];
    assert_eq!(
        planned["before"], t["before"],
        "the before line changed with the plan"
    );
    assert_tracing(
        planned["after"].as_str().unwrap(),
        &midsagittal_cut(&page_face, &o.skin.triangles, &frame),
        "after setPlan",
    );
    let moved = path_points(planned["after"].as_str().unwrap())
        .iter()
        .zip(path_points(t["after"].as_str().unwrap()))
        .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
        .fold(0.0, f64::max);
    assert!(
        moved > 2.0,
        "the after line hardly moved with the plan: {moved} mm"
    );

    // ---- PNG export: a PNG of the canvas' size ----
    let png = &r["png"];
    let url = png["url"].as_str().unwrap();
    let bytes = unbase64(
        url.strip_prefix("data:image/png;base64,")
            .expect("not a PNG data URL"),
    );
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&bytes[12..16], b"IHDR");
    let wh = [
        u32::from_be_bytes(bytes[16..20].try_into().unwrap()),
        u32::from_be_bytes(bytes[20..24].try_into().unwrap()),
    ];
    assert_eq!(json!(wh), png["canvas"], "the PNG's size");
    assert_eq!(
        png["natural"], png["canvas"],
        "the PNG as the browser decodes it"
    );
    std::fs::write(shots.join("export.png"), &bytes).unwrap();

    // ---- keyboard: every control reachable by Tab and named; keys on the picture ----
    for c in r["controls"].as_array().unwrap() {
        assert!(
            c["tab_index"].as_i64().unwrap() >= 0 && !c["name"].as_str().unwrap().is_empty(),
            "a control without a name or out of the Tab order: {c}"
        );
    }
    let tabbed: Vec<&str> = r["tab_order"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    for want in [
        "canvas",
        "button:front",
        "button:profile-right",
        "button:profile-left",
        "button:three-quarter",
        "button:before",
        "button:after",
        "button:both",
        "button#png",
        "button#print",
        "input#colour",
        "input#landmarks",
        "input#skull",
        "input#tracing",
        "input",
    ] {
        assert!(
            tabbed.contains(&want),
            "Tab never reaches {want}: {tabbed:?}"
        );
    }
    let offset = |c: &serde_json::Value| sub(v3(&c["position"]), v3(&c["target"]));
    let angle = |a: [f64; 3], b: [f64; 3]| {
        (dot(a, b) / norm(a) / norm(b))
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    };
    let keys = r["keys"].as_array().unwrap();
    let mut before = offset(&r["keys_start"]);
    for k in keys {
        let (key, now) = (k["key"].as_str().unwrap(), offset(&k["camera"]));
        let dir = scale(now, 1.0 / norm(now));
        match key {
            "ArrowRight" | "ArrowUp" => {
                let a = angle(before, now);
                assert!((a - 15.0).abs() < 0.5, "{key} turned {a}°");
                if key == "ArrowRight" {
                    // About the head's vertical: the height above the target is kept.
                    assert!((dot(before, vframe.up) - dot(now, vframe.up)).abs() < 1e-6);
                }
            }
            "-" => {
                let k = norm(now) / norm(before);
                assert!((k - 1.0 / 0.85).abs() < 1e-6, "'-' zoomed by {k}");
            }
            _ => {
                let (view, axis) = match key {
                    "1" => ("front", vframe.front),
                    "2" => ("profile-right", scale(vframe.left, -1.0)),
                    "3" => ("profile-left", vframe.left),
                    _ => (
                        "three-quarter",
                        scale(sub(vframe.front, vframe.left), 1.0 / 2f64.sqrt()),
                    ),
                };
                assert_eq!(k["view"], json!(view), "key {key}");
                assert!(dot(dir, axis) > 0.999, "key {key}: camera towards {dir:?}");
            }
        }
        before = now;
    }
    assert!(keys[4]["aria"].as_str().unwrap().contains("from the front"));

    // ---- tables with captions; the region table and the measurements ----
    let tables = r["tables"].as_array().unwrap();
    assert!(
        tables
            .iter()
            .all(|t| !t["caption"].as_str().unwrap().is_empty()),
        "a table without caption"
    );
    let find = |w: &str| {
        tables
            .iter()
            .find(|t| t["caption"].as_str().unwrap().contains(w))
    };
    assert_eq!(find("per region").unwrap()["rows"], json!(5));
    assert!(find("Measurements").is_some_and(|t| t["rows"].as_u64().unwrap() >= 4));

    // ---- print: one page, the picture, tracing and tables, no controls ----
    assert_eq!(r["print"]["controls_shown"], json!([]));
    assert_eq!(
        r["print"]["parts_shown"],
        json!(["#view canvas", "#profile svg", "#summary table"])
    );
    assert_eq!(
        r["pdf_pages"],
        json!(1),
        "the print layout is not one page ({}/summary.pdf)",
        shots.display()
    );

    // Screenshots for docs/guide/report-page.md: FACESIM_DOC_SHOTS=1 copies them into docs/img.
    if std::env::var_os("FACESIM_DOC_SHOTS").is_some() {
        let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/img");
        std::fs::create_dir_all(&docs).unwrap();
        for (from, to) in [
            ("profile-right-after.png", "report-profile.png"),
            ("three-quarter-both.png", "report-three-quarter-both.png"),
            ("export.png", "report-export.png"),
            ("print.png", "report-print.png"),
        ] {
            std::fs::copy(shots.join(from), docs.join(to)).unwrap();
        }
    }
}

// ---- the plan in the surgeon's terms: sliders in the clinical frame; the views on the face ----

/// Run web/test/clinical.test.mjs on `html` with `steps` ([api, argument] pairs).
fn drive_clinical(html: &Path, steps: &serde_json::Value, shot: &str) -> serde_json::Value {
    let dir = html.parent().unwrap();
    let steps_file = dir.join("clinical-steps.json");
    std::fs::write(&steps_file, steps.to_string()).unwrap();
    let out = dir.join("clinical.json");
    let shot = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("../test-artefacts")
        .join(shot);
    let run = Command::new("node")
        .current_dir(web_dir())
        .arg("test/clinical.test.mjs")
        .args([html, &steps_file, &out, &shot])
        .output()
        .expect("node missing: run scripts/test-setup.sh");
    assert!(
        run.status.success(),
        "clinical.test.mjs failed: {}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    for k in ["console_errors", "page_errors", "outside_requests"] {
        assert_eq!(r[k], json!([]), "{k} in {}", html.display());
    }
    r
}

/// The right-handed rotation by `deg` about the unit axis `u` (Rodrigues), written here from
/// docs/guide/planning.md "Signs", not taken from the crate.
fn rodrigues(u: [f64; 3], deg: f64) -> [[f64; 3]; 3] {
    let (s, c) = deg.to_radians().sin_cos();
    let mut r = [[0.0; 3]; 3];
    let k = [[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = c * f64::from(u8::from(i == j)) + s * k[i][j] + (1.0 - c) * u[i] * u[j];
        }
    }
    r
}

/// `rotate_deg` [rx, ry, rz] with R = Rz·Ry·Rx (setPlan's convention, docs/guide/report-page.md).
fn zyx_degrees(r: [[f64; 3]; 3]) -> [f64; 3] {
    [
        r[2][1].atan2(r[2][2]).to_degrees(),
        (-r[2][0]).asin().to_degrees(),
        r[1][0].atan2(r[0][0]).to_degrees(),
    ]
}

/// Largest |a − b| over two flat arrays of one length.
fn max_abs(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn the_jaws_sample_page_plans_in_the_clinical_frame_and_frames_the_face() {
    use facesim::vec3::{dot, scale, sub};
    // The first sample (data-samples/jaws: the mandible advanced 5 mm), run by the pipeline; its
    // report.html has the clinical frame and an exact plan basis.
    let case = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws/case.toml");
    let dir = common::kept_dir("facesim-page-clinical");
    let o = facesim::commands::run(&case, Some(&dir.join("out")), &Quiet).unwrap();
    let html = o.out_dir.join("report.html");
    assert_self_contained(&std::fs::read_to_string(&html).unwrap());
    let report = common::report_json(&o);
    let cf = &report["clinical_frame"];
    assert!(cf.is_object(), "the jaws sample has no clinical frame");
    let (forward, up, left) = (v3(&cf["forward"]), v3(&cf["up"]), v3(&cf["left"]));
    let seg = &report["plan"]["segments"][0];
    let name = seg["name"].as_str().unwrap().to_string();

    // advance 5 against translate = 5 × forward; pitch 3° against the LPS rotation about the
    // left axis through the pivot (the pivot's part of the move is setPlan's own).
    let pitch = zyx_degrees(rodrigues(left, 3.0));
    let steps = json!([
        ["setPlanClinical", {name.clone(): {"advance_mm": 5.0}}],
        ["setPlan", {name.clone(): {"translate": scale(forward, 5.0), "rotate_deg": [0.0, 0.0, 0.0]}}],
        ["setPlanClinical", {name.clone(): {"pitch_deg": 3.0}}],
        ["setPlan", {name.clone(): {"translate": [0.0, 0.0, 0.0], "rotate_deg": pitch}}],
        ["setPlanClinical", {name.clone(): {"advance": 5.0}}],
        ["setPlanClinical", {"maxilla": {"advance_mm": 5.0}}],
    ]);
    let r = drive_clinical(&html, &steps, "clinical/jaws-default.png");
    let st = r["steps"].as_array().unwrap();
    for s in &st[..4] {
        assert_eq!(s["error"], json!(null));
    }

    // ---- the sliders: the run's plan read back in the clinical frame (report.json) ----
    assert_eq!(r["sliders"]["frame"], json!("clinical"));
    assert_eq!(
        r["slider_labels"],
        json!(["advance", "up", "left", "pitch", "roll", "yaw"])
    );
    let moves = &seg["moves"];
    for key in [
        "advance_mm",
        "up_mm",
        "left_mm",
        "pitch_deg",
        "roll_deg",
        "yaw_deg",
    ] {
        let want = moves[key].as_f64().unwrap();
        let got = &r["sliders"]["segments"][&name][key];
        let value = got["value"].as_f64().unwrap();
        println!("slider {key}: {value} (report.json {want})");
        assert!(
            (value - want).abs() <= 1e-9 * want.abs().max(1.0),
            "slider {key} starts at {value}, report.json plan moves {want}"
        );
        // What the slider shows: its value to 0.1 with its unit, the range input on its 0.1 step.
        let unit = if key.ends_with("_mm") { " mm" } else { " °" };
        let text = got["text"].as_str().unwrap();
        let shown: f64 = text.strip_suffix(unit).unwrap().parse().unwrap();
        assert!((shown - want).abs() <= 0.05 + 1e-9, "{key}: shows {text}");
        assert!(
            (got["input"].as_f64().unwrap() - want).abs() <= 0.05 + 1e-9,
            "{key}: {got}"
        );
    }
    // The run advanced the mandible: 5 mm along LPS −y, read in the frame.
    let advance = moves["advance_mm"].as_f64().unwrap();
    assert!(advance > 4.0, "advance read back {advance}");

    // ---- setPlanClinical: exact against setPlan of the same LPS move ----
    let rel = |a: &[f64], b: &[f64]| {
        let scale_ = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        max_abs(a, b) / scale_
    };
    let (adv, adv_lps) = (&st[0], &st[1]);
    let face_diff = max_abs(&flat(&adv["vertices"]), &flat(&adv_lps["vertices"]));
    let mat_rel = rel(
        &flat(&adv["matrices"][&name]),
        &flat(&adv_lps["matrices"][&name]),
    );
    println!(
        "advance 5 vs translate 5·forward: face |Δ| {face_diff:e} mm, plan matrix {mat_rel:e} relative"
    );
    assert!(
        mat_rel <= 1e-9,
        "advance 5: plan matrix {mat_rel} relative off"
    );
    assert!(
        face_diff <= 1e-9,
        "advance 5: the face is {face_diff} mm off setPlan's"
    );
    let face_pre: Vec<f64> = o.skin.vertices.iter().flatten().copied().collect();
    let moved = max_abs(&flat(&adv["vertices"]), &face_pre);
    assert!(moved > 2.0, "advance 5 hardly moved the face: {moved} mm");
    // The sliders show the clinical plan; after setPlan, its moves read back.
    let sl = |s: &serde_json::Value, k: &str| {
        s["sliders"]["segments"][&name][k]["value"]
            .as_f64()
            .unwrap()
    };
    assert_eq!(sl(adv, "advance_mm"), 5.0);
    assert_eq!(sl(adv, "pitch_deg"), 0.0);
    assert!((sl(adv_lps, "advance_mm") - 5.0).abs() < 1e-9 && sl(adv_lps, "up_mm").abs() < 1e-9);

    let (pit, pit_lps) = (&st[2], &st[3]);
    let mat_rel = rel(
        &flat(&pit["matrices"][&name]),
        &flat(&pit_lps["matrices"][&name]),
    );
    let face_pit = flat(&pit["vertices"]);
    let face_diff = max_abs(&face_pit, &flat(&pit_lps["vertices"]));
    let face_scale = face_pre.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    println!(
        "pitch 3° vs setPlan of Rz·Ry·Rx = {pitch:?}: plan matrix {mat_rel:e} relative, face |Δ| {face_diff:e} mm (float32 vertices up to {face_scale:.0} mm)"
    );
    assert!(
        mat_rel <= 1e-9,
        "pitch 3°: plan matrix {mat_rel} relative off"
    );
    // The vertex buffer is float32: one rounding step of the largest coordinate at most.
    assert!(
        face_diff <= face_scale * f64::from(f32::EPSILON),
        "pitch 3°: the face is {face_diff} mm off setPlan's"
    );
    assert!(
        (sl(pit_lps, "pitch_deg") - 3.0).abs() < 1e-9,
        "pitch read back"
    );
    // A positive pitch turns the front down: in front of the pivot, the chin goes down.
    let pivot = v3(&seg["pivot"]);
    let chin = |s: &serde_json::Value| v3(&s["landmarks"]["Pog"]);
    let pog_pre = v3(&report["landmarks"]["Pog"]["pre"]);
    if dot(sub(pog_pre, pivot), forward) > 10.0 {
        assert!(
            dot(sub(chin(pit), pog_pre), up) < -0.1,
            "pitch +3° did not lower the chin"
        );
    }
    // Unknown keys and segments are refused.
    assert!(
        st[4]["error"]
            .as_str()
            .unwrap()
            .contains("no clinical move 'advance'")
    );
    assert!(
        st[5]["error"]
            .as_str()
            .unwrap()
            .contains("unknown segment 'maxilla'")
    );

    // ---- the default view: profile, upright in the clinical frame, framed on the face ----
    assert_face_framed(&r, up, forward, left, "the jaws sample");
}

/// The page as it opens (`r` from clinical.test.mjs): the profile from the patient's right,
/// upright in the clinical frame (`up`, `forward`, `left`), framed on the face: the nose tip and
/// the lip landmarks at least 40 px inside the picture with their labels whole on it, the face
/// from G' (or N') to Me' (or Pog' or the lowest lip landmark) over more than half its height.
fn assert_face_framed(
    r: &serde_json::Value,
    up: [f64; 3],
    forward: [f64; 3],
    left: [f64; 3],
    what: &str,
) {
    use facesim::vec3::{dot, norm, sub};
    assert_eq!(r["info"]["view"], json!("profile-right"), "{what}");
    let vf = &r["view_frame"];
    for (k, want) in [("front", forward), ("up", up), ("left", left)] {
        assert!(
            norm(sub(v3(&vf[k]), want)) < 1e-9,
            "{what}: view frame {k}: {} vs {want:?}",
            vf[k]
        );
    }
    let cam = Camera::new(&r["camera"]);
    assert!(
        dot(cam.up, up) > 0.999,
        "{what}: the profile is not upright: {:?}",
        cam.up
    );
    assert!(
        dot(cam.right, forward) > 0.999,
        "{what}: the face does not look right"
    );
    let [w, h] = cam.size;
    let lm = &r["landmarks"];
    let mut found = Vec::new();
    for label in ["Prn", "Sn", "Ls", "Sto", "Li", "Pog'"] {
        let Some(p) = lm.get(label).map(v3) else {
            continue;
        };
        found.push(label);
        let q = cam.project(p);
        println!("{what}: {label} at ({:.0}, {:.0}) of {w} × {h}", q[0], q[1]);
        assert!(
            q[0] >= 40.0 && q[0] <= w - 40.0 && q[1] >= 40.0 && q[1] <= h - 40.0,
            "{what}: {label} at {q:?}: not 40 px inside the {w} × {h} picture"
        );
        // Its label on the picture, whole.
        let l = &r["labels"][label];
        assert_eq!(l["shown"], json!(true), "{what}: label {label} hidden");
        let b = flat(&l["box"]);
        assert!(
            b[0] >= 0.0 && b[0] + b[2] <= w && b[1] >= 0.0 && b[1] + b[3] <= h,
            "{what}: label {label} at {b:?} leaves the {w} × {h} picture"
        );
    }
    assert!(
        found.contains(&"Prn") && found.contains(&"Ls"),
        "{what}: no Prn or Ls ({found:?})"
    );
    // Framed on the face, not the whole head.
    let top = lm.get("G'").or(lm.get("N'")).map(v3).unwrap();
    let bottom = ["Me'", "Pog'", "Li", "Sto", "Ls"]
        .iter()
        .find_map(|l| lm.get(*l).map(v3))
        .unwrap();
    let height_px = cam.project(bottom)[1] - cam.project(top)[1];
    let height_mm = dot(sub(top, bottom), up);
    println!("{what}: the face's {height_mm:.0} mm from G'/N' down: {height_px:.0} px of {h}");
    assert!(
        height_px > 0.5 * h,
        "{what}: the face is small in its picture: {height_px:.0} px of {h}"
    );
}

#[test]
fn the_real_ct_pages_open_in_profile_with_the_nose_and_lips_inside_the_picture() {
    // Both real CTs, run by the pipeline, their own pages as they open: data-samples/real
    // (ProMED 0051, a 5 mm maxillary advancement; its clinical frame the CT's axes) and
    // data-samples/real-mandible (VTK's headsq, a 5 mm BSSO advancement; Frankfort, the head
    // pitched about 11° in the CT).
    common::real_ct();
    common::real_mandible_ct();
    for (sample, shot) in [
        ("real", "clinical/real-default.png"),
        ("real-mandible", "clinical/real-mandible-default.png"),
    ] {
        let case = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../data-samples")
            .join(sample)
            .join("case.toml");
        let dir = common::kept_dir(&format!("facesim-page-{sample}"));
        let o = facesim::commands::run(&case, Some(&dir.join("out")), &Quiet).unwrap();
        let report = common::report_json(&o);
        let cf = &report["clinical_frame"];
        assert!(cf.is_object(), "{sample}: no clinical frame");
        let r = drive_clinical(&o.out_dir.join("report.html"), &json!([]), shot);
        assert_eq!(r["sliders"]["frame"], json!("clinical"));
        assert_face_framed(
            &r,
            v3(&cf["up"]),
            v3(&cf["forward"]),
            v3(&cf["left"]),
            &format!("data-samples/{sample}"),
        );
    }
}

// ---- the tissue sliders: the reduced model re-solved in the page ----

/// The page's online solve (web/src/tissue.js) against Rust's `OnlineForm::solve` for the same
/// forms and θ: synthetic forms (SPD and semi-definite terms, ragged Riesz columns, the
/// round-off floor), through node's test runner with the analytic cases of tissue.test.mjs.
#[test]
fn the_page_solves_the_reduced_model_as_the_rust_online_form_does() {
    use facesim::reduced::{OnlineForm, OutputBound};
    // A small deterministic generator (SplitMix64), values in [-1, 1).
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut rand = move || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    };
    let mut cases = Vec::new();
    for (n, q) in [(1_usize, 2_usize), (3, 4), (6, 8), (12, 8)] {
        // M_q = B Bᵀ (rank n − 1 for odd q: semi-definite) + (q == 0) I.
        let matrices: Vec<Vec<f64>> = (0..q)
            .map(|k| {
                let rank = if k % 2 == 1 {
                    n.saturating_sub(1).max(1)
                } else {
                    n
                };
                gram(&mut rand, n, rank, k == 0)
            })
            .collect();
        let loads: Vec<Vec<f64>> = (0..q).map(|_| (0..n).map(|_| rand()).collect()).collect();
        let (riesz, riesz_norms) = ragged_riesz(&mut rand, q * (n + 1));
        let form = OnlineForm {
            theta_bar: (0..q).map(|_| 1.0 + rand().abs() * 10.0).collect(),
            matrices,
            loads,
            riesz,
            riesz_norms,
            unknowns: 50_000,
        };
        assert!(form.consistent());
        for s in 0..4 {
            let theta: Vec<f64> = if s == 0 {
                form.theta_bar.clone()
            } else {
                form.theta_bar
                    .iter()
                    .map(|t| t * (1.0 + 0.9 * rand()).max(0.05))
                    .collect()
            };
            let o = form.solve(&theta).unwrap();
            // An output of 3 rows over the Riesz coordinates, small enough that the split
            // (not g Δ) is the bound.
            let output = OutputBound {
                gain: 1.0 + rand().abs(),
                factor: (0..3 * o.coordinates.len()).map(|_| 0.1 * rand()).collect(),
                rows: 3,
            };
            let dual = random_dual(&mut rand, q, n);
            let answer = dual.answer(&theta, &o).unwrap();
            cases.push(json!({
                "dual": dual, "dual_correction": answer.correction, "dual_bound": answer.bound,
                "form": form, "theta": theta,
                "coefficients": o.coefficients.iter().collect::<Vec<_>>(),
                "residual": o.residual, "alpha": o.alpha, "gamma": o.gamma,
                "energy_bound": o.energy_bound, "energy_norm": o.energy_norm,
                "output": output, "output_bound": output.bound(&o),
                "output_plain": output.gain * o.energy_bound,
            }));
        }
    }
    let dir = common::kept_dir("facesim-page-tissue-fixture");
    let fixture = dir.join("online.json");
    std::fs::write(&fixture, json!({ "cases": cases }).to_string()).unwrap();
    let run = Command::new("node")
        .current_dir(web_dir())
        .args(["--test", "test/tissue.test.mjs"])
        .env("FACESIM_TISSUE_FIXTURE", &fixture)
        .output()
        .expect("node missing: run scripts/test-setup.sh");
    let out = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success() && out.contains("# fail 0") && out.contains("# skipped 0"),
        "tissue.test.mjs: {out}{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

/// B Bᵀ (n × n, row-major) for a random n × `rank` matrix B, plus the identity if `identity`.
fn gram(rand: &mut impl FnMut() -> f64, n: usize, rank: usize, identity: bool) -> Vec<f64> {
    let b: Vec<f64> = (0..n * rank).map(|_| rand()).collect();
    let mut m = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            m[i * n + j] = (0..rank).map(|r| b[i * rank + r] * b[j * rank + r]).sum();
        }
        if identity {
            m[i * n + i] += 1.0;
        }
    }
    m
}

/// `cols` random Riesz columns of coordinates, column j of j + 1 of them (ragged, as stored),
/// and norms above their coordinates' (a representer's norm includes the round-off).
fn ragged_riesz(rand: &mut impl FnMut() -> f64, cols: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
    let riesz: Vec<Vec<f64>> = (0..cols)
        .map(|j| (0..(j + 1).min(cols)).map(|_| rand()).collect())
        .collect();
    let norms = riesz
        .iter()
        .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt() * 1.5)
        .collect();
    (riesz, norms)
}

/// A landmark's dual form for a primal of `q` terms and `n` vectors: m = 4 dual vectors, three
/// components, SPD terms (the first with the identity added), ragged Riesz columns.
fn random_dual(
    rand: &mut impl FnMut() -> f64,
    q: usize,
    n: usize,
) -> facesim::reduced::dual::DualForm {
    let (m, comps) = (4, 3);
    let matrices = (0..q).map(|k| gram(rand, m, m, k == 0)).collect();
    let mut vectors = |count: usize, len: usize| -> Vec<Vec<f64>> {
        (0..count)
            .map(|_| (0..len).map(|_| rand()).collect())
            .collect()
    };
    let outputs = vectors(comps, m);
    let loads = vectors(q, m);
    let coupling = vectors(q, m * n);
    let (riesz, riesz_norms) = ragged_riesz(rand, comps + q * m);
    let d = facesim::reduced::dual::DualForm {
        matrices,
        outputs,
        loads,
        coupling,
        riesz,
        riesz_norms,
        unknowns: 50_000,
        greedy: Vec::new(),
    };
    assert!(d.consistent(q, n));
    d
}

/// The first sample (the jaws phantom, BSSO 5 mm) meshed coarse, sampled by the reduced method,
/// so that its page carries the tissue sliders; the page against the run's reduced_model.bin
/// solved in Rust.
#[test]
fn tissue_sliders_resolve_the_reduced_model_live_within_its_bound() {
    use facesim::case::uncertainty::Method;
    use facesim::model::reduced::file;
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws");
    let (mut case, _) = Case::load(&sample).unwrap();
    // As crates/facesim/tests/library/reduced.rs: coarser than the default, to keep the test short.
    case.tet.skin_size_mm = 8.0;
    case.tet.deep_size_mm = 16.0;
    case.tet.error_estimate = false;
    case.uncertainty.samples = 8;
    case.uncertainty.method = Method::Reduced;
    // One round of the landmarks' duals: the page bounds the face's value at each landmark by
    // the correction plus the primal–dual bound where that is smaller.
    case.uncertainty.landmark_dual_rounds = 1;
    let dir = common::out_dir("facesim-page-tissue");
    let o = facesim::commands::run_case(case.clone(), &dir, &Quiet).unwrap();
    let html = o.out_dir.join("report.html");
    assert_self_contained(&std::fs::read_to_string(&html).unwrap());
    let stored = file::read(&o.out_dir.join(file::FILE_NAME), &o.skin.vertices).unwrap();
    let run_model = stored
        .models
        .iter()
        .find(|m| m.sliding == stored.sliding)
        .unwrap();
    // Inside the default box (ν 0.45–0.49, muscle/fat 1.7–15, skin/fat 5–30), then outside it.
    let inside = json!({"poisson": 0.455, "muscle_fat": 12.0, "skin_fat": 6.0});
    let steps = json!({
        "tissues": [inside, {"muscle_fat": 2.0}, {"poisson": 0.30}],
        "plan": {o.report.parameters.as_ref().unwrap().osteotomy[0].name.clone(): {"translate": [0.0, -8.0, 1.0], "rotate_deg": [0.0, 0.0, 0.0]}},
    });
    let steps_file = dir.join("tissue-steps.json");
    std::fs::write(&steps_file, steps.to_string()).unwrap();
    let out = dir.join("tissue.json");
    let shot = Path::new(env!("CARGO_TARGET_TMPDIR")).join("../test-artefacts/report-tissue.png");
    let started = std::time::Instant::now();
    let run = Command::new("node")
        .current_dir(web_dir())
        .arg("test/tissue_page.mjs")
        .args([&html, &steps_file, &out, &shot])
        .arg("3")
        .output()
        .expect("node missing: run scripts/test-setup.sh");
    assert!(
        run.status.success(),
        "tissue_page.mjs failed: {}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    println!("browser part: {:.1} s", started.elapsed().as_secs_f64());
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    for k in ["console_errors", "page_errors", "outside_requests"] {
        assert_eq!(r[k], json!([]), "{k}");
    }
    assert_eq!(r["info"]["tissue"], json!(true));
    // At the start: the run's tissues, the run's face.
    let t0 = &r["initial"]["tissue"];
    assert_eq!(t0["nominal"], json!(true), "{t0}");
    assert!(max_diff(&flat(&r["initial"]["vertices"]), &o.face_post.vertices) < 1e-4);

    // The same materials in Rust: the run's case with the sampled parameters (Draw::apply).
    let with = |nu: f64, muscle_fat: f64, skin_fat: f64| {
        let mut c = case.clone();
        let fat = c.tet.fat_dark.youngs_kpa;
        for m in c.tet.tissues_mut() {
            m.poisson = nu;
        }
        c.tet.muscle.youngs_kpa = muscle_fat * fat;
        c.tet.skin.youngs_kpa = skin_fat * fat;
        c
    };
    let at_nominal = run_model.form.solve(&run_model.form.theta_bar).unwrap();
    let nominal_face = run_model
        .face
        .all(&at_nominal.coefficients.iter().copied().collect::<Vec<_>>());
    for (k, (nu, mf, sf)) in [(0.455, 12.0, 6.0), (0.455, 2.0, 6.0)]
        .into_iter()
        .enumerate()
    {
        let step = &r["steps"][k];
        assert_eq!(step["error"], json!(null));
        let t = &step["tissue"];
        assert_eq!(t["nominal"], json!(false), "{t}");
        assert_eq!(t["outside"], json!(null), "{t}");
        let c = with(nu, mf, sf);
        let theta = run_model.theta(&c.tet);
        let rust = run_model.form.solve(&theta).unwrap();
        // θ, the coefficients and the bound as Rust's, to round-off.
        let page_theta = flat(&t["theta"]);
        for (a, b) in page_theta.iter().zip(&theta) {
            assert!((a - b).abs() <= 1e-12 * b.abs(), "θ {a} vs {b}");
        }
        let coef = flat(&t["coefficients"]);
        let scale = rust.coefficients.amax();
        for (a, b) in coef.iter().zip(rust.coefficients.iter()) {
            assert!((a - b).abs() <= 1e-9 * scale, "c {a} vs {b}");
        }
        let eb = t["energy_bound"].as_f64().unwrap();
        assert!(
            (eb - rust.energy_bound).abs() <= 1e-8 * rust.energy_bound,
            "Δ {eb} vs {}",
            rust.energy_bound
        );
        let face_bound =
            run_model.face_bound.bound(&rust) + run_model.face_bound.bound(&at_nominal);
        let fb = t["face_bound_mm"].as_f64().unwrap();
        assert!(
            (fb - face_bound).abs() <= 1e-8 * face_bound,
            "face bound {fb} vs {face_bound}"
        );
        // Each landmark's bound on the face's value, at θ and at θ̄ (as sets: the page keys
        // them by label).
        let face_value = |k: usize, th: &[f64], at: &facesim::reduced::Online| {
            let plain = run_model.output_bounds[k].bound(at);
            let a = run_model.duals[k].answer(th, at).unwrap();
            let len = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            plain.min(len(&a.correction) + len(&a.bound))
        };
        let mut expected: Vec<f64> = (0..run_model.output_bounds.len())
            .map(|k| {
                face_value(k, &theta, &rust) + face_value(k, &run_model.form.theta_bar, &at_nominal)
            })
            .collect();
        let mut page: Vec<f64> = t["landmark_bounds_mm"]
            .as_object()
            .unwrap()
            .values()
            .map(|v| v.as_f64().unwrap())
            .collect();
        expected.sort_by(f64::total_cmp);
        page.sort_by(f64::total_cmp);
        assert_eq!(page.len(), expected.len(), "{t}");
        for (a, b) in page.iter().zip(&expected) {
            assert!((a - b).abs() <= 1e-8 * b.abs(), "landmark bound {a} vs {b}");
        }
        let used_dual = (0..run_model.output_bounds.len())
            .any(|k| face_value(k, &theta, &rust) < run_model.output_bounds[k].bound(&rust));
        println!("tissue step {k}: landmark bounds {page:?} (a dual bound used: {used_dual})");
        let text = t["text"].as_str().unwrap();
        assert!(
            text.contains(&format!("{face_bound:.2} mm")) && text.contains("Prn within"),
            "{text}"
        );
        // The face: the run's face plus the reduced model's change from θ̄ to θ (float32 fields).
        let reduced = run_model.face(&c).unwrap();
        let expected: Vec<[f64; 3]> = o
            .face_post
            .vertices
            .iter()
            .zip(reduced.displacement.iter().zip(&nominal_face))
            .map(|(p, (d, d0))| [0, 1, 2].map(|i| p[i] + d[i] - d0[i]))
            .collect();
        let got = flat(&step["vertices"]);
        let d = max_diff(&got, &expected);
        let moved = max_diff(&got, &o.face_post.vertices);
        println!(
            "tissue step {k}: face vs Rust {d:.2e} mm, moved {moved:.3} mm, bound {face_bound:.2} mm"
        );
        assert!(
            d < 1e-4,
            "step {k}: the page's face is {d} mm off Rust's reduced face"
        );
        assert!(
            moved > 0.01,
            "step {k}: the tissue change hardly moved the face ({moved} mm)"
        );
    }
    // ν = 0.30 is outside the trained box: not answered, said so, the run's face shown.
    let out_step = &r["steps"][2];
    let t = &out_step["tissue"];
    assert!(
        t["outside"]
            .as_str()
            .is_some_and(|s| s.contains("outside the trained range")),
        "{t}"
    );
    assert!(
        t["notice"]
            .as_str()
            .is_some_and(|s| s.contains("not answered")),
        "{t}"
    );
    assert_eq!(t["face_bound_mm"], json!(null));
    assert!(max_diff(&flat(&out_step["vertices"]), &o.face_post.vertices) < 1e-4);

    // The keyboard: the slider is a named, focusable range input; ArrowRight moves it and the
    // face follows on the next frame.
    let kb = &r["keyboard"];
    let controls = kb["controls"].as_array().unwrap();
    assert!(
        controls
            .iter()
            .all(|c| c["tab"].as_i64().unwrap() >= 0 && !c["name"].as_str().unwrap().is_empty()),
        "{controls:?}"
    );
    assert!(
        controls.iter().filter(|c| c["type"] == "range").count() >= 3,
        "{controls:?}"
    );
    assert_eq!(kb["focused"], json!(true));
    assert_ne!(kb["before"], kb["after"], "{kb}");
    assert_ne!(kb["text_before"], kb["text_after"]);
    assert_eq!(kb["tissue"]["nominal"], json!(false));
    assert!(max_diff(&flat(&kb["vertices"]), &o.face_post.vertices) > 0.01);
    // Sliding off: the other model, when the mesh slides.
    if stored.sliding_matters && stored.models.len() == 2 {
        let s = &r["sliding"];
        assert_eq!(s["sliding"], json!(!stored.sliding), "{s}");
        assert!(s["face_bound_mm"].as_f64().unwrap() > 0.0);
    }
    // "the run's tissues" restores the run's face.
    assert_eq!(r["reset"]["tissue"]["nominal"], json!(true));
    assert!(max_diff(&flat(&r["reset"]["vertices"]), &o.face_post.vertices) < 1e-4);
    // Another plan: the tissue change is said to be the run's plan's.
    let op = &r["other_plan"];
    assert_eq!(op["plan_differs"], json!(true));
    assert!(
        op["plan_note"]
            .as_str()
            .is_some_and(|s| s.contains("not certified")),
        "{op}"
    );
    // The picture's text alternative names the tissues shown.
    let aria = r["aria"].as_str().unwrap();
    assert!(
        aria.contains(
            "tissues re-solved by the reduced model: ν 0.455, muscle/fat 12.0, skin/fat 6.00"
        ),
        "{aria}"
    );
    // The update rate of a tissue slider drag (docs/guide/report-page.md): reported; a floor catches
    // a page that re-solves or redraws far too much per update.
    let rate = r["rate"]["per_s"].as_f64().unwrap();
    println!(
        "tissue slider: {rate:.1} updates/s ({} face vertices, canvas {})",
        o.skin.vertices.len(),
        r["rate"]["canvas"]
    );
    assert!(rate > 5.0, "tissue slider: {rate} updates/s");
}

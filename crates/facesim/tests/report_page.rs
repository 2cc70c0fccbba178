//! report.html in a real browser (docs/report-page.md): Debian's chromium, driven by
//! puppeteer-core from web/ (web/test/page.test.mjs), opens the page from disk. Checked: no
//! console or page errors, no request leaving the file, a drawn canvas, and `setPlan` → the face
//! against two independent paths: the rigid motion of the osteotomy module (an analytic basis), and
//! full runs of the linear volumetric model. Screenshots go to target/test-artefacts/.

#[path = "common/browser.rs"]
mod browser;
mod common;

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
    let mut rest = lower.as_str();
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
                {"soft": "Prn", "axis": "horizontal", "segment": "maxilla", "hard": "A / U1",
                 "hard_at": "", "soft_mm": null, "hard_mm": null, "predicted": null,
                 "low": 0.17, "high": 0.36, "inside": null, "source": "another",
                 "missing": "Prn not found"}
            ]
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
    // The plan against the clinic: a row outside its range marked so, one not measured.
    let clinic: Vec<(String, String)> = r["clinic"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| (x[0].as_str().unwrap().into(), x[1].as_str().unwrap().into()))
        .collect();
    assert_eq!(clinic.len(), 3, "{clinic:?}");
    assert!(
        clinic[1].0 == "outside"
            && clinic[1].1.contains("0.96")
            && clinic[1].1.contains("0.50–0.90"),
        "{clinic:?}"
    );
    assert!(
        clinic[2].0 == "unmeasured" && clinic[2].1.contains("not measured"),
        "{clinic:?}"
    );
    // Before any plan: the run's face_post (float32 in the page).
    assert!(max_diff(&flat(&r["vertices_initial"]), &face_post) < 1e-4);
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

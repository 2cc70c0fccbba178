//! `facesim-lab study --quick` end to end, and exact invariants of the face baselines.

use facesim::case::{Case, Osteotomy, Region};
use facesim::pipeline::prepare_case;
use facesim_lab::study::{mass_spring, volumetric};
use serde_json::Value;
use std::path::Path;

// Counts heap bytes for the peak-memory column, as the facesim binary does.
#[global_allocator]
static ALLOC: facesim::meter::CountingAllocator = facesim::meter::CountingAllocator;

fn phantom_case() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/phantom")
}

#[test]
fn quick_study_writes_tables_and_charts_and_reproduces_the_papers_findings() {
    let out = tempfile::tempdir().unwrap();
    let dir = out.path().join("study");
    // What `facesim-lab study --quick DIR --case data-samples/phantom` runs.
    facesim_lab::study::run(&dir, true, &[phantom_case()], &facesim::observe::Quiet).unwrap();
    for f in [
        "results.json",
        "benchmarks.csv",
        "stability.csv",
        "face.csv",
        "summary.md",
        "error_over_time_block_mp1.svg",
        "error_over_time_block_mp1.png",
        "error_over_time_block_mp2.png",
        "error_over_time_rod_mp3.png",
        "accuracy_vs_time_phantom_mandible_advance_6mm.svg",
        "accuracy_vs_time_phantom_mandible_advance_6mm.png",
        "accuracy_vs_unknowns_phantom_mandible_advance_6mm.png",
        "regions_phantom_mandible_advance_6mm.png",
        "calibration_phantom_mandible_advance_6mm.png",
    ] {
        let p = dir.join(f);
        assert!(
            p.is_file() && std::fs::metadata(&p).unwrap().len() > 100,
            "{f} missing or empty"
        );
    }
    // No temporary files left behind.
    for e in std::fs::read_dir(&dir).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().to_string();
        assert!(!name.starts_with(".facesim-tmp"), "{name} left behind");
    }
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    println!("study wall time {:.1} s", s["wall_s"].as_f64().unwrap());

    // Findings (Alterovitz & Goldberg): every bounded integrator settles to the static state …
    let f = &s["findings"];
    let worst = f["worst_final_vs_static"].as_f64().unwrap();
    assert!(worst < 1e-3, "final states {worst} from static");
    // … explicit consistent < explicit lumped < quasi-static in all three error measures (MP1) …
    let ord = f["orderings"].as_array().unwrap();
    let mp1: Vec<&Value> = ord
        .iter()
        .filter(|o| o["benchmark"] == "block MP1")
        .collect();
    assert_eq!(
        mp1.len(),
        3,
        "energy, surface and interior orderings for MP1"
    );
    for o in &mp1 {
        println!("{o}");
        assert_eq!(o["holds"], true, "{o}");
    }
    // … and MP1 and MP2 reach different steady states.
    let d = f["mp1_vs_mp2_steady"].as_f64().unwrap();
    assert!(d > 0.1, "MP1 vs MP2 steady states differ by only {d}");

    // MP2 explicit at h = 1/30 s diverges and is reported, with no NaN in the tables.
    let mp2 = s["benchmarks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|b| b["name"] == "block MP2")
        .unwrap();
    for sr in mp2["series"].as_array().unwrap() {
        let name = sr["integrator"].as_str().unwrap();
        let div = sr["diverged"].as_str();
        if name.starts_with("Explicit") {
            assert!(
                div.is_some_and(|d| d.starts_with("diverged at step")),
                "{name}: {div:?}"
            );
        } else {
            assert!(div.is_none(), "{name} diverged: {div:?}");
        }
        for k in ["energy", "surface", "interior"] {
            assert!(
                sr[k]
                    .as_array()
                    .unwrap()
                    .iter()
                    .all(|v| v.as_f64().is_some())
            );
        }
    }
    let csv = std::fs::read_to_string(dir.join("benchmarks.csv")).unwrap();
    assert!(!csv.to_lowercase().contains("nan") && !csv.contains("inf"));

    // Stability: bounded at 0.9 h_crit, diverged at 1.1 h_crit, for both mass matrices.
    for row in s["stability"].as_array().unwrap() {
        assert!(
            row["at_0_9"].as_str().unwrap().starts_with("bounded"),
            "{row}"
        );
        assert!(
            row["at_1_1"]
                .as_str()
                .unwrap()
                .starts_with("diverged at step"),
            "{row}"
        );
        if row["problem"].as_str().unwrap().contains("MP2") {
            // MP2's limit is far below the benchmark's step: explicit diverges there.
            assert!(row["h_crit"].as_f64().unwrap() < 1.0 / 30.0);
            assert!(
                row["at_benchmark_h"]
                    .as_str()
                    .unwrap()
                    .starts_with("diverged at step")
            );
        }
    }

    // Face rows: one reference at distance 0, the product's volumetric model; every other row
    // has distances or says why not.
    let face = s["face"].as_array().unwrap();
    let refs: Vec<&Value> = face.iter().filter(|r| r["is_reference"] == true).collect();
    assert_eq!(refs.len(), 1);
    assert_eq!(refs[0]["distance"]["max"].as_f64(), Some(0.0));
    assert_eq!(refs[0]["family"], "volumetric FEM (product)", "{}", refs[0]);
    for r in face {
        assert!(r["distance"].is_object() || r["note"].is_string(), "{r}");
        assert!(r["wall_s"].as_f64().unwrap() > 0.0);
        // The counting allocator (installed above, as in the facesim binary) measured it.
        assert!(r["peak_mb"].as_f64().is_some(), "{r}");
    }
    let families: std::collections::HashSet<&str> =
        face.iter().map(|r| r["family"].as_str().unwrap()).collect();
    for fam in [
        "volumetric FEM (product)",
        "C1 surface FEM",
        "surface mass-spring",
        "volumetric mass-spring",
        "volumetric FEM",
    ] {
        assert!(families.contains(fam), "{fam} missing");
    }
    // The volumetric model converges under refinement: its coarser linear rows have fewer
    // elements and are farther from the reference the coarser they are; the neo-Hookean row
    // exists and solved.
    let mut tets: Vec<(usize, f64)> = face
        .iter()
        .filter(|r| r["method"] == "tet linear, 4-node" && r["is_reference"] == false)
        .map(|r| {
            (
                r["elements"].as_u64().unwrap() as usize,
                r["distance"]["mean"].as_f64().unwrap(),
            )
        })
        .collect();
    tets.sort_by_key(|t| t.0);
    println!("tet linear (elements, mean distance mm): {tets:?}");
    assert!(tets.len() >= 2, "{tets:?}");
    let ref_elements = refs[0]["elements"].as_u64().unwrap() as usize;
    for w in tets.windows(2) {
        assert!(w[0].1 > w[1].1, "not converging: {tets:?}");
    }
    assert!(tets.iter().all(|t| t.0 < ref_elements));
    let neo = face
        .iter()
        .find(|r| r["method"] == "tet neo-Hookean, 4-node")
        .expect("a neo-Hookean row");
    assert!(neo["distance"]["mean"].as_f64().is_some(), "{neo}");
    // The former reference, the finest C1 equilibrium solve, is still measured: distance 0 to
    // itself, and coarser C1 meshes monotonically farther from it.
    let mut eq: Vec<(usize, f64)> = face
        .iter()
        .filter(|r| r["method"] == "C1 equilibrium")
        .filter_map(|r| {
            let tri: usize = r["resolution"]
                .as_str()?
                .split_whitespace()
                .next()?
                .parse()
                .ok()?;
            Some((tri, r["distance_c1"]["mean"].as_f64()?))
        })
        .collect();
    eq.sort_by_key(|x| x.0);
    println!("C1 equilibrium (triangles, mean distance to the finest C1 mm): {eq:?}");
    assert!(eq.len() >= 3, "{eq:?}");
    assert!(eq.last().unwrap().1 < 1e-9, "{eq:?}");
    for w in eq.windows(2) {
        assert!(w[0].1 > w[1].1, "not converging: {eq:?}");
    }
    // Regions: the phantom has no mouth, so its landmarks come from proportions; every region
    // is present with vertices, and every measured row reports each region.
    let case = &s["face_cases"][0];
    assert_eq!(case["regions"]["landmarks"]["rule"], "proportional");
    for info in case["regions"]["summary"].as_array().unwrap() {
        assert!(info["absent"].is_null(), "{info}");
        assert!(info["vertices"].as_u64().unwrap() > 20, "{info}");
    }
    for r in face.iter().filter(|r| r["distance"].is_object()) {
        let g = r["regions"].as_array().unwrap();
        assert_eq!(g.len(), 5, "{}: {g:?}", r["method"]);
        for g in g {
            let d = &g["distance"];
            assert!(d["mean"].as_f64().unwrap() <= d["max"].as_f64().unwrap() + 1e-12);
        }
    }
    // Calibration: the fitted k_c is no worse than the default; the default's evaluation is the
    // native C1 row's distance, and the calibrated row's distance is the fitted value (the same
    // figures reached by the calibration's own arithmetic and by the study's distances).
    let cal = &case["calibration"];
    let (m0, m1) = (
        cal["mean_default_mm"].as_f64().unwrap(),
        cal["mean_mm"].as_f64().unwrap(),
    );
    println!(
        "calibration: k_c {} → {} (struts {}), mean {m0:.4} → {m1:.4} mm in {} solves",
        cal["k_c_default"],
        cal["k_c"],
        cal["struts"],
        cal["evaluations"].as_array().unwrap().len()
    );
    assert!(m1 <= m0, "calibrated {m1} worse than the default {m0}");
    let native = face
        .iter()
        .filter(|r| r["method"] == "C1 equilibrium")
        .max_by_key(|r| r["unknowns"].as_u64().unwrap())
        .unwrap();
    let row_mean = |r: &Value| r["distance"]["mean"].as_f64().unwrap();
    assert!(
        (row_mean(native) - m0).abs() < 1e-6,
        "{} vs {m0}",
        row_mean(native)
    );
    let calibrated = face
        .iter()
        .find(|r| r["method"] == "C1 equilibrium, k_c calibrated here")
        .unwrap();
    assert!(
        (row_mean(calibrated) - m1).abs() < 1e-6,
        "{} vs {m1}",
        row_mean(calibrated)
    );
    // Every family is closer to the reference than predicting no change at all would be (that
    // would be the reference's own mean displacement away), and moves the skin by a comparable
    // amount.
    let moved = refs[0]["mean_displacement_mm"].as_f64().unwrap();
    assert!(moved > 0.5, "the reference hardly moves: {moved}");
    for r in face.iter().filter(|r| r["distance"].is_object()) {
        let m = r["distance"]["mean"].as_f64().unwrap();
        let own = r["mean_displacement_mm"].as_f64().unwrap();
        println!(
            "{} {}: mean distance {m:.3} mm, mean displacement {own:.3} (reference {moved:.3})",
            r["method"], r["resolution"]
        );
        assert!(
            m < moved,
            "{}: {m} mm from the reference, no better than no change",
            r["method"]
        );
        assert!(
            own > 0.2 * moved && own < 3.0 * moved,
            "{}: moves {own} mm",
            r["method"]
        );
    }
}

/// Translate the whole skull by t: every model must carry the skin along by exactly t (a rigid
/// motion stores no energy).
#[test]
fn a_rigid_translation_of_all_bone_translates_the_skin_in_every_baseline() {
    let (mut case, _) = Case::load(&phantom_case()).unwrap();
    let t = [1.5, -2.0, 0.5];
    case.osteotomy = vec![Osteotomy {
        name: "everything".into(),
        region: Region::Box {
            min: [-1e4; 3],
            max: [1e4; 3],
        },
        translate: t,
        rotate_deg: [0.0; 3],
        pivot: [0.0; 3],
    }];
    case.surface.movable = None;
    // The surface baselines need the C1 model's springs.
    case.solve.model = facesim::case::SolveModel::Equilibrium;
    let scene = prepare_case(&case, &facesim::observe::Quiet).unwrap();
    let tn = (t.iter().map(|x| x * x).sum::<f64>()).sqrt();
    for kind in [volumetric::Kind::Lattice, volumetric::Kind::Tetrahedra] {
        let p = volumetric::predict(
            &scene.vol,
            &scene.seg,
            &case.tissue.stiffness,
            &scene.model.plan,
            &scene.face.skin.vertices,
            volumetric::Options {
                spacing: 6.0,
                max_depth_mm: 20.0,
                kind,
                nu: 0.45,
            },
        )
        .unwrap();
        let worst = p
            .displacement
            .iter()
            .map(|d| (0..3).map(|c| (d[c] - t[c]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        println!(
            "{kind:?}: {} unknowns, worst |d − t| = {worst:.2e} mm",
            p.unknowns
        );
        assert!(worst < 1e-6 * tn, "{kind:?}: {worst}");
    }
    let rigid = vec![false; scene.face.skin.vertices.len()];
    let r = mass_spring::relax(
        &scene.face.skin,
        &scene.model.springs,
        &scene.model.plan,
        &rigid,
        case.surface.alpha,
        case.surface.beta,
        case.solve.k_c,
        1e-7,
        200_000,
    );
    let worst = r
        .positions
        .iter()
        .zip(&scene.face.skin.vertices)
        .map(|(p, q)| {
            (0..3)
                .map(|c| (p[c] - q[c] - t[c]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    println!(
        "mass-spring: {} steps, residual {:.1e}, worst |d − t| = {worst:.2e} mm",
        r.iterations, r.residual
    );
    assert!(r.converged);
    assert!(worst < 1e-2 * tn, "{worst}");
}

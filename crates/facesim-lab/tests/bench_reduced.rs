//! `facesim-lab bench reduced --quick` (docs/lab/performance.md) through the real command on
//! the first sample (the jaws phantom, coarse mesh): it writes bench_reduced.json and .md, and
//! what the JSON says is consistent — every certified bound at least the true error it bounds,
//! positive times, the sample counts asked for, each band run by the method asked for, and the
//! ratios equal to the quotients of the times they are made of.

use serde_json::Value;
use std::path::Path;
use std::process::Command;

struct Ran {
    code: i32,
    stdout: String,
    stderr: String,
}

/// `facesim-lab ARGS`; its children are the `facesim` command built beside it (a workspace
/// `cargo test` builds both).
fn facesim_lab(args: &[&str]) -> Ran {
    let out = Command::new(env!("CARGO_BIN_EXE_facesim-lab"))
        .args(args)
        .output()
        .unwrap();
    Ran {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-300)
}

#[test]
fn bench_reduced_quick_writes_a_consistent_report() {
    let jaws = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws");
    let out = tempfile::tempdir().unwrap();
    let t = std::time::Instant::now();
    let r = facesim_lab(&[
        "bench",
        "reduced",
        "--case",
        jaws.to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
        "--quick",
    ]);
    eprintln!("bench reduced --quick: {:.0} s", t.elapsed().as_secs_f64());
    assert_eq!(r.code, 0, "stderr: {}\nstdout: {}", r.stderr, r.stdout);
    assert!(r.stdout.contains("| target |"), "{}", r.stdout);
    let md = std::fs::read_to_string(out.path().join("bench_reduced.md")).unwrap();
    assert!(md.contains("offline ≤ 15 full solves"), "{md}");
    let b: Value =
        serde_json::from_slice(&std::fs::read(out.path().join("bench_reduced.json")).unwrap())
            .unwrap();
    assert_eq!(b["quick"], true);
    // No temporary files or child-run directories left behind.
    let left: Vec<_> = std::fs::read_dir(out.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let mut sorted = left.clone();
    sorted.sort();
    assert_eq!(
        sorted,
        ["bench_reduced.json", "bench_reduced.md"],
        "{left:?}"
    );

    // The machine and the model.
    let m = &b["machine"];
    assert!(m["cores"].as_u64().unwrap() >= 1 && !m["cpu"].as_str().unwrap().is_empty());
    assert!(f(&m["load_start"][0]) >= 0.0, "{m}");
    let model = &b["model"];
    assert!(model["face_vertices"].as_u64().unwrap() > 1000, "{model}");
    assert!(model["free_dofs"].as_u64().unwrap() > 0, "{model}");

    // One full solve, offline.
    let full = f(&b["full_solve"]["median_s"]);
    assert!(full > 0.0);
    assert_eq!(b["full_solve"]["resolve_s"].as_array().unwrap().len(), 3);
    assert!(f(&b["full_solve"]["run_solve_stage_s"]) > 0.0);
    let off = &b["offline"];
    let models = off["models"].as_array().unwrap();
    let states = if model["sliding_matters"] == true {
        2
    } else {
        1
    };
    assert_eq!(models.len(), states, "{off}");
    // The sliding states build side by side: the wall time is at least the longest build's
    // and at most their sum.
    let builds: Vec<f64> = models.iter().map(|x| f(&x["offline_seconds"])).collect();
    assert!(
        f(&off["wall_s"]) >= builds.iter().copied().fold(0.0, f64::max) * 0.99,
        "{off}"
    );
    assert!(
        f(&off["wall_s"]) <= builds.iter().sum::<f64>() * 1.05 + 0.5,
        "{off}"
    );
    assert!(
        close(f(&off["full_solves"]), f(&off["wall_s"]) / full),
        "{off}"
    );
    let factorisations: u64 = models
        .iter()
        .map(|x| x["full_factorisations"].as_u64().unwrap())
        .sum();
    assert_eq!(off["full_factorisations"].as_u64().unwrap(), factorisations);
    for x in models {
        assert!(x["basis_size"].as_u64().unwrap() >= 1, "{x}");
        assert!(x["full_factorisations"].as_u64().unwrap() >= 1, "{x}");
        assert!(f(&x["face_gain"]) > 0.0, "{x}");
    }
    // 128 draws and the corners of the box of the 4 sampled parameters.
    assert_eq!(off["training_points"], 128 + 16);

    // Online: positive medians over the θ asked for; the face costs at least the coefficients.
    let on = &b["online"];
    assert_eq!(on["samples"], 1000);
    for k in ["solve_us", "face_us", "memory_pass_us"] {
        assert!(f(&on[k]) > 0.0, "{k}: {on}");
    }
    assert!(f(&on["solve_p90_us"]) >= f(&on["solve_us"]), "{on}");
    assert!(f(&on["face_us"]) >= f(&on["solve_us"]), "{on}");
    assert!(close(
        f(&on["face_over_memory_pass"]),
        f(&on["face_us"]) / f(&on["memory_pass_us"])
    ));
    // Some of the face moves, not more than all of it.
    let moving = on["moving_vertices"].as_u64().unwrap();
    assert!(
        moving > 0 && moving <= b["model"]["face_vertices"].as_u64().unwrap(),
        "{on}"
    );
    assert!(f(&on["largest_face_bound_mm"]) >= f(&on["median_face_bound_mm"]));
    assert!(f(&on["median_face_bound_mm"]) > 0.0, "{on}");

    // The three runs: samples and methods as asked, positive times and memory.
    let sizes = &b["sizes"];
    let band = &b["band"];
    let fb = &b["full_band"];
    let plain = &b["plain"];
    assert_eq!(band["samples"], sizes["band_samples"]);
    assert_eq!(band["samples"], 1000);
    assert_eq!(band["method"], "reduced");
    assert_eq!(fb["samples"], sizes["full_band_samples"]);
    assert_eq!(fb["method"], "full");
    assert!(fb["solves"].as_u64().unwrap() >= 1, "{fb}");
    assert_eq!(plain["samples"], 0);
    for r in [band, fb, plain] {
        assert!(f(&r["wall_s"]) > 0.0 && f(&r["total_s"]) > 0.0, "{r}");
        assert!(f(&r["total_s"]) <= f(&r["wall_s"]), "{r}");
        assert!(f(&r["max_rss_mb"]) > 10.0, "{r}");
        assert!(f(&r["solve_stage_s"]) > 0.0, "{r}");
    }
    assert!(
        f(&band["uncertainty_s"]) > f(&band["reduced_build_s"]),
        "{band}"
    );
    assert!(f(&band["largest_bound_mm"]) > 0.0, "{band}");
    assert!(close(
        f(&b["band_run_over_full_run"]),
        f(&band["wall_s"]) / f(&plain["wall_s"])
    ));
    // The same band from the band run's stored models (`facesim replan` with [uncertainty]):
    // the same samples and bound, no build, and less memory than the run that built them.
    let stored = &b["stored_band"];
    assert_eq!(stored["samples"], band["samples"], "{stored}");
    assert_eq!(stored["method"], "reduced", "{stored}");
    assert_eq!(
        stored["largest_bound_mm"], band["largest_bound_mm"],
        "{stored}"
    );
    assert_eq!(stored["reduced_build_s"], 0.0, "{stored}");
    assert!(
        f(&stored["uncertainty_s"]) > 0.0 && f(&stored["uncertainty_s"]) <= f(&stored["wall_s"]),
        "{stored}"
    );
    assert!(
        f(&stored["max_rss_mb"]) > 1.0 && f(&stored["max_rss_mb"]) < f(&band["max_rss_mb"]),
        "{stored} {band}"
    );
    assert!(close(
        f(&b["stored_band_over_full_run"]),
        f(&stored["wall_s"]) / f(&plain["wall_s"])
    ));
    let band_target = &b["targets"][3];
    assert_eq!(
        band_target["met"],
        f(&stored["wall_s"]) < f(&plain["wall_s"]),
        "{band_target}"
    );

    // The error: at every θ the bound holds the Euclidean error, which holds the worst vertex.
    let errors = b["errors"].as_array().unwrap();
    assert_eq!(errors.len(), 2);
    for e in errors {
        let (max, l2, bound) = (
            f(&e["max_vertex_mm"]),
            f(&e["euclidean_mm"]),
            f(&e["bound_mm"]),
        );
        assert!(max > 0.0 && max <= l2 && l2 <= bound, "{e}");
        assert!(close(f(&e["effectivity"]), bound / l2), "{e}");
        assert!(
            f(&e["max_displacement_mm"]) > 1.0,
            "the jaws advance moves the face: {e}"
        );
        assert!(f(&e["full_solve_s"]) > 0.0, "{e}");
    }

    // The targets, each with its verdict.
    let targets = b["targets"].as_array().unwrap();
    assert_eq!(targets.len(), 5);
    let offline = &targets[0];
    assert_eq!(offline["met"], f(&off["full_solves"]) <= 15.0, "{offline}");
}

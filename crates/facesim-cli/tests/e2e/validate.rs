//! `facesim validate` through the real binary: one coarse phantom and one
//! surgery, its ratios recomputed from the run's own report.json and its ranges held against
//! docs/guide/validation.md's table; a Le Fort I's region holding the whole nose; the real headsq's
//! BSSO advance against the published chin ratio; the tissue the Le Fort I's and the
//! genioplasty's approaches raise; bad input as one line.

use crate::cli;
use crate::common;

use cli::{CliResult, assert_clean_failure, facesim, read_csv};
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// docs/guide/validation.md's published table: (surgery, soft) → (low, high).
fn documented_ranges() -> HashMap<(String, String), (f64, f64)> {
    let text = std::fs::read_to_string(root().join("docs/guide/validation.md")).unwrap();
    // The table under "The published ratios", not the results' tables above it.
    let table = text
        .split_once("## The published ratios")
        .expect("docs/guide/validation.md has no \"The published ratios\"")
        .1;
    let mut out = HashMap::new();
    for line in table.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let keys = [
            "lefort-advance",
            "lefort-impaction",
            "lefort-setback",
            "bsso-advance",
            "bsso-setback",
            "genioplasty",
            "bimax",
        ];
        if cells.len() < 8 || !keys.contains(&cells[1]) {
            continue;
        }
        // A range "lo–hi", or one published value "x" (lo = hi = x).
        let (lo, hi) = cells[5].split_once('–').unwrap_or((cells[5], cells[5]));
        if let (Ok(lo), Ok(hi)) = (lo.parse::<f64>(), hi.parse::<f64>()) {
            out.insert((cells[1].to_string(), cells[2].to_string()), (lo, hi));
        }
    }
    assert_eq!(out.len(), 23, "docs/guide/validation.md's table: {out:?}");
    out
}

fn vec3(v: &Value) -> Option<[f64; 3]> {
    let a = v.as_array()?;
    Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?])
}

fn num(s: &str) -> Option<f64> {
    s.parse().ok()
}

/// Each measured row's ratio from the run's report.json alone: the landmark's pre/post and the
/// segment's translation in `parameters.osteotomy` (ratio = Δ · t / |t|²).
fn recompute(run: &Value, row: &HashMap<String, String>) -> f64 {
    let seg = &row["segment"];
    let t = run["parameters"]["osteotomy"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["name"].as_str() == Some(seg))
        .and_then(|o| vec3(&o["translate"]))
        .unwrap();
    let lm = &run["landmarks"][row["landmark"].as_str()];
    let (a, b) = (vec3(&lm["pre"]).unwrap(), vec3(&lm["post"]).unwrap());
    let t2: f64 = t.iter().map(|x| x * x).sum();
    (0..3).map(|k| (b[k] - a[k]) * t[k]).sum::<f64>() / t2
}

/// `facesim validate --out DIR/v --samples data-samples ARGS` into a kept directory named `dir`;
/// the output directory and what the command printed, after a successful run. Without bands
/// (`--band-samples 0`) unless ARGS ask for them: the band's reduced model is most of a run's
/// time, and one test checks the bands.
fn validate_into(dir: &str, args: &[&str]) -> (PathBuf, CliResult) {
    let out = common::kept_dir(dir).join("v");
    let samples = root().join("data-samples");
    let mut all = vec![
        "validate",
        "--out",
        out.to_str().unwrap(),
        "--samples",
        samples.to_str().unwrap(),
    ];
    if !args.contains(&"--band-samples") {
        all.extend_from_slice(&["--band-samples", "0"]);
    }
    all.extend_from_slice(args);
    let r = facesim(&all);
    assert_eq!(r.code, 0, "facesim validate failed: {}", r.stderr);
    (out, r)
}

/// `facesim validate` of one coarse phantom (3 mm voxels) and one surgery, with `extra`
/// arguments, into a kept directory named `dir`; the output directory, after a successful run.
fn validate_one_phantom(dir: &str, surgery: &str, extra: &[&str]) -> PathBuf {
    let mut args = vec![
        "--case",
        "phantom",
        "--phantoms",
        "1",
        "--phantom-spacing",
        "3",
        "--surgery",
        surgery,
    ];
    args.extend_from_slice(extra);
    validate_into(dir, &args).0
}

/// The coarse phantom's Le Fort I advance with the defaults, validated once for the tests that
/// read it (the nose in the region, the hollow nose's passages).
fn phantom_le_fort_advance() -> &'static Path {
    static OUT: OnceLock<PathBuf> = OnceLock::new();
    OUT.get_or_init(|| validate_one_phantom("facesim-validate-nose", "lefort-advance", &[]))
}

/// The coarse phantom's BSSO advance with `[tet] degloved_maxilla = true` (the chin's approach
/// at its default), validated once for the tests that read it: a BSSO raises neither the tissue
/// over the maxilla nor that over the chin.
fn phantom_bsso_degloved_maxilla() -> &'static Path {
    static OUT: OnceLock<PathBuf> = OnceLock::new();
    OUT.get_or_init(|| {
        validate_one_phantom(
            "facesim-validate-degloved-bsso",
            "bsso-advance",
            &["--set", "tet.degloved_maxilla=true"],
        )
    })
}

/// The report.json of one run of a validation in `out`.
fn run_report(out: &Path, case: &str, surgery: &str) -> Value {
    let path = out.join(format!("runs/{case}/{surgery}/report.json"));
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

#[test]
fn a_coarse_phantom_bsso_advance_reports_the_runs_own_ratios_and_the_documented_ranges() {
    let out = validate_one_phantom(
        "facesim-validate-phantom",
        "bsso-advance",
        &[
            "--set",
            "tet.fat_dark.youngs_kpa=2.5",
            "--keep-runs",
            // Four full solves: the band's wiring, not the reduced model (its own tests).
            "--band-samples",
            "4",
        ],
    );
    for f in ["validation.md", "validation.csv", "validation.svg"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // --keep-runs keeps each run's every output (the impaction test below checks the default
    // prunes them).
    for f in ["tets.vtu", "report.html", "skull_post.ply"] {
        let kept = out.join("runs/phantom01/bsso-advance").join(f);
        assert!(kept.is_file(), "--keep-runs: {} missing", kept.display());
    }
    let rows = read_csv(&out.join("validation.csv"));
    let ranges = documented_ranges();
    let run = run_report(&out, "phantom01", "bsso-advance");
    // The published BSSO advance rows: Li, B', Pog', Me'.
    assert_eq!(rows.len(), 4, "{rows:?}");
    let md = std::fs::read_to_string(out.join("validation.md")).unwrap();
    // --set reached the run, and the table says it is not the defaults.
    assert_eq!(
        run["parameters"]["tet"]["fat_dark"]["youngs_kpa"].as_f64(),
        Some(2.5)
    );
    assert!(md.contains("Not the product's defaults"), "{md}");
    // The run's own report holds the plan against the same table (report.json
    // published_ratios), read as a BSSO advance, with the same ratios.
    assert_eq!(run["published_ratios"]["surgery"], "bsso-advance");
    let mut measured = 0;
    for row in &rows {
        assert_eq!(row["case"], "phantom01");
        assert_eq!(row["surgery"], "bsso-advance");
        let key = (row["surgery"].clone(), row["landmark"].clone());
        let (lo, hi) = ranges[&key];
        assert_eq!(
            (num(&row["published_low"]), num(&row["published_high"])),
            (Some(lo), Some(hi)),
            "{key:?}: validation.csv's range is not docs/guide/validation.md's"
        );
        match num(&row["predicted_ratio"]) {
            Some(ratio) => {
                measured += 1;
                let again = recompute(&run, row);
                assert!(
                    (ratio - again).abs() < 1.5e-3,
                    "{key:?}: csv {ratio} but the run's landmarks give {again}"
                );
                let own = run["published_ratios"]["rows"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|r| r["soft"] == row["landmark"].as_str())
                    .and_then(|r| r["predicted"].as_f64())
                    .expect("the run's report has no such row");
                assert!(
                    (ratio - own).abs() < 1.5e-3,
                    "{key:?}: csv {ratio} but the run's published_ratios {own}"
                );
                let inside = (lo - 5e-3..=hi + 5e-3).contains(&ratio);
                assert_eq!(row["inside"], if inside { "yes" } else { "no" }, "{key:?}");
                assert_band(row, ratio, (lo, hi), &run);
            }
            None => assert!(!row["note"].is_empty(), "{key:?}: no ratio and no reason"),
        }
    }
    assert!(measured >= 3, "only {measured} rows measured: {rows:?}");
    assert!(md.contains("With their bands"), "{md}");
    if rows.iter().any(|r| r["verdict"] == "outside") {
        assert!(md.contains("**OUTSIDE**"), "an outside row is not shown");
    }
    // A mandibular move leaves the region alone: the nose rests on the maxilla, which stays.
    assert!(run["tet"].get("region_grown_for_nose_tip").is_none());
    // The chart names the case and each measured row (SVG escapes the prime as &apos;).
    let svg = std::fs::read_to_string(out.join("validation.svg")).unwrap();
    assert!(svg.contains("phantom01") && svg.contains("bsso-advance: Pog&apos; (horizontal)"));
}

/// A measured row's band in validation.csv (printed to 0.001): the tissue parameters move the
/// ratio (a band of some width about it), the coarse mesh gives another ratio, the band is the
/// hull of the three, its verdict the protocol's, and the run's report.json row says the same.
fn assert_band(row: &HashMap<String, String>, ratio: f64, (lo, hi): (f64, f64), run: &Value) {
    let key = &row["landmark"];
    let get = |k: &str| num(&row[k]).unwrap_or_else(|| panic!("{key}: no {k}: {row:?}"));
    let (p05, p95, coarse) = (
        get("tissue_p05"),
        get("tissue_p95"),
        get("coarse_mesh_ratio"),
    );
    let (low, high) = (get("band_low"), get("band_high"));
    assert!(
        p05 < p95 && p95 - p05 < 0.5,
        "{key}: tissue band {p05}–{p95}"
    );
    assert!(
        (coarse - ratio).abs() > 1e-4,
        "{key}: the coarse mesh gave the same ratio"
    );
    assert!(
        (low - p05.min(ratio).min(coarse)).abs() < 1.5e-3
            && (high - p95.max(ratio).max(coarse)).abs() < 1.5e-3,
        "{key}: band {low}–{high} is not the hull of {p05}–{p95}, {ratio} and {coarse}"
    );
    let e = 5e-3;
    let verdict = if high < lo - e || low > hi + e {
        "outside"
    } else if lo == hi || (low >= lo - e && high <= hi + e) {
        "inside"
    } else {
        "consistent"
    };
    assert_eq!(
        row["verdict"], verdict,
        "{key}: band {low}–{high} against {lo}–{hi}"
    );
    let own = run["published_ratios"]["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["soft"] == key.as_str())
        .unwrap();
    assert_eq!(own["verdict"], verdict, "{key}: {own}");
}

/// A Le Fort I impaction closes the mandible after it (the autorotation): the run's plan turns
/// the mandible about the condylar pivot validation.md names until the lower incisal edge it
/// names has risen the impaction, the run's own report reads the plan as an impaction, with
/// validation.csv's ratios, and the lower lip rises with the teeth.
#[test]
fn an_impaction_closes_the_mandible_and_the_run_still_reads_as_an_impaction() {
    let out = validate_one_phantom("facesim-validate-impaction", "lefort-impaction", &[]);
    let run = run_report(&out, "phantom01", "lefort-impaction");
    // The 4 mm impaction squeezes this coarse phantom's gap above the palate: a few elements
    // tear and the tearing settles (a round inverting two neighbours of the first torn one has
    // not spread: model::volumetric's SPREAD_FLOOR), leaving none inverted.
    assert_eq!(
        run["tet"]["inverted_elements"].as_u64(),
        Some(0),
        "{}",
        run["tet"]
    );
    // Without --keep-runs a run keeps its report, landmarks and faces only.
    let run_dir = out.join("runs/phantom01/lefort-impaction");
    assert!(run_dir.join("face_post.ply").is_file());
    assert!(
        !run_dir.join("tets.vtu").exists(),
        "tets.vtu kept without --keep-runs"
    );
    // report.json `plan`: the maxilla up 4 mm in the head frame, the mandible turned about the
    // condyles found on the CT until the lower incisal edge has risen as much.
    let plan = &run["plan"];
    let seg = |name: &str| {
        plan["segments"]
            .as_array()
            .unwrap()
            .iter()
            .find(|o| o["name"] == name)
            .unwrap()
            .clone()
    };
    let (maxilla, mandible) = (seg("maxilla"), seg("mandible"));
    assert!(
        (maxilla["moves"]["up_mm"].as_f64().unwrap() - 4.0).abs() < 1e-9,
        "{maxilla}"
    );
    assert_eq!(mandible["surgery"], "autorotation");
    assert_eq!(mandible["pivot_landmark"], "condyles");
    let pitch = mandible["moves"]["pitch_deg"].as_f64().unwrap();
    assert!(
        (-4.5..-2.0).contains(&pitch),
        "a closing turn of a few degrees: {mandible}"
    );
    let l1_up = plan["landmarks"]["L1"]["up_mm"].as_f64().unwrap();
    assert!(
        (l1_up - 4.0).abs() < 1e-6,
        "the lower incisal edge rose {l1_up} mm"
    );
    let up = vec3(&run["clinical_frame"]["up"]).unwrap();
    let md = std::fs::read_to_string(out.join("validation.md")).unwrap();
    assert!(
        md.contains("- autorotation: about the condyles Co-R and Co-L found on the CT"),
        "validation.md names the autorotation"
    );
    // The run's own report reads the plan as an impaction, with the same ratios.
    assert_eq!(
        run["published_ratios"]["surgery"], "lefort-impaction",
        "{}",
        run["published_ratios"]
    );
    let rows = read_csv(&out.join("validation.csv"));
    let mut compared = 0;
    for row in &rows {
        let Some(ratio) = num(&row["predicted_ratio"]) else {
            continue;
        };
        let own = run["published_ratios"]["rows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["soft"] == row["landmark"].as_str())
            .and_then(|r| r["predicted"].as_f64());
        if let Some(own) = own {
            assert!(
                (ratio - own).abs() < 1.5e-3,
                "{}: csv {ratio}, run {own}",
                row["landmark"]
            );
            compared += 1;
        }
    }
    assert!(compared >= 2, "{rows:?}");
    // The lower lip rises with the closing teeth, more than the maxilla's 4 mm takes subnasale.
    let rise_of = |label: &str| {
        let lm = &run["landmarks"][label];
        let (p, q) = (vec3(&lm["pre"]).unwrap(), vec3(&lm["post"]).unwrap());
        (0..3).map(|k| (q[k] - p[k]) * up[k]).sum::<f64>()
    };
    assert!(
        rise_of("Li") > rise_of("Sn") && rise_of("Li") > 2.0,
        "Li {} Sn {}",
        rise_of("Li"),
        rise_of("Sn")
    );
}

/// The region's held faces must not cut through the nose over a moving maxilla: on this
/// phantom the box of a Le Fort I grown by `[tet] margin_mm` ends 2.3 mm short of pronasale,
/// which was held still ("Prn did not move"). Grown to hold the tip with 10 mm about it, the
/// tip follows the advance by the published fraction.
#[test]
fn a_le_fort_advance_takes_in_the_whole_nose() {
    let out = phantom_le_fort_advance();
    let run = run_report(out, "phantom01", "lefort-advance");
    // A Le Fort I advance treats Class III: its phantom is built with the mandible ahead
    // (docs/guide/validation.md "What was compared"), and validation.md says so.
    let built: Vec<PathBuf> = std::fs::read_dir(out.join("phantoms"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(built.len(), 1, "{built:?}");
    let shape = std::fs::read_to_string(built[0].join("phantom.toml")).unwrap();
    let mandible = shape
        .lines()
        .find_map(|l| l.strip_prefix("mandible_mm = "))
        .and_then(num)
        .expect("no mandible_mm in phantom.toml");
    assert!(
        mandible > 0.0,
        "a Class III phantom with prognathism {mandible}"
    );
    let md = std::fs::read_to_string(out.join("validation.md")).unwrap();
    assert!(md.contains("### phantom01 (Class III)"), "{md}");
    let tet = &run["tet"];
    let tip = vec3(&tet["region_grown_for_nose_tip"]).expect("the region did not grow");
    let prn = vec3(&run["landmarks"]["Prn"]["pre"]).unwrap();
    assert!(
        (0..3).all(|k| (tip[k] - prn[k]).abs() < 1e-9),
        "{tip:?} is not pronasale {prn:?}"
    );
    let (lo, hi) = (
        vec3(&tet["region"][0]).unwrap(),
        vec3(&tet["region"][1]).unwrap(),
    );
    for k in 0..3 {
        assert!(
            prn[k] - lo[k] >= 10.0 - 1e-9 && hi[k] - prn[k] >= 10.0 - 1e-9,
            "pronasale {prn:?} nearer than 10 mm to the region {lo:?}..{hi:?}"
        );
    }
    let rows = read_csv(&out.join("validation.csv"));
    let row = rows.iter().find(|r| r["landmark"] == "Prn").unwrap();
    assert!(row["note"].is_empty(), "{row:?}");
    let ratio = num(&row["predicted_ratio"]).expect("Prn not measured");
    assert!((ratio - recompute(&run, row)).abs() < 1.5e-3, "{row:?}");
    // Evidence, not a pass mark (docs/guide/validation.md): with the cut and frame found from the CT
    // this phantom's Prn follows by 0.49, above the published 0.17-0.36; what is required is
    // that the nose tip follows the maxilla, by less than it moves.
    let (lo, hi) = documented_ranges()[&("lefort-advance".to_string(), "Prn".to_string())];
    println!("Prn follows the Le Fort I advance by {ratio}, published {lo}-{hi}");
    assert!(ratio > 0.05 && ratio < 1.0, "Prn {ratio}");
    // The alar width (Al-R to Al-L) is measured, as the widening along the head frame's lateral
    // axis over the advance, recomputed here from report.json's alare and frame alone.
    let alar = rows
        .iter()
        .find(|r| r["landmark"] == "alar base width")
        .unwrap();
    let l = vec3(&run["head_frame"]["lateral"]).unwrap();
    let moved = |label: &str| {
        let lm = &run["landmarks"][label];
        let (a, b) = (vec3(&lm["pre"]).unwrap(), vec3(&lm["post"]).unwrap());
        (0..3).map(|k| (b[k] - a[k]) * l[k]).sum::<f64>()
    };
    let widening = moved("Al-L") - moved("Al-R");
    let mm = num(&alar["move_mm"]).unwrap();
    let ratio = num(&alar["predicted_ratio"]).expect("the alar width not measured");
    assert!(
        (ratio - widening / mm).abs() < 1.5e-3 && alar["axis"] == "lateral",
        "{alar:?}: widening {widening} mm over {mm} mm"
    );
}

#[test]
fn hollow_phantom_noses_are_asked_for_and_the_segmentation_finds_their_passages() {
    // The validation's phantoms have hollow noses by default, `--phantom-noses solid` the
    // standard head's (docs/design/phantom.md "Nasal passages"): the phantom written says which, and
    // a hollow nose's CT holds the passages as a cavity the solid nose does not have: the
    // segmentation's enclosed air grows by more than a millilitre.
    let cavity = |out: &Path| {
        let run = run_report(out, "phantom01", "lefort-advance");
        run["segmentation"]["cavity_voxels"].as_f64().unwrap()
    };
    let hollow = phantom_le_fort_advance();
    let solid = validate_one_phantom(
        "facesim-validate-solid-nose",
        "lefort-advance",
        &["--phantom-noses", "solid"],
    );
    let shape = |out: &Path| {
        std::fs::read_to_string(out.join("phantoms/phantom01-class-iii/phantom.toml")).unwrap()
    };
    assert!(shape(hollow).contains("\nnasal_passages = true\n"));
    assert!(!shape(&solid).contains("nasal_passages"));
    // 3 mm voxels: 27 mm^3 each; the passages hold about 8 ml (docs/design/phantom.md), of which the
    // voxels wholly inside, with 4 mm walls, are well over 1 ml.
    let (h, s) = (cavity(hollow), cavity(&solid));
    assert!(h - s > 1000.0 / 27.0, "cavity voxels {h} hollow, {s} solid");
    let md = std::fs::read_to_string(solid.join("validation.md")).unwrap();
    assert!(
        md.contains("--phantom-noses solid"),
        "the command is not recorded"
    );
    assert!(
        md.contains("; a solid nose)"),
        "the phantom's nose is not said"
    );
    let md = std::fs::read_to_string(hollow.join("validation.md")).unwrap();
    assert!(
        md.contains("; a hollow nose: two nasal passages beside a septum)"),
        "the phantom's nose is not said"
    );
}

#[test]
fn the_real_headsq_bsso_advance_keeps_the_soft_chin_inside_the_published_range() {
    common::real_mandible_ct();
    common::real_ct();
    let (out, r) = validate_into(
        "facesim-validate-headsq",
        &[
            "--case",
            "real-mandible",
            "--case",
            "real",
            "--phantoms",
            "0",
            "--surgery",
            "bsso-advance",
        ],
    );
    // ProMED 0051 has no mandible: the BSSO is skipped, and says why.
    assert!(
        r.stderr.contains("not run: real bsso-advance")
            && r.stderr.contains("ends above the mandible"),
        "{}",
        r.stderr
    );
    let md = std::fs::read_to_string(out.join("validation.md")).unwrap();
    assert!(
        md.contains("ends above the mandible"),
        "validation.md does not say why"
    );
    let rows = read_csv(&out.join("validation.csv"));
    let pog = rows
        .iter()
        .find(|r| r["case"] == "real-mandible" && r["landmark"] == "Pog'")
        .expect("no Pog' row for headsq");
    let ratio = num(&pog["predicted_ratio"]).expect("Pog' not measured on headsq");
    // Hallulli & Sjöström 2026 (20 articles): 0.80–1.33.
    assert!(
        (0.80..=1.33).contains(&ratio),
        "headsq BSSO advance Pog'/Pog {ratio}"
    );
    assert_eq!(pog["inside"], "yes");
    // The move is the head's forward, not the scanner's: headsq's pitch turns it down.
    let run = run_report(&out, "real-mandible", "bsso-advance");
    let t = vec3(&run["parameters"]["osteotomy"][0]["translate"]).unwrap();
    assert!(t[2] < -1.0 && t[1] < -4.5, "{t:?}");
    // Found from the CT: the frame's pitch is the head's, 10-25 degrees face-down.
    let pitch = run["clinical_frame"]["pitch_deg"].as_f64().unwrap();
    assert!((10.0..25.0).contains(&pitch), "{}", run["clinical_frame"]);
}

/// `[tet] degloved_maxilla` (docs/lab/validation-notes.md "The degloved maxilla") on the real CT's Le
/// Fort I advance and setback: the tissue raised off the anterior maxilla rests on it one way only.
/// Signorini's conditions where the rounds end: every raised node still on the bone is pushed by
/// it (the rounds settled), every lifted one lies clear of the bone's move (within 0.01 mm).
/// The bone pulls the tissue after it in a setback and pushes it in an advance, so the model is
/// no longer odd in the move (bonded, a setback's ratios are the advance's to round-off): the
/// setback leaves subnasale and the upper lip behind, subnasale inside the range the clinic
/// measures for a setback (docs/guide/validation.md's table). A BSSO moves no maxilla: nothing is
/// raised, nothing lifts off. Without sliding or on the 10-node element the option is refused.
#[test]
fn a_degloved_maxilla_rests_on_its_bone_one_way_and_a_setback_leaves_the_lip_behind() {
    common::real_ct();
    let (out, _) = validate_into(
        "facesim-validate-degloved",
        &[
            "--case",
            "real",
            "--phantoms",
            "0",
            "--surgery",
            "lefort-advance",
            "--surgery",
            "lefort-setback",
            "--set",
            "tet.degloved_maxilla=true",
        ],
    );
    for surgery in ["lefort-advance", "lefort-setback"] {
        let run = run_report(&out, "real", surgery);
        let t = &run["tet"];
        let count = |k: &str| t[k].as_u64().unwrap();
        println!(
            "{surgery}: {} raised, {} lifted off, deepest {:.4} mm",
            count("degloved_nodes"),
            count("lifted_in_tension"),
            t["lifted_penetration_mm"].as_f64().unwrap()
        );
        assert!(count("degloved_nodes") > 100, "{surgery}: {t}");
        assert!(count("lifted_in_tension") > 0, "{surgery}: {t}");
        assert!(
            count("lifted_in_tension") < count("degloved_nodes"),
            "{surgery}: {t}"
        );
        assert_eq!(t["degloved_settled"], true, "{surgery}: {t}");
        assert!(
            t["lifted_penetration_mm"].as_f64().unwrap() <= 0.01,
            "{surgery}: {t}"
        );
        assert_eq!(count("inverted_elements"), 0, "{surgery}");
        // Nothing torn: a volume of +0, not an empty sum's −0 printed as "-0.0".
        assert_eq!(count("torn_elements"), 0, "{surgery}");
        assert_eq!(t["torn_volume_mm3"].to_string(), "0.0", "{surgery}");
    }
    let rows = read_csv(&out.join("validation.csv"));
    let ratio = |surgery: &str, landmark: &str| {
        let row = rows
            .iter()
            .find(|r| r["surgery"] == surgery && r["landmark"] == landmark)
            .unwrap_or_else(|| panic!("no {surgery} {landmark} row"));
        num(&row["predicted_ratio"]).unwrap()
    };
    let (sn_advance, sn_setback) = (ratio("lefort-advance", "Sn"), ratio("lefort-setback", "Sn"));
    let (ls_advance, ls_setback) = (ratio("lefort-advance", "Ls"), ratio("lefort-setback", "Ls"));
    println!("Sn {sn_advance:.3} / {sn_setback:.3}, Ls {ls_advance:.3} / {ls_setback:.3}");
    assert!(
        sn_setback < sn_advance - 0.1,
        "Sn {sn_advance} / {sn_setback}"
    );
    assert!(
        ls_setback < ls_advance - 0.05,
        "Ls {ls_advance} / {ls_setback}"
    );
    // Evidence, not a pass mark (docs/guide/validation.md): with the Le Fort I cut found from the CT
    // (3 mm above ANS, back to PNS) subnasale follows the setback by 0.52, above the published
    // 0.33 (one value); the one-sided contact above is what this test holds.
    let ranges = documented_ranges();
    let (lo, hi) = ranges[&("lefort-setback".to_string(), "Sn".to_string())];
    println!("setback Sn {sn_setback} (published {lo}–{hi})");

    let run = run_report(phantom_bsso_degloved_maxilla(), "phantom01", "bsso-advance");
    assert_eq!(run["tet"]["degloved_nodes"], 0, "{}", run["tet"]);
    assert_eq!(run["tet"]["lifted_in_tension"], 0, "{}", run["tet"]);
    // The bundled phantom's face has no lip profile (no Sn, Ls or Sto found): its mandibular
    // advance leaves the upper teeth in place, so it raises nothing rather than asking for them.
    let out = common::out_dir("facesim-degloved-no-lips");
    let r = facesim(&[
        "run",
        root().join("data-samples/phantom").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        "tet.degloved_maxilla=true",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert!(report["landmarks"]["Sn"]["pre"].is_null(), "Sn was found");
    assert_eq!(report["tet"]["degloved_nodes"], 0, "{}", report["tet"]);

    // Without sliding, or on the 10-node element, the option is refused in one line.
    let jaws = root().join("data-samples/jaws");
    for (set, problem) in [
        ("tet.sliding=false", "needs [tet] sliding and release_cuts"),
        ("tet.element=\"quadratic\"", "runs on the 4-node element"),
    ] {
        let out = common::out_dir("facesim-degloved-refused");
        let r = facesim(&[
            "run",
            jaws.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--set",
            "tet.degloved_maxilla=true",
            "--set",
            set,
        ]);
        assert_clean_failure(&r, "case.toml", problem);
    }
}

/// `[tet] degloved_maxilla = "auto"` (off by default, refused by the validation protocol's rule):
/// a coarse phantom's Le Fort I advance raises the tissue over its anterior maxilla as `true`
/// does (the same nodes, the same face); where `true` is refused — here sliding off — it steps
/// aside, says why in a warning and report.json `tet.degloved_not_applied`, and the run goes on
/// bonded.
#[test]
fn the_degloved_maxilla_on_auto_serves_where_it_can_and_steps_aside_where_it_cannot() {
    let by_default = validate_one_phantom(
        "facesim-degloved-auto",
        "lefort-advance",
        &["--set", "tet.degloved_maxilla=auto"],
    );
    let asked = validate_one_phantom(
        "facesim-degloved-asked",
        "lefort-advance",
        &["--set", "tet.degloved_maxilla=true"],
    );
    let (d, a) = (
        run_report(&by_default, "phantom01", "lefort-advance"),
        run_report(&asked, "phantom01", "lefort-advance"),
    );
    assert!(
        d["tet"]["degloved_nodes"].as_u64().unwrap() > 10,
        "{}",
        d["tet"]
    );
    assert_eq!(d["tet"]["degloved_nodes"], a["tet"]["degloved_nodes"]);
    assert_eq!(d["tet"]["lifted_in_tension"], a["tet"]["lifted_in_tension"]);
    assert!(d["tet"]["degloved_not_applied"].is_null(), "{}", d["tet"]);
    let face =
        |o: &Path| std::fs::read(o.join("runs/phantom01/lefort-advance/face_post.ply")).unwrap();
    assert!(
        face(&by_default) == face(&asked),
        "auto's face is not true's"
    );

    // Sliding off (the 10-node element's step aside, the same branch, is model::degloved's unit
    // test: a 10-node phantom run takes minutes).
    let out = validate_one_phantom(
        "facesim-degloved-aside",
        "lefort-advance",
        &[
            "--set",
            "tet.sliding=false",
            "--set",
            "tet.degloved_maxilla=auto",
        ],
    );
    let run = run_report(&out, "phantom01", "lefort-advance");
    assert_eq!(run["tet"]["degloved_nodes"], 0, "{}", run["tet"]);
    let reason = run["tet"]["degloved_not_applied"]
        .as_str()
        .unwrap_or_default();
    assert!(reason.contains("sliding and release_cuts"), "{reason:?}");
    let warned = run["warnings"].as_array().unwrap().iter().any(|w| {
        w.as_str()
            .unwrap()
            .contains("degloved_maxilla = \"auto\" stepped aside")
    });
    assert!(warned, "{}", run["warnings"]);
}

/// `[tet] degloved_chin = "auto"`, the default (docs/lab/validation-notes.md "The degloved chin"): a
/// coarse phantom's advancement genioplasty raises the tissue over the anterior mandible, from
/// the lower teeth down, and rests it on the bone one way: the rounds settle, lifted nodes lie
/// clear of the bone, nothing inverts, `true` gives the same face. Resting one way, the soft
/// tissue above the cut lifts off the symphysis that stays as the chin pushes it forward, so the
/// soft chin follows the bony chin further than bonded to it (`false`): measured on headsq,
/// where much of the soft chin lies over the symphysis above the cut (on the coarse phantom,
/// whose chin lies over the segment, the two differ by 0.005 since the tissue slides on the bone
/// surface's own normal). A BSSO moves the chin with the teeth: nothing is raised.
#[test]
fn a_genioplasty_raises_the_chin_by_default_and_the_soft_chin_follows_further() {
    let by_default = validate_one_phantom("facesim-degloved-chin", "genioplasty", &[]);
    let asked = validate_one_phantom(
        "facesim-degloved-chin-asked",
        "genioplasty",
        &["--set", "tet.degloved_chin=true"],
    );
    let bonded = validate_one_phantom(
        "facesim-degloved-chin-off",
        "genioplasty",
        &["--set", "tet.degloved_chin=false"],
    );
    let (d, a, b) = (
        run_report(&by_default, "phantom01", "genioplasty"),
        run_report(&asked, "phantom01", "genioplasty"),
        run_report(&bonded, "phantom01", "genioplasty"),
    );
    let t = &d["tet"];
    let count = |k: &str| t[k].as_u64().unwrap();
    println!(
        "genioplasty: {} raised ({} by the chin's approach), {} lifted off, deepest {:.4} mm",
        count("degloved_nodes"),
        count("degloved_chin_nodes"),
        count("lifted_in_tension"),
        t["lifted_penetration_mm"].as_f64().unwrap()
    );
    assert!(count("degloved_chin_nodes") > 10, "{t}");
    assert_eq!(count("degloved_nodes"), count("degloved_chin_nodes"), "{t}");
    assert!(count("lifted_in_tension") > 0, "{t}");
    assert_eq!(t["degloved_settled"], true, "{t}");
    assert!(t["lifted_penetration_mm"].as_f64().unwrap() <= 0.01, "{t}");
    assert_eq!(count("inverted_elements"), 0);
    assert!(t["degloved_chin_not_applied"].is_null(), "{t}");
    assert_eq!(b["tet"]["degloved_nodes"], 0, "{}", b["tet"]);
    let face =
        |o: &Path| std::fs::read(o.join("runs/phantom01/genioplasty/face_post.ply")).unwrap();
    assert!(
        face(&by_default) == face(&asked),
        "the default's face is not true's"
    );
    assert_eq!(a["tet"]["degloved_chin_nodes"], t["degloved_chin_nodes"]);

    // The soft chin's follow, on the real head: headsq's CT ends 7.5 mm below pogonion, so much
    // of its soft chin lies over the symphysis above the cut, which bonded holds it back.
    common::real_mandible_ct();
    let headsq = |dir: &str, extra: &[&str]| {
        let mut args = vec![
            "--case",
            "real-mandible",
            "--phantoms",
            "0",
            "--surgery",
            "genioplasty",
        ];
        args.extend_from_slice(extra);
        let out = validate_into(dir, &args).0;
        let rows = read_csv(&out.join("validation.csv"));
        let row = rows
            .iter()
            .find(|r| r["surgery"] == "genioplasty" && r["landmark"] == "Pog'")
            .expect("no genioplasty Pog' row");
        num(&row["predicted_ratio"]).unwrap()
    };
    let raised = headsq("facesim-degloved-chin-headsq", &[]);
    let attached = headsq(
        "facesim-degloved-chin-headsq-off",
        &["--set", "tet.degloved_chin=false"],
    );
    println!("headsq genioplasty Pog'/Pog: {raised:.3} raised, {attached:.3} attached");
    // Published 0.57–1.0 (docs/guide/validation.md); bonded, headsq's soft chin falls below it.
    assert!(raised > attached + 0.1, "{raised} vs {attached}");
    println!("headsq genioplasty Pog'/Pog {raised:.3} (published 0.57–1.0)");
    assert!(raised > 0.3 && raised < 1.2, "{raised}");

    let run = run_report(phantom_bsso_degloved_maxilla(), "phantom01", "bsso-advance");
    assert_eq!(run["tet"]["degloved_chin_nodes"], 0, "{}", run["tet"]);
    assert!(
        run["tet"]["degloved_chin_not_applied"].is_null(),
        "{}",
        run["tet"]
    );
}

#[test]
fn bad_input_is_one_line() {
    let out = common::kept_dir("facesim-validate-bad").join("v");
    let r = facesim(&[
        "validate",
        "--out",
        out.to_str().unwrap(),
        "--surgery",
        "le-fort-ii",
    ]);
    assert_clean_failure(&r, "le-fort-ii", "unknown surgery");
    let r = facesim(&[
        "validate",
        "--out",
        out.to_str().unwrap(),
        "--samples",
        root().join("data-samples").to_str().unwrap(),
        "--case",
        "nosuch",
    ]);
    assert_clean_failure(&r, "nosuch", "no case");
    let r = facesim(&[
        "validate",
        "--out",
        out.to_str().unwrap(),
        "--samples",
        "/nonexistent-samples",
    ]);
    assert_clean_failure(&r, "/nonexistent-samples", "not found");
    let r = facesim(&["validate", "--out", out.to_str().unwrap(), "--set", "tet"]);
    assert_clean_failure(&r, "--set tet", "expected KEY=VALUE");
    // A validation.toml that still places a segment by hand: segments come from `[[surgery]]`.
    let samples = common::kept_dir("facesim-validate-bad-samples");
    let case = samples.join("headsq");
    std::fs::create_dir_all(&case).unwrap();
    let real = root().join("data-samples/real-mandible");
    std::fs::copy(real.join("case.toml"), case.join("case.toml")).unwrap();
    let ct = case.join("headsq.vti");
    if !ct.exists() {
        std::os::unix::fs::symlink(real.join("headsq.vti"), &ct).unwrap();
    }
    let text = std::fs::read_to_string(real.join("validation.toml")).unwrap();
    let bad = case.join("validation.toml");
    std::fs::write(
        &bad,
        format!("{text}\n[segments.maxilla]\nregion = {{ box = {{ min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }} }}\n"),
    )
    .unwrap();
    let r = facesim(&[
        "validate",
        "--out",
        out.to_str().unwrap(),
        "--samples",
        samples.to_str().unwrap(),
        "--phantoms",
        "0",
    ]);
    assert_clean_failure(&r, bad.to_str().unwrap(), "unknown field `segments`");
    assert!(!out.exists(), "a failed validation left {}", out.display());
}

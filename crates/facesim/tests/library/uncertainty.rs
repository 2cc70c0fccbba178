//! `[uncertainty]` (docs/guide/uncertainty.md) on the phantom with the volumetric
//! model: zero spread gives a zero band at exactly the deterministic prediction, and a point away
//! from the nominal parameters equals a full run with those parameters (an independent path);
//! nested ranges widen the band; the same seed writes the same bytes; impossible ranges and
//! parameters the model lacks are refused naming the key.

use crate::common;

use facesim::case::uncertainty::{Chance, Range};
use facesim::case::{Case, SolveModel};
use facesim::commands::{self, Outcome};
use facesim::observe::Quiet;
use std::path::Path;

fn case() -> Case {
    common::coarse_tet_phantom(
        "uncertainty",
        common::PHANTOM_MANDIBLE,
        [0.0, -6.0, 0.0],
        [0.0; 3],
    )
}

/// Every tet parameter at a point: ν, muscle/fat, skin/fat, sliding probability.
fn points(c: &mut Case, samples: usize, nu: f64, muscle_fat: f64, skin_fat: f64, slide: f64) {
    let u = &mut c.uncertainty;
    u.samples = samples;
    u.poisson = Some(Range::uniform(nu, nu));
    u.muscle_fat = Some(Range::log_uniform(muscle_fat, muscle_fat));
    u.skin_fat = Some(Range::log_uniform(skin_fat, skin_fat));
    u.sliding = Some(Chance { probability: slide });
}

fn run(c: Case, name: &str) -> Outcome {
    commands::run_case(c, &common::out_dir(name), &Quiet).unwrap()
}

use common::{band_columns, report_json as json};

fn magnitudes(o: &Outcome) -> Vec<f64> {
    o.skin
        .vertices
        .iter()
        .zip(&o.face_post.vertices)
        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*b, *a)))
        .collect()
}

#[test]
fn zero_spread_gives_a_zero_band_at_exactly_the_deterministic_prediction() {
    // At the nominal parameters ([tet] defaults: ν 0.45, muscle 10 / fat 2, skin 30 / fat 2,
    // sliding): no solve, the band is the run's own displacement.
    let plain = run(case(), "facesim-unc-plain");
    let mut c = case();
    points(&mut c, 3, 0.45, 5.0, 15.0, 1.0);
    let o = run(c, "facesim-unc-zero");
    assert_eq!(o.face_post.vertices, plain.face_post.vertices);
    let j = json(&o);
    let u = &j["uncertainty"];
    assert_eq!(u["samples"], 3);
    assert_eq!(u["solves"], 0, "{u}");
    let [mean, p05, p95] = band_columns(&o.out_dir);
    let d = magnitudes(&plain);
    assert!(d.iter().any(|x| *x > 1.0));
    for i in 0..d.len() {
        assert_eq!(
            (mean[i], p05[i], p95[i]),
            (d[i] as f32 as f64, mean[i], mean[i])
        );
    }
    for (label, b) in u["landmarks"].as_object().unwrap() {
        let change = &j["landmarks"][label]["change_mm"];
        assert_eq!(&b["mean"], change, "{label}");
        assert_eq!(b["p05"], b["p95"], "{label}");
        assert_eq!(b["p05"], b["mean"], "{label}");
    }
    // This phantom's face yields few landmarks and no regions: the jaws phantom below has them.
    assert!(!u["landmarks"].as_object().unwrap().is_empty(), "{u}");
}

/// Landmarks and regions in report.json `uncertainty` equal the run's own `landmarks` and
/// `regions` at zero spread, on the phantom with jaws (a face with lips and chin; mucosa that
/// slides on the teeth).
#[test]
fn zero_spread_landmark_and_region_bands_are_the_runs_own_figures() {
    use facesim_validate::phantom::PhantomOptions;
    use facesim_validate::phantom_jaws::{self, JawsOptions};
    let dir = common::kept_dir("facesim-unc-jaws");
    let opts = JawsOptions {
        phantom: PhantomOptions {
            spacing: [2.0; 3],
            ..PhantomOptions::default()
        },
        solve_model: Some("tet".into()),
    };
    phantom_jaws::write_case(&dir, &opts).unwrap();
    let (mut c, _) = Case::load(&dir.join("case.toml")).unwrap();
    c.tet.skin_size_mm = 6.0;
    c.tet.deep_size_mm = 12.0;
    points(&mut c, 3, 0.45, 5.0, 15.0, 1.0);
    let o = run(c, "facesim-unc-jaws-run");
    let j = json(&o);
    let u = &j["uncertainty"];
    assert_eq!(u["solves"], 0, "{u}");
    let landmarks = u["landmarks"].as_object().unwrap();
    assert!(
        landmarks.contains_key("Pog'") && landmarks.contains_key("Li"),
        "{u}"
    );
    for (label, b) in landmarks {
        assert_eq!(&b["mean"], &j["landmarks"][label]["change_mm"], "{label}");
        assert_eq!((&b["p05"], &b["p95"]), (&b["mean"], &b["mean"]), "{label}");
    }
    assert!(
        u["landmarks"]["Pog'"]["mean"].as_f64().unwrap() > 1.0,
        "{u}"
    );
    let regions = u["regions"].as_object().unwrap();
    assert!(
        regions.contains_key("chin") && regions.contains_key("lower lip"),
        "{u}"
    );
    for (name, b) in regions {
        assert_eq!(&b["mean"], &j["regions"][name]["mean"], "{name}");
        assert_eq!((&b["p05"], &b["p95"]), (&b["mean"], &b["mean"]), "{name}");
    }
}

#[test]
fn a_point_away_from_the_nominal_equals_a_run_with_those_parameters() {
    // The resampled solve (the run's mesh, mucosa and face embedding reused) against a full run
    // of the same parameters: ν 0.47 everywhere, muscle 4 × fat, skin 10 × fat, attached mucosa.
    let mut direct = case();
    for m in direct.tet.tissues_mut() {
        m.poisson = 0.47;
    }
    direct.tet.muscle.youngs_kpa = 8.0;
    direct.tet.skin.youngs_kpa = 20.0;
    direct.tet.sliding = false;
    let direct = run(direct, "facesim-unc-direct");
    let mut c = case();
    points(&mut c, 2, 0.47, 4.0, 10.0, 0.0);
    let o = run(c, "facesim-unc-point");
    let u = &json(&o)["uncertainty"];
    assert_eq!(
        (u["solves"].as_u64(), u["reused"].as_u64()),
        (Some(1), Some(1))
    );
    assert_eq!(u["draws"][0]["sliding"], false);
    let d = magnitudes(&direct);
    let nominal = magnitudes(&o);
    let [mean, p05, p95] = band_columns(&o.out_dir);
    let mut differs = 0.0f64;
    for i in 0..d.len() {
        // f32 in the file: half an ulp of the value.
        let tol = 1e-6 * d[i].max(1e-3);
        assert!(
            (mean[i] - d[i]).abs() <= tol,
            "vertex {i}: {} vs {}",
            mean[i],
            d[i]
        );
        assert_eq!((p05[i], p95[i]), (mean[i], mean[i]));
        differs = differs.max((d[i] - nominal[i]).abs());
    }
    // The parameters matter: otherwise this test could not tell the paths apart.
    assert!(
        differs > 0.05,
        "largest change from the nominal {differs} mm"
    );
}

/// Mean band width over the face, and the widths per vertex, for muscle/fat in
/// [5/s, 5·s] (log-uniform) and ν in [0.47 − w, 0.47 + w], the rest at the nominal.
fn widths(s: f64, w: f64, name: &str) -> (f64, Vec<f64>, serde_json::Value) {
    let mut c = case();
    points(&mut c, 5, 0.47, 5.0, 15.0, 1.0);
    c.uncertainty.muscle_fat = Some(Range::log_uniform(5.0 / s, 5.0 * s));
    c.uncertainty.poisson = Some(Range::uniform(0.47 - w, 0.47 + w));
    let o = run(c, name);
    let [_, p05, p95] = band_columns(&o.out_dir);
    let v: Vec<f64> = p05.iter().zip(&p95).map(|(a, b)| b - a).collect();
    let u = json(&o)["uncertainty"].clone();
    (u["face"]["mean_width"].as_f64().unwrap(), v, u)
}

#[test]
fn the_band_widens_with_the_spread() {
    let runs = [
        widths(1.0, 0.0, "facesim-unc-w0"),
        widths(1.5, 0.005, "facesim-unc-w1"),
        widths(3.0, 0.01, "facesim-unc-w2"),
        widths(6.0, 0.015, "facesim-unc-w3"),
    ];
    assert_eq!(runs[0].0, 0.0);
    for k in 1..runs.len() {
        let (prev, next) = (&runs[k - 1], &runs[k]);
        assert!(next.0 > prev.0, "mean width {} then {}", prev.0, next.0);
        // Per vertex (f32 in the file): no vertex's band narrows.
        for (i, (a, b)) in prev.1.iter().zip(&next.1).enumerate() {
            assert!(*b >= a - 1e-5, "vertex {i}: width {a} then {b}");
        }
        for key in ["landmarks", "regions"] {
            for (name, b) in next.2[key].as_object().unwrap() {
                let w =
                    |v: &serde_json::Value| v["p95"].as_f64().unwrap() - v["p05"].as_f64().unwrap();
                let a = &prev.2[key][name];
                assert!(w(b) >= w(a) - 1e-9, "{key} {name}: {a} then {b}");
            }
        }
    }
    assert!(runs[3].0 > 0.05, "widest mean band {} mm", runs[3].0);
}

#[test]
fn the_same_seed_writes_the_same_bytes() {
    let with = |seed: u64, name: &str| {
        let mut c = case();
        c.uncertainty.samples = 4;
        c.uncertainty.seed = seed;
        let o = run(c, name);
        (
            std::fs::read(o.out_dir.join("face_band.ply")).unwrap(),
            json(&o)["uncertainty"]["draws"].clone(),
        )
    };
    let a = with(7, "facesim-unc-seed-a");
    let b = with(7, "facesim-unc-seed-b");
    let c = with(8, "facesim-unc-seed-c");
    assert!(
        a.0 == b.0,
        "face_band.ply differs between two runs of seed 7"
    );
    assert_eq!(a.1, b.1);
    assert_ne!(a.1, c.1);
    assert!(a.0 != c.0);
}

#[test]
fn impossible_ranges_and_foreign_parameters_are_refused_naming_the_key() {
    let base = "[ct]\npath = \"ct.nii.gz\"\n[uncertainty]\nsamples = 4\n";
    for (extra, key) in [
        (
            "[uncertainty.poisson]\nuniform = [0.45, 0.5]\n",
            "[uncertainty.poisson]",
        ),
        (
            "[uncertainty.poisson]\nuniform = [-1.5, 0.3]\n",
            "[uncertainty.poisson]",
        ),
        (
            "[uncertainty.poisson]\nuniform = [0.49, 0.45]\n",
            "[uncertainty.poisson]",
        ),
        (
            "[uncertainty.muscle_fat]\nlog_uniform = [-2.0, 5.0]\n",
            "[uncertainty.muscle_fat]",
        ),
        (
            "[uncertainty.skin_fat]\nuniform = [0.0, 5.0]\n",
            "[uncertainty.skin_fat]",
        ),
        (
            "[uncertainty.skin_fat]\nuniform = [1.0, 5.0]\nlog_uniform = [1.0, 5.0]\n",
            "[uncertainty.skin_fat]",
        ),
        (
            "[uncertainty.sliding]\nprobability = 1.5\n",
            "[uncertainty.sliding]",
        ),
        (
            "[uncertainty.spring_scale]\nlog_uniform = [0.5, 2.0]\n",
            "[uncertainty.spring_scale]",
        ),
        ("[uncertainty.poison]\nuniform = [0.45, 0.49]\n", "poison"),
        (
            "[solve]\nmodel = \"equilibrium\"\n[uncertainty.poisson]\nuniform = [0.45, 0.49]\n",
            "[uncertainty.poisson]",
        ),
    ] {
        let e = Case::parse(&format!("{base}{extra}"), Path::new("case.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("case.toml") && e.contains(key), "{extra}: {e}");
        assert!(!e.contains('\n'), "{e}");
    }
    // The defaults, and a C1 case's spring scale, are accepted.
    Case::parse(base, Path::new("case.toml")).unwrap();
    Case::parse(
        &format!("{base}[solve]\nmodel = \"koch1996\"\n[uncertainty.spring_scale]\nlog_uniform = [0.5, 2.0]\n"),
        Path::new("case.toml"),
    )
    .unwrap();
}

#[test]
fn a_uniform_scale_of_every_modulus_leaves_the_face() {
    // Why only ratios of moduli are sampled: with bone moves as the only load, K(cE) = c·K(E)
    // and the free nodes' displacement −K_ff⁻¹ K_fp u_p does not change.
    let plain = run(case(), "facesim-unc-scale1");
    let mut c = case();
    for m in c.tet.tissues_mut() {
        m.youngs_kpa *= 7.0;
    }
    let scaled = run(c, "facesim-unc-scale7");
    let scale = magnitudes(&plain).iter().cloned().fold(0.0, f64::max);
    assert!(scale > 1.0);
    for (a, b) in plain
        .face_post
        .vertices
        .iter()
        .zip(&scaled.face_post.vertices)
    {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-9 * scale, "{a:?} {b:?}");
        }
    }
}

/// The C1 model's parameter: a spring scale held at one point (2×) gives the band of a full
/// `equilibrium` run whose k_c and koch_k_c are doubled (the resampled solve reuses the run's
/// springs and skin; an independent run builds them again).
#[test]
fn a_c1_spring_scale_point_equals_a_run_with_scaled_springs() {
    let c1 = || {
        let mut c = case();
        c.solve.model = SolveModel::Equilibrium;
        c
    };
    let mut direct = c1();
    direct.solve.k_c *= 2.0;
    direct.solve.koch_k_c *= 2.0;
    let direct = run(direct, "facesim-unc-c1-direct");
    let mut c = c1();
    c.uncertainty.samples = 2;
    c.uncertainty.spring_scale = Some(Range::log_uniform(2.0, 2.0));
    let o = run(c, "facesim-unc-c1-point");
    let u = &json(&o)["uncertainty"];
    assert_eq!(u["model"], "equilibrium", "{u}");
    let d = magnitudes(&direct);
    let nominal = magnitudes(&o);
    let [mean, p05, p95] = band_columns(&o.out_dir);
    let mut worst = 0.0f64;
    let mut differs = 0.0f64;
    for i in 0..d.len() {
        worst = worst.max((mean[i] - d[i]).abs());
        assert!(
            p05[i] <= mean[i] + 1e-9 && mean[i] <= p95[i] + 1e-9,
            "vertex {i}"
        );
        differs = differs.max((d[i] - nominal[i]).abs());
    }
    println!(
        "C1 spring scale 2: band mean vs full run {worst:.2e} mm; change from nominal {differs:.3} mm"
    );
    // Both solve the same equilibrium to the Newton tolerance; f32 in the file.
    assert!(worst < 1e-3, "band mean {worst} mm from the full run");
    assert!(
        differs > 0.01,
        "the spring scale changed the face by only {differs} mm"
    );
}

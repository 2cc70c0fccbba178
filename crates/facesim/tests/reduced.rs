//! The certified reduced model (issue 28 items 1–2; docs/reduced.md) on the first sample (the
//! jaws phantom, 5 mm BSSO advance): built by the greedy on the run's mesh, it gives the full
//! model's face within its certified bound at parameters it was not trained on (the full
//! solve on the run's own path, `Prediction::resolve`, is the truth), the bound is not vacuous,
//! and the greedy's bound falls with the basis size.

use facesim::case::Case;
use facesim::model::{Solved, predict};
use facesim::observe::Quiet;
use facesim::pipeline::inputs::CaseFiles;
use facesim::pipeline::{Recorder, prepare_case};
use facesim::reduced::Greedy;
use facesim::vec3::{norm, sub};
use std::path::Path;

/// Cases with the tissue parameters of `samples` draws of `[uncertainty]` (its default
/// ranges) from `seed`, sliding as given.
fn draws(case: &Case, samples: usize, seed: u64, sliding: bool) -> Vec<Case> {
    let mut c = case.clone();
    c.uncertainty.samples = samples;
    c.uncertainty.seed = seed;
    facesim::uncertainty::run::draws(&c)
        .iter()
        .map(|d| {
            let mut x = d.apply(case);
            x.tet.sliding = sliding;
            x
        })
        .collect()
}

#[test]
fn the_reduced_face_is_within_its_certified_bound_of_the_full_model() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data-samples/jaws");
    let (mut case, _) = Case::load(&dir).unwrap();
    // Coarser than the sample's default, to keep the test short (the figures at the default
    // size are in docs/reduced.md).
    case.tet.skin_size_mm = 6.0;
    case.tet.deep_size_mm = 12.0;
    case.tet.error_estimate = false;
    let scene = prepare_case(&case, &Quiet).unwrap();
    let mut rec = Recorder::new(&Quiet);
    let p = predict(&scene, &case, &CaseFiles::in_memory(&case), &mut rec).unwrap();
    let Solved::Tet(Some(v)) = &p.solved else {
        panic!("the jaws sample solves the volumetric model")
    };
    let train = draws(&case, 128, 99, true);
    let greedy = Greedy {
        tolerance: 1e-4,
        max_size: 16,
    };
    let t = std::time::Instant::now();
    let r = v
        .reduced(&scene, &case, &p.skin, &train, greedy, &|m| {
            eprintln!("{:.1} s {m}", t.elapsed().as_secs_f64())
        })
        .unwrap();
    let report = r.report();
    eprintln!(
        "offline {:.1} s, N = {}, {} factorisations, {} reference solves, face gain {:.3e}; bound by N: {:?}",
        t.elapsed().as_secs_f64(),
        report.basis_size,
        report.full_factorisations,
        report.reference_solves,
        report.face_gain,
        report
            .greedy
            .iter()
            .map(|s| format!("{}:{:.1e}", s.size, s.max_relative_bound))
            .collect::<Vec<_>>()
    );
    let g = &report.greedy;
    assert!(g.len() >= 3, "{g:?}");
    assert!(
        g.last().unwrap().max_relative_bound < 0.01 * g[0].max_relative_bound,
        "the greedy's bound falls with N"
    );
    // Parameters it was not trained on: the run's own sample draws (seed 1).
    let mut ratios = Vec::new();
    for c in draws(&case, 6, 1, true) {
        let t = std::time::Instant::now();
        let ours = r.face(&c).unwrap();
        let online = t.elapsed().as_secs_f64();
        let full = p.resolve(&scene, &c).unwrap();
        let err: Vec<f64> = p
            .skin
            .vertices
            .iter()
            .zip(&full)
            .zip(&ours.displacement)
            .map(|((pre, post), d)| norm(sub(sub(*post, *pre), *d)))
            .collect();
        let max = err.iter().cloned().fold(0.0, f64::max);
        let l2 = err.iter().map(|e| e * e).sum::<f64>().sqrt();
        eprintln!(
            "max error {max:.3e} mm, l2 {l2:.3e}, bound {:.3e} mm ({:.0}x max, {:.0}x l2), relative energy bound {:.1e}, online {:.1} ms",
            ours.bound_mm,
            ours.bound_mm / max,
            ours.bound_mm / l2,
            ours.relative_energy_bound,
            online * 1e3
        );
        assert!(
            max <= l2 && l2 <= ours.bound_mm,
            "true error {l2:.3e} mm exceeds the bound {:.3e}",
            ours.bound_mm
        );
        ratios.push(ours.bound_mm / l2);
    }
    let worst = ratios.iter().cloned().fold(0.0, f64::max);
    eprintln!("bound / true l2 error: worst {worst:.1}");
}

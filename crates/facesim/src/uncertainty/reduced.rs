//! Sampling with the certified reduced model (docs/design/reduced.md, docs/guide/uncertainty.md): each
//! sample is a reduced solve (coefficients and a bound, microseconds), the face linear in the
//! coefficients; the band per vertex is reduced in chunks of vertices, so memory grows with the
//! samples × a chunk, not × the face, and 10 000 samples of a real head's face fit.

use super::band::Band;
use super::run::{
    Draw, Nominal, Sampled, Tallies, Tracker, assemble, draw_at, draws, regions, solve_key,
    trackers,
};
use super::sensitivity::{Index, Sensitivity, indices};
use crate::case::Case;
use crate::error::Result;
use crate::landmarks::Analysis;
use crate::landmarks::Ordered;
use crate::landmarks::face_regions::Regions;
use crate::model::reduced::Bounds;
use crate::observe::Observer;
use crate::reduced::{LinearFace, ReducedReport};
use crate::vec3::{norm, sub};
use rayon::prelude::*;

/// A case's reduced answer: which linear face, its coefficients, and the certified bounds (mm)
/// on the face's and each soft landmark's error ([`landmark_outputs`] order).
pub(crate) type SolveReduced<'a> = dyn Fn(&Case) -> Result<(usize, Vec<f64>, Bounds)> + Sync + 'a;

/// A reduced model for the sampling: the linear faces (one per sliding state) and the solve
/// that picks one and gives its coefficients and bounds for a case.
pub struct Reduced<'a> {
    pub faces: Vec<&'a LinearFace>,
    pub solve: &'a SolveReduced<'a>,
    pub reports: Vec<ReducedReport>,
}

/// The soft landmarks the samples measure, as weights on face vertices (their anchors'
/// triangles), in the order of the run's landmarks: the outputs the reduced model bounds.
pub fn landmark_outputs(analysis: &Analysis, skin: &crate::mesh::Mesh) -> Vec<Vec<(usize, f64)>> {
    trackers(analysis)
        .iter()
        .filter_map(|(_, t)| match t {
            Tracker::Soft(a, _) => Some(
                skin.triangles[a.triangle as usize]
                    .iter()
                    .zip(a.weights)
                    .map(|(v, w)| (*v as usize, w))
                    .collect(),
            ),
            Tracker::Fixed(_) => None,
        })
        .collect()
}

/// The labels of [`landmark_outputs`], in its order.
pub fn landmark_output_labels(analysis: &Analysis) -> Vec<String> {
    trackers(analysis)
        .into_iter()
        .filter_map(|(label, t)| matches!(t, Tracker::Soft(..)).then_some(label))
        .collect()
}

/// One sample's face: the run's own (the nominal parameters) or a reduced answer.
enum Face {
    Nominal,
    Reduced(usize, Vec<f64>),
}

/// Vertices per chunk of the band's reduction.
const CHUNK: usize = 512;

/// As `run::sample`, each sample solved by the reduced model (samples at the nominal
/// parameters are the run's own face, bit for bit).
pub(crate) fn sample_reduced(
    run: &Nominal,
    reduced: &Reduced,
    analysis: &Analysis,
    case: &Case,
    obs: &dyn Observer,
) -> Result<Sampled> {
    let n = case.uncertainty.samples;
    let start = std::time::Instant::now();
    let skin = run.skin;
    let draws: Vec<Draw> = draws(case);
    obs.started(&format!("uncertainty: {n} reduced solves"));
    let t = std::time::Instant::now();
    let solved = solve_samples(run, reduced, case, &draws);
    let solve_s = t.elapsed().as_secs_f64();
    let solved: Vec<Solved> = solved.into_iter().collect::<Result<_>>()?;
    let largest = solved
        .iter()
        .map(|s| bound(s, &|b| b.face_mm))
        .fold(0.0, f64::max);
    let solves = solved
        .iter()
        .filter(|s| matches!(s.0, Face::Reduced(..)))
        .count();
    let trackers = trackers(analysis);
    let positions = soft_landmark_positions(run, reduced, &trackers, &solved);
    let at_landmarks = landmark_changes(&trackers, &positions, n);
    obs.started("uncertainty: the band per vertex");
    let regions = regions(analysis, skin);
    let members: Vec<&[bool]> = regions
        .as_ref()
        .map(|r| r.members.iter().flatten().map(Vec::as_slice).collect())
        .unwrap_or_default();
    let (bands, sums) = bands_and_region_sums(run, reduced, &solved, &members);
    let in_regions = region_means(regions.as_ref(), &sums);
    let mut report = assemble(Tallies {
        case,
        draws,
        bands: &bands,
        trackers: &trackers,
        at_landmarks: &at_landmarks,
        in_regions: &in_regions,
        solves,
        seconds: start.elapsed().as_secs_f64(),
        solve_s,
    });
    report.method = "reduced".into();
    report.largest_bound_mm = Some(largest);
    report.landmark_bounds_mm = Some(crate::landmarks::Ordered(landmark_bounds(
        &trackers, &solved,
    )));
    report.reduced = Some(reduced.reports.clone());
    obs.started("uncertainty: Sobol indices");
    report.sensitivity = Some(sensitivity(run, reduced, analysis, case, &trackers));
    let soft_positions = super::run::soft_positions(&trackers, positions);
    Ok(Sampled {
        bands,
        report,
        soft_positions,
    })
}

/// One sample's face and bounds (none for the nominal face, which is the run's own).
type Solved = (Face, Option<Bounds>);

/// Per draw, its reduced solve, or the nominal face where the draw solves as the run did.
fn solve_samples(
    run: &Nominal,
    reduced: &Reduced,
    case: &Case,
    draws: &[Draw],
) -> Vec<Result<Solved>> {
    let nominal = solve_key(case, run.sliding_matters);
    draws
        .par_iter()
        .map(|d| {
            let c = d.apply(case);
            if !run.moves || solve_key(&c, run.sliding_matters) == nominal {
                return Ok((Face::Nominal, None));
            }
            let (m, coefficients, bounds) = (reduced.solve)(&c)?;
            Ok((Face::Reduced(m, coefficients), Some(bounds)))
        })
        .collect()
}

/// A sample's bound `of` (zero for the nominal face).
fn bound(sample: &Solved, of: &dyn Fn(&Bounds) -> f64) -> f64 {
    sample.1.as_ref().map_or(0.0, of)
}

/// Face vertex `v`'s displacement on a sample's face.
fn displacement(run: &Nominal, reduced: &Reduced, face: &Face, v: usize) -> [f64; 3] {
    match face {
        Face::Nominal => sub(run.face_post[v], run.skin.vertices[v]),
        Face::Reduced(m, c) => reduced.faces[*m].at(v, c),
    }
}

/// Each soft landmark's position on each sample's face (None for the fixed landmarks).
/// (A reduced sample's landmark is corrected by its dual: the primal–dual output, whose
/// error the landmark bound certifies.)
fn soft_landmark_positions(
    run: &Nominal,
    reduced: &Reduced,
    trackers: &[(String, Tracker)],
    solved: &[Solved],
) -> Vec<Option<Vec<[f64; 3]>>> {
    let skin = run.skin;
    let mut soft = 0;
    trackers
        .iter()
        .map(|(_, t)| match t {
            Tracker::Soft(a, _) => {
                let k = soft;
                soft += 1;
                Some(
                    solved
                        .par_iter()
                        .map(|s| match s {
                            (Face::Nominal, _) => a.place(&skin.triangles, run.face_post),
                            (face @ Face::Reduced(..), b) => {
                                let disp = |v| displacement(run, reduced, face, v);
                                let on_face = place_on(skin, a, &disp);
                                corrected(on_face, b.as_ref(), k)
                            }
                        })
                        .collect(),
                )
            }
            Tracker::Fixed(_) => None,
        })
        .collect()
}

/// Per landmark, its change (mm) in each sample: a soft landmark's distance from its
/// pre-operative position, a fixed one's change as the run measured it.
fn landmark_changes(
    trackers: &[(String, Tracker)],
    positions: &[Option<Vec<[f64; 3]>>],
    n: usize,
) -> Vec<Vec<f64>> {
    trackers
        .iter()
        .zip(positions)
        .map(|((_, t), at)| match (t, at) {
            (Tracker::Soft(_, pre), Some(at)) => at.iter().map(|p| norm(sub(*p, *pre))).collect(),
            (Tracker::Fixed(m), _) => vec![*m; n],
            (Tracker::Soft(..), None) => unreachable!("a soft tracker has its positions"),
        })
        .collect()
}

/// The band per face vertex and, per present region (`members`), each sample's sum of its
/// vertices' displacement magnitudes: reduced in chunks of CHUNK vertices.
fn bands_and_region_sums(
    run: &Nominal,
    reduced: &Reduced,
    solved: &[Solved],
    members: &[&[bool]],
) -> (Vec<Band>, Vec<Vec<f64>>) {
    let skin = run.skin;
    let n = solved.len();
    let mut sums = vec![vec![0.0; n]; members.len()];
    let mut bands: Vec<Band> = Vec::with_capacity(skin.vertices.len());
    let still = still(run, reduced);
    const ZERO: Band = Band {
        mean: 0.0,
        p05: 0.0,
        p95: 0.0,
    };
    for lo in (0..skin.vertices.len()).step_by(CHUNK) {
        let hi = (lo + CHUNK).min(skin.vertices.len());
        let mags: Vec<Option<Vec<f64>>> = (lo..hi)
            .into_par_iter()
            .map(|v| {
                (!still[v]).then(|| {
                    (0..n)
                        .map(|s| norm(displacement(run, reduced, &solved[s].0, v)))
                        .collect()
                })
            })
            .collect();
        bands.par_extend(mags.par_iter().map(|m| m.as_deref().map_or(ZERO, Band::of)));
        // Region sums in vertex order, as the full path's (the nominal gives its figures).
        for (r, sum) in members.iter().zip(&mut sums) {
            sum.par_iter_mut().enumerate().for_each(|(s, acc)| {
                for v in lo..hi {
                    if let (true, Some(m)) = (r[v], &mags[v - lo]) {
                        *acc += m[s];
                    }
                }
            });
        }
    }
    (bands, sums)
}

/// Per region of `face_regions::NAMES`, each sample's mean displacement magnitude (empty for
/// an absent region), from the present regions' `sums`.
fn region_means(regions: Option<&Regions>, sums: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut in_regions: Vec<Vec<f64>> =
        vec![Vec::new(); crate::landmarks::face_regions::NAMES.len()];
    if let Some(r) = regions {
        let mut k = 0;
        for (i, m) in r.members.iter().enumerate() {
            if let Some(m) = m {
                let count = m.iter().filter(|b| **b).count() as f64;
                in_regions[i] = sums[k].iter().map(|x| x / count).collect();
                k += 1;
            }
        }
    }
    in_regions
}

/// Per soft landmark, the largest bound over the samples.
fn landmark_bounds(trackers: &[(String, Tracker)], solved: &[Solved]) -> Vec<(String, f64)> {
    let mut soft = 0;
    let mut per_landmark = Vec::new();
    for (label, t) in trackers {
        if let Tracker::Soft(..) = t {
            let k = soft;
            soft += 1;
            let b = solved
                .iter()
                .map(|s| bound(s, &|b| b.landmarks_mm[k]))
                .fold(0.0, f64::max);
            per_landmark.push((label.clone(), b));
        }
    }
    per_landmark
}

/// The anchor's position on a face of displacement `disp` per vertex (placed as on any face:
/// its triangle's corners moved).
fn place_on(
    skin: &crate::mesh::Mesh,
    a: &crate::landmarks::SurfaceAnchor,
    disp: &dyn Fn(usize) -> [f64; 3],
) -> [f64; 3] {
    let tri = skin.triangles[a.triangle as usize];
    let corners = tri.map(|v| {
        let (p, d) = (skin.vertices[v as usize], disp(v as usize));
        [p[0] + d[0], p[1] + d[1], p[2] + d[2]]
    });
    let local = crate::landmarks::SurfaceAnchor { triangle: 0, ..*a };
    local.place(&[[0, 1, 2]], &corners)
}

/// A reduced landmark position with its output's dual correction ψ_Nᵀ r added (the k-th soft
/// landmark; none for the nominal face, the run's own).
fn corrected(at: [f64; 3], bounds: Option<&Bounds>, k: usize) -> [f64; 3] {
    match bounds.and_then(|b| b.corrections.get(k)) {
        Some(c) => [at[0] + c[0], at[1] + c[1], at[2] + c[2]],
        None => at,
    }
}

/// Per face vertex: exactly still in every sample — no face field moves it and the nominal face
/// leaves it in place — so its displacement is zero, its band is zero and it adds zero to its
/// regions' sums (most of a face: the held skin and what lies beyond the modelled region).
fn still(run: &Nominal, reduced: &Reduced) -> Vec<bool> {
    (0..run.skin.vertices.len())
        .into_par_iter()
        .map(|v| {
            run.face_post[v] == run.skin.vertices[v] && reduced.faces.iter().all(|f| !f.moves(v))
        })
        .collect()
}

/// As [`sample_reduced`], from the reduced models a run stored (`reduced_model.bin`; `facesim
/// replan` with `[uncertainty]`): no mesh, no factorisation. `analysis` must hold the run's
/// landmarks in the run's order (the order of the models' landmark bounds).
pub(crate) fn sample_stored(
    run: &Nominal,
    stored: &crate::model::reduced::file::StoredReduced,
    analysis: &Analysis,
    case: &Case,
    obs: &dyn Observer,
) -> Result<Sampled> {
    let outputs = landmark_outputs(analysis, run.skin).len();
    if let Some(m) = stored
        .models
        .iter()
        .find(|m| m.output_bounds.len() != outputs)
    {
        return Err(crate::error::Error::config(format!(
            "the stored reduced model bounds {} landmarks, the run's report.json has {outputs} soft landmarks",
            m.output_bounds.len()
        )));
    }
    let solve = |c: &Case| stored.solve(c);
    let reduced = Reduced {
        faces: stored.models.iter().map(|m| &m.face).collect(),
        solve: &solve,
        reports: stored.models.iter().map(|m| m.report()).collect(),
    };
    sample_reduced(run, &reduced, analysis, case, obs)
}

/// A sample's face displacement per vertex.
type Displacement<'a> = Box<dyn Fn(usize) -> [f64; 3] + 'a>;

/// Rows of the Sobol matrices A and B: N (d + 2) reduced solves (d ≤ 4 parameters: ≤ 6144).
const SOBOL_BASE: usize = 1024;

/// The Sobol indices of each soft landmark's displacement magnitude and each region's mean
/// magnitude for the sampled parameters, on the reduced model.
fn sensitivity(
    run: &Nominal,
    reduced: &Reduced,
    analysis: &Analysis,
    case: &Case,
    trackers: &[(String, Tracker)],
) -> Sensitivity {
    let skin = run.skin;
    let params = case.uncertainty.parameters(case.solve.model);
    let d = params.len();
    let nominal = solve_key(case, run.sliding_matters);
    let soft: Vec<(&String, &crate::landmarks::SurfaceAnchor, [f64; 3])> = trackers
        .iter()
        .filter_map(|(l, t)| match t {
            Tracker::Soft(a, pre) => Some((l, a, *pre)),
            Tracker::Fixed(_) => None,
        })
        .collect();
    let regions = regions(analysis, skin);
    let members: Vec<(&str, Vec<usize>)> = regions
        .as_ref()
        .map(|r| {
            crate::landmarks::face_regions::NAMES
                .iter()
                .zip(&r.members)
                .filter_map(|(name, m)| {
                    let m = m.as_ref()?;
                    Some((*name, (0..m.len()).filter(|v| m[*v]).collect()))
                })
                .collect()
        })
        .unwrap_or_default();
    let f = |x: &[f64]| -> Vec<f64> {
        let c = draw_at(&params, &|k, _| x[k]).apply(case);
        let (disp, bounds): (Displacement, Option<Bounds>) =
            if !run.moves || solve_key(&c, run.sliding_matters) == nominal {
                (
                    Box::new(|v: usize| sub(run.face_post[v], skin.vertices[v])),
                    None,
                )
            } else {
                match (reduced.solve)(&c) {
                    Ok((m, coef, b)) => (
                        Box::new(move |v: usize| reduced.faces[m].at(v, &coef)),
                        Some(b),
                    ),
                    Err(_) => return vec![f64::NAN; soft.len() + members.len()],
                }
            };
        let mut out: Vec<f64> = soft
            .iter()
            .enumerate()
            .map(|(k, (_, a, pre))| {
                let at = corrected(place_on(skin, a, &disp), bounds.as_ref(), k);
                norm(sub(at, *pre))
            })
            .collect();
        out.extend(
            members
                .iter()
                .map(|(_, m)| m.iter().map(|v| norm(disp(*v))).sum::<f64>() / m.len() as f64),
        );
        out
    };
    let got = indices(d, SOBOL_BASE, case.uncertainty.seed, &f);
    let names: Vec<String> = params.iter().map(|(p, _)| p.key().to_string()).collect();
    let table = |i: Option<&Vec<Index>>| {
        i.map(|v| Ordered(names.iter().cloned().zip(v.iter().copied()).collect()))
    };
    let labels = soft.iter().map(|s| s.0.clone());
    let regions = members.iter().map(|m| m.0.to_string());
    let mut lm = Vec::new();
    let mut rg = Vec::new();
    for (k, name) in labels.chain(regions).enumerate() {
        if let Some(t) = table(got[k].as_ref()) {
            if k < soft.len() {
                lm.push((name, t));
            } else {
                rg.push((name, t));
            }
        }
    }
    Sensitivity {
        base_samples: SOBOL_BASE,
        evaluations: SOBOL_BASE * (d + 2),
        estimator: "Saltelli et al. 2010 first order, Jansen 1999 total; scrambled Halton A, B"
            .into(),
        landmarks: Ordered(lm),
        regions: Ordered(rg),
    }
}

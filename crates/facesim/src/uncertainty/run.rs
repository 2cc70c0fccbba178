//! Sampling a run's tissue parameters (docs/guide/uncertainty.md): draw N parameter sets from the
//! scrambled Halton sequence, solve each on what the run already built, and reduce the face's
//! displacement magnitudes to the band per vertex, landmark and region.

use super::band::{self, Band};
use super::sample::ScrambledHalton;
use crate::case::Case;
use crate::case::uncertainty::{Distribution, Parameter};
use crate::error::Result;
use crate::landmarks::{Analysis, Kind, Ordered, SurfaceAnchor, face_regions};
use crate::mesh::Mesh;
use crate::observe::Observer;
use crate::vec3::{norm, sub};
use serde::{Deserialize, Serialize};

/// One sample's parameters (those the model samples; the others are absent).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Draw {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub poisson: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub muscle_fat: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skin_fat: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sliding: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spring_scale: Option<f64>,
}

impl Draw {
    /// The nominal case with this sample's parameters: ν for every soft tissue, muscle and skin
    /// moduli as ratios to the (dark) fat's, which stays (with the moduli's scale: with bone moves
    /// as the only load, a uniform scale of every modulus leaves the displacement unchanged, so
    /// only ratios are sampled); the spring scale multiplies `k_c` and `koch_k_c`.
    pub fn apply(&self, nominal: &Case) -> Case {
        let mut c = nominal.clone();
        let t = &mut c.tet;
        if let Some(nu) = self.poisson {
            for m in t.tissues_mut() {
                m.poisson = nu;
            }
        }
        let fat = t.fat_dark.youngs_kpa;
        if let Some(r) = self.muscle_fat {
            t.muscle.youngs_kpa = r * fat;
        }
        if let Some(r) = self.skin_fat {
            t.skin.youngs_kpa = r * fat;
        }
        if let Some(s) = self.sliding {
            t.sliding = s;
        }
        if let Some(s) = self.spring_scale {
            c.solve.k_c *= s;
            c.solve.koch_k_c *= s;
        }
        c
    }
}

/// The draws of `samples` points of the sequence.
pub fn draws(case: &Case) -> Vec<Draw> {
    let u = &case.uncertainty;
    let params = u.parameters(case.solve.model);
    let seq = ScrambledHalton::new(Parameter::ALL.len(), u.seed);
    (0..u.samples as u64)
        .map(|i| draw_at(&params, &|_, p| seq.at(i, p.dimension())))
        .collect()
}

/// The draw whose parameter k of `params` (a parameter and its distribution) sits at
/// `x(k, parameter)` ∈ [0, 1) of its distribution.
pub(super) fn draw_at(
    params: &[(Parameter, Distribution)],
    x: &dyn Fn(usize, Parameter) -> f64,
) -> Draw {
    let mut d = Draw::default();
    for (k, (p, dist)) in params.iter().enumerate() {
        let x = x(k, *p);
        match (p, dist) {
            (Parameter::Sliding, Distribution::Chance(c)) => d.sliding = Some(x < c.probability),
            (Parameter::Poisson, Distribution::Range(r)) => d.poisson = Some(r.at(x)),
            (Parameter::MuscleFat, Distribution::Range(r)) => d.muscle_fat = Some(r.at(x)),
            (Parameter::SkinFat, Distribution::Range(r)) => d.skin_fat = Some(r.at(x)),
            (Parameter::SpringScale, Distribution::Range(r)) => d.spring_scale = Some(r.at(x)),
            _ => {}
        }
    }
    d
}

/// Points the reduced model's greedy trains on: 128 draws of the case's `[uncertainty]` box
/// from another seed than the samples' (so the samples test it; docs/design/reduced.md), and the box's
/// corners. Every Lamé parameter is monotone in each sampled parameter, so the corners span the
/// box's image in θ: the trained box the reduced model answers in.
pub fn training(case: &Case) -> Vec<Case> {
    let mut c = case.clone();
    c.uncertainty.samples = TRAINING_POINTS;
    c.uncertainty.seed = case.uncertainty.seed.wrapping_add(TRAINING_SEED_OFFSET);
    let params = case.uncertainty.parameters(case.solve.model);
    let corners =
        (0..1usize << params.len()).map(|i| draw_at(&params, &|k, _| ((i >> k) & 1) as f64));
    draws(&c)
        .into_iter()
        .chain(corners)
        .map(|d| d.apply(case))
        .collect()
}

const TRAINING_POINTS: usize = 128;
const TRAINING_SEED_OFFSET: u64 = 1_000_003;

/// What decides a solve's answer among the sampled parameters, as bits: equal keys, equal
/// displacement. Sliding is left out when the mesh has no mucosa node (it then holds nothing).
pub(super) fn solve_key(c: &Case, sliding_matters: bool) -> Vec<u64> {
    let t = &c.tet;
    let mut k: Vec<u64> = [t.skin, t.muscle, t.fat_dark, t.fat_bright]
        .iter()
        .flat_map(|m| [m.youngs_kpa.to_bits(), m.poisson.to_bits()])
        .collect();
    k.push(u64::from(t.sliding && sliding_matters));
    k.push(c.solve.k_c.to_bits());
    k.push(c.solve.koch_k_c.to_bits());
    k
}

/// report.json `uncertainty` (docs/guide/uncertainty.md).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct UncertaintyReport {
    pub samples: usize,
    pub seed: u64,
    pub model: String,
    /// "full" (a solve per distinct sample) or "reduced" (the certified reduced model).
    #[serde(default = "full")]
    pub method: String,
    pub sequence: String,
    /// Parameter → its distribution as used (given in case.toml or the default).
    pub parameters: Ordered<Distribution>,
    /// Per sample, the parameters drawn.
    pub draws: Vec<Draw>,
    /// Solves run; the other samples equalled the nominal parameters or an earlier sample.
    pub solves: usize,
    pub reused: usize,
    pub seconds: f64,
    pub seconds_per_sample: f64,
    pub seconds_per_solve: Option<f64>,
    /// Over the face's vertices: the largest p95, and the mean and largest band width p95 − p05.
    pub face: FaceSummary,
    /// Landmark label → band of its displacement magnitude (mm); only landmarks found.
    pub landmarks: Ordered<Band>,
    /// Region → band of the region's mean displacement magnitude (mm); only regions present.
    pub regions: Ordered<Band>,
    /// The reduced method: the largest certified bound (mm) on any sample's face error (the
    /// Euclidean norm over the face's vertices, so every vertex's too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub largest_bound_mm: Option<f64>,
    /// The reduced method: per soft landmark, the largest certified bound (mm) on its
    /// displacement's error over the samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landmark_bounds_mm: Option<Ordered<f64>>,
    /// The reduced method: Sobol indices per landmark and region for each parameter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity: Option<super::sensitivity::Sensitivity>,
    /// The reduced method: how each reduced model was built (one per sliding state).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reduced: Option<Vec<crate::reduced::ReducedReport>>,
}

fn full() -> String {
    "full".into()
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FaceSummary {
    pub vertices: usize,
    pub max_p95: f64,
    pub mean_width: f64,
    pub max_width: f64,
}

/// The band per face vertex (face_post's order) and the report.
pub struct Sampled {
    pub bands: Vec<Band>,
    pub report: UncertaintyReport,
    /// Per soft landmark (label), its position on each sample's face, in the samples' order:
    /// what report.json `published_ratios` bands are measured from.
    pub soft_positions: Vec<(String, Vec<[f64; 3]>)>,
}

/// The soft landmarks' positions per sample, from the trackers' columns (`positions[t][s]`;
/// None for a bony landmark's tracker).
pub(super) fn soft_positions(
    trackers: &[(String, Tracker)],
    positions: Vec<Option<Vec<[f64; 3]>>>,
) -> Vec<(String, Vec<[f64; 3]>)> {
    trackers
        .iter()
        .zip(positions)
        .filter_map(|((label, _), p)| Some((label.clone(), p?)))
        .collect()
}

/// A landmark on the samples' faces: a soft one as the same material point as report.json
/// `landmarks` carries it (its anchor on face_pre and its position before), a bony one moves
/// with its segment whatever the tissue (its move in the run).
pub(super) enum Tracker {
    Soft(SurfaceAnchor, [f64; 3]),
    Fixed(f64),
}

/// The run's landmarks (analysis of face_pre) as the samples measure them.
pub(super) fn trackers(analysis: &Analysis) -> Vec<(String, Tracker)> {
    analysis
        .carried
        .iter()
        .zip(&analysis.anchors)
        .filter_map(|(c, anchor)| {
            let pre = c.pre?;
            let t = match (c.kind, anchor) {
                (Kind::Soft, Some(a)) => Tracker::Soft(*a, pre),
                _ => Tracker::Fixed(c.change_mm.unwrap_or(0.0)),
            };
            Some((c.label.clone(), t))
        })
        .collect()
}

/// The run's facial regions on face_pre (None without a head frame).
pub(super) fn regions(analysis: &Analysis, skin: &Mesh) -> Option<face_regions::Regions> {
    analysis.frame.as_ref().map(|f| {
        face_regions::regions(
            &skin.vertices,
            f,
            &crate::landmarks::positions(&analysis.landmarks),
        )
    })
}

/// The run's prediction as the samples see it.
pub struct Nominal<'a> {
    /// The face before (face_pre) and the run's predicted positions, same vertex order.
    pub skin: &'a Mesh,
    pub face_post: &'a [[f64; 3]],
    /// Whether the run moved anything (else every sample is the pre-operative face).
    pub moves: bool,
    /// Whether `[tet] sliding` can change the answer (the mesh has mucosa nodes).
    pub sliding_matters: bool,
    /// How many full solves to run side by side (`crate::model::Prediction::solves_at_once`).
    pub solves_at_once: usize,
}

/// Sample the tissue parameters `case.uncertainty.samples` times (at least one): `resolve`
/// gives the face's positions for a case with other tissue parameters (the model's re-solve on
/// what the run built, `crate::model::Prediction::resolve`).
pub fn sample(
    run: &Nominal,
    resolve: &(dyn Fn(&Case) -> Result<Vec<[f64; 3]>> + Sync),
    analysis: &Analysis,
    case: &Case,
    obs: &dyn Observer,
) -> Result<Sampled> {
    let n = case.uncertainty.samples;
    let start = std::time::Instant::now();
    let skin = run.skin;
    // Positions, not displacements, so that the nominal sample gives the run's own figures
    // bit for bit (report.json's are computed from face_pre and face_post).
    let nominal = run.face_post;
    let draws = draws(case);
    let sliding_matters = run.sliding_matters;
    let nominal_key = solve_key(case, sliding_matters);
    // Landmarks and regions of the run (analysis of face_pre), measured on every sample.
    let trackers = trackers(analysis);
    let regions = regions(analysis, skin);
    // The distinct solves the draws need (a draw that changes nothing the model reads reuses
    // the nominal face or an earlier draw's), in draw order.
    // Per draw, which of them answers it (None: the nominal face).
    let mut wanted: Vec<(Vec<u64>, Case)> = Vec::new();
    let mut answer: Vec<Option<usize>> = Vec::with_capacity(draws.len());
    for d in &draws {
        let c = d.apply(case);
        let key = solve_key(&c, sliding_matters);
        answer.push(if !run.moves || key == nominal_key {
            None
        } else if let Some(k) = wanted.iter().position(|(w, _)| *w == key) {
            Some(k)
        } else {
            wanted.push((key, c));
            Some(wanted.len() - 1)
        });
    }
    let (solved, solve_s) = solve_side_by_side(&wanted, run.solves_at_once, resolve, obs)?;
    let mut magnitudes: Vec<Vec<f64>> = Vec::with_capacity(n);
    let mut at_landmarks: Vec<Vec<f64>> = vec![Vec::with_capacity(n); trackers.len()];
    let mut positions: Vec<Option<Vec<[f64; 3]>>> = trackers
        .iter()
        .map(|(_, t)| matches!(t, Tracker::Soft(..)).then(|| Vec::with_capacity(n)))
        .collect();
    let mut in_regions: Vec<Vec<f64>> = vec![Vec::with_capacity(n); face_regions::NAMES.len()];
    for a in &answer {
        let post: &[[f64; 3]] = a.map_or(nominal, |k| &solved[k]);
        // As outputs::displacement and report.json: |face_pre − face_post| per vertex.
        let mag: Vec<f64> = skin
            .vertices
            .iter()
            .zip(post)
            .map(|(a, b)| norm(sub(*a, *b)))
            .collect();
        for (((_, t), out), at) in trackers.iter().zip(&mut at_landmarks).zip(&mut positions) {
            out.push(match t {
                Tracker::Soft(a, pre) => {
                    let p = a.place(&skin.triangles, post);
                    if let Some(at) = at {
                        at.push(p);
                    }
                    norm(sub(p, *pre))
                }
                Tracker::Fixed(m) => *m,
            });
        }
        if let Some(r) = &regions {
            for (members, out) in r.members.iter().zip(&mut in_regions) {
                if let Some(m) = members {
                    // As report.json `regions` `mean`: the sum over the members / their count.
                    let v: Vec<f64> = m
                        .iter()
                        .zip(&mag)
                        .filter(|(b, _)| **b)
                        .map(|(_, x)| *x)
                        .collect();
                    out.push(v.iter().sum::<f64>() / v.len() as f64);
                }
            }
        }
        magnitudes.push(mag);
    }
    let bands = band::per_vertex(&magnitudes, skin.vertices.len());
    let report = assemble(Tallies {
        case,
        draws,
        bands: &bands,
        trackers: &trackers,
        at_landmarks: &at_landmarks,
        in_regions: &in_regions,
        solves: solved.len(),
        seconds: start.elapsed().as_secs_f64(),
        solve_s,
    });
    let soft_positions = soft_positions(&trackers, positions);
    Ok(Sampled {
        bands,
        report,
        soft_positions,
    })
}

/// Solve `wanted` (in order) `at_once` at a time on the thread pool: the faces, and the
/// solves' summed time (s).
fn solve_side_by_side(
    wanted: &[(Vec<u64>, Case)],
    at_once: usize,
    resolve: &(dyn Fn(&Case) -> Result<Vec<[f64; 3]>> + Sync),
    obs: &dyn Observer,
) -> Result<(Vec<Vec<[f64; 3]>>, f64)> {
    use rayon::prelude::*;
    let mut solved = Vec::with_capacity(wanted.len());
    let mut seconds = 0.0;
    for chunk in wanted.chunks(at_once.max(1)) {
        obs.started(&format!(
            "uncertainty: solve {} of {}",
            solved.len() + chunk.len(),
            wanted.len()
        ));
        let faces: Vec<(Vec<[f64; 3]>, f64)> = chunk
            .par_iter()
            .map(|(_, c)| {
                let t = std::time::Instant::now();
                resolve(c).map(|u| (u, t.elapsed().as_secs_f64()))
            })
            .collect::<Result<_>>()?;
        for (u, s) in faces {
            solved.push(u);
            seconds += s;
        }
    }
    Ok((solved, seconds))
}

/// What a sampling measured, for the report.
pub(super) struct Tallies<'a> {
    pub case: &'a Case,
    pub draws: Vec<Draw>,
    pub bands: &'a [Band],
    pub trackers: &'a [(String, Tracker)],
    pub at_landmarks: &'a [Vec<f64>],
    pub in_regions: &'a [Vec<f64>],
    /// Model solves (full or reduced) and their time.
    pub solves: usize,
    pub seconds: f64,
    pub solve_s: f64,
}

/// report.json `uncertainty` of a sampling (the full path's fields; the reduced path adds its).
pub(super) fn assemble(t: Tallies) -> UncertaintyReport {
    let (case, n) = (t.case, t.case.uncertainty.samples);
    let widths: Vec<f64> = t.bands.iter().map(Band::width).collect();
    UncertaintyReport {
        samples: n,
        seed: case.uncertainty.seed,
        model: case.solve.model.name().into(),
        method: "full".into(),
        sequence: "scrambled Halton (bases 2, 3, 5, 7, 11; random digit permutations)".into(),
        parameters: Ordered(
            case.uncertainty
                .parameters(case.solve.model)
                .into_iter()
                .map(|(p, d)| (p.key().to_string(), d))
                .collect(),
        ),
        solves: t.solves,
        reused: n - t.solves,
        seconds: t.seconds,
        seconds_per_sample: t.seconds / n as f64,
        seconds_per_solve: (t.solves > 0).then(|| t.solve_s / t.solves as f64),
        face: FaceSummary {
            vertices: t.bands.len(),
            max_p95: t.bands.iter().map(|b| b.p95).fold(0.0, f64::max),
            mean_width: band::mean(&widths),
            max_width: widths.iter().cloned().fold(0.0, f64::max),
        },
        landmarks: Ordered(
            t.trackers
                .iter()
                .zip(t.at_landmarks)
                .map(|((l, _), v)| (l.clone(), Band::of(v)))
                .collect(),
        ),
        regions: Ordered(
            face_regions::NAMES
                .iter()
                .zip(t.in_regions)
                .filter(|(_, v)| !v.is_empty())
                .map(|(name, v)| (name.to_string(), Band::of(v)))
                .collect(),
        ),
        draws: t.draws,
        largest_bound_mm: None,
        landmark_bounds_mm: None,
        sensitivity: None,
        reduced: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Error;

    /// A stand-in for a model's re-solve: a face that says which case it was solved for.
    fn face_of(c: &Case) -> Result<Vec<[f64; 3]>> {
        let e = c.tet.skin.youngs_kpa;
        if e < 0.0 {
            return Err(Error::config(format!("no solve at {e} kPa")));
        }
        Ok(vec![[e, 2.0 * e, 3.0 * e]; 5])
    }

    fn wanted(moduli: &[f64]) -> Vec<(Vec<u64>, Case)> {
        moduli
            .iter()
            .map(|e| {
                let mut c = Case::default();
                c.tet.skin.youngs_kpa = *e;
                (vec![e.to_bits()], c)
            })
            .collect()
    }

    /// Side by side or one at a time, each face is the one of its own case, in the draws' order,
    /// and a failed solve fails the sampling.
    #[test]
    fn solves_side_by_side_keep_each_face_with_its_case() {
        let w = wanted(&[31.0, 12.0, 47.0, 5.0, 18.0]);
        for at_once in [1, 2, 3, 8] {
            let (faces, _) = solve_side_by_side(&w, at_once, &face_of, &crate::observe::Quiet)
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(faces.len(), w.len());
            for (f, (_, c)) in faces.iter().zip(&w) {
                assert_eq!(
                    f[0],
                    [
                        c.tet.skin.youngs_kpa,
                        2.0 * c.tet.skin.youngs_kpa,
                        3.0 * c.tet.skin.youngs_kpa
                    ]
                );
            }
        }
        let bad = wanted(&[31.0, 12.0, -1.0, 5.0]);
        for at_once in [1, 2, 4] {
            let r = solve_side_by_side(&bad, at_once, &face_of, &crate::observe::Quiet);
            assert!(matches!(r, Err(Error::Config(ref m)) if m.contains("-1 kPa")));
        }
    }
}

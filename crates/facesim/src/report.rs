//! report.json as types, both ways (docs/reference/case.md: parameters, per-stage `timings`, counts, the
//! displacement summary, warnings): every section is a struct, `assemble` is the one place a
//! report is built (for a run and for `facesim replan`), [`Report::read`] the one place a report
//! is read back. Stage costs are kept in pipeline order (`pipeline::stage`).

use crate::case::{Case, Osteotomy};
use crate::error::{Error, Result};
use crate::landmarks::clinic::Clinic;
use crate::landmarks::face_regions::RegionStats;
use crate::landmarks::measure::{Measure, Ratio};
use crate::landmarks::{Analysis, Carried, HeadFrame, Landmark, Ordered};
use crate::model::TetReport;
use crate::pipeline::stage::{Costs, Skipped};
use crate::pipeline::surfaces::SurfaceReport;
use crate::plan::PlanBasis;
use crate::segment::SegmentReport;
use crate::solve::StepRecord;
use crate::springs::SpringReport;
use crate::surface::register::Transform;
use crate::uncertainty::UncertaintyReport;
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Counts {
    pub voxels: usize,
    pub dims: [usize; 3],
    pub skin_vertices: usize,
    pub skin_triangles: usize,
    pub skull_vertices: usize,
    pub skull_triangles: usize,
    pub springs_main: usize,
    pub springs_strut: usize,
    /// Free unknowns of the solved system (0 when nothing was solved).
    pub unknowns: usize,
    /// Skin vertices in the mesh the equations were assembled on.
    pub solved_vertices: usize,
    /// The process's peak resident set (MB) at the end of the run.
    pub max_rss_mb: f64,
}

/// |x_post − x_pre| over the skin (mm), and the colour scale of face_displacement.ply.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Displacement {
    pub max: f64,
    pub mean: f64,
    pub colour_scale_mm: [f64; 2],
    pub colour_map: String,
    /// The face's edge where the displacement changes most per mm (`skin_jump`): a crease or
    /// tear shows here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub largest_jump: Option<crate::skin_jump::Jump>,
}

#[derive(Debug, Default, Serialize, Deserialize)]
pub struct Report {
    pub name: String,
    pub case: String,
    pub facesim_version: String,
    #[serde(flatten)]
    pub costs: Costs,
    pub counts: Counts,
    pub segmentation: Option<SegmentReport>,
    pub surfaces: SurfaceReport,
    pub registration: Option<Transform>,
    pub parameters: Option<Case>,
    pub springs: Option<SpringReport>,
    pub solve: Option<Vec<StepRecord>>,
    /// The volumetric model (`[solve] model = "tet"`).
    pub tet: Option<TetReport>,
    pub displacement: Displacement,
    /// The plan basis written with the outputs (docs/design/plan-basis.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plan_basis: Option<BasisReport>,
    /// Set by `facesim replan`: where the basis came from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replan: Option<ReplanReport>,
    /// The head frame the landmarks were found in (docs/guide/landmarks.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head_frame: Option<HeadFrame>,
    /// The clinical head frame the plan is read in: how it was found (docs/guide/planning.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clinical_frame: Option<crate::anatomy::readback::FrameReport>,
    /// The plan in the surgeon's terms: per segment its six moves in the clinical frame, per
    /// bony landmark its move forward, up and left (docs/guide/planning.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<crate::anatomy::readback::PlanReport>,
    /// Label → pre, post (LPS mm), change_mm; a missing landmark says why.
    pub landmarks: Ordered<Carried>,
    /// Nasolabial and mentolabial angles, lips to the E-line: before, after, change.
    pub measurements: Ordered<Measure>,
    /// Soft over hard tissue anterior movement per landmark pair (e.g. Pog'/Pog).
    pub soft_hard_ratios: Ordered<Ratio>,
    /// The plan read as a surgery type of the published table, and its ratios as predicted beside
    /// the published ranges and sources (`landmarks::clinic`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub published_ratios: Option<Clinic>,
    /// Region → vertices, mean, p90, max of the displacement (mm).
    pub regions: Ordered<RegionStats>,
    /// `[uncertainty] samples > 0`: the band per landmark and region (docs/guide/uncertainty.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<UncertaintyReport>,
    /// The volumetric model's estimated discretisation error on the face, per region
    /// (`model::discretisation`; `[tet] error_estimate`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discretisation_error: Option<crate::model::discretisation::DiscretisationError>,
    /// `[tet] material = "neo-hookean"`: how far its face lies from the linear model's, per
    /// region (`model::discretisation::nonlinear_vs_linear`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nonlinear_vs_linear: Option<crate::model::discretisation::ModelDifference>,
    pub warnings: Vec<String>,
    /// Optional stages this case did not need (no plan → no solve, a skin solved as given → no
    /// coarsening or embedding, ...).
    pub stages_not_run: Vec<Skipped>,
}

/// report.json's `plan_basis` section.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BasisReport {
    pub file: String,
    pub model: String,
    pub exact: bool,
    pub segments: Vec<String>,
    pub columns_per_segment: usize,
    /// See [`PlanBasis::run_plan_error_mm`].
    pub run_plan_error_mm: f64,
    pub warnings: Vec<String>,
}

impl BasisReport {
    /// The summary of `b` a report carries.
    pub(crate) fn of(b: &PlanBasis) -> BasisReport {
        BasisReport {
            file: crate::plan::file::FILE_NAME.into(),
            model: b.model.clone(),
            exact: b.exact,
            segments: b.segments.iter().map(|s| s.name.clone()).collect(),
            columns_per_segment: crate::plan::basis::COLUMNS,
            run_plan_error_mm: b.run_plan_error_mm,
            warnings: b.warnings.clone(),
        }
    }
}

/// report.json's `replan` section (a report written by `facesim replan`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReplanReport {
    /// The run's output directory the basis came from.
    pub from: String,
    /// The plan file.
    pub plan: String,
    pub basis_model: String,
    pub exact: bool,
    /// The plan predicted.
    pub osteotomy: Vec<Osteotomy>,
    /// With `[tet]` in PLAN.toml: the tissues answered by the run's reduced model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tissue: Option<TissueReplan>,
}

/// report.json `replan.tissue`: new tissue parameters answered by the stored reduced model at the
/// run's plan (docs/design/reduced.md "Re-solving from the stored model").
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TissueReplan {
    /// Per tissue (`[tet.skin]` …) the material used.
    pub materials: Vec<(String, crate::case::TissueElastic)>,
    pub sliding: bool,
    /// The certified bound on the face's difference from the full model's (mm; the Euclidean
    /// norm over all face vertices, so every vertex too).
    pub bound_mm: f64,
    pub relative_energy_bound: f64,
}

impl Displacement {
    /// The summary of per-vertex displacement magnitudes `dist` (mm).
    pub(crate) fn of(dist: &[f64]) -> Displacement {
        let max = dist.iter().cloned().fold(0.0, f64::max);
        Displacement {
            max,
            mean: dist.iter().sum::<f64>() / dist.len().max(1) as f64,
            colour_scale_mm: [0.0, max],
            colour_map: "viridis".into(),
            largest_jump: None,
        }
    }
}

/// The sections only a run has, as its stages made them (a replan's report leaves them empty).
pub(crate) struct RunSections {
    pub costs: Costs,
    pub counts: Counts,
    pub segmentation: SegmentReport,
    pub surfaces: SurfaceReport,
    pub registration: Option<Transform>,
    pub parameters: Case,
    pub springs: Option<SpringReport>,
    pub solve: Option<Vec<StepRecord>>,
    pub tet: Option<TetReport>,
    pub plan_basis: Option<BasisReport>,
    pub uncertainty: Option<UncertaintyReport>,
    pub stages_not_run: Vec<Skipped>,
}

/// The report of a run (`run`) or a replan (`replan`): `name` and `case` name the case, `dist`
/// is the face's displacement magnitude per vertex, `analysis` the landmark stage's answer.
pub(crate) fn assemble(
    name: String,
    case: String,
    run: Option<RunSections>,
    dist: &[f64],
    analysis: Option<&Analysis>,
    replan: Option<ReplanReport>,
    warnings: Vec<String>,
) -> Report {
    let mut r = Report {
        name,
        case,
        facesim_version: env!("CARGO_PKG_VERSION").into(),
        displacement: Displacement::of(dist),
        replan,
        warnings,
        ..Default::default()
    };
    if let Some(s) = run {
        r.costs = s.costs;
        r.counts = s.counts;
        r.segmentation = Some(s.segmentation);
        r.surfaces = s.surfaces;
        r.registration = s.registration;
        r.parameters = Some(s.parameters);
        r.springs = s.springs;
        r.solve = s.solve;
        r.tet = s.tet;
        r.plan_basis = s.plan_basis;
        r.uncertainty = s.uncertainty;
        r.stages_not_run = s.stages_not_run;
    }
    if let Some(a) = analysis {
        r.head_frame = a.frame;
        r.landmarks = Ordered(
            a.carried
                .iter()
                .map(|c| (c.label.clone(), c.clone()))
                .collect(),
        );
        r.measurements = a.measurements.clone();
        r.soft_hard_ratios = a.ratios.clone();
        r.published_ratios = a.clinic.clone();
        r.regions = a.regions.clone();
    }
    r
}

impl Report {
    /// The report.json at `path`. Missing, unreadable or not a report of this form is an error
    /// naming the file (the parser's message carries the line and column).
    pub fn read(path: &Path) -> Result<Report> {
        let bytes = std::fs::read(path).map_err(|e| {
            Error::input(
                path,
                if e.kind() == std::io::ErrorKind::NotFound {
                    "not found — run `facesim run` on the case first".to_string()
                } else {
                    e.to_string()
                },
            )
        })?;
        serde_json::from_slice(&bytes).map_err(|e| Error::input(path, format!("not a report: {e}")))
    }

    /// The landmarks (and head frame) the run found, as located on its pre-operative face, in
    /// label order; None for a report without landmarks. Label order is the order replan's
    /// report and markups and sweep's columns have always had (the report used to be read
    /// back through a sorted JSON map).
    pub(crate) fn located_landmarks(&self) -> Option<(Option<HeadFrame>, Vec<Landmark>)> {
        if self.landmarks.0.is_empty() {
            return None;
        }
        let mut lms: Vec<Landmark> = self
            .landmarks
            .0
            .iter()
            .map(|(label, c)| Landmark {
                label: label.clone(),
                kind: c.kind,
                position: c.pre,
                source: c.source,
                missing: c.missing.clone(),
            })
            .collect();
        lms.sort_by(|a, b| a.label.cmp(&b.label));
        Some((self.head_frame, lms))
    }

    /// [`Report::located_landmarks`] in the run's order (report.json's): the order of the
    /// landmarks the run carried and of the reduced model's landmark bounds.
    pub fn located_in_run_order(&self) -> Option<(Option<HeadFrame>, Vec<Landmark>)> {
        let (frame, mut lms) = self.located_landmarks()?;
        let order: Vec<&String> = self.landmarks.0.iter().map(|(l, _)| l).collect();
        lms.sort_by_key(|l| order.iter().position(|x| **x == l.label));
        Some((frame, lms))
    }
}

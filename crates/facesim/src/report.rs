//! report.json as types (docs/case.md: parameters, per-stage `timings`, counts, the displacement
//! summary, warnings). Every section is a struct; stage costs are kept in pipeline order.

use crate::case::Case;
use crate::compare::DistanceStats;
use crate::meter::StageCost;
use crate::segment::SegmentReport;
use crate::solve::StepRecord;
use crate::springs::SpringReport;
use crate::surface::register::Transform;
use serde::Serialize;
use serde::ser::{SerializeMap, Serializer};

/// A pipeline stage, named in report.json's `timings` and `stage_costs` by [`Stage::key`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    ReadCt,
    Segment,
    Surfaces,
    SmoothDecimate,
    ReadScan,
    PlaceScan,
    Coarsen,
    Springs,
    TetMesh,
    Solve,
    Embed,
    /// The plan basis: 12 solves per segment on the run's factor (docs/plan-basis.md).
    PlanBasis,
    /// Landmarks, measurements and regions (docs/landmarks.md).
    Landmarks,
    /// Sampling the tissue parameters (docs/uncertainty.md).
    Uncertainty,
    Write,
    Total,
}

impl Stage {
    pub fn key(self) -> &'static str {
        match self {
            Stage::ReadCt => "read_ct",
            Stage::Segment => "segment",
            Stage::Surfaces => "surfaces",
            Stage::SmoothDecimate => "smooth_decimate",
            Stage::ReadScan => "read_scan",
            Stage::PlaceScan => "place_scan",
            Stage::Coarsen => "coarsen",
            Stage::Springs => "springs",
            Stage::TetMesh => "tet_mesh",
            Stage::Solve => "solve",
            Stage::Embed => "embed",
            Stage::PlanBasis => "plan_basis",
            Stage::Landmarks => "landmarks",
            Stage::Uncertainty => "uncertainty",
            Stage::Write => "write",
            Stage::Total => "total",
        }
    }
}

/// Stage costs in the order the stages ran; written as two maps, `timings` (stage → wall
/// seconds) and `stage_costs` (stage → wall, CPU, peak heap).
#[derive(Clone, Debug, Default)]
pub struct Costs(pub Vec<(Stage, StageCost)>);

impl Costs {
    pub fn get(&self, stage: Stage) -> Option<&StageCost> {
        self.0.iter().find(|(s, _)| *s == stage).map(|(_, c)| c)
    }
    /// Wall seconds of `stage` (0 when it did not run).
    pub fn wall_s(&self, stage: Stage) -> f64 {
        self.get(stage).map_or(0.0, |c| c.wall_s)
    }
}

impl Serialize for Costs {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        struct Walls<'a>(&'a [(Stage, StageCost)]);
        impl Serialize for Walls<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut m = s.serialize_map(Some(self.0.len()))?;
                for (k, c) in self.0 {
                    m.serialize_entry(k.key(), &c.wall_s)?;
                }
                m.end()
            }
        }
        struct Full<'a>(&'a [(Stage, StageCost)]);
        impl Serialize for Full<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut m = s.serialize_map(Some(self.0.len()))?;
                for (k, c) in self.0 {
                    m.serialize_entry(k.key(), c)?;
                }
                m.end()
            }
        }
        let mut m = s.serialize_map(Some(2))?;
        m.serialize_entry("timings", &Walls(&self.0))?;
        m.serialize_entry("stage_costs", &Full(&self.0))?;
        m.end()
    }
}

#[derive(Clone, Debug, Default, Serialize)]
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

/// How the skin and skull were made, and what was dropped or changed on the way.
#[derive(Clone, Debug, Default, Serialize)]
pub struct SurfaceReport {
    /// "rangescan" or "marching".
    pub method: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rays: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skin_misses: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skull_misses: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub axis_xy: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub r0: Option<f64>,
    pub skin_islands_dropped: usize,
    pub skull_islands_dropped: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skin_decimation_error_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skull_decimation_error_mm: Option<f64>,
    pub extracted_skin_components: usize,
    pub skull_components: usize,
    /// A given face scan's distance to the CT's skin.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scan_to_ct_skin_mm: Option<DistanceStats>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coarse: Option<CoarseReport>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub embedding: Option<EmbeddingReport>,
    /// A given skin that was not a clean face (another program's iso-surface): what keeping
    /// its outer face dropped (surface::outer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub foreign_skin: Option<crate::surface::outer::OuterReport>,
}

/// The coarse copy a dense skin was solved on (`[solve] coarse_triangles`).
#[derive(Clone, Debug, Serialize)]
pub struct CoarseReport {
    pub triangles: usize,
    pub vertices: usize,
    pub fine_triangles: usize,
    pub fine_vertices: usize,
}

/// The shell embedding that carried the full skin along the coarse answer.
#[derive(Clone, Debug, Serialize)]
pub struct EmbeddingReport {
    pub shell_mm: f64,
    pub poisson: f64,
    pub fine_to_coarse_mm: DistanceStats,
}

/// |x_post − x_pre| over the skin (mm), and the colour scale of face_displacement.ply.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Displacement {
    pub max: f64,
    pub mean: f64,
    pub colour_scale_mm: [f64; 2],
    pub colour_map: &'static str,
}

/// A stage that did not run for this case, and why.
#[derive(Clone, Debug, Serialize, PartialEq, Eq)]
pub struct Skipped {
    pub stage: &'static str,
    pub reason: String,
}

#[derive(Debug, Default, Serialize)]
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
    pub tet: Option<crate::model::TetReport>,
    pub displacement: Displacement,
    /// The plan basis written with the outputs (docs/plan-basis.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plan_basis: Option<crate::plan::basis::BasisReport>,
    /// Set by `facesim replan`: where the basis came from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replan: Option<crate::plan::basis::ReplanReport>,
    /// The head frame the landmarks were found in (docs/landmarks.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head_frame: Option<crate::landmarks::HeadFrame>,
    /// Label → pre, post (LPS mm), change_mm; a missing landmark says why.
    pub landmarks: crate::landmarks::Ordered<crate::landmarks::Carried>,
    /// Nasolabial and mentolabial angles, lips to the E-line: before, after, change.
    pub measurements: crate::landmarks::Ordered<crate::landmarks::measure::Measure>,
    /// Soft over hard tissue anterior movement per landmark pair (e.g. Pog'/Pog).
    pub soft_hard_ratios: crate::landmarks::Ordered<crate::landmarks::measure::Ratio>,
    /// Region → vertices, mean, p90, max of the displacement (mm).
    pub regions: crate::landmarks::Ordered<crate::landmarks::face_regions::RegionStats>,
    /// `[uncertainty] samples > 0`: the band per landmark and region (docs/uncertainty.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<crate::uncertainty::UncertaintyReport>,
    pub warnings: Vec<String>,
    /// Optional stages this case did not need (no plan → no solve, a skin solved as given → no
    /// coarsening or embedding, ...).
    pub stages_not_run: Vec<Skipped>,
}

//! The serde types of case.toml (docs/reference/case.md): what each section holds. Defaults are in
//! `defaults.rs`, checks in `validate.rs`, region shapes in `region.rs`.

use super::region::Region;
pub use super::solve_model::SolveModel;
use super::uncertainty::Uncertainty;
use crate::labels::{FAT_BRIGHT, FAT_DARK, SKIN};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Case {
    #[serde(default)]
    pub name: Option<String>,
    pub ct: CtSection,
    #[serde(default)]
    pub skin: Option<PathSection>,
    #[serde(default)]
    pub registration: Option<Registration>,
    pub tissue: Tissue,
    pub extract: Extract,
    pub springs: Springs,
    pub surface: Surface,
    #[serde(default)]
    pub osteotomy: Vec<Osteotomy>,
    /// `[[surgery]]`: osteotomies in clinical terms, their cuts found from the CT
    /// (docs/guide/planning.md).
    #[serde(default)]
    pub surgery: Vec<Surgery>,
    /// `[head]`: how the clinical head frame is found, and a pitch correction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head: Option<Head>,
    pub solve: Solve,
    pub tet: Tet,
    pub output: Output,
    /// `[uncertainty]`: sampling the tissue parameters (docs/guide/uncertainty.md).
    #[serde(default)]
    pub uncertainty: Uncertainty,
    /// User landmarks (`[[landmark]]` label and LPS position), overriding detection
    /// (docs/guide/landmarks.md).
    #[serde(default, rename = "landmark")]
    pub landmark: Vec<UserLandmark>,
    /// Which series of a DICOM directory holding several is the CT (`[dicom] series`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dicom: Option<Dicom>,
    /// A 3D Slicer markups file of user landmarks (`landmarks = "file.mrk.json"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landmarks: Option<PathBuf>,
}

/// `[dicom]`: `series` is a SeriesInstanceUID, or a SeriesNumber, of the series to read from a
/// `[ct] path` directory holding several (docs/guide/dicom.md). Without it the largest CT series is
/// read, with a warning.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Dicom {
    pub series: String,
}

/// One `[[landmark]]`: a label (docs/guide/landmarks.md) and its position (LPS mm).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct UserLandmark {
    pub label: String,
    pub position: [f64; 3],
}

/// `[ct]`: the CT file, and what a file that does not say it needs stated (docs/reference/case.md): the
/// patient directions of its voxel axes and the offset from its numbers to HU.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CtSection {
    pub path: PathBuf,
    /// Where the voxel axes i, j, k point in the patient, three letters of L/R, P/A, S/I
    /// (e.g. "LAI": i to the left, j anterior, k inferior). Replaces the file's orientation
    /// (origin and spacing kept): for formats with no patient frame (a vtk.js dataset).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axes: Option<String>,
    /// Added to every voxel value (after the file's own rescale, if any) to give HU: e.g.
    /// -1024 for a CT stored as HU + 1024 with no rescale in the file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intercept: Option<f64>,
}

impl CtSection {
    /// `[ct] path` alone.
    pub fn new(path: impl Into<PathBuf>) -> CtSection {
        CtSection {
            path: path.into(),
            ..CtSection::default()
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PathSection {
    pub path: PathBuf,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Registration {
    pub scan: Vec<[f64; 3]>,
    pub ct: Vec<[f64; 3]>,
    #[serde(default)]
    pub scale: bool,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TissueMethod {
    Windows,
    Fit,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Stiffness {
    pub skin: f64,
    pub muscle: f64,
    pub fat_dark: f64,
    pub fat_bright: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Tissue {
    pub method: TissueMethod,
    pub head_threshold: f64,
    pub skin_thickness_mm: f64,
    pub min_bone_component_mm3: f64,
    pub fat_dark: f64,
    pub fat_bright: f64,
    pub soft: f64,
    pub bone: f64,
    pub stiffness: Stiffness,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ExtractMethod {
    Rangescan,
    Marching,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Extract {
    pub method: ExtractMethod,
    pub angle_step_deg: f64,
    pub z_step_mm: f64,
    pub smooth_iterations: usize,
    pub decimate_target: usize,
    pub decimate_max_error_mm: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Springs {
    pub max_length_mm: f64,
    pub struts: bool,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Parameterization {
    Cylindrical,
    Planar,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Surface {
    pub alpha: f64,
    pub beta: f64,
    pub parameterization: Parameterization,
    #[serde(default)]
    pub movable: Option<Region>,
    /// Per-region stretching/bending (`[[surface.region]]`), applied by triangle centroid; later
    /// entries win where regions overlap.
    #[serde(default, rename = "region")]
    pub regions: Vec<SurfaceRegion>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceRegion {
    pub shape: Region,
    pub alpha: f64,
    pub beta: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Osteotomy {
    pub name: String,
    pub region: Region,
    #[serde(default)]
    pub translate: [f64; 3],
    #[serde(default)]
    pub rotate_deg: [f64; 3],
    #[serde(default)]
    pub pivot: [f64; 3],
}

/// The osteotomy a `[[surgery]]` names.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, PartialOrd, Ord)]
#[serde(rename_all = "kebab-case")]
pub enum SurgeryKind {
    /// Le Fort I: the maxilla below a cut from the piriform rim, above the tooth apices, back to
    /// the pterygomaxillary junction.
    LeFortI,
    /// Bilateral sagittal split: the tooth-bearing mandible; the rami and condyles stay.
    Bsso,
    /// Genioplasty: the chin below the canine apices and the mental foramina.
    Genioplasty,
}

/// A landmark named as a pivot, or a point (LPS mm).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(untagged)]
pub enum Pivot {
    Landmark(String),
    Point([f64; 3]),
}

/// `[[surgery]]`: one osteotomy in the surgeon's words. Moves are in the clinical head frame:
/// forward, up and toward the patient's left; rotations in degrees about the frame's axes
/// through the pivot (docs/guide/planning.md "Signs").
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Surgery {
    pub kind: SurgeryKind,
    #[serde(default)]
    pub advance_mm: f64,
    #[serde(default)]
    pub up_mm: f64,
    #[serde(default)]
    pub left_mm: f64,
    #[serde(default)]
    pub pitch_deg: f64,
    #[serde(default)]
    pub roll_deg: f64,
    #[serde(default)]
    pub yaw_deg: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pivot: Option<Pivot>,
    #[serde(default)]
    pub autorotate: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
}

/// How the clinical head frame is found (`[head] frame`).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum FrameChoice {
    /// Frankfort horizontal (porion and orbitale, both sides) and the midsagittal plane.
    Frankfort,
    /// The soft-tissue facial plane N'–Pog' vertical: natural head position estimated.
    FacialPlane,
}

/// `[head]`: the clinical frame's method (default: Frankfort where the CT holds porion and
/// orbitale, else the facial plane) and a pitch correction added to the found frame.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Head {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<FrameChoice>,
    #[serde(default)]
    pub pitch_deg: f64,
}

/// The volumetric model's constitutive law.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum TetMaterial {
    /// Small-strain isotropic linear elasticity.
    Linear,
    /// Compressible neo-Hookean (CalculiX's NEO HOOKE form), geometrically nonlinear: exact
    /// for rigid moves of any size.
    NeoHookean,
}

/// The volumetric model's element.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum TetElement {
    /// 4-node tetrahedra (locks as ν → 0.5).
    Linear,
    /// 10-node tetrahedra (CalculiX C3D10), which do not lock; linear material only.
    Quadratic,
}

/// `[tet] scan_end`: how the tissue is held where the CT's field of view ends in it.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum ScanEndHold {
    /// A traction-free surface: nothing beyond the scan holds the tissue (the default, and what a
    /// report.json written before the key existed ran).
    #[default]
    Free,
    /// It slides on the plane the scan ends in: no motion across it, free along it. The mirror
    /// condition of tissue that goes on past the scan (docs/lab/validation-notes.md "Where the scan
    /// ends: a truncation study").
    Slides,
}

/// `[tet] degloved_maxilla` and `degloved_chin`: `"auto"`, `true` or `false` in case.toml.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Degloved {
    /// On where it can serve: `sliding` and `release_cuts` on, the 4-node element, and the
    /// region's limits found (for a plan that moves the upper teeth, subnasale and stomion or
    /// labrale superius). Elsewhere off, with a warning and report.json's reason
    /// (`tet.degloved_not_applied`, `tet.degloved_chin_not_applied`).
    #[default]
    Auto,
    /// On; a case it cannot serve is refused.
    On,
    Off,
}

impl Degloved {
    /// Whether it was asked for by name (`true`): then what it cannot serve is an error.
    pub fn required(self) -> bool {
        self == Degloved::On
    }
}

impl Serialize for Degloved {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Degloved::Auto => s.serialize_str("auto"),
            Degloved::On => s.serialize_bool(true),
            Degloved::Off => s.serialize_bool(false),
        }
    }
}

impl<'de> Deserialize<'de> for Degloved {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Degloved;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("true, false or \"auto\"")
            }
            fn visit_bool<E: serde::de::Error>(self, v: bool) -> std::result::Result<Degloved, E> {
                Ok(if v { Degloved::On } else { Degloved::Off })
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<Degloved, E> {
                match v {
                    "auto" => Ok(Degloved::Auto),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Str(v), &self)),
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// Young's modulus (kPa) and Poisson ratio of one tissue: `[tet.skin]` etc., and the material
/// of each element of the volumetric model (`crate::tet`).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TissueElastic {
    pub youngs_kpa: f64,
    pub poisson: f64,
}

impl TissueElastic {
    /// Lamé's (λ, μ).
    pub fn lame(self) -> (f64, f64) {
        let (e, nu) = (self.youngs_kpa, self.poisson);
        (
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            e / (2.0 * (1.0 + nu)),
        )
    }
}

/// `[tet]`: the volumetric model (used when `[solve] model = "tet"`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Tet {
    pub material: TetMaterial,
    pub element: TetElement,
    /// Load steps of the nonlinear material's fallback solve (used when Newton from the linear
    /// answer fails; `tet::newton_krylov`).
    pub load_steps: usize,
    /// Mucosa (tissue surface facing a cavity, e.g. the inner lip across the vestibule) within
    /// `mucosa_gap_mm` of the skull: true slides along the bone (its normal displacement follows
    /// the bone, tangential free), false is attached (moves with the bone). With false nothing
    /// slides or lifts off anywhere: the tissue is bonded to the bone it touches.
    pub sliding: bool,
    pub mucosa_gap_mm: f64,
    /// The periosteum raised at each saw line: bone nodes nearer than this (mm) to bone of
    /// another piece slide on their bone instead of being attached
    /// (`tet::conditions::release_at_cuts`).
    pub cut_release_mm: f64,
    /// Release the tissue at the saw lines (`cut_release_mm`) and free sliding nodes of inverted
    /// elements (default true).
    pub release_cuts: bool,
    /// Tissue off the face that a move still turns inside out after lift-off (the osteotomy
    /// gap, stretched or squeezed by a large move) tears: its stiffness falls to a trace and the
    /// model is solved again (default true; linear element).
    pub tear_gap: bool,
    /// A solved displacement that turns elements inside out is a numerical failure (outputs
    /// written, non-zero exit) unless this is true.
    pub accept_inverted: bool,
    /// Estimate the discretisation error on the face by solving again at twice the element
    /// size (report.json `discretisation_error`; `model::discretisation`).
    pub error_estimate: bool,
    /// Element edge length (mm) at the skin inside the region the plan reaches.
    pub skin_size_mm: f64,
    /// Element edge length (mm) deep in the tissue and far from the moved bone.
    pub deep_size_mm: f64,
    /// The modelled region: the box around the moved bone grown by this much (mm); its cut
    /// faces are held fixed.
    pub margin_mm: f64,
    /// The tissue a Le Fort I approach raises off the anterior maxilla rests on the bone in
    /// one-sided contact: it slides, and lifts off where the bone would pull it (`model::degloved`;
    /// docs/lab/validation-notes.md "The degloved maxilla"). `"auto"`, the default: on where it can
    /// serve, stepping aside with a warning where it cannot; `true`: on, refusing a case it cannot
    /// serve; `false`: off.
    #[serde(default)]
    pub degloved_maxilla: Degloved,
    /// The tissue a genioplasty's approach raises off the anterior mandible rests on the bone the
    /// same way, on a plan that moves a chin segment (`model::degloved`; docs/lab/validation-notes.md
    /// "The degloved chin").
    /// `"auto"`, `true` and `false` as `degloved_maxilla`.
    #[serde(default)]
    pub degloved_chin: Degloved,
    /// Where the scan ends in the tissue (the field of view cutting through a lip or the neck),
    /// `"free"`, the default: a free surface; `"slides"`: the tissue there slides on the scan's end
    /// plane. Defaulted to `"free"` when absent, so a report.json written before the key existed
    /// reads back as it ran.
    #[serde(default)]
    pub scan_end: ScanEndHold,
    pub skin: TissueElastic,
    pub muscle: TissueElastic,
    pub fat_dark: TissueElastic,
    pub fat_bright: TissueElastic,
    /// The keys of the retired `[tet]` mechanisms ([`RETIRED_TET_KEYS`]) in a report.json's
    /// parameters written while they existed: read and ignored, never written, so such a run
    /// still reads back. A case.toml or `--set` that sets one is refused before it is read
    /// (`Case::parse_with`).
    #[serde(default, skip_serializing, rename = "nose_youngs_kpa")]
    #[allow(dead_code, reason = "read only to be ignored")]
    pub(super) retired_nose_youngs_kpa: serde::de::IgnoredAny,
    #[serde(default, skip_serializing, rename = "nose_base_above_sn_mm")]
    #[allow(dead_code, reason = "read only to be ignored")]
    pub(super) retired_nose_base_above_sn_mm: serde::de::IgnoredAny,
    #[serde(default, skip_serializing, rename = "septum_detached")]
    #[allow(dead_code, reason = "read only to be ignored")]
    pub(super) retired_septum_detached: serde::de::IgnoredAny,
}

/// `[tet]` keys of mechanisms that failed the validation gate and left the product
/// (docs/lab/retired-mechanisms.md): the external nose as one stiff framework and the septum
/// detached from the maxilla. A case that sets one is refused in one line naming the key.
pub(crate) const RETIRED_TET_KEYS: [&str; 3] = [
    "nose_youngs_kpa",
    "nose_base_above_sn_mm",
    "septum_detached",
];

impl Tet {
    /// Why the raised tissue cannot rest on its bone one way in this case (None: it can): the
    /// one-sided rounds slide and free the corner nodes of the 4-node element.
    pub(crate) fn one_sided_unavailable(&self) -> Option<&'static str> {
        if !(self.sliding && self.release_cuts) {
            Some("it needs [tet] sliding and release_cuts, which are off")
        } else if self.element == TetElement::Quadratic {
            Some(
                "it runs on the 4-node element (the 10-node element's midpoints on the bone would stay bonded)",
            )
        } else {
            None
        }
    }

    /// The material of a tissue label (`crate::labels`) (soft labels; anything else is
    /// muscle, the bulk of the face's soft tissue).
    pub fn elastic(&self, label: u8) -> TissueElastic {
        self.tissues()[Tet::slot(label)]
    }

    /// The materials of the four tissues, in the order of [`Tet::TISSUES`].
    pub fn tissues(&self) -> [TissueElastic; 4] {
        [self.skin, self.muscle, self.fat_dark, self.fat_bright]
    }

    /// The four tissues' materials to change, in the order of [`Tet::tissues`].
    pub fn tissues_mut(&mut self) -> [&mut TissueElastic; 4] {
        [
            &mut self.skin,
            &mut self.muscle,
            &mut self.fat_dark,
            &mut self.fat_bright,
        ]
    }

    /// The tissues' case.toml keys (`[tet.skin]` …), the order of [`Tet::tissues`].
    pub const TISSUES: [&'static str; 4] = ["skin", "muscle", "fat_dark", "fat_bright"];

    /// A tissue label's place in [`Tet::tissues`].
    pub fn slot(label: u8) -> usize {
        match label {
            SKIN => 0,
            FAT_DARK => 2,
            FAT_BRIGHT => 3,
            _ => 1,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Solve {
    pub model: SolveModel,
    pub steps: usize,
    /// Spring stiffness per unit relative stiffness c per mm² (equilibrium model).
    pub k_c: f64,
    /// Force scale k_c of eq. 20 for the koch1996 model (forces are loads there, not springs,
    /// so the scale is a different quantity; docs/design/pipeline.md).
    pub koch_k_c: f64,
    /// Solve only on the movable skin and its ring of rigid neighbours (exact: elements whose
    /// DOFs are all fixed add nothing). Off solves on the whole skin.
    pub restrict: bool,
    /// Solve on a copy of the skin decimated to this many triangles and carry the full skin
    /// along by shell embedding (paper 002), when the skin has more than twice as many.
    /// 0 = always solve on the skin as given.
    pub coarse_triangles: usize,
    /// Depth of the embedding shell below the coarse skin (mm).
    pub shell_mm: f64,
    /// Poisson ratio of the shell's thickness rule (paper 002 eq. 2), in [0, 0.5].
    pub shell_poisson: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    pub subdivide: usize,
}

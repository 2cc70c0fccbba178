//! A synthetic head with jaws: cranium, maxilla, mandible, teeth, lips over a vestibule, chin
//! and nose, every tissue an analytic function of the point (docs/design/phantom.md, "Jaws").
//!
//! Frame: LPS mm, origin on the head axis (the capsule head's z axis), face towards −y. Three
//! coordinate systems build it:
//! - **cylindrical** (ρ = √(x² + y²), φ from −y towards +x, z) for the skin surface
//!   ρ = R_s(φ, z) and the layers under it (skin 2 mm, fat 4 mm, measured radially);
//! - **arch** coordinates about two ellipses in the horizontal plane, centre (0, −24): the upper
//!   labial arch line (semi-axes 31.5 × 48 mm) and the lower one (29 × 45.5 mm, 2.5 mm inside
//!   the upper: the overjet). A point has the ellipse angle t (0 on the midline, ±90° at the
//!   widest point) and the first-order signed distance n = (q − 1)/|∇q| from the line
//!   (q = √((x/a)² + ((y + 24)/b)²), n > 0 outside, towards the lips);
//! - plain boxes, segments and ellipsoids for the rami and condyles.
//!
//! Dimensions (mm; on the midline unless said otherwise; docs/design/phantom.md has the measured
//! proportions):
//!
//! | part | geometry |
//! |---|---|
//! | cranium | the capsule's bone cylinder ρ ∈ [60, 67] for z ≥ 4.5, closed by a skull-base plate z ∈ [4.5, 9.5]; brain (35 HU) above it; in front a bony glabella (+4.5 at z = 64) and nasal bones (+7 at z = 32, 9 mm wide) |
//! | forehead | a brow ridge (+7 mm at z = 66, σ 9 mm, σ_φ 0.45 rad) over eye hollows (−5 mm at z = 45, φ = ±24°): soft nasion at z ≈ 48, glabella at z ≈ 66 |
//! | Le Fort I gap | z ∈ [1.5, 4.5], soft tissue, horizontal: maxilla below, cranium above |
//! | maxilla | alveolar band n_u ∈ [−10, 0] (labial face dips 1.5 mm at A point, z = −4), z ∈ [−13, 1.5], \|t\| ≤ 95°, y ≤ −13.5; palate z ∈ [−6, −2] inside the arch |
//! | upper teeth | crowns z ∈ [−23, −13] (incisal edge to CEJ), labial face on the arch line, labio-lingual 7 (incisors), 8 (canine), 9 (premolars), 10 (molars) at the CEJ tapering to 1.5 at the edge; widths along the arch 8.5, 6.5, 7.5, 7, 6.5, 10, 9 (central incisor to second molar); 2 mm embrasure notches; 1500 HU |
//! | occlusion | horizontal occlusal plane z = −25; a 4 mm interocclusal gap (soft tissue, as in a CT taken with a bite wafer) keeps the jaws separate bone pieces at 2 mm voxels |
//! | lower teeth | crowns z ∈ [−36, −27], widths 5.5, 6, 7, 7, 7, 11, 10.5, same thicknesses |
//! | mandible body | n_l ∈ [−13, front], z from the alveolar crest −36 down to the lower border −66 + 12 (1 − cos t) + (n + 5)²/20; front = [4 exp(−((z + 55)/7)²) − 1.5 exp(−((z + 42)/4)²)] exp(−(t/0.45)²) (chin, B point) |
//! | symphysis | height 30 (crest −36 to menton −66), thickness 13 + chin |
//! | posterior body | 13 mm bars from (±29, −26) to (±46, 4), z ∈ [−54, −36] (rounded lower border) |
//! | rami | \|x\| ∈ [38, 47], y ∈ [−8, 18], z ∈ [−56, −10]; condylar necks \|x\| ∈ [40, 48], y ∈ [2, 12], z ∈ [−10, −4] |
//! | condyles | ellipsoids centred (±48, 7, −3), semi-axes 10 × 5 × 4 (top z = 1): 3.5 mm joint space below the skull base; intercondylar distance 96 |
//! | vestibule | air 2 mm thick in front of the arch lines (n ∈ (0, 2]), from the upper sulcus z = −3 to the lower sulcus z = −45, \|t\| ≤ 70°; closed at both sulci and at its ends; between the incisal edges it bridges the overjet |
//! | lips | in contact at stomion; a 2.5 mm skin crease marks the lip line; lips and crease end at the mouth's corners, 26 mm either side |
//! | alae | wings at the nose's base (+6 at z = 4.5) ending in the alar groove 17 mm either side; zero on the midline |
//! | skin, fat | 2 mm and 4 mm radially under R_s(φ, z) = envelope + nose + alae + lips − crease + chin (see `skin_radius`) |
//! | nasal passages | only with `Shape::nasal_passages`: air inside the nose where it stands ≥ 9 mm over the face, from 6 mm behind the face's plane forward, \|x\| ≥ 2.5 (the septum), z ≥ 5 (the nostril sills), ≥ 4 mm inside the skin every way; closed at the nostrils (`nasal_passage`) |
//!
//! HU as the capsule: air −1000, skin and soft tissue 45, fat −100, brain 35, bone 600, teeth
//! 1500 (dentine and enamel). The field of view is x ∈ [−92, 92], y ∈ [−118, 90],
//! z ∈ [−100, 80]: the capsule's cap is left out, and the head leaves the volume through the
//! neck and the top of the cranium, as a clinical CT does. A shaped head (`Shape`) maps these
//! standard-frame numbers, the field of view included, to the world through `Shape::world_of`.

use crate::phantom::{PhantomOptions, grid_mesh, sample_ct};
use facesim::error::{Error, Result};
use facesim::mesh::Mesh;
use facesim::volume::Volume;
use std::f64::consts::PI;
use std::sync::OnceLock;

pub(crate) const HU_AIR: f64 = -1000.0;
pub(crate) const HU_SOFT: f64 = 45.0;
pub(crate) const HU_BRAIN: f64 = 35.0;
pub(crate) const HU_FAT: f64 = -100.0;
pub(crate) const HU_BONE: f64 = 600.0;
pub(crate) const HU_TOOTH: f64 = 1500.0;

/// Skin and subcutaneous fat, radially under R_s.
pub(crate) const SKIN_MM: f64 = 2.0;
pub(crate) const FAT_MM: f64 = 4.0;

/// Cranium (the capsule's cylinder) and the skull base.
pub(crate) const R_BRAIN: f64 = 60.0;
pub const R_BONE: f64 = 67.0;
pub const Z_SKULL_BASE: f64 = 4.5;
pub const Z_BRAIN: f64 = 9.5;
/// Le Fort I gap: z ∈ [Z_MAXILLA_TOP, Z_SKULL_BASE].
pub const Z_MAXILLA_TOP: f64 = 1.5;

/// Arch ellipses: common centre y, upper and lower semi-axes (x, y).
pub(crate) const Y_ARCH: f64 = -24.0;
pub(crate) const ARCH_UPPER: [f64; 2] = [31.5, 48.0];
pub(crate) const ARCH_LOWER: [f64; 2] = [29.0, 45.5];

/// Occlusion and crowns.
pub(crate) const Z_OCCLUSAL: f64 = -25.0;
pub(crate) const Z_UPPER_EDGE: f64 = -23.0;
pub const Z_UPPER_CEJ: f64 = -13.0;
pub const Z_LOWER_EDGE: f64 = -27.0;
pub const Z_LOWER_CEJ: f64 = -36.0;
const UPPER_WIDTHS: [f64; 7] = [8.5, 6.5, 7.5, 7.0, 6.5, 10.0, 9.0];
const LOWER_WIDTHS: [f64; 7] = [5.5, 6.0, 7.0, 7.0, 7.0, 11.0, 10.5];
const THICKNESS: [f64; 7] = [7.0, 7.0, 8.0, 9.0, 9.0, 10.0, 10.0];
const EDGE_THICKNESS: f64 = 1.5;
const NOTCH_MM: f64 = 2.0;

/// Maxilla.
const MAXILLA_T_MAX: f64 = 95.0 * PI / 180.0;
const MAXILLA_Y_MAX: f64 = -13.5;
const ALVEOLAR_MM: f64 = 10.0;
const Z_A_POINT: f64 = -4.0;
const PALATE_Z: [f64; 2] = [-6.0, -2.0];

/// Mandible.
const BODY_MM: f64 = 13.0;
pub const Z_MENTON: f64 = -66.0;
const N_MENTON: f64 = -5.0;
const Z_POGONION: f64 = -55.0;
const Z_B_DIP: f64 = -42.0;
const BAR: [[f64; 2]; 2] = [[29.0, -26.0], [46.0, 4.0]];
const BAR_Z: [f64; 2] = [-54.0, -36.0];
const RAMUS: [[f64; 2]; 3] = [[38.0, 47.0], [-8.0, 18.0], [-56.0, -10.0]];
const NECK: [[f64; 2]; 3] = [[40.0, 48.0], [2.0, 12.0], [-10.0, -4.0]];
/// Condyle centre (the +x one; the other mirrors it) and semi-axes.
pub(crate) const CONDYLE: [f64; 3] = [48.0, 7.0, -3.0];
const CONDYLE_AXES: [f64; 3] = [10.0, 5.0, 4.0];
/// The pivot of a mandibular rotation: on the condylar axis, in the mid-sagittal plane.
pub const CONDYLAR_PIVOT: [f64; 3] = [0.0, CONDYLE[1], CONDYLE[2]];

/// No skin point is farther from the axis (the nose tip is at 103.5).
const MAX_SKIN_RADIUS: f64 = 110.0;

/// Vestibule.
pub(crate) const VESTIBULE_MM: f64 = 2.0;
pub(crate) const Z_SULCUS_UPPER: f64 = -3.0;
pub(crate) const Z_SULCUS_LOWER: f64 = -45.0;
const VESTIBULE_T_MAX: f64 = 70.0 * PI / 180.0;

/// The vertical pattern (`Shape::vertical_mm`) stretches the head below this height: the
/// maxilla's top, where its midline front is the anterior nasal spine (the Le Fort I gap is
/// just above it; subnasale is at z ≈ 2.4). The lower anterior face (ANS to menton) is what
/// differs between long and short faces; the cranium, the Le Fort I gap (the osteotomy's
/// level) and the nose above it stay as they are.
pub const Z_VERTICAL: f64 = Z_MAXILLA_TOP;
/// The standard head's lower anterior face height, ANS (Z_VERTICAL) to menton: 67.5 mm.
pub const LOWER_FACE_MM: f64 = Z_VERTICAL - Z_MENTON;

/// Field of view of `ct`.
pub(crate) const FOV_LO: [f64; 3] = [-92.0, -118.0, -100.0];
pub const FOV_HI: [f64; 3] = [92.0, 90.0, 80.0];

/// One synthetic patient: how a jaws phantom differs from the standard head (docs/design/phantom.md,
/// "Cohort parameters"). `Shape::default()` is the standard head. Lengths are mm of the
/// standard head, before `scale`. The geometry below is written for the standard frame; a
/// shaped head evaluates it at `standard_of(p)` (the vertical stretch and the scale undone)
/// with the mandible's parts moved by (asymmetry_mm, −mandible_mm, 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shape {
    /// Head size: every point, the field of view and the plans' regions scale about the origin.
    pub scale: f64,
    /// Soft-tissue thickness: the skin surface moves out (+) or in (−) by this much everywhere.
    pub soft_mm: f64,
    /// Mandibular prognathism: the mandible with its teeth, the lower vestibule and the skin of
    /// the lower face (below the lip line) sit this much anterior (+, towards −y) or posterior.
    pub mandible_mm: f64,
    /// Chin prominence: added to the bony chin's projection (4 mm) and to the skin chin's.
    pub chin_mm: f64,
    /// Mandibular midline shift towards the patient's left (+x): the mandible, the lower
    /// vestibule and the lower face's skin (by an angle asymmetry_mm / 85 mm about the axis).
    pub asymmetry_mm: f64,
    /// Vertical facial pattern: the change of the lower anterior face height, ANS to menton
    /// (+ a long, hyperdivergent face; − a short, hypodivergent one). Everything below
    /// Z_VERTICAL (the maxilla's top) stretches vertically by 1 + vertical_mm / LOWER_FACE_MM
    /// about it: jaws, teeth, lips, chin, skin, neck and the field of view's lower end.
    pub vertical_mm: f64,
    /// Lips and cheeks closed on the teeth: the vestibule is a potential space (soft tissue, no
    /// air), as in most CTs, so the lip's inner surface lies on the crowns and the alveolar bone
    /// (the lip–tooth contact the volumetric model finds). Not a cohort parameter (`values`
    /// leaves it out).
    pub closed_lips: bool,
    /// The nose is a shell over two nasal passages (air either side of a septum, under walls of
    /// skin and fat; `nasal_passage`), as in a CT, instead of a solid bump. Off in the standard
    /// head (the bundled sample), on in `facesim validate`'s phantoms (`--phantom-noses`). Not a
    /// cohort parameter.
    pub nasal_passages: bool,
}

impl Default for Shape {
    fn default() -> Shape {
        Shape {
            scale: 1.0,
            soft_mm: 0.0,
            mandible_mm: 0.0,
            chin_mm: 0.0,
            asymmetry_mm: 0.0,
            vertical_mm: 0.0,
            closed_lips: false,
            nasal_passages: false,
        }
    }
}

/// The accepted range of each shape parameter: (name as in phantom.toml and the CLI, min, max).
/// Inside them the three bone pieces stay separate, every plan's boxes still select exactly
/// their segment and the skin stays inside the field of view (docs/design/phantom.md).
pub(crate) const SHAPE_RANGES: [(&str, f64, f64); 6] = [
    ("scale", 0.8, 1.2),
    ("soft_mm", -3.0, 5.0),
    ("mandible_mm", -4.0, 4.0),
    ("chin_mm", -3.0, 4.0),
    ("asymmetry_mm", -4.0, 4.0),
    ("vertical_mm", -8.0, 10.0),
];

/// The radius (mm) at which the lower face's skin features sit: asymmetry_mm / this is their
/// angular shift, so the skin chin moves about asymmetry_mm sideways with the bony chin.
const R_LOWER_FACE: f64 = 85.0;

impl Shape {
    /// The parameters in SHAPE_RANGES order.
    pub fn values(&self) -> [f64; 6] {
        [
            self.scale,
            self.soft_mm,
            self.mandible_mm,
            self.chin_mm,
            self.asymmetry_mm,
            self.vertical_mm,
        ]
    }

    /// The shape with the parameters in SHAPE_RANGES order.
    pub fn from_values(v: [f64; 6]) -> Shape {
        Shape {
            scale: v[0],
            soft_mm: v[1],
            mandible_mm: v[2],
            chin_mm: v[3],
            asymmetry_mm: v[4],
            vertical_mm: v[5],
            closed_lips: false,
            nasal_passages: false,
        }
    }

    /// Refuse a parameter outside its SHAPE_RANGES range, naming it.
    pub fn validate(&self) -> Result<()> {
        for ((name, lo, hi), v) in SHAPE_RANGES.iter().zip(self.values()) {
            if !(v >= *lo && v <= *hi) {
                return Err(Error::config(format!(
                    "phantom shape: {name} = {v} is outside [{lo}, {hi}]"
                )));
            }
        }
        Ok(())
    }

    /// A world point (LPS mm) in the standard head's frame: the scale undone, then the
    /// vertical stretch. Every function of a shaped head at world points goes through this
    /// and `world_of` (heights alone through `standard_z`).
    pub fn standard_of(&self, p: [f64; 3]) -> [f64; 3] {
        [
            p[0] / self.scale,
            p[1] / self.scale,
            self.unstretched(p[2] / self.scale),
        ]
    }

    /// A standard-frame point in the world: stretched vertically below Z_VERTICAL, then scaled
    /// about the origin.
    pub fn world_of(&self, p: [f64; 3]) -> [f64; 3] {
        [
            p[0] * self.scale,
            p[1] * self.scale,
            self.stretched(p[2]) * self.scale,
        ]
    }

    /// A world height in the standard frame (`standard_of`'s z, which depends on z alone).
    fn standard_z(&self, z: f64) -> f64 {
        self.standard_of([0.0, 0.0, z])[2]
    }

    /// The vertical pattern's stretch factor below Z_VERTICAL: the standard head's lower
    /// anterior face height LOWER_FACE_MM becomes LOWER_FACE_MM + vertical_mm.
    fn stretch(&self) -> f64 {
        1.0 + self.vertical_mm / LOWER_FACE_MM
    }

    /// A standard-frame height stretched by the vertical pattern (before the scale). The
    /// identity, bit for bit, above Z_VERTICAL and when vertical_mm is 0.
    fn stretched(&self, z: f64) -> f64 {
        if z < Z_VERTICAL && self.vertical_mm != 0.0 {
            Z_VERTICAL + (z - Z_VERTICAL) * self.stretch()
        } else {
            z
        }
    }

    /// The inverse of `stretched`.
    fn unstretched(&self, z: f64) -> f64 {
        if z < Z_VERTICAL && self.vertical_mm != 0.0 {
            Z_VERTICAL + (z - Z_VERTICAL) / self.stretch()
        } else {
            z
        }
    }

    /// A standard-frame (x, y) in the mandible's own frame (undoing its shift).
    fn mandible_xy(&self, x: f64, y: f64) -> (f64, f64) {
        (x - self.asymmetry_mm, y + self.mandible_mm)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tissue {
    Air,
    Skin,
    Fat,
    Soft,
    Brain,
    Bone,
    Tooth,
}

/// The three bone pieces the osteotomies separate (teeth belong to their jaw).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Piece {
    Cranium,
    Maxilla,
    Mandible,
}

/// Smooth step from 0 (z ≥ z0) to 1 (z ≤ z1), z1 < z0.
fn step_down(z: f64, z0: f64, z1: f64) -> f64 {
    let u = ((z0 - z) / (z0 - z1)).clamp(0.0, 1.0);
    u * u * (3.0 - 2.0 * u)
}

fn gauss(d: f64, sigma: f64) -> f64 {
    (-(d * d) / (2.0 * sigma * sigma)).exp()
}

/// The head's envelope without face features: an ellipse per height with half-width X(z) and
/// half-depths Y_front(z), Y_back(z) — the capsule's radius 80 above z = 0, narrowing to the
/// jaw (X = 66) and the neck (58 wide, 58 deep in front, 65 behind).
fn envelope(phi: f64, z: f64) -> f64 {
    let x = 80.0 - 14.0 * step_down(z, 0.0, -30.0) - 8.0 * step_down(z, -50.0, -80.0);
    let (s, c) = phi.sin_cos();
    let y = if c > 0.0 {
        80.0 - 22.0 * step_down(z, -40.0, -85.0)
    } else {
        80.0 - 15.0 * step_down(z, -10.0, -50.0)
    };
    1.0 / ((s / x).powi(2) + (c / y).powi(2)).sqrt()
}

/// Midline heights of the features (z, mm) and their amplitudes (radial mm).
const NOSE: (f64, f64, f64, f64, f64) = (23.5, 13.0, 5.0, 14.0, 0.14); // amp, z, σ below, σ above, σ_φ
const UPPER_LIP: (f64, f64, f64) = (5.2, -9.5, 11.0); // amp, z, half-width (power 8)
const VERMILION: (f64, f64, f64) = (1.6, -11.5, 3.5); // amp, z, σ_z (the upper lip's most anterior part)
const LOWER_LIP: (f64, f64, f64) = (5.8, -31.0, 9.0); // amp, z, half-width (power 4)
const CREASE: (f64, f64, f64) = (2.5, -21.0, 1.5); // depth, z, σ_z
const CHIN: (f64, f64, f64, f64, f64) = (10.8, -56.0, 11.0, 7.5, 0.35); // amp, z, σ below, σ above, σ_φ
/// The nasal passages: wall (mm), septum half-width (mm), depth behind the face's plane (mm),
/// the nose's least height over the face (mm), the nostril sills' height z (2.6 mm above
/// subnasale, z = 2.4).
const NASAL_PASSAGE: (f64, f64, f64, f64, f64) = (4.0, 2.5, 6.0, 9.0, 5.0);
/// The lips and their crease end at the mouth's corners: their sideways profile is
/// exp(−(φ/w)¹²), flat across the mouth and falling within a few millimetres at its corners,
/// where a Gaussian would fade on past them (adult mouth width 45–55 mm, Farkas 1994).
const MOUTH_HALF_ANGLE: (f64, f64) = (0.31, 0.29); // w of the lips, of the crease (rad)
/// The alae: a wing each side of the nose's base, flat out to w and falling steeply to the
/// cheek there (the alar-facial groove; alar width 31–38 mm, Farkas 1994), zero on the midline
/// (the columella), so the midline profile and its landmarks are unchanged.
const ALAE: (f64, f64, f64, f64, f64) = (6.0, 4.5, 3.5, 0.19, 0.07); // amp, z, σ_z, w (power 12), midline gap σ_φ
/// The brow: a ridge across the forehead whose midline crest is the glabella; with the nose's
/// dorsum below it, the soft nasion is the hollow between (45 mm above subnasale, 5 mm behind
/// the glabella; docs/design/phantom.md compares adult proportions).
const BROW: (f64, f64, f64, f64) = (7.0, 66.0, 9.0, 0.45); // amp, z, σ_z, σ_φ
/// The eye hollows: radial depressions either side of the nose's root (φ = ±EYES.2).
const EYES: (f64, f64, f64, f64, f64) = (5.0, 45.0, 7.0, 0.42, 0.13); // depth, z, σ_z, φ, σ_φ
/// The frontal bone's glabella and the nasal bones: radial bumps on the cranium's outer surface
/// under the brow and the dorsum, so the bony profile has a nasion too.
const BONY_BROW: (f64, f64, f64, f64) = (4.5, 64.0, 8.0, 0.5); // amp, z, σ_z, σ_φ
const NASAL_BONES: (f64, f64, f64, f64) = (7.0, 32.0, 6.0, 0.12); // amp, z, σ_z, σ_φ

/// How much of the mandible's shift the skin at height z follows: 0 above the lip crease
/// (stomion), 1 from the lower lip down.
fn lower_face_weight(z: f64) -> f64 {
    step_down(z, CREASE.1, LOWER_LIP.1)
}

/// The angle (rad) by which the lower face's skin features turn with the midline shift.
fn lower_face_turn(sh: &Shape, z: f64) -> f64 {
    lower_face_weight(z) * sh.asymmetry_mm / R_LOWER_FACE
}

/// The skin surface: distance from the z axis at angle φ (from −y towards +x) and height z.
pub fn skin_radius(phi: f64, z: f64) -> f64 {
    radius(&Shape::default(), phi, z)
}

/// The skin radius of a shaped head in its standard frame: the standard surface plus the
/// soft-tissue change everywhere, the lower lip and chin turned by the midline shift, the chin
/// grown by chin_mm, and the lower face moved forward by mandible_mm (fading out sideways).
fn radius(sh: &Shape, phi: f64, z: f64) -> f64 {
    let (au, zu, wu) = UPPER_LIP;
    let (av, zv, sv) = VERMILION;
    let (lips_w, crease_w) = MOUTH_HALF_ANGLE;
    let across = |phi: f64, w: f64| (-(phi / w).powi(12)).exp();
    let upper =
        (au * (-((z - zu) / wu).powi(8)).exp() + av * gauss(z - zv, sv)) * across(phi, lips_w);
    let (al, zl, wl) = LOWER_LIP;
    let phi_l = phi - lower_face_turn(sh, z);
    let lower = al * (-((z - zl) / wl).powi(4)).exp() * across(phi_l, lips_w);
    let (dc, zc, sc) = CREASE;
    let crease = dc * gauss(z - zc, sc) * across(phi, crease_w);
    let (ach, zch, sbc, sac, spch) = CHIN;
    let chin =
        (ach + sh.chin_mm) * gauss(z - zch, if z < zch { sbc } else { sac }) * gauss(phi_l, spch);
    // Prognathism moves the lower face forward: radially by mandible_mm at the midline,
    // fading sideways (σ 0.9 rad, ~52°) where the mandible's move is tangential.
    let forward = sh.mandible_mm * lower_face_weight(z) * gauss(phi_l, 0.9);
    let (ab, zb, sz, sp) = BROW;
    let brow = ab * gauss(z - zb, sz) * gauss(phi, sp);
    let (de, ze, sze, pe, spe) = EYES;
    let eyes = de * gauss(z - ze, sze) * (gauss(phi - pe, spe) + gauss(phi + pe, spe));
    envelope(phi, z) + sh.soft_mm + nose_bump(phi, z) + upper + lower - crease
        + chin
        + forward
        + brow
        - eyes
}

/// The external nose's height over the face (mm, radial): the nose and its alae.
fn nose_bump(phi: f64, z: f64) -> f64 {
    let (an, zn, sb, sa, sp) = NOSE;
    let nose = an * gauss(z - zn, if z < zn { sb } else { sa }) * gauss(phi, sp);
    let (aa, za, sza, wa, gap) = ALAE;
    let alae = aa * gauss(z - za, sza) * (-(phi / wa).powi(12)).exp() * (1.0 - gauss(phi, gap));
    nose + alae
}

/// The nasal passages (`Shape::nasal_passages`), in the standard frame: air inside the external
/// nose where it stands at least NASAL_PASSAGE.3 over the face, from NASAL_PASSAGE.2 mm behind
/// the face's plane (the piriform aperture's depth) forward, beside a septum |x| < NASAL_PASSAGE.1
/// and above the nostril sills z = NASAL_PASSAGE.4, at least NASAL_PASSAGE.0 inside the skin
/// every way (the alar and lateral walls, skin over cartilage: 3-5 mm; septum with its mucosa
/// 4-6 mm). `rho`, `phi` and `r` are p's cylindrical radius, angle and the skin's radius there.
fn nasal_passage(sh: &Shape, p: [f64; 3], rho: f64, phi: f64, r: f64) -> bool {
    let (wall, septum, depth, min_bump, sill) = NASAL_PASSAGE;
    let [x, _, z] = p;
    if x.abs() < septum || z < sill || phi.abs() > 0.5 {
        return false;
    }
    let bump = nose_bump(phi, z);
    if bump < min_bump || rho < r - bump - depth || rho > r - wall {
        return false;
    }
    // The wall: p moved `wall` any of 26 ways (the cube's faces, edges and corners) stays
    // inside the skin.
    let steps: [f64; 3] = [-1.0, 0.0, 1.0];
    steps.iter().all(|&a| {
        steps.iter().all(|&b| {
            steps.iter().all(|&c| {
                let n = (a * a + b * b + c * c).sqrt();
                n == 0.0 || inside_skin(sh, [0, 1, 2].map(|k| p[k] + wall * [a, b, c][k] / n))
            })
        })
    })
}

/// Whether p (standard frame) lies inside the skin surface ρ = R_s(φ, z) of a shaped head.
fn inside_skin(sh: &Shape, p: [f64; 3]) -> bool {
    let rho = (p[0] * p[0] + p[1] * p[1]).sqrt();
    rho < radius(sh, p[0].atan2(-p[1]), p[2])
}

/// The cranium's outer radius at (φ, z): R_BONE plus the bony glabella and the nasal bones.
pub fn cranium_outer(phi: f64, z: f64) -> f64 {
    let (ab, zb, sz, sp) = BONY_BROW;
    let (an, zn, szn, spn) = NASAL_BONES;
    R_BONE + ab * gauss(z - zb, sz) * gauss(phi, sp) + an * gauss(z - zn, szn) * gauss(phi, spn)
}

/// The skin point at (φ, z).
pub fn skin_point(phi: f64, z: f64) -> [f64; 3] {
    point_at(&Shape::default(), phi, z)
}

/// The skin point at (φ, z) of a shaped head, in its standard frame.
fn point_at(sh: &Shape, phi: f64, z: f64) -> [f64; 3] {
    let r = radius(sh, phi, z);
    [r * phi.sin(), -r * phi.cos(), z]
}

/// Arch coordinates (t, n) of (x, y) about the ellipse with semi-axes `ab` centred (0, Y_ARCH).
fn arch(ab: [f64; 2], x: f64, y: f64) -> (f64, f64) {
    let u = x / ab[0];
    let v = -(y - Y_ARCH) / ab[1];
    let q = (u * u + v * v).sqrt();
    if q < 1e-9 {
        return (0.0, -ab[0].min(ab[1]));
    }
    let grad = ((u / ab[0]).powi(2) + (v / ab[1]).powi(2)).sqrt() / q;
    (u.atan2(v), (q - 1.0) / grad)
}

/// Ellipse angles where each tooth of an arch starts and ends (8 values from 0), from the arc
/// length s(t) = ∫₀ᵗ √(a² cos² τ + b² sin² τ) dτ of x = a sin τ, y = Y_ARCH − b cos τ.
fn tooth_bounds(ab: [f64; 2], widths: &[f64; 7]) -> [f64; 8] {
    let mut out = [0.0; 8];
    let (mut t, mut s, dt) = (0.0f64, 0.0f64, 1e-5);
    let speed = |t: f64| ((ab[0] * t.cos()).powi(2) + (ab[1] * t.sin()).powi(2)).sqrt();
    let mut target = 0.0;
    for (k, w) in widths.iter().enumerate() {
        target += w;
        while s < target && t < PI {
            s += 0.5 * (speed(t) + speed(t + dt)) * dt;
            t += dt;
        }
        out[k + 1] = t;
    }
    out
}

fn upper_bounds() -> &'static [f64; 8] {
    static B: OnceLock<[f64; 8]> = OnceLock::new();
    B.get_or_init(|| tooth_bounds(ARCH_UPPER, &UPPER_WIDTHS))
}

fn lower_bounds() -> &'static [f64; 8] {
    static B: OnceLock<[f64; 8]> = OnceLock::new();
    B.get_or_init(|| tooth_bounds(ARCH_LOWER, &LOWER_WIDTHS))
}

/// Is (t, n, z) inside a crown? `edge` and `cej` are the crown's incisal and cervical heights.
fn in_crown(bounds: &[f64; 8], t: f64, n: f64, z: f64, edge: f64, cej: f64) -> bool {
    let at = t.abs();
    let Some(k) = (0..7).find(|&k| at >= bounds[k] && at < bounds[k + 1]) else {
        return false;
    };
    // Position across the tooth (0..1) and the embrasure notch at its incisal corners.
    let u = (at - bounds[k]) / (bounds[k + 1] - bounds[k]);
    let notch = NOTCH_MM * (2.0 * u - 1.0).powi(4);
    let h = cej - edge; // signed: + for the upper crown (edge below), − for the lower
    let f = (z - edge) / h; // 0 at the edge, 1 at the CEJ
    if !(f >= notch / h.abs() && f <= 1.0) {
        return false;
    }
    let thick = EDGE_THICKNESS + (THICKNESS[k] - EDGE_THICKNESS) * f;
    n <= 0.0 && n >= -thick
}

/// `bone_at` of a shaped head, in its standard frame.
fn bone(sh: &Shape, p: [f64; 3]) -> Option<(Piece, bool)> {
    let [x, y, z] = p;
    if z >= Z_SKULL_BASE {
        let rho = (x * x + y * y).sqrt();
        let outer = cranium_outer(x.atan2(-y), z);
        return ((R_BRAIN..outer).contains(&rho) || (rho < R_BRAIN && z < Z_BRAIN))
            .then_some((Piece::Cranium, false));
    }
    if maxilla(x, y, z) {
        return Some((Piece::Maxilla, false));
    }
    // Both arches of crowns lie within |x| ≤ 33, y ≤ MAXILLA_Y_MAX.
    let arches = x.abs() <= 33.0 && y <= MAXILLA_Y_MAX;
    if arches && (Z_UPPER_EDGE..=Z_UPPER_CEJ).contains(&z) {
        let (t, n) = arch(ARCH_UPPER, x, y);
        if in_crown(upper_bounds(), t, n, z, Z_UPPER_EDGE, Z_UPPER_CEJ) {
            return Some((Piece::Maxilla, true));
        }
    }
    // The lower teeth and the mandible in their own (shifted) frame.
    let (x, y) = sh.mandible_xy(x, y);
    let arches = x.abs() <= 33.0 && y <= MAXILLA_Y_MAX;
    if arches && (Z_LOWER_CEJ..=Z_LOWER_EDGE).contains(&z) {
        let (t, n) = arch(ARCH_LOWER, x, y);
        if in_crown(lower_bounds(), t, n, z, Z_LOWER_EDGE, Z_LOWER_CEJ) {
            return Some((Piece::Mandible, true));
        }
    }
    mandible(sh.chin_mm, x, y, z).then_some((Piece::Mandible, false))
}

fn midline_weight(t: f64, width: f64) -> f64 {
    (-(t / width).powi(2)).exp()
}

fn maxilla(x: f64, y: f64, z: f64) -> bool {
    if !(Z_UPPER_CEJ..=Z_MAXILLA_TOP).contains(&z) || y > MAXILLA_Y_MAX || x.abs() > 33.0 {
        return false;
    }
    let (t, n) = arch(ARCH_UPPER, x, y);
    if t.abs() > MAXILLA_T_MAX {
        return false;
    }
    let front = -1.5 * gauss(z - Z_A_POINT, 4.0 / 2f64.sqrt()) * midline_weight(t, 0.5);
    let alveolar = n <= front && n >= -ALVEOLAR_MM;
    let palate = n < -ALVEOLAR_MM + 1.0 && (PALATE_Z[0]..=PALATE_Z[1]).contains(&z);
    alveolar || palate
}

/// The labial face of the symphysis and body, n_l(t, z): the chin (4 mm + `chin_mm` proud of
/// the arch line) and the B-point dip.
fn mandible_front(chin_mm: f64, t: f64, z: f64) -> f64 {
    let w = midline_weight(t, 0.45);
    ((4.0 + chin_mm) * (-((z - Z_POGONION) / 7.0).powi(2)).exp()
        - 1.5 * (-((z - Z_B_DIP) / 4.0).powi(2)).exp())
        * w
}

fn in_box(b: &[[f64; 2]; 3], p: [f64; 3]) -> bool {
    (0..3).all(|a| p[a] >= b[a][0] && p[a] <= b[a][1])
}

/// The mandible in its own frame, with the chin `chin_mm` more prominent.
fn mandible(chin_mm: f64, x: f64, y: f64, z: f64) -> bool {
    if !(Z_MENTON - 1.0..=CONDYLE[2] + CONDYLE_AXES[2]).contains(&z) {
        return false;
    }
    // Anterior body (in front of the arch centre).
    if y <= Y_ARCH && z <= Z_LOWER_CEJ {
        let (t, n) = arch(ARCH_LOWER, x, y);
        let bottom = Z_MENTON + 12.0 * (1.0 - t.cos()) + (n - N_MENTON).powi(2) / 20.0;
        if n >= -BODY_MM && n <= mandible_front(chin_mm, t, z) && z >= bottom {
            return true;
        }
    }
    // The mirrored posterior parts: work on |x|.
    let ax = x.abs();
    let q = [ax, y, z];
    // Posterior body: a bar from BAR[0] to BAR[1], outer face on the segment, 13 mm medial.
    if (BAR_Z[0]..=BAR_Z[1]).contains(&z) {
        let d = [BAR[1][0] - BAR[0][0], BAR[1][1] - BAR[0][1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        let (dx, dy) = (d[0] / len, d[1] / len);
        let (rx, ry) = (ax - BAR[0][0], y - BAR[0][1]);
        let s = rx * dx + ry * dy;
        let m = rx * dy - ry * dx; // + lateral (towards +|x|)
        let bottom = BAR_Z[0] + (m + 0.5 * BODY_MM).powi(2) / 20.0;
        if s >= -3.0 && s <= len + 3.0 && (-BODY_MM..=0.0).contains(&m) && z >= bottom {
            return true;
        }
    }
    if in_box(&RAMUS, q) || in_box(&NECK, q) {
        return true;
    }
    let e = [
        (ax - CONDYLE[0]) / CONDYLE_AXES[0],
        (y - CONDYLE[1]) / CONDYLE_AXES[1],
        (z - CONDYLE[2]) / CONDYLE_AXES[2],
    ];
    e[0] * e[0] + e[1] * e[1] + e[2] * e[2] <= 1.0
}

/// Is p in the vestibule (the air between the lips and the teeth and alveolar bone)?
pub fn in_vestibule(p: [f64; 3]) -> bool {
    vestibule(&Shape::default(), p)
}

/// `in_vestibule` of a shaped head, in its standard frame: the part along the lower arch moves
/// with the mandible.
fn vestibule(sh: &Shape, p: [f64; 3]) -> bool {
    let [x, y, z] = p;
    let (xl, yl) = sh.mandible_xy(x, y);
    // Cheap bounds first: the vestibule lies in front of y = −35, within |x| < 35 (of either
    // jaw's frame).
    let near = |x: f64, y: f64| y <= -35.0 && x.abs() <= 35.0;
    if !(Z_SULCUS_LOWER..=Z_SULCUS_UPPER).contains(&z) || !(near(x, y) || near(xl, yl)) {
        return false;
    }
    let (tu, nu) = arch(ARCH_UPPER, x, y);
    let (tl, nl) = arch(ARCH_LOWER, xl, yl);
    if z > Z_UPPER_EDGE {
        tu.abs() <= VESTIBULE_T_MAX && nu > 0.0 && nu <= VESTIBULE_MM
    } else if z >= Z_LOWER_EDGE {
        // Between the incisal edges the air bridges the overjet step.
        tu.abs() <= VESTIBULE_T_MAX && nl > 0.0 && nu <= VESTIBULE_MM
    } else {
        tl.abs() <= VESTIBULE_T_MAX && nl > 0.0 && nl <= VESTIBULE_MM
    }
}

/// Exact tissue at p (LPS mm). Precedence: outside air, skin, vestibule, nasal passages (when
/// the shape has them), bone and teeth, brain, fat, soft tissue.
pub fn tissue_at(p: [f64; 3]) -> Tissue {
    tissue(&Shape::default(), p)
}

/// `tissue_at` of a shaped head, in its standard frame.
fn tissue(sh: &Shape, p: [f64; 3]) -> Tissue {
    let [x, y, z] = p;
    let rho = (x * x + y * y).sqrt();
    if rho > MAX_SKIN_RADIUS + sh.soft_mm.max(0.0) {
        return Tissue::Air;
    }
    let phi = x.atan2(-y);
    let r = radius(sh, phi, z);
    if rho >= r {
        return Tissue::Air;
    }
    if rho >= r - SKIN_MM {
        return Tissue::Skin;
    }
    if !sh.closed_lips && vestibule(sh, p) {
        return Tissue::Air;
    }
    if sh.nasal_passages && nasal_passage(sh, p, rho, phi, r) {
        return Tissue::Air;
    }
    if let Some((_, tooth)) = bone(sh, p) {
        return if tooth { Tissue::Tooth } else { Tissue::Bone };
    }
    if z >= Z_BRAIN && rho < R_BRAIN {
        return Tissue::Brain;
    }
    if rho >= r - SKIN_MM - FAT_MM {
        return Tissue::Fat;
    }
    Tissue::Soft
}

fn hu_of(t: Tissue) -> f64 {
    match t {
        Tissue::Air => HU_AIR,
        Tissue::Skin | Tissue::Soft => HU_SOFT,
        Tissue::Fat => HU_FAT,
        Tissue::Brain => HU_BRAIN,
        Tissue::Bone => HU_BONE,
        Tissue::Tooth => HU_TOOTH,
    }
}

/// The bone piece at p, if p is bone or tooth (and not in the skin or the vestibule).
pub fn piece_at(p: [f64; 3]) -> Option<Piece> {
    Shape::default().piece_at(p)
}

/// The shaped head at world points (LPS mm): the standard head's functions of the same names.
impl Shape {
    pub fn tissue_at(&self, p: [f64; 3]) -> Tissue {
        tissue(self, self.standard_of(p))
    }

    pub(crate) fn hu_at(&self, p: [f64; 3]) -> f64 {
        hu_of(self.tissue_at(p))
    }

    pub fn piece_at(&self, p: [f64; 3]) -> Option<Piece> {
        let q = self.standard_of(p);
        match tissue(self, q) {
            Tissue::Bone | Tissue::Tooth => bone(self, q).map(|(piece, _)| piece),
            _ => None,
        }
    }

    /// Is p in the vestibule (with `closed_lips`: where it would be, now soft tissue)?
    pub fn in_vestibule(&self, p: [f64; 3]) -> bool {
        vestibule(self, self.standard_of(p))
    }

    /// The skin's distance from the z axis at angle φ and height z (world mm).
    pub fn skin_radius(&self, phi: f64, z: f64) -> f64 {
        self.scale * radius(self, phi, self.standard_z(z))
    }

    /// The skin point at (φ, z) (world mm).
    pub fn skin_point(&self, phi: f64, z: f64) -> [f64; 3] {
        self.world_of(point_at(self, phi, self.standard_z(z)))
    }

    /// The field of view of `ct`: the standard one through `world_of` (scaled; its lower end
    /// stretched with the vertical pattern, so the neck stays in the CT).
    pub fn fov(&self) -> [[f64; 3]; 2] {
        [self.world_of(FOV_LO), self.world_of(FOV_HI)]
    }
}

/// Golden-section search for the maximum of f on [a, b] (f unimodal there).
fn argmax(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..200 {
        let c = b - g * (b - a);
        let d = a + g * (b - a);
        if f(c) > f(d) {
            b = d;
        } else {
            a = c;
        }
    }
    0.5 * (a + b)
}

/// Named landmarks (LPS mm), from the defining functions: soft-tissue points on the midline
/// skin profile ρ = R_s(0, z) (pronasale its most anterior point above the lips, subnasale and
/// stomion the deepest points between nose and upper lip and between the lips, labrale
/// superius / inferius the most anterior points of the lips, soft pogonion of the chin, soft
/// menton the skin point vertically below bony menton); bone points on the midline contours of
/// the jaws (A point the deepest point of the maxilla's labial face, B point of the mandible's
/// between the alveolar crest and pogonion, pogonion its most anterior point, menton the
/// lowest), the incisal-edge midpoints of the right central incisors and of the upper canines
/// (their cusp tips), and the condyle centres.
pub fn landmarks() -> Vec<(&'static str, [f64; 3])> {
    Shape::default().landmarks()
}

impl Shape {
    /// `landmarks()` of the shaped head (world mm). The soft-tissue points lie on the skin
    /// profile that follows the lower face's turn (the midline above the lip crease), the
    /// mandible's points move with it, everything below Z_VERTICAL stretches with the vertical
    /// pattern, and everything scales.
    pub fn landmarks(&self) -> Vec<(&'static str, [f64; 3])> {
        self.standard_landmarks()
            .into_iter()
            .map(|(n, p)| (n, self.world_of(p)))
            .collect()
    }

    /// The landmark called `name` (world mm).
    pub fn landmark(&self, name: &str) -> Option<[f64; 3]> {
        self.landmarks()
            .into_iter()
            .find(|(n, _)| *n == name)
            .map(|(_, p)| p)
    }

    fn standard_landmarks(&self) -> Vec<(&'static str, [f64; 3])> {
        let sh = self;
        let turn = |z: f64| lower_face_turn(sh, z);
        let r = |z: f64| radius(sh, turn(z), z);
        let midline_skin = |z: f64| point_at(sh, turn(z), z);
        let (ma, md, chin) = (sh.asymmetry_mm, sh.mandible_mm, sh.chin_mm);
        standard_landmarks_with(r, midline_skin, ma, md, chin, |p| inside_skin(sh, p))
    }
}

/// The landmarks' definitions in the standard frame: `r(z)` the skin profile's radius,
/// `profile(z)` its point, the mandible shifted by (ma, −md, 0) with its chin `chin` mm more
/// prominent, `inside(p)` whether p is inside the skin.
fn standard_landmarks_with(
    r: impl Fn(f64) -> f64,
    midline_skin: impl Fn(f64) -> [f64; 3],
    ma: f64,
    md: f64,
    chin: f64,
    inside: impl Fn([f64; 3]) -> bool,
) -> Vec<(&'static str, [f64; 3])> {
    let r = &r;
    let prn = argmax(r, 0.0, 35.0);
    let glabella = argmax(r, 50.0, 70.0);
    let n_soft = argmax(|z| -r(z), prn, glabella);
    let bony_nasion = argmax(|z| -cranium_outer(0.0, z), NASAL_BONES.1, BONY_BROW.1);
    let ls = argmax(r, -18.0, -2.0);
    let sn = argmax(|z| -r(z), ls, prn);
    let li = argmax(r, -38.0, -24.0);
    let sto = argmax(|z| -r(z), li, ls);
    let pg_soft = argmax(r, -65.0, -45.0);
    let yl = |n: f64| Y_ARCH - ARCH_LOWER[1] - n - md;
    let front = |z: f64| mandible_front(chin, 0.0, z);
    let pog = argmax(front, -62.0, -48.0);
    let b = argmax(|z| -front(z), pog, Z_LOWER_CEJ);
    let a = Z_A_POINT;
    let a_n = -1.5;
    let menton = [ma, yl(N_MENTON), Z_MENTON];
    // Soft menton: the skin crossing below menton on its vertical line: step down out of the
    // skin, then bisect.
    let at = |z: f64| [menton[0], menton[1], z];
    let mut lo = Z_MENTON;
    while inside(at(lo)) && lo > FOV_LO[2] {
        lo -= 0.5;
    }
    let mut hi = Z_MENTON;
    for _ in 0..100 {
        let m = 0.5 * (lo + hi);
        if inside(at(m)) {
            hi = m;
        } else {
            lo = m;
        }
    }
    let me_soft = at(0.5 * (lo + hi));
    // The middle of tooth k's incisal edge, on the right (x < 0, side = −1) or left.
    let tip = |ab: [f64; 2], bounds: &[f64; 8], z: f64, k: usize, side: f64, shift: [f64; 2]| {
        let t = side * 0.5 * (bounds[k] + bounds[k + 1]);
        let n = -0.5 * EDGE_THICKNESS;
        let (u, v) = (t.sin(), t.cos());
        // The point at distance n along the ellipse's normal.
        let p = [ab[0] * u, Y_ARCH - ab[1] * v];
        let g = [u / ab[0], v / ab[1]];
        let gl = (g[0] * g[0] + g[1] * g[1]).sqrt();
        [
            p[0] + n * g[0] / gl + shift[0],
            p[1] - n * g[1] / gl + shift[1],
            z,
        ]
    };
    let (fixed, moved) = ([0.0, 0.0], [ma, -md]);
    vec![
        ("glabella", midline_skin(glabella)),
        ("soft tissue nasion", midline_skin(n_soft)),
        ("pronasale", midline_skin(prn)),
        ("subnasale", midline_skin(sn)),
        ("labrale superius", midline_skin(ls)),
        ("stomion", midline_skin(sto)),
        ("labrale inferius", midline_skin(li)),
        ("soft tissue pogonion", midline_skin(pg_soft)),
        ("soft tissue menton", me_soft),
        (
            "nasion",
            [0.0, -cranium_outer(0.0, bony_nasion), bony_nasion],
        ),
        ("A point", [0.0, Y_ARCH - ARCH_UPPER[1] - a_n, a]),
        ("B point", [ma, yl(front(b)), b]),
        ("pogonion", [ma, yl(front(pog)), pog]),
        ("menton", menton),
        (
            "upper incisor tip",
            tip(ARCH_UPPER, upper_bounds(), Z_UPPER_EDGE, 0, -1.0, fixed),
        ),
        (
            "lower incisor tip",
            tip(ARCH_LOWER, lower_bounds(), Z_LOWER_EDGE, 0, -1.0, moved),
        ),
        (
            "upper canine right",
            tip(ARCH_UPPER, upper_bounds(), Z_UPPER_EDGE, 2, -1.0, fixed),
        ),
        (
            "upper canine left",
            tip(ARCH_UPPER, upper_bounds(), Z_UPPER_EDGE, 2, 1.0, fixed),
        ),
        (
            "condyle right",
            [-CONDYLE[0] + ma, CONDYLE[1] - md, CONDYLE[2]],
        ),
        (
            "condyle left",
            [CONDYLE[0] + ma, CONDYLE[1] - md, CONDYLE[2]],
        ),
    ]
}

/// The landmark called `name`.
pub fn landmark(name: &str) -> Option<[f64; 3]> {
    landmarks()
        .into_iter()
        .find(|(n, _)| *n == name)
        .map(|(_, p)| p)
}

/// Osteotomy regions (boxes `[min, max]`) that select each segment's bone and nothing else.
/// The mandible needs two: its anterior part below the occlusal plane (in front of y = −11)
/// and everything behind y = −11 below the skull base (posterior body, rami, condyles); the
/// maxilla lies between the occlusal plane and the Le Fort I gap in front of y = −11.
pub const MANDIBLE_FRONT_BOX: [[f64; 3]; 2] = [[-90.0, -120.0, -110.0], [90.0, -11.0, Z_OCCLUSAL]];
pub const MANDIBLE_BACK_BOX: [[f64; 3]; 2] = [[-90.0, -11.0, -110.0], [90.0, 90.0, 3.0]];
pub const MAXILLA_BOX: [[f64; 3]; 2] = [[-90.0, -120.0, Z_OCCLUSAL], [90.0, -11.0, 3.0]];

impl Shape {
    /// The plans' boxes of the shaped head (world mm): MANDIBLE_FRONT_BOX, MANDIBLE_BACK_BOX and
    /// MAXILLA_BOX, their front/back split at y = −11 moved back to midway between the maxilla
    /// (y ≤ −13.5) and the rami when a prognathic mandible brings the rami (y ≥ −8) forward
    /// of −10.5, then through `world_of` (a box maps to a box: the stretch is monotonic in z).
    pub fn boxes(&self) -> [[[f64; 3]; 2]; 3] {
        let split = (-11.0f64).min(0.5 * (MAXILLA_Y_MAX + RAMUS[1][0] - self.mandible_mm));
        let mut b = [MANDIBLE_FRONT_BOX, MANDIBLE_BACK_BOX, MAXILLA_BOX];
        b[0][1][1] = split;
        b[1][0][1] = split;
        b[2][1][1] = split;
        b.map(|bx| bx.map(|p| self.world_of(p)))
    }

    /// The pivot of a mandibular rotation (world mm): CONDYLAR_PIVOT moved with the mandible.
    pub(crate) fn condylar_pivot(&self) -> [f64; 3] {
        let [x, y, z] = CONDYLAR_PIVOT;
        self.world_of([x + self.asymmetry_mm, y - self.mandible_mm, z])
    }
}

/// The CT of the box [lo, hi].
pub fn ct_box(opts: &PhantomOptions, lo: [f64; 3], hi: [f64; 3]) -> Volume {
    Shape::default().ct_box(opts, lo, hi)
}

/// The phantom CT over the default field of view.
pub fn ct(opts: &PhantomOptions) -> Volume {
    ct_box(opts, FOV_LO, FOV_HI)
}

/// A face scan of the analytic skin: a (φ, z) grid, φ ∈ ±100°, z from below the chin (−85) to
/// the top of the field of view.
pub fn face_scan(step_mm: f64) -> Mesh {
    Shape::default().face_scan(step_mm)
}

impl Shape {
    /// The shaped head's CT of the box [lo, hi] (world mm).
    pub fn ct_box(&self, opts: &PhantomOptions, lo: [f64; 3], hi: [f64; 3]) -> Volume {
        sample_ct(lo, hi, opts, |p| self.hu_at(p))
    }

    /// The shaped head's CT over its field of view.
    pub fn ct(&self, opts: &PhantomOptions) -> Volume {
        let [lo, hi] = self.fov();
        self.ct_box(opts, lo, hi)
    }

    /// `face_scan` of the shaped head: the same (φ, z) grid, through `world_of`, `step_mm`
    /// apart in the world (the rows evenly spaced in the stretched head, so a long face has
    /// more of them).
    pub fn face_scan(&self, step_mm: f64) -> Mesh {
        let step = step_mm / self.scale;
        let phi_max = 100f64.to_radians();
        let nphi = ((2.0 * phi_max * 80.0) / step).round() as usize + 1;
        let (z0, z1) = (self.stretched(-85.0), self.stretched(FOV_HI[2]));
        let nz = ((z1 - z0) / step).round() as usize + 1;
        let mut verts = Vec::with_capacity(nphi * nz);
        for j in 0..nz {
            let z = self.unstretched(z0 + (z1 - z0) * j as f64 / (nz - 1) as f64);
            for i in 0..nphi {
                let phi = -phi_max + 2.0 * phi_max * i as f64 / (nphi - 1) as f64;
                verts.push(self.world_of(point_at(self, phi, z)));
            }
        }
        grid_mesh(verts, nphi, nz)
    }
}

#[derive(Clone, Debug, Default)]
pub struct JawsOptions {
    pub phantom: PhantomOptions,
    /// `[solve] model = "…"` in every case file; None writes no `[solve]` section (the default
    /// model).
    pub solve_model: Option<String>,
}

/// One osteotomy table of a case file.
fn osteotomy(name: &str, b: [[f64; 3]; 2], moves: &str) -> String {
    let v = |p: [f64; 3]| format!("[{:.1}, {:.1}, {:.1}]", p[0], p[1], p[2]);
    format!(
        "\n[[osteotomy]]\nname = \"{name}\"\nregion = {{ box = {{ min = {}, max = {} }} }}\n{moves}\n",
        v(b[0]),
        v(b[1])
    )
}

/// The text of one case file. `segments` are (name, box, move) in the order they apply.
fn case_text(
    name: &str,
    what: &str,
    segments: &[(&str, [[f64; 3]; 2], String)],
    model: Option<&str>,
    shape: &Shape,
) -> String {
    let c = shape.world_of([0.0, -30.0, -35.0]);
    let radius = 85.0 * shape.scale;
    let mut s = format!(
        r#"# facesim phantom case with jaws: {what} (docs/design/phantom.md, "Jaws").
name = "{name}"

[ct]
path = "ct.nii.gz"

[skin]
path = "face.ply"

[surface]
alpha = 0.01
beta = 0.02
movable = {{ sphere = {{ center = [{:.1}, {:.1}, {:.1}], radius = {radius:.1} }} }}
"#,
        c[0], c[1], c[2]
    );
    for (n, b, m) in segments {
        s.push_str(&osteotomy(n, *b, m));
    }
    if let Some(m) = model {
        s.push_str(&format!("\n[solve]\nmodel = \"{m}\"\n"));
    }
    s
}

/// The four plans: (file name, text).
pub fn case_files(model: Option<&str>) -> Vec<(&'static str, String)> {
    Shape::default().case_files(model)
}

impl Shape {
    /// The four plans of the shaped head, on its boxes and pivot (the moves in mm as for the
    /// standard head): (file name, text).
    pub fn case_files(&self, model: Option<&str>) -> Vec<(&'static str, String)> {
        case_files_of(self, model)
    }
}

fn case_files_of(shape: &Shape, model: Option<&str>) -> Vec<(&'static str, String)> {
    let [front, back, maxilla] = shape.boxes();
    let tr = |d: [f64; 3]| format!("translate = [{:.1}, {:.1}, {:.1}]", d[0], d[1], d[2]);
    let p = shape.condylar_pivot();
    let rot = format!(
        "rotate_deg = [-5.0, 0.0, 0.0]\npivot = [{:.1}, {:.1}, {:.1}]",
        p[0], p[1], p[2]
    );
    // Each segment moves the points inside its box at their current position, so the boxes
    // apply in the order that moves no point into the next box: forwards (advancement, the
    // rotation, whose chin goes up and forwards) front first; backwards (setback) back first.
    vec![
        (
            "case.toml",
            case_text(
                "phantom-jaws-mandible-advance-5mm",
                "mandibular advancement 5 mm",
                &[
                    ("mandible", front, tr([0.0, -5.0, 0.0])),
                    ("mandible_rami", back, tr([0.0, -5.0, 0.0])),
                ],
                model,
                shape,
            ),
        ),
        (
            "case_setback.toml",
            case_text(
                "phantom-jaws-mandible-setback-4mm",
                "mandibular setback 4 mm",
                // A sagittal split setback moves the tooth-bearing segment back; the rami and
                // condyles (the proximal segments) stay in their joints: moving them 4 mm back
                // would push the condyles into the skull base.
                &[("mandible", front, tr([0.0, 4.0, 0.0]))],
                model,
                shape,
            ),
        ),
        (
            "case_rotation.toml",
            case_text(
                "phantom-jaws-mandible-ccw-5deg",
                "counter-clockwise mandibular rotation of 5° about the condylar axis (chin up and forwards)",
                &[
                    ("mandible", front, rot.clone()),
                    ("mandible_rami", back, rot),
                ],
                model,
                shape,
            ),
        ),
        (
            "case_maxilla.toml",
            case_text(
                "phantom-jaws-le-fort-i-advance-4mm",
                "Le Fort I advancement 4 mm",
                &[("maxilla", maxilla, tr([0.0, -4.0, 0.0]))],
                model,
                shape,
            ),
        ),
    ]
}

/// Write the jaws phantom case into `dir`: ct.nii.gz, face.ply and the four case files.
pub fn write_case(dir: &std::path::Path, opts: &JawsOptions) -> Result<()> {
    write_shaped_case(dir, opts, &Shape::default())
}

/// Write the shaped jaws phantom into `dir`: as `write_case`, plus phantom.toml (the shape and
/// its analytic landmarks, world mm).
pub fn write_shaped_case(dir: &std::path::Path, opts: &JawsOptions, shape: &Shape) -> Result<()> {
    shape.validate()?;
    let step = opts.phantom.scan_step_mm;
    if !(step >= 0.1) {
        return Err(Error::config(format!(
            "phantom face scan step {step} mm must be at least 0.1 mm"
        )));
    }
    facesim::output::create_dir_guarded(dir)?;
    let vol = shape.ct(&opts.phantom);
    facesim::volume::nifti_io::write(&vol, &dir.join("ct.nii.gz"))?;
    facesim::mesh::ply::write(
        &shape.face_scan(step),
        &dir.join("face.ply"),
        facesim::mesh::ply::Encoding::BinaryLittleEndian,
    )?;
    for (name, text) in shape.case_files(opts.solve_model.as_deref()) {
        facesim::output::write_bytes_atomic(&dir.join(name), |w| w.write_all(text.as_bytes()))?;
    }
    let text = shape.phantom_toml();
    facesim::output::write_bytes_atomic(&dir.join("phantom.toml"), |w| w.write_all(text.as_bytes()))
}

impl Shape {
    /// phantom.toml: `[shape]` with the parameters and `[landmarks]` with the analytic
    /// landmarks (world mm, LPS), so a cohort's known geometry travels with each case.
    pub(crate) fn phantom_toml(&self) -> String {
        let mut s = String::from(
            "# The jaws phantom's shape and analytic landmarks (LPS mm; docs/design/phantom.md, \"Cohort parameters\").\n[shape]\n",
        );
        for ((name, _, _), v) in SHAPE_RANGES.iter().zip(self.values()) {
            s.push_str(&format!("{name} = {v:?}\n"));
        }
        if self.nasal_passages {
            s.push_str("nasal_passages = true\n");
        }
        s.push_str("\n[landmarks]\n");
        for (name, p) in self.landmarks() {
            s.push_str(&format!(
                "\"{name}\" = [{:.4}, {:.4}, {:.4}]\n",
                p[0], p[1], p[2]
            ));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tooth_bounds_follow_the_arc_length() {
        // Quarter perimeter of the upper ellipse by Ramanujan's formula vs the tooth widths.
        let [a, b] = ARCH_UPPER;
        let quarter = PI * (3.0 * (a + b) - ((3.0 * a + b) * (a + 3.0 * b)).sqrt()) / 4.0;
        let total: f64 = UPPER_WIDTHS.iter().sum();
        assert!(total < quarter, "{total} {quarter}");
        // The first bound: s(t) ≈ a t for small t.
        let t1 = upper_bounds()[1];
        assert!((t1 * a / UPPER_WIDTHS[0] - 1.0).abs() < 0.04, "{t1}");
    }

    /// Points of the nose region on a 1 mm grid (standard frame).
    fn nose_grid() -> impl Iterator<Item = [f64; 3]> {
        (-20..=20).flat_map(|x| {
            (-106..=-66).flat_map(move |y| (0..=44).map(move |z| [x as f64, y as f64, z as f64]))
        })
    }

    #[test]
    fn the_nasal_passages_are_air_inside_a_walled_nose_beside_a_septum() {
        let hollow = Shape {
            nasal_passages: true,
            ..Shape::default()
        };
        let solid = Shape::default();
        let mut passage = 0usize;
        let mut z_range = [f64::INFINITY, f64::NEG_INFINITY];
        for p in nose_grid() {
            let (h, s) = (tissue(&hollow, p), tissue(&solid, p));
            if h == s {
                continue;
            }
            // Only solid tissue under the skin turns to air; the skin never does.
            assert_eq!(h, Tissue::Air, "{p:?}");
            assert!(matches!(s, Tissue::Fat | Tissue::Soft), "{p:?} was {s:?}");
            assert!(p[0].abs() >= NASAL_PASSAGE.1, "{p:?} in the septum");
            // The septum between the passages is tissue.
            assert_ne!(tissue(&hollow, [0.0, p[1], p[2]]), Tissue::Air, "{p:?}");
            // The wall: the outside air is at least 3.5 mm away in each of 26 directions.
            for d in [-1.0f64, 0.0, 1.0].iter().flat_map(|&a| {
                [-1.0f64, 0.0, 1.0]
                    .iter()
                    .flat_map(move |&b| [-1.0f64, 0.0, 1.0].map(move |c| [a, b, c]))
            }) {
                let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                if n == 0.0 {
                    continue;
                }
                let q = [0, 1, 2].map(|k| p[k] + 3.5 * d[k] / n);
                assert!(inside_skin(&hollow, q), "{p:?}: outside air at {q:?}");
            }
            passage += 1;
            z_range = [z_range[0].min(p[2]), z_range[1].max(p[2])];
        }
        println!("passage points {passage}, z {z_range:?}");
        // Two passages of some millilitres (the external nose's vestibules hold ~2 x 2-5 ml),
        // from above the nostril sills to the dorsum below the nasal bones' top.
        assert!(passage > 2000 && passage < 12000, "{passage}");
        assert!(
            z_range[0] >= NASAL_PASSAGE.4 && z_range[1] < 40.0,
            "{z_range:?}"
        );
        // Mirror symmetric, and the skin and its landmarks unchanged.
        for p in nose_grid() {
            assert_eq!(
                tissue(&hollow, p),
                tissue(&hollow, [-p[0], p[1], p[2]]),
                "{p:?}"
            );
        }
        assert_eq!(hollow.landmarks(), solid.landmarks());
        assert!(hollow.phantom_toml().contains("nasal_passages = true"));
        assert!(!solid.phantom_toml().contains("nasal_passages"));
    }

    /// The vertical pattern stretches the head below the maxilla's top and nothing above it:
    /// ANS–menton grows by exactly vertical_mm (scaled), the CT is the standard head's tissue
    /// at the mapped points, and the field of view grows with the stretch.
    #[test]
    fn the_vertical_pattern_stretches_the_lower_face_only() {
        let scale = 1.1;
        let plain = Shape {
            scale,
            ..Shape::default()
        };
        let long = Shape {
            vertical_mm: 6.0,
            ..plain
        };
        let standard = Shape::default();
        // ANS (the maxilla's top on the midline; the anterior nasal spine) to menton, along
        // z, of the truth landmarks.
        let ans_me = |s: &Shape| {
            let ans = s.world_of([0.0, Y_ARCH - ARCH_UPPER[1], Z_MAXILLA_TOP]);
            ans[2] - s.landmark("menton").unwrap()[2]
        };
        assert!((ans_me(&plain) - LOWER_FACE_MM * scale).abs() < 1e-9);
        assert!(
            (ans_me(&long) - ans_me(&plain) - 6.0 * scale).abs() < 1e-9,
            "{} vs {}",
            ans_me(&long),
            ans_me(&plain)
        );
        let short = Shape {
            vertical_mm: -5.0,
            ..plain
        };
        assert!((ans_me(&short) - ans_me(&plain) + 5.0 * scale).abs() < 1e-9);
        // Landmarks above the stretch are unchanged (the nose's and forehead's; subnasale's
        // search bracket starts at the stretched labrale superius, hence the tolerance), those
        // below have the same x and y and lie lower.
        for ((name, a), (_, b)) in long.landmarks().into_iter().zip(plain.landmarks()) {
            if b[2] >= Z_VERTICAL * scale {
                let d = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max);
                assert!(d < 1e-6, "{name}: {a:?} vs {b:?}");
            } else {
                assert!(
                    (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6,
                    "{name}: {a:?} vs {b:?}"
                );
                assert!(a[2] < b[2], "{name}: {a:?} vs {b:?}");
            }
        }
        // Points and the skin above z0 are unchanged, bit for bit.
        for p in [[3.0, -60.0, 1.5], [-20.0, -70.0, 2.0], [0.0, -100.0, 13.0]] {
            assert_eq!(long.world_of(p), plain.world_of(p));
            let w = plain.world_of(p);
            assert_eq!(long.standard_of(w), plain.standard_of(w));
            assert_eq!(long.tissue_at(w), plain.tissue_at(w));
            assert_eq!(long.skin_radius(0.3, w[2]), plain.skin_radius(0.3, w[2]));
        }
        // Below, the maps are each other's inverse and follow the stretch.
        let p = [10.0, -50.0, -40.0];
        let w = long.world_of(p);
        let k = 1.0 + 6.0 / LOWER_FACE_MM;
        assert!((w[2] - scale * (Z_VERTICAL + (p[2] - Z_VERTICAL) * k)).abs() < 1e-12);
        let back = long.standard_of(w);
        assert!((0..3).all(|a| (back[a] - p[a]).abs() < 1e-12), "{back:?}");
        // The CT, the pieces and the vestibule at world_of(p) are the standard head's at p:
        // points in the chin, the teeth, the vestibule, the lips, the fat, the neck, a condyle.
        let points = [
            [0.3, -73.1, -55.2],
            [0.2, -71.7, -18.1],
            [0.4, -73.0, -30.9],
            [0.1, -73.3, -10.3],
            [0.3, -84.2, -32.1],
            [5.3, -79.5, -40.2],
            [0.6, -37.3, -90.7],
            [3.1, -54.2, -95.3],
            [47.9, 7.1, -2.9],
            [40.3, 5.2, -30.1],
            [0.2, -60.1, -4.1],
        ];
        let mut seen = Vec::new();
        for p in points {
            let w = long.world_of(p);
            let t = tissue_at(p);
            assert_eq!(long.tissue_at(w), t, "{p:?}");
            assert_eq!(long.piece_at(w), piece_at(p), "{p:?}");
            assert_eq!(long.in_vestibule(w), in_vestibule(p), "{p:?}");
            // The skin there: the standard head's radius, scaled.
            let phi = p[0].atan2(-p[1]);
            let r = long.skin_radius(phi, w[2]);
            assert!((r - scale * skin_radius(phi, p[2])).abs() < 1e-9, "{p:?}");
            if !seen.contains(&t) {
                seen.push(t);
            }
        }
        for t in [
            Tissue::Bone,
            Tissue::Tooth,
            Tissue::Air,
            Tissue::Soft,
            Tissue::Fat,
        ] {
            assert!(seen.contains(&t), "no {t:?} among the points: {seen:?}");
        }
        // The field of view: its top as the plain head's, its lower end stretched with the
        // face, so bony and soft menton and the neck below them are in the CT as far above
        // its lower end as in the standard head, stretched and scaled.
        let [lo, hi] = long.fov();
        let [plo, phi_] = plain.fov();
        assert_eq!(hi, phi_);
        assert_eq!([lo[0], lo[1]], [plo[0], plo[1]]);
        assert!((lo[2] - long.world_of(FOV_LO)[2]).abs() < 1e-12);
        assert!(lo[2] < plo[2], "{lo:?} vs {plo:?}");
        for name in ["menton", "soft tissue menton"] {
            let (m, sm) = (
                long.landmark(name).unwrap(),
                standard.landmark(name).unwrap(),
            );
            assert!(m[2] > lo[2] && m[2] < hi[2], "{name} {m:?} outside {lo:?}");
            let margin = (m[2] - lo[2]) / (sm[2] - FOV_LO[2]);
            assert!((margin - k * scale).abs() < 1e-6, "{name}: {margin}");
        }
        // The CT's bottom slice cuts through the neck: tissue on the axis's front there.
        let neck = [0.0, -30.0 * scale, lo[2] + 0.5];
        assert_ne!(long.tissue_at(neck), Tissue::Air, "{neck:?}");
        // The face scan reaches as far down (to the standard −85, stretched) with rows about
        // step apart in the world.
        let scan = long.face_scan(2.0);
        let zmin = scan
            .vertices
            .iter()
            .map(|v| v[2])
            .fold(f64::INFINITY, f64::min);
        assert!(
            (zmin - long.world_of([0.0, 0.0, -85.0])[2]).abs() < 1e-9,
            "{zmin}"
        );
        let mut zs: Vec<f64> = scan.vertices.iter().map(|v| v[2]).collect();
        zs.sort_by(f64::total_cmp);
        zs.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        let gaps = zs.windows(2).map(|w| w[1] - w[0]);
        assert!(gaps.clone().all(|g| (g - 2.0).abs() < 0.05), "{zs:?}");
    }

    #[test]
    fn arch_depth_is_adult() {
        // From the incisors' labial point to the line through the second molars' distal ends.
        for (ab, bounds) in [(ARCH_UPPER, upper_bounds()), (ARCH_LOWER, lower_bounds())] {
            let depth = ab[1] * (1.0 - bounds[7].cos());
            println!("arch depth {depth:.1} mm");
            // Adult arch depths to the second molars span about 38–50 mm.
            assert!((38.0..=50.0).contains(&depth), "{depth}");
        }
    }
}

//! The bony anatomy a plan in clinical terms needs, found from the CT (docs/planning.md):
//!
//! - `head`: the clinical head frame — Frankfort horizontal (porion and orbitale, both sides)
//!   and the midsagittal plane, or where the CT does not hold them the soft-tissue facial plane
//!   N'–Pog' as the vertical of natural head position;
//! - `jaws`: the bony landmarks of the maxilla and the mandible the cuts are placed from;
//! - `cuts`: the osteotomies of `[[surgery]]` entries as segments of bone.
//!
//! Every landmark is detected or missing with the reason; positions are LPS mm.

pub mod cuts;
pub mod head;
pub mod jaws;
pub mod moves;
pub mod readback;
pub mod surgery;

use crate::labels;
use crate::volume::Volume;

/// The CT and its tissue labels, with the bone test the detectors share.
pub struct Bone<'a> {
    pub vol: &'a Volume,
    /// Tissue labels per voxel (`crate::labels`), the segmentation's.
    pub labels: &'a [u8],
}

impl Bone<'_> {
    /// Whether the voxel nearest to p (LPS mm) is bone; false outside the CT.
    pub fn is_bone(&self, p: [f64; 3]) -> bool {
        let c = self.vol.to_voxel(p).map(f64::round);
        if (0..3).any(|a| c[a] < 0.0 || c[a] >= self.vol.dims[a] as f64) {
            return false;
        }
        self.labels[self.vol.idx(c[0] as usize, c[1] as usize, c[2] as usize)] == labels::BONE
    }
}

/// The bony landmark labels found from the CT, in the order report.json lists them.
/// Paired ones end in `-R` / `-L` (the patient's right and left).
pub const LANDMARKS: [&str; 27] = [
    "Po-R", "Po-L", "Or-R", "Or-L", // Frankfort horizontal: porion, orbitale
    "ANS", "A", "PNS", "Pir-R", "Pir-L", // maxilla; Pir: lowest point of the piriform rim
    "PTM-R", "PTM-L", // pterygomaxillary junction, at the Le Fort I level
    "U1", "U1-apex", "L1", "L1-apex", // incisal edges and root apices (central incisors)
    "U6-R", "U6-L", // upper first molars' mesiobuccal cusps (the occlusal plane)
    "B", "Pog", "Gn", "Me", // symphysis
    "MF-R", "MF-L", // mental foramina
    "Go-R", "Go-L", // gonion
    "Co-R", "Co-L", // condylion: the top of each condylar head
];

/// `frame` turned face-down by `pitch_deg` about its lateral axis: forward tips down, up tips
/// forward (the origin and the midsagittal plane stay).
pub fn turned(frame: &crate::landmarks::HeadFrame, pitch_deg: f64) -> crate::landmarks::HeadFrame {
    use crate::vec3::{add, scale, sub};
    let (s, c) = pitch_deg.to_radians().sin_cos();
    let mut f = *frame;
    f.anterior = sub(scale(frame.anterior, c), scale(frame.vertical, s));
    f.vertical = add(scale(frame.vertical, c), scale(frame.anterior, s));
    f
}

/// The clinical frame and the bony landmarks of a head.
pub struct Anatomy {
    pub frame: head::ClinicalFrame,
    /// Every label of [`LANDMARKS`], detected or missing with the reason.
    pub landmarks: Vec<crate::landmarks::Landmark>,
}

/// Find the clinical frame (from `midsagittal`, the skin's symmetry frame, and `soft`, its
/// soft-tissue landmarks) and then the jaw landmarks in it. Err: `[head] frame` asks for a
/// method the CT cannot give.
pub fn find(
    bone: &Bone,
    midsagittal: &crate::landmarks::HeadFrame,
    soft: &[crate::landmarks::Landmark],
    head: &crate::case::Head,
) -> Result<Anatomy, String> {
    let frame = head::clinical_frame(bone, midsagittal, soft, head)?;
    let mut landmarks = frame.landmarks.clone();
    landmarks.extend(jaws::jaw_landmarks(bone, &frame.frame));
    Ok(Anatomy { frame, landmarks })
}

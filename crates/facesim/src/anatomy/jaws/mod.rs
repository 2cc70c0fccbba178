//! The bony landmarks of the maxilla and the mandible (docs/planning.md "Landmarks").

use super::Bone;
use crate::landmarks::{HeadFrame, Kind, Landmark};

/// The jaw landmarks of `super::LANDMARKS` (all but porion and orbitale), each detected or
/// missing with the reason, searched in the clinical frame `frame`.
pub fn jaw_landmarks(bone: &Bone, frame: &HeadFrame) -> Vec<Landmark> {
    let _ = (bone, frame);
    super::LANDMARKS[4..]
        .iter()
        .map(|l| Landmark::missing(l, Kind::Bone, "not detected yet".into()))
        .collect()
}

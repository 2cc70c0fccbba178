//! The anatomy of a head: the clinical frame, then the jaw landmarks found in it.

use super::bone::Bone;
use super::{head, jaws};

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

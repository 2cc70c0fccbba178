//! The clinical head frame (docs/planning.md "The head frame").

use super::Bone;
use crate::case::{FrameChoice, Head};
use crate::landmarks::{HeadFrame, Landmark};
use serde::Serialize;

/// How the clinical frame was found.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Frankfort horizontal through porion and orbitale, both sides.
    Frankfort,
    /// The soft-tissue facial plane N'–Pog' taken as vertical (natural head position estimated).
    FacialPlane,
    /// Neither could be found: the CT's superior axis is up.
    CtAxes,
}

/// The clinical head frame: `frame.anterior` is forward, `frame.vertical` up,
/// `frame.lateral` toward the patient's left; origin on the midsagittal plane.
#[derive(Clone, Debug, Serialize)]
pub struct ClinicalFrame {
    pub frame: HeadFrame,
    pub method: Method,
    /// Why this method: what was found, or what was missing.
    pub why: String,
    /// The found frame's pitch from the CT's axes (degrees, face down +), before `[head] pitch_deg`.
    pub pitch_deg: f64,
    /// `[head] pitch_deg`, added.
    pub correction_deg: f64,
    /// Porion and orbitale, both sides, each detected or missing with the reason.
    pub landmarks: Vec<Landmark>,
}

/// The clinical frame of a head: `midsagittal` is the skin's symmetry frame
/// (`crate::landmarks::head_frame`), `soft` its soft-tissue landmarks (N', Pog' for the
/// fallback). Err: the one-line reason when `[head] frame` asks for a method the CT cannot
/// give.
pub fn clinical_frame(
    bone: &Bone,
    midsagittal: &HeadFrame,
    soft: &[Landmark],
    head: &Head,
) -> Result<ClinicalFrame, String> {
    let _ = (bone, soft);
    if head.frame == Some(FrameChoice::Frankfort) {
        return Err("[head] frame = \"frankfort\": porion and orbitale are not detected yet".into());
    }
    let frame = super::turned(midsagittal, head.pitch_deg);
    Ok(ClinicalFrame {
        frame,
        method: Method::CtAxes,
        why: "porion and orbitale are not detected yet".into(),
        pitch_deg: 0.0,
        correction_deg: head.pitch_deg,
        landmarks: Vec::new(),
    })
}

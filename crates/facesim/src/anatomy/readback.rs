//! The plan read back in the surgeon's terms (report.json `clinical_frame` and `plan`;
//! docs/guide/planning.md "The plan read back"): each segment's six moves in the clinical head frame,
//! and each bony landmark's move forward, up and toward the patient's left.

use super::find::Anatomy;
use super::moves::{self, Moves};
use super::surgery::Planned;
use crate::landmarks::{HeadFrame, Ordered};
use crate::osteotomy::Plan;
use crate::vec3::{dot, sub};
use serde::{Deserialize, Serialize};

/// report.json `clinical_frame`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FrameReport {
    /// "frankfort", "facial-plane" or "ct-axes".
    pub method: String,
    pub why: String,
    /// The found frame's pitch from the CT's axes (degrees, face down +).
    pub pitch_deg: f64,
    /// `[head] pitch_deg`, added to it.
    pub correction_deg: f64,
    /// A point on the midsagittal plane and the axes (LPS unit vectors).
    pub origin: [f64; 3],
    pub forward: [f64; 3],
    pub up: [f64; 3],
    pub left: [f64; 3],
}

impl FrameReport {
    pub fn of(a: &Anatomy) -> FrameReport {
        let f = &a.frame;
        FrameReport {
            method: serde_json::to_value(f.method)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default(),
            why: f.why.clone(),
            pitch_deg: f.pitch_deg,
            correction_deg: f.correction_deg,
            origin: f.frame.origin,
            forward: f.frame.anterior,
            up: f.frame.vertical,
            left: f.frame.lateral,
        }
    }

    /// The frame these axes span.
    pub fn frame(&self) -> HeadFrame {
        HeadFrame {
            origin: self.origin,
            lateral: self.left,
            vertical: self.up,
            anterior: self.forward,
            symmetry_residual_mm: f64::NAN,
        }
    }
}

/// One segment of report.json `plan`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SegmentMove {
    pub name: String,
    /// "le-fort-i", "bsso", "genioplasty", "autorotation"; absent for an `[[osteotomy]]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surgery: Option<String>,
    /// The pivot (LPS mm) and, when a landmark, its label.
    pub pivot: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pivot_landmark: Option<String>,
    /// The segment's whole move in the head frame, about the pivot (a chin on a moved
    /// mandible: the mandible's move and its own).
    pub moves: Moves,
    /// The bone the cut freed (mL) and the files holding it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_ml: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<String>,
}

/// One bony landmark of report.json `plan.landmarks`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LandmarkMove {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pre: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub post: Option<[f64; 3]>,
    /// The move forward, up and toward the patient's left (mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub forward_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left_mm: Option<f64>,
    /// The segment that moved it (none: it stays).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segment: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
}

/// report.json `plan`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PlanReport {
    pub segments: Vec<SegmentMove>,
    pub landmarks: Ordered<LandmarkMove>,
}

/// The plan `plan` (every step; the first `planned.len()` are the surgeries) read in `a`'s
/// frame.
pub(crate) fn plan_report(a: &Anatomy, planned: &[Planned], plan: &Plan) -> PlanReport {
    let frame = &a.frame.frame;
    let segments = plan
        .segments()
        .iter()
        .enumerate()
        .map(|(k, o)| {
            let p = planned.get(k);
            SegmentMove {
                name: o.name.clone(),
                surgery: p.map(|p| p.what.to_string()),
                pivot: o.pivot,
                pivot_landmark: p.map(|p| p.pivot_label.clone()).filter(|l| l != "point"),
                moves: moves::read_back(
                    frame,
                    crate::osteotomy::rotation(o.rotate_deg),
                    o.translate,
                ),
                bone_ml: p.map(|p| p.segment.bone_ml),
                mesh: p.map(|p| format!("segment_{}.ply", p.name)),
                mask: p.map(|p| format!("segment_{}.nii.gz", p.name)),
            }
        })
        .collect();
    let found: Vec<[f64; 3]> = a.landmarks.iter().filter_map(|l| l.position).collect();
    let (moved, by) = plan.carry_steps(&found);
    let mut next = moved.iter().zip(&by);
    let landmarks = a
        .landmarks
        .iter()
        .map(|l| {
            let m = match l.position {
                None => LandmarkMove {
                    pre: None,
                    post: None,
                    forward_mm: None,
                    up_mm: None,
                    left_mm: None,
                    segment: None,
                    missing: l.missing.clone(),
                },
                Some(pre) => {
                    let (post, step) = next.next().map(|(p, s)| (*p, *s)).unwrap_or((pre, None));
                    let d = sub(post, pre);
                    LandmarkMove {
                        pre: Some(pre),
                        post: Some(post),
                        forward_mm: Some(dot(d, frame.anterior)),
                        up_mm: Some(dot(d, frame.vertical)),
                        left_mm: Some(dot(d, frame.lateral)),
                        segment: step.map(|s| plan.segments()[s].name.clone()),
                        missing: None,
                    }
                }
            };
            (l.label.clone(), m)
        })
        .collect();
    PlanReport {
        segments,
        landmarks: Ordered(landmarks),
    }
}

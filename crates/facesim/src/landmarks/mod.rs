//! Cephalometric landmarks, measurements and facial regions (docs/guide/landmarks.md).
//!
//! - `frame`: the head frame (midsagittal plane by mirror symmetry) and midsagittal profiles;
//! - `detect`: soft-tissue and bony landmarks on the profiles, or why each is missing;
//! - `lateral`: the paired ones beside the midline (alare, cheilion);
//! - `measure`: nasolabial and mentolabial angles, lips to the E-line, soft/hard ratios;
//! - `markups`: 3D Slicer markups files (.mrk.json) in and out;
//! - `face_regions`: nose, lips, chin and cheeks from the landmarks, and their statistics.
//!
//! [`locate`] finds the landmarks of a pre-operative face (user landmarks override detection);
//! [`carry`] takes them to the predicted face as the same material points.

pub mod clinic;
pub(crate) mod detect;
mod extremum;
pub mod face_regions;
pub mod frame;
mod landmark;
mod lateral;
pub mod markups;
pub mod measure;
pub mod outcome;
pub mod published;
pub mod scan;

use crate::compare::SurfaceIndex;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::osteotomy::Plan;
use crate::vec3::{norm, sub};
use std::path::Path;

pub(crate) use detect::kind_of;
pub use detect::{BONE, SOFT};
pub use frame::{HeadFrame, head_frame};
pub use landmark::{Carried, Kind, Landmark, Ordered, Source, SurfaceAnchor, positions};
pub use lateral::PAIRED;

/// A user landmark farther than this from the face (soft) is an input error.
pub(crate) const USER_MAX_OFF_FACE_MM: f64 = 10.0;

/// The landmarks of a pre-operative face: detected on `skin` and `skull` in the head frame,
/// then each user landmark (`[[landmark]]`, or a markups file read into them) replaces the
/// detected one of its label or is added. A soft user landmark more than
/// `USER_MAX_OFF_FACE_MM` from the skin is an error naming `case_file`.
pub fn locate(
    skin: &Mesh,
    skull: Option<&Mesh>,
    user: &[(String, [f64; 3])],
    case_file: &Path,
) -> Result<(Option<HeadFrame>, Vec<Landmark>)> {
    let frame = head_frame(skin);
    let mut lms = match &frame {
        Some(f) => {
            let mut lms = detect::detect(skin, skull, f);
            let paired = lateral::with_paired(skin, f, &lms);
            lms.extend(paired);
            lms
        }
        None => SOFT
            .iter()
            .chain(BONE.iter())
            .chain(PAIRED.iter())
            .map(|l| Landmark::missing(l, kind_of(l), "the skin is empty".into()))
            .collect(),
    };
    if !user.is_empty() {
        let index = SurfaceIndex::new(skin);
        for (label, p) in user {
            let kind = kind_of(label);
            if kind == Kind::Soft {
                let (d, _) = index.closest(*p);
                if !(d <= USER_MAX_OFF_FACE_MM) {
                    return Err(Error::input(
                        case_file,
                        format!(
                            "landmark '{label}' at [{:.1}, {:.1}, {:.1}] (LPS mm) is {d:.1} mm from the face; a soft-tissue landmark must lie within {USER_MAX_OFF_FACE_MM} mm of it",
                            p[0], p[1], p[2]
                        ),
                    ));
                }
            }
            let lm = Landmark {
                label: label.clone(),
                kind,
                position: Some(*p),
                source: Source::User,
                missing: None,
            };
            match lms.iter_mut().find(|l| l.label == *label) {
                Some(l) => *l = lm,
                None => lms.push(lm),
            }
        }
    }
    Ok((frame, lms))
}

/// The surface anchors of the soft landmarks of `lms` on `face_pre` (None: bony or missing).
pub fn anchors(lms: &[Landmark], face_pre: &Mesh) -> Vec<Option<SurfaceAnchor>> {
    let index = SurfaceIndex::new(face_pre);
    lms.iter()
        .map(|l| match (l.kind, l.position) {
            (Kind::Soft, Some(p)) => Some(SurfaceAnchor::new(&index, face_pre, p)),
            _ => None,
        })
        .collect()
}

/// The landmarks on the predicted face: a soft one as the same material point (its closest
/// point on `face_pre`, in barycentric coordinates of that triangle, applied to `face_post`,
/// which has face_pre's vertices and triangles in the same order); a bony one moved by the
/// plan's rigid move of the segment that holds it.
pub fn carry(lms: &[Landmark], face_pre: &Mesh, face_post: &Mesh, plan: &Plan) -> Vec<Carried> {
    carry_anchored(lms, &anchors(lms, face_pre), face_post, plan)
}

/// [`carry`] with the anchors already found (a sweep carries the same landmarks many times).
pub(crate) fn carry_anchored(
    lms: &[Landmark],
    anchors: &[Option<SurfaceAnchor>],
    face_post: &Mesh,
    plan: &Plan,
) -> Vec<Carried> {
    lms.iter()
        .zip(anchors)
        .map(|(l, a)| {
            let post = l.position.map(|p| match (l.kind, a) {
                (Kind::Soft, Some(a)) => a.place(&face_post.triangles, &face_post.vertices),
                _ => plan.apply(&[p], 1.0).0[0],
            });
            Carried {
                label: l.label.clone(),
                kind: l.kind,
                source: l.source,
                pre: l.position,
                post,
                change_mm: l.position.zip(post).map(|(a, b)| norm(sub(b, a))),
                missing: l.missing.clone(),
            }
        })
        .collect()
}

/// Everything the landmark stage reports (report.json `landmarks`, `measurements`,
/// `soft_hard_ratios`, `regions`, `head_frame`).
#[derive(Clone, Debug, Default)]
pub struct Analysis {
    pub frame: Option<HeadFrame>,
    /// The pre-operative landmarks and, for the soft ones, where they sit on face_pre.
    pub landmarks: Vec<Landmark>,
    pub anchors: Vec<Option<SurfaceAnchor>>,
    pub carried: Vec<Carried>,
    pub measurements: Ordered<measure::Measure>,
    pub ratios: Ordered<measure::Ratio>,
    /// The plan's surgery type and its published ratios as predicted (None without a head frame).
    pub clinic: Option<clinic::Clinic>,
    pub regions: Ordered<face_regions::RegionStats>,
    /// Per face vertex, its region's index in `face_regions::NAMES` (`face_regions::NONE`: none).
    pub region_of: Vec<u8>,
}

/// Landmarks, measurements and region statistics of one prediction.
pub fn analyse(
    face_pre: &Mesh,
    face_post: &Mesh,
    skull: Option<&Mesh>,
    plan: &Plan,
    user: &[(String, [f64; 3])],
    case_file: &Path,
) -> Result<Analysis> {
    let (frame, lms) = locate(face_pre, skull, user, case_file)?;
    Ok(analyse_located(face_pre, face_post, frame, lms, plan))
}

/// [`analyse`] of landmarks already located (a run's, read back from its report.json).
pub fn analyse_located(
    face_pre: &Mesh,
    face_post: &Mesh,
    frame: Option<HeadFrame>,
    lms: Vec<Landmark>,
    plan: &Plan,
) -> Analysis {
    let anchors = anchors(&lms, face_pre);
    let carried = carry_anchored(&lms, &anchors, face_post, plan);
    let (measurements, ratios) = match &frame {
        Some(f) => measure::measure(&carried, f),
        None => (Ordered::default(), Ordered::default()),
    };
    let clinic = frame
        .as_ref()
        .map(|f| clinic::against_published(plan.segments(), &carried, f));
    let (regions, region_of) = match &frame {
        Some(f) => {
            let r = face_regions::regions(&face_pre.vertices, f, &positions(&lms));
            let dist: Vec<f64> = face_pre
                .vertices
                .iter()
                .zip(&face_post.vertices)
                .map(|(a, b)| norm(sub(*a, *b)))
                .collect();
            (
                face_regions::displacement_stats(&r, &dist),
                r.index(face_pre.vertices.len()),
            )
        }
        None => (
            Ordered::default(),
            vec![face_regions::NONE; face_pre.vertices.len()],
        ),
    };
    Analysis {
        frame,
        landmarks: lms,
        anchors,
        carried,
        measurements,
        ratios,
        clinic,
        regions,
        region_of,
    }
}

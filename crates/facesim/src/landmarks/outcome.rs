//! Outcomes measured the clinic's way (`facesim compare A B --landmarks`, docs/guide/landmarks.md
//! "Two faces of one person"): two face meshes of one person — a prediction and the
//! post-operative 3D photo, or two photos — each in its own frame and unit, registered rigidly
//! on what surgery does not move, then compared per landmark and per facial region (mean, p90,
//! % within 2 mm: the measures of Liebregts et al. 2015 and the studies of VALIDATION.md).

use super::face_regions::{self, RegionDistance};
use super::landmark::{Landmark, Ordered, positions};
use super::scan::{FaceLandmarks, FrameFrom, landmarks_of};
use crate::compare::SurfaceIndex;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::surface::register::{Transform, fit};
use crate::vec3::{dot, norm, scale, sub};
use serde::Serialize;
use std::path::Path;

/// A rigid motion p ↦ R p + t (mm).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Rigid {
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

/// How A was laid onto B.
#[derive(Clone, Debug, Serialize)]
pub struct Registration {
    /// Which of A's skin took part, in words.
    pub on: String,
    pub vertices: usize,
    /// RMS distance of those vertices to B after the fit (mm; the worse 10 % left out).
    pub rms_mm: f64,
    pub iterations: usize,
    /// A (in mm) to B (in mm).
    pub motion: Rigid,
}

/// One landmark's distance between the faces after registration.
#[derive(Clone, Debug, Serialize)]
pub struct LandmarkDistance {
    pub distance_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
}

/// `compare --landmarks`: the faces' units and landmarks, the registration, and the distances.
#[derive(Clone, Debug, Serialize)]
pub struct Outcome {
    pub a: FaceLandmarks,
    pub b: FaceLandmarks,
    pub registration: Registration,
    pub landmarks: Ordered<LandmarkDistance>,
    /// Per facial region of A (after registration): its vertices' distances to B's surface.
    pub regions: Ordered<RegionDistance>,
    /// A laid onto B, in B's head frame as LPS (x to the left, −y forward, z up; mm), and each
    /// of its vertices' distance to B: for a picture.
    #[serde(skip)]
    pub a_in_frame: Mesh,
    #[serde(skip)]
    pub distances: Vec<f64>,
}

fn found(f: &FaceLandmarks, label: &str) -> Option<[f64; 3]> {
    f.landmarks
        .iter()
        .find(|l| l.label == label)
        .and_then(|l| l.position)
        .map(|p| scale(p, f.unit.mm_per_unit))
}

fn in_mm(m: &Mesh, f: &FaceLandmarks) -> Mesh {
    let k = f.unit.mm_per_unit;
    Mesh::new(
        m.vertices.iter().map(|p| scale(*p, k)).collect(),
        m.triangles.clone(),
    )
}

/// Skin above this far over pronasale's height is what a jaw operation leaves in place: the
/// forehead, the eyes, the nasal bridge (mm; Le Fort I cuts below the nose's bony base).
const STABLE_ABOVE_PRN_MM: f64 = 15.0;

/// Compare face A with face B (any frames and units): A is laid onto B by its stable skin and
/// both are measured in mm. Errors are input errors naming the face they are about.
pub fn compare_faces(a: &Mesh, a_path: &Path, b: &Mesh, b_path: &Path) -> Result<Outcome> {
    let fa = landmarks_of(a, FrameFrom::Shape).map_err(|e| Error::input(a_path, e))?;
    let fb = landmarks_of(b, FrameFrom::Shape).map_err(|e| Error::input(b_path, e))?;
    let (am, bm) = (in_mm(a, &fa), in_mm(b, &fb));
    let start = starting_motion(&fa, a_path, &fb, b_path)?;
    let stable = stable_skin(&am, &fa, a_path)?;
    let on_b = SurfaceIndex::new(&bm);
    let (motion, rms, iterations) = icp(&stable, &on_b, start)?;
    let a_on_b: Vec<[f64; 3]> = am.vertices.iter().map(|p| motion.apply(*p)).collect();
    let lms_a: Vec<(String, [f64; 3])> = positions(&fa.landmarks)
        .into_iter()
        .map(|(l, p)| (l, motion.apply(scale(p, fa.unit.mm_per_unit))))
        .collect();
    let landmarks = landmark_distances(&fa, &lms_a, &fb);
    // Regions of A (registered), in B's head frame.
    let frame_b = super::HeadFrame {
        origin: scale(fb.frame.origin, fb.unit.mm_per_unit),
        lateral: fb.frame.lateral,
        vertical: fb.frame.vertical,
        anterior: fb.frame.anterior,
        symmetry_residual_mm: fb.frame.symmetry_residual_mm,
    };
    let r = face_regions::regions(&a_on_b, &frame_b, &lms_a);
    let distances = on_b.distances(&a_on_b);
    let regions = face_regions::distance_stats(&r, &distances);
    let a_in_frame = Mesh::new(
        a_on_b
            .iter()
            .map(|p| {
                let c = frame_b.coords(*p);
                [c[0], -c[2], c[1]]
            })
            .collect(),
        am.triangles.clone(),
    );
    Ok(Outcome {
        a_in_frame,
        distances,
        registration: Registration {
            on: format!(
                "A's skin more than {STABLE_ABOVE_PRN_MM} mm above its pronasale (forehead, eyes, nasal bridge)"
            ),
            vertices: stable.len(),
            rms_mm: rms,
            iterations,
            motion: Rigid {
                rotation: motion.rotation,
                translation: motion.translation,
            },
        },
        a: fa,
        b: fb,
        landmarks,
        regions,
    })
}

/// The fit's start: A's head frame onto B's, A's soft nasion (else its nose tip) onto B's.
fn starting_motion(
    fa: &FaceLandmarks,
    a_path: &Path,
    fb: &FaceLandmarks,
    b_path: &Path,
) -> Result<Transform> {
    let axes = |f: &FaceLandmarks| [f.frame.lateral, f.frame.vertical, f.frame.anterior];
    let (xa, xb) = (axes(fa), axes(fb));
    let rotation = [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| xb[k][i] * xa[k][j]).sum()));
    let anchor = ["N'", "Prn"]
        .into_iter()
        .find_map(|l| Some((found(fa, l)?, found(fb, l)?)))
        .ok_or_else(|| {
            Error::input(
                a_path,
                format!(
                    "shares neither a soft nasion nor a pronasale with {} to start the fit from",
                    b_path.display()
                ),
            )
        })?;
    let mut motion = Transform {
        rotation,
        translation: [0.0; 3],
        scale: 1.0,
        rms_residual: 0.0,
        max_residual: 0.0,
    };
    motion.translation = sub(anchor.1, motion.apply(anchor.0));
    Ok(motion)
}

/// The stable skin of A (`am`, in mm): above pronasale by STABLE_ABOVE_PRN_MM in A's frame,
/// thinned to about 3000 points.
fn stable_skin(am: &Mesh, fa: &FaceLandmarks, a_path: &Path) -> Result<Vec<[f64; 3]>> {
    let prn = found(fa, "Prn").ok_or_else(|| Error::input(a_path, "no pronasale"))?;
    let v_prn = dot(prn, fa.frame.vertical);
    let stable: Vec<[f64; 3]> = am
        .vertices
        .iter()
        .filter(|p| dot(**p, fa.frame.vertical) > v_prn + STABLE_ABOVE_PRN_MM)
        .copied()
        .collect();
    if stable.len() < 100 {
        return Err(Error::input(
            a_path,
            format!(
                "{} vertices more than {STABLE_ABOVE_PRN_MM} mm above its nose tip: too little forehead and nasal bridge to register on",
                stable.len()
            ),
        ));
    }
    let step = (stable.len() / 3000).max(1);
    Ok(stable.into_iter().step_by(step).collect())
}

/// ICP from `motion`: each stable point, moved, to its closest point on B; the better 90 % of
/// the pairs give the next motion (the least-squares rigid fit of `register::fit`, from A's own
/// points). The motion, the last RMS distance (mm) and the iterations.
fn icp(
    stable: &[[f64; 3]],
    index: &SurfaceIndex,
    mut motion: Transform,
) -> Result<(Transform, f64, usize)> {
    let mut rms = f64::NAN;
    let mut iterations = 0;
    for it in 0..60 {
        iterations = it + 1;
        let mut pairs: Vec<([f64; 3], [f64; 3], f64)> = stable
            .iter()
            .map(|p| {
                let (d, q) = index.closest(motion.apply(*p));
                (*p, q, d)
            })
            .collect();
        pairs.sort_by(|x, y| x.2.total_cmp(&y.2));
        pairs.truncate((pairs.len() * 9).div_ceil(10));
        rms = (pairs.iter().map(|x| x.2 * x.2).sum::<f64>() / pairs.len() as f64).sqrt();
        let (from, to): (Vec<_>, Vec<_>) = pairs.iter().map(|x| (x.0, x.1)).unzip();
        let next = fit(&from, &to, false)?;
        let shift = from
            .iter()
            .map(|p| norm(sub(next.apply(*p), motion.apply(*p))))
            .fold(0.0, f64::max);
        motion = next;
        if shift < 1e-4 {
            break;
        }
    }
    Ok((motion, rms, iterations))
}

/// Per landmark of A, its distance (mm) between A registered (`lms_a`) and B, or why it is
/// missing.
fn landmark_distances(
    fa: &FaceLandmarks,
    lms_a: &[(String, [f64; 3])],
    fb: &FaceLandmarks,
) -> Ordered<LandmarkDistance> {
    let mut landmarks = Ordered::default();
    for l in &fa.landmarks {
        let why = |f: &FaceLandmarks, which: &str| {
            f.landmarks
                .iter()
                .find(|x| x.label == l.label)
                .and_then(|x: &Landmark| x.missing.clone())
                .map(|m| format!("not found on {which}: {m}"))
        };
        let pa = lms_a.iter().find(|(k, _)| *k == l.label).map(|x| x.1);
        let pb = found(fb, &l.label);
        landmarks.0.push((
            l.label.clone(),
            match (pa, pb) {
                (Some(p), Some(q)) => LandmarkDistance {
                    distance_mm: Some(norm(sub(p, q))),
                    missing: None,
                },
                _ => LandmarkDistance {
                    distance_mm: None,
                    missing: why(fa, "A").or_else(|| why(fb, "B")),
                },
            },
        ));
    }
    landmarks
}

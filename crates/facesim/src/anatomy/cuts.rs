//! Osteotomies from the bony landmarks (docs/guide/planning.md "The cuts").
//!
//! Each cut is a set of planes in the clinical head frame; its segment is the bone on the freed
//! side of every plane that is connected to the segment's own landmarks (the incisors, the
//! chin), so that a stray piece of bone inside the planes (a coronoid process, the hyoid) stays.
//! The segment is a voxel mask on the CT's grid, grown by one voxel within the planes so that
//! the skull surface, which lies between bone and soft voxels, falls inside it.
//!
//! - **Le Fort I**: above the occlusal plane, below a horizontal plane 3 mm above the higher of
//!   the piriform rim's lowest point and the upper incisor apex, in front of the
//!   pterygomaxillary junctions, within 8 mm lateral of them.
//! - **BSSO** (the distal segment): below the occlusal plane and in front of a coronal plane at
//!   the ramus' anterior border (30 mm in front of gonion; without gonion, 20 mm behind the
//!   upper first molars), where the split leaves the body for the ramus. The proximal
//!   segments, with the condyles, stay.
//! - **Genioplasty**: below a plane 3 mm under the lower canines' apices (6 mm below the incisor's)
//!   on the midline and 4 mm under each mental foramen, in front of a coronal plane 12 mm behind the foramina.
//! - **Autorotation** (a Le Fort I impaction's option): the whole mandible, below the occlusal
//!   plane in front of the rami and 3 mm below the condylion behind.

use super::bone::Bone;
use crate::case::{Region, SurgeryKind};
use crate::landmarks::{HeadFrame, Landmark};
use crate::vec3::{add, cross, dot, norm, scale, sub};
use crate::volume::Volume;
use rayon::prelude::*;
use std::collections::VecDeque;
use std::sync::Arc;

/// Above the higher of the incisor apex and the piriform rim's lowest point (mm).
const LE_FORT_ABOVE_MM: f64 = 3.0;
/// Lateral reach of the Le Fort I segment beyond the pterygomaxillary junctions (mm).
const LE_FORT_LATERAL_MM: f64 = 8.0;
/// The sagittal split leaves the body at the ramus' anterior border: this far in front of
/// gonion (the adult minimum ramus breadth, about 30 mm), or without gonion this far behind the
/// upper first molars' cusps (mm).
const RAMUS_BREADTH_MM: f64 = 30.0;
const SPLIT_BEHIND_MOLAR_MM: f64 = 20.0;
/// The genioplasty cut under the lower canines' apices and under the mental foramina (mm). The
/// canine's root ends about 6 mm deeper than the central incisor's (whole tooth about 27 mm
/// against 21 mm), so its apex is taken that far below L1-apex.
const CHIN_BELOW_APEX_MM: f64 = 3.0;
const CANINE_APEX_BELOW_INCISOR_MM: f64 = 6.0;
const CHIN_BELOW_FORAMEN_MM: f64 = 4.0;
/// The genioplasty cut exits the lower border this far behind the foramina (mm).
const CHIN_BEHIND_FORAMEN_MM: f64 = 12.0;
/// Least height of bone a chin segment must keep under its cut (mm).
const CHIN_MIN_HEIGHT_MM: f64 = 5.0;
/// A Le Fort I cut must stay this far below the orbit's floor (orbitale; mm).
const ORBIT_CLEARANCE_MM: f64 = 10.0;
/// A seed landmark finds its component within this distance (mm).
const SEED_REACH_MM: f64 = 6.0;

/// A half-space: the points p with (p − point)·normal ≥ 0 (LPS mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub point: [f64; 3],
    pub normal: [f64; 3],
}

impl Plane {
    fn keeps(&self, p: [f64; 3]) -> bool {
        dot(sub(p, self.point), self.normal) >= 0.0
    }
}

/// The landmarks found, by label.
pub struct Found<'a> {
    pub landmarks: &'a [Landmark],
}

impl Found<'_> {
    pub fn at(&self, label: &str) -> Option<[f64; 3]> {
        self.landmarks
            .iter()
            .find(|l| l.label == label)
            .and_then(|l| l.position)
    }

    /// "LABEL (why it is missing)".
    pub fn why(&self, label: &str) -> String {
        let why = self
            .landmarks
            .iter()
            .find(|l| l.label == label)
            .and_then(|l| l.missing.clone())
            .unwrap_or_else(|| "not searched".into());
        format!("{label} ({why})")
    }

    /// All of `labels`, or an error naming each one missing.
    fn all<const N: usize>(&self, labels: [&str; N], what: &str) -> Result<[[f64; 3]; N], String> {
        let missing: Vec<String> = labels
            .iter()
            .filter(|l| self.at(l).is_none())
            .map(|l| self.why(l))
            .collect();
        if !missing.is_empty() {
            return Err(format!("{what} needs {}", missing.join(", ")));
        }
        Ok(labels.map(|l| self.at(l).unwrap_or_default()))
    }

    fn mean(&self, labels: &[&str]) -> Option<[f64; 3]> {
        let ps: Vec<[f64; 3]> = labels.iter().filter_map(|l| self.at(l)).collect();
        (!ps.is_empty()).then(|| {
            scale(
                ps.iter().fold([0.0; 3], |a, p| add(a, *p)),
                1.0 / ps.len() as f64,
            )
        })
    }
}

/// A cut: the planes bounding its segment and the landmarks inside the segment's bone.
#[derive(Clone, Debug)]
pub struct Cut {
    pub planes: Vec<Plane>,
    pub seeds: Vec<[f64; 3]>,
    /// What the user should know about how the cut was placed (a run's warning).
    pub note: Option<String>,
}

/// The plane between the upper and the lower teeth, as the half-space above it: through the
/// incisal point (midway between the incisal edges; the upper edge alone without a mandible),
/// parallel to the upper occlusal plane (the upper incisal edge and the upper first molars'
/// cusps), horizontal in `frame` when the molars are missing. Parallel rather than through the
/// molars: with the bite open (headsq's incisors stand 8 mm apart) a plane through the upper
/// molars' cusps would leave their crowns below it.
fn above_occlusal(f: &Found, frame: &HeadFrame) -> Option<Plane> {
    let incisal = match (f.at("U1"), f.at("L1")) {
        (Some(u), Some(l)) => scale(add(u, l), 0.5),
        (Some(u), None) => u,
        _ => return None,
    };
    let normal = match (f.at("U6-R"), f.at("U6-L"), f.at("U1")) {
        (Some(r), Some(l), Some(u1)) => {
            let n = cross(sub(l, r), sub(u1, r));
            let n = scale(n, 1.0 / norm(n).max(1e-12));
            if dot(n, frame.vertical) < 0.0 {
                scale(n, -1.0)
            } else {
                n
            }
        }
        _ => frame.vertical,
    };
    Some(Plane {
        point: incisal,
        normal,
    })
}

fn flip(p: Plane) -> Plane {
    Plane {
        point: p.point,
        normal: scale(p.normal, -1.0),
    }
}

/// The frame height of the higher of two points.
fn higher(frame: &HeadFrame, a: [f64; 3], b: [f64; 3]) -> f64 {
    frame.coords(a)[1].max(frame.coords(b)[1])
}

/// The Le Fort I cut.
pub(crate) fn le_fort_i(f: &Found, frame: &HeadFrame) -> Result<Cut, String> {
    let rim = f
        .mean(&["Pir-R", "Pir-L"])
        .or_else(|| f.at("ANS"))
        .ok_or_else(|| {
            format!(
                "a Le Fort I needs the piriform rim or ANS: {}, {}",
                f.why("Pir-R"),
                f.why("ANS")
            )
        })?;
    let back = f
        .mean(&["PTM-R", "PTM-L"])
        .or_else(|| f.at("PNS"))
        .ok_or_else(|| {
            format!(
                "a Le Fort I needs the pterygomaxillary junctions or PNS: {}, {}",
                f.why("PTM-R"),
                f.why("PNS")
            )
        })?;
    // Without the incisors (a field of view ending in their crowns) the cut is placed from the
    // rim alone, and says so (`Cut::note`).
    let (v_cut, note) = match f.at("U1-apex") {
        Some(apex) => (higher(frame, rim, apex) + LE_FORT_ABOVE_MM, None),
        None => (
            frame.coords(rim)[1] + LE_FORT_ABOVE_MM,
            Some(format!(
                "the Le Fort I cut is {LE_FORT_ABOVE_MM} mm above the piriform rim (or ANS), not checked against the incisor roots: {}",
                f.why("U1-apex")
            )),
        ),
    };
    let reference = f.at("U1").unwrap_or(rim);
    if let Some(or) = f.mean(&["Or-R", "Or-L"]) {
        let v_or = frame.coords(or)[1];
        if v_cut > v_or - ORBIT_CLEARANCE_MM {
            return Err(format!(
                "a Le Fort I cut {:.1} mm above the incisal edge (or ANS) would pass within {ORBIT_CLEARANCE_MM} mm of the orbit's floor (orbitale {:.1} mm above it)",
                v_cut - frame.coords(reference)[1],
                v_or - frame.coords(reference)[1]
            ));
        }
    }
    let c = frame.coords(reference);
    let mut planes = vec![
        // Below the cut.
        Plane {
            point: frame.point([c[0], v_cut, c[2]]),
            normal: scale(frame.vertical, -1.0),
        },
        // In front of the pterygomaxillary junctions.
        Plane {
            point: back,
            normal: frame.anterior,
        },
    ];
    let reach = ["PTM-R", "PTM-L"]
        .iter()
        .filter_map(|l| f.at(l))
        .map(|p| frame.coords(p)[0].abs())
        .fold(f64::NAN, f64::max);
    if reach.is_finite() {
        let half = reach + LE_FORT_LATERAL_MM;
        planes.push(Plane {
            point: frame.point([-half, 0.0, 0.0]),
            normal: frame.lateral,
        });
        planes.push(Plane {
            point: frame.point([half, 0.0, 0.0]),
            normal: scale(frame.lateral, -1.0),
        });
    }
    if f.at("L1").is_some()
        && let Some(occ) = above_occlusal(f, frame)
    {
        planes.push(occ);
    }
    let seeds = ["U1", "A", "ANS", "U6-R", "U6-L"]
        .iter()
        .filter_map(|l| f.at(l))
        .collect();
    Ok(Cut {
        planes,
        seeds,
        note,
    })
}

/// Why a mandibular surgery cannot be planned: the mandible's landmarks that are missing.
fn mandible_needed<const N: usize>(
    f: &Found,
    labels: [&str; N],
    kind: &str,
) -> Result<[[f64; 3]; N], String> {
    f.all(labels, &format!("a {kind} needs the mandible;"))
}

/// Where the sagittal split leaves the body for the ramus (frame anteriority): the ramus'
/// anterior border, `RAMUS_BREADTH_MM` in front of gonion; without gonion,
/// `SPLIT_BEHIND_MOLAR_MM` behind the upper first molars (behind the second molars).
fn split_at(f: &Found, frame: &HeadFrame) -> Result<f64, String> {
    if let Some(go) = f.mean(&["Go-R", "Go-L"]) {
        return Ok(frame.coords(go)[2] + RAMUS_BREADTH_MM);
    }
    match f.mean(&["U6-R", "U6-L"]) {
        Some(m) => Ok(frame.coords(m)[2] - SPLIT_BEHIND_MOLAR_MM),
        None => Err(format!(
            "a BSSO needs gonion or the upper first molars to place the split: {}, {}",
            f.why("Go-R"),
            f.why("U6-R")
        )),
    }
}

/// The BSSO's distal segment.
pub fn bsso(f: &Found, frame: &HeadFrame) -> Result<Cut, String> {
    let [l1, pog] = mandible_needed(f, ["L1", "Pog"], "BSSO")?;
    let occ = above_occlusal(f, frame)
        .ok_or("a BSSO needs the upper incisal edge U1 for the occlusal plane")?;
    let split = split_at(f, frame)?;
    let planes = vec![
        flip(occ),
        Plane {
            point: frame.point([0.0, 0.0, split]),
            normal: frame.anterior,
        },
    ];
    let seeds = [Some(l1), Some(pog), f.at("B"), f.at("Me"), f.at("Gn")]
        .into_iter()
        .flatten()
        .collect();
    Ok(Cut {
        planes,
        seeds,
        note: None,
    })
}

/// The genioplasty's chin.
pub fn genioplasty(f: &Found, frame: &HeadFrame) -> Result<Cut, String> {
    let [apex, pog, me] = mandible_needed(f, ["L1-apex", "Pog", "Me"], "genioplasty")?;
    let a = frame.coords(apex);
    let below = CANINE_APEX_BELOW_INCISOR_MM + CHIN_BELOW_APEX_MM;
    let mid = frame.point([a[0], a[1] - below, frame.coords(pog)[2]]);
    if frame.coords(mid)[1] - frame.coords(me)[1] < CHIN_MIN_HEIGHT_MM {
        return Err(format!(
            "a genioplasty cut {CHIN_BELOW_APEX_MM} mm below the lower canines' apices ({below} mm below the incisor's) would leave {:.1} mm of chin above menton (at least {CHIN_MIN_HEIGHT_MM}): it would pass through the roots",
            frame.coords(mid)[1] - frame.coords(me)[1]
        ));
    }
    let [r, l] = f.all(["MF-R", "MF-L"], "a genioplasty")?;
    let low = |p: [f64; 3]| sub(p, scale(frame.vertical, CHIN_BELOW_FORAMEN_MM));
    let (r, l) = (low(r), low(l));
    // The plane through the three points, its normal pointing down.
    let n = cross(sub(l, mid), sub(r, mid));
    let n = scale(n, 1.0 / norm(n).max(1e-12));
    let n = if dot(n, frame.vertical) > 0.0 {
        scale(n, -1.0)
    } else {
        n
    };
    let back = frame.coords(r)[2].min(frame.coords(l)[2]) - CHIN_BEHIND_FORAMEN_MM;
    let planes = vec![
        Plane {
            point: mid,
            normal: n,
        },
        Plane {
            point: frame.point([0.0, 0.0, back]),
            normal: frame.anterior,
        },
    ];
    let seeds = [Some(pog), Some(me), f.at("Gn")]
        .into_iter()
        .flatten()
        .collect();
    Ok(Cut {
        planes,
        seeds,
        note: None,
    })
}

/// The whole mandible, for the autorotation after a Le Fort I impaction.
pub fn mandible(f: &Found, frame: &HeadFrame) -> Result<(Cut, Cut), String> {
    let [l1, pog, co_r, co_l] = mandible_needed(f, ["L1", "Pog", "Co-R", "Co-L"], "autorotation")?;
    let occ = above_occlusal(f, frame).ok_or("autorotation needs the upper incisal edge U1")?;
    let ramus = split_at(f, frame).unwrap_or(0.5 * (frame.coords(l1)[2] + frame.coords(co_r)[2]));
    let top = frame.coords(co_r)[1].min(frame.coords(co_l)[1]) - 3.0;
    let front = Plane {
        point: frame.point([0.0, 0.0, ramus]),
        normal: frame.anterior,
    };
    let seeds: Vec<[f64; 3]> = [Some(l1), Some(pog), f.at("Me"), f.at("Go-R"), f.at("Go-L")]
        .into_iter()
        .flatten()
        .collect();
    let body = Cut {
        planes: vec![flip(occ), front],
        seeds: seeds.clone(),
        note: None,
    };
    let rami = Cut {
        planes: vec![
            flip(front),
            Plane {
                point: frame.point([0.0, top, 0.0]),
                normal: scale(frame.vertical, -1.0),
            },
        ],
        seeds,
        note: None,
    };
    Ok((body, rami))
}

/// The cut of a surgery kind.
pub fn cut(kind: SurgeryKind, f: &Found, frame: &HeadFrame) -> Result<Cut, String> {
    match kind {
        SurgeryKind::LeFortI => le_fort_i(f, frame),
        SurgeryKind::Bsso => bsso(f, frame),
        SurgeryKind::Genioplasty => genioplasty(f, frame),
    }
}

/// A segment: its voxel mask (the CT's grid, cropped) and its bone volume.
pub struct Segment {
    pub mask: Arc<Volume>,
    pub bone_voxels: usize,
    pub bone_ml: f64,
}

impl Segment {
    /// This segment without the voxels of `other` (a chin cut from a moved mandible).
    pub fn minus(&self, other: &Segment) -> Segment {
        let m = &self.mask;
        let o = &other.mask;
        let mut data = m.data.clone();
        for k in 0..m.dims[2] {
            for j in 0..m.dims[1] {
                for i in 0..m.dims[0] {
                    let idx = m.idx(i, j, k);
                    if data[idx] == 0.0 {
                        continue;
                    }
                    let c = o
                        .to_voxel(m.to_world([i as f64, j as f64, k as f64]))
                        .map(f64::round);
                    if (0..3).all(|a| c[a] >= 0.0 && c[a] < o.dims[a] as f64)
                        && o.data[o.idx(c[0] as usize, c[1] as usize, c[2] as usize)] != 0.0
                    {
                        data[idx] = 0.0;
                    }
                }
            }
        }
        let voxels = self.bone_voxels.saturating_sub(other.bone_voxels);
        Segment {
            mask: Arc::new(Volume {
                data,
                ..(**m).clone()
            }),
            bone_voxels: voxels,
            bone_ml: self.bone_ml * voxels as f64 / self.bone_voxels.max(1) as f64,
        }
    }

    /// The segment as an osteotomy region; `path` is where the run writes the mask.
    pub fn region(&self, path: &str) -> Region {
        Region::Mask(crate::case::Mask {
            path: path.into(),
            voxels: Some(self.mask.clone()),
            found: true,
        })
    }
}

/// The bone inside all of `cuts`' planes (a union of cuts) that is connected to their seeds.
/// Connected: 26-neighbours, bridging one-voxel gaps (a tooth's periodontal space).
pub fn segment(bone: &Bone, cuts: &[&Cut], what: &str) -> Result<Segment, String> {
    let vol = bone.vol;
    let [nx, ny, nz] = vol.dims;
    let inside = |p: [f64; 3]| cuts.iter().any(|c| c.planes.iter().all(|pl| pl.keeps(p)));
    let world = |i: usize, j: usize, k: usize| vol.to_world([i as f64, j as f64, k as f64]);
    // Bone inside, per slice.
    let hits: Vec<Vec<[usize; 3]>> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let mut v = Vec::new();
            for j in 0..ny {
                for i in 0..nx {
                    if bone.labels[vol.idx(i, j, k)] == crate::labels::BONE
                        && inside(world(i, j, k))
                    {
                        v.push([i, j, k]);
                    }
                }
            }
            v
        })
        .collect();
    let hits: Vec<[usize; 3]> = hits.into_iter().flatten().collect();
    if hits.is_empty() {
        return Err(format!("{what}: no bone lies inside its cut"));
    }
    // The crop: the hits' box and a margin for the growth.
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    for h in &hits {
        for a in 0..3 {
            lo[a] = lo[a].min(h[a]);
            hi[a] = hi[a].max(h[a]);
        }
    }
    for a in 0..3 {
        lo[a] = lo[a].saturating_sub(2);
        hi[a] = (hi[a] + 2).min(vol.dims[a] - 1);
    }
    let d = [hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1];
    let at = |c: [usize; 3]| (c[0] - lo[0]) + d[0] * ((c[1] - lo[1]) + d[1] * (c[2] - lo[2]));
    // 0 outside, 1 bone inside, 2 kept.
    let mut state = vec![0u8; d[0] * d[1] * d[2]];
    for h in &hits {
        state[at(*h)] = 1;
    }
    let mut kept = 0usize;
    for seed in cuts.iter().flat_map(|c| c.seeds.iter()) {
        let Some(start) = nearest(&hits, vol, *seed, SEED_REACH_MM) else {
            continue;
        };
        if state[at(start)] == 2 {
            continue;
        }
        state[at(start)] = 2;
        kept += 1;
        let mut queue = VecDeque::from([start]);
        while let Some(c) = queue.pop_front() {
            for dk in -2i64..=2 {
                for dj in -2i64..=2 {
                    for di in -2i64..=2 {
                        let n = [c[0] as i64 + di, c[1] as i64 + dj, c[2] as i64 + dk];
                        if (0..3).any(|a| n[a] < lo[a] as i64 || n[a] > hi[a] as i64) {
                            continue;
                        }
                        let n = [n[0] as usize, n[1] as usize, n[2] as usize];
                        let s = &mut state[at(n)];
                        if *s == 1 {
                            *s = 2;
                            kept += 1;
                            queue.push_back(n);
                        }
                    }
                }
            }
        }
    }
    if kept == 0 {
        return Err(format!(
            "{what}: no bone inside its cut lies within {SEED_REACH_MM} mm of its landmarks"
        ));
    }
    // The mask: kept bone grown by one voxel within the planes.
    let mut data = vec![0f32; state.len()];
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            for i in lo[0]..=hi[0] {
                if state[at([i, j, k])] != 2 {
                    continue;
                }
                for dk in -1i64..=1 {
                    for dj in -1i64..=1 {
                        for di in -1i64..=1 {
                            let n = [i as i64 + di, j as i64 + dj, k as i64 + dk];
                            if (0..3).any(|a| n[a] < lo[a] as i64 || n[a] > hi[a] as i64) {
                                continue;
                            }
                            let n = [n[0] as usize, n[1] as usize, n[2] as usize];
                            if data[at(n)] == 0.0
                                && (state[at(n)] == 2 || inside(world(n[0], n[1], n[2])))
                            {
                                data[at(n)] = 1.0;
                            }
                        }
                    }
                }
            }
        }
    }
    let mask = Volume {
        dims: d,
        spacing: vol.spacing,
        origin: world(lo[0], lo[1], lo[2]),
        direction: vol.direction,
        data,
    };
    Ok(Segment {
        mask: Arc::new(mask),
        bone_voxels: kept,
        bone_ml: kept as f64 * vol.voxel_volume() / 1000.0,
    })
}

/// The voxel of `hits` nearest to p within `reach` mm.
fn nearest(hits: &[[usize; 3]], vol: &Volume, p: [f64; 3], reach: f64) -> Option<[usize; 3]> {
    hits.par_iter()
        .map(|h| {
            (
                norm(sub(
                    vol.to_world([h[0] as f64, h[1] as f64, h[2] as f64]),
                    p,
                )),
                *h,
            )
        })
        .filter(|(d, _)| *d <= reach)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, h)| h)
}

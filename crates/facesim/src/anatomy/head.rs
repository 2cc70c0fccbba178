//! The clinical head frame (docs/planning.md "The head frame").

use super::Bone;
use crate::case::{FrameChoice, Head};
use crate::labels;
use crate::landmarks::{HeadFrame, Kind, Landmark, Source};
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
    /// The Frankfort plane's roll from the midsagittal frame's horizontal (degrees, the left
    /// side up +), where it was found; the frame keeps the midsagittal plane, so this is
    /// reported only.
    pub plane_roll_deg: Option<f64>,
    /// Porion and orbitale, both sides, each detected or missing with the reason.
    pub landmarks: Vec<Landmark>,
}

/// The clinical frame of a head: `midsagittal` is the skin's symmetry frame
/// (`crate::landmarks::head_frame`), `soft` its soft-tissue landmarks (N', Pog' for the
/// fallback). Err: the one-line reason when `[head] frame` asks for a method the CT cannot
/// give.
///
/// Frankfort is taken where at least one porion and one orbitale are found and three of the
/// four points are: the frame keeps the midsagittal normal as its lateral axis, so only the
/// plane's pitch matters, and a porion–orbitale pair 70–80 mm apart fixes it; the third point
/// completes the plane (its roll) and two points alone would leave a single wrong point
/// unchecked. The points are searched in the best frame at hand (the facial plane's, else the
/// CT's), then again in the Frankfort frame they give, until its pitch settles (the top of the
/// ear canal and of the orbital rim are "highest" in that frame).
pub fn clinical_frame(
    bone: &Bone,
    midsagittal: &HeadFrame,
    soft: &[Landmark],
    head: &Head,
) -> Result<ClinicalFrame, String> {
    let facial = facial_plane_pitch(midsagittal, soft);
    let mut search_pitch = facial.as_ref().map_or(0.0, |p| p.clamp(-35.0, 35.0));
    let mut found = detect(bone, &super::turned(midsagittal, search_pitch));
    if head.frame != Some(FrameChoice::FacialPlane) {
        for _ in 0..3 {
            match fit_frankfort(midsagittal, &found) {
                Ok(fit) if (fit.pitch_deg - search_pitch).abs() > 0.5 => {
                    search_pitch = fit.pitch_deg;
                    found = detect(bone, &super::turned(midsagittal, search_pitch));
                }
                _ => break,
            }
        }
    }
    let frankfort = fit_frankfort(midsagittal, &found);
    let landmarks: Vec<Landmark> = found
        .iter()
        .map(|(label, r)| match r {
            Ok(p) => Landmark {
                label: (*label).into(),
                kind: Kind::Bone,
                position: Some(*p),
                source: Source::Detected,
                missing: None,
            },
            Err(why) => Landmark::missing(label, Kind::Bone, why.clone()),
        })
        .collect();
    let (method, pitch_deg, why, plane_roll_deg) = match (head.frame, &frankfort, &facial) {
        (Some(FrameChoice::FacialPlane), _, Err(why)) => {
            return Err(format!("[head] frame = \"facial-plane\": {why}"));
        }
        (Some(FrameChoice::Frankfort), Err(why), _) => {
            return Err(format!("[head] frame = \"frankfort\": {why}"));
        }
        (Some(FrameChoice::FacialPlane), _, Ok(p)) => (
            Method::FacialPlane,
            *p,
            format!(
                "facial plane ([head] frame): soft nasion to soft pogonion set vertical, {p:.1}° from the CT's vertical"
            ),
            None,
        ),
        (_, Ok(fit), _) => (
            Method::Frankfort,
            fit.pitch_deg,
            format!("Frankfort: {}", fit.summary),
            Some(fit.roll_deg),
        ),
        (_, Err(no_fh), Ok(p)) => (
            Method::FacialPlane,
            *p,
            format!(
                "facial plane: soft nasion to soft pogonion set vertical, {p:.1}° from the CT's vertical, as no Frankfort plane: {no_fh}"
            ),
            None,
        ),
        (_, Err(no_fh), Err(no_fp)) => (
            Method::CtAxes,
            0.0,
            format!("CT axes: no Frankfort plane ({no_fh}) and no facial plane ({no_fp})"),
            None,
        ),
    };
    Ok(ClinicalFrame {
        frame: super::turned(midsagittal, pitch_deg + head.pitch_deg),
        method,
        why,
        pitch_deg,
        correction_deg: head.pitch_deg,
        plane_roll_deg,
        landmarks,
    })
}

/// The pitch (degrees, face down +) that makes the soft-tissue facial plane N'–Pog' vertical.
///
/// In natural head position the soft-tissue facial plane stands close to vertical: Holdaway's
/// soft-tissue facial angle, between Frankfort horizontal and the line from soft nasion to soft
/// pogonion, averages about 90° (Holdaway, Am J Orthod 1983;84:1–28).
fn facial_plane_pitch(mid: &HeadFrame, soft: &[Landmark]) -> Result<f64, String> {
    let at = |label: &str| {
        let l = soft.iter().find(|l| l.label == label);
        match l.and_then(|l| l.position) {
            Some(p) => Ok(mid.coords(p)),
            None => Err(format!(
                "{label} is missing ({})",
                l.and_then(|l| l.missing.clone())
                    .unwrap_or_else(|| "not among the soft-tissue landmarks".into())
            )),
        }
    };
    let n = at("N'")?;
    let pog = at("Pog'")?;
    let (dv, da) = (n[1] - pog[1], n[2] - pog[2]);
    if dv < 40.0 {
        return Err(format!(
            "N' lies {dv:.0} mm above Pog', too little for a facial plane"
        ));
    }
    Ok(da.atan2(dv).to_degrees())
}

/// HU below which a sample is air (the ear canal's lumen).
const AIR_HU: f32 = -300.0;
/// HU from which a sample is bone (also where the segmentation says bone).
const BONE_HU: f32 = 300.0;
/// Sample spacing of the search grids (mm).
const STEP: f64 = 1.0;

/// The CT sampled on a box of a frame's (s, v, a) coordinates, `STEP` apart; NaN outside the CT.
struct Grid {
    lo: [f64; 3],
    n: [usize; 3],
    hu: Vec<f32>,
    bone: Vec<bool>,
}

impl Grid {
    fn new(bone: &Bone, f: &HeadFrame, lo: [f64; 3], hi: [f64; 3]) -> Grid {
        use rayon::prelude::*;
        let n = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / STEP).floor().max(0.0) as usize + 1);
        let vol = bone.vol;
        let map = vol.voxel_map();
        let c0 = map.to_voxel(f.point(lo));
        let axis = |a: usize| {
            let mut q = lo;
            q[a] += STEP;
            let c = map.to_voxel(f.point(q));
            [c[0] - c0[0], c[1] - c0[1], c[2] - c0[2]]
        };
        let d = [axis(0), axis(1), axis(2)];
        let mut hu = vec![f32::NAN; n[0] * n[1] * n[2]];
        let mut is_bone = vec![false; hu.len()];
        hu.par_chunks_mut(n[0] * n[1])
            .zip(is_bone.par_chunks_mut(n[0] * n[1]))
            .enumerate()
            .for_each(|(ia, (h, b))| {
                for iv in 0..n[1] {
                    for is in 0..n[0] {
                        let c = [0, 1, 2].map(|r| {
                            c0[r] + is as f64 * d[0][r] + iv as f64 * d[1][r] + ia as f64 * d[2][r]
                        });
                        let x = crate::volume::sample_field(&vol.data, vol.dims, c, f32::NAN);
                        let k = is + n[0] * iv;
                        h[k] = x;
                        if x.is_nan() {
                            continue;
                        }
                        let r = c.map(|x| x.round().max(0.0) as usize);
                        let labelled = r.iter().zip(vol.dims).all(|(r, d)| *r < d)
                            && bone.labels.get(vol.idx(r[0], r[1], r[2])) == Some(&labels::BONE);
                        b[k] = x >= BONE_HU || labelled;
                    }
                }
            });
        Grid {
            lo,
            n,
            hu,
            bone: is_bone,
        }
    }

    fn idx(&self, i: [usize; 3]) -> usize {
        i[0] + self.n[0] * (i[1] + self.n[1] * i[2])
    }

    fn ijk(&self, k: usize) -> [usize; 3] {
        [k % self.n[0], (k / self.n[0]) % self.n[1], k / (self.n[0] * self.n[1])]
    }

    fn coords(&self, i: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|a| self.lo[a] + i[a] * STEP)
    }

    /// The share of samples inside the CT.
    fn coverage(&self) -> f64 {
        let inside = self.hu.iter().filter(|h| !h.is_nan()).count();
        inside as f64 / self.hu.len().max(1) as f64
    }
}

/// "right" / "left" for a side (-1 / +1 along `lateral`).
fn side_name(side: f64) -> &'static str {
    if side < 0.0 { "right" } else { "left" }
}

/// Po-R, Po-L, Or-R, Or-L searched in the frame `f`: LPS positions or why each is missing.
fn detect(bone: &Bone, f: &HeadFrame) -> Vec<(&'static str, Result<[f64; 3], String>)> {
    let mut out = Vec::with_capacity(4);
    for (label, side) in [("Po-R", -1.0), ("Po-L", 1.0)] {
        out.push((label, porion(bone, f, side).map(|c| f.point(c))));
    }
    for (label, side) in [("Or-R", -1.0), ("Or-L", 1.0)] {
        out.push((label, orbitale(bone, f, side).map(|c| f.point(c))));
    }
    out
}

/// Where porion is searched (frame mm, the side's half; the origin at the nose tip's level):
/// 20–100 mm from the midsagittal plane, 30–150 mm behind the nose tip, 70 mm either side of
/// its height — the canal lies 80–110 mm behind the tip and within ±50 mm of its height at a
/// pitch of up to 30°.
const PORION_BOX: [[f64; 2]; 3] = [[20.0, 100.0], [-70.0, 70.0], [-150.0, -30.0]];
/// The lumen of the bony canal: bone within this distance (mm) above, below, in front of and
/// behind an air sample (the canal is 5–10 mm wide).
const CANAL_WALL_MM: f64 = 12.0;
/// Porion is the top of the canal within this path length (mm) of its bony opening: the
/// tympanic membrane lies 15–20 mm deeper, and the middle ear and mastoid cells beyond it.
const CANAL_LATERAL_MM: f64 = 10.0;

/// Porion of one side (`side` -1 right, +1 left) in frame coordinates: the air connected to the
/// outside that enters bone there (the external acoustic meatus: air with bone above, below,
/// in front and behind in the sagittal plane), and the top of its lumen (HU crossing
/// `AIR_HU`) within `CANAL_LATERAL_MM` of where the bony canal begins.
fn porion(bone: &Bone, f: &HeadFrame, side: f64) -> Result<[f64; 3], String> {
    let [sb, vb, ab] = PORION_BOX;
    let (lo_s, hi_s) = if side < 0.0 {
        (-sb[1], -sb[0])
    } else {
        (sb[0], sb[1])
    };
    let g = Grid::new(bone, f, [lo_s, vb[0], ab[0]], [hi_s, vb[1], ab[1]]);
    let name = side_name(side);
    if g.coverage() < 0.3 {
        return Err(format!(
            "the CT's field of view holds {:.0} % of the region where the {name} ear canal lies",
            100.0 * g.coverage()
        ));
    }
    let [ns, nv, na] = g.n;
    // Lateral-most first: i = 0 is the side's outer face.
    let s_of = |i: usize| if side < 0.0 { i } else { ns - 1 - i };
    let air = |k: usize| g.hu[k] < AIR_HU;
    let mut dist = vec![u32::MAX; g.hu.len()];
    let mut queue = std::collections::VecDeque::new();
    for ia in 0..na {
        for iv in 0..nv {
            // The outermost sample inside the CT along this line: outside the head if air.
            if let Some(k) = (0..ns)
                .map(|i| g.idx([s_of(i), iv, ia]))
                .find(|k| !g.hu[*k].is_nan())
                && air(k)
            {
                dist[k] = 0;
                queue.push_back(g.ijk(k));
            }
        }
    }
    while let Some(i) = queue.pop_front() {
        let d = dist[g.idx(i)];
        for (a, delta) in [(0, -1), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)] {
            let mut j = i;
            let x = j[a] as i64 + delta;
            if x < 0 || x >= g.n[a] as i64 {
                continue;
            }
            j[a] = x as usize;
            let k = g.idx(j);
            if dist[k] == u32::MAX && air(k) {
                dist[k] = d + 1;
                queue.push_back(j);
            }
        }
    }
    let reach = (CANAL_WALL_MM / STEP).round() as i64;
    let walled = |i: [usize; 3]| {
        [(1, 1), (1, -1), (2, 1), (2, -1)].iter().all(|&(a, delta)| {
            (1..=reach).any(|t| {
                let x = i[a] as i64 + delta * t;
                if x < 0 || x >= g.n[a] as i64 {
                    return false;
                }
                let mut j = i;
                j[a] = x as usize;
                g.bone[g.idx(j)]
            })
        })
    };
    let canal: Vec<([usize; 3], u32)> = (0..g.hu.len())
        .filter(|k| dist[*k] != u32::MAX)
        .map(|k| (g.ijk(k), dist[k]))
        .filter(|(i, _)| walled(*i))
        .collect();
    let Some(d0) = canal.iter().map(|c| c.1).min() else {
        return Err(format!(
            "no air canal runs from the skin into the {name} temporal bone (no external acoustic meatus in the CT)"
        ));
    };
    let keep = d0 + (CANAL_LATERAL_MM / STEP).round() as u32;
    let near: Vec<[usize; 3]> = canal
        .iter()
        .filter(|c| c.1 <= keep)
        .map(|c| c.0)
        .collect();
    if near.len() < 20 {
        return Err(format!(
            "the {name} ear canal's bony part is too small to be the external acoustic meatus ({} mm³)",
            near.len()
        ));
    }
    let top = near.iter().map(|i| i[1]).max().unwrap_or(0);
    let tops: Vec<[usize; 3]> = near.iter().filter(|i| i[1] == top).copied().collect();
    let m = tops.len() as f64;
    let s = tops.iter().map(|i| i[0] as f64).sum::<f64>() / m;
    let a = tops.iter().map(|i| i[2] as f64).sum::<f64>() / m;
    // The lumen's edge: where HU crosses AIR_HU between the top air sample and the one above.
    let frac = tops
        .iter()
        .filter(|i| i[1] + 1 < nv)
        .map(|i| {
            let h0 = g.hu[g.idx(*i)];
            let h1 = g.hu[g.idx([i[0], i[1] + 1, i[2]])];
            if h1.is_nan() || h1 <= h0 {
                0.5
            } else {
                f64::from((AIR_HU - h0) / (h1 - h0)).clamp(0.0, 1.0)
            }
        })
        .sum::<f64>()
        / m;
    Ok(g.coords([s, top as f64 + frac, a]))
}

/// Where orbitale is searched (frame mm, the side's half): 8–60 mm from the midsagittal
/// plane, from 40 mm below to 70 mm above the nose tip's height, from 15 mm in front of it to
/// 90 mm behind.
const ORBIT_BOX: [[f64; 2]; 3] = [[8.0, 60.0], [-40.0, 70.0], [-90.0, 15.0]];
/// A ray from the front through the orbit crosses at least this much soft tissue (mm) before
/// bone (the globe is 24 mm deep); over the rims and the cheek it crosses 3–15 mm.
const ORBIT_DEPTH_MM: f64 = 22.0;

/// Orbitale of one side in frame coordinates. Rays run backwards (along −anterior) from in front
/// of the face; the orbit's opening is the region of rays that cross `ORBIT_DEPTH_MM` of soft
/// tissue before bone (the largest such region beside the orbit's usual place, 22–45 mm from
/// the midsagittal plane). Under each column of the opening the first ray that stops short lies
/// on the inferior rim; orbitale is the lowest of these rim tops, at the HU crossing
/// `BONE_HU` above the rim's bone.
fn orbitale(bone: &Bone, f: &HeadFrame, side: f64) -> Result<[f64; 3], String> {
    let [sb, vb, ab] = ORBIT_BOX;
    let (lo_s, hi_s) = if side < 0.0 {
        (-sb[1], -sb[0])
    } else {
        (sb[0], sb[1])
    };
    let g = Grid::new(bone, f, [lo_s, vb[0], ab[0]], [hi_s, vb[1], ab[1]]);
    let name = side_name(side);
    if g.coverage() < 0.3 {
        return Err(format!(
            "the CT's field of view holds {:.0} % of the region where the {name} orbit lies",
            100.0 * g.coverage()
        ));
    }
    let [ns, nv, na] = g.n;
    // Per (s, v): Some(bone hit index along a) or None (unknown); deep when the soft path is long.
    let mut hit = vec![None::<usize>; ns * nv];
    let mut deep = vec![false; ns * nv];
    let depth = (ORBIT_DEPTH_MM / STEP).round() as usize;
    for iv in 0..nv {
        for is in 0..ns {
            let mut entry = None;
            for ia in (0..na).rev() {
                let k = g.idx([is, iv, ia]);
                let h = g.hu[k];
                if h.is_nan() {
                    break;
                }
                if entry.is_none() && h >= AIR_HU {
                    entry = Some(ia);
                }
                if g.bone[k] {
                    hit[is + ns * iv] = Some(ia);
                    break;
                }
            }
            let stop = hit[is + ns * iv].unwrap_or(0);
            deep[is + ns * iv] = entry.is_some_and(|e| e >= stop + depth)
                && (hit[is + ns * iv].is_some() || g.hu[g.idx([is, iv, 0])].is_finite());
        }
    }
    // The opening: 4-connected regions of deep rays; the one with most rays 22–45 mm out.
    let mut comp = vec![usize::MAX; ns * nv];
    let mut best: Option<(usize, usize, usize)> = None; // (id, score, size)
    let mut id = 0;
    for start in 0..ns * nv {
        if !deep[start] || comp[start] != usize::MAX {
            continue;
        }
        let mut stack = vec![start];
        comp[start] = id;
        let (mut size, mut score) = (0, 0);
        while let Some(k) = stack.pop() {
            size += 1;
            let (is, iv) = (k % ns, k / ns);
            let s = (g.lo[0] + is as f64 * STEP).abs();
            if (22.0..=45.0).contains(&s) {
                score += 1;
            }
            let mut nb = Vec::with_capacity(4);
            if is > 0 {
                nb.push(k - 1);
            }
            if is + 1 < ns {
                nb.push(k + 1);
            }
            if iv > 0 {
                nb.push(k - ns);
            }
            if iv + 1 < nv {
                nb.push(k + ns);
            }
            for j in nb {
                if deep[j] && comp[j] == usize::MAX {
                    comp[j] = id;
                    stack.push(j);
                }
            }
        }
        if best.is_none_or(|b| score > b.1) {
            best = Some((id, score, size));
        }
        id += 1;
    }
    let min_area = (300.0 / (STEP * STEP)) as usize;
    let Some((orbit, _, _)) = best.filter(|b| b.1 > 0 && b.2 >= min_area) else {
        return Err(format!(
            "no {name} orbit found: no region where {ORBIT_DEPTH_MM:.0} mm of soft tissue lies in front of bone, 22–45 mm from the midline"
        ));
    };
    // Rim top per column: the lowest ray of the opening whose ray below stops at bone.
    let min_height = (10.0 / STEP) as usize;
    let mut rim: Vec<(usize, usize)> = Vec::new(); // (is, iv of the rim ray)
    for is in 0..ns {
        let rows: Vec<usize> = (0..nv).filter(|iv| comp[is + ns * iv] == orbit).collect();
        let (Some(&low), Some(&high)) = (rows.first(), rows.last()) else {
            continue;
        };
        if high - low < min_height || low == 0 {
            continue;
        }
        if hit[is + ns * (low - 1)].is_some() {
            rim.push((is, low - 1));
        }
    }
    if rim.len() < 3 {
        return Err(format!(
            "the {name} orbit's opening has no inferior rim in the CT (the bone under it is missing)"
        ));
    }
    // The lowest rim top, its height a median of 3 columns against single-ray noise.
    let heights: Vec<usize> = (0..rim.len())
        .map(|k| {
            let mut w: Vec<usize> = rim[k.saturating_sub(1)..(k + 2).min(rim.len())]
                .iter()
                .map(|r| r.1)
                .collect();
            w.sort_unstable();
            w[w.len() / 2]
        })
        .collect();
    let lowest = heights.iter().copied().min().unwrap_or(0);
    let cols: Vec<usize> = (0..rim.len()).filter(|k| heights[*k] == lowest).collect();
    let (is, iv) = rim[cols[cols.len() / 2]];
    let front = hit[is + ns * iv].unwrap_or(0);
    // The crest lies on the rim's bone a little behind its front: the middle of the bone run of
    // the rim ray, at most 8 mm deep.
    let run_end = (0..=front)
        .rev()
        .take((8.0 / STEP) as usize)
        .take_while(|ia| g.bone[g.idx([is, iv, *ia])])
        .last()
        .unwrap_or(front);
    let ia = (front + run_end) / 2;
    let h0 = g.hu[g.idx([is, iv, ia])];
    let h1 = g.hu[g.idx([is, iv + 1, ia])];
    let frac = if h1.is_finite() && h0 > h1 {
        f64::from((h0 - BONE_HU) / (h0 - h1)).clamp(0.0, 1.0)
    } else {
        0.5
    };
    Ok(g.coords([is as f64, iv as f64 + frac, ia as f64]))
}

/// The Frankfort plane fitted to the found points, in the midsagittal frame.
struct Fit {
    pitch_deg: f64,
    roll_deg: f64,
    summary: String,
}

/// The plane v = c0 + c1 s + c2 a (midsagittal frame) through the found porions and orbitales,
/// or why there is none. Its pitch is atan(−c2) (face down +: orbitale below porion), its roll
/// atan(c1) (the left side up +).
fn fit_frankfort(
    mid: &HeadFrame,
    found: &[(&'static str, Result<[f64; 3], String>)],
) -> Result<Fit, String> {
    let pts: Vec<(&str, [f64; 3])> = found
        .iter()
        .filter_map(|(l, r)| r.as_ref().ok().map(|p| (*l, mid.coords(*p))))
        .collect();
    let missing: Vec<String> = found
        .iter()
        .filter_map(|(l, r)| r.as_ref().err().map(|w| format!("{l}: {w}")))
        .collect();
    let porions = pts.iter().filter(|p| p.0.starts_with("Po")).count();
    let orbitales = pts.len() - porions;
    if pts.len() < 3 || porions == 0 || orbitales == 0 {
        return Err(format!(
            "it needs three of porion and orbitale, one of each at least ({})",
            missing.join("; ")
        ));
    }
    // Least squares of v on (1, s, a): the normal equations, solved by Cramer's rule.
    let mut m = [[0.0; 3]; 3];
    let mut r = [0.0; 3];
    for (_, c) in &pts {
        let x = [1.0, c[0], c[2]];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += x[i] * x[j];
            }
            r[i] += x[i] * c[1];
        }
    }
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    if d.abs() < 1e-6 {
        return Err("porion and orbitale are found but lie on one line".into());
    }
    let c = [0, 1, 2].map(|col| {
        let mut mc = m;
        for (row, rr) in mc.iter_mut().zip(r) {
            row[col] = rr;
        }
        det(&mc) / d
    });
    let rms = (pts
        .iter()
        .map(|(_, p)| (p[1] - c[0] - c[1] * p[0] - c[2] * p[2]).powi(2))
        .sum::<f64>()
        / pts.len() as f64)
        .sqrt();
    let summary = if pts.len() == 4 {
        format!("porion and orbitale found both sides; the plane fits them within {rms:.1} mm")
    } else {
        format!(
            "three of porion and orbitale found, which fix the plane ({})",
            missing.join("; ")
        )
    };
    Ok(Fit {
        pitch_deg: (-c[2]).atan().to_degrees(),
        roll_deg: c[1].atan().to_degrees(),
        summary,
    })
}

#[cfg(test)]
mod dump {
    use crate::landmarks::HeadFrame;
    use std::io::Write;
    use std::path::Path;

    fn dump(dir: &str, tag: &str) {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let case_path = root.join(dir).join("case.toml");
        let (case, _) = crate::case::Case::load(&case_path).unwrap();
        let t = std::time::Instant::now();
        let scene = crate::pipeline::prepare_case(&case, &crate::observe::Quiet).unwrap();
        eprintln!("prepare {:?}", t.elapsed());
        let vol = &scene.vol;
        let frame: HeadFrame = crate::landmarks::head_frame(&scene.face.skin).unwrap();
        let lms = crate::landmarks::detect::detect(&scene.face.skin, Some(&scene.face.skull), &frame);
        let out = root.join("target/tmp/headdump");
        std::fs::create_dir_all(&out).unwrap();
        let mut f = std::fs::File::create(out.join(format!("{tag}.txt"))).unwrap();
        writeln!(f, "dims {:?}", vol.dims).unwrap();
        writeln!(f, "spacing {:?}", vol.spacing).unwrap();
        writeln!(f, "origin {:?}", vol.origin).unwrap();
        writeln!(f, "direction {:?}", vol.direction).unwrap();
        writeln!(f, "frame {:?}", frame).unwrap();
        for l in &lms {
            writeln!(f, "lm {} {:?} {:?}", l.label, l.position, l.missing).unwrap();
        }
        let bytes: Vec<u8> = vol.data.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(out.join(format!("{tag}.f32")), bytes).unwrap();
        std::fs::write(out.join(format!("{tag}.labels")), &scene.seg.labels).unwrap();
    }

    #[test]
    #[ignore]
    fn show_real() {
        for dir in ["data-samples/real", "data-samples/real-mandible"] {
            let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
            let (case, _) = crate::case::Case::load(&root.join(dir).join("case.toml")).unwrap();
            let scene = crate::pipeline::prepare_case(&case, &crate::observe::Quiet).unwrap();
            let frame = crate::landmarks::head_frame(&scene.face.skin).unwrap();
            let lms = crate::landmarks::detect::detect(&scene.face.skin, Some(&scene.face.skull), &frame);
            let bone = super::Bone { vol: &scene.vol, labels: &scene.seg.labels };
            let t = std::time::Instant::now();
            let cf = super::clinical_frame(&bone, &frame, &lms, &Default::default()).unwrap();
            eprintln!("{dir}: {:?} {:?} pitch {:.2} roll {:?} why {}", t.elapsed(), cf.method, cf.pitch_deg, cf.plane_roll_deg, cf.why);
            for l in &cf.landmarks {
                eprintln!("  {} {:?} {:?}", l.label, l.position.map(|p| p.map(|x| (x * 10.0).round() / 10.0)), l.missing);
            }
        }
    }

    #[test]
    #[ignore]
    fn dump_real() {
        dump("data-samples/real", "real");
        dump("data-samples/real-mandible", "mandible");
    }
}

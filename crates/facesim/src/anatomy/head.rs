//! The clinical head frame (docs/guide/planning.md "The head frame").

use super::bone::{Bone, turned};
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
    let mut found = detect(bone, &turned(midsagittal, search_pitch), None);
    if head.frame != Some(FrameChoice::FacialPlane) {
        let mut porion_pitch = search_pitch;
        for _ in 0..3 {
            match fit_frankfort(midsagittal, &found) {
                Ok(fit) if (fit.pitch_deg - search_pitch).abs() > 0.5 => {
                    search_pitch = fit.pitch_deg;
                    // The canal's top moves by its radius times the turn (< 0.5 mm for 8°):
                    // porion is searched again only after a larger turn.
                    let po: Found = found[..2].to_vec();
                    let keep = (search_pitch - porion_pitch).abs() < PORION_RESEARCH_DEG;
                    if !keep {
                        porion_pitch = search_pitch;
                    }
                    let f = turned(midsagittal, search_pitch);
                    found = detect(bone, &f, keep.then_some(&po));
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
        frame: turned(midsagittal, pitch_deg + head.pitch_deg),
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

/// A turn of the search frame (degrees) after which porion is searched again.
const PORION_RESEARCH_DEG: f64 = 8.0;
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
        [
            k % self.n[0],
            (k / self.n[0]) % self.n[1],
            k / (self.n[0] * self.n[1]),
        ]
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

type Found = Vec<(&'static str, Result<[f64; 3], String>)>;

/// Po-R, Po-L (searched in `f` unless `porions` are given) and Or-R, Or-L searched in `f`:
/// LPS positions or why each is missing. The sides run in parallel.
fn detect(bone: &Bone, f: &HeadFrame, porions: Option<&Found>) -> Found {
    let side = |label: &'static str,
                s: f64,
                find: fn(&Bone, &HeadFrame, f64) -> Result<[f64; 3], String>| {
        (label, find(bone, f, s).map(|c| f.point(c)))
    };
    let (po, or) = rayon::join(
        || match porions {
            Some(p) => p.clone(),
            None => {
                let (r, l) =
                    rayon::join(|| side("Po-R", -1.0, porion), || side("Po-L", 1.0, porion));
                vec![r, l]
            }
        },
        || {
            let (r, l) = rayon::join(
                || side("Or-R", -1.0, orbitale),
                || side("Or-L", 1.0, orbitale),
            );
            vec![r, l]
        },
    );
    po.into_iter().chain(or).collect()
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
const CANAL_LATERAL_MM: f64 = 16.0;

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
        [(1, 1), (1, -1), (2, 1), (2, -1)]
            .iter()
            .all(|&(a, delta)| {
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
    let near: Vec<[usize; 3]> = canal.iter().filter(|c| c.1 <= keep).map(|c| c.0).collect();
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
    let rays = Rays::cast(&g);
    let Some(opening) = Opening::find(&g, &rays) else {
        return Err(format!(
            "no {name} orbit found: no region where {ORBIT_DEPTH_MM:.0} mm of soft tissue lies in front of bone, 22–45 mm from the midline"
        ));
    };
    let rim = inferior_rim(&g, &rays, &opening);
    if rim.len() < 3 {
        return Err(format!(
            "the {name} orbit's opening has no inferior rim in the CT (the bone under it is missing)"
        ));
    }
    Ok(rim_crest(&g, &rays, &rim))
}

/// The rays of an orbit search grid, one per (s, v), run backwards from in front of the face.
struct Rays {
    /// Per (s, v): Some(bone hit index along a) or None (unknown).
    hit: Vec<Option<usize>>,
    /// Deep when the soft path is long.
    deep: Vec<bool>,
    /// Rays that leave the CT before bone: what lies behind them is unknown.
    open: Vec<bool>,
    /// Rays that cross air inside the head (a sinus, the nose) before bone.
    cavity: Vec<bool>,
}

impl Rays {
    fn cast(g: &Grid) -> Rays {
        let [ns, nv, na] = g.n;
        let mut rays = Rays {
            hit: vec![None; ns * nv],
            deep: vec![false; ns * nv],
            open: vec![false; ns * nv],
            cavity: vec![false; ns * nv],
        };
        let depth = (ORBIT_DEPTH_MM / STEP).round() as usize;
        for iv in 0..nv {
            for is in 0..ns {
                // Soft tissue crossed before bone; air inside (a sinus) does not count.
                let mut soft = 0;
                let mut entered = false;
                let mut known = true;
                for ia in (0..na).rev() {
                    let k = g.idx([is, iv, ia]);
                    let h = g.hu[k];
                    // In front of the face the CT may end: air until the skin; within, unknown.
                    if h.is_nan() {
                        if entered {
                            known = false;
                            break;
                        }
                        continue;
                    }
                    if g.bone[k] {
                        rays.hit[is + ns * iv] = Some(ia);
                        break;
                    }
                    if h >= AIR_HU {
                        entered = true;
                        soft += 1;
                    } else if entered {
                        rays.cavity[is + ns * iv] = true;
                    }
                }
                rays.deep[is + ns * iv] = known && soft >= depth;
                // A ray wholly outside the CT (beyond its last slice) is unknown too.
                let inside = (0..na).any(|ia| !g.hu[g.idx([is, iv, ia])].is_nan());
                rays.open[is + ns * iv] = !known || !inside;
            }
        }
        rays
    }
}

/// The orbit's opening: the 4-connected regions of deep rays (`comp`, per (s, v); `usize::MAX`
/// where not deep) and the one that is the orbit.
struct Opening {
    comp: Vec<usize>,
    orbit: usize,
}

impl Opening {
    /// The region with most rays 22–45 mm out among those with bone under them, if it has some
    /// such rays and the area of an orbit.
    fn find(g: &Grid, rays: &Rays) -> Option<Opening> {
        let [ns, nv, _] = g.n;
        let (deep, open) = (&rays.deep, &rays.open);
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
            let (mut size, mut score, mut floored) = (0, 0, true);
            while let Some(k) = stack.pop() {
                size += 1;
                let (is, iv) = (k % ns, k / ns);
                // An orbit has bone under its opening: not the grid's end nor the CT's.
                if iv == 0 || open[k - ns] {
                    floored = false;
                }
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
            if floored && best.is_none_or(|b| score > b.1) {
                best = Some((id, score, size));
            }
            id += 1;
        }
        let min_area = (300.0 / (STEP * STEP)) as usize;
        let (orbit, _, _) = best.filter(|b| b.1 > 0 && b.2 >= min_area)?;
        Some(Opening { comp, orbit })
    }
}

/// The inferior rim under `opening`: (is, iv) of the rim ray of each column that has one.
fn inferior_rim(g: &Grid, rays: &Rays, opening: &Opening) -> Vec<(usize, usize)> {
    let [ns, nv, _] = g.n;
    // Rim top per column: the lowest ray of the opening whose ray below stops at bone.
    let min_height = (10.0 / STEP) as usize;
    let mut rim: Vec<(usize, usize)> = Vec::new(); // (is, iv of the rim ray)
    for is in 0..ns {
        let rows: Vec<usize> = (0..nv)
            .filter(|iv| opening.comp[is + ns * iv] == opening.orbit)
            .collect();
        let (Some(&low), Some(&high)) = (rows.first(), rows.last()) else {
            continue;
        };
        if high - low < min_height || low == 0 {
            continue;
        }
        // The rim is solid bone under the skin: its ray meets no sinus before it.
        let below = is + ns * (low - 1);
        if rays.hit[below].is_some() && !rays.cavity[below] {
            rim.push((is, low - 1));
        }
    }
    rim
}

/// Orbitale on the inferior rim `rim` (at least one column): the lowest rim top, at the HU
/// crossing `BONE_HU` above the rim's bone, in frame coordinates.
fn rim_crest(g: &Grid, rays: &Rays, rim: &[(usize, usize)]) -> [f64; 3] {
    let ns = g.n[0];
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
    let front = rays.hit[is + ns * iv].unwrap_or(0);
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
    g.coords([is as f64, iv as f64 + frac, ia as f64])
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
mod tests {
    use super::*;
    use crate::vec3::{dot, sub};
    use crate::volume::Volume;
    use std::path::Path;
    use std::sync::OnceLock;

    /// A CT with its labels, the skin's midsagittal frame and its soft landmarks.
    struct Head3 {
        vol: Volume,
        labels: Vec<u8>,
        mid: HeadFrame,
        soft: Vec<Landmark>,
    }

    impl Head3 {
        fn run(&self, head: &Head) -> (Result<ClinicalFrame, String>, f64) {
            let bone = Bone {
                vol: &self.vol,
                labels: &self.labels,
            };
            let t = std::time::Instant::now();
            let r = clinical_frame(&bone, &self.mid, &self.soft, head);
            (r, t.elapsed().as_secs_f64())
        }
    }

    /// A real sample read as the pipeline reads it (its stages up to the face); None, with a
    /// line saying so, when its CT has not been fetched.
    fn real(dir: &str) -> Option<Head3> {
        let s = crate::anatomy::sample::read(dir)?;
        let mid = crate::landmarks::head_frame(&s.skin).unwrap();
        let soft = crate::landmarks::detect::detect(&s.skin, Some(&s.skull), &mid);
        Some(Head3 {
            vol: s.vol,
            labels: s.labels,
            mid,
            soft,
        })
    }

    /// The jaws phantom at 1.5 mm (upright, face toward −y; no ear canals or orbits in its
    /// bone) with its analytic skin, the skin turned face-down by `pitch_deg` about the x axis
    /// through the condyles' level.
    fn phantom(pitch_deg: f64) -> Head3 {
        static CT: OnceLock<(Volume, Vec<u8>)> = OnceLock::new();
        let (vol, labels) = CT.get_or_init(|| {
            let vol = crate::test_phantoms::jaws_ct();
            let seg = crate::segment::segment(
                &vol,
                &crate::case::Case::default().tissue,
                Path::new("phantom"),
            )
            .unwrap();
            (vol, seg.labels)
        });
        let mut skin = crate::test_phantoms::jaws_face_scan(2.0);
        let (s, c) = pitch_deg.to_radians().sin_cos();
        for p in &mut skin.vertices {
            // Face-down: forward (−y) tips down (−z).
            let (y, z) = (p[1], p[2]);
            p[1] = y * c - z * s;
            p[2] = z * c + y * s;
        }
        let mid = crate::landmarks::head_frame(&skin).unwrap();
        let soft = crate::landmarks::detect::detect(&skin, None, &mid);
        Head3 {
            vol: vol.clone(),
            labels: labels.clone(),
            mid,
            soft,
        }
    }

    /// Porion and orbitale placed by hand (LPS mm), each with how.
    type Fixture = [(&'static str, [f64; 3], &'static str); 4];

    /// ProMED CT 0051 (0.96 × 0.96 × 1.5 mm; LPS x = 0.957 i, y = 244.04 − 0.957 j,
    /// z = 1.5 k). Porion: the top of the air lumen (the −300 HU crossing) under the canal's
    /// bony roof, read on coronal slices; orbitale: the top of the inferior rim (the 300 HU
    /// crossing going down from the orbit), read per sagittal slice, the lowest slice's.
    const REAL_CT: Fixture = [
        (
            "Po-R",
            [75.6, 130.6, 36.6],
            "coronal j 117-120: lumen k 20-24 from the concha (i 58) to i 92 under a roof of 1000-1400 HU; its top at i 79, j 118.5, k 24.4",
        ),
        (
            "Po-L",
            [174.2, 133.0, 36.6],
            "coronal j 115-117: lumen k 21-24, i 172-198 under a roof at k 25-27; its top at i 182, j 116, k 24.4",
        ),
        (
            "Or-R",
            [93.8, 60.3, 41.8],
            "sagittal i 84-110: rim top k 31.1 (i 88) down to 27.9 at i 98 (j 192), up to 30.6 at i 110; the lowest at i 98",
        ),
        (
            "Or-L",
            [158.9, 56.5, 46.0],
            "sagittal i 150-180: rim top 30.6-31.0 flat over i 156-168 (within 0.3 mm), the lowest at i 166, j 196, k 30.6",
        ),
    ];

    /// VTK headsq (3.2 × 3.2 × 1.5 mm; x = 3.2 i, y = −3.2 j, z = −1.5 k), the head ~14°
    /// face-down. Porion as above on coronal slices; orbitale per sagittal slice as the top of
    /// the rim's front bone (300 HU crossing), highest in a frame turned 14° face-down, the
    /// lowest slice's.
    const REAL_MANDIBLE: Fixture = [
        (
            "Po-R",
            [57.6, -89.6, -25.9],
            "coronal j 27-28: lumen k 18-21, i 13-19 (-300..-800 HU) under a roof of 600-1400 HU at k 16-18; the -300 HU crossing at i 18, j 28, k 17.25",
        ),
        (
            "Po-L",
            [139.2, -89.6, -27.0],
            "coronal j 27-28: lumen k 19-23, i 43-48 under a roof at k 16-17 (700-1400 HU); the crossing at i 43.5, j 28, k 18.0",
        ),
        (
            "Or-R",
            [70.4, -160.0, -43.6],
            "sagittal i 20-22: the rim's front bone at j 50, its top k 28.1-29.1; lowest at i 22 (the rim is at the front there)",
        ),
        (
            "Or-L",
            [121.6, -160.0, -44.1],
            "sagittal i 38-41: the rim's front bone at j 50 (i 38), top k 29.4; i 39-40 have no front lip (top at j 47)",
        ),
    ];

    /// Pitch (face down +) and roll (left up +) of the Frankfort plane of four points in the
    /// midsagittal frame, from the porion and orbitale midpoints and the left and right means.
    fn hand_angles(mid: &HeadFrame, pts: &Fixture) -> (f64, f64) {
        let c: Vec<[f64; 3]> = pts.iter().map(|p| mid.coords(p.1)).collect();
        let mean = |a: usize, b: usize, k: usize| 0.5 * (c[a][k] + c[b][k]);
        let pitch = (mean(0, 1, 1) - mean(2, 3, 1))
            .atan2(mean(2, 3, 2) - mean(0, 1, 2))
            .to_degrees();
        let roll = (mean(1, 3, 1) - mean(0, 2, 1))
            .atan2(mean(1, 3, 0) - mean(0, 2, 0))
            .to_degrees();
        (pitch, roll)
    }

    /// Detected against hand points: height and depth (v, a: what sets the plane) within
    /// `tol_va` mm, the lateral offset within `tol_s` (a flat rim or a level canal roof has its
    /// highest or lowest point anywhere along it).
    fn check(
        name: &str,
        h: &Head3,
        fixture: &Fixture,
        tol_va: f64,
        tol_s: f64,
        tol_deg: f64,
    ) -> ClinicalFrame {
        let (cf, secs) = h.run(&Head::default());
        let cf = cf.unwrap();
        println!("{name}: {:?}, {secs:.2} s: {}", cf.method, cf.why);
        for (label, hand, _) in fixture {
            let l = cf.landmarks.iter().find(|l| l.label == *label).unwrap();
            let p = l
                .position
                .unwrap_or_else(|| panic!("{label}: {:?}", l.missing));
            let d = h.mid.coords(sub(p, *hand));
            let d = sub(d, h.mid.coords([0.0; 3]));
            println!(
                "  {label}: detected [{:.1}, {:.1}, {:.1}] hand [{:.1}, {:.1}, {:.1}] (s, v, a) off [{:.1}, {:.1}, {:.1}] mm",
                p[0], p[1], p[2], hand[0], hand[1], hand[2], d[0], d[1], d[2]
            );
            assert!(
                d[1].abs() <= tol_va && d[2].abs() <= tol_va && d[0].abs() <= tol_s,
                "{name} {label}: off {d:?} mm"
            );
        }
        let (pitch, roll) = hand_angles(&h.mid, fixture);
        let roll_found = cf.plane_roll_deg.unwrap();
        println!(
            "  pitch {:.1}° (hand {pitch:.1}°), Frankfort roll {roll_found:.1}° (hand {roll:.1}°)",
            cf.pitch_deg
        );
        assert_eq!(cf.method, Method::Frankfort);
        assert!(
            (cf.pitch_deg - pitch).abs() <= tol_deg,
            "pitch {}",
            cf.pitch_deg
        );
        assert!((roll_found - roll).abs() <= tol_deg, "roll {roll_found}");
        // The frame is the midsagittal one turned by the pitch.
        let f = cf.frame;
        assert!((dot(f.lateral, h.mid.lateral) - 1.0).abs() < 1e-9);
        let turned = dot(f.anterior, h.mid.vertical).asin().to_degrees();
        assert!((turned + cf.pitch_deg).abs() < 1e-6, "{turned}");
        cf
    }

    #[test]
    fn real_ct_frankfort_matches_the_hand_points() {
        let Some(h) = real("real") else { return };
        check("real", &h, &REAL_CT, 3.0, 5.0, 2.0);
    }

    #[test]
    fn real_mandible_frankfort_matches_the_hand_points() {
        let Some(h) = real("real-mandible") else {
            return;
        };
        // 3.2 mm voxels in-plane: a voxel and a half for (v, a), two laterally.
        let cf = check("real-mandible", &h, &REAL_MANDIBLE, 4.5, 6.5, 2.5);
        // The facial plane on this head (validation.toml: 16.2°) agrees within Holdaway's spread.
        let fp = facial_plane_pitch(&h.mid, &h.soft).unwrap();
        println!("  facial plane {fp:.1}°");
        assert!((fp - 16.2).abs() < 1.0, "{fp}");
        assert!((cf.pitch_deg - fp).abs() < 6.0);
    }

    #[test]
    fn phantom_falls_back_to_the_facial_plane() {
        let h = phantom(0.0);
        let (cf, secs) = h.run(&Head::default());
        let cf = cf.unwrap();
        println!(
            "phantom: {:?} {:.2}° {secs:.2} s: {}",
            cf.method, cf.pitch_deg, cf.why
        );
        assert_eq!(cf.method, Method::FacialPlane);
        for l in &cf.landmarks {
            println!("  {} {:?}", l.label, l.missing);
            assert!(l.position.is_none() && l.missing.as_ref().is_some_and(|m| !m.is_empty()));
        }
        // Its known upright frame: N'–Pog' of the analytic skin.
        let n = facesim_validate::phantom_jaws::landmark("soft tissue nasion").unwrap();
        let pog = facesim_validate::phantom_jaws::landmark("soft tissue pogonion").unwrap();
        let upright = (pog[1] - n[1]).atan2(n[2] - pog[2]).to_degrees();
        println!("  analytic facial plane {upright:.2}°");
        assert!((cf.pitch_deg - upright).abs() < 1.0);
        assert!(cf.pitch_deg.abs() < 5.0);
        assert!(cf.why.starts_with("facial plane"), "{}", cf.why);
    }

    #[test]
    fn a_pitched_phantom_comes_back_with_its_pitch() {
        let base = phantom(0.0).run(&Head::default()).0.unwrap().pitch_deg;
        for pitch in [-15.0, -10.0, 10.0, 15.0] {
            let cf = phantom(pitch).run(&Head::default()).0.unwrap();
            println!(
                "phantom turned {pitch}°: {:.2}° ({base:.2}° upright)",
                cf.pitch_deg
            );
            assert_eq!(cf.method, Method::FacialPlane);
            assert!(
                (cf.pitch_deg - base - pitch).abs() < 1.0,
                "{}",
                cf.pitch_deg
            );
        }
    }

    #[test]
    fn frankfort_forced_on_the_phantom_names_what_is_missing() {
        let h = phantom(0.0);
        let head = Head {
            frame: Some(FrameChoice::Frankfort),
            pitch_deg: 0.0,
        };
        let e = h.run(&head).0.unwrap_err();
        println!("{e}");
        assert!(e.starts_with("[head] frame = \"frankfort\""));
        assert!(
            e.contains("Po-R") && e.contains("Or-L") && !e.contains('\n'),
            "{e}"
        );
    }

    #[test]
    fn the_pitch_correction_adds_exactly() {
        let h = phantom(0.0);
        let plain = h.run(&Head::default()).0.unwrap();
        let head = Head {
            frame: Some(FrameChoice::FacialPlane),
            pitch_deg: 7.5,
        };
        let cf = h.run(&head).0.unwrap();
        assert_eq!(cf.method, Method::FacialPlane);
        assert_eq!(cf.pitch_deg, plain.pitch_deg);
        assert_eq!(cf.correction_deg, 7.5);
        let want = crate::anatomy::bone::turned(&h.mid, plain.pitch_deg + 7.5);
        for (a, b) in [
            (cf.frame.anterior, want.anterior),
            (cf.frame.vertical, want.vertical),
        ] {
            assert!(sub(a, b).iter().all(|x| x.abs() < 1e-12));
        }
        let up = |f: &HeadFrame| dot(f.anterior, h.mid.vertical).asin().to_degrees();
        assert!((up(&plain.frame) - up(&cf.frame) - 7.5).abs() < 1e-9);
    }

    #[test]
    fn the_facial_plane_forced_without_soft_pogonion_is_an_error() {
        let h = phantom(0.0);
        let soft: Vec<Landmark> = h
            .soft
            .iter()
            .filter(|l| l.label != "Pog'")
            .cloned()
            .collect();
        let bone = Bone {
            vol: &h.vol,
            labels: &h.labels,
        };
        let head = Head {
            frame: Some(FrameChoice::FacialPlane),
            pitch_deg: 0.0,
        };
        let e = clinical_frame(&bone, &h.mid, &soft, &head).unwrap_err();
        assert!(e.contains("Pog'"), "{e}");
        let cf = clinical_frame(&bone, &h.mid, &soft, &Head::default()).unwrap();
        assert_eq!(cf.method, Method::CtAxes);
        assert_eq!(cf.pitch_deg, 0.0);
    }
}

//! Landmarks of a face mesh alone — a 3D photo (3dMD, Vectra, a phone scan) or any program's
//! skin — with no CT (docs/guide/landmarks.md "A face mesh alone", `facesim landmarks`).
//!
//! A scan comes in its scanner's frame (often y up, z forward), tilted, in millimetres or
//! metres, with neck, ears and holes. Its unit is read from its size (a head is 0.1–1 m
//! across); its head frame is found from its shape alone, so that rotating or rescaling the
//! file rotates and rescales the landmarks with it:
//!
//! 1. the midsagittal plane: the mirror plane that maps the mesh onto itself best, searched over
//!    directions through the area centroid, then refined by mirror ICP (as `head_frame`);
//! 2. up and front within that plane: every 10° direction (and both sides of the plane) is tried
//!    as "up", the profile landmarks are detected, and the direction whose landmarks form a face
//!    (nose, fold, lips, chin in order, plausibly spaced) wins;
//! 3. the vertical is then made the soft-tissue facial line N'–Pog' (else G'–Sn, else N'–Sn),
//!    redetecting until the line stops turning: a definition on the face itself, not on the
//!    10° search grid.
//!
//! Everything is computed in millimetres; positions are returned in the file's own unit and axes.

use super::detect::{self, SOFT};
use super::frame::{HeadFrame, head_frame, profile, section, unit};
use super::landmark::{Carried, Kind, Landmark, Ordered};
use super::lateral::PAIRED;
use super::measure::{self, Measure};
use crate::mesh::Mesh;
use crate::vec3::{add, cross, dot, norm, scale, sub};
use rayon::prelude::*;
use serde::Serialize;

/// Where the head frame comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameFrom {
    /// Found from the mesh's shape (the default).
    Shape,
    /// The file's axes taken as LPS (x left, y back, z up), as a CT's skin is.
    Lps,
}

/// The unit a mesh is in, judged from its size.
#[derive(Clone, Debug, Serialize)]
pub struct Unit {
    /// "mm", "cm" or "m".
    pub name: &'static str,
    pub mm_per_unit: f64,
    /// Twice the largest distance of a vertex from the centroid, in the file's unit.
    pub extent: f64,
}

/// A head (or a face cut from one) is this many mm across, at most and at least.
const HEAD_MM: (f64, f64) = (50.0, 1000.0);

/// The unit of `mesh`: the one of mm, cm, m in which it is a head's size; or why none is.
pub fn unit_of(mesh: &Mesh) -> Result<Unit, String> {
    let v = &mesh.vertices;
    if v.len() < 3 || mesh.triangles.is_empty() {
        return Err(format!(
            "not a face: {} vertices and {} triangles",
            v.len(),
            mesh.triangles.len()
        ));
    }
    let c = scale(
        v.iter().fold([0.0; 3], |s, p| add(s, *p)),
        1.0 / v.len() as f64,
    );
    let extent = 2.0 * v.iter().map(|p| norm(sub(*p, c))).fold(0.0, f64::max);
    for (name, mm) in [("mm", 1.0), ("cm", 10.0), ("m", 1000.0)] {
        let size = extent * mm;
        if (HEAD_MM.0..HEAD_MM.1).contains(&size) {
            return Ok(Unit {
                name,
                mm_per_unit: mm,
                extent,
            });
        }
    }
    Err(format!(
        "not a face: the mesh is {extent:.3} units across, which is not a head's size in mm, cm \
         or m (a face is about 150 mm tall)"
    ))
}

/// The head frame found, in the file's unit and axes.
#[derive(Clone, Debug, Serialize)]
pub struct FoundFrame {
    /// "shape" (found from the mesh) or "lps" (the file's axes).
    pub from: &'static str,
    /// The line the vertical was set along ("N'–Pog'", …), or how it was set.
    pub vertical_from: String,
    /// A point of the midsagittal plane (file unit).
    pub origin: [f64; 3],
    /// Unit vectors in the file's axes: towards the patient's left, up, forward.
    pub lateral: [f64; 3],
    pub vertical: [f64; 3],
    pub anterior: [f64; 3],
    /// Mean mirror mismatch of the points used to place the plane (mm).
    pub symmetry_residual_mm: f64,
}

/// The landmarks and measurements of a face mesh.
#[derive(Clone, Debug, Serialize)]
pub struct FaceLandmarks {
    pub unit: Unit,
    pub frame: FoundFrame,
    /// In the file's own unit and axes; missing ones say why.
    pub landmarks: Vec<Landmark>,
    /// Measurements (mm, degrees) of docs/guide/landmarks.md, one value each (`before`).
    pub measurements: Ordered<Measure>,
}

/// Reflect p across the plane through o with unit normal n.
fn mirror(p: [f64; 3], o: [f64; 3], n: [f64; 3]) -> [f64; 3] {
    sub(p, scale(n, 2.0 * dot(sub(p, o), n)))
}

/// The area-weighted centroid of a surface (its triangles' centroids weighted by area).
fn area_centroid(m: &Mesh) -> [f64; 3] {
    let mut s = [0.0; 3];
    let mut w = 0.0;
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.vertices[i as usize]);
        let area = 0.5 * norm(cross(sub(b, a), sub(c, a)));
        s = add(s, scale(add(add(a, b), c), area / 3.0));
        w += area;
    }
    if w > 0.0 {
        scale(s, 1.0 / w)
    } else {
        m.vertices[0]
    }
}

/// About `n` points spread evenly over the upper half sphere (the Fibonacci lattice): the
/// plane normals tried; a normal and its opposite are one plane.
fn half_sphere(n: usize) -> Vec<[f64; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            [r * phi.cos(), r * phi.sin(), z]
        })
        .collect()
}

/// The mean of the smallest `keep` fraction of `d`.
fn trimmed_mean(mut d: Vec<f64>, keep: f64) -> f64 {
    d.sort_by(f64::total_cmp);
    let k = ((d.len() as f64 * keep).ceil() as usize).clamp(1, d.len().max(1));
    d[..k.min(d.len())].iter().sum::<f64>() / k as f64
}

/// The skin within this distance of the nose tip sets the face's front (mm).
const FRONT_MM: f64 = 60.0;

/// The widest a nose is 8 mm behind its tip (mm; adult noses are 25–40 mm wide at the alae).
const NOSE_WIDTH_MM: f64 = 40.0;

/// Subnasale lies at most this far from pronasale (mm, in the midsagittal plane). Adult nasal tip
/// protrusion sn–prn is about 20 ± 2 mm (Farkas 1994); facesim's concavity-based subnasale sits
/// 23–24 mm from the tip on the jaws phantom and on a real scanner's face, so 30 mm leaves room
/// for a large nose. Read upside down, a face cut below the nose (the real CT's, 36 mm below the
/// tip) passes every other rule with its soft nasion as "subnasale", 37 mm from the tip.
const SN_PRN_MAX_MM: f64 = 30.0;

/// A nose tip is at least this far from the mesh's open border (mm).
const BORDER_MM: f64 = 5.0;

/// Vertices bucketed in cubes of side `h`: the distance to the nearest one, up to h.
struct VertexGrid {
    h: f64,
    cells: std::collections::HashMap<[i64; 3], Vec<[f64; 3]>>,
}

impl VertexGrid {
    fn new(points: &[[f64; 3]], h: f64) -> VertexGrid {
        let mut cells: std::collections::HashMap<[i64; 3], Vec<[f64; 3]>> = Default::default();
        for p in points {
            cells
                .entry(p.map(|x| (x / h).floor() as i64))
                .or_default()
                .push(*p);
        }
        VertexGrid { h, cells }
    }

    /// The vertices on the mesh's open border (edges of one triangle), bucketed by BORDER_MM.
    fn border(mesh: &Mesh) -> VertexGrid {
        let mut count: std::collections::HashMap<(u32, u32), u32> = Default::default();
        for t in &mesh.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let pts: Vec<[f64; 3]> = count
            .iter()
            .filter(|(_, n)| **n == 1)
            .flat_map(|((a, b), _)| [mesh.vertices[*a as usize], mesh.vertices[*b as usize]])
            .collect();
        VertexGrid::new(&pts, BORDER_MM)
    }

    fn near(&self, p: [f64; 3]) -> f64 {
        let c = p.map(|x| (x / self.h).floor() as i64);
        let mut best = self.h;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for q in list {
                            best = best.min(norm(sub(p, *q)));
                        }
                    }
                }
            }
        }
        best
    }
}

/// Mean mirror mismatch of `pts` across the plane (o, n): each mirror image's distance to the
/// nearest vertex of `grid` (capped at its cell), the worse 10 % dropped (a face is not
/// exactly symmetric, and its border is not).
fn mismatch(grid: &VertexGrid, pts: &[[f64; 3]], o: [f64; 3], n: [f64; 3]) -> f64 {
    trimmed_mean(
        pts.iter().map(|p| grid.near(mirror(*p, o, n))).collect(),
        0.9,
    )
}

/// Two unit vectors spanning the plane normal to the unit vector n.
fn in_plane(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let t1 = unit(if n[0].abs() < 0.9 {
        cross(n, [1.0, 0.0, 0.0])
    } else {
        cross(n, [0.0, 1.0, 0.0])
    });
    (t1, cross(n, t1))
}

/// The plane (o, n) improved by a pattern search: at each (tilt °, shift mm) step the 27
/// planes tilted by -1, 0, 1 steps about two axes and shifted by -1, 0, 1 steps along the
/// normal are scored and the best kept.
fn pattern_search(
    grid: &VertexGrid,
    pts: &[[f64; 3]],
    mut o: [f64; 3],
    mut n: [f64; 3],
    steps: &[(f64, f64)],
) -> ([f64; 3], [f64; 3], f64) {
    let mut best = mismatch(grid, pts, o, n);
    for &(tilt, shift) in steps {
        // Repeat a step while it improves (at most 10 times).
        for _ in 0..10 {
            let (t1, t2) = in_plane(n);
            let d = tilt.to_radians();
            let trials: Vec<([f64; 3], [f64; 3])> = (-1..=1)
                .flat_map(|i| (-1..=1).flat_map(move |j| (-1..=1).map(move |k| (i, j, k))))
                .map(|(i, j, k)| {
                    let m = unit(add(
                        n,
                        add(scale(t1, i as f64 * d), scale(t2, j as f64 * d)),
                    ));
                    (add(o, scale(m, k as f64 * shift)), m)
                })
                .collect();
            match trials
                .par_iter()
                .map(|(o2, n2)| (mismatch(grid, pts, *o2, *n2), (*o2, *n2)))
                .min_by(|a, b| a.0.total_cmp(&b.0))
            {
                Some((s, (o2, n2))) if s < best - 1e-9 => (best, o, n) = (s, o2, n2),
                _ => break,
            }
        }
    }
    (o, n, best)
}

/// The midsagittal plane of a head-sized mesh (mm): (a point, the unit normal, the residual).
/// Every direction of a 1000-point half sphere through the area centroid is scored by
/// `mismatch`; the best is refined by `pattern_search` down to 0.5° and 0.5 mm.
fn symmetry_plane(mesh: &Mesh, grid: &VertexGrid) -> ([f64; 3], [f64; 3], f64) {
    let c = area_centroid(mesh);
    let step = (mesh.vertices.len() / 1000).max(1);
    let pts: Vec<[f64; 3]> = mesh.vertices.iter().step_by(step).copied().collect();
    let (_, n) = half_sphere(1000)
        .par_iter()
        .map(|n| (mismatch(grid, &pts, c, *n), *n))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap_or((f64::NAN, [1.0, 0.0, 0.0]));
    pattern_search(
        grid,
        &pts,
        c,
        n,
        &[(4.0, 4.0), (2.0, 2.0), (1.0, 1.0), (0.5, 0.5)],
    )
}

/// (v, a) of a found landmark in `frame`.
fn va(lms: &[Landmark], label: &str, frame: &HeadFrame) -> Option<[f64; 2]> {
    let p = lms.iter().find(|l| l.label == label)?.position?;
    let c = frame.coords(p);
    Some([c[1], c[2]])
}

/// How much the detected landmarks look like a face: one point per landmark found where a face
/// has it, relative to the one above it (heights and depths in mm, ranges wide enough for any
/// adult face, narrow enough that a forehead, a chin or the back of a head read as a nose fail).
fn face_score(mesh: &Mesh, border: &VertexGrid, lms: &[Landmark], frame: &HeadFrame) -> usize {
    let g = |l: &str| va(lms, l, frame);
    let Some(prn) = g("Prn") else {
        return 0;
    };
    // Not where the scan stops: a tip at the mesh's open border is the scan's edge.
    let at = lms
        .iter()
        .find(|l| l.label == "Prn")
        .and_then(|l| l.position);
    if at.is_some_and(|p| border.near(p) < border.h) {
        return 0;
    }
    // A nose is narrow: the skin within 8 mm behind its tip and 3 mm of its height spans at
    // most NOSE_WIDTH_MM from side to side (a bump on the back of a head or a chin is wider).
    if width_at(mesh, frame, prn, 3.0, 8.0, f64::INFINITY).is_some_and(|w| w > NOSE_WIDTH_MM) {
        return 0;
    }
    // A nose has a root: a soft nasion above the tip and behind it.
    let root = g("N'").is_some_and(|n| {
        (15.0..=75.0).contains(&(n[0] - prn[0])) && (8.0..=45.0).contains(&(prn[1] - n[1]))
    });
    // Subnasale, where found, no farther from the tip than a nose's (an upside-down lower lip's
    // "subnasale" is a chin or a nose above it).
    let near_sn = g("Sn").is_none_or(|p| (prn[0] - p[0]).hypot(prn[1] - p[1]) <= SN_PRN_MAX_MM);
    // A nose tip, not where the scan stops: skin 10 mm above and below it, behind it.
    // And a nose the right way up: 10 mm below the tip (the columella, towards subnasale) the
    // profile lies farther behind it than 10 mm above (the dorsum), or the nose has its root
    // above it and no subnasale too far below. Read upside down, a lower lip or a chin would
    // pass every other rule. A drooping tip or a head bowed in the scanner (the real CT's: the
    // columella 3 mm ahead of the dorsum) fails the first test and passes the second.
    let tip = profile(&section(mesh, frame), |_, _| true).is_some_and(|p| {
        let (below, above) = (p.at(prn[0] - 10.0), p.at(prn[0] + 10.0));
        below.is_finite()
            && above.is_finite()
            && above < prn[1] - 1.0
            && (below < above || (root && near_sn))
    });
    if !tip {
        return 0;
    }
    // (label, the landmark above it, its drop below that one, how far behind pronasale).
    type Link = (&'static str, &'static str, (f64, f64), (f64, f64));
    let below: [Link; 6] = [
        ("Sn", "Prn", (5.0, 35.0), (6.0, 35.0)),
        ("Ls", "Sn", (3.0, 30.0), (0.0, 35.0)),
        ("Sto", "Ls", (1.5, 25.0), (0.0, 40.0)),
        ("Li", "Sto", (1.5, 25.0), (0.0, 40.0)),
        ("B'", "Li", (3.0, 35.0), (0.0, 50.0)),
        ("Pog'", "B'", (2.0, 35.0), (0.0, 50.0)),
    ];
    let mut score = 0;
    for (l, above, drop, depth) in below {
        match (g(l), g(above)) {
            (Some(p), Some(q))
                if (drop.0..=drop.1).contains(&(q[0] - p[0]))
                    && (depth.0..=depth.1).contains(&(prn[1] - p[1]))
                    && (l != "Sn" || near_sn) =>
            {
                score += 1
            }
            _ => break,
        }
    }
    if root {
        // A nose has a root: worth more than one more lip landmark below.
        score += 2;
    }
    score
}

/// The midline's soft landmarks (a face mesh has no bone), in `frame`: what the frame search
/// judges; the paired ones are added once the frame is chosen (`landmarks_of`).
fn soft(mesh: &Mesh, frame: &HeadFrame) -> Vec<Landmark> {
    detect::detect(mesh, None, frame)
        .into_iter()
        .filter(|l| l.kind == Kind::Soft)
        .collect()
}

/// The frame whose anterior axis is the face's own front: the area vector (Σ ½ (b−a)×(c−a))
/// of the skin within FRONT_MM of the nose tip of `lms`, made orthogonal to the plane and
/// pointing the way `frame` faces. It depends on the face's shape alone (by Stokes, on the loop
/// where that sphere cuts the face), so a rotated scan gives the rotated frame.
fn front_frame(mesh: &Mesh, frame: &HeadFrame, lms: &[Landmark]) -> Option<HeadFrame> {
    let tip = lms.iter().find(|l| l.label == "Prn")?.position?;
    let mut area = [0.0; 3];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let mid = scale(add(add(a, b), c), 1.0 / 3.0);
        if norm(sub(mid, tip)) < FRONT_MM {
            area = add(area, scale(cross(sub(b, a), sub(c, a)), 0.5));
        }
    }
    let l = frame.lateral;
    let front = sub(area, scale(l, dot(area, l)));
    if norm(front) < 1e-9 {
        return None;
    }
    let front = if dot(front, frame.anterior) < 0.0 {
        scale(front, -1.0)
    } else {
        front
    };
    Some(HeadFrame::with_up(
        frame.origin,
        l,
        cross(unit(front), l),
        frame.symmetry_residual_mm,
    ))
}

/// The width (mm, side to side) of the skin within 5 mm behind the tip of `lms` and 2 mm of its
/// height: a nose tip is narrow (about 15 mm there); a lip, a chin or a brow is not.
fn tip_width(mesh: &Mesh, frame: &HeadFrame, lms: &[Landmark]) -> f64 {
    let Some(tip) = lms
        .iter()
        .find(|l| l.label == "Prn")
        .and_then(|l| l.position)
    else {
        return f64::INFINITY;
    };
    let t = frame.coords(tip);
    width_at(mesh, frame, [t[1], t[2]], 2.0, 5.0, 1.0)
        .filter(|w| *w > 0.0)
        .unwrap_or(f64::INFINITY)
}

/// The side-to-side extent (mm) of the mesh's vertices within `half_height` of the height of
/// `tip` (v, a in `frame`), from `behind` behind it to `ahead` in front of it; None if none.
fn width_at(
    mesh: &Mesh,
    frame: &HeadFrame,
    tip: [f64; 2],
    half_height: f64,
    behind: f64,
    ahead: f64,
) -> Option<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in &mesh.vertices {
        let c = frame.coords(*p);
        if (c[1] - tip[0]).abs() < half_height && c[2] > tip[1] - behind && c[2] < tip[1] + ahead {
            lo = lo.min(c[0]);
            hi = hi.max(c[0]);
        }
    }
    (hi >= lo).then_some(hi - lo)
}

/// The best of 72 frames in the plane (o, n): both sides of the plane as the patient's left,
/// every 10° as up, each turned to its nose tip's front (`front_frame`). Of those that read
/// as a face (`face_score` ≥ 2), the one with the narrowest tip (`tip_width`) wins: the finer
/// score is brittle at its ranges' edges (a 10° turn moves a landmark across one), the nose's
/// narrowness is not, and read upside down a lower lip passes every other rule.
fn best_up(
    mesh: &Mesh,
    border: &VertexGrid,
    o: [f64; 3],
    n: [f64; 3],
    residual: f64,
) -> (usize, HeadFrame, Vec<Landmark>) {
    let (e1, e2) = in_plane(n);
    let candidates: Vec<HeadFrame> = [1.0, -1.0]
        .iter()
        .flat_map(|side| {
            (0..36).map(move |k| {
                let phi = (k as f64 * 10.0).to_radians();
                HeadFrame::with_up(
                    o,
                    scale(n, *side),
                    add(scale(e1, phi.cos()), scale(e2, phi.sin())),
                    residual,
                )
            })
        })
        .collect();
    candidates
        .par_iter()
        .map(|f| {
            // Each candidate is judged in the front frame of its nose tip: the score then
            // does not depend on how the 10° grid happens to fall on the face.
            let lms = soft(mesh, f);
            let (f, lms) = match front_frame(mesh, f, &lms) {
                Some(g) => {
                    let l = soft(mesh, &g);
                    (g, l)
                }
                None => (*f, lms),
            };
            (
                face_score(mesh, border, &lms, &f),
                tip_width(mesh, &f, &lms),
                f,
                lms,
            )
        })
        .collect::<Vec<_>>()
        .into_iter()
        .max_by(|a, b| (a.0 >= 2).cmp(&(b.0 >= 2)).then(b.1.total_cmp(&a.1)))
        .map(|(s, _, f, l)| (s, f, l))
        .unwrap_or_else(|| (0, HeadFrame::with_up(o, n, e1, residual), Vec::new()))
}

/// The head frame of a face mesh in mm found from its shape, its landmarks in it, and how the
/// vertical was set; or why no face was found.
fn frame_from_shape(mesh: &Mesh) -> Result<(HeadFrame, Vec<Landmark>, String), String> {
    let border = VertexGrid::border(mesh);
    let border = &border;
    let grid = VertexGrid::new(&mesh.vertices, 4.0);
    let (o, n, residual) = symmetry_plane(mesh, &grid);
    let (mut score, mut frame, mut lms) = best_up(mesh, border, o, n, residual);
    let mut o = o;
    // The plane again from the face alone, as `head_frame` places it: the points within 70 mm
    // of the nose tip and at most 60 mm behind it. The whole mesh's symmetry is blurred by
    // hair, ears, neck and where the scan stops. Twice: the second tip is the better one.
    for _ in 0..2 {
        if score < 2 {
            return Err(not_a_face(&lms));
        }
        let Some(tip) = lms
            .iter()
            .find(|l| l.label == "Prn")
            .and_then(|l| l.position)
        else {
            break;
        };
        let face: Vec<[f64; 3]> = mesh
            .vertices
            .iter()
            .filter(|p| {
                let d = sub(**p, tip);
                norm(d) < 70.0 && dot(d, frame.anterior) > -60.0
            })
            .copied()
            .collect();
        let step = (face.len() / 4000).max(1);
        let face: Vec<[f64; 3]> = face.into_iter().step_by(step).collect();
        if face.len() < 20 {
            break;
        }
        let o1 = add(o, scale(frame.lateral, dot(sub(tip, o), frame.lateral)));
        let (o2, n2, r2) = pattern_search(
            &grid,
            &face,
            o1,
            frame.lateral,
            &[(2.0, 2.0), (1.0, 1.0), (0.5, 0.5), (0.25, 0.25)],
        );
        o = o2;
        (score, frame, lms) = best_up(mesh, border, o2, n2, r2);
    }
    if score < 2 {
        return Err(not_a_face(&lms));
    }
    // Three more rounds of the face's front, the tip moving with the frame.
    let mut how = "the 10° search".to_string();
    for _ in 0..3 {
        let Some(next) = front_frame(mesh, &frame, &lms) else {
            break;
        };
        let next_lms = soft(mesh, &next);
        // Kept while it still reads as a face: a rule on the face, not on the search grid.
        if face_score(mesh, border, &next_lms, &next) < 2 {
            break;
        }
        how = format!("the face's front (its area vector within {FRONT_MM} mm of the nose tip)");
        frame = next;
        lms = next_lms;
    }
    // The landmarks under the nose are extrema of the profile along the front, so a few degrees
    // of pitch decide whether a lip cut off near the scan's edge still shows its fold and
    // convexity (the real CT's face ends 36 mm below the tip: its front finds no fold under the
    // nose, a frame 6° away finds subnasale and labrale superius). When some of them are
    // missing, the frame turned by up to PITCH_TRIES_DEG about the lateral axis that finds more
    // of them (and still reads as a face) is taken, the smallest turn first; the measurements
    // say so.
    let under_nose = |l: &[Landmark]| {
        ["Sn", "Ls", "Sto", "Li"]
            .iter()
            .filter(|x| l.iter().any(|y| y.label == **x && y.position.is_some()))
            .count()
    };
    let found = under_nose(&lms);
    if found < 4 {
        let mut best: Option<(usize, f64, HeadFrame, Vec<Landmark>)> = None;
        for deg in PITCH_TRIES_DEG {
            let turned = pitched(&frame, deg);
            let l = soft(mesh, &turned);
            let n = under_nose(&l);
            if n > best.as_ref().map_or(found, |b| b.0)
                && face_score(mesh, border, &l, &turned) >= 2
            {
                best = Some((n, deg, turned, l));
            }
        }
        if let Some((_, deg, turned, l)) = best {
            how = format!(
                "{how}, turned {deg:+}° about the lateral axis (there the profile below the nose has more of its landmarks)"
            );
            frame = turned;
            lms = l;
        }
    }
    Ok((frame, lms, how))
}

/// Pitches (degrees, the smallest first) tried when the profile below the nose lacks landmarks
/// in the face's front frame: the face's front is not the Frankfort horizontal, and a 3D photo's
/// vertical is a convention within about this much.
const PITCH_TRIES_DEG: [f64; 6] = [-3.0, 3.0, -6.0, 6.0, -10.0, 10.0];

/// `frame` turned by `deg` about its lateral axis (positive: its vertical leans back).
fn pitched(frame: &HeadFrame, deg: f64) -> HeadFrame {
    let (s, c) = deg.to_radians().sin_cos();
    let up = add(scale(frame.vertical, c), scale(frame.anterior, -s));
    HeadFrame::with_up(frame.origin, frame.lateral, up, frame.symmetry_residual_mm)
}

/// Why the best orientation found no face: the first landmark of the nose-to-lip chain missing.
fn not_a_face(lms: &[Landmark]) -> String {
    let why = ["Prn", "Sn", "Ls", "N'"]
        .iter()
        .find_map(|l| {
            lms.iter()
                .find(|x| x.label == *l)
                .and_then(|x| x.missing.as_ref().map(|m| format!("{l}: {m}")))
        })
        .unwrap_or_else(|| "the landmarks found are not spaced as a face's".into());
    format!("not a face: in no orientation does the mesh have a nose with a lip below it ({why})")
}

/// The landmarks and measurements of a face mesh, in its own unit and axes.
pub fn landmarks_of(mesh: &Mesh, from: FrameFrom) -> Result<FaceLandmarks, String> {
    let unit = unit_of(mesh)?;
    let k = unit.mm_per_unit;
    let mm = Mesh::new(
        mesh.vertices.iter().map(|p| scale(*p, k)).collect(),
        mesh.triangles.clone(),
    );
    let (frame, lms, how) = match from {
        FrameFrom::Shape => frame_from_shape(&mm)?,
        FrameFrom::Lps => {
            let f = head_frame(&mm).ok_or("not a face: the mesh is empty")?;
            let lms = soft(&mm, &f);
            if face_score(&mm, &VertexGrid::border(&mm), &lms, &f) < 2 {
                return Err(not_a_face(&lms));
            }
            (f, lms, "the file's superior axis (z), as a CT's".into())
        }
    };
    let mut lms = lms;
    let paired = super::lateral::with_paired(&mm, &frame, &lms);
    lms.extend(paired);
    let carried: Vec<Carried> = lms
        .iter()
        .map(|l| Carried {
            label: l.label.clone(),
            kind: l.kind,
            source: l.source,
            pre: l.position,
            post: l.position,
            change_mm: None,
            missing: l.missing.clone(),
        })
        .collect();
    let (mut measurements, _) = measure::measure(&carried, &frame);
    for (_, m) in measurements.0.iter_mut() {
        m.after = None;
        m.change = None;
    }
    let back = |p: [f64; 3]| scale(p, 1.0 / k);
    let landmarks = SOFT
        .iter()
        .chain(PAIRED.iter())
        .filter_map(|l| lms.iter().find(|x| x.label == *l).cloned())
        .map(|mut l| {
            l.position = l.position.map(back);
            l
        })
        .collect();
    Ok(FaceLandmarks {
        frame: FoundFrame {
            from: match from {
                FrameFrom::Shape => "shape",
                FrameFrom::Lps => "lps",
            },
            vertical_from: how,
            origin: back(frame.origin),
            lateral: frame.lateral,
            vertical: frame.vertical,
            anterior: frame.anterior,
            symmetry_residual_mm: frame.symmetry_residual_mm,
        },
        unit,
        landmarks,
        measurements,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(r: f64) -> Mesh {
        let (nu, nv) = (32, 16);
        let mut v = Vec::new();
        for j in 0..=nv {
            let th = std::f64::consts::PI * j as f64 / nv as f64;
            for i in 0..nu {
                let ph = 2.0 * std::f64::consts::PI * i as f64 / nu as f64;
                v.push([
                    r * th.sin() * ph.cos(),
                    r * th.sin() * ph.sin(),
                    r * th.cos(),
                ]);
            }
        }
        let mut t = Vec::new();
        for j in 0..nv {
            for i in 0..nu {
                let a = (j * nu + i) as u32;
                let b = (j * nu + (i + 1) % nu) as u32;
                let c = a + nu as u32;
                let d = b + nu as u32;
                t.push([a, c, b]);
                t.push([b, c, d]);
            }
        }
        Mesh::new(v, t)
    }

    #[test]
    fn the_unit_is_read_from_the_size() {
        let u = unit_of(&sphere(90.0)).unwrap();
        assert_eq!((u.name, u.mm_per_unit), ("mm", 1.0));
        let u = unit_of(&sphere(0.09)).unwrap();
        assert_eq!((u.name, u.mm_per_unit), ("m", 1000.0));
        let u = unit_of(&sphere(9.0)).unwrap();
        assert_eq!(u.name, "cm");
        let e = unit_of(&sphere(5000.0)).unwrap_err();
        assert!(e.contains("not a head's size"), "{e}");
    }

    #[test]
    fn a_sphere_is_not_a_face() {
        let e = landmarks_of(&sphere(90.0), FrameFrom::Shape).unwrap_err();
        assert!(e.starts_with("not a face: in no orientation"), "{e}");
        let one = Mesh::new(
            vec![[0.0; 3], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]],
            vec![[0, 1, 2]],
        );
        assert!(
            landmarks_of(&one, FrameFrom::Shape)
                .unwrap_err()
                .starts_with("not a face")
        );
    }

    #[test]
    fn the_plane_of_a_mirror_symmetric_shape_is_found() {
        // An ellipsoid squashed unevenly, with a bump off-centre in its plane x = 3: the only
        // mirror plane that keeps the bump is x = 3.
        let mut s = sphere(1.0);
        for p in &mut s.vertices {
            let bump = 25.0 * (-((p[1] + 0.6).powi(2) + (p[2] - 0.5).powi(2)) * 8.0).exp();
            *p = [3.0 + 70.0 * p[0], 95.0 * p[1] - bump, 110.0 * p[2]];
        }
        let grid = VertexGrid::new(&s.vertices, 4.0);
        let (o, n, _) = symmetry_plane(&s, &grid);
        assert!(n[0].abs() > 0.999, "{n:?}");
        assert!((o[0] - 3.0).abs() < 0.5, "{o:?}");
    }
}

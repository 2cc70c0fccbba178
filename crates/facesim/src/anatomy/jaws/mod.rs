//! The bony landmarks of the maxilla and the mandible (docs/guide/planning.md "Landmarks").
//!
//! The CT is resampled on a 1 mm grid of the clinical frame (`grid`): lateral s, up v,
//! forward a. Each detector then reads sections of that grid: the midsagittal slab for the
//! incisors, the palate and the symphysis, horizontal sections swept up and down each ramus
//! for the condyles and the angles. The upper central incisor is found first (the most
//! anterior tooth near the midline); every other search window is set from it, so that a
//! face of any size and height works.

mod grid;
#[cfg(test)]
mod tests;

use super::bone::Bone;
use crate::landmarks::{HeadFrame, Kind, Landmark, Source};
use grid::{Grid, H, OUT, TOOTH, hard};

/// Typical crown-tip-to-apex lengths of the central incisors (mm): upper 23.5, lower 21.
pub(crate) const UPPER_INCISOR_MM: f64 = 23.5;
pub(crate) const LOWER_INCISOR_MM: f64 = 21.0;

/// A landmark in frame coordinates (s, v, a), or why it is missing.
type Spot = Result<[f64; 3], String>;

/// The jaw landmarks of `super::LANDMARKS` (all but porion and orbitale), each detected or
/// missing with the reason, searched in the clinical frame `frame`.
pub(crate) fn jaw_landmarks(bone: &Bone, frame: &HeadFrame) -> Vec<Landmark> {
    let g = Grid::new(bone, frame);
    let hu = |c: [f64; 3]| bone.vol.sample(frame.point(c), -1000.0) as f64;
    let found = detect(&g, &hu);
    super::bone::LANDMARKS[4..]
        .iter()
        .map(|label| {
            let spot = found
                .iter()
                .find(|(l, _)| l == label)
                .map(|(_, s)| s.clone())
                .unwrap_or_else(|| Err("not searched".into()));
            match spot {
                Ok(c) if c.iter().all(|x| x.is_finite()) => Landmark {
                    label: (*label).into(),
                    kind: Kind::Bone,
                    position: Some(frame.point(c)),
                    source: Source::Detected,
                    missing: None,
                },
                Ok(_) => Landmark::missing(label, Kind::Bone, "no finite position".into()),
                Err(why) => Landmark::missing(label, Kind::Bone, why),
            }
        })
        .collect()
}

/// Every landmark's spot, in frame coordinates.
/// `hu` reads the CT (trilinear) at frame coordinates.
fn detect(g: &Grid, hu: &dyn Fn([f64; 3]) -> f64) -> Vec<(&'static str, Spot)> {
    let mut out: Vec<(&'static str, Spot)> = Vec::new();
    let upper = upper_incisor(g);
    let anchor = upper.anchor;
    match &upper.found {
        Ok(u) => {
            out.push(("U1", Ok(u.edge)));
            out.push(("U1-apex", Ok(u.apex)));
        }
        Err(why) => {
            out.push(("U1", Err(why.clone())));
            out.push(("U1-apex", Err(why.clone())));
        }
    }
    // The maxilla: palate, ANS, A, PNS, then the piriform rims and the pterygomaxillary
    // junctions from them.
    let maxilla = match anchor {
        Some(anc) => maxilla(g, hu, anc, upper.found.as_ref().ok()),
        None => Err(upper
            .found
            .as_ref()
            .err()
            .cloned()
            .unwrap_or_else(|| "no upper incisor".into())),
    };
    match &maxilla {
        Ok(m) => {
            out.push(("ANS", m.ans.clone()));
            out.push(("A", m.a.clone()));
            out.push(("PNS", m.pns.clone()));
        }
        Err(why) => {
            for l in ["ANS", "A", "PNS"] {
                out.push((l, Err(format!("{why}: the maxilla's midline is not found"))));
            }
        }
    }
    let side_labels = [("Pir-R", "Pir-L"), ("PTM-R", "PTM-L")];
    match &maxilla {
        Ok(m) => {
            let pir = piriform(g, hu, m);
            out.push(("Pir-R", pir[0].clone()));
            out.push(("Pir-L", pir[1].clone()));
            let ptm = pterygomaxillary(g, m);
            out.push(("PTM-R", ptm[0].clone()));
            out.push(("PTM-L", ptm[1].clone()));
        }
        Err(_) => {
            for (r, l) in side_labels {
                for x in [r, l] {
                    out.push((x, Err("the palate is not found".into())));
                }
            }
        }
    }
    // Upper first molars.
    let u6 = match (&upper.found, anchor) {
        (Ok(u), _) => upper_molars(g, (u.iv_edge, g.index(2, u.edge[2]))),
        (Err(_), Some(anc)) => upper_molars(g, anc),
        (Err(why), None) => [Err(why.clone()), Err(why.clone())],
    };
    out.push(("U6-R", u6[0].clone()));
    out.push(("U6-L", u6[1].clone()));
    // The mandible.
    let lower =
        match (&upper.found, anchor) {
            (Ok(u), _) => lower_incisor(g, u),
            (Err(_), Some(anc)) => Err(mandible_absent(g, anc)
                .unwrap_or_else(|| "the upper incisal edge is not found".into())),
            (Err(why), None) => Err(why.clone()),
        };
    let mand_labels = [
        "L1", "L1-apex", "B", "Pog", "Gn", "Me", "MF-R", "MF-L", "Go-R", "Go-L", "Co-R", "Co-L",
    ];
    match (&lower, &upper.found) {
        (Ok(l), Ok(u)) => {
            out.push(("L1", Ok(l.edge)));
            out.push(("L1-apex", Ok(l.apex)));
            let sym = symphysis(g, hu, u, l);
            match &sym {
                Ok(s) => {
                    out.push(("B", s.b.clone()));
                    out.push(("Pog", s.pog.clone()));
                    out.push(("Gn", s.gn.clone()));
                    out.push(("Me", s.me.clone()));
                }
                Err(why) => {
                    for x in ["B", "Pog", "Gn", "Me"] {
                        out.push((x, Err(why.clone())));
                    }
                }
            }
            let me = sym.as_ref().ok().and_then(|s| s.me.as_ref().ok().copied());
            let mf = mental_foramina(g, l, me);
            out.push(("MF-R", mf[0].clone()));
            out.push(("MF-L", mf[1].clone()));
            for (k, (go, co)) in [("Go-R", "Co-R"), ("Go-L", "Co-L")].into_iter().enumerate() {
                let sign = if k == 0 { -1.0 } else { 1.0 };
                let (gonion, condyle) = ramus(g, hu, u, l, me, sign);
                out.push((go, gonion));
                out.push((co, condyle));
            }
        }
        (Err(why), _) | (_, Err(why)) => {
            for x in mand_labels {
                out.push((x, Err(why.clone())));
            }
        }
    }
    out
}

/// Indices of the midsagittal plane and a slab of half-width `half` mm about it.
fn slab(g: &Grid, half: f64) -> std::ops::RangeInclusive<isize> {
    g.index(0, -half)..=g.index(0, half)
}

/// The most anterior cell index in row `iv` (a ∈ [a_lo, a_hi] indices) with a cell of the slab
/// `ss` that `keep` accepts.
fn front(
    g: &Grid,
    iv: isize,
    ss: &std::ops::RangeInclusive<isize>,
    a_lo: isize,
    a_hi: isize,
    keep: impl Fn(u8) -> bool,
) -> Option<isize> {
    (a_lo..=a_hi)
        .rev()
        .find(|&ia| ss.clone().any(|is| keep(g.at(is, iv, ia))))
}

/// Whether any cell of slab `ss` at (iv, ia) is accepted by `keep`.
fn any(
    g: &Grid,
    iv: isize,
    ia: isize,
    ss: &std::ops::RangeInclusive<isize>,
    keep: impl Fn(u8) -> bool,
) -> bool {
    ss.clone().any(|is| keep(g.at(is, iv, ia)))
}

/// The fraction of cells outside the CT in a box of indices.
fn out_fraction(g: &Grid, s: [isize; 2], v: [isize; 2], a: [isize; 2]) -> f64 {
    let (mut n, mut out) = (0usize, 0usize);
    for iv in v[0]..=v[1] {
        for ia in a[0]..=a[1] {
            for is in s[0]..=s[1] {
                n += 1;
                if g.at(is, iv, ia) == OUT {
                    out += 1;
                }
            }
        }
    }
    if n == 0 { 1.0 } else { out as f64 / n as f64 }
}

/// Frame coordinates of a (fractional) cell index.
fn coords(g: &Grid, c: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| g.coord(k, 0) + c[k] * H)
}

/// The upper central incisor: its edge (frame coordinates), the edge's row, the front of the
/// crown there, the crown's most anterior cell and the estimated apex.
struct Upper {
    edge: [f64; 3],
    apex: [f64; 3],
    /// Row of the edge, the crown's front index there.
    iv_edge: isize,
    ia_front: isize,
}

struct UpperSearch {
    /// The most anterior tooth cell near the midline (row, a index), when there is one: the
    /// maxilla's searches start from it even when the edge itself is cut off.
    anchor: Option<(isize, isize)>,
    found: Result<Upper, String>,
}

/// Teeth within this many mm of the midline count as central incisors.
const INCISOR_HALF_MM: f64 = 8.0;

/// U1: the incisal edge of the more prominent upper central incisor. The most anterior tooth
/// cell within 8 mm of the midline, below the nose, is on the upper incisor crown (the upper
/// incisors overlap the lower ones); walking down the crown's labial face from there, the
/// edge is the last row before the face ends or steps back by more than 2 mm (to the lower
/// incisor behind it). Of the two central incisors the one reaching farther forward at the
/// edge is taken (the right one when they are level); U1 is the middle of its lowest row.
///
/// U1-apex, estimated: the root apex lies 23.5 mm (a typical upper central incisor, crown tip
/// to apex) from U1 along the tooth's long axis, the line through the middles of the crown's
/// labio-lingual sections over the 8 mm above the edge (the roots cannot be told from the
/// alveolar bone reliably at CT resolution).
fn upper_incisor(g: &Grid) -> UpperSearch {
    let ss = slab(g, INCISOR_HALF_MM);
    let (v_lo, v_hi) = (g.index(1, -110.0), g.index(1, 0.0));
    let (a_lo, a_hi) = (g.index(2, -90.0), g.n[2] as isize - 1);
    let is_tooth = |c: u8| c == TOOTH;
    let fronts: Vec<(isize, Option<isize>)> = (v_lo..=v_hi)
        .map(|iv| (iv, front(g, iv, &ss, a_lo, a_hi, is_tooth)))
        .collect();
    let star = fronts
        .iter()
        .filter_map(|(iv, f)| f.map(|f| (*iv, f)))
        .max_by_key(|&(iv, f)| (f, -iv));
    let Some((iv_star, _)) = star else {
        let why = if out_fraction(
            g,
            [*ss.start(), *ss.end()],
            [g.index(1, -90.0), g.index(1, -20.0)],
            [g.index(2, -60.0), g.index(2, 0.0)],
        ) > 0.5
        {
            "the CT's field of view ends above the upper teeth"
        } else {
            "no tooth (over 1200 HU) within 8 mm of the midline below the nose"
        };
        return UpperSearch {
            anchor: None,
            found: Err(why.into()),
        };
    };
    let f_of = |iv: isize| {
        fronts
            .iter()
            .find(|(i, _)| *i == iv)
            .and_then(|(_, f)| *f)
            .or_else(|| front(g, iv, &ss, a_lo, a_hi, is_tooth))
    };
    let anchor = star;
    // Down the labial face.
    let mut iv = iv_star;
    let mut f = star.map_or(0, |s| s.1);
    loop {
        match f_of(iv - 1) {
            Some(n) if n >= f - 2 => {
                iv -= 1;
                f = n;
            }
            _ => break,
        }
    }
    // Where the CT ends just below, the edge is not seen.
    if (f - 4..=f + 1).any(|ia| ss.clone().any(|is| g.at(is, iv - 1, ia) == OUT)) {
        return UpperSearch {
            anchor,
            found: Err("the CT's field of view ends within the upper incisor crowns".into()),
        };
    }
    let Some(edge) = incisor_edge(g, &ss, iv, f - 4, f, -0.5) else {
        return UpperSearch {
            anchor,
            found: Err("the upper incisor's edge is not found".into()),
        };
    };
    // The long axis: middles of the crown's sections above the edge.
    let mids: Vec<(f64, f64)> = (iv..=iv + 8)
        .filter_map(|r| {
            let fr = front(g, r, &ss, f - 6, f + 6, is_tooth)?;
            let mut back = fr;
            while back > fr - 12 && any(g, r, back - 1, &ss, hard) {
                back -= 1;
            }
            Some((g.coord(1, r), 0.5 * (g.coord(2, fr) + g.coord(2, back))))
        })
        .collect();
    let slope = axis_slope(&mids);
    let dir = unit([0.0, 1.0, slope]);
    let apex = add(edge, scale(dir, UPPER_INCISOR_MM));
    UpperSearch {
        anchor,
        found: Ok(Upper {
            edge,
            apex,
            iv_edge: iv,
            ia_front: f,
        }),
    }
}

/// The slope da/dv of a line fitted to (v, a) points; 0 (upright) with fewer than 4 points or
/// a slope steeper than 45° (not an incisor's axis).
fn axis_slope(p: &[(f64, f64)]) -> f64 {
    if p.len() < 4 {
        return 0.0;
    }
    let n = p.len() as f64;
    let mv = p.iter().map(|x| x.0).sum::<f64>() / n;
    let ma = p.iter().map(|x| x.1).sum::<f64>() / n;
    let svv: f64 = p.iter().map(|x| (x.0 - mv).powi(2)).sum();
    let sva: f64 = p.iter().map(|x| (x.0 - mv) * (x.1 - ma)).sum();
    let b = if svv > 0.0 { sva / svv } else { 0.0 };
    if b.abs() <= 1.0 { b } else { 0.0 }
}

/// The middle of an incisal edge: tooth cells of row `iv` in slab `ss` with a index in
/// [a_lo, a_hi], on the side reaching farther forward (the right, s < 0, when level). `dv` is
/// where the edge lies from the row's centre (−½ cell below for an upper tooth, +½ above for a
/// lower one).
fn incisor_edge(
    g: &Grid,
    ss: &std::ops::RangeInclusive<isize>,
    iv: isize,
    a_lo: isize,
    a_hi: isize,
    dv: f64,
) -> Option<[f64; 3]> {
    let mid = g.index(0, 0.0);
    let cells: Vec<(isize, isize)> = ss
        .clone()
        .flat_map(|is| (a_lo..=a_hi).map(move |ia| (is, ia)))
        .filter(|&(is, ia)| g.at(is, iv, ia) == TOOTH)
        .collect();
    let reach = |right: bool| {
        cells
            .iter()
            .filter(|(is, _)| if right { *is <= mid } else { *is >= mid })
            .map(|c| c.1)
            .max()
    };
    let right = match (reach(true), reach(false)) {
        (Some(r), Some(l)) => r >= l,
        (Some(_), None) => true,
        (None, Some(_)) => false,
        (None, None) => return None,
    };
    let reach = reach(right).unwrap_or(a_hi);
    let side: Vec<&(isize, isize)> = cells
        .iter()
        .filter(|(is, ia)| (if right { *is <= mid } else { *is >= mid }) && *ia >= reach - 1)
        .collect();
    let n = side.len() as f64;
    let s = side.iter().map(|c| c.0 as f64).sum::<f64>() / n;
    let a = side.iter().map(|c| c.1 as f64).sum::<f64>() / n;
    Some(coords(g, [s, iv as f64 + dv, a]))
}

/// L1 and its apex.
struct Lower {
    edge: [f64; 3],
    apex: [f64; 3],
    /// The first row of lower tooth below the upper edge, and the crown's front there.
    iv_first: isize,
    /// The edge's row.
    iv_top: isize,
    ia_front: isize,
}

/// Why the mandible is not there, when the CT ends above it (None when it does not).
fn mandible_absent(g: &Grid, anchor: (isize, isize)) -> Option<String> {
    let ss = slab(g, 20.0);
    let frac = out_fraction(
        g,
        [*ss.start(), *ss.end()],
        [anchor.0 - 45, anchor.0 - 8],
        [anchor.1 - 30, anchor.1 + 5],
    );
    (frac > 0.3).then(|| "the CT's field of view ends above the mandible".into())
}

/// L1: the incisal edge of the more prominent lower central incisor. Below the upper edge the
/// first tooth within 15 mm behind (or 3 mm in front of) the upper crown's face is the lower
/// incisor; its crown is followed up behind the upper incisor (an overbite) while a tooth
/// section lies there apart from the upper crown, at most 8 mm above the upper edge. L1 is the
/// middle of the highest row, on the side reaching farther forward.
///
/// L1-apex, estimated: 21 mm (a typical lower central incisor, crown tip to apex) from L1 down
/// the long axis through the middles of the crown's sections over the 8 mm below its labial
/// face's first row.
fn lower_incisor(g: &Grid, u: &Upper) -> Result<Lower, String> {
    let ss = slab(g, INCISOR_HALF_MM);
    let is_tooth = |c: u8| c == TOOTH;
    let (a_lo, a_hi) = (u.ia_front - 15, u.ia_front + 3);
    let first = (u.iv_edge - 30..u.iv_edge)
        .rev()
        .find(|&iv| front(g, iv, &ss, a_lo, a_hi, is_tooth).is_some());
    let Some(iv_first) = first else {
        return Err(
            mandible_absent(g, (u.iv_edge, u.ia_front)).unwrap_or_else(|| {
                "no lower incisor within 30 mm below the upper incisal edge".into()
            }),
        );
    };
    let a_l = front(g, iv_first, &ss, a_lo, a_hi, is_tooth).unwrap_or(u.ia_front);
    // The lower crown's back bound in row iv: behind the upper crown's section when the
    // upper incisor reaches this row (one clear cell between them).
    let lower_hi = |iv: isize| -> isize {
        match front(g, iv, &ss, a_l + 3, u.ia_front + 6, is_tooth) {
            Some(fu) => {
                let mut back = fu;
                while back > a_l - 8 && any(g, iv, back - 1, &ss, is_tooth) {
                    back -= 1;
                }
                back - 2
            }
            None => a_l + 2,
        }
    };
    let has_lower = |iv: isize| {
        let hi = lower_hi(iv);
        hi >= a_l - 6 && front(g, iv, &ss, a_l - 6, hi, is_tooth).is_some()
    };
    let mut top = iv_first;
    while top < u.iv_edge + 8 && has_lower(top + 1) {
        top += 1;
    }
    let edge = incisor_edge(g, &ss, top, a_l - 6, lower_hi(top), 0.5)
        .ok_or_else(|| "the lower incisor's edge is not found".to_string())?;
    let mids: Vec<(f64, f64)> = (iv_first - 8..=iv_first)
        .filter_map(|r| {
            let fr = front(g, r, &ss, a_l - 8, a_l + 4, is_tooth)?;
            let mut back = fr;
            while back > fr - 12 && any(g, r, back - 1, &ss, hard) {
                back -= 1;
            }
            Some((g.coord(1, r), 0.5 * (g.coord(2, fr) + g.coord(2, back))))
        })
        .collect();
    let slope = axis_slope(&mids);
    let apex = add(edge, scale(unit([0.0, -1.0, -slope]), LOWER_INCISOR_MM));
    Ok(Lower {
        edge,
        apex,
        iv_first,
        iv_top: top,
        ia_front: a_l,
    })
}

/// The maxilla's midline: ANS, A, PNS and the palate they lie on.
struct Maxilla {
    ans: Spot,
    a: Spot,
    pns: Spot,
}

/// The midsagittal slab of the palate and the symphysis (mm either side).
const MIDLINE_HALF_MM: f64 = 1.0;

/// The palate is sought this far behind the upper incisor's face (mm): its middle.
const PALATE_BEHIND_MM: f64 = 25.0;

/// How far the nasal floor may rise above the mid-palate's on its way forward to ANS (mm):
/// 25 mm forward at the palatal plane's largest usual tilt to the head frame (15°), 6.7 mm.
const FLOOR_RISE_MM: f64 = 7.0;

/// The hard palate on the midline and the landmarks on it.
///
/// The palate is the first bone above the upper incisor's level 25 mm behind its face (the
/// middle of the palate). From there its section is followed backward (its middle within 2 mm
/// of the last, gaps of up to 2 mm bridged): PNS, the posterior end of the hard palate, is the
/// middle of its last section. Its upper surface (the nasal floor) is followed forward (within
/// 3 mm a column, gaps of 1 mm bridged): ANS, the tip of the anterior nasal spine, is the
/// middle of the bone in its last column, the most anterior bone at the nasal floor's level.
///
/// A: the deepest point of the concave anterior face of the maxilla between ANS and the upper
/// alveolus (10 mm above the incisal edge, about the alveolar crest), deepest measured behind
/// the line joining those two ends of the midline profile.
fn maxilla(
    g: &Grid,
    hu: &dyn Fn([f64; 3]) -> f64,
    anchor: (isize, isize),
    upper: Option<&Upper>,
) -> Result<Maxilla, String> {
    let ss = slab(g, MIDLINE_HALF_MM);
    let bone = |iv: isize, ia: isize| any(g, iv, ia, &ss, hard);
    let (iv0, ia0) = anchor;
    let ia_m = ia0 - (PALATE_BEHIND_MM / H) as isize;
    let reach = (45.0 / H) as isize;
    let Some(bottom) = (iv0 + 2..=iv0 + reach).find(|&iv| bone(iv, ia_m)) else {
        return Err("no hard palate within 45 mm above the upper incisors".into());
    };
    let mut top = bottom;
    while top < bottom + 15 && bone(top + 1, ia_m) {
        top += 1;
    }
    let thick = (top - bottom).max(1);
    // Backward: the section's middle.
    let mut mid = (bottom + top) as f64 / 2.0;
    let (mut ia_back, mut mid_back) = (ia_m, mid);
    let mut gap = 0;
    let mut ia = ia_m;
    while ia > 0 {
        ia -= 1;
        let lo = (mid - thick as f64 / 2.0 - 2.0).floor() as isize;
        let hi = (mid + thick as f64 / 2.0 + 2.0).ceil() as isize;
        let rows: Vec<isize> = (lo..=hi).filter(|&iv| bone(iv, ia)).collect();
        match (rows.first(), rows.last()) {
            (Some(&a), Some(&b)) => {
                let m = (a + b) as f64 / 2.0;
                mid = m.clamp(mid - 2.0, mid + 2.0);
                ia_back = ia;
                mid_back = mid;
                gap = 0;
            }
            _ => {
                gap += 1;
                if gap > (2.0 / H) as isize {
                    break;
                }
            }
        }
    }
    // Forward along the nasal floor. The floor runs near the palate's level (the palatal plane
    // is within about 15° of the head frame's horizontal, so ANS lies within a few millimetres
    // of the mid-palate's floor): a walk that climbs more than FLOOR_RISE_MM above it has left
    // the floor up the front of the maxilla towards the nasal bones, and ends there.
    let ceiling = top + (FLOOR_RISE_MM / H).round() as isize;
    let mut floor = top;
    let (mut ia_front, mut floor_front) = (ia_m, top);
    let mut gap = 0;
    let mut ia = ia_m;
    while ia < g.n[2] as isize - 1 {
        ia += 1;
        match (floor - 3..=floor + 3).rev().find(|&iv| bone(iv, ia)) {
            Some(t) if t > ceiling => break,
            Some(t) => {
                floor = t;
                ia_front = ia;
                floor_front = t;
                gap = 0;
            }
            None => {
                gap += 1;
                if gap > (1.0 / H) as isize {
                    break;
                }
            }
        }
    }
    let tip_rows: Vec<isize> = (floor_front - 3..=floor_front)
        .filter(|&iv| bone(iv, ia_front))
        .collect();
    let ans_v = tip_rows.iter().sum::<isize>() as f64 / tip_rows.len().max(1) as f64;
    let ans = [
        0.0,
        g.coord(1, 0) + ans_v * H,
        g.coord(2, ia_front) + 0.5 * H,
    ];
    let pns = [
        0.0,
        g.coord(1, 0) + mid_back * H,
        g.coord(2, ia_back) - 0.5 * H,
    ];
    // The alveolar crest: 10 mm above the incisal edge, or 8 mm above the lowest crown seen.
    let crest = match upper {
        Some(u) => (u.iv_edge + (10.0 / H) as isize, u.ia_front),
        None => (iv0 + (8.0 / H) as isize, ia0),
    };
    let a = a_point(g, hu, &ss, crest, ans);
    Ok(Maxilla {
        ans: Ok(ans),
        a,
        pns: Ok(pns),
    })
}

/// The CT's bone edge on the midline: HU over this is bone's cortex, not soft tissue.
const EDGE_HU: f64 = 400.0;

/// The front of the bone in row `iv` to a quarter millimetre, as a fractional a index: from
/// 2 mm in front of the cell front `ia` backward, the first point where the CT (the brightest
/// of three samples 1 mm apart across the midline) reaches `EDGE_HU`; the cell's front edge
/// where it does not within 3 mm.
fn refine_front(g: &Grid, hu: &dyn Fn([f64; 3]) -> f64, iv: isize, ia: isize) -> f64 {
    let v = g.coord(1, iv);
    let a0 = g.coord(2, ia);
    (0..=20)
        .map(|k| a0 + 2.0 - 0.25 * k as f64)
        .find(|&a| [-1.0, 0.0, 1.0].iter().any(|&s| hu([s, v, a]) >= EDGE_HU))
        .map_or(ia as f64 + 0.5, |a| (a - g.coord(2, 0)) / H)
}

/// The deepest point of a midline profile (rows and their front a index) behind the chord
/// between its ends: (row, depth mm). Of rows within 0.25 mm of the deepest, the middle one
/// that is on the profile (a flat bottom's middle).
fn deepest(prof: &[(isize, f64)]) -> Option<(isize, f64)> {
    let (&(v0, a0), &(v1, a1)) = (prof.first()?, prof.last()?);
    let span = (v1 - v0) as f64;
    let depth: Vec<(isize, f64)> = prof
        .iter()
        .map(|&(iv, a)| {
            let t = if span != 0.0 {
                (iv - v0) as f64 / span
            } else {
                0.0
            };
            (iv, a0 + t * (a1 - a0) - a)
        })
        .collect();
    let best = depth.iter().map(|x| x.1).fold(f64::NEG_INFINITY, f64::max);
    let deep: Vec<&(isize, f64)> = depth.iter().filter(|x| x.1 >= best - 0.25).collect();
    let mid = deep.iter().map(|x| x.0 as f64).sum::<f64>() / deep.len().max(1) as f64;
    deep.iter()
        .min_by(|x, y| {
            (x.0 as f64 - mid)
                .abs()
                .total_cmp(&(y.0 as f64 - mid).abs())
        })
        .map(|x| (x.0, best))
}

/// A point on the midline profile between the alveolar crest `crest` (row, the incisor's front
/// a index) and ANS.
fn a_point(
    g: &Grid,
    hu: &dyn Fn([f64; 3]) -> f64,
    ss: &std::ops::RangeInclusive<isize>,
    crest: (isize, isize),
    ans: [f64; 3],
) -> Spot {
    let lo = crest.0;
    let hi = g.index(1, ans[1]) - 1;
    if hi - lo < 3 {
        return Err("the maxilla between ANS and the incisors is too short to hold A point".into());
    }
    let a_min = crest.1 - 25;
    let prof: Vec<(isize, f64)> = (lo..=hi)
        .filter_map(|iv| {
            front(g, iv, ss, a_min, crest.1 + 5, hard).map(|f| (iv, refine_front(g, hu, iv, f)))
        })
        .collect();
    let mut chord = prof.clone();
    chord.push((g.index(1, ans[1]), g.index(2, ans[2]) as f64));
    let (iv, depth) =
        deepest(&chord).ok_or_else(|| "no anterior maxilla on the midline".to_string())?;
    if depth < 0.5 {
        return Err(
            "the maxilla's anterior face is not concave between ANS and the incisors".into(),
        );
    }
    let a = prof.iter().find(|p| p.0 == iv).map_or(f64::NAN, |p| p.1);
    Ok([0.0, g.coord(1, iv), g.coord(2, 0) + a * H])
}

/// Pir-R and Pir-L: the lowest point of the piriform aperture's lateral rim each side. Seen
/// from the front, the aperture is where no bone lies within 30 mm behind ANS's depth (the
/// nasal cavity), from ANS's level up; it is the region of such lines of sight connected to
/// the one 12 mm above ANS beside the midline, within 25 mm of it. Each side of the septum its
/// outline's lowest row holds the rim's lowest point (the middle of that row, where the
/// lateral rim runs into the aperture's floor); the point is put on the front face of the bone
/// under it (the most anterior point reaching 400 HU within 2 mm below).
fn piriform(g: &Grid, hu: &dyn Fn([f64; 3]) -> f64, m: &Maxilla) -> [Spot; 2] {
    let Ok(ans) = m.ans else {
        return [
            Err("ANS is not found".into()),
            Err("ANS is not found".into()),
        ];
    };
    let ia0 = g.index(2, ans[2]) + (5.0 / H) as isize;
    let depth = (30.0 / H) as isize;
    let (s_lo, s_hi) = (g.index(0, -25.0), g.index(0, 25.0));
    let (v_lo, v_hi) = (g.index(1, ans[1] - 5.0), g.index(1, ans[1] + 35.0));
    let w = (s_hi - s_lo + 1) as usize;
    let hgt = (v_hi - v_lo + 1) as usize;
    let key = |is: isize, iv: isize| (is - s_lo) as usize + w * (iv - v_lo) as usize;
    // A line of sight through the aperture: inside the CT all the way, no bone on it.
    let open: Vec<bool> = (0..w * hgt)
        .map(|k| {
            let (is, iv) = (s_lo + (k % w) as isize, v_lo + (k / w) as isize);
            (ia0 - depth..=ia0).all(|ia| {
                let c = g.at(is, iv, ia);
                c != OUT && !hard(c)
            })
        })
        .collect();
    let seed_v = g.index(1, ans[1] + 12.0);
    let mid = g.index(0, 0.0);
    let mut seen = vec![false; w * hgt];
    let mut stack: Vec<(isize, isize)> = (2..=8)
        .flat_map(|d| [(mid - d, seed_v), (mid + d, seed_v)])
        .filter(|&(is, iv)| open[key(is, iv)])
        .collect();
    let mut cells = Vec::new();
    while let Some((is, iv)) = stack.pop() {
        if seen[key(is, iv)] {
            continue;
        }
        seen[key(is, iv)] = true;
        cells.push((is, iv));
        for (ds, dv) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let (s2, v2) = (is + ds, iv + dv);
            if s2 >= s_lo && s2 <= s_hi && v2 >= v_lo && v2 <= v_hi && open[key(s2, v2)] {
                stack.push((s2, v2));
            }
        }
    }
    [-1.0, 1.0].map(|side: f64| {
        let on_side: Vec<&(isize, isize)> = cells
            .iter()
            .filter(|c| side * (c.0 - mid) as f64 >= 2.0)
            .collect();
        if on_side
            .iter()
            .any(|c| c.0 == s_lo || c.0 == s_hi || c.1 == v_lo)
        {
            return Err("the piriform aperture is not closed by bone around it".into());
        }
        let Some(low) = on_side.iter().map(|c| c.1).min() else {
            return Err("no piriform aperture above ANS".into());
        };
        let row: Vec<isize> = on_side.iter().filter(|c| c.1 == low).map(|c| c.0).collect();
        let is = row.iter().sum::<isize>() as f64 / row.len() as f64;
        let c = coords(g, [is, low as f64 - 0.5, ia0 as f64]);
        let steps = (depth as f64 * H / 0.25) as usize;
        // The most anterior bone within 2 mm below the rim.
        let a = (1..=4)
            .filter_map(|k| {
                let below = c[1] - 0.5 * k as f64;
                (0..=steps)
                    .map(|j| c[2] - 0.25 * j as f64)
                    .find(|&a| hu([c[0], below, a]) >= EDGE_HU)
            })
            .fold(f64::NEG_INFINITY, f64::max);
        if !a.is_finite() {
            return Err("no bone under the piriform aperture".into());
        }
        Ok([c[0], c[1], a])
    })
}

/// PTM-R and PTM-L, the pterygomaxillary junctions: not detected (the fissure between the
/// maxillary tuberosity and the pterygoid plates is not traced reliably at clinical CT
/// resolutions); missing with that reason rather than placed wrong.
fn pterygomaxillary(g: &Grid, m: &Maxilla) -> [Spot; 2] {
    let _ = (g, m);
    let why =
        || Err("not detected: the pterygomaxillary fissure is not traced from the CT".to_string());
    [why(), why()]
}

/// U6-R, U6-L: the upper first molars' mesiobuccal cusps, taken as the most occlusal point of
/// the upper dentition 25–35 mm behind U1 on each side (8–40 mm from the midline): each
/// column there is followed down from 15 mm above the incisal level through the maxilla and
/// the crown to its end, stopping 2 mm under the incisal level (the lower molars below); U6 is
/// the middle of the columns ending lowest.
///
/// `incisal` is U1's row and a index (or, where the CT ends above the incisal edge, the lowest
/// row of the incisor crown it holds).
fn upper_molars(g: &Grid, incisal: (isize, isize)) -> [Spot; 2] {
    let iv_top = incisal.0 + (15.0 / H) as isize;
    let iv_stop = incisal.0 - (2.0 / H) as isize;
    let ia_u1 = incisal.1;
    let a_range = (ia_u1 - (35.0 / H) as isize)..=(ia_u1 - (25.0 / H) as isize);
    [-1.0, 1.0].map(|side: f64| {
        let s_range = if side < 0.0 {
            g.index(0, -40.0)..=g.index(0, -8.0)
        } else {
            g.index(0, 8.0)..=g.index(0, 40.0)
        };
        let mut ends: Vec<(isize, isize, isize)> = Vec::new();
        let mut cut = false;
        for is in s_range.clone() {
            for ia in a_range.clone() {
                let Some(start) = (iv_stop..=iv_top).rev().find(|&iv| hard(g.at(is, iv, ia)))
                else {
                    continue;
                };
                let mut iv = start;
                while iv > iv_stop && hard(g.at(is, iv - 1, ia)) {
                    iv -= 1;
                }
                if (iv..=iv + 2).any(|r| g.at(is, r, ia) == TOOTH) {
                    cut |= g.at(is, iv - 1, ia) == OUT;
                    ends.push((is, iv, ia));
                }
            }
        }
        if cut {
            return Err("the CT's field of view ends within the upper molar crowns".into());
        }
        let Some(low) = ends.iter().map(|e| e.1).min() else {
            return Err("no upper molar found 25–35 mm behind the upper incisors".into());
        };
        let pick: Vec<_> = ends.iter().filter(|e| e.1 == low).collect();
        let n = pick.len() as f64;
        let s = pick.iter().map(|e| e.0 as f64).sum::<f64>() / n;
        let a = pick.iter().map(|e| e.2 as f64).sum::<f64>() / n;
        Ok(coords(g, [s, low as f64 - 0.5, a]))
    })
}

/// The symphysis' landmarks.
struct Symphysis {
    b: Spot,
    pog: Spot,
    gn: Spot,
    me: Spot,
}

/// The symphysis on the midline: the bone connected (in the midsagittal slab) to the lower
/// incisor's crown, below the upper incisal edge and no farther than 45 mm behind it.
///
/// - Me, menton: the lowest point of the symphysis (the middle of its lowest row);
/// - Pog, pogonion: its most anterior point in its lower 60 % (between menton and the lower
///   incisor);
/// - B: the deepest point of its anterior concavity between the lower incisal edge and
///   pogonion, deepest measured behind the line joining those two;
/// - Gn, gnathion: the most anterior-inferior point of the chin's outline (the point the
///   outline's tangent at 45° to the frame's vertical touches), between pogonion and menton.
fn symphysis(
    g: &Grid,
    hu: &dyn Fn([f64; 3]) -> f64,
    u: &Upper,
    l: &Lower,
) -> Result<Symphysis, String> {
    let ss = slab(g, MIDLINE_HALF_MM);
    let bone = |iv: isize, ia: isize| any(g, iv, ia, &ss, hard);
    let (v_max, a_min) = (u.iv_edge - 1, u.ia_front - (45.0 / H) as isize);
    let (nv, na) = (g.n[1] as isize, g.n[2] as isize);
    let inside = |iv: isize, ia: isize| iv >= 0 && iv <= v_max && ia >= a_min && ia < na && iv < nv;
    let mut seen = vec![false; (nv * na) as usize];
    let mut stack: Vec<(isize, isize)> = Vec::new();
    for iv in l.iv_first - 3..=l.iv_first {
        for ia in l.ia_front - 6..=l.ia_front {
            if inside(iv, ia) && bone(iv, ia) {
                stack.push((iv, ia));
            }
        }
    }
    let mut cells: Vec<(isize, isize)> = Vec::new();
    while let Some((iv, ia)) = stack.pop() {
        let k = (iv * na + ia) as usize;
        if seen[k] {
            continue;
        }
        seen[k] = true;
        cells.push((iv, ia));
        for (dv, da) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let (v2, a2) = (iv + dv, ia + da);
            if inside(v2, a2) && !seen[(v2 * na + a2) as usize] && bone(v2, a2) {
                stack.push((v2, a2));
            }
        }
    }
    let Some(iv_me) = cells.iter().map(|c| c.0).min() else {
        return Err("no bone under the lower incisor on the midline".into());
    };
    let low: Vec<isize> = cells.iter().filter(|c| c.0 == iv_me).map(|c| c.1).collect();
    let a_me = low.iter().sum::<isize>() as f64 / low.len() as f64;
    let cut = (low.iter().min().copied().unwrap_or(0)..=low.iter().max().copied().unwrap_or(0))
        .any(|ia| {
            ss.clone()
                .any(|is| g.at(is, iv_me - 1, ia) == OUT || g.at(is, iv_me - 2, ia) == OUT)
        });
    let me: Spot = if cut {
        Err("the CT's field of view ends within the chin".into())
    } else {
        Ok(coords(
            g,
            [g.index(0, 0.0) as f64, iv_me as f64 - 0.5, a_me],
        ))
    };
    // The anterior profile of the component.
    let mut prof: Vec<(isize, f64)> = Vec::new();
    for iv in iv_me..=l.iv_first {
        if let Some(f) = cells.iter().filter(|c| c.0 == iv).map(|c| c.1).max() {
            prof.push((iv, refine_front(g, hu, iv, f)));
        }
    }
    // Prominence: how far in front of the line from menton to the lower incisal edge.
    let pog_hi = iv_me + ((l.iv_first - iv_me) as f64 * 0.6).round() as isize;
    let (v_l1, a_l1) = (g.index(1, l.edge[1]) as f64, g.index(2, l.edge[2]) as f64);
    let prom = |p: &(isize, f64)| {
        let t = (p.0 as f64 - iv_me as f64) / (v_l1 - iv_me as f64).max(1.0);
        p.1 - (a_me + t * (a_l1 - a_me))
    };
    let best = prof
        .iter()
        .filter(|p| p.0 <= pog_hi)
        .map(prom)
        .fold(f64::NEG_INFINITY, f64::max);
    let plateau: Vec<isize> = prof
        .iter()
        .filter(|p| p.0 <= pog_hi && prom(p) >= best - 0.25)
        .map(|p| p.0)
        .collect();
    let pog = if plateau.is_empty() {
        Err("no chin on the midline".to_string())
    } else if cut && plateau.contains(&iv_me) {
        Err("the CT's field of view ends within the chin".to_string())
    } else {
        let iv = plateau.iter().sum::<isize>() as f64 / plateau.len() as f64;
        let row = iv.round() as isize;
        let a = prof.iter().find(|p| p.0 == row).map_or(f64::NAN, |p| p.1);
        Ok(coords(g, [g.index(0, 0.0) as f64, iv, a]))
    };
    let b = match &pog {
        Ok(p) => {
            let iv_pog = g.index(1, p[1]);
            let mut chord: Vec<(isize, f64)> = prof
                .iter()
                .filter(|q| q.0 >= iv_pog && q.0 < l.iv_first)
                .copied()
                .collect();
            chord.push((l.iv_top, g.index(2, l.edge[2]) as f64));
            match deepest(&chord) {
                Some((iv, _)) if iv > iv_pog => {
                    let a = prof.iter().find(|q| q.0 == iv).map_or(f64::NAN, |q| q.1);
                    Ok(coords(g, [g.index(0, 0.0) as f64, iv as f64, a]))
                }
                _ => Err("no concavity between the lower incisor and pogonion".into()),
            }
        }
        Err(why) => Err(why.clone()),
    };
    let gn = match (&pog, &me) {
        (Ok(p), Ok(_)) => {
            let iv_pog = g.index(1, p[1]);
            cells
                .iter()
                .filter(|c| c.0 <= iv_pog)
                .max_by_key(|c| c.1 - c.0)
                .map(|c| {
                    coords(
                        g,
                        [g.index(0, 0.0) as f64, c.0 as f64 - 0.3, c.1 as f64 + 0.3],
                    )
                })
                .ok_or_else(|| "no chin outline between pogonion and menton".into())
        }
        (Err(why), _) | (_, Err(why)) => Err(why.clone()),
    };
    Ok(Symphysis { b, pog, gn, me })
}

/// MF-R, MF-L, estimated: the mental foramen lies below the second premolar, about midway up
/// the mandibular body, on its outer face. At the CT resolutions the canal's opening is not
/// told apart, so the foramen is placed 22 mm behind the lower incisor's face (the second
/// premolar's usual place along the frame's forward axis), on the body's outer surface midway
/// between its lower border and 10 mm below the lower incisal edge (the alveolar crest).
fn mental_foramina(g: &Grid, l: &Lower, me: Option<[f64; 3]>) -> [Spot; 2] {
    let ia = l.ia_front - (22.0 / H) as isize;
    let iv_crest = l.iv_top - (10.0 / H) as isize;
    let iv_floor = me.map_or(l.iv_top - (45.0 / H) as isize, |m| g.index(1, m[1]) - 5);
    [-1.0, 1.0].map(|side: f64| {
        // Outermost bone per row, 6-45 mm from the midline.
        let outer = |iv: isize| {
            (6..=45)
                .rev()
                .map(|d| g.index(0, side * d as f64))
                .find(|&is| (ia - 1..=ia + 1).any(|a| hard(g.at(is, iv, a))))
        };
        let rows: Vec<isize> = (iv_floor..=iv_crest)
            .filter(|&iv| outer(iv).is_some())
            .collect();
        let Some(&bottom) = rows.first() else {
            return Err("no mandibular body found below the premolars".into());
        };
        let mid = (bottom + iv_crest) / 2;
        let Some(is) = outer(mid) else {
            return Err("no mandibular body found midway below the premolars".into());
        };
        Ok(coords(g, [is as f64 - side * 0.5, mid as f64, ia as f64]))
    })
}

/// The ramus of one side (`side` −1 right, +1 left): gonion and condylion.
///
/// The ramus is the largest bone section 25–75 mm from the midline, 40–120 mm behind the
/// upper incisors, at the occlusal level (midway between the incisal edges). It is swept up
/// through horizontal sections, each the bone connected to the last one's cells; where the
/// section splits (the sigmoid notch) only the posterior part, the condylar process, goes on.
/// Co, condylion: the middle of the highest section, the top of the condylar head (or of the
/// last section before it merges with the skull base through the joint, if the CT does not
/// resolve the joint space).
///
/// Go, gonion: the ramus swept down from the occlusal level to the lower border, with the
/// condylar process above; in side view (v, a) the convex outline of that bone and menton
/// gives the ramus tangent (its edge facing most backward) and the mandibular-plane tangent
/// (its edge facing most downward); gonion is the outline point farthest out along their
/// angle's bisector.
fn ramus(
    g: &Grid,
    hu: &dyn Fn([f64; 3]) -> f64,
    u: &Upper,
    l: &Lower,
    me: Option<[f64; 3]>,
    side: f64,
) -> (Spot, Spot) {
    let iv_o = (u.iv_edge + l.iv_top) / 2;
    let (s_lo, s_hi) = if side < 0.0 {
        (g.index(0, -75.0), g.index(0, -25.0))
    } else {
        (g.index(0, 25.0), g.index(0, 75.0))
    };
    let a_lo = u.ia_front - (120.0 / H) as isize;
    let a_hi = u.ia_front - (40.0 / H) as isize;
    let in_box = |is: isize, ia: isize| is >= s_lo && is <= s_hi && ia >= a_lo && ia <= a_hi;
    // 2D components of a level's bone in the box.
    let components = |iv: isize, seeds: Option<&Vec<(isize, isize)>>| -> Vec<Vec<(isize, isize)>> {
        let w = (s_hi - s_lo + 1) as usize;
        let hgt = (a_hi - a_lo + 1) as usize;
        let mut seen = vec![false; w * hgt];
        let key = |is: isize, ia: isize| (is - s_lo) as usize + w * (ia - a_lo) as usize;
        let ok = |is: isize, ia: isize| in_box(is, ia) && hard(g.at(is, iv, ia));
        let mut starts: Vec<(isize, isize)> = Vec::new();
        match seeds {
            Some(prev) => {
                for &(is, ia) in prev {
                    for ds in -1..=1 {
                        for da in -1..=1 {
                            if ok(is + ds, ia + da) {
                                starts.push((is + ds, ia + da));
                            }
                        }
                    }
                }
            }
            None => {
                for ia in a_lo..=a_hi {
                    for is in s_lo..=s_hi {
                        if ok(is, ia) {
                            starts.push((is, ia));
                        }
                    }
                }
            }
        }
        let mut comps = Vec::new();
        for st in starts {
            if seen[key(st.0, st.1)] {
                continue;
            }
            let mut comp = Vec::new();
            let mut stack = vec![st];
            seen[key(st.0, st.1)] = true;
            while let Some((is, ia)) = stack.pop() {
                comp.push((is, ia));
                for (ds, da) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    let (s2, a2) = (is + ds, ia + da);
                    if ok(s2, a2) && !seen[key(s2, a2)] {
                        seen[key(s2, a2)] = true;
                        stack.push((s2, a2));
                    }
                }
            }
            comps.push(comp);
        }
        comps
    };
    let start = components(iv_o, None).into_iter().max_by_key(|c| c.len());
    let Some(start) = start.filter(|c| c.len() as f64 * H * H >= 20.0) else {
        let why = "no mandibular ramus found at the occlusal level".to_string();
        return (Err(why.clone()), Err(why));
    };
    let mut side_cells: Vec<(isize, isize, isize)> =
        start.iter().map(|&(is, ia)| (is, iv_o, ia)).collect();
    // Up to the condyle.
    let mut prev = start.clone();
    let mut iv = iv_o;
    let top = |c: &Vec<(isize, isize)>, iv: isize| {
        let n = c.len() as f64;
        let s = c.iter().map(|x| x.0 as f64).sum::<f64>() / n;
        let a = c.iter().map(|x| x.1 as f64).sum::<f64>() / n;
        coords(g, [s, iv as f64, a])
    };
    // The level where the sweep ran into the skull base, if it did; from there on each section
    // keeps only the cells next to the last one's (the condylar head, not the fossa around it).
    let mut merged: Option<(isize, Vec<(isize, isize)>)> = None;
    let condyle: Spot = loop {
        let mut comps = components(iv + 1, Some(&prev));
        comps.retain(|c| !c.is_empty());
        let mean_a =
            |c: &Vec<(isize, isize)>| c.iter().map(|x| x.1 as f64).sum::<f64>() / c.len() as f64;
        let biggest = comps.iter().map(|c| c.len()).max().unwrap_or(0);
        let next = comps
            .into_iter()
            .filter(|c| c.len() * 10 >= biggest * 3)
            .min_by(|x, y| mean_a(x).total_cmp(&mean_a(y)));
        let iv_merged = merged.as_ref().map_or(iv, |m| m.0);
        let Some(mut c) = next else {
            break condyle_top(hu, top(&prev, iv), iv_merged, iv);
        };
        let grown = c.len() * 10 > prev.len() * 18 && (c.len() - prev.len()) as f64 * H * H > 40.0;
        if merged.is_some() || grown || c.len() as f64 * H * H > 900.0 {
            let (_, foot) = merged.get_or_insert_with(|| (iv, prev.clone()));
            let near = |&(is, ia): &(isize, isize)| {
                foot.iter()
                    .any(|&(ps, pa)| (ps - is).abs() <= 2 && (pa - ia).abs() <= 2)
            };
            c.retain(near);
            if c.is_empty() || iv >= iv_merged + (12.0 / H) as isize {
                break condyle_top(hu, top(&prev, iv), iv_merged, iv);
            }
        }
        if c.iter().any(|&(is, ia)| g.at(is, iv + 2, ia) == OUT) {
            break Err("the CT's field of view ends within the condyle".into());
        }
        iv += 1;
        if merged.is_none() {
            side_cells.extend(c.iter().map(|&(is, ia)| (is, iv, ia)));
        }
        prev = c;
        if iv > iv_o + (90.0 / H) as isize {
            break Err("the ramus does not end within 90 mm above the teeth".into());
        }
    };
    // Down to the lower border.
    let mut prev = start;
    let mut iv = iv_o;
    let iv_floor = me.map_or(iv_o - (80.0 / H) as isize, |m| g.index(1, m[1]) - 10);
    while iv > iv_floor {
        let comps = components(iv - 1, Some(&prev));
        let cells: Vec<(isize, isize)> = comps.into_iter().flatten().collect();
        if cells.is_empty() {
            break;
        }
        iv -= 1;
        side_cells.extend(cells.iter().map(|&(is, ia)| (is, iv, ia)));
        prev = cells;
    }
    let gonion = gonion(g, &side_cells, me);
    (gonion, condyle)
}

/// The top of the condylar head on the vertical through `c` (the middle of the highest section
/// swept, at row `iv_end`; `iv_merged` the row where the sweep met the skull base, or
/// `iv_end`): the CT's value (averaged over 3 × 3 mm) is lowest in the joint space (or the soft
/// tissue) above the head; the top is where, going down from that minimum, the value first
/// reaches halfway to the head's (its highest within 4 mm below the minimum).
fn condyle_top(hu: &dyn Fn([f64; 3]) -> f64, c: [f64; 3], iv_merged: isize, iv_end: isize) -> Spot {
    let step = 0.25;
    let at = |v: f64| {
        let mut sum = 0.0;
        for ds in [-1.0, 0.0, 1.0] {
            for da in [-1.0, 0.0, 1.0] {
                sum += hu([c[0] + ds, v, c[2] + da]);
            }
        }
        sum / 9.0
    };
    let v0 = c[1] - (iv_end - iv_merged) as f64 * H - 2.0;
    let n = ((c[1] + 3.0 - v0) / step).ceil().max(1.0) as usize;
    let prof: Vec<(f64, f64)> = (0..=n)
        .map(|k| v0 + k as f64 * step)
        .map(|v| (v, at(v)))
        .collect();
    let Some(k_min) = (0..prof.len()).min_by(|&x, &y| prof[x].1.total_cmp(&prof[y].1)) else {
        return Err("the condyle is not found".into());
    };
    let h_min = prof[k_min].1;
    let back = (4.0 / step) as usize;
    let h_head = prof[k_min.saturating_sub(back)..=k_min]
        .iter()
        .map(|x| x.1)
        .fold(f64::NEG_INFINITY, f64::max);
    if h_head - h_min < 150.0 {
        return Err(
            "the condylar head is not told from the skull base at this CT's resolution".into(),
        );
    }
    let half = 0.5 * (h_head + h_min);
    let top = (0..=k_min)
        .rev()
        .find(|&k| prof[k].1 >= half)
        .map_or(prof[k_min].0, |k| prof[k].0 + 0.5 * step);
    Ok([c[0], top, c[2]])
}

fn gonion(g: &Grid, cells: &[(isize, isize, isize)], me: Option<[f64; 3]>) -> Spot {
    // Side view points (a, v) in mm.
    let mut pts: Vec<[f64; 2]> = cells
        .iter()
        .map(|c| [g.coord(2, c.2), g.coord(1, c.1)])
        .collect();
    if let Some(m) = me {
        pts.push([m[2], m[1]]);
    }
    let hull = convex_hull(&mut pts);
    if hull.len() < 3 {
        return Err("the mandible's angle is not found".into());
    }
    // Outward normals of the hull's edges (counter-clockwise hull: normal = (dy, −dx)).
    let mut ramus: Option<([f64; 2], f64)> = None;
    let mut base: Option<([f64; 2], f64)> = None;
    for k in 0..hull.len() {
        let p = hull[k];
        let q = hull[(k + 1) % hull.len()];
        let d = [q[0] - p[0], q[1] - p[1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if len <= 0.0 {
            continue;
        }
        let n = [d[1] / len, -d[0] / len];
        if n[0] < -0.7 && ramus.is_none_or(|r| len * -n[0] > r.1) {
            ramus = Some((n, len * -n[0]));
        }
        if n[1] < -0.7 && base.is_none_or(|b| len * -n[1] > b.1) {
            base = Some((n, len * -n[1]));
        }
    }
    // The mandibular plane through menton (Downs): the outline's edge from menton backward.
    if let Some(m) = me
        && let Some(k) = hull.iter().position(|p| p[0] == m[2] && p[1] == m[1])
    {
        let p = hull[(k + hull.len() - 1) % hull.len()];
        let d = [m[2] - p[0], m[1] - p[1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if len > 0.0 && d[1] < 0.0 {
            base = Some(([d[1] / len, -d[0] / len], len));
        }
    }
    let (Some((nr, _)), Some((nb, _))) = (ramus, base) else {
        return Err("the ramus and the lower border do not form an angle".into());
    };
    let d = unit2([nr[0] + nb[0], nr[1] + nb[1]]);

    let dot = |c: &(isize, isize, isize)| g.coord(2, c.2) * d[0] + g.coord(1, c.1) * d[1];
    let best = cells.iter().map(dot).fold(f64::NEG_INFINITY, f64::max);
    let near: Vec<&(isize, isize, isize)> = cells.iter().filter(|c| dot(c) >= best - 1.0).collect();
    if near.is_empty() {
        return Err("the mandible's angle is not found".into());
    }
    let n = near.len() as f64;
    let mean = |k: usize| near.iter().map(|c| [c.0, c.1, c.2][k] as f64).sum::<f64>() / n;
    // Onto the outline: half a cell outward along the bisector.
    let c = coords(g, [mean(0), mean(1), mean(2)]);
    Ok([c[0], c[1] + 0.5 * d[1], c[2] + 0.5 * d[0]])
}

/// The convex hull of 2D points, counter-clockwise (Andrew's monotone chain).
fn convex_hull(p: &mut [[f64; 2]]) -> Vec<[f64; 2]> {
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for &x in p.iter() {
        while h.len() >= 2 && cross(h[h.len() - 2], h[h.len() - 1], x) <= 0.0 {
            h.pop();
        }
        h.push(x);
    }
    let lower = h.len() + 1;
    for &x in p.iter().rev().skip(1) {
        while h.len() >= lower && cross(h[h.len() - 2], h[h.len() - 1], x) <= 0.0 {
            h.pop();
        }
        h.push(x);
    }
    h.pop();
    h
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale(a: [f64; 3], k: f64) -> [f64; 3] {
    [a[0] * k, a[1] * k, a[2] * k]
}

fn unit(a: [f64; 3]) -> [f64; 3] {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if n > 0.0 {
        scale(a, 1.0 / n)
    } else {
        [0.0, 1.0, 0.0]
    }
}

fn unit2(a: [f64; 2]) -> [f64; 2] {
    let n = (a[0] * a[0] + a[1] * a[1]).sqrt();
    if n > 0.0 {
        [a[0] / n, a[1] / n]
    } else {
        [-1.0, 0.0]
    }
}

//! Landmark detection on the midsagittal profiles (docs/guide/landmarks.md "Definitions").
//!
//! The soft-tissue profile is the most anterior point of the skin's midsagittal section per
//! height (0.25 mm steps). Walking down from pronasale (its most anterior point) the profile's
//! concavities and convexities alternate; walking up, soft nasion and glabella. An extremum
//! counts when the profile rises and falls by ≥ 0.5 mm on both sides within 15 mm without a gap
//! of more than 2 mm (where the scan or the section stops there is no extremum, only an end).
//! The bony profile is the skull's section, kept within 35 mm behind the soft profile at the
//! same height (the facial bone, not the spine); its landmarks are searched in windows set by
//! the soft ones. A landmark whose definition the scan does not satisfy is missing, with the
//! reason.

use super::extremum::{Ext, GAP_MM, PROMINENCE_MM, is_extremum};
use super::frame::{HeadFrame, Profile, STEP_MM, profile, section};
use super::landmark::{Kind, Landmark, Source};
use crate::mesh::Mesh;

/// Bone farther behind the soft profile than this is not facial bone.
const BONE_DEPTH_MM: f64 = 35.0;
/// Without a skull, skin farther behind the most anterior point than this is not the face.
const FACE_DEPTH_MM: f64 = 70.0;

/// The first extremum `e` walking from `from` (exclusive) down (`down`) or up; on a flat
/// extremum, its most extreme sample.
fn walk(p: &Profile, from: usize, e: Ext, down: bool) -> Option<usize> {
    let s = e.sign();
    let n = p.a.len();
    let mut i = from;
    loop {
        if down {
            if i == 0 {
                return None;
            }
            i -= 1;
        } else {
            i += 1;
            if i >= n {
                return None;
            }
        }
        if is_extremum(p, i, e) {
            let mut best = i;
            loop {
                let next = if down {
                    best.checked_sub(1)
                } else {
                    (best + 1 < n).then_some(best + 1)
                };
                match next {
                    Some(j) if s * p.a[j] > s * p.a[best] => best = j,
                    _ => break,
                }
            }
            // A plateau: its middle.
            let mut far = best;
            loop {
                let next = if down {
                    far.checked_sub(1)
                } else {
                    (far + 1 < n).then_some(far + 1)
                };
                match next {
                    Some(j) if (p.a[j] - p.a[best]).abs() < 1e-9 => far = j,
                    _ => break,
                }
            }
            return Some((best + far) / 2);
        }
    }
}

/// The most extreme `e` sample in heights [v_lo, v_hi] that is an extremum.
fn extremum_in(p: &Profile, v_lo: f64, v_hi: f64, e: Ext) -> Option<usize> {
    let s = e.sign();
    (0..p.a.len())
        .filter(|i| (v_lo..=v_hi).contains(&p.height(*i)) && is_extremum(p, *i, e))
        .max_by(|a, b| (s * p.a[*a]).total_cmp(&(s * p.a[*b])))
}

/// The contiguous run of the profile around i (gaps ≤ GAP_MM bridged): [lo, hi].
fn run(p: &Profile, i: usize) -> (usize, usize) {
    let gap = (GAP_MM / STEP_MM) as usize;
    let mut ends = [i, i];
    for (k, dir) in [(0usize, -1i64), (1, 1)] {
        let mut j = i as i64;
        let mut hole = 0;
        loop {
            j += dir;
            if j < 0 || j as usize >= p.a.len() {
                break;
            }
            if p.a[j as usize].is_finite() {
                hole = 0;
                ends[k] = j as usize;
            } else {
                hole += 1;
                if hole > gap {
                    break;
                }
            }
        }
    }
    (ends[0], ends[1])
}

/// Soft-tissue labels in profile order (top to bottom) and bony ones.
pub const SOFT: [&str; 10] = [
    "G'", "N'", "Prn", "Sn", "Ls", "Sto", "Li", "B'", "Pog'", "Me'",
];
pub const BONE: [&str; 6] = ["N", "ANS", "A", "B", "Pog", "Me"];

/// (v, a) of a landmark, or why it is missing.
type Spot = std::result::Result<[f64; 2], String>;

struct Found {
    list: Vec<(&'static str, Kind, Spot)>,
}

impl Found {
    fn get(&self, label: &str) -> Option<[f64; 2]> {
        self.list
            .iter()
            .find(|(l, _, _)| *l == label)
            .and_then(|(_, _, r)| r.as_ref().ok().copied())
    }
    fn put(&mut self, label: &'static str, kind: Kind, r: Spot) {
        self.list.push((label, kind, r));
    }
}

/// Detect the soft-tissue landmarks of the midsagittal profile of `skin` and the bony ones on
/// `skull` (None: no skull); `lateral` adds the paired ones beside them (`super::locate`).
pub(crate) fn detect(skin: &Mesh, skull: Option<&Mesh>, frame: &HeadFrame) -> Vec<Landmark> {
    let mut f = Found { list: Vec::new() };
    let seg = section(skin, frame);
    // A face mesh alone may be a whole head: its profile is the face's, not the back of the head
    // where the frame's heights run on past the face's ends.
    let front = seg
        .iter()
        .flat_map(|s| [s[0][1], s[1][1]])
        .fold(f64::NEG_INFINITY, f64::max);
    let soft = profile(&seg, |_, a| skull.is_some() || a > front - FACE_DEPTH_MM);
    let Some(sp) = soft else {
        let why = "the skin has no midsagittal section".to_string();
        return SOFT
            .iter()
            .map(|l| Landmark::missing(l, Kind::Soft, why.clone()))
            .chain(
                BONE.iter()
                    .map(|l| Landmark::missing(l, Kind::Bone, why.clone())),
            )
            .collect();
    };
    soft_landmarks(&sp, skull.is_none(), &mut f);
    let bone_prof = skull.and_then(|m| {
        profile(&section(m, frame), |v, a| {
            let s = sp.at(v);
            s.is_finite() && a > s - BONE_DEPTH_MM
        })
    });
    match (skull, &bone_prof) {
        (Some(_), Some(bp)) => bone_landmarks(bp, &mut f),
        _ => {
            for l in ["N", "ANS", "A"] {
                f.put(
                    l,
                    Kind::Bone,
                    Err("the skull has no midsagittal section within 35 mm of the face".into()),
                );
            }
        }
    }
    if skull.is_none() {
        // A face mesh alone (a 3D photo): the soft chin by its own shape.
        soft_chin(&sp, &seg, &mut f);
        return in_order(&f, frame);
    }
    chin_landmarks(&sp, skull.zip(bone_prof.as_ref()), frame, &mut f);
    // Soft menton: the skin below bony menton (on its vertical line in the plane).
    let me_soft = match f.get("Me") {
        Some(me) => {
            let seg = section(skin, frame);
            seg.iter()
                .filter_map(|s| {
                    let (p, q) = (s[0], s[1]);
                    let (lo, hi) = (p[1].min(q[1]), p[1].max(q[1]));
                    if !(lo <= me[1] && me[1] <= hi) || hi - lo < 1e-12 {
                        return None;
                    }
                    let t = (me[1] - p[1]) / (q[1] - p[1]);
                    let v = p[0] + t * (q[0] - p[0]);
                    (v < me[0]).then_some(v)
                })
                .max_by(f64::total_cmp)
                .map(|v| [v, me[1]])
                .ok_or_else(|| {
                    // Where the skin's section stops (the scan's lower edge, or an open mesh).
                    let low = seg
                        .iter()
                        .flat_map(|s| [s[0][0], s[1][0]])
                        .fold(f64::INFINITY, f64::min);
                    format!(
                        "no skin below bony menton in the midsagittal plane (the skin's \
                         section ends {:.1} mm below menton's height)",
                        me[0] - low
                    )
                })
        }
        None => Err("defined below bony menton (Me), which is missing".into()),
    };
    f.put("Me'", Kind::Soft, me_soft);
    in_order(&f, frame)
}

/// The landmarks found, in the documented order, as LPS points.
fn in_order(f: &Found, frame: &HeadFrame) -> Vec<Landmark> {
    SOFT.iter()
        .map(|l| (*l, Kind::Soft))
        .chain(BONE.iter().map(|l| (*l, Kind::Bone)))
        .map(|(label, kind)| {
            match f
                .list
                .iter()
                .find(|(l, _, _)| *l == label)
                .map(|(_, _, r)| r.clone())
            {
                Some(Ok([v, a])) => Landmark {
                    label: label.into(),
                    kind,
                    position: Some(frame.point([0.0, v, a])),
                    source: Source::Detected,
                    missing: None,
                },
                Some(Err(why)) => Landmark::missing(label, kind, why),
                None => Landmark::missing(label, kind, "not searched".into()),
            }
        })
        .collect()
}

/// The soft chin without bone (docs/guide/landmarks.md "A face mesh alone"): B' the first concavity
/// of the profile below Li, Pog' the first convexity below B', Me' the lowest point of the
/// midsagittal section within 20 mm behind Pog' — only where the skin goes on behind it (the
/// underside of the chin), not where the scan simply ends.
fn soft_chin(sp: &Profile, seg: &[[[f64; 2]; 2]], f: &mut Found) {
    let va = |i: usize| [sp.height(i), sp.a[i]];
    let li = f.get("Li").and_then(|li| sp.index(li[0]));
    let b = li.and_then(|i| walk(sp, i, Ext::Concave, true));
    let pog = b.and_then(|i| walk(sp, i, Ext::Convex, true));
    let li_v = f.get("Li").map_or(f64::NAN, |l| l[0]);
    let end = |what: &str| {
        let lo = (0..sp.a.len()).find(|i| sp.a[*i].is_finite()).unwrap_or(0);
        format!(
            "the midsagittal skin profile has no {what} (it ends {:.0} mm below labrale inferius)",
            li_v - sp.height(lo)
        )
    };
    let missing_li = || "defined below labrale inferius (Li), which is missing".to_string();
    f.put(
        "B'",
        Kind::Soft,
        match (li, b) {
            (_, Some(i)) => Ok(va(i)),
            (Some(_), None) => Err(end("concavity below labrale inferius")),
            _ => Err(missing_li()),
        },
    );
    f.put(
        "Pog'",
        Kind::Soft,
        match (b, pog) {
            (_, Some(i)) => Ok(va(i)),
            (Some(_), None) => Err(end("convexity below soft B point")),
            _ => Err("defined below soft B point (B'), which is missing".into()),
        },
    );
    let me = match pog.map(va) {
        Some([vp, ap]) => {
            let pts = seg.iter().flat_map(|s| [s[0], s[1]]);
            let low = pts
                .clone()
                .filter(|q| q[0] < vp && q[1] <= ap + 0.5 && q[1] >= ap - 20.0)
                .min_by(|x, y| x[0].total_cmp(&y[0]));
            match low {
                Some(m)
                    if pts.clone().any(|q| {
                        q[1] < m[1] - 5.0 && q[1] > m[1] - 30.0 && (q[0] - m[0]).abs() < 12.0
                    }) =>
                {
                    Ok(m)
                }
                Some(_) => {
                    Err("the skin's midsagittal section ends at the chin (no skin under it)".into())
                }
                None => Err("no skin below soft pogonion".into()),
            }
        }
        None => Err("defined below soft pogonion (Pog'), which is missing".into()),
    };
    f.put("Me'", Kind::Soft, me);
}

fn soft_landmarks(p: &Profile, scan: bool, f: &mut Found) {
    let end_lo = (0..p.a.len()).find(|i| p.a[*i].is_finite()).unwrap_or(0);
    let end_hi = (0..p.a.len())
        .rev()
        .find(|i| p.a[*i].is_finite())
        .unwrap_or(0);
    // Without a skull (a face mesh alone, perhaps cut off at the lips) the tip must stand out
    // as a convexity: the scan's cut edge can lie in front of it.
    let Some(prn) = (0..p.a.len())
        .filter(|i| p.a[*i].is_finite() && (!scan || is_extremum(p, *i, Ext::Convex)))
        .max_by(|a, b| p.a[*a].total_cmp(&p.a[*b]))
    else {
        f.put(
            "Prn",
            Kind::Soft,
            Err("the midsagittal skin profile has no convexity to be a nose tip".into()),
        );
        return;
    };
    let va = |i: usize| [p.height(i), p.a[i]];
    let miss = |e: Ext, what: &str, down: bool| {
        let end = if down { end_lo } else { end_hi };
        format!(
            "the midsagittal skin profile has no {} {} {what} (it ends {:.0} mm {} pronasale)",
            e.word(),
            if down { "below" } else { "above" },
            (p.height(end) - p.height(prn)).abs(),
            if down { "below" } else { "above" },
        )
    };
    // Up: soft nasion (the first concavity above the nose tip), glabella (the convexity above).
    let n_soft = walk(p, prn, Ext::Concave, false);
    f.put(
        "N'",
        Kind::Soft,
        n_soft
            .map(va)
            .ok_or_else(|| miss(Ext::Concave, "pronasale", false)),
    );
    let g = n_soft.and_then(|n| walk(p, n, Ext::Convex, false));
    f.put(
        "G'",
        Kind::Soft,
        match (n_soft, g) {
            (_, Some(g)) => Ok(va(g)),
            (Some(_), None) => Err(miss(Ext::Convex, "soft nasion", false)),
            (None, None) => Err("defined above soft nasion (N'), which is missing".into()),
        },
    );
    // Down: fold under the nose, Ls, Sto, Li, B', Pog'.
    let chain = [
        ("", Ext::Concave, "pronasale"),
        ("Ls", Ext::Convex, "the fold under the nose"),
        ("Sto", Ext::Concave, "labrale superius"),
        ("Li", Ext::Convex, "stomion"),
    ];
    let mut at = Some(prn);
    let mut prev_label = "Prn";
    let mut ls = None;
    if let Some((sto, ls_flat)) = flat_upper_lip(p, prn) {
        // The first concavity under the nose is stomion: the chain goes on from it.
        ls = ls_flat.as_ref().ok().copied();
        f.put("Ls", Kind::Soft, ls_flat.map(va));
        f.put("Sto", Kind::Soft, Ok(va(sto)));
        at = Some(sto);
        prev_label = "Sto";
    }
    let chain = if f.get("Sto").is_some() {
        &chain[3..]
    } else {
        &chain[..]
    };
    // Why the unlabelled step (the fold under the nose) failed, said at the landmark after it.
    let mut unlabelled_miss = None;
    for &(label, e, after) in chain {
        let next = at.and_then(|i| walk(p, i, e, true));
        if label.is_empty() {
            if at.is_some() && next.is_none() {
                unlabelled_miss = Some(miss(e, after, true));
            }
        } else {
            f.put(
                label,
                Kind::Soft,
                match (at, next) {
                    (_, Some(i)) => Ok(va(i)),
                    (Some(_), None) => Err(miss(e, after, true)),
                    (None, None) => Err(unlabelled_miss.take().unwrap_or_else(|| {
                        format!("defined below {prev_label}, which is missing")
                    })),
                },
            );
            prev_label = label;
        }
        if label == "Ls" {
            ls = next;
        }
        at = next;
    }
    // Subnasale: between Prn and Ls, the profile point farthest behind the chord Prn–Ls (the
    // corner where the columella meets the lip).
    let subnasale = |prn: usize| {
        ls.and_then(|ls| {
            let [v1, a1] = va(prn);
            let [v2, a2] = va(ls);
            let (dv, da) = (v2 - v1, a2 - a1);
            let len = (dv * dv + da * da).sqrt().max(1e-12);
            (ls..=prn)
                .filter(|i| p.a[*i].is_finite())
                .max_by(|x, y| {
                    let d = |i: usize| {
                        let [v, a] = va(i);
                        // Signed distance behind the chord (posterior side positive).
                        ((a - a1) * dv - (v - v1) * da) / len
                    };
                    d(*x).total_cmp(&d(*y))
                })
                .map(va)
        })
    };
    // Pronasale, the most protruded point of the nose: the profile's point farthest in front of
    // the chord N'–Sn, where both are found (then Sn again, from it). The profile's most anterior
    // point, which the chain starts from, is the tip only for a head upright in its frame: VTK's
    // headsq lies pitched face-down and its dorsum runs within 2.3 mm of the frame's vertical for
    // 60 mm, so its most anterior point lay 30 mm above the tip, on the dorsum. A nose that
    // does not stand PROMINENCE_MM out of that chord keeps the most anterior point.
    let first = subnasale(prn);
    let tip = n_soft
        .zip(first)
        .and_then(|(n, s)| off_chord(p, va(n), s, Ext::Convex))
        .filter(|(_, front)| *front >= PROMINENCE_MM);
    let (prn, sn) = match tip {
        Some((tip, _)) => (tip, subnasale(tip)),
        None => (prn, first),
    };
    f.put("Prn", Kind::Soft, Ok(va(prn)));
    f.put(
        "Sn",
        Kind::Soft,
        sn.ok_or_else(|| {
            "defined between pronasale and labrale superius (Ls), which is missing".into()
        }),
    );
}

/// An upper lip with no convexity of its own (retruded, sloping back from the nose to the
/// lips' crease, as on menpo3d's scanned face): the first concavity under the nose is then
/// stomion, not a fold under the nose. It is read so when the columella–lip corner (the profile's
/// point deepest behind the chord from Prn to that concavity, ≥ CORNER_MM) lies at least
/// UPPER_LIP_MM above it: an upper lip's length (adults 19–24 mm, Farkas 1994), where a fold
/// under the nose lies within a few millimetres of the corner. Ls is then the upper lip's point
/// farthest in front of the chord from the corner to stomion. (stomion, Ls or why not), or None.
fn flat_upper_lip(p: &Profile, prn: usize) -> Option<(usize, std::result::Result<usize, String>)> {
    let va = |i: usize| [p.height(i), p.a[i]];
    let fold = walk(p, prn, Ext::Concave, true)?;
    let (corner, depth) = off_chord(p, va(prn), va(fold), Ext::Concave)?;
    if depth < CORNER_MM || p.height(corner) - p.height(fold) < UPPER_LIP_MM {
        return None;
    }
    let ls = match off_chord(p, va(corner), va(fold), Ext::Convex) {
        Some((i, front)) if front >= PROMINENCE_MM => Ok(i),
        _ => Err(format!(
            "the upper lip, between the columella's corner and stomion, has no point {PROMINENCE_MM} mm in front of their chord"
        )),
    };
    Some((fold, ls))
}

/// The columella–lip corner's least depth behind the chord Prn–stomion, and its least height
/// above stomion, for a first concavity under the nose to be read as stomion (`flat_upper_lip`).
const CORNER_MM: f64 = 2.0;
const UPPER_LIP_MM: f64 = 15.0;

fn bone_landmarks(p: &Profile, f: &mut Found) {
    let va = |i: usize| [p.height(i), p.a[i]];
    let window_miss = |what: &str, anchor: &str| {
        format!("the bony midsagittal profile has no {what} near {anchor}")
    };
    let anchor_miss = |anchor: &str| format!("searched near {anchor}, which is missing");
    // Nasion: the deepest concavity within 12 mm of soft nasion's height.
    let n = match f.get("N'") {
        Some([v, _]) => extremum_in(p, v - 12.0, v + 12.0, Ext::Concave)
            .map(va)
            .ok_or_else(|| window_miss("concavity", "soft nasion")),
        None => Err(anchor_miss("soft nasion (N')")),
    };
    f.put("N", Kind::Bone, n);
    // A point: the deepest concavity from 5 mm below Ls to 5 mm above Sn; ANS: the most
    // anterior point of A's run above A, up to 10 mm above Sn.
    let a = match (f.get("Sn"), f.get("Ls")) {
        (Some(sn), Some(ls)) => extremum_in(p, ls[0] - 5.0, sn[0] + 5.0, Ext::Concave)
            .ok_or_else(|| window_miss("concavity", "the upper lip")),
        _ => Err(anchor_miss("subnasale and labrale superius (Sn, Ls)")),
    };
    f.put("A", Kind::Bone, a.clone().map(va));
    let ans = match (&a, f.get("Sn")) {
        (Ok(ai), Some(sn)) => {
            let (_, top) = run(p, *ai);
            (*ai..=top)
                .filter(|i| p.a[*i].is_finite() && p.height(*i) <= sn[0] + 10.0)
                .max_by(|x, y| p.a[*x].total_cmp(&p.a[*y]))
                .filter(|i| *i > *ai)
                .map(va)
                .ok_or_else(|| "no bone above A point".to_string())
        }
        _ => Err("defined above A point, which is missing".into()),
    };
    f.put("ANS", Kind::Bone, ans);
}

/// (index, offset) of the profile sample strictly between heights of `top` and `bottom` (v, a;
/// top above bottom) that lies farthest in front of the chord top–bottom (`e` Convex; offset in
/// mm, perpendicular to the chord) or farthest behind it (Concave). None when no sample lies
/// between them.
fn off_chord(p: &Profile, top: [f64; 2], bottom: [f64; 2], e: Ext) -> Option<(usize, f64)> {
    let (dv, da) = (bottom[0] - top[0], bottom[1] - top[1]);
    let len = (dv * dv + da * da).sqrt().max(1e-12);
    (0..p.a.len())
        .filter(|i| {
            let v = p.height(*i);
            p.a[*i].is_finite() && v < top[0] && v > bottom[0]
        })
        .map(|i| {
            // In front of the chord (+) for a chord running down.
            let front = (da * (p.height(i) - top[0]) - dv * (p.a[i] - top[1])) / len;
            (i, e.sign() * front)
        })
        .max_by(|x, y| x.1.total_cmp(&y.1))
}

/// Below labrale inferius, the chin (docs/guide/landmarks.md "The chin"): defined by chords between
/// neighbouring landmarks, not by the frame's vertical, so that a head pitched in the scanner
/// (VTK's headsq lies some 25° face-down) keeps them. Bone: infradentale Id (the top of the
/// bony run at the lower lip, at most 5 mm above Li) and menton Me (the lowest bone of that
/// run's symphysis); pogonion Pog the bony profile's point farthest in front of the chord
/// Id–Me; B the deepest behind Id–Pog. Soft: Pog' the skin profile's point farthest in front of
/// the chord from Li to the skin at Me's height; B' the deepest behind Li–Pog'. Each must stand
/// out by PROMINENCE_MM from its chord.
fn chin_landmarks(sp: &Profile, bone: Option<(&Mesh, &Profile)>, frame: &HeadFrame, f: &mut Found) {
    let Some(li) = f.get("Li") else {
        for (l, k) in [
            ("B'", Kind::Soft),
            ("Pog'", Kind::Soft),
            ("B", Kind::Bone),
            ("Pog", Kind::Bone),
            ("Me", Kind::Bone),
        ] {
            f.put(
                l,
                k,
                Err("defined below labrale inferius (Li), which is missing".into()),
            );
        }
        return;
    };
    let bony = bone_chin(li, bone, frame);
    let (b, pog, me, id) = match bony {
        Ok(x) => (x.0, x.1, x.2, Some(x.3)),
        Err(why) => (Err(why.clone()), Err(why.clone()), Err(why), None),
    };
    let b_v = b.as_ref().ok().copied();
    f.put("B", Kind::Bone, b);
    f.put("Pog", Kind::Bone, pog);
    f.put("Me", Kind::Bone, me.clone());
    let va = |i: usize| [sp.height(i), sp.a[i]];
    // The soft chin's lower end: the skin profile at menton's height (or the lowest skin above
    // it, in labrale inferius' run).
    let (pog_s, b_s) = match me {
        Ok(me) if id.is_some() => {
            let id = id.unwrap_or(me);
            let (lo, _) = sp.index(li[0]).map_or((0, 0), |i| run(sp, i));
            let end = sp
                .index(li[0])
                .and_then(|top| {
                    (lo..top)
                        .filter(|i| sp.a[*i].is_finite() && sp.height(*i) >= me[0])
                        .min_by(|x, y| sp.height(*x).total_cmp(&sp.height(*y)))
                })
                .map(va);
            match end {
                Some(end) => {
                    // Below bony B, the soft chin's tangent parallel to the bony chord Id–Me.
                    let tangent = b_v.and_then(|b0| {
                        let (dv, da) = (me[0] - id[0], me[1] - id[1]);
                        (0..sp.a.len())
                            .filter(|i| {
                                let v = sp.height(*i);
                                sp.a[*i].is_finite() && v < b0[0] && v >= end[0]
                            })
                            .max_by(|x, y| {
                                let front = |i: usize| da * sp.height(i) - dv * sp.a[i];
                                front(*x).total_cmp(&front(*y))
                            })
                    });
                    let pog_s = match tangent.map(va) {
                        Some(pg)
                            if off_chord(sp, li, pg, Ext::Concave)
                                .is_some_and(|(_, d)| d >= PROMINENCE_MM) =>
                        {
                            Ok(pg)
                        }
                        Some(_) => Err(format!(
                            "the skin between labrale inferius and the soft chin in front of \
                             the bony chin lies less than {PROMINENCE_MM} mm behind their chord"
                        )),
                        None if b_v.is_none() => {
                            Err("searched below bony B point, which is missing".into())
                        }
                        None => Err("no skin in front of the bony chin".into()),
                    };
                    let b_s = match &pog_s {
                        Ok(pg) => match off_chord(sp, li, *pg, Ext::Concave) {
                            Some((i, d)) if d >= PROMINENCE_MM => Ok(va(i)),
                            _ => Err(format!(
                                "the skin between labrale inferius and soft pogonion lies less \
                                 than {PROMINENCE_MM} mm behind their chord"
                            )),
                        },
                        Err(_) => Err("defined between Li and Pog', which is missing".into()),
                    };
                    (pog_s, b_s)
                }
                None => {
                    let why = "the skin profile does not reach from labrale inferius down to \
                               menton's height"
                        .to_string();
                    (Err(why.clone()), Err(why))
                }
            }
        }
        _ => {
            let why = "the soft chin is bounded by bony menton (Me), which is missing".to_string();
            (Err(why.clone()), Err(why))
        }
    };
    f.put("B'", Kind::Soft, b_s);
    f.put("Pog'", Kind::Soft, pog_s);
}

type Chin = (Spot, Spot, Spot, [f64; 2]);

/// B, Pog, Me (see `chin_landmarks`), or why the bony chin is not there.
fn bone_chin(
    li: [f64; 2],
    bone: Option<(&Mesh, &Profile)>,
    frame: &HeadFrame,
) -> std::result::Result<Chin, String> {
    let Some((skull, p)) = bone else {
        return Err("the skull has no midsagittal section within 35 mm of the face".into());
    };
    let va = |i: usize| [p.height(i), p.a[i]];
    // The bony run at the lower lip: the bone sample nearest Li's height within 5 mm.
    let start = (0..p.a.len())
        .filter(|i| p.a[*i].is_finite() && (p.height(*i) - li[0]).abs() <= 5.0)
        .min_by(|x, y| {
            (p.height(*x) - li[0])
                .abs()
                .total_cmp(&(p.height(*y) - li[0]).abs())
        })
        .ok_or_else(|| {
            "the bony midsagittal profile has no bone within 5 mm of labrale inferius' height"
                .to_string()
        })?;
    let (lo, hi) = run(p, start);
    // Infradentale: the run's top, at most 5 mm above Li; the run's lowest sample, at most
    // 50 mm below Li.
    let id = (start..=hi)
        .filter(|i| p.a[*i].is_finite() && p.height(*i) <= li[0] + 5.0)
        .max_by(|x, y| p.height(*x).total_cmp(&p.height(*y)))
        .map(va)
        .unwrap_or(va(start));
    let bottom = (lo..=start)
        .filter(|i| p.a[*i].is_finite() && p.height(*i) >= li[0] - 50.0)
        .min_by(|x, y| p.height(*x).total_cmp(&p.height(*y)))
        .map(va)
        .unwrap_or(va(start));
    // Menton: the lowest point of the skull's section within 15 mm behind and 5 mm in front of
    // the run's lowest sample, and at most 15 mm below it.
    let me = section(skull, frame)
        .iter()
        .flat_map(|s| [s[0], s[1]])
        .filter(|q| {
            q[1] > bottom[1] - 15.0
                && q[1] < bottom[1] + 5.0
                && q[0] < id[0]
                && q[0] > bottom[0] - 15.0
        })
        .min_by(|x, y| x[0].total_cmp(&y[0]))
        .ok_or_else(|| "no bone below labrale inferius".to_string())?;
    if id[0] - me[0] < 5.0 {
        return Err(format!(
            "the bony chin below labrale inferius spans only {:.1} mm in height",
            id[0] - me[0]
        ));
    }
    let pog = match off_chord(p, id, me, Ext::Convex) {
        Some((i, d)) if d >= PROMINENCE_MM => Ok(va(i)),
        _ => Err(format!(
            "the bony chin stands less than {PROMINENCE_MM} mm in front of the chord from \
             infradentale to menton"
        )),
    };
    let b = match &pog {
        Ok(pg) => match off_chord(p, id, *pg, Ext::Concave) {
            Some((i, d)) if d >= PROMINENCE_MM => Ok(va(i)),
            _ => Err(format!(
                "the bone between infradentale and pogonion lies less than {PROMINENCE_MM} mm \
                 behind their chord"
            )),
        },
        Err(_) => Err("defined between infradentale and pogonion (Pog), which is missing".into()),
    };
    Ok((b, pog, Ok(me), id))
}

/// The kind of a label: the bony labels of [`BONE`], every other label soft tissue.
pub(crate) fn kind_of(label: &str) -> Kind {
    if BONE.contains(&label) {
        Kind::Bone
    } else {
        Kind::Soft
    }
}

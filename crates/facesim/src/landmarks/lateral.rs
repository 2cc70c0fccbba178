//! The paired soft-tissue landmarks beside the midline (docs/guide/landmarks.md "Alare and
//! cheilion"): alare, the most lateral point of each ala where it meets the cheek, and
//! cheilion, each corner of the mouth. Both are found on plane sections of the skin in the head
//! frame, starting from the midline landmarks (Sn, Prn; Sto), so they follow the face in any
//! scanner frame as those do.

use super::extremum::{Ext, is_extremum};
use super::frame::{HeadFrame, Profile, plane_cut as cut, profile};
use super::landmark::{Kind, Landmark, Source};
use crate::mesh::Mesh;

/// Patient's right (−lateral) and left, alare then cheilion.
pub const PAIRED: [&str; 4] = ["Al-R", "Al-L", "Ch-R", "Ch-L"];

/// Cheilion: the lips' crease is followed outwards from stomion in sections parallel to the
/// midsagittal plane every CREASE_STEP_MM, as the concavity within CREASE_DRIFT_MM (height) of
/// the last; where it stops being one, the last is the mouth's corner. A crease that ends within
/// MIN_HALF_MOUTH_MM or runs on past MAX_HALF_MOUTH_MM has no corner a mouth would have (adult
/// mouths are 45–55 mm wide, Farkas 1994; a wide smile ~70).
const CREASE_STEP_MM: f64 = 1.0;
const CREASE_DRIFT_MM: f64 = 3.0;
const MAX_HALF_MOUTH_MM: f64 = 35.0;
const MIN_HALF_MOUTH_MM: f64 = 10.0;

/// Alare: in horizontal sections from subnasale up to ALA_TOP of the way to pronasale, the
/// alar-facial groove on each side is where the skin's outline turns most from the ala's side
/// wall to the cheek (the angle between its chords over ALA_CHORD_MM either side), at least
/// MIN_GROOVE_DEG, between ALA_MIN_MM and ALA_MAX_MM from the midline; alare is the most lateral
/// of those grooves (the nose at its widest; adult alar width 31–38 mm, Farkas 1994).
const ALA_TOP: f64 = 0.7;
const ALA_CHORD_MM: f64 = 2.0;
const MIN_GROOVE_DEG: f64 = 25.0;
const ALA_MIN_MM: f64 = 5.0;
const ALA_MAX_MM: f64 = 30.0;
/// Skin more than this behind the nose tip (or stomion) is not the face's front.
const FRONT_DEPTH_MM: f64 = 45.0;
/// Alae found farther apart or nearer than these (mm) are not a nose's: adult alar width is
/// 31–38 mm (Farkas 1994), and these leave 6–7 mm either side. On VTK's headsq (3.2 mm voxels,
/// the head pitched face-down) the grooves found lay 19.7 mm apart low on the nose's base, or
/// 46.6 mm apart on the cheeks.
const ALAR_WIDTH_MM: (f64, f64) = (25.0, 45.0);

/// A paired landmark: its label and LPS position, or why it is missing.
pub(super) type Spot = (&'static str, Result<[f64; 3], String>);

/// The paired landmarks of `skin` from the midline ones (`at(label)`: a landmark's LPS position
/// when found), in PAIRED order.
pub(super) fn paired(
    skin: &Mesh,
    frame: &HeadFrame,
    at: impl Fn(&str) -> Option<[f64; 3]>,
) -> Vec<Spot> {
    let coords: Vec<[f64; 3]> = skin.vertices.iter().map(|p| frame.coords(*p)).collect();
    let at = |label: &str| at(label).map(|p| frame.coords(p));
    let mut out = Vec::with_capacity(4);
    let mut alae = [("Al-R", -1.0), ("Al-L", 1.0)].map(|(label, side)| {
        let spot = match (at("Sn"), at("Prn")) {
            (Some(sn), Some(prn)) => alare(&coords, &skin.triangles, sn, prn, side),
            _ => Err("searched between subnasale and pronasale, and one is missing".into()),
        };
        (label, spot)
    });
    if let [(_, Ok(r)), (_, Ok(l))] = &alae {
        let width = l[0] - r[0];
        let (lo, hi) = ALAR_WIDTH_MM;
        if !(lo..=hi).contains(&width) {
            let why = format!(
                "the alar grooves found lie {width:.1} mm apart, not a nose's width ({lo:.0}–{hi:.0} mm; adults 31–38 mm, Farkas 1994)"
            );
            alae = alae.map(|(label, _)| (label, Err(why.clone())));
        }
    }
    for (label, spot) in alae {
        out.push((label, spot.map(|c| frame.point(c))));
    }
    for (label, side) in [("Ch-R", -1.0), ("Ch-L", 1.0)] {
        let spot = match at("Sto") {
            Some(sto) => cheilion(&coords, &skin.triangles, sto, side),
            None => Err("traced from stomion (Sto), which is missing".into()),
        };
        out.push((label, spot.map(|c| frame.point(c))));
    }
    out
}

/// The corner of the mouth on `side` (−1 right, +1 left), traced from stomion `sto` (s, v, a).
fn cheilion(
    c: &[[f64; 3]],
    tris: &[[u32; 3]],
    sto: [f64; 3],
    side: f64,
) -> Result<[f64; 3], String> {
    let mut v = sto[1];
    let mut last: Option<[f64; 3]> = None;
    let mut s = CREASE_STEP_MM;
    while s <= MAX_HALF_MOUTH_MM {
        let seg = cut(c, tris, 0, side * s);
        let near = |p: &Profile| {
            (0..p.a.len())
                .filter(|i| {
                    (p.height(*i) - v).abs() <= CREASE_DRIFT_MM && is_extremum(p, *i, Ext::Concave)
                })
                .min_by(|x, y| {
                    (p.height(*x) - v)
                        .abs()
                        .total_cmp(&(p.height(*y) - v).abs())
                })
                .map(|i| [p.height(i), p.a[i]])
        };
        let window = 20.0;
        let found = profile(&seg, |vv, aa| {
            (vv - v).abs() <= window && aa > sto[2] - FRONT_DEPTH_MM
        })
        .and_then(|p| near(&p));
        match found {
            Some([vv, aa]) => {
                v = vv;
                last = Some([side * s, vv, aa]);
            }
            None => break,
        }
        s += CREASE_STEP_MM;
    }
    if s > MAX_HALF_MOUTH_MM {
        return Err(format!(
            "the lips' crease runs on past {MAX_HALF_MOUTH_MM} mm beside stomion without a corner"
        ));
    }
    match last {
        Some(p) if p[0].abs() >= MIN_HALF_MOUTH_MM => Ok(p),
        Some(p) => Err(format!(
            "the lips' crease ends {:.0} mm beside stomion (a mouth's corner lies at least {MIN_HALF_MOUTH_MM} mm out)",
            p[0].abs()
        )),
        None => Err("the lips' crease does not go on beside stomion".into()),
    }
}

/// Alare on `side` (−1 right, +1 left), between subnasale `sn` and pronasale `prn` (s, v, a).
fn alare(
    c: &[[f64; 3]],
    tris: &[[u32; 3]],
    sn: [f64; 3],
    prn: [f64; 3],
    side: f64,
) -> Result<[f64; 3], String> {
    let (v0, v1) = (sn[1], sn[1] + ALA_TOP * (prn[1] - sn[1]));
    if v1 - v0 < 1.0 {
        return Err("pronasale lies less than 1.5 mm above subnasale: no ala between".into());
    }
    let mut best: Option<([f64; 3], f64)> = None;
    let mut v = v0;
    while v <= v1 {
        // The outline a(u) of this side, u = side · s outwards.
        let seg: Vec<[[f64; 2]; 2]> = cut(c, tris, 1, v)
            .into_iter()
            .map(|q| q.map(|p| [side * p[0], p[1]]))
            .collect();
        if let Some(p) = profile(&seg, |u, a| u > -1.0 && a > prn[2] - FRONT_DEPTH_MM) {
            let k = (ALA_CHORD_MM / super::frame::STEP_MM).round() as usize;
            let groove = (k..p.a.len().saturating_sub(k))
                .filter(|i| (ALA_MIN_MM..=ALA_MAX_MM).contains(&p.height(*i)))
                .filter_map(|i| {
                    let (a0, a1, a2) = (p.a[i - k], p.a[i], p.a[i + k]);
                    if !(a0.is_finite() && a1.is_finite() && a2.is_finite()) {
                        return None;
                    }
                    // The outline's turn at u: towards the front (concave) is positive.
                    let turn =
                        ((a2 - a1) / ALA_CHORD_MM).atan() - ((a1 - a0) / ALA_CHORD_MM).atan();
                    Some((i, turn.to_degrees()))
                })
                .max_by(|x, y| x.1.total_cmp(&y.1));
            if let Some((i, turn)) = groove
                && turn >= MIN_GROOVE_DEG
                && best.is_none_or(|(b, _)| p.height(i) > b[0] * side)
            {
                best = Some(([side * p.height(i), v, p.a[i]], turn));
            }
        }
        v += 0.5;
    }
    best.map(|(p, _)| p).ok_or_else(|| {
        format!(
            "the nose meets the cheek without an alar groove (no turn of the skin's outline of {MIN_GROOVE_DEG}° between subnasale and pronasale)"
        )
    })
}

/// The paired landmarks (alare, cheilion) of `skin` beside the midline ones in `found`.
pub(crate) fn with_paired(skin: &Mesh, frame: &HeadFrame, found: &[Landmark]) -> Vec<Landmark> {
    let at = |label: &str| {
        found
            .iter()
            .find(|l| l.label == label)
            .and_then(|l| l.position)
    };
    paired(skin, frame, at)
        .into_iter()
        .map(|(label, spot)| match spot {
            Ok(p) => Landmark {
                label: label.into(),
                kind: Kind::Soft,
                position: Some(p),
                source: Source::Detected,
                missing: None,
            },
            Err(why) => Landmark::missing(label, Kind::Soft, why),
        })
        .collect()
}

//! The tissue an operation's approach raises off the bone (`[tet] degloved_maxilla` and
//! `[tet] degloved_chin`, docs/lab/validation-notes.md "The degloved maxilla" and "The degloved chin").
//! Until it heals that tissue rests on the bone: pushed where the bone moves into it, left behind
//! where the bone moves away. With the options, the bone nodes that lip or cheek cover over the
//! raised region slide on their bone and lift off where the bone would pull them
//! (`model::volumetric`'s one-sided rounds).
//!
//! A Le Fort I is reached through an incision in the upper vestibule, and the mucoperiosteum is
//! raised off the front and sides of the maxilla up to the piriform rim and the infraorbital
//! nerve before the bone is cut. The region, in the head frame of the pre-operative landmarks:
//! the bone that lip or cheek covers (`tet::conditions::covered_bone`), from the lips' meeting
//! line (stomion; without it, [`UPPER_VERMILION_MM`] below labrale superius) up to
//! [`ABOVE_SN_MM`] above subnasale, on the segment that carries the upper teeth and on the bone
//! left above it. It applies when a segment carries most of the upper teeth (a Le Fort I, alone or
//! in a bimaxillary move).
//!
//! A genioplasty is reached through an incision in the lower vestibule, and the periosteum is
//! raised off the symphysis down to its lower border, between the mental nerves, before the chin
//! is cut. The region: the bone that lip or cheek covers from the top of the lower teeth down,
//! within [`MENTAL_FORAMEN_MM`] of the midsagittal plane, on every segment and on the bone left in
//! place. It applies when a moved segment under the lip or cheek lies below the lower teeth and
//! B point (a chin; [`raised_chin`]). A sagittal split is reached from behind the teeth: a BSSO
//! alone raises nothing, and neither approach raises anything for a plan it is not part of.

use crate::case::{Degloved, Tet};
use crate::error::{Error, Result};
use crate::landmarks::{HeadFrame, Landmark};
use crate::tet::conditions::Covered;

/// The raised region ends this far above subnasale (mm): about the infraorbital foramen's
/// height above the nasal floor, where the dissection stops to spare the nerve.
const ABOVE_SN_MM: f64 = 20.0;
/// Without stomion, the lips' meeting line is taken this far below labrale superius (mm): the
/// upper vermilion's height (7–9 mm in adults; Farkas 1994).
const UPPER_VERMILION_MM: f64 = 8.0;
/// The chin's raised region ends this far either side of the midsagittal plane (mm): the mental
/// foramina, which the dissection spares (25.9 and 25.5 mm from the midline, right and left, on
/// 180 CBCTs; Sheikhi & Karbasi Kheir 2016, Int J Dent, doi 10.1155/2016/5821048).
const MENTAL_FORAMEN_MM: f64 = 25.0;
/// A segment carrying at most this share of the tooth nodes lip or cheek cover carries none of
/// the teeth: a CT's dental streaks put a few on a chin segment (2 of 121 on headsq).
const STREAKS: f64 = 0.1;

/// The two approaches and their options.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Approach {
    /// `[tet] degloved_maxilla`: a Le Fort I's.
    Maxilla,
    /// `[tet] degloved_chin`: a genioplasty's.
    Chin,
}

impl Approach {
    /// The case.toml key.
    pub(crate) fn option(self) -> &'static str {
        match self {
            Approach::Maxilla => "degloved_maxilla",
            Approach::Chin => "degloved_chin",
        }
    }

    /// The bone whose tissue stays attached when it steps aside (its warning).
    pub(crate) fn over(self) -> &'static str {
        match self {
            Approach::Maxilla => "anterior maxilla",
            Approach::Chin => "chin",
        }
    }

    /// What the case asks of it.
    pub(crate) fn asked(self, t: &Tet) -> Degloved {
        match self {
            Approach::Maxilla => t.degloved_maxilla,
            Approach::Chin => t.degloved_chin,
        }
    }
}

/// What an approach raises on this mesh.
pub(crate) enum Raised {
    /// The plan has no part the approach serves (for the maxilla's, no segment carries the upper
    /// teeth; for the chin's, no segment is a chin): nothing is raised, whatever the landmarks.
    Nothing,
    /// Per mesh node: whether it is bone tissue raised by the approach.
    Nodes(Vec<bool>),
    /// The approach serves the plan, but the region's limits were not found: why, as a
    /// sentence's end ("needs subnasale (Sn), which was not found").
    Unknown(String),
}

/// The raised nodes the run takes (None: nothing raised), and why `"auto"` stepped aside (None
/// when it did not). `true` makes a region it cannot find an error (what it cannot run on,
/// `case::validate` refused before); `"auto"` steps aside from both, but only on a plan the
/// approach serves: elsewhere there is nothing to raise, and nothing to warn about.
pub(crate) fn applied(
    t: &Tet,
    approach: Approach,
    raised: Raised,
) -> Result<(Option<Vec<bool>>, Option<String>)> {
    let aside = |why: &str| Ok((None, Some(why.to_string())));
    match raised {
        Raised::Nothing => Ok((None, None)),
        Raised::Unknown(why) if approach.asked(t).required() => Err(Error::config(format!(
            "[tet] {}: the raised region {why}; give it as a [[landmark]] in case.toml",
            approach.option()
        ))),
        Raised::Unknown(why) => aside(&format!("the raised region {why}")),
        Raised::Nodes(r) => match t.one_sided_unavailable() {
            Some(why) => aside(why),
            None => Ok((Some(r), None)),
        },
    }
}

/// The tooth nodes lip or cheek cover: their height in the head frame, highest first, and their
/// segment.
fn teeth(
    frame: &HeadFrame,
    nodes: &[[f64; 3]],
    covered: &[Option<Covered>],
) -> Vec<(f64, Option<usize>)> {
    let mut teeth: Vec<(f64, Option<usize>)> = nodes
        .iter()
        .zip(covered)
        .filter_map(|(p, c)| {
            c.filter(|c| c.tooth)
                .map(|c| (frame.coords(*p)[1], c.segment()))
        })
        .collect();
    teeth.sort_by(|a, b| b.0.total_cmp(&a.0));
    teeth
}

/// What a genioplasty's approach raises: nothing unless a moved segment is a chin; then the
/// bone lip or cheek cover from the top of the lower teeth down, between the mental foramina.
/// A chin: its covered bone lies mostly below the top of the lower teeth, and its bone lies
/// below B point, as a cut under the incisors' apices leaves it (without B point: it carries at
/// most [`STREAKS`] of the tooth nodes covered). A sagittal split's distal segment carries the
/// lower teeth and B point: not a chin. `bone_segment`: the segment of a node's bone (None for
/// a node not on bone or on bone left in place), asked only of a plan with a candidate chin.
pub(crate) fn raised_chin(
    (frame, lms): (Option<&HeadFrame>, &[Landmark]),
    nodes: &[[f64; 3]],
    covered: &[Option<Covered>],
    bone_segment: &dyn Fn(usize) -> Option<usize>,
) -> Raised {
    let Some(frame) = frame else {
        return Raised::Unknown("needs a head frame (the skin is empty)".into());
    };
    let teeth = teeth(frame, nodes, covered);
    // The lower teeth: the lower half of the tooth nodes by height (as for the upper teeth in
    // `raised`); their top bounds the region.
    let Some(&(top, _)) = teeth.get(teeth.len() / 2) else {
        return Raised::Nothing;
    };
    let height = |p: &[f64; 3]| frame.coords(*p)[1];
    let b_point = lms
        .iter()
        .find(|l| l.label == "B")
        .and_then(|l| l.position)
        .map(|p| height(&p));
    let mut segments: Vec<(usize, usize, usize)> = Vec::new(); // (segment, covered nodes, below top)
    for (p, c) in nodes.iter().zip(covered) {
        let Some(s) = c.and_then(|c| c.segment()) else {
            continue;
        };
        let below = usize::from(height(p) <= top);
        match segments.iter_mut().find(|(t, _, _)| *t == s) {
            Some((_, n, b)) => {
                *n += 1;
                *b += below;
            }
            None => segments.push((s, 1, below)),
        }
    }
    let bone_top = |s: usize| {
        (0..nodes.len())
            .filter(|n| bone_segment(*n) == Some(s))
            .map(|n| height(&nodes[n]))
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let carried = |s: usize| teeth.iter().filter(|t| t.1 == Some(s)).count();
    let chin = segments.iter().any(|&(s, n, below)| {
        2 * below > n
            && match b_point {
                Some(b) => bone_top(s) < b,
                None => carried(s) as f64 <= STREAKS * teeth.len() as f64,
            }
    });
    if !chin {
        return Raised::Nothing;
    }
    Raised::Nodes(
        nodes
            .iter()
            .zip(covered)
            .map(|(p, c)| {
                let [side, height, _] = frame.coords(*p);
                c.is_some() && height <= top && side.abs() <= MENTAL_FORAMEN_MM
            })
            .collect(),
    )
}

/// The segment that carries the upper teeth (a Le Fort I's), when one carries more than half
/// of them: of the tooth nodes lip or cheek cover, the upper half by height.
pub(crate) fn upper_teeth_segment(
    frame: &HeadFrame,
    nodes: &[[f64; 3]],
    covered: &[Option<Covered>],
) -> Option<usize> {
    let teeth = teeth(frame, nodes, covered);
    let upper = &teeth[..teeth.len() / 2];
    let moved = |s: usize| upper.iter().filter(|t| t.1 == Some(s)).count();
    upper
        .iter()
        .filter_map(|t| t.1)
        .find(|s| 2 * moved(*s) > upper.len())
}

/// The raised region from the pre-operative landmarks, the mesh nodes and what lip or cheek
/// covers.
pub(crate) fn raised(
    (frame, lms): (Option<&HeadFrame>, &[Landmark]),
    nodes: &[[f64; 3]],
    covered: &[Option<Covered>],
) -> Raised {
    let Some(frame) = frame else {
        return Raised::Unknown("needs a head frame (the skin is empty)".into());
    };
    let height = |label: &str| -> Option<f64> {
        lms.iter()
            .find(|l| l.label == label)
            .and_then(|l| l.position)
            .map(|p| frame.coords(p)[1])
    };
    // The upper teeth need no landmark to tell: of the tooth nodes lip or cheek cover, the
    // upper half by height, and the segment that carries most of them. Left in place (a BSSO, a
    // genioplasty), nothing is raised, and a face whose lips the landmarks miss (a scan cut
    // above them, a phantom without a lip profile) still runs. (Not the group highest on
    // average: a few dense nodes above a Le Fort cut read as tooth would outrank it.)
    if upper_teeth_segment(frame, nodes, covered).is_none() {
        return Raised::Nothing;
    }
    let Some(sn) = height("Sn") else {
        return Raised::Unknown("needs subnasale (Sn), which was not found".into());
    };
    let bottom = match (height("Sto"), height("Ls")) {
        (Some(sto), _) => sto,
        (None, Some(ls)) => ls - UPPER_VERMILION_MM,
        (None, None) => {
            return Raised::Unknown(
                "needs stomion (Sto) or labrale superius (Ls), neither of which was found".into(),
            );
        }
    };
    let top = sn + ABOVE_SN_MM;
    let in_band: Vec<bool> = nodes
        .iter()
        .zip(covered)
        .map(|(p, c)| {
            let v = frame.coords(*p)[1];
            c.is_some() && v >= bottom && v <= top
        })
        .collect();
    // The maxilla's segment: the one that carries most of the upper teeth (the covered tooth
    // nodes of the band), when it carries more than half of them. A mandibular plan's segment may
    // reach above stomion at the incisal edges, but not over the upper teeth.
    let mut teeth: Vec<(Option<usize>, usize)> = Vec::new();
    for (c, b) in covered.iter().zip(&in_band) {
        let Some(c) = c.filter(|c| *b && c.tooth) else {
            continue;
        };
        match teeth.iter_mut().find(|(s, _)| *s == c.segment()) {
            Some((_, k)) => *k += 1,
            None => teeth.push((c.segment(), 1)),
        }
    }
    let total: usize = teeth.iter().map(|(_, k)| k).sum();
    let maxilla = teeth
        .iter()
        .filter(|(s, k)| s.is_some() && 2 * k > total)
        .map(|(s, _)| *s)
        .next();
    match maxilla {
        // The raised region: the maxilla's segment and the bone above the cut it was raised
        // from, not another segment's.
        Some(m) => Raised::Nodes(
            in_band
                .iter()
                .zip(covered)
                .map(|(b, c)| *b && c.is_some_and(|c| c.segment().is_none() || c.segment() == m))
                .collect(),
        ),
        None => Raised::Nothing,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::case::{Case, Degloved};
    use std::path::Path;

    fn tet(sets: &[&str]) -> Tet {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        let over = crate::case::overrides_table(&sets).unwrap();
        Case::parse_with(
            "[ct]\npath = \"ct.nii.gz\"\n",
            Path::new("case.toml"),
            &over,
        )
        .unwrap()
        .tet
    }

    #[test]
    fn off_by_default_and_auto_steps_aside_only_where_the_upper_teeth_move() {
        let nodes = || Raised::Nodes(vec![true, false]);
        let unknown = || Raised::Unknown("needs subnasale (Sn), which was not found".into());
        // Off by default (refused by the validation protocol's rule); `raise` skips it.
        assert_eq!(tet(&[]).degloved_maxilla, Degloved::Off);
        let auto = tet(&["tet.degloved_maxilla=auto"]);
        assert_eq!(
            applied(&auto, Approach::Maxilla, nodes()).unwrap(),
            (Some(vec![true, false]), None)
        );
        assert_eq!(
            applied(&auto, Approach::Maxilla, Raised::Nothing).unwrap(),
            (None, None)
        );
        let (r, why) = applied(&auto, Approach::Maxilla, unknown()).unwrap();
        assert!(r.is_none() && why.unwrap().contains("subnasale"));
        for (set, words) in [
            ("tet.sliding=false", "sliding and release_cuts"),
            ("tet.release_cuts=false", "sliding and release_cuts"),
            ("tet.element=quadratic", "4-node element"),
        ] {
            let t = tet(&[set, "tet.degloved_maxilla=auto"]);
            let (r, why) = applied(&t, Approach::Maxilla, nodes()).unwrap();
            assert!(r.is_none(), "{set}");
            assert!(
                why.as_deref().unwrap_or_default().contains(words),
                "{set}: {why:?}"
            );
            // A mandibular plan: nothing to raise, nothing to say.
            assert_eq!(
                applied(&t, Approach::Maxilla, Raised::Nothing).unwrap(),
                (None, None),
                "{set}"
            );
        }
        // Asked for by name: served, or an error naming what is missing.
        let on = tet(&["tet.degloved_maxilla=true"]);
        assert_eq!(
            applied(&on, Approach::Maxilla, nodes()).unwrap(),
            (Some(vec![true, false]), None)
        );
        let e = applied(&on, Approach::Maxilla, unknown())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("degloved_maxilla") && e.contains("subnasale"),
            "{e}"
        );
    }

    #[test]
    fn the_chin_asked_for_by_name_names_its_own_option() {
        let auto = tet(&[]);
        assert_eq!(auto.degloved_chin, Degloved::Auto);
        let unknown = || Raised::Unknown("needs a head frame (the skin is empty)".into());
        // Asked for by the maxilla's name only: the chin's "auto" steps aside.
        let maxilla = tet(&["tet.degloved_maxilla=true"]);
        let (r, why) = applied(&maxilla, Approach::Chin, unknown()).unwrap();
        assert!(r.is_none() && why.unwrap().contains("head frame"));
        let on = tet(&["tet.degloved_chin=true"]);
        let e = applied(&on, Approach::Chin, unknown())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("[tet] degloved_chin") && e.contains("head frame"),
            "{e}"
        );
        let off = tet(&["tet.sliding=false"]);
        let (r, why) = applied(&off, Approach::Chin, Raised::Nodes(vec![true])).unwrap();
        assert!(r.is_none() && why.unwrap().contains("sliding"));
    }

    /// Heights are z, the midsagittal plane x = 0. The upper teeth at z = 10, the lower at 0,
    /// B point at −15, the anterior mandible below them.
    #[test]
    fn the_chin_is_raised_for_a_segment_below_b_point_and_the_lower_teeth() {
        use crate::landmarks::{Kind, Source};
        let frame = HeadFrame::from_plane([0.0; 3], [1.0, 0.0, 0.0], 0.0);
        let nodes = [
            [0.0, 0.0, 10.0],   // upper tooth
            [5.0, 0.0, 10.0],   // upper tooth
            [0.0, 0.0, 0.0],    // lower tooth
            [5.0, 0.0, 0.0],    // lower tooth
            [0.0, 0.0, -10.0],  // the symphysis above the cut
            [40.0, 0.0, -10.0], // the body of the mandible beyond the mental foramen
            [0.0, 0.0, -25.0],  // the chin
            [0.0, 5.0, -25.0],  // not covered: inside the chin
        ];
        let b = Landmark {
            label: "B".into(),
            kind: Kind::Bone,
            position: Some([0.0, 0.0, -15.0]),
            source: Source::Detected,
            missing: None,
        };
        let with_b = std::slice::from_ref(&b);
        // Every node here is bone; `covered` leaves the last one out.
        let segs = |mandible: Option<usize>, chin: Option<usize>| {
            [
                None, None, mandible, mandible, mandible, mandible, chin, chin,
            ]
        };
        let covered = |mandible: Option<usize>, chin: Option<usize>| {
            let s = segs(mandible, chin);
            let tooth = [true, true, true, true, false, false, false];
            let mut c: Vec<Option<Covered>> = (0..7)
                .map(|k| Some(Covered::at_rest(s[k], tooth[k])))
                .collect();
            c.push(None);
            c
        };
        let raise = |lms: &[Landmark], mandible: Option<usize>, chin: Option<usize>| {
            let s = segs(mandible, chin);
            raised_chin(
                (Some(&frame), lms),
                &nodes,
                &covered(mandible, chin),
                &|n| s[n],
            )
        };
        for lms in [with_b, &[]] {
            // A genioplasty: the lower teeth, the symphysis and the chin between the mental
            // foramina.
            let Raised::Nodes(r) = raise(lms, None, Some(0)) else {
                panic!("a genioplasty raises the chin");
            };
            assert_eq!(r, [false, false, true, true, true, false, true, false]);
            // A BSSO advance with a genioplasty: the chin still.
            assert!(matches!(raise(lms, Some(1), Some(0)), Raised::Nodes(_)));
            // A BSSO alone (the chin moves with the teeth and B point), or nothing moved.
            for (mandible, chin) in [(Some(0), Some(0)), (None, None)] {
                assert!(matches!(raise(lms, mandible, chin), Raised::Nothing));
            }
        }
        // A distal segment whose teeth the lip does not cover (an open vestibule: the lip faces
        // them across air): the tooth count cannot tell, B point does.
        let mut bare = covered(Some(0), Some(0));
        bare[2] = None;
        bare[3] = None;
        let segs_bsso = segs(Some(0), Some(0));
        assert!(matches!(
            raised_chin((Some(&frame), with_b), &nodes, &bare, &|n| segs_bsso[n]),
            Raised::Nothing
        ));
        // A segment above the lower teeth that carries none (a zygoma): nothing.
        let mut above = covered(None, None);
        above[4] = None;
        above[5] = None;
        above.push(Some(Covered::at_rest(Some(2), false)));
        let nodes_high: Vec<[f64; 3]> = nodes.iter().chain(&[[30.0, 0.0, 30.0]]).copied().collect();
        let mut segs_high = segs(None, None).to_vec();
        segs_high.push(Some(2));
        assert!(matches!(
            raised_chin((Some(&frame), with_b), &nodes_high, &above, &|n| segs_high
                [n]),
            Raised::Nothing
        ));
        assert!(matches!(
            raised_chin((None, with_b), &nodes, &covered(None, Some(0)), &|n| segs(
                None,
                Some(0)
            )[n]),
            Raised::Unknown(_)
        ));
    }
}

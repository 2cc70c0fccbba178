//! The degloved anterior maxilla (`[tet] degloved_maxilla`, docs/validation.md "The degloved
//! maxilla"). A Le Fort I is reached through an incision in the upper vestibule, and the
//! mucoperiosteum is raised off the front and sides of the maxilla up to the piriform rim and the
//! infraorbital nerve before the bone is cut. Until it heals the soft tissue there rests on the
//! bone: pushed where the bone moves into it, left behind where the bone moves away. With the
//! option, the bone nodes that lip or cheek cover over that region slide on their bone and lift
//! off where the bone would pull them (`model::volumetric`'s one-sided rounds).
//!
//! The region, in the head frame of the pre-operative landmarks: the bone that lip or cheek
//! covers (`tet::conditions::covered_bone`), from the lips' meeting line (stomion; without it,
//! [`UPPER_VERMILION_MM`] below labrale superius) up to [`ABOVE_SN_MM`] above subnasale, on the
//! segment that carries the upper teeth and on the bone left above it. It applies when a segment
//! carries most of the upper teeth (a Le Fort I, alone or in a bimaxillary move): a mandibular
//! move leaves the maxilla's tissue attached, as the operation does, and the chin's soft tissue
//! is never raised here (the sagittal split is reached from behind the teeth).

use crate::case::{Tet, TetElement};
use crate::error::{Error, Result};
use crate::landmarks::{HeadFrame, Landmark};
use crate::tet::conditions::Covered;

/// The raised region ends this far above subnasale (mm): about the infraorbital foramen's
/// height above the nasal floor, where the dissection stops to spare the nerve.
const ABOVE_SN_MM: f64 = 20.0;
/// Without stomion, the lips' meeting line is taken this far below labrale superius (mm): the
/// upper vermilion's height (7–9 mm in adults; Farkas 1994).
const UPPER_VERMILION_MM: f64 = 8.0;

/// What the Le Fort I approach raises on this mesh.
pub(crate) enum Raised {
    /// No segment carries the upper teeth (a BSSO, a genioplasty): nothing is raised, whatever
    /// the landmarks.
    Nothing,
    /// Per mesh node: whether it is bone tissue raised by the approach.
    Nodes(Vec<bool>),
    /// The upper teeth move, but the region's limits were not found: why, as a sentence's end
    /// ("needs subnasale (Sn), which was not found").
    Unknown(String),
}

/// The raised nodes the run takes (None: nothing raised), and why `"auto"` stepped aside (None
/// when it did not). `true` makes a region it cannot find an error (what it cannot run on,
/// `case::validate` refused before); `"auto"` steps aside from both, but only on a plan that moves
/// the upper teeth: a mandibular plan has nothing to raise, and nothing to warn about.
pub(crate) fn applied(t: &Tet, raised: Raised) -> Result<(Option<Vec<bool>>, Option<String>)> {
    let aside = |why: &str| Ok((None, Some(why.to_string())));
    match raised {
        Raised::Nothing => Ok((None, None)),
        Raised::Unknown(why) if t.degloved_maxilla.required() => Err(Error::config(format!(
            "[tet] degloved_maxilla: the raised region {why}; give it as a [[landmark]] in case.toml"
        ))),
        Raised::Unknown(why) => aside(&format!("the raised region {why}")),
        Raised::Nodes(_) if !(t.sliding && t.release_cuts) => {
            aside("it needs [tet] sliding and release_cuts, which are off")
        }
        Raised::Nodes(_) if t.element == TetElement::Quadratic => aside(
            "it runs on the 4-node element (the 10-node element's midpoints on the bone would stay bonded)",
        ),
        Raised::Nodes(r) => Ok((Some(r), None)),
    }
}

/// The raised region from the pre-operative landmarks, the mesh nodes and what lip or cheek
/// covers.
pub(crate) fn raised(
    (frame, lms): (Option<HeadFrame>, Vec<Landmark>),
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
    let mut teeth: Vec<(f64, Option<usize>)> = nodes
        .iter()
        .zip(covered)
        .filter_map(|(p, c)| {
            c.filter(|c| c.tooth)
                .map(|c| (frame.coords(*p)[1], c.segment()))
        })
        .collect();
    teeth.sort_by(|a, b| b.0.total_cmp(&a.0));
    let upper = &teeth[..teeth.len() / 2];
    let moved = |s: usize| upper.iter().filter(|t| t.1 == Some(s)).count();
    if !upper
        .iter()
        .any(|t| t.1.is_some_and(|s| 2 * moved(s) > upper.len()))
    {
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
    fn auto_serves_where_it_can_and_steps_aside_only_where_the_upper_teeth_move() {
        let nodes = || Raised::Nodes(vec![true, false]);
        let unknown = || Raised::Unknown("needs subnasale (Sn), which was not found".into());
        let auto = tet(&[]);
        assert_eq!(auto.degloved_maxilla, Degloved::Auto);
        assert_eq!(
            applied(&auto, nodes()).unwrap(),
            (Some(vec![true, false]), None)
        );
        assert_eq!(applied(&auto, Raised::Nothing).unwrap(), (None, None));
        let (r, why) = applied(&auto, unknown()).unwrap();
        assert!(r.is_none() && why.unwrap().contains("subnasale"));
        for (set, words) in [
            ("tet.sliding=false", "sliding and release_cuts"),
            ("tet.release_cuts=false", "sliding and release_cuts"),
            ("tet.element=quadratic", "4-node element"),
        ] {
            let t = tet(&[set]);
            let (r, why) = applied(&t, nodes()).unwrap();
            assert!(r.is_none(), "{set}");
            assert!(
                why.as_deref().unwrap_or_default().contains(words),
                "{set}: {why:?}"
            );
            // A mandibular plan: nothing to raise, nothing to say.
            assert_eq!(applied(&t, Raised::Nothing).unwrap(), (None, None), "{set}");
        }
        // Asked for by name: served, or an error naming what is missing.
        let on = tet(&["tet.degloved_maxilla=true"]);
        assert_eq!(
            applied(&on, nodes()).unwrap(),
            (Some(vec![true, false]), None)
        );
        let e = applied(&on, unknown()).unwrap_err().to_string();
        assert!(
            e.contains("degloved_maxilla") && e.contains("subnasale"),
            "{e}"
        );
    }
}

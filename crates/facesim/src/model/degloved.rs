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

use crate::error::{Error, Result};
use crate::landmarks::{HeadFrame, Landmark};
use crate::tet::conditions::Covered;

/// The raised region ends this far above subnasale (mm): about the infraorbital foramen's
/// height above the nasal floor, where the dissection stops to spare the nerve.
const ABOVE_SN_MM: f64 = 20.0;
/// Without stomion, the lips' meeting line is taken this far below labrale superius (mm): the
/// upper vermilion's height (7–9 mm in adults; Farkas 1994).
const UPPER_VERMILION_MM: f64 = 8.0;

/// Per mesh node: whether it is bone tissue raised by the Le Fort I approach. All false when no
/// segment carries the upper teeth, whatever landmarks were found. Otherwise missing landmarks are
/// an error naming them: the option asks for a region the landmarks must find.
pub(crate) fn raised(
    (frame, lms): (Option<HeadFrame>, Vec<Landmark>),
    nodes: &[[f64; 3]],
    covered: &[Option<Covered>],
) -> Result<Vec<bool>> {
    let missing = |why: String| {
        Error::config(format!(
            "[tet] degloved_maxilla: the raised region needs {why}; give it as a [[landmark]] in case.toml"
        ))
    };
    let frame = frame.ok_or_else(|| missing("a head frame (the skin is empty)".into()))?;
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
        return Ok(vec![false; nodes.len()]);
    }
    let sn = height("Sn").ok_or_else(|| missing("subnasale (Sn), which was not found".into()))?;
    let bottom = match (height("Sto"), height("Ls")) {
        (Some(sto), _) => sto,
        (None, Some(ls)) => ls - UPPER_VERMILION_MM,
        (None, None) => {
            return Err(missing(
                "stomion (Sto) or labrale superius (Ls), neither of which was found".into(),
            ));
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
    Ok(match maxilla {
        // The raised region: the maxilla's segment and the bone above the cut it was raised
        // from, not another segment's.
        Some(m) => in_band
            .iter()
            .zip(covered)
            .map(|(b, c)| *b && c.is_some_and(|c| c.segment().is_none() || c.segment() == m))
            .collect(),
        None => vec![false; nodes.len()],
    })
}

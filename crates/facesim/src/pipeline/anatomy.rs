//! The anatomy stage (docs/guide/planning.md): the clinical head frame and the bony landmarks from the
//! CT, and the `[[surgery]]` entries turned into osteotomies over the segments their cuts free.

use super::stage::{Recorder, Stage};
use crate::anatomy::surgery::{self, Planned};
use crate::anatomy::{self, Anatomy, Bone, cuts::Found};
use crate::case::Case;
use crate::error::{Error, Result};
use crate::landmarks::{HeadFrame, Landmark};
use crate::segment::Segmentation;
use crate::volume::Volume;

/// What the stage found: the anatomy and the planned surgeries (the osteotomies they add lead
/// the case's plan).
pub struct Anatomical {
    pub anatomy: Anatomy,
    pub planned: Vec<Planned>,
}

/// Whether the case asks for the anatomy: a plan in clinical terms or a `[head]` table. Such a
/// case fails when the anatomy cannot be found; any other case gets it when the CT holds it (the
/// report's clinical frame and the page's views), and a note when not.
pub fn wanted(case: &Case) -> bool {
    !case.surgery.is_empty() || case.head.is_some()
}

/// The anatomy of the head, and the case's `[[surgery]]` entries as osteotomies placed before its
/// `[[osteotomy]]` entries. `located` is the skin's midsagittal frame and soft landmarks (None:
/// the skin gave none). None (the stage skipped, with the reason): a case that did not ask for
/// the anatomy ([`wanted`]) and whose CT does not hold it.
pub fn find(
    case: &mut Case,
    ct: &Volume,
    seg: &Segmentation,
    located: Option<&(Option<HeadFrame>, Vec<Landmark>)>,
    rec: &mut Recorder,
) -> Result<Option<Anatomical>> {
    let asked = wanted(case);
    let Some((Some(midsagittal), soft)) = located else {
        if !case.surgery.is_empty() {
            return Err(Error::config(
                "case.toml: [[surgery]] needs the head's midsagittal plane, and the skin gave none (an empty or partial face)",
            ));
        }
        rec.skip(
            Stage::Anatomy,
            "the skin gave no midsagittal plane (an empty or partial face): no clinical frame",
        );
        return Ok(None);
    };
    let found = rec.time(
        Stage::Anatomy,
        "finding the head frame, bony landmarks and cuts",
        || {
            let bone = Bone {
                vol: ct,
                labels: &seg.labels,
            };
            let head = case.head.clone().unwrap_or_default();
            let anatomy = anatomy::find(&bone, midsagittal, soft, &head)
                .map_err(|e| Error::config(format!("case.toml: [head]: {e}")))?;
            let planned = surgery::plan(
                &case.surgery,
                &Found {
                    landmarks: &anatomy.landmarks,
                },
                &anatomy.frame.frame,
                &bone,
            )
            .map_err(|e| Error::config(format!("case.toml: {e}")))?;
            Ok(Anatomical { anatomy, planned })
        },
    );
    let found = match found {
        Ok(f) => f,
        Err(e) if !asked => {
            rec.skip(Stage::Anatomy, format!("no clinical frame: {e}"));
            return Ok(None);
        }
        Err(e) => return Err(e),
    };
    for note in found.planned.iter().flat_map(|p| &p.notes) {
        rec.warn(note.clone());
    }
    let mut steps: Vec<_> = found.planned.iter().map(|p| p.osteotomy.clone()).collect();
    steps.append(&mut case.osteotomy);
    case.osteotomy = steps;
    Ok(Some(found))
}

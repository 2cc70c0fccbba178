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
/// case fails when its landmarks cannot be located; any other case runs on, and the landmark stage
/// reports why.
pub fn wanted(case: &Case) -> bool {
    !case.surgery.is_empty() || case.head.is_some()
}

/// The anatomy of the head, and the case's `[[surgery]]` entries as osteotomies placed before its
/// `[[osteotomy]]` entries. Every CT case gets it (the report's clinical frame, the page's views).
/// `located` is the skin's midsagittal frame and soft landmarks (None: they could not be
/// located). None (the stage skipped, with the reason) when there is no midsagittal frame and no
/// surgery asks for one.
pub fn find(
    case: &mut Case,
    ct: &Volume,
    seg: &Segmentation,
    located: Option<&(Option<HeadFrame>, Vec<Landmark>)>,
    rec: &mut Recorder,
) -> Result<Option<Anatomical>> {
    let Some((Some(midsagittal), soft)) = located else {
        if case.surgery.is_empty() {
            rec.skip(
                Stage::Anatomy,
                "the skin gave no midsagittal plane (an empty or partial face): no clinical frame",
            );
            return Ok(None);
        }
        return Err(Error::config(
            "case.toml: [[surgery]] needs the head's midsagittal plane, and the skin gave none (an empty or partial face)",
        ));
    };
    // Err only for what the case asked: a `[head] frame` the CT cannot give, a `[[surgery]]` it
    // cannot cut.
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
    )?;
    for note in found.planned.iter().flat_map(|p| &p.notes) {
        rec.warn(note.clone());
    }
    let mut steps: Vec<_> = found.planned.iter().map(|p| p.osteotomy.clone()).collect();
    steps.append(&mut case.osteotomy);
    case.osteotomy = steps;
    Ok(Some(found))
}

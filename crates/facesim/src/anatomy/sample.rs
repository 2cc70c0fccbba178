//! The real samples as the pipeline reads them (its stages up to the face), for the detectors'
//! tests.

use crate::mesh::Mesh;
use crate::pipeline::{Recorder, face, inputs, surfaces, tissues};
use crate::volume::Volume;
use std::path::Path;

pub(crate) struct Sample {
    pub vol: Volume,
    pub labels: Vec<u8>,
    pub skin: Mesh,
    pub skull: Mesh,
}

/// data-samples/`dir` read up to the face; None, with a line saying so, when its CT has not
/// been fetched.
pub(crate) fn read(dir: &str) -> Option<Sample> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data-samples")
        .join(dir);
    let (case, _) = crate::case::Case::load(&dir).unwrap();
    if !case.ct.path.exists() {
        println!("{} is not fetched: skipped", case.ct.path.display());
        return None;
    }
    let mut rec = Recorder::new(&crate::observe::Quiet);
    let inp = inputs::read_case(case, &mut rec).unwrap();
    let seg = tissues(&inp.ct, &inp.case, &mut rec).unwrap();
    let field = seg.bone_field(&inp.ct);
    let surf = surfaces::extract(&inp.ct, &seg, &field, &inp.case, &mut rec).unwrap();
    let face = face::place(surf, None, &inp.ct, &inp.case, &mut rec).unwrap();
    Some(Sample {
        vol: inp.ct,
        labels: seg.labels,
        skin: face.skin,
        skull: face.skull,
    })
}

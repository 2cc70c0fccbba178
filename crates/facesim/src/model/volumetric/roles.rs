//! The tissue's anatomy at rest that the holds read (docs/design/pipeline.md "Volumetric soft
//! tissue"): the bone and its moves, the mucosa facing a cavity near the skull, the bone lip or
//! cheek covers (on the teeth: contact), the bone a Le Fort I's or a genioplasty's approach raises
//! (`[tet] degloved_maxilla`, `degloved_chin`; `model::degloved`), and the skin on the face. A run
//! finds them once; its re-solves reuse them (`Reuse`).

use super::mesh::Meshed;
use crate::case::{Case, Degloved};
use crate::error::Result;
use crate::mesh::Mesh;
use crate::model::degloved::{self, Approach};
use crate::pipeline::{Recorder, Scene};
use crate::tet::conditions::{Bone, Covered, Mucosa, covered_bone, mucosa, on_face};
use crate::tet::from_ct::NodeKind;
use std::path::Path;

/// The bone of the scene, moved by the case's plan; its normals where tissue slides on it at the
/// scale the mesh resolves there (`tet::bone_normal`).
pub(super) fn bone<'a>(scene: &'a Scene, case: &'a Case) -> Bone<'a> {
    Bone::new(
        &scene.face.skull,
        &scene.model.plan,
        &case.osteotomy,
        case.tet.skin_size_mm,
    )
}

/// Per solved node: its kind, the mucosa or contact it slides on, whether it is the face's skin;
/// and where the scan ends. What the holds read of the anatomy.
#[derive(Clone, Copy)]
pub(super) struct Roles<'a> {
    pub(super) kind: &'a [NodeKind],
    pub(super) mucosa: &'a [Option<Mucosa>],
    pub(super) on_face: &'a [bool],
    /// The CT's outermost voxel centres (`Volume::bounds`): where the scan ends.
    pub(super) scan: ([f64; 3], [f64; 3]),
}

/// The anatomy a run finds on its mesh.
pub(super) struct Anatomy {
    /// Per corner node: the mucosa it faces, or (bone-kind) the contact or raised bone it slides
    /// on; one list.
    pub(super) mucosa: Vec<Option<Mucosa>>,
    /// Per corner node: the bone lip or cheek covers ([`covered_bone`]).
    pub(super) covered: Vec<Option<Covered>>,
    /// Per corner node: raised by a degloving approach (rests on its bone one-sidedly).
    pub(super) raised: Vec<bool>,
    /// Per solved node: a skin node on the face (`tet::conditions::on_face`).
    pub(super) on_face: Vec<bool>,
    /// Report counts: mucosa nodes, contact (tooth) nodes.
    pub(super) mucosa_nodes: usize,
    pub(super) contact_nodes: usize,
    pub(super) deglove: Deglove,
}

/// What the degloving approaches raised, and why `"auto"` stepped aside where it did.
#[derive(Default)]
pub(super) struct Deglove {
    pub(super) nodes: usize,
    pub(super) chin_nodes: usize,
    pub(super) not_applied: Option<String>,
    pub(super) chin_not_applied: Option<String>,
}

/// Find the anatomy on the run's mesh; the warnings of a degloving approach that stepped aside.
pub(super) fn find(
    scene: &Scene,
    case: &Case,
    skin: &Mesh,
    m: &Meshed,
    bone: &Bone,
    rec: &mut Recorder,
) -> Result<Anatomy> {
    let (mesh, t) = (&m.mesh, &case.tet);
    let mucosa = mucosa(
        &mesh.nodes,
        &mesh.kind,
        bone,
        &scene.vol,
        &scene.seg.outside,
        t.mucosa_gap_mm,
    );
    // Lip and cheek on the teeth (bone-kind nodes; the mucosa above is skin-kind): one list.
    let covered = covered_bone(
        &mesh.nodes,
        &mesh.tets,
        &mesh.kind,
        bone,
        &scene.vol,
        &scene.seg,
        &|p| !crate::pipeline::model::rigid_mask(case, &[p])[0],
    );
    let (raised, deglove) = raise(scene, case, skin, m, &covered, rec)?;
    let contact: Vec<Option<Mucosa>> = covered
        .iter()
        .zip(&raised)
        .map(|(c, r)| c.filter(|c| c.tooth || *r).map(|c| c.mucosa))
        .collect();
    let contact_nodes = covered.iter().flatten().filter(|c| c.tooth).count();
    let mucosa_nodes = mucosa.iter().filter(|m| m.is_some()).count();
    let mucosa: Vec<Option<Mucosa>> = mucosa
        .into_iter()
        .zip(contact)
        .map(|(m, c)| m.or(c))
        .collect();
    let on_face = on_face(m.nodes(), &m.kind, &scene.vol, &scene.seg.outside);
    Ok(Anatomy {
        mucosa,
        covered,
        raised,
        on_face,
        mucosa_nodes,
        contact_nodes,
        deglove,
    })
}

/// With `[tet] degloved_maxilla` and `degloved_chin`, the bone a Le Fort I's or a genioplasty's
/// approach raises slides too, and (with the teeth it covers) rests on its bone one-sidedly (the
/// one-sided rounds, `rounds::OneSidedContact`). "auto" (the chin's default) steps aside where `true`
/// is refused or fails, with a warning and report.json's reason (`model::degloved::applied`).
/// Per corner node: raised; and what was raised.
fn raise(
    scene: &Scene,
    case: &Case,
    skin: &Mesh,
    m: &Meshed,
    covered: &[Option<Covered>],
    rec: &mut Recorder,
) -> Result<(Vec<bool>, Deglove)> {
    let (mesh, t) = (&m.mesh, &case.tet);
    let found = if t.degloved_maxilla == Degloved::Off && t.degloved_chin == Degloved::Off {
        (None, Vec::new())
    } else {
        match scene.landmarks_pre(skin, Path::new("case.toml")) {
            Ok(found) => found,
            // The landmark stage reports why (`commands::run`).
            Err(_) if !(t.degloved_maxilla.required() || t.degloved_chin.required()) => {
                (None, Vec::new())
            }
            Err(e) => return Err(e),
        }
    };
    // The segment of a bone node: where a segment's bone ends tells a chin (`degloved`).
    let bone_segment = |n: usize| {
        (mesh.kind[n] == NodeKind::Bone)
            .then(|| crate::tet::plan_holds::segment_at(&case.osteotomy, mesh.nodes[n]).0)
            .flatten()
    };
    let mut not_applied = [None, None];
    let mut raised: Option<Vec<bool>> = None;
    let mut deglove = Deglove::default();
    for (k, approach) in [Approach::Maxilla, Approach::Chin].into_iter().enumerate() {
        if approach.asked(t) == Degloved::Off {
            continue;
        }
        let region = match approach {
            Approach::Maxilla => {
                degloved::raised((found.0.as_ref(), &found.1), &mesh.nodes, covered)
            }
            Approach::Chin => degloved::raised_chin(
                (found.0.as_ref(), &found.1),
                &mesh.nodes,
                covered,
                &bone_segment,
            ),
        };
        let (r, why) = degloved::applied(t, approach, region)?;
        if let Some(why) = &why {
            rec.warn(format!(
                "[tet] {} = \"auto\" stepped aside: {why}; the tissue over the {} stays attached to its bone",
                approach.option(),
                approach.over()
            ));
        }
        not_applied[k] = why;
        if let Some(r) = r {
            if approach == Approach::Chin {
                deglove.chin_nodes = r.iter().filter(|b| **b).count();
            }
            raised = Some(match raised {
                Some(q) => q.iter().zip(&r).map(|(a, b)| *a || *b).collect(),
                None => r,
            });
        }
    }
    [deglove.not_applied, deglove.chin_not_applied] = not_applied;
    let raised = raised.unwrap_or_else(|| vec![false; mesh.nodes.len()]);
    deglove.nodes = raised.iter().filter(|r| **r).count();
    Ok((raised, deglove))
}

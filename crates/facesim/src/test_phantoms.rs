//! The phantom heads for the library's unit tests, from crates/facesim-validate (a
//! dev-dependency: the generators are not product code).
//!
//! A unit-test build is a second copy of this crate, so the volumes and meshes the generators
//! return (the first copy's types, which facesim-validate links) are copied field by field into
//! this copy's [`Volume`] and [`Mesh`]. Plain values ([f64; 3] landmarks) and facesim-validate's
//! own types ([`facesim_validate::phantom_jaws::Tissue`]) need no copy.

use crate::mesh::Mesh;
use crate::volume::Volume;

/// The jaws phantom's CT with the default options (1.5 mm voxels).
pub(crate) fn jaws_ct() -> Volume {
    let v =
        facesim_validate::phantom_jaws::ct(&facesim_validate::phantom::PhantomOptions::default());
    Volume {
        dims: v.dims,
        spacing: v.spacing,
        origin: v.origin,
        direction: v.direction,
        data: v.data,
    }
}

/// The jaws phantom's analytic skin sampled every `step` mm (`phantom_jaws::face_scan`): its
/// vertices and triangles.
pub(crate) fn jaws_face_scan(step: f64) -> Mesh {
    let m = facesim_validate::phantom_jaws::face_scan(step);
    Mesh {
        vertices: m.vertices,
        triangles: m.triangles,
        ..Mesh::default()
    }
}

//! Re-solves on the run's mesh with other tissue parameters (`Volumetric::resolve`, the
//! uncertainty band's full solves): the mesh, node roles, mucosa and face embedding are the
//! run's; the holds are made again by the same [`hold_tissue`], the stiffness assembled and
//! factored again.

use super::Volumetric;
use super::face::{carry_face, displaced};
use super::holds::hold_tissue;
use super::roles::{Roles, bone};
use super::rounds::torn_trace;
use super::state::{constrain, stiffness};
use crate::case::Case;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::pipeline::Scene;
use crate::tet::conditions::{Holds, materials};
use crate::tet::newton_krylov;
use crate::tet::quadratic::{Rule, Tet10Mesh};
use crate::tet::{Constrained, Hold, Loads, TetMesh};

impl Volumetric {
    /// The run's holds for `case` (its sliding state; the plan and mesh settings must be the
    /// run's), the nodes the run lifted off freed when `case` slides.
    pub(super) fn holds_for(&self, scene: &Scene, case: &Case, rest_normals: bool) -> Vec<Hold> {
        let r = &self.reuse;
        let (Holds { hold, .. }, _) = hold_tissue(
            &self.mesh,
            self.quadratic.as_ref(),
            Roles {
                kind: &r.kind,
                mucosa: &r.mucosa,
                on_face: &r.on_face,
                scan: scene.vol.bounds(),
            },
            &bone(scene, case),
            case,
            rest_normals,
        );
        r.lift_off(hold, case)
    }

    /// The face positions (per vertex of `skin`, the run's face) with other tissue
    /// parameters (`case.tet`'s moduli, Poisson ratios and sliding; the plan and mesh settings
    /// must be the run's): the stiffness is assembled and factored again, the mesh, node roles,
    /// mucosa and face embedding are the run's.
    pub fn resolve(&self, scene: &Scene, case: &Case, skin: &Mesh) -> Result<Vec<[f64; 3]>> {
        let r = &self.reuse;
        let nodes = self.nodes();
        let hold = self.holds_for(scene, case, r.linear_solve);
        let linear = TetMesh {
            nodes: self.mesh.nodes.clone(),
            tets: self.mesh.tets.clone(),
            material: torn_trace(materials(&self.mesh.tissue, &case.tet), &r.torn),
        };
        let quadratic = self
            .quadratic
            .as_ref()
            .map(|_| Tet10Mesh::from_linear(&linear, Rule::Full));
        let u = if r.linear_solve {
            let k = stiffness(quadratic.as_ref(), &linear)?;
            let c = constrain(quadratic.as_ref(), &k, &hold, r.ordering(), false)?;
            let f = Loads::none().nodal_vector(nodes.len())?;
            c.solve(&[(&hold, &f)])?.remove(0)
        } else {
            // As the run: Newton from the linear answer, preconditioned by its factor.
            let c = Constrained::ordered(&linear.assemble()?, &hold, nodes.len(), r.ordering())?;
            let f = Loads::none().nodal_vector(nodes.len())?;
            let start = c.solve(&[(&hold, &f)])?.remove(0);
            newton_krylov::solve(&linear, &c, &start, &newton_krylov::Options::default())?
                .displacements
        };
        let carried = carry_face(
            &r.embedding,
            quadratic.as_ref(),
            &self.mesh.tets,
            &u,
            &r.face_still,
        );
        Ok(displaced(skin, &carried))
    }
}

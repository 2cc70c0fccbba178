//! The plan basis (docs/design/plan-basis.md): the face's response to each segment's 12 affine
//! columns, solved on the run's factor, so that a re-plan is a sum instead of a solve.

use crate::case::Case;
use crate::error::Result;
use crate::mesh::Mesh;
use crate::plan::{PlanBasis, SegmentBasis};
use crate::tet::plan_holds::LinearHold;
use crate::tet::{Constrained, Hold};

/// What the plan basis is built from.
pub(super) struct BasisInputs<'a> {
    pub(super) factor: &'a Constrained,
    pub(super) linear_hold: &'a [LinearHold],
    pub(super) overlapping_segments: &'a [usize],
    /// The run solved the nonlinear material: the basis is its linearisation at rest.
    pub(super) nonlinear: bool,
    pub(super) skin: &'a Mesh,
    /// The run's own face displacement, to check the basis against.
    pub(super) run_face_displacement: &'a [[f64; 3]],
}

/// The plan basis's iterative solves (the 10-node element's) stop at this relative residual,
/// the run's own at `fem::pmultigrid::TOLERANCE` (1e-10): each decade costs some four
/// iterations of the basis's twelve solves per segment. It keeps the basis's faces within 1e-6
/// mm, the bound a basis that gives the run's own face back must meet (`run_plan_error_mm`
/// below): on the real CT's 10-node basis that difference was 1.3e-9 mm at 1e-10 and 8.7e-8
/// mm at 1e-8, each column within 6.3e-8 of its largest entry of the 1e-10 column. A factor
/// solves exactly either way.
const BASIS_TOLERANCE: f64 = 1e-8;

/// 12 solves per segment on the run's factor (only the held values change: segment s's bone
/// moved by E_k·[x; 1], the rest held still), each carried to the face like the run's own.
pub(super) fn plan_basis(
    b: &BasisInputs,
    case: &Case,
    carry: impl Fn(&[[f64; 3]]) -> Vec<[f64; 3]>,
) -> Result<PlanBasis> {
    use crate::plan::basis::{COLUMNS, unit};
    let ns = case.osteotomy.len();
    let n = b.linear_hold.len();
    let zero = vec![0.0; 3 * n];
    let unit_holds: Vec<Vec<Hold>> = (0..ns * COLUMNS)
        .map(|sk| {
            let mut ms = vec![[0.0; COLUMNS]; ns];
            ms[sk / COLUMNS] = unit(sk % COLUMNS);
            b.linear_hold.iter().map(|l| l.hold(&ms)).collect()
        })
        .collect();
    let cases: Vec<(&[Hold], &[f64])> = unit_holds
        .iter()
        .map(|h| (h.as_slice(), zero.as_slice()))
        .collect();
    let mut solved = b.factor.solve_to(&cases, BASIS_TOLERANCE)?.into_iter();
    let segments = case
        .osteotomy
        .iter()
        .map(|o| SegmentBasis {
            name: o.name.clone(),
            region: o.region.clone(),
            pivot: o.pivot,
            columns: solved.by_ref().take(COLUMNS).map(|u| carry(&u)).collect(),
        })
        .collect();
    let mut basis = PlanBasis {
        model: if b.nonlinear {
            "tet-neo-hookean-linearised"
        } else {
            "tet-linear"
        }
        .into(),
        exact: !b.nonlinear,
        warnings: Vec::new(),
        segments,
        face_pre: b.skin.vertices.clone(),
        triangles: b.skin.triangles.clone(),
        run_plan: case.osteotomy.clone(),
        offset: None,
        facesim_version: env!("CARGO_PKG_VERSION").into(),
        run_plan_error_mm: 0.0,
    };
    if b.nonlinear {
        basis.warnings.push(
            "linear preview: the basis is the linear model at rest, the run solved the neo-Hookean material".into(),
        );
    }
    if !b.overlapping_segments.is_empty() {
        let names: Vec<String> = b
            .overlapping_segments
            .iter()
            .map(|s| format!("'{}'", case.osteotomy[*s].name))
            .collect();
        basis.exact = false;
        basis.warnings.push(format!(
            "osteotomies {} share bone nodes (their moves compose, which is not linear): the plan basis is not exact",
            names.join(", ")
        ));
    }
    // The basis must give the run's own face back: the same linear system, summed.
    let ms = basis.matrices(&case.osteotomy)?;
    let again = basis.displacement_of(&ms);
    basis.run_plan_error_mm = again
        .iter()
        .zip(b.run_face_displacement)
        .map(|(a, r)| crate::vec3::norm(crate::vec3::sub(*a, *r)))
        .fold(0.0, f64::max);
    if basis.exact && !(basis.run_plan_error_mm <= 1e-6) {
        basis.exact = false;
        basis.warnings.push(format!(
            "the plan basis differs from the run's own face by up to {:.3e} mm (a segment moves bone into another's region): not exact",
            basis.run_plan_error_mm
        ));
    }
    Ok(basis)
}

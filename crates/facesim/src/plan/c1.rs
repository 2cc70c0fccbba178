//! The plan basis of the C1 models (docs/design/plan-basis.md, "C1 models"): their linearisation at the
//! pre-operative state. The solver (solve/linearised.rs) answers unit moves of the spring
//! attachments; here are those moves, one per segment s and entry k of M = [R − I | t′], and the
//! basis assembled from the face's answers.

use super::basis::{COLUMNS, PlanBasis, SegmentBasis, displace, unit};
use crate::case::Osteotomy;
use crate::error::Result;
use crate::mesh::Mesh;

/// The attachments' moves for the basis, column s·12 + k: segment s moved by E_k, the others
/// still. Linearised at rest, an attachment inside several segments' regions moves by the sum
/// of their moves (the first-order part of the plan's composition); those segments are listed.
pub(crate) struct AttachmentMoves {
    pub columns: Vec<Vec<[f64; 3]>>,
    pub overlapping_segments: Vec<usize>,
}

pub(crate) fn attachment_moves(
    osteotomies: &[Osteotomy],
    attachments: &[[f64; 3]],
) -> AttachmentMoves {
    let inside: Vec<Vec<bool>> = osteotomies
        .iter()
        .map(|o| attachments.iter().map(|p| o.region.contains(*p)).collect())
        .collect();
    let mut overlapping: Vec<usize> = (0..osteotomies.len())
        .filter(|&s| {
            (0..attachments.len())
                .any(|j| inside[s][j] && inside.iter().filter(|r| r[j]).count() > 1)
        })
        .collect();
    overlapping.dedup();
    let columns = (0..osteotomies.len() * COLUMNS)
        .map(|sk| {
            let e = unit(sk % COLUMNS);
            attachments
                .iter()
                .zip(&inside[sk / COLUMNS])
                .map(|(p, &i)| if i { displace(&e, *p) } else { [0.0; 3] })
                .collect()
        })
        .collect();
    AttachmentMoves {
        columns,
        overlapping_segments: overlapping,
    }
}

/// What the basis of a C1 run is made of.
pub struct C1Basis<'a> {
    /// "c1-linearised" (equilibrium) or "koch1996-linearised".
    pub model: &'a str,
    /// The face of face_pre (the fine skin when a coarse copy was solved).
    pub skin: &'a Mesh,
    /// The face displacement per column (mm per unit entry), s·12 + k, face_pre order.
    pub columns: Vec<Vec<[f64; 3]>>,
    /// The face displacement with nothing moved, when not zero (the shell embedding's rest).
    pub offset: Option<Vec<[f64; 3]>>,
    pub overlapping_segments: &'a [usize],
    /// The run's own face displacement, to measure the linearisation's error at its plan.
    pub run_face_displacement: &'a [[f64; 3]],
}

/// The basis, with its error at the run's own plan (`run_plan_error_mm`). Never exact: the
/// springs turn and stretch, so a plan's face differs from the linear preview by O(move²).
pub fn basis(b: C1Basis, osteotomies: &[Osteotomy]) -> Result<PlanBasis> {
    let mut columns = b.columns.into_iter();
    let segments = osteotomies
        .iter()
        .map(|o| SegmentBasis {
            name: o.name.clone(),
            region: o.region.clone(),
            pivot: o.pivot,
            columns: columns.by_ref().take(COLUMNS).collect(),
        })
        .collect();
    let mut basis = PlanBasis {
        model: b.model.into(),
        exact: false,
        warnings: Vec::new(),
        segments,
        face_pre: b.skin.vertices.clone(),
        triangles: b.skin.triangles.clone(),
        run_plan: osteotomies.to_vec(),
        offset: b.offset,
        facesim_version: env!("CARGO_PKG_VERSION").into(),
        run_plan_error_mm: 0.0,
    };
    let again = basis.displacement_of(&basis.matrices(osteotomies)?);
    basis.run_plan_error_mm = again
        .iter()
        .zip(b.run_face_displacement)
        .map(|(a, r)| crate::vec3::norm(crate::vec3::sub(*a, *r)))
        .fold(0.0, f64::max);
    basis.warnings.push(format!(
        "linear preview: the plan basis is the {} model linearised at the pre-operative state (its springs are nonlinear); at the run's own plan it is {:.3} mm from the solved face, and the error grows with the square of the move (docs/design/plan-basis.md)",
        if b.model.starts_with("koch") { "koch1996" } else { "C1 equilibrium" },
        basis.run_plan_error_mm
    ));
    if !b.overlapping_segments.is_empty() {
        let names: Vec<String> = b
            .overlapping_segments
            .iter()
            .map(|s| format!("'{}'", osteotomies[*s].name))
            .collect();
        basis.warnings.push(format!(
            "osteotomies {} share spring attachments (their moves compose; the basis sums them)",
            names.join(", ")
        ));
    }
    Ok(basis)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::case::Region;

    #[test]
    fn unit_moves_follow_the_segment_regions() {
        let seg = |name: &str, x0: f64, x1: f64| Osteotomy {
            name: name.into(),
            region: Region::Box {
                min: [x0, -10.0, -10.0],
                max: [x1, 10.0, 10.0],
            },
            translate: [0.0; 3],
            rotate_deg: [0.0; 3],
            pivot: [0.0; 3],
        };
        let pts = [[1.0, 2.0, 3.0], [5.0, 0.0, 0.0], [50.0, 0.0, 0.0]];
        let m = attachment_moves(&[seg("a", 0.0, 6.0), seg("b", 4.0, 8.0)], &pts);
        assert_eq!(m.columns.len(), 24);
        assert_eq!(m.overlapping_segments, vec![0, 1]);
        // Segment a, k = 1 (row 0, column 1): x-displacement = y.
        assert_eq!(m.columns[1][0], [2.0, 0.0, 0.0]);
        // Segment b, k = 11 (t′_z): the point at x = 1 is outside b.
        assert_eq!(m.columns[COLUMNS + 11][0], [0.0; 3]);
        assert_eq!(m.columns[COLUMNS + 11][1], [0.0, 0.0, 1.0]);
        assert!(m.columns.iter().all(|c| c[2] == [0.0; 3]));
    }
}

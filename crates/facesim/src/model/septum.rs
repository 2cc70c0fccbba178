//! `[tet] septum_detached` (off by default; docs/validation-notes.md "The septum off the
//! maxilla"). A Le Fort I's down-fracture separates the nasal septum from the maxilla's nasal
//! crest with an osteotome, and in an impaction the septum is trimmed by the impaction's height:
//! the septum stays with the skull base, and the maxilla's nasal floor no longer carries it. The
//! mesh has no septum of its own (the CT shows cartilage as soft tissue), so the option holds
//! still the tissue on the nasal surface of the segment that carries the upper teeth: the nodes
//! on its bone that face up, behind the piriform aperture.

use crate::landmarks::HeadFrame;
use crate::vec3::{dot, sub};

/// A node is on the nasal floor's side when its bone faces up within this angle of the head
/// frame's vertical (degrees): the floor and the crest, not the maxilla's front or the
/// aperture's rim.
const UP_WITHIN_DEG: f64 = 45.0;
/// ... and lies this far behind subnasale (mm), behind the nostril sills and the anterior nasal
/// spine's tip: the nasal base and the columella over them stay with their bone.
const BEHIND_SN_MM: f64 = 10.0;

/// Per node: held still with the skull base. `on_maxilla`: per node, the bone surface's normal
/// at rest when the node is held on the Le Fort I segment's bone (bonded or sliding), else None.
pub(crate) fn held_still(
    frame: &HeadFrame,
    sn: [f64; 3],
    nodes: &[[f64; 3]],
    on_maxilla: &[Option<[f64; 3]>],
) -> Vec<bool> {
    let cos = UP_WITHIN_DEG.to_radians().cos();
    nodes
        .iter()
        .zip(on_maxilla)
        .map(|(p, n)| {
            n.is_some_and(|n| {
                dot(n, frame.vertical) >= cos && dot(sub(*p, sn), frame.anterior) < -BEHIND_SN_MM
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Only nodes on the maxilla's bone that face up and lie behind the aperture are held: the
    /// nasal floor, not the maxilla's front, not the nostril sill, not other bone.
    #[test]
    fn the_nasal_floor_behind_the_aperture_is_held_and_nothing_else() {
        let frame = HeadFrame {
            origin: [0.0; 3],
            lateral: [1.0, 0.0, 0.0],
            vertical: [0.0, 0.0, 1.0],
            anterior: [0.0, -1.0, 0.0],
            symmetry_residual_mm: 0.0,
        };
        let sn = [0.0, -80.0, 0.0];
        let up = Some([0.0, 0.0, 1.0]);
        let tilted = Some([0.0, -0.8, 0.6]); // 53° off vertical: the aperture's rim
        let front = Some([0.0, -1.0, 0.0]);
        let nodes = [
            [0.0, -60.0, -2.0], // floor, 20 mm behind Sn
            [0.0, -75.0, -2.0], // 5 mm behind Sn: the sill
            [0.0, -60.0, -2.0], // the floor's height, but its bone faces forward
            [0.0, -60.0, -2.0], // tilted past 45°
            [0.0, -60.0, -2.0], // not on the maxilla
        ];
        let held = held_still(&frame, sn, &nodes, &[up, up, front, tilted, None]);
        assert_eq!(held, vec![true, false, false, false, false]);
    }
}

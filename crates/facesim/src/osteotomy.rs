//! Bone moves (docs/reference/case.md `[[osteotomy]]`, Koch §4.4): each segment moves the skull points
//! inside its region by a rigid transform p' = R (p − pivot) + pivot + translate, with
//! R = Rz·Ry·Rx (rotate about x, then y, then z; degrees). Segments apply in order, each to the
//! points inside its region at their current position; a segment a `[[surgery]]` cut
//! (`crate::anatomy`) selects by the pre-operative position, since it is one piece of bone.

use crate::case::Osteotomy;
use crate::error::{Error, Result};

pub struct Plan {
    steps: Vec<Osteotomy>,
}

/// R = Rz·Ry·Rx of the angles in degrees (the plan's convention, also used by the plan basis).
pub fn rotation(deg: [f64; 3]) -> [[f64; 3]; 3] {
    let [a, b, c] = deg.map(f64::to_radians);
    let rx = [
        [1.0, 0.0, 0.0],
        [0.0, a.cos(), -a.sin()],
        [0.0, a.sin(), a.cos()],
    ];
    let ry = [
        [b.cos(), 0.0, b.sin()],
        [0.0, 1.0, 0.0],
        [-b.sin(), 0.0, b.cos()],
    ];
    let rz = [
        [c.cos(), -c.sin(), 0.0],
        [c.sin(), c.cos(), 0.0],
        [0.0, 0.0, 1.0],
    ];
    let mul = |p: [[f64; 3]; 3], q: [[f64; 3]; 3]| {
        let mut r = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                r[i][j] = (0..3).map(|k| p[i][k] * q[k][j]).sum();
            }
        }
        r
    };
    mul(rz, mul(ry, rx))
}

impl Plan {
    /// The plan of `osteotomies`, whose mask regions have been read (`pipeline::inputs::read_masks`).
    pub fn new(osteotomies: &[Osteotomy]) -> Plan {
        Plan {
            steps: osteotomies.to_vec(),
        }
    }

    /// The segments, in the order they apply.
    pub fn segments(&self) -> &[Osteotomy] {
        &self.steps
    }

    /// Move points; `scale` ∈ [0, 1] applies a fraction of every move (load increments:
    /// translation and rotation angles scaled). Returns the moved points and, per point,
    /// whether any segment moved it.
    pub fn apply(&self, points: &[[f64; 3]], scale: f64) -> (Vec<[f64; 3]>, Vec<bool>) {
        self.carry(points, points, scale)
    }

    /// Move each point with the segments that move its anchor (a step moves both when its
    /// region holds the anchor's current position): tissue off the bone is carried rigidly
    /// as the bone point under it is, so a rigid plan moves it rigidly (the mucosa
    /// held with its bone point's displacement made a rotated skull's face 0.3 % non-rigid).
    /// Returns the moved points and whether any segment moved each.
    pub(crate) fn carry(
        &self,
        points: &[[f64; 3]],
        anchors: &[[f64; 3]],
        scale: f64,
    ) -> (Vec<[f64; 3]>, Vec<bool>) {
        let (out, step) = self.carry_by(points, anchors, scale);
        (out, step.iter().map(Option::is_some).collect())
    }

    /// [`Plan::apply`] with, per point, the last step (segment index) that moved it.
    pub(crate) fn carry_steps(&self, points: &[[f64; 3]]) -> (Vec<[f64; 3]>, Vec<Option<usize>>) {
        self.carry_by(points, points, 1.0)
    }

    fn carry_by(
        &self,
        points: &[[f64; 3]],
        anchors: &[[f64; 3]],
        scale: f64,
    ) -> (Vec<[f64; 3]>, Vec<Option<usize>>) {
        let mut out = points.to_vec();
        let mut anchor = anchors.to_vec();
        let mut moved = vec![None; points.len()];
        for (k, o) in self.steps.iter().enumerate() {
            let r = rotation(o.rotate_deg.map(|d| d * scale));
            let turn = |p: &mut [f64; 3]| {
                let d = [p[0] - o.pivot[0], p[1] - o.pivot[1], p[2] - o.pivot[2]];
                for a in 0..3 {
                    p[a] = (0..3).map(|k| r[a][k] * d[k]).sum::<f64>()
                        + o.pivot[a]
                        + scale * o.translate[a];
                }
            };
            let pre = o.region.selects_pre_operative();
            for (((p, q), m), q0) in out
                .iter_mut()
                .zip(anchor.iter_mut())
                .zip(moved.iter_mut())
                .zip(anchors)
            {
                if o.region.contains(if pre { *q0 } else { *q }) {
                    turn(p);
                    turn(q);
                    *m = Some(k);
                }
            }
        }
        (out, moved)
    }

    /// Each segment must select something, or the plan is surely wrong.
    pub(crate) fn check_selects(&self, points: &[[f64; 3]], what: &str) -> Result<()> {
        for o in &self.steps {
            if !points.iter().any(|p| o.region.contains(*p)) {
                return Err(Error::config(format!(
                    "case.toml: osteotomy '{}': its region contains none of the {} {what}",
                    o.name,
                    points.len()
                )));
            }
        }
        Ok(())
    }

    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_order_is_x_then_y_then_z() {
        // x axis rotated 90° about z → y axis; about y first (90°) → −z, then about z stays −z.
        let r = rotation([0.0, 90.0, 90.0]);
        let v = [1.0, 0.0, 0.0];
        let w: Vec<f64> = (0..3)
            .map(|a| (0..3).map(|k| r[a][k] * v[k]).sum())
            .collect();
        assert!(
            (w[0]).abs() < 1e-12 && (w[1]).abs() < 1e-12 && (w[2] + 1.0).abs() < 1e-12,
            "{w:?}"
        );
    }

    #[test]
    fn a_carried_point_moves_rigidly_with_its_anchor_not_with_the_region_it_lies_in() {
        use crate::case::Region;
        // The segment: everything with x < 0, turned and moved.
        let seg = Osteotomy {
            name: "s".into(),
            region: Region::Box {
                min: [-1e3, -1e3, -1e3],
                max: [0.0, 1e3, 1e3],
            },
            translate: [1.0, -2.0, 0.5],
            rotate_deg: [10.0, -20.0, 5.0],
            pivot: [-3.0, 4.0, 1.0],
        };
        let plan = Plan::new(std::slice::from_ref(&seg));
        let rigid = |p: [f64; 3]| {
            let r = rotation(seg.rotate_deg);
            let d = [0, 1, 2].map(|c| p[c] - seg.pivot[c]);
            [0, 1, 2].map(|a| {
                (0..3).map(|k| r[a][k] * d[k]).sum::<f64>() + seg.pivot[a] + seg.translate[a]
            })
        };
        // Anchored in the segment, lying outside it: moved by the segment's rigid transform.
        let (out, moved) = plan.carry(&[[5.0, 2.0, 3.0]], &[[-1.0, 2.0, 3.0]], 1.0);
        let want = rigid([5.0, 2.0, 3.0]);
        assert!(moved[0]);
        assert!(
            (0..3).all(|c| (out[0][c] - want[c]).abs() < 1e-12),
            "{out:?} {want:?}"
        );
        // Anchored outside, lying inside: stays.
        let (out, moved) = plan.carry(&[[-5.0, 2.0, 3.0]], &[[1.0, 2.0, 3.0]], 1.0);
        assert!(!moved[0]);
        assert_eq!(out[0], [-5.0, 2.0, 3.0]);
    }
}

//! Where the plan drives moved bone into bone that stays (colliding teeth, say):
//! the moved skull surface is tested against the segmentation's bone at rest. facesim moves bone
//! pieces rigidly and removes none, so such a plan has either bone the surgeon would remove (an
//! impaction or a setback against the bone above or behind the segment) or teeth driven into
//! each other; the tissue caught between is squeezed or torn. The run says where and how deep.

use crate::labels::BONE;
use crate::mesh::Mesh;
use crate::osteotomy::Plan;
use crate::vec3::{add, norm, scale, sub};
use crate::volume::Volume;

/// Moved bone inside bone that stays, per segment.
#[derive(Clone, Debug, PartialEq)]
pub struct Overlap {
    pub segment: String,
    /// Moved skull surface vertices that end up deeper than [`REPORTED_DEPTH_MM`].
    pub vertices: usize,
    /// The deepest one's depth (mm: how far back along its own move it is still inside bone
    /// that stays, the bone a surgeon would remove for it) and where it ends up.
    pub deepest_mm: f64,
    pub at: [f64; 3],
}

/// Shallower overlaps are the voxel's own tolerance (a moved vertex grazing a wall).
pub(crate) const REPORTED_DEPTH_MM: f64 = 1.0;

/// The overlaps of `plan` on `skull` (the bone surface at rest), bone at rest from `labels` on
/// `vol`'s grid. A moved surface vertex inside bone that no segment moves is marched back along
/// its own move, in steps of a quarter voxel, until it leaves that bone: the distance is its
/// depth (at most its move). The surface mesh has no faces where the saw cut, so the distance
/// to the staying bone's surface would not measure it; the path back does.
pub fn bone_overlap(plan: &Plan, skull: &Mesh, vol: &Volume, labels: &[u8]) -> Vec<Overlap> {
    let (moved, step) = plan.carry_steps(&skull.vertices);
    if step.iter().all(Option::is_none) {
        return Vec::new();
    }
    let map = vol.voxel_map();
    // Bone at rest at `p` that no segment moves.
    let bone_that_stays = |p: [f64; 3]| -> bool {
        let c = map.to_voxel(p);
        let mut ijk = [0usize; 3];
        for a in 0..3 {
            let r = c[a].round();
            if r < 0.0 || r >= vol.dims[a] as f64 {
                return false;
            }
            ijk[a] = r as usize;
        }
        labels[vol.idx(ijk[0], ijk[1], ijk[2])] == BONE && !plan.apply(&[p], 1.0).1[0]
    };
    let h = 0.25 * vol.spacing.iter().copied().fold(f64::INFINITY, f64::min);
    let depth = |from: [f64; 3], to: [f64; 3]| -> f64 {
        let d = sub(to, from);
        let len = norm(d);
        let n = (len / h).ceil().max(1.0) as usize;
        (1..=n)
            .find(|i| !bone_that_stays(add(to, scale(d, -(*i as f64) / n as f64))))
            .map_or(len, |i| len * i as f64 / n as f64)
    };
    let mut out: Vec<Overlap> = Vec::new();
    for (k, seg) in plan.segments().iter().enumerate() {
        let mut o = Overlap {
            segment: seg.name.clone(),
            vertices: 0,
            deepest_mm: 0.0,
            at: [0.0; 3],
        };
        for ((p, q), s) in skull.vertices.iter().zip(&moved).zip(&step) {
            if *s != Some(k) || !bone_that_stays(*q) {
                continue;
            }
            let d = depth(*p, *q);
            if d > REPORTED_DEPTH_MM {
                o.vertices += 1;
                if d > o.deepest_mm {
                    o.deepest_mm = d;
                    o.at = *q;
                }
            }
        }
        if o.vertices > 0 {
            out.push(o);
        }
    }
    out
}

/// The run's warning for one overlap.
pub fn warning(o: &Overlap) -> String {
    format!(
        "the plan drives segment '{}' into bone that stays: {} of its surface vertices end up inside it, up to {:.1} mm deep (at [{:.1}, {:.1}, {:.1}] mm LPS). facesim removes no bone: that is bone the surgeon would remove (an impaction or a setback against the bone above or behind) or teeth driven into each other; the tissue caught between is squeezed or torn",
        o.segment, o.vertices, o.deepest_mm, o.at[0], o.at[1], o.at[2]
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::case::{Osteotomy, Region};

    /// Two blocks of bone, 1 mm voxels: the lower (x, y 5–34, z 5–14) stays, the upper (z 20–29,
    /// 5 mm above it, as teeth apart) is the segment; each with its surface, 1 mm triangles.
    fn blocks() -> (Volume, Vec<u8>, Mesh) {
        let n = 40;
        let vol = Volume {
            dims: [n; 3],
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            data: vec![0.0; n * n * n],
        };
        let mut labels = vec![0u8; n * n * n];
        let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
        for (z0, z1) in [(5usize, 14usize), (20, 29)] {
            for k in z0..=z1 {
                for j in 5..35 {
                    for i in 5..35 {
                        labels[vol.idx(i, j, k)] = BONE;
                    }
                }
            }
            box_surface(
                [5.0, 5.0, z0 as f64],
                [34.0, 34.0, z1 as f64],
                &mut vertices,
                &mut triangles,
            );
        }
        (vol, labels, Mesh::new(vertices, triangles))
    }

    /// The surface of the box [lo, hi], a grid of 1 mm on each face.
    fn box_surface(
        lo: [f64; 3],
        hi: [f64; 3],
        vertices: &mut Vec<[f64; 3]>,
        triangles: &mut Vec<[u32; 3]>,
    ) {
        for axis in 0..3 {
            for at in [lo[axis], hi[axis]] {
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let (nu, nv) = ((hi[u] - lo[u]) as usize + 1, (hi[v] - lo[v]) as usize + 1);
                let base = vertices.len() as u32;
                for a in 0..nu {
                    for b in 0..nv {
                        let mut p = [0.0; 3];
                        p[axis] = at;
                        p[u] = lo[u] + a as f64;
                        p[v] = lo[v] + b as f64;
                        vertices.push(p);
                    }
                }
                for a in 0..nu - 1 {
                    for b in 0..nv - 1 {
                        let i = base + (a * nv + b) as u32;
                        let m = nv as u32;
                        triangles.push([i, i + 1, i + m]);
                        triangles.push([i + 1, i + m + 1, i + m]);
                    }
                }
            }
        }
    }

    fn upper_block(translate: [f64; 3]) -> Plan {
        Plan::new(&[Osteotomy {
            name: "upper".into(),
            region: Region::Box {
                min: [0.0, 0.0, 17.5],
                max: [40.0, 40.0, 40.0],
            },
            translate,
            rotate_deg: [0.0; 3],
            pivot: [0.0; 3],
        }])
    }

    #[test]
    fn a_move_short_of_the_other_bone_or_away_from_it_overlaps_nothing() {
        let (vol, labels, skull) = blocks();
        for t in [[0.0, 0.0, -4.0], [0.0, 0.0, 6.0], [0.0, 5.0, 0.0]] {
            let o = bone_overlap(&upper_block(t), &skull, &vol, &labels);
            assert!(o.is_empty(), "{t:?}: {o:?}");
        }
    }

    #[test]
    fn a_move_into_the_bone_that_stays_is_found_as_deep_as_it_goes() {
        let (vol, labels, skull) = blocks();
        // Down 9 mm: the upper block's underside (z 20) ends at z 11, inside the lower block,
        // whose bone voxels reach z 14.5: 3.5 mm back along the move to leave it.
        let o = bone_overlap(&upper_block([0.0, 0.0, -9.0]), &skull, &vol, &labels);
        assert_eq!(o.len(), 1, "{o:?}");
        assert_eq!(o[0].segment, "upper");
        assert!(o[0].vertices > 100, "{o:?}");
        assert!((o[0].deepest_mm - 3.5).abs() <= 0.25 + 1e-9, "{o:?}");
        assert!((o[0].at[2] - 11.0).abs() < 1e-9, "{o:?}");
        assert!(warning(&o[0]).contains("'upper'"), "{}", warning(&o[0]));
        // Turned about a pivot beside it: the path back is the move's chord.
        // Its far end (x 5, 55 mm from the pivot) swings 19 mm down, through the lower block.
        let turned = Plan::new(&[Osteotomy {
            rotate_deg: [0.0, -20.0, 0.0],
            pivot: [60.0, 20.0, 20.0],
            ..upper_block([0.0; 3]).segments()[0].clone()
        }]);
        let o = bone_overlap(&turned, &skull, &vol, &labels);
        assert_eq!(o.len(), 1, "{o:?}");
        assert!(o[0].deepest_mm > 5.0 && o[0].at[0] < 20.0, "{o:?}");
    }
}

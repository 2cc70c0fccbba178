//! The volumetric model's boundary conditions as linear functions of the segments' matrices
//! M_s (docs/design/plan-basis.md): evaluated at the unit matrices they give the plan basis's right-hand
//! sides; the held directions (and so the factor) do not depend on the plan.

use super::Hold;
use crate::case::Osteotomy;
use crate::plan::basis::{COLUMNS, displace};

/// A node's hold, linear in the M_s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum LinearHold {
    Free,
    /// Held at rest (bone outside every segment, the region's cut faces, rigid skin).
    Still,
    /// Moves with segment `segment` as the point `at` does: u = M_s·[at; 1].
    Moves {
        segment: usize,
        at: [f64; 3],
    },
    /// Slides on the bone surface with rest normal `normal` (unit): n · u = n · M_s·[at; 1]
    /// (0 when `segment` is None).
    Slides {
        normal: [f64; 3],
        segment: Option<usize>,
        at: [f64; 3],
    },
}

impl LinearHold {
    /// The hold for segment matrices `ms`.
    pub fn hold(&self, ms: &[[f64; COLUMNS]]) -> Hold {
        let moved = |s: usize, at: [f64; 3]| ms.get(s).map_or([0.0; 3], |m| displace(m, at));
        match *self {
            LinearHold::Free => Hold::Free,
            LinearHold::Still => Hold::Fixed([0.0; 3]),
            LinearHold::Moves { segment, at } => Hold::Fixed(moved(segment, at)),
            LinearHold::Slides {
                normal,
                segment,
                at,
            } => {
                let d = segment.map_or([0.0; 3], |s| moved(s, at));
                Hold::Slide {
                    normal,
                    value: (0..3).map(|c| normal[c] * d[c]).sum(),
                }
            }
        }
    }
}

/// The segment whose region holds `p` at rest (the first), and the names of all segments that
/// do when more than one does (their moves compose: not linear in the M_s).
pub(crate) fn segment_at(osteotomies: &[Osteotomy], p: [f64; 3]) -> (Option<usize>, Vec<usize>) {
    let all: Vec<usize> = osteotomies
        .iter()
        .enumerate()
        .filter(|(_, o)| o.region.contains(p))
        .map(|(s, _)| s)
        .collect();
    let first = all.first().copied();
    (first, if all.len() > 1 { all } else { Vec::new() })
}

//! The holds that read the solved displacement: each [`Round`] looks at the solution, changes
//! the holds (or a material) where it says the tissue cannot stay as held, and solves again on
//! the run's factor (bordered, not factored anew) or a new one, a few rounds at most. In the
//! order they run (`solve::solve`): the degloved tissue's one-sided contact
//! ([`OneSidedContact`]), lift-off where a move inverts tissue next to bone ([`LiftOff`]), and
//! tearing of the osteotomy gap's tissue ([`Tearing`]).

use super::state::{OneSidedOutcome, Solving};
use crate::error::Result;
use crate::tet::Hold;
use crate::tet::TissueElastic;
use crate::tet::from_ct::NodeKind;
use crate::tet::plan_holds::LinearHold;
use crate::tet::vtu::{FIXED, MOVED, SLIDING};

/// A hold that reads the solution: its rounds of changing the holds and solving again.
pub(super) trait Round {
    fn run(&self, s: &mut Solving) -> Result<()>;
}

/// Rounds of the degloved tissue's one-sided contact (`model::degloved`), and how far (mm) a
/// lifted node may lie inside its bone's move before it rests on the bone again (the solve's
/// round-off is far below; a tenth of a voxel is far above it).
pub(super) const ONE_SIDED_ROUNDS: usize = 8;
const PENETRATION_MM: f64 = 0.01;

/// A node of the degloved tissue on its bone: its sliding hold n · u = value with n the unit
/// normal into the tissue, and its holds to rest it again.
struct OneSided {
    node: usize,
    normal: [f64; 3],
    value: f64,
    rest: (Hold, LinearHold),
}

impl OneSided {
    /// How far the node lies off its bone along the normal at displacement `u` (mm; negative:
    /// inside the bone's move).
    fn gap(&self, u: [f64; 3]) -> f64 {
        crate::vec3::dot(self.normal, u) - self.value
    }
}

/// (K u) on the rows of the `watched` nodes only (zero elsewhere), from K's lower triangle in one
/// pass: the one-sided contact's hold forces. (`fem::sparse::multiply` sorts K into rows first,
/// about 0.5 s a round on the real CT.)
fn rows_times(k: &[(usize, usize, f64)], watched: &[bool], u: &[[f64; 3]]) -> Vec<f64> {
    let u = u.as_flattened();
    let mut ku = vec![0.0; u.len()];
    for &(r, c, v) in k {
        if watched[r / 3] {
            ku[r] += v * u[c];
        }
        if r != c && watched[c / 3] {
            ku[c] += v * u[r];
        }
    }
    ku
}

/// `[tet] degloved_maxilla` and `degloved_chin`: the raised tissue's sliding nodes rest on the
/// bone one way only. Where the hold's force n · (K u) points into the bone (the bone pulls the
/// tissue after it) the node lifts off; a lifted node the bone would pass into (n · u below the
/// bone's normal move) rests on it again. Rounds until the set settles, none factoring anew.
pub(super) struct OneSidedContact<'a> {
    /// Per corner node: raised by an approach (`roles::Anatomy::raised`).
    pub(super) raised: &'a [bool],
    /// The run's stiffness (lower triangle), whose rows give the hold forces.
    pub(super) k: &'a [(usize, usize, f64)],
}

impl OneSidedContact<'_> {
    /// The raised nodes sliding on their bone after the holds.
    fn nodes(&self, s: &Solving) -> Vec<OneSided> {
        (0..self.raised.len())
            .filter(|n| self.raised[*n] && s.constraint[*n] == SLIDING)
            .filter_map(|n| match s.hold[n] {
                Hold::Slide { normal, value } => Some(OneSided {
                    node: n,
                    normal: crate::vec3::scale(normal, 1.0 / crate::vec3::norm(normal)),
                    value,
                    rest: (s.hold[n], s.linear_hold[n]),
                }),
                _ => None,
            })
            .collect()
    }
}

impl Round for OneSidedContact<'_> {
    fn run(&self, s: &mut Solving) -> Result<()> {
        let one_sided = self.nodes(s);
        let mut settled = one_sided.is_empty();
        let rounds = if one_sided.is_empty() {
            0
        } else {
            ONE_SIDED_ROUNDS + 1
        };
        let mut watched = vec![false; s.nodes];
        one_sided.iter().for_each(|o| watched[o.node] = true);
        // K's entries on the watched rows, once: each round's hold forces pass over them only
        // (a twentieth of K on the real CT).
        let k_watched: Vec<(usize, usize, f64)> = self
            .k
            .iter()
            .filter(|(r, c, _)| watched[r / 3] || watched[c / 3])
            .copied()
            .collect();
        for round in 0..rounds {
            let ku = rows_times(&k_watched, &watched, &s.u);
            let mut freed = Vec::new();
            let mut rests = Vec::new();
            for o in &one_sided {
                let n = o.node;
                if s.hold[n] == Hold::Free {
                    if o.gap(s.u[n]) < -PENETRATION_MM {
                        rests.push(n);
                    }
                } else if crate::vec3::dot(o.normal, [0, 1, 2].map(|c| ku[3 * n + c])) < 0.0 {
                    freed.push(n);
                }
            }
            if freed.is_empty() && rests.is_empty() {
                settled = true;
                break;
            }
            if round == ONE_SIDED_ROUNDS {
                break;
            }
            s.free(&freed);
            let mut rested = Vec::with_capacity(rests.len());
            for o in one_sided.iter().filter(|o| rests.contains(&o.node)) {
                s.constraint[o.node] = SLIDING;
                (s.hold[o.node], s.linear_hold[o.node]) = o.rest;
                rested.push((o.node, o.rest.0));
            }
            s.lifted.retain(|n| !rests.contains(n));
            // The factor is bordered by the normal components of the nodes lifted so far (one
            // solve each, the first time), and a node that rests again is held on the border:
            // no round factors anew.
            if !freed.is_empty() {
                s.factor_mut()?.free_nodes(&freed)?;
            }
            if !rested.is_empty() {
                s.factor_mut()?.rest_nodes(&rested)?;
            }
            s.solve()?;
        }
        s.one_sided = OneSidedOutcome {
            settled,
            lifted_in_tension: s.lifted.len(),
            penetration_mm: one_sided
                .iter()
                .filter(|o| s.hold[o.node] == Hold::Free)
                .map(|o| -o.gap(s.u[o.node]))
                .fold(0.0, f64::max),
        };
        Ok(())
    }
}

/// Rounds of freeing the bone and sliding nodes of inverted elements and solving again.
const RELEASE_ROUNDS: usize = 6;

/// Where the solution turns an element next to bone inside out, the bone would drag that tissue
/// through itself or through the bone of another piece (the tissue behind an advanced segment,
/// or between it and the skull it slides past): the tissue there lifts off (the element's nodes
/// that move with a segment, are held on bone or slide are freed) and the model is solved
/// again, [`RELEASE_ROUNDS`] at most. The region's cut faces and held skin stay held. Lift-off
/// is contact, as sliding is: with `[tet] sliding = false` the tissue stays bonded (and a plan
/// basis exact for every plan, with no contact state to choose), so it runs with `sliding` and
/// `release_cuts` only.
pub(super) struct LiftOff;

impl Round for LiftOff {
    fn run(&self, s: &mut Solving) -> Result<()> {
        for _ in 0..RELEASE_ROUNDS {
            let mut freed = Vec::new();
            for e in s.inverted() {
                for n in s.cell(e) {
                    let n = n as usize;
                    let c = s.constraint[n];
                    let lifts =
                        c == SLIDING || c == MOVED || (c == FIXED && s.kind[n] == NodeKind::Bone);
                    if lifts {
                        s.free(&[n]);
                        freed.push(n);
                    }
                }
            }
            if freed.is_empty() {
                break;
            }
            // The factor bordered by the freed components: no second factorisation.
            s.factor_mut()?.free_nodes(&freed)?;
            s.solve()?;
        }
        Ok(())
    }
}

/// Rounds of tearing the gap tissue a move inverts (after lift-off) and solving again.
const TEAR_ROUNDS: usize = 8;
/// A tearing round that inverts up to this many elements has not spread, whatever the first
/// round inverted: on a coarse phantom's impaction one torn gap element leaves two neighbours
/// inverted, which tear in the next round; tissue sheared by a 25 mm move inverts tens.
const SPREAD_FLOOR: usize = 8;

/// A torn element's stiffness, as a fraction of its tissue's: a trace, so that a node left only
/// in torn elements still has a definite (if meaningless) displacement.
pub(super) const TORN_STIFFNESS: f64 = 1e-4;

/// `material` with the torn tetrahedra's stiffness a trace ([`TORN_STIFFNESS`]).
pub(super) fn torn_trace(mut material: Vec<TissueElastic>, torn: &[bool]) -> Vec<TissueElastic> {
    for (m, _) in material.iter_mut().zip(torn).filter(|(_, t)| **t) {
        m.youngs_kpa *= TORN_STIFFNESS;
    }
    material
}

/// `[tet] tear_gap`: what lift-off leaves inverted is tissue in the osteotomy gap that the move
/// stretches or squeezes beyond what a continuum can follow: the mobilisation tears it
/// (docs/design/pipeline.md "Large moves"). It is released: its stiffness falls to a trace, the model is
/// factored and solved again, [`TEAR_ROUNDS`] at most. Tissue on the face never tears: an
/// inverted element there stays a failure. A round that inverts more than the first, and more
/// than [`SPREAD_FLOOR`], spreads instead of settling (tissue sheared against a held face, or
/// lips the scan fused): it stops there. (A torn element's few neighbours may invert in the next
/// round as the gap settles.) The 4-node element only, and not beyond orthognathic size
/// (centimetres typed as millimetres?): the inverted elements then refuse the plan.
pub(super) struct Tearing<'a> {
    /// Per tetrahedron: carries a face vertex (the face itself, which never tears).
    pub(super) carries_face: &'a [bool],
    /// The tissues' materials before tearing.
    pub(super) material: &'a [TissueElastic],
}

impl Round for Tearing<'_> {
    fn run(&self, s: &mut Solving) -> Result<()> {
        let mut first: Option<usize> = None;
        for _ in 0..TEAR_ROUNDS {
            let inverted: Vec<usize> = s
                .linear
                .inverted_after(&s.u)
                .into_iter()
                .filter(|e| !s.torn[*e])
                .collect();
            let on_the_face = |e: &usize| self.carries_face[*e];
            if inverted.is_empty()
                || first.is_some_and(|n| inverted.len() > n.max(SPREAD_FLOOR))
                || inverted.iter().any(on_the_face)
            {
                break;
            }
            first.get_or_insert(inverted.len());
            for e in inverted {
                s.torn[e] = true;
            }
            s.linear.material = torn_trace(self.material.to_vec(), &s.torn);
            // The old factor goes before the new one is made: two at once set the run's peak
            // (a rotation on a 2.5 mm phantom: 3.3 GB against 2.0 GB).
            s.refactor()?;
            s.solve()?;
        }
        Ok(())
    }
}

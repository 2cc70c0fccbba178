//! The holds (boundary conditions) set before the solve, each its own type built from the case
//! and applied in turn to one [`Holds`] set (the pattern of dolfinx's list of `DirichletBC`s or
//! SOFA's constraint components): the bone moves ([`BoneMoves`]), sliding contact
//! ([`SlidingContact`]), the release at the saw lines ([`CutRelease`]), the pieces too loosely
//! held to solve ([`FloatingPieces`]), the scan's end ([`ScanEndSlides`]). The order is
//! [`conditions`]'s: a later hold overrides what an earlier one set on a node. The geometry of
//! each lives in `tet::conditions`; here is which apply, with what parameters, in what order.
//! The run and its re-solves hold the tissue alike ([`hold_tissue`]).
//!
//! Holds that read the solved displacement and solve again (the degloved tissue's one-sided
//! contact, lift-off, tearing) are rounds of the solve (`rounds`).

use super::mesh::Box3;
use super::roles::Roles;
use crate::case::{Case, ScanEndHold};
use crate::error::{Error, Result};
use crate::pipeline::Recorder;
use crate::tet::Hold;
use crate::tet::conditions::{
    self, Bone, Holds, follow_bone, hold_floating_pieces, release_at_cuts,
};
use crate::tet::from_ct::{NodeKind, SoftTissueMesh};
use crate::tet::quadratic::Tet10Mesh;
use crate::tet::vtu::MOVED;

/// The solved cells: a 10-node mesh's midpoints are nodes of its cells, not of the corners'.
#[derive(Clone, Copy)]
pub(super) enum Cells<'a> {
    Linear(&'a [[u32; 4]]),
    Quadratic(&'a [[u32; 10]]),
}

/// What a hold reads: the solved nodes and cells, their roles, the moved bone, and the skin
/// `[surface] movable` holds.
pub(super) struct Site<'a> {
    pub(super) nodes: &'a [[f64; 3]],
    pub(super) cells: Cells<'a>,
    pub(super) roles: Roles<'a>,
    pub(super) bone: &'a Bone<'a>,
    /// Per solved node: skin on the face outside `[surface] movable` (held still).
    pub(super) rigid: Vec<bool>,
}

/// How many nodes the holds took, for the report.
#[derive(Default)]
pub(super) struct Held {
    /// Bone nodes at the saw lines that slide instead (`[tet] release_cuts`).
    pub(super) released_at_cuts: usize,
    /// Pieces of the mesh held by too few nodes, held rigidly, and their nodes.
    pub(super) pieces: usize,
    pub(super) piece_nodes: usize,
    /// Free nodes where the scan ends that slide on its end plane (`[tet] scan_end`).
    pub(super) on_scan_end: usize,
}

/// One hold: built from the case, it sets the holds of the nodes it takes.
pub(super) trait Condition {
    fn apply(&self, site: &Site, holds: &mut Holds, held: &mut Held);
}

/// Bone nodes follow their segment rigidly; bone left in place, the region's cut faces and the
/// skin outside `[surface] movable` stay; mucosa moves with its bone; the rest is free
/// (`tet::conditions::bone_moves`). The first hold: it sets every node.
struct BoneMoves;

impl Condition for BoneMoves {
    fn apply(&self, site: &Site, holds: &mut Holds, _: &mut Held) {
        let r = &site.roles;
        *holds = conditions::bone_moves(site.nodes, r.kind, r.mucosa, &site.rigid, site.bone);
    }
}

/// `[tet] sliding`: mucosa, lip and cheek on the teeth and the degloved bone slide along their
/// bone (`tet::conditions::slide_on_bone`); along its normal at rest for the linear models.
struct SlidingContact {
    rest_normals: bool,
}

impl Condition for SlidingContact {
    fn apply(&self, site: &Site, holds: &mut Holds, _: &mut Held) {
        let r = &site.roles;
        conditions::slide_on_bone(holds, r.kind, r.mucosa, &site.rigid, self.rest_normals);
    }
}

/// `[tet] release_cuts`: the tissue over a saw line is not attached; bone nodes within
/// `cut_release_mm` of another piece slide on their bone (or are free without sliding;
/// `tet::conditions::release_at_cuts`).
struct CutRelease {
    band_mm: f64,
    slide: bool,
}

impl Condition for CutRelease {
    fn apply(&self, site: &Site, holds: &mut Holds, held: &mut Held) {
        let (at, kind) = (site.nodes, site.roles.kind);
        held.released_at_cuts = match site.cells {
            Cells::Linear(c) => release_at_cuts(c, at, kind, holds, self.band_mm, self.slide),
            Cells::Quadratic(c) => release_at_cuts(c, at, kind, holds, self.band_mm, self.slide),
        };
    }
}

/// Pieces of the mesh held by fewer than three nodes move rigidly with their bone
/// (`tet::conditions::hold_floating_pieces`); after the release, which may leave them so.
struct FloatingPieces {
    /// The segments' matrices (`plan::basis::matrix`), each piece's move as the plan's.
    ms: Vec<[f64; crate::plan::basis::COLUMNS]>,
}

impl Condition for FloatingPieces {
    fn apply(&self, site: &Site, holds: &mut Holds, held: &mut Held) {
        let follow = follow_bone(site.bone, site.nodes);
        let at = site.nodes;
        (held.pieces, held.piece_nodes) = match site.cells {
            Cells::Linear(c) => hold_floating_pieces(c, at, holds, &follow, &self.ms),
            Cells::Quadratic(c) => hold_floating_pieces(c, at, holds, &follow, &self.ms),
        };
    }
}

/// `[tet] scan_end = "slides"`: free tissue past the scan's end slides on its end plane
/// (`tet::conditions::slide_on_scan_end`). After the floating pieces: a piece held by the end
/// plane alone could still slide along it, so it is held with its bone as before.
struct ScanEndSlides;

impl Condition for ScanEndSlides {
    fn apply(&self, site: &Site, holds: &mut Holds, held: &mut Held) {
        let r = &site.roles;
        held.on_scan_end = conditions::slide_on_scan_end(holds, site.nodes, r.kind, r.scan);
    }
}

/// The case's holds, in the order they apply. `rest_normals`: the linear models, which slide
/// on the bone's normals at rest.
fn conditions(case: &Case, rest_normals: bool) -> Vec<Box<dyn Condition>> {
    let t = &case.tet;
    let mut c: Vec<Box<dyn Condition>> = vec![Box::new(BoneMoves)];
    if t.sliding {
        c.push(Box::new(SlidingContact { rest_normals }));
    }
    if t.release_cuts {
        c.push(Box::new(CutRelease {
            band_mm: t.cut_release_mm,
            slide: t.sliding,
        }));
    }
    let ms = case
        .osteotomy
        .iter()
        .map(crate::plan::basis::matrix)
        .collect();
    c.push(Box::new(FloatingPieces { ms }));
    if t.scan_end == ScanEndHold::Slides {
        c.push(Box::new(ScanEndSlides));
    }
    c
}

/// Every solved node's hold (the nodes are the corners, then the midpoints when `quadratic`):
/// the case's [`conditions`] applied in turn; with how many nodes the holds took. The run and
/// its re-solves hold the tissue alike.
pub(super) fn hold_tissue(
    mesh: &SoftTissueMesh,
    quadratic: Option<&Tet10Mesh>,
    roles: Roles,
    bone: &Bone,
    case: &Case,
    rest_normals: bool,
) -> (Holds, Held) {
    let nodes = quadratic.map_or(&mesh.nodes, |q| &q.nodes);
    // `[surface] movable` holds the face outside it, not the walls of cavities.
    let rigid: Vec<bool> = crate::pipeline::model::rigid_mask(case, nodes)
        .into_iter()
        .zip(roles.on_face)
        .map(|(r, f)| r && *f)
        .collect();
    let site = Site {
        nodes,
        cells: match quadratic {
            Some(q) => Cells::Quadratic(&q.tets),
            None => Cells::Linear(&mesh.tets),
        },
        roles,
        bone,
        rigid,
    };
    let (mut holds, mut held) = (Holds::default(), Held::default());
    for c in conditions(case, rest_normals) {
        c.apply(&site, &mut holds, &mut held);
    }
    (holds, held)
}

/// Bone moves beyond this (mm) are warned about: orthognathic advancements and setbacks stay
/// within about 15 mm, distraction of the maxilla reaches ~20.
pub(super) const LARGE_MOVE_MM: f64 = 25.0;

/// The largest move (mm) the holds give a node moved with its bone.
pub(super) fn largest_move(holds: &Holds) -> f64 {
    holds
        .hold
        .iter()
        .zip(&holds.constraint)
        .filter(|(_, c)| **c == MOVED)
        .filter_map(|(h, _)| match h {
            Hold::Fixed(u) => Some((u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()),
            _ => None,
        })
        .fold(0.0, f64::max)
}

/// What the run's holds say before it solves: the pieces held rigidly and a move no skin could
/// follow (warnings), and a segment whose bone carries no tissue (an error naming case.toml).
pub(super) fn check(
    held: &Held,
    largest: f64,
    mesh: &SoftTissueMesh,
    roi: Box3,
    case: &Case,
    rec: &mut Recorder,
) -> Result<()> {
    let (pieces, held_still) = (held.pieces, held.piece_nodes);
    if pieces > 0 {
        rec.warn(format!(
            "{pieces} pieces of the tissue mesh ({held_still} nodes) are held by fewer than three bone or region-face nodes: each moves rigidly with the bone it lies on (thin tissue the mesh separated or hinged; a smaller [tet] skin_size_mm resolves it)"
        ));
    }
    // The tissue follows its bone, so a move no skin could follow (centimetres typed as
    // millimetres) is no error here as it is in the C1 model's spring check; say it instead.
    if largest > LARGE_MOVE_MM {
        rec.warn(format!(
            "the plan moves bone up to {largest:.0} mm, beyond the {LARGE_MOVE_MM:.0} mm of the largest orthognathic moves: check the osteotomy's translate (mm) and rotate_deg (degrees); the small-strain model is not valid there"
        ));
    }
    // Each segment must carry tissue: a segment whose bone touches no node of the mesh moves
    // nothing, and the plan is surely not what was meant.
    for o in &case.osteotomy {
        let carried = mesh
            .nodes
            .iter()
            .zip(&mesh.kind)
            .any(|(p, k)| *k == NodeKind::Bone && o.region.contains(*p));
        if !carried {
            return Err(Error::config(format!(
                "case.toml: osteotomy '{}': no node of the soft-tissue mesh lies on its bone (modelled region {:.0?} to {:.0?} mm): the segment carries no tissue; check its region",
                o.name, roi.0, roi.1
            )));
        }
    }
    Ok(())
}

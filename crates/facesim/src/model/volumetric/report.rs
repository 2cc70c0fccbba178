//! report.json's `tet` section, and what the run says of its solution: where the scan ends in
//! the tissue, the elements a move turns inside out or tears.

use crate::case::{TetElement, TetMaterial};
use crate::compare::DistanceStats;
use crate::tet::holds::SolverUsed;
use crate::tet::quality::Quality;
use crate::tet::vtu::{FREE, MOVED, SLIDING};
use serde::{Deserialize, Serialize};

/// One converged Newton load step of the nonlinear material.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct NewtonStep {
    pub load: f64,
    pub iterations: usize,
    pub residual: f64,
    /// Conjugate-gradient iterations of the step's Newton systems (0: factored).
    #[serde(default)]
    pub krylov_iterations: usize,
}

/// report.json's `tet` section.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TetReport {
    pub material: TetMaterial,
    pub element: TetElement,
    /// The face region (LPS mm): the box around the moved bone grown by `[tet] margin_mm`,
    /// within the CT, and grown further to hold the nose tip when the nose's base is inside.
    /// The face inside it is carried by the tissue mesh; the face beyond it stays.
    pub region: ([f64; 3], [f64; 3]),
    /// The tissue mesh's box (LPS mm): `region` grown by `[tet] margin_mm` once more, its upper
    /// corner rounded up to whole lattice cells (`tet::from_ct::SoftTissueMesh::lattice_box`).
    /// Its faces are held; where the scan ends inside it the tissue ends in a free surface.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh_box: Option<([f64; 3], [f64; 3])>,
    /// Pronasale (LPS mm) when the region was grown to hold it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub region_grown_for_nose_tip: Option<[f64; 3]>,
    pub nodes: usize,
    pub tets: usize,
    pub dofs: usize,
    pub free_dofs: usize,
    /// Nonzeros of the Cholesky factor of the solved system: 8 bytes each, what sets the run's
    /// peak memory (`facesim estimate` predicts it before the run).
    #[serde(default)]
    pub factor_nonzeros: usize,
    /// How the system was solved: its Cholesky factor, or (a 10-node model whose factor would
    /// not fit) conjugate gradients with the p-multigrid preconditioner, whose coarse level's
    /// factor `factor_nonzeros` then counts. Defaulted when absent: a report.json written before
    /// the key existed was solved directly.
    #[serde(default)]
    pub solver: SolverReport,
    /// Nodes per role: skin (free), bone moved with a segment, bone or cut faces held.
    pub skin_nodes: usize,
    /// Skin-kind nodes facing a cavity within `[tet] mucosa_gap_mm` of the skull, and those
    /// of them that slide (`[tet] sliding`; otherwise they move with the bone).
    pub mucosa_nodes: usize,
    pub sliding_nodes: usize,
    /// Bone-kind nodes where lip or cheek rests on a tooth with no air between
    /// (`tet::conditions::contact`: the tooth by its HU, the lip or cheek by the face's air
    /// reached through soft tissue), and those of them sliding in the solve (`[tet] sliding`, not
    /// lifted off); otherwise they stay attached to their bone.
    #[serde(default)]
    pub contact_nodes: usize,
    #[serde(default)]
    pub contact_sliding_nodes: usize,
    pub moved_nodes: usize,
    pub fixed_nodes: usize,
    pub quality: Quality,
    /// Linear material: elements the solved displacement turns inside out (the move is too
    /// large for small-strain elasticity; the nonlinear material handles it).
    pub inverted_elements: usize,
    /// Of those, the ones with nodes on both moved and held bone (the osteotomy's gap).
    pub inverted_between_moved_and_held_bone: usize,
    /// Bone nodes at the saw lines left unattached (`[tet] cut_release_mm`).
    #[serde(default)]
    pub released_at_cuts: usize,
    /// Bone and sliding nodes of elements a solve turned inside out, freed (the tissue lifts
    /// off the bone there) before solving again.
    #[serde(default)]
    pub lifted_off: usize,
    /// Tetrahedra off the face torn because the move still turned them inside out after lift-off
    /// (`[tet] tear_gap`), and their volume at rest (mm³).
    #[serde(default)]
    pub torn_elements: usize,
    #[serde(default)]
    pub torn_volume_mm3: f64,
    /// `[tet] degloved_maxilla` and `degloved_chin`: bone nodes of the raised regions (sliding,
    /// one-sided), those lifted off where the bone pulled them, and the deepest a lifted node
    /// lies inside its bone's move when the rounds end (mm; 0 when every lifted node is clear of
    /// it).
    #[serde(default)]
    pub degloved_nodes: usize,
    #[serde(default)]
    pub lifted_in_tension: usize,
    #[serde(default)]
    pub lifted_penetration_mm: f64,
    /// Whether the one-sided rounds settled: every raised node still on its bone pushed by it,
    /// every lifted one clear of it (false: a warning says how far from it they ended).
    #[serde(default)]
    pub degloved_settled: bool,
    /// Why `[tet] degloved_maxilla = "auto"` stepped aside on a plan that moves the upper teeth
    /// (absent when it served, was off, or had nothing to raise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degloved_not_applied: Option<String>,
    /// `[tet] degloved_chin`: of `degloved_nodes`, those the genioplasty's approach raised, and
    /// why `"auto"` stepped aside on a plan that moves a chin (absent when it did not).
    #[serde(default)]
    pub degloved_chin_nodes: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degloved_chin_not_applied: Option<String>,
    /// Pieces of the mesh held by fewer than three nodes, moved rigidly with their bone.
    #[serde(default)]
    pub floating_pieces: usize,
    /// Where the scan ends inside the tissue mesh's box: the free tissue nodes past the CT's
    /// outermost voxel centres (the surface the tissue ends in there) and how near bone the plan
    /// moves they come. None: the scan ends nowhere in the tissue, or no bone moves.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_end: Option<ScanEnd>,
    /// Nonlinear material: the load steps.
    pub newton: Option<Vec<NewtonStep>>,
    /// Face vertices farther from the mesh's skin than the reach (carried by extrapolation).
    pub face_vertices_unreached: usize,
    /// Distance from each carried face vertex to the mesh's skin boundary (mm).
    pub face_to_mesh_mm: DistanceStats,
}

/// report.json's `tet.solver`: `method` "direct" or "pcg-pmultigrid"; for the latter the run's
/// last solve's conjugate-gradient `iterations` and final `relative_residual` ‖b − K u‖ / ‖b‖.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct SolverReport {
    pub method: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_residual: Option<f64>,
}

impl SolverReport {
    pub(crate) fn of(used: SolverUsed) -> SolverReport {
        match used {
            SolverUsed::Direct => SolverReport {
                method: "direct".into(),
                ..SolverReport::default()
            },
            SolverUsed::PcgPmultigrid(last) => SolverReport {
                method: "pcg-pmultigrid".into(),
                iterations: last.map(|l| l.iterations),
                relative_residual: last.map(|l| l.relative_residual),
            },
        }
    }
}

/// Where the scan ends in the tissue (report.json `tet.scan_end`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct ScanEnd {
    /// The tissue's free surface there.
    pub free_nodes: usize,
    /// Nodes there sliding on the scan's end plane (`[tet] scan_end = "slides"`; 0 with
    /// `"free"`). Defaulted when absent: a report.json written before the key existed had none.
    #[serde(default)]
    pub sliding_nodes: usize,
    /// From the nearest of them to a node on bone the plan moves (mm).
    pub nearest_moved_bone_mm: f64,
}

/// The tissue past the CT's outermost voxel centres (`bounds`), where the scan ends (beyond the
/// CT the fields read air, docs/design/pipeline.md "Region"): its free nodes, the `sliding` nodes
/// `[tet] scan_end` slides on the end plane, and the distance from the nearest free or sliding
/// node there to moved bone; None when there are none or nothing moves.
pub(super) fn scan_end(
    nodes: &[[f64; 3]],
    constraint: &[u8],
    bounds: ([f64; 3], [f64; 3]),
    sliding: usize,
) -> Option<ScanEnd> {
    let (end, free_nodes) = nodes
        .iter()
        .zip(constraint)
        .filter(|(p, c)| {
            (**c == FREE || (sliding > 0 && **c == SLIDING))
                && crate::volume::past_scan_end(bounds, **p)
        })
        .fold((Vec::new(), 0), |(mut end, free), (p, c)| {
            end.push(*p);
            (end, free + usize::from(*c == FREE))
        });
    let moved: Vec<[f64; 3]> = nodes
        .iter()
        .zip(constraint)
        .filter(|(_, c)| **c == MOVED)
        .map(|(p, _)| *p)
        .collect();
    let nearest = end
        .iter()
        .flat_map(|a| {
            moved
                .iter()
                .map(move |b| crate::vec3::norm(crate::vec3::sub(*a, *b)))
        })
        .fold(f64::INFINITY, f64::min);
    (!end.is_empty() && nearest.is_finite()).then_some(ScanEnd {
        free_nodes,
        sliding_nodes: sliding,
        nearest_moved_bone_mm: nearest,
    })
}

/// How many of `a` are `c`.
pub(super) fn counted(a: &[u8], c: u8) -> usize {
    a.iter().filter(|k| **k == c).count()
}

/// What the solved move did to the tissue (report.json `tet.inverted_elements`, `torn_*`).
pub(super) struct Damage {
    /// Elements the solution turns inside out (torn ones aside), and of them those spanning
    /// moved and held bone.
    pub inverted: usize,
    pub at_cuts: usize,
    /// Tetrahedra torn, and their volume at rest (mm³).
    pub torn_elements: usize,
    pub torn_volume_mm3: f64,
}

/// The run's damage, with a warning for the torn tissue and one for what stays inverted (why
/// it did not tear). `inverted`: the solved elements the displacement turns inside out;
/// `tear_gap` and `largest` (mm): the case's tearing and the plan's largest bone move.
pub(super) fn damage(
    inverted: Vec<usize>,
    torn: &[bool],
    mesh: &crate::tet::from_ct::SoftTissueMesh,
    constraint: &[u8],
    carries_face: &[bool],
    (tear_gap, largest): (bool, f64),
    rec: &mut crate::pipeline::Recorder,
) -> Damage {
    use super::holds::LARGE_MOVE_MM;
    use crate::tet::vtu::FIXED;
    let inverted_tets: Vec<usize> = inverted.into_iter().filter(|e| !torn[*e]).collect();
    let torn_elements = torn.iter().filter(|b| **b).count();
    let torn_volume_mm3: f64 = (0..mesh.tets.len())
        .filter(|e| torn[*e])
        .filter_map(|e| crate::tet::gradients(mesh.tets[e].map(|n| mesh.nodes[n as usize])))
        .map(|(v, _)| v)
        // From +0: an empty f64 sum is −0, which report.json would print as "-0.0".
        .fold(0.0, |a, v| a + v);
    if torn_elements > 0 {
        rec.warn(format!(
            "the move tears {torn_elements} tetrahedra ({torn_volume_mm3:.0} mm³) of tissue off the face that it would turn inside out (the osteotomy gap): their stiffness is a trace of their tissue's ([tet] tear_gap; docs/design/pipeline.md \"Large moves\")"
        ));
    }
    // Tetrahedra spanning moved and held bone (the osteotomy's gap, where the plan shears the
    // tissue between bone pieces) are told apart from those a large move inverts elsewhere.
    let at_cuts = inverted_tets
        .iter()
        .filter(|t| {
            let c = mesh.tets[**t].map(|n| constraint[n as usize]);
            c.contains(&MOVED) && c.contains(&FIXED)
        })
        .count();
    let inverted = inverted_tets.len();
    if inverted > 0 {
        let on_the_face = inverted_tets.iter().filter(|e| carries_face[**e]).count();
        let why = if !tear_gap {
            "[tet] tear_gap = true tears such tissue off the face".to_string()
        } else if largest > LARGE_MOVE_MM {
            format!("nothing tears for a move beyond {LARGE_MOVE_MM:.0} mm")
        } else if on_the_face > 0 {
            format!(
                "{on_the_face} of them carry the face, which does not tear: the bone moves further than the face can follow (teeth or bone of two segments colliding, skin held outside [surface] movable, or tissue squeezed against the CT's edge?)"
            )
        } else {
            "the tearing stopped without leaving every element valid".to_string()
        };
        rec.warn(format!(
            "the predicted move turns {inverted} of {} tetrahedra inside out ({at_cuts} of them span moved and held bone, where the osteotomy shears the tissue between bone pieces); {why}",
            mesh.tets.len()
        ));
    }
    Damage {
        inverted,
        at_cuts,
        torn_elements,
        torn_volume_mm3,
    }
}

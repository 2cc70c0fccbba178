//! The pipeline as a library: cases built in memory, the stages' typed outputs, structured errors,
//! and defects once found in it (each of these tests failed before its fix).

use crate::common;

use common::phantom_dir;
use facesim::case::{Case, CtSection, Osteotomy, PathSection, Region, SolveModel};
use facesim::commands::{self, Outcome};
use facesim::error::Error;
use facesim::observe::Quiet;
use std::path::PathBuf;

/// The phantom case of data-samples/phantom, built in memory (no case.toml), with a coarse
/// tetrahedral mesh: these tests check the stages around the solve, not its accuracy (CI time).
fn phantom_case() -> Case {
    let mut case = Case {
        name: Some("in memory".into()),
        ct: CtSection::new(phantom_dir().join("ct.nii.gz")),
        skin: Some(PathSection {
            path: phantom_dir().join("face.ply"),
        }),
        osteotomy: vec![Osteotomy {
            name: "mandible".into(),
            region: Region::Box {
                min: [-70.0, -75.0, -125.0],
                max: [70.0, -1.5, -26.5],
            },
            translate: [0.0, -6.0, 0.0],
            rotate_deg: [0.0; 3],
            pivot: [0.0; 3],
        }],
        ..Case::default()
    };
    case.tet.skin_size_mm = 12.0;
    case.tet.deep_size_mm = 24.0;
    case
}

const TET_SKIPS_WITHOUT_MOVE: [&str; 5] = ["coarsen", "tet_mesh", "solve", "embed", "plan_basis"];
// The phantom's CT holds the clinical frame: the anatomy stage runs for a plan of
// [[osteotomy]] regions too (the report's frame and the page's views), and cuts nothing.
const TET_SKIPS: [&str; 1] = ["coarsen"];

const MOVABLE: ([f64; 3], f64) = ([0.0, -60.0, -45.0], 70.0);

fn run(case: Case) -> facesim::Result<Outcome> {
    commands::run_case(case, &common::out_dir("facesim-pipeline"), &Quiet)
}

fn displacement(o: &Outcome) -> Vec<f64> {
    o.skin
        .vertices
        .iter()
        .zip(&o.face_post.vertices)
        .map(|(a, b)| facesim::vec3::norm(facesim::vec3::sub(*a, *b)))
        .collect()
}

fn distance_to_centre(p: [f64; 3]) -> f64 {
    facesim::vec3::norm(facesim::vec3::sub(p, MOVABLE.0))
}

#[test]
fn a_movable_mask_selects_the_skin_it_covers() {
    // Before the fix an unread mask selected nothing: every skin vertex was rigid and the run
    // failed with "no skin vertex found bone within 40 mm".
    let ct = facesim::volume::read_volume(&phantom_dir().join("ct.nii.gz")).unwrap();
    let mut mask = ct.clone();
    for (i, v) in mask.data.iter_mut().enumerate() {
        let p = ct.to_world(ct.ijk(i).map(|x| x as f64));
        *v = if distance_to_centre(p) <= MOVABLE.1 {
            1.0
        } else {
            0.0
        };
    }
    let path = common::kept_dir("facesim-mask").join("movable.nii.gz");
    facesim::volume::nifti_io::write(&mask, &path).unwrap();

    let mut by_mask = phantom_case();
    by_mask.surface.movable = Some(Region::Mask(PathBuf::from(&path).into()));
    let mut by_sphere = phantom_case();
    by_sphere.surface.movable = Some(Region::Sphere {
        center: MOVABLE.0,
        radius: MOVABLE.1,
    });
    let (m, s) = (run(by_mask).unwrap(), run(by_sphere).unwrap());
    let (dm, ds) = (displacement(&m), displacement(&s));
    let peak = ds.iter().cloned().fold(0.0, f64::max);
    assert!(peak > 1.0, "the plan moves the face ({peak} mm)");
    // The mask is the sphere voxelised (1.5 mm voxels): away from its boundary the two runs
    // agree on which skin is rigid, and outside it nothing moves — but within the skin
    // elements (12 mm here; twice that for the tetrahedra along the edge) that reach across its
    // edge, where the face stays continuous with the face inside.
    let diagonal = 1.5 * 3f64.sqrt();
    let reach = 2.0 * phantom_case().tet.skin_size_mm;
    for ((p, a), b) in m.skin.vertices.iter().zip(&dm).zip(&ds) {
        if distance_to_centre(*p) > MOVABLE.1 + diagonal + reach {
            assert_eq!((*a, *b), (0.0, 0.0), "rigid skin moved at {p:?}");
        }
    }
    let peak_mask = dm.iter().cloned().fold(0.0, f64::max);
    assert!(
        (peak_mask - peak).abs() < 0.1 * peak,
        "mask {peak_mask} mm vs sphere {peak} mm"
    );
}

#[test]
fn a_movable_region_without_skin_is_refused_naming_the_region() {
    let mut case = phantom_case();
    case.surface.movable = Some(Region::Sphere {
        center: [0.0, 0.0, 5000.0],
        radius: 10.0,
    });
    let e = run(case).err().unwrap();
    assert!(matches!(e, Error::Config(_)), "{e:?}");
    assert!(e.to_string().contains("[surface] movable"), "{e}");
}

#[test]
fn stages_not_run_says_which_optional_stages_a_case_skipped() {
    // Before the fix the list was always empty. The C1 model: no coarse copy of the scan, and
    // no embedding without one.
    let c1 = || {
        let mut case = phantom_case();
        case.solve.model = SolveModel::Equilibrium;
        case
    };
    let mut case = c1();
    case.osteotomy.clear();
    let o = run(case).unwrap();
    let skipped: Vec<&str> = o
        .report
        .stages_not_run
        .iter()
        .map(|s| s.stage.as_str())
        .collect();
    assert_eq!(skipped, ["coarsen", "solve", "embed"]);
    assert!(displacement(&o).iter().all(|d| *d == 0.0));
    let o = run(c1()).unwrap();
    let skipped: Vec<&str> = o
        .report
        .stages_not_run
        .iter()
        .map(|s| s.stage.as_str())
        .collect();
    assert_eq!(skipped, ["coarsen", "embed"]);
    // The volumetric model (the default) carries the scan whole: it never coarsens, and with
    // no bone move it neither meshes nor solves.
    let mut case = phantom_case();
    case.osteotomy.clear();
    let o = run(case).unwrap();
    let skipped: Vec<&str> = o
        .report
        .stages_not_run
        .iter()
        .map(|s| s.stage.as_str())
        .collect();
    assert_eq!(skipped, TET_SKIPS_WITHOUT_MOVE);
    assert!(displacement(&o).iter().all(|d| *d == 0.0));
    let o = run(phantom_case()).unwrap();
    let skipped: Vec<&str> = o
        .report
        .stages_not_run
        .iter()
        .map(|s| s.stage.as_str())
        .collect();
    assert_eq!(skipped, TET_SKIPS);
    let frame = o
        .report
        .clinical_frame
        .as_ref()
        .expect("the phantom's clinical frame");
    // The one [[osteotomy]] step read back in the clinical frame.
    assert_eq!(o.report.plan.as_ref().map(|p| p.segments.len()), Some(1));
    assert!(!frame.why.is_empty());
}

#[test]
fn input_problems_are_input_errors_naming_the_file() {
    // A marching-tetrahedra skin of the phantom folds over in the cylindrical (u, v) map: a
    // property of the surface, reported against the CT it came from (was a "numerical failure").
    // The (u, v) map is the C1 model's.
    let mut case = phantom_case();
    case.solve.model = SolveModel::Equilibrium;
    case.skin = None;
    case.extract.method = facesim::case::ExtractMethod::Marching;
    match run(case).err().unwrap() {
        Error::Input { path, msg } => {
            assert_eq!(path, phantom_dir().join("ct.nii.gz"));
            assert!(msg.contains("folds over"), "{msg}");
        }
        e => panic!("expected an input error, got {e:?}"),
    }
    // Bone windows above every voxel: no skull surface, an input error about the CT.
    let mut case = phantom_case();
    case.tissue.bone = 5000.0;
    match run(case).err().unwrap() {
        Error::Input { path, msg } => {
            assert_eq!(path, phantom_dir().join("ct.nii.gz"));
            assert!(msg.contains("bone"), "{msg}");
        }
        e => panic!("expected an input error, got {e:?}"),
    }
}

#[test]
fn an_impossible_plan_is_matched_by_kind_not_by_text() {
    // The C1 model's check: the skin hangs on springs, so bone can pass through it. (In the
    // volumetric model the tissue follows its bone; such a move is a warning there.)
    let mut case = phantom_case();
    case.solve.model = SolveModel::Equilibrium;
    case.osteotomy[0].translate = [0.0, -60.0, 0.0];
    let e = run(case).err().unwrap();
    assert!(
        matches!(e, Error::ImpossiblePlan { file: Some(_), .. }),
        "{e:?}"
    );
    assert!(e.to_string().contains("impossible plan"), "{e}");
}

//! The real CT (ProMED CT 0051 from Debian's invesalius-examples): one skin, one skull, and the
//! head rest left out.

use crate::common;

use facesim::case::Case;
use facesim::segment;
use facesim::surface::rangescan;
use facesim::volume::read_volume;
use std::path::Path;

fn run_real(extra: &str) -> facesim::commands::Outcome {
    let ct = common::real_ct();
    let dir = common::kept_dir("facesim-real");
    std::fs::write(
        dir.join("case.toml"),
        format!("[ct]\npath = \"{}\"\n{extra}", ct.display()),
    )
    .unwrap();
    facesim::commands::run(&dir, None, &facesim::observe::Quiet).unwrap()
}

#[test]
fn real_ct_reads_in_lps_with_the_face_anterior() {
    let v = read_volume(&common::real_ct()).unwrap();
    assert_eq!(v.dims, [256, 256, 108]);
    assert!((v.spacing[0] - 0.9570312).abs() < 1e-6 && (v.spacing[2] - 1.5).abs() < 1e-12);
    assert!(v.data.iter().all(|x| (-1024.0..=3071.0).contains(x)));
}

#[test]
fn real_ct_gives_one_skin_and_one_skull_without_the_head_rest() {
    let o = run_real("");
    let seg = &o.segmentation;
    let vol = &o.volume;
    let r = &seg.report;
    println!(
        "head {} voxels; removed {} pieces ({} voxels); bone kept {} dropped {} ({} voxels); cavities {} voxels",
        r.head_voxels,
        r.removed_components,
        r.removed_voxels,
        r.bone_components_kept,
        r.bone_components_dropped,
        r.bone_voxels_dropped,
        r.cavity_voxels
    );
    println!(
        "skin {} vertices / {} triangles; skull {} / {}",
        o.skin.vertices.len(),
        o.skin.triangles.len(),
        o.skull.vertices.len(),
        o.skull.triangles.len()
    );
    // The head rest is above the head threshold but not part of the head.
    assert!(
        r.removed_components >= 1 && r.removed_voxels > 10_000,
        "the head-rest arc should be found and dropped"
    );
    assert_eq!(o.skin.components().1, 1, "one skin surface");
    assert_eq!(o.skull.components().1, 1, "one skull surface");
    // No surface vertex sits on a dropped piece: the voxel nearest each vertex, and its
    // neighbours, belong to the head or to air.
    let dropped = |p: [f64; 3]| {
        let c = vol.to_voxel(p).map(|x| x.round() as i64);
        let mut hit = false;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let q = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if (0..3).all(|a| q[a] >= 0 && q[a] < vol.dims[a] as i64) {
                        let i = vol.idx(q[0] as usize, q[1] as usize, q[2] as usize);
                        hit |= !seg.head[i] && vol.data[i] as f64 > seg.windows.head_threshold;
                    }
                }
            }
        }
        hit
    };
    let on_rest = o
        .skin
        .vertices
        .iter()
        .chain(&o.skull.vertices)
        .filter(|p| dropped(**p))
        .count();
    assert_eq!(
        on_rest, 0,
        "{on_rest} surface vertices touch the dropped head rest"
    );

    // The same scan on the raw HU (no clean-up) does hit the head rest: the check above can fail.
    let raw = rangescan::scan(
        vol,
        &vol.data,
        &vol.data,
        &seg.head,
        &rangescan::ScanParams {
            angle_step_deg: 2.0,
            z_step: 1.5,
            skin_iso: -500.0,
            bone_iso: 300.0,
            max_skull_depth: 40.0,
        },
    );
    let raw_on_rest = raw.skin.vertices.iter().filter(|p| dropped(**p)).count();
    println!("raw-HU range scan: {raw_on_rest} skin vertices on the head rest");
    assert!(raw_on_rest > 100);

    // The face is anterior (−y): the nose tip is the most anterior skin point, in the middle
    // third of the head's width.
    let tip = o
        .skin
        .vertices
        .iter()
        .min_by(|a, b| a[1].total_cmp(&b[1]))
        .unwrap();
    let (lo, hi) = o.skin.bounds();
    assert!(
        (tip[0] - 0.5 * (lo[0] + hi[0])).abs() < (hi[0] - lo[0]) / 6.0,
        "nose tip {tip:?}"
    );
}

#[test]
fn real_ct_fit_windows_are_close_to_the_literature_windows() {
    let vol = read_volume(&common::real_ct()).unwrap();
    let mut case = Case::parse(
        "[ct]\npath = \"x.nii\"\n[tissue]\nmethod = \"fit\"\n",
        Path::new("case.toml"),
    )
    .unwrap();
    let fit = segment::segment(&vol, &case.tissue, Path::new("real")).unwrap();
    case.tissue.method = facesim::case::TissueMethod::Windows;
    let win = segment::segment(&vol, &case.tissue, Path::new("real")).unwrap();
    let w = &fit.windows;
    println!("fit windows {w:?}; mixture {:?}", fit.report.mixture);
    assert!((-60.0..=0.0).contains(&w.soft), "fat/soft bound {}", w.soft);
    assert!(
        (200.0..=700.0).contains(&w.bone),
        "soft/bone bound {}",
        w.bone
    );
    // Every class keeps a real share of the head (no component collapsed onto a spike).
    for g in fit.report.mixture.as_ref().unwrap() {
        assert!(g.weight > 0.01, "{} collapsed: {g:?}", g.name);
    }
    // Both methods find a skull of plausible size (adult skull bone: several hundred cm³ in
    // a field of view from the teeth up), within 25% of each other.
    let vv = vol.voxel_volume() / 1000.0;
    let (b1, b2) = (
        fit.count(segment::BONE) as f64 * vv,
        win.count(segment::BONE) as f64 * vv,
    );
    println!("bone: fit {b1:.0} cm³, windows {b2:.0} cm³");
    assert!(b1 > 200.0 && b2 > 200.0 && (b1 / b2 - 1.0).abs() < 0.25);
}

#[test]
fn real_ct_decimation_reaches_its_target_or_is_undone_with_a_warning() {
    let o = run_real("[extract]\nsmooth_iterations = 3\ndecimate_target = 10000\n");
    println!(
        "range scan decimated: skin {} triangles, skull {}",
        o.skin.triangles.len(),
        o.skull.triangles.len()
    );
    assert!(o.skin.triangles.len() <= 10000 && o.skull.triangles.len() <= 10000);
    assert_eq!(o.skin.components().1, 1);
    o.skin.check(Path::new("skin")).unwrap();
    let m = run_real("[extract]\nmethod = \"marching\"\ndecimate_target = 100000\n");
    m.skin.check(Path::new("skin")).unwrap();
    let undone = m
        .report
        .warnings
        .iter()
        .any(|w| w.contains("decimation of the skin was undone"));
    println!(
        "marching skin {} triangles, decimation undone: {undone}",
        m.skin.triangles.len()
    );
    assert!(undone || m.skin.triangles.len() <= 100000);
}

#[test]
fn real_ct_maxillary_advancement_moves_the_upper_lip_more_than_the_nose_and_not_the_forehead() {
    let ct = common::real_ct();
    let case_dir = ct.parent().unwrap();
    // `out` inside the temporary directory: its parent, where the output library keeps its
    // temporaries, is then this test's alone and not the system's temporary directory.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let o = facesim::commands::run(case_dir, Some(&out), &facesim::observe::Quiet).unwrap();
    let pre = &o.skin.vertices;
    let post = &o.face_post.vertices;
    let tip = (0..pre.len())
        .min_by(|&a, &b| pre[a][1].total_cmp(&pre[b][1]))
        .unwrap();
    let xc = pre[tip][0];
    let front = |z0: f64, z1: f64| {
        (0..pre.len())
            .filter(|&i| (pre[i][0] - xc).abs() < 3.0 && pre[i][2] >= z0 && pre[i][2] <= z1)
            .min_by(|&a, &b| pre[a][1].total_cmp(&pre[b][1]))
            .unwrap()
    };
    let (lip, forehead) = (front(8.0, 20.0), front(110.0, 130.0));
    let dy = |i: usize| pre[i][1] - post[i][1]; // anterior movement (−y), mm
    println!(
        "5 mm maxillary advancement: upper lip {:.2} mm, nose tip {:.2} mm, forehead {:.2e} mm",
        dy(lip),
        dy(tip),
        dy(forehead)
    );
    assert!(
        dy(lip) > 1.0 && dy(lip) > 2.0 * dy(tip),
        "lip {} nose {}",
        dy(lip),
        dy(tip)
    );
    assert!(dy(forehead).abs() < 1e-6);
    // Two boxes (docs/design/pipeline.md "Region"): the face region, inside the CT, and the tissue
    // mesh's, the region grown by margin_mm once more, which holds every node. The scan ends
    // through the upper lip (z = 0): there the tissue ends in a surface half a voxel past the
    // last slice, free by default (`[tet] scan_end = "free"`; `"slides"` holds it on the scan's
    // end plane), not in a held face at it.
    let tet = o.report.tet.as_ref().expect("the volumetric model ran");
    let margin = 30.0;
    let (lo, hi) = tet.mesh_box.expect("report.json tet.mesh_box");
    let (vlo, vhi) = o.volume.bounds();
    // The upper corner is rounded up to whole cells of the lattice's coarsest size (8 mm).
    for k in 0..3 {
        assert!((lo[k] - (tet.region.0[k] - margin)).abs() < 1e-9, "{k}");
        let over = hi[k] - (tet.region.1[k] + margin);
        assert!((-1e-9..8.0).contains(&over), "{k}: {over}");
        assert!(
            tet.region.0[k] >= vlo[k] && tet.region.1[k] <= vhi[k],
            "{k}"
        );
    }
    let mesh = facesim::tet::vtu::read(&out.join("tets.vtu")).unwrap();
    assert!(
        mesh.nodes
            .iter()
            .all(|p| (0..3).all(|k| p[k] >= lo[k] - 1e-9 && p[k] <= hi[k] + 1e-9))
    );
    let past_end: Vec<u8> = mesh
        .nodes
        .iter()
        .zip(&mesh.constraint)
        .filter(|(p, _)| p[2] < vlo[2] - 0.1)
        .map(|(_, c)| *c)
        .collect();
    // (Held there, no node would lie past the last slice. Most of these are bone, or skin
    // outside [surface] movable, held as anywhere else; the lip's and the mouth's are free:
    // constraint 0. Those sliding there slide on the teeth, as mucosa or in contact.)
    let sliding = past_end.iter().filter(|c| **c == 3).count();
    let free = past_end.iter().filter(|c| **c == 0).count();
    assert!(
        past_end.len() > 500 && free > 20 * sliding,
        "of {} nodes past the scan's end {sliding} slide and {free} are free",
        past_end.len()
    );
    // report.json says where: the lip and the mouth at the scan's end, beside the moved teeth.
    let end = tet.scan_end.expect("report.json tet.scan_end");
    assert!(
        end.sliding_nodes == 0 && end.free_nodes > 0 && end.free_nodes <= free,
        "{end:?}"
    );
    assert!(end.nearest_moved_bone_mm < 10.0, "{end:?}");
    // The default model is the volumetric one: its mesh, no springs.
    for f in [
        "face_post.obj",
        "face_post.ply",
        "skull_post.ply",
        "tets.vtu",
        "plan_basis.bin",
        "report.html",
        "displacement.csv",
        "face_displacement.ply",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
}

#[test]
fn a_stiffer_nose_region_deforms_less() {
    // Per-region α/β of the C1 model (Koch §4.2: higher values for cartilage, e.g. the nose): a
    // stiff nose is carried along more as a unit, so the displacement varies less across it.
    let ct = common::real_ct();
    let base = std::fs::read_to_string(ct.parent().unwrap().join("case.toml")).unwrap();
    let run_with = |extra: &str| {
        let d = tempfile::tempdir().unwrap();
        let text = base.replace(
            "path = \"Cranium.inv3\"",
            &format!("path = \"{}\"", ct.display()),
        ) + "\n[solve]\nmodel = \"equilibrium\"\n"
            + extra;
        std::fs::write(d.path().join("case.toml"), text).unwrap();
        let o = facesim::commands::run(d.path(), None, &facesim::observe::Quiet).unwrap();
        let v = &o.skin.vertices;
        let tip = (0..v.len())
            .min_by(|&a, &b| v[a][1].total_cmp(&v[b][1]))
            .unwrap();
        let d = |i: usize| facesim::vec3::sub(o.face_post.vertices[i], v[i]);
        let spread = (0..v.len())
            .filter(|&i| facesim::vec3::norm(facesim::vec3::sub(v[i], v[tip])) < 10.0)
            .map(|i| facesim::vec3::norm(facesim::vec3::sub(d(i), d(tip))))
            .fold(0.0, f64::max);
        (facesim::vec3::norm(d(tip)), spread)
    };
    let (soft_tip, soft) = run_with("");
    let (stiff_tip, stiff) = run_with(
        "\n[[surface.region]]\nshape = { sphere = { center = [122.7, 10.9, 34.5], radius = 20.0 } }\nalpha = 1.0\nbeta = 10.0\n",
    );
    println!(
        "nose within 10 mm of the tip: displacement spread {soft:.3} mm (tip {soft_tip:.3}) default, {stiff:.3} mm (tip {stiff_tip:.3}) stiff"
    );
    assert!(stiff < 0.8 * soft, "{stiff} vs {soft}");
}

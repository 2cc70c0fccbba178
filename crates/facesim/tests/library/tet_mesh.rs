//! Tetrahedral meshing by isosurface stuffing (Labelle & Shewchuk 2007): analytic spheres and
//! shells checked against exact volumes, surfaces and the paper's proven angle bounds; the box
//! restriction; the phantom's and the real CT's soft tissue.

use facesim::tet::quality::Quality;
use facesim::tet::stuffing::{self, MAX_DIHEDRAL_BOUND_DEG, MIN_DIHEDRAL_BOUND_DEG, NodeKind};
use facesim::vec3::{cross, dot, norm, sub};
use std::collections::HashMap;
use std::f64::consts::PI;

/// Faces (sorted node triples) and how many tetrahedra use each.
fn face_counts(tets: &[[u32; 4]]) -> HashMap<[u32; 3], usize> {
    let mut m = HashMap::new();
    for t in tets {
        for skip in 0..4 {
            let mut f = [0u32; 3];
            let mut k = 0;
            for (i, v) in t.iter().enumerate() {
                if i != skip {
                    f[k] = *v;
                    k += 1;
                }
            }
            f.sort_unstable();
            *m.entry(f).or_insert(0) += 1;
        }
    }
    m
}

/// Every face is used by one or two tetrahedra; the boundary (faces used once) is a closed
/// 2-manifold: every boundary edge is shared by exactly two boundary faces. Returns the
/// boundary faces.
fn check_conforming(tets: &[[u32; 4]], closed: bool) -> Vec<[u32; 3]> {
    let faces = face_counts(tets);
    assert!(
        faces.values().all(|c| *c == 1 || *c == 2),
        "a face is shared by more than two tetrahedra"
    );
    let boundary: Vec<[u32; 3]> = faces
        .iter()
        .filter(|(_, c)| **c == 1)
        .map(|(f, _)| *f)
        .collect();
    if closed {
        let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
        for f in &boundary {
            for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[0], f[2])] {
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let bad = edges.values().filter(|c| **c != 2).count();
        assert_eq!(
            bad, 0,
            "{bad} boundary edges not shared by exactly two faces"
        );
    }
    boundary
}

fn assert_bounds(q: &Quality) {
    assert_eq!(q.inverted, 0);
    assert!(
        q.min_dihedral_deg >= MIN_DIHEDRAL_BOUND_DEG
            && q.max_dihedral_deg <= MAX_DIHEDRAL_BOUND_DEG,
        "dihedral angles {:.2}°..{:.2}° outside the proven [{MIN_DIHEDRAL_BOUND_DEG}, {MAX_DIHEDRAL_BOUND_DEG}]",
        q.min_dihedral_deg,
        q.max_dihedral_deg
    );
}

#[test]
fn a_sphere_is_filled_with_bounded_angles_and_converging_volume() {
    let r = 10.0;
    let c = [0.31, -0.17, 0.23];
    let f = move |p: [f64; 3]| norm([p[0] - c[0], p[1] - c[1], p[2] - c[2]]) - r;
    let exact = 4.0 / 3.0 * PI * r.powi(3);
    let mut errors = Vec::new();
    for h in [2.0, 1.0, 0.5] {
        let m = stuffing::stuff(&f, [-12.0; 3], [12.0; 3], h).unwrap();
        let q = Quality::of(&m.nodes, &m.tets);
        assert_bounds(&q);
        let boundary = check_conforming(&m.tets, true);
        for (p, k) in m.nodes.iter().zip(&m.kind) {
            let d = f(*p);
            match k {
                NodeKind::Surface => assert!(d.abs() < 1e-3 * h, "surface node off by {d}"),
                NodeKind::Interior => assert!(d < 0.0),
                NodeKind::Cut => panic!("nothing is cut"),
            }
        }
        for b in &boundary {
            assert!(b.iter().all(|v| m.kind[*v as usize] == NodeKind::Surface));
        }
        let e = (q.volume_mm3 - exact).abs() / exact;
        println!(
            "sphere h = {h}: {} nodes, {} tets, dihedral {:.2}°..{:.2}°, worst ratio {:.2}, volume error {:.3e}",
            q.nodes, q.tets, q.min_dihedral_deg, q.max_dihedral_deg, q.worst_aspect_ratio, e
        );
        errors.push(e);
    }
    // Inscribed polyhedron: volume error O(h²); halving h quarters it (rate ≥ 1.7 allowed).
    for w in errors.windows(2) {
        assert!(w[1] < w[0] / 2f64.powf(1.7), "{errors:?}");
    }
}

/// Spherical cap volume of height `c` on a ball of radius `r`.
fn cap(r: f64, c: f64) -> f64 {
    PI * c * c * (3.0 * r - c) / 3.0
}

/// The shell r1 < r < r2 ("soft tissue between bone and skin").
fn shell(r1: f64, r2: f64) -> impl Fn([f64; 3]) -> f64 + Sync {
    move |p| (r1 - norm(p)).max(norm(p) - r2)
}

#[test]
fn a_shell_has_both_surfaces_bounded_angles_and_second_order_volume() {
    let (r1, r2) = (6.0, 10.0);
    let f = shell(r1, r2);
    let exact = 4.0 / 3.0 * PI * (r2.powi(3) - r1.powi(3));
    let mut errors = Vec::new();
    for h in [1.6, 0.8, 0.4] {
        let m = stuffing::stuff(&f, [-11.0; 3], [11.0; 3], h).unwrap();
        let q = Quality::of(&m.nodes, &m.tets);
        assert_bounds(&q);
        let boundary = check_conforming(&m.tets, true);
        let on_sphere = |p: [f64; 3]| (norm(p) - r1).abs().min((norm(p) - r2).abs());
        for (p, k) in m.nodes.iter().zip(&m.kind) {
            if *k == NodeKind::Surface {
                assert!(on_sphere(*p) < 1e-3 * h, "{p:?} off both spheres");
            }
        }
        // Each boundary face lies on one sphere: all three nodes on the same one.
        let (mut inner, mut outer) = (0, 0);
        for b in &boundary {
            let r: Vec<f64> = b.iter().map(|v| norm(m.nodes[*v as usize])).collect();
            if r.iter().all(|x| (x - r1).abs() < 1e-3 * h) {
                inner += 1;
            } else if r.iter().all(|x| (x - r2).abs() < 1e-3 * h) {
                outer += 1;
            } else {
                panic!("boundary face with radii {r:?}");
            }
        }
        assert!(inner > 0 && outer > inner);
        let e = (q.volume_mm3 - exact).abs() / exact;
        println!(
            "shell h = {h}: {} nodes, {} tets, dihedral {:.2}°..{:.2}°, worst ratio {:.2}, volume error {:.3e}",
            q.nodes, q.tets, q.min_dihedral_deg, q.max_dihedral_deg, q.worst_aspect_ratio, e
        );
        errors.push(e);
    }
    for w in errors.windows(2) {
        assert!(w[1] < w[0] / 2f64.powf(1.7), "{errors:?}");
    }
}

#[test]
fn a_box_cuts_the_shell_on_lattice_planes_with_cut_nodes() {
    let (r1, r2) = (6.0, 10.0);
    let f = shell(r1, r2);
    // The top face z = 2 lies on a lattice plane: a whole number of cubes above z = −12.
    let exact = 4.0 / 3.0 * PI * (r2.powi(3) - r1.powi(3)) - cap(r2, r2 - 2.0) + cap(r1, r1 - 2.0);
    let mut errors = Vec::new();
    for h in [1.0, 0.5] {
        let m = stuffing::stuff(&f, [-12.0; 3], [12.0, 12.0, 2.0], h).unwrap();
        let q = Quality::of(&m.nodes, &m.tets);
        assert_bounds(&q);
        let boundary = check_conforming(&m.tets, true);
        let on_plane = |p: [f64; 3]| (p[2] - 2.0).abs() < 1e-12;
        let mut cut = 0;
        for (p, k) in m.nodes.iter().zip(&m.kind) {
            assert!(p[2] <= 2.0 + 1e-12, "a node above the cut: {p:?}");
            if *k == NodeKind::Cut {
                cut += 1;
                assert!(on_plane(*p), "cut node {p:?} off the plane z = 2");
                assert!(f(*p) < 0.0);
            }
        }
        assert!(cut > 50, "{cut} cut nodes");
        let mut cut_faces = 0;
        for b in &boundary {
            let x = b.map(|v| m.nodes[v as usize]);
            if x.iter().all(|p| on_plane(*p)) {
                cut_faces += 1;
            } else {
                // On a sphere, or chamfering the crease where a sphere meets the plane
                // (stuffing does not keep sharp creases): never an interior node.
                assert!(
                    b.iter().all(|v| m.kind[*v as usize] != NodeKind::Interior),
                    "boundary face off the cut with an interior node"
                );
            }
        }
        assert!(cut_faces > 50);
        // Shell ∩ {z < 2}: each ball minus its cap above z = 2.
        let e = (q.volume_mm3 - exact).abs() / exact;
        println!(
            "cut shell h = {h}: {} nodes ({cut} cut), {} tets, dihedral {:.2}°..{:.2}°, volume error {e:.3e}",
            q.nodes, q.tets, q.min_dihedral_deg, q.max_dihedral_deg
        );
        errors.push(e);
    }
    assert!(
        errors[0] < 1e-2 && errors[1] < errors[0] / 2f64.powf(1.7),
        "{errors:?}"
    );
    // Everything inside the box: the box alone is meshed exactly (its volume to rounding).
    let all = |_: [f64; 3]| -1.0;
    let b = stuffing::stuff(&all, [-3.0, -2.0, -1.0], [3.0, 2.0, 4.0], 1.0).unwrap();
    let qb = Quality::of(&b.nodes, &b.tets);
    assert!((qb.volume_mm3 - 120.0).abs() < 1e-9, "{}", qb.volume_mm3);
    check_conforming(&b.tets, true);
    assert!(b.kind.iter().all(|k| *k != NodeKind::Surface));
}

#[test]
fn stuffing_many_offsets_never_leaves_the_angle_bounds() {
    // The sphere's position relative to the lattice decides which stencils and warps occur;
    // sweep it so that near-vertex, near-edge and near-face cut points all happen.
    let mut worst: (f64, f64) = (180.0, 0.0);
    for i in 0..24 {
        let t = i as f64 / 24.0;
        let c = [0.37 * t, 0.71 * t * t, (0.53 * t).sin()];
        let r = 4.0 + 0.9 * t;
        let f = move |p: [f64; 3]| norm([p[0] - c[0], p[1] - c[1], p[2] - c[2]]) - r;
        let m = stuffing::stuff(&f, [-6.0; 3], [6.0; 3], 0.7).unwrap();
        let q = Quality::of(&m.nodes, &m.tets);
        assert_bounds(&q);
        check_conforming(&m.tets, true);
        worst = (
            worst.0.min(q.min_dihedral_deg),
            worst.1.max(q.max_dihedral_deg),
        );
    }
    println!("24 spheres: dihedral {:.2}°..{:.2}°", worst.0, worst.1);
}

#[test]
fn bad_input_is_a_one_line_error() {
    let f = |_: [f64; 3]| -1.0;
    assert!(stuffing::stuff(&f, [0.0; 3], [1.0; 3], 0.0).is_err());
    assert!(stuffing::stuff(&f, [0.0; 3], [-1.0, 1.0, 1.0], 0.5).is_err());
    assert!(stuffing::stuff(&f, [0.0; 3], [1e4; 3], 0.01).is_err());
    let nan = |_: [f64; 3]| f64::NAN;
    assert!(stuffing::stuff(&nan, [0.0; 3], [1.0; 3], 0.5).is_err());
}

// ---- The CT layer -------------------------------------------------------------------------

use crate::common;

use facesim::case::Case;
use facesim::segment::{self, FAT_BRIGHT, FAT_DARK, MUSCLE, SKIN, Segmentation};
use facesim::surface::marching;
use facesim::tet::from_ct::{self, MeshParams, SoftTissueMesh};
use facesim::volume::{Volume, sample_field};
use std::path::Path;

fn segmented(vol: &Volume) -> Segmentation {
    let case = Case::parse("[ct]\npath = \"ct.nii.gz\"\n", Path::new("case.toml")).unwrap();
    segment::segment(vol, &case.tissue, Path::new("ct.nii.gz")).unwrap()
}

/// Distance from p to the segment ab.
fn segment_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let t = (dot(sub(p, a), ab) / dot(ab, ab).max(1e-300)).clamp(0.0, 1.0);
    norm(sub(
        p,
        [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]],
    ))
}

/// Distance from p to the triangle abc: to its plane when the projection falls inside,
/// else to the nearest edge.
fn triangle_distance(p: [f64; 3], t: [[f64; 3]; 3]) -> f64 {
    let (e0, e1) = (sub(t[1], t[0]), sub(t[2], t[0]));
    let n = cross(e0, e1);
    let nn = dot(n, n);
    if nn > 0.0 {
        let d = dot(sub(p, t[0]), n) / nn;
        let q = [p[0] - d * n[0], p[1] - d * n[1], p[2] - d * n[2]];
        // Barycentric signs: q inside when on the inner side of each edge.
        let inside = (0..3).all(|k| {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let c = sub(b, a);
            let w = sub(q, a);
            let x = [
                c[1] * w[2] - c[2] * w[1],
                c[2] * w[0] - c[0] * w[2],
                c[0] * w[1] - c[1] * w[0],
            ];
            dot(x, n) >= 0.0
        });
        if inside {
            return d.abs() * nn.sqrt();
        }
    }
    (0..3)
        .map(|k| segment_distance(p, t[k], t[(k + 1) % 3]))
        .fold(f64::INFINITY, f64::min)
}

/// Distance from each query point to a triangle mesh, through a uniform grid of buckets
/// (a point farther than `reach` from every triangle reports ≥ reach).
fn distances(mesh: &facesim::mesh::Mesh, queries: &[[f64; 3]], reach: f64) -> Vec<f64> {
    let cell = reach.max(1.0);
    let key = |p: [f64; 3]| p.map(|x| (x / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    for (i, t) in mesh.triangles.iter().enumerate() {
        let x = t.map(|v| mesh.vertices[v as usize]);
        let lo = key([0, 1, 2].map(|a| x.iter().map(|p| p[a]).fold(f64::INFINITY, f64::min)));
        let hi = key([0, 1, 2].map(|a| x.iter().map(|p| p[a]).fold(f64::NEG_INFINITY, f64::max)));
        for i0 in lo[0]..=hi[0] {
            for i1 in lo[1]..=hi[1] {
                for i2 in lo[2]..=hi[2] {
                    grid.entry([i0, i1, i2]).or_default().push(i as u32);
                }
            }
        }
    }
    queries
        .iter()
        .map(|q| {
            let k = key(*q);
            let mut best = reach;
            for d0 in -1..=1 {
                for d1 in -1..=1 {
                    for d2 in -1..=1 {
                        for t in grid
                            .get(&[k[0] + d0, k[1] + d1, k[2] + d2])
                            .into_iter()
                            .flatten()
                        {
                            let x = mesh.triangles[*t as usize].map(|v| mesh.vertices[v as usize]);
                            best = best.min(triangle_distance(*q, x));
                        }
                    }
                }
            }
            best
        })
        .collect()
}

fn assert_ct_mesh(m: &SoftTissueMesh) {
    assert_bounds(&m.quality);
    assert!(
        m.tets
            .iter()
            .all(|t| facesim::tet::gradients(t.map(|n| m.nodes[n as usize])).is_some())
    );
    assert_eq!(m.tissue.len(), m.tets.len());
    assert_eq!(m.kind.len(), m.nodes.len());
    assert!(
        m.tissue
            .iter()
            .all(|l| [SKIN, FAT_DARK, FAT_BRIGHT, MUSCLE].contains(l))
    );
    check_conforming(&m.tets, false);
}

#[test]
fn phantom_soft_tissue_conforms_to_the_skin_and_bone_iso_surfaces() {
    let vol = facesim_validate::phantom::ct(&facesim_validate::phantom::PhantomOptions::default());
    let seg = segmented(&vol);
    let roi = ([-50.0, -100.0, -45.0], [50.0, -30.0, 35.0]);
    let p = MeshParams {
        skin_size_mm: 2.0,
        deep_size_mm: 4.0,
        margin_mm: 0.0,
    };
    let m = from_ct::soft_tissue(&vol, &seg, roi, &p).unwrap();
    assert_ct_mesh(&m);
    assert_eq!(m.tissue_fallbacks, 0);
    let count = |k: from_ct::NodeKind| m.kind.iter().filter(|x| **x == k).count();
    let (skin_n, bone_n, cut_n) = (
        count(from_ct::NodeKind::Skin),
        count(from_ct::NodeKind::Bone),
        count(from_ct::NodeKind::Cut),
    );
    let q = &m.quality;
    println!(
        "phantom: {} nodes ({skin_n} skin, {bone_n} bone, {cut_n} cut), {} tets, dihedral {:.2}°..{:.2}°, worst ratio {:.2}, volume {:.0} mm³ + {:.0} enclosed left out (voxels {:.0})",
        q.nodes,
        q.tets,
        q.min_dihedral_deg,
        q.max_dihedral_deg,
        q.worst_aspect_ratio,
        q.volume_mm3,
        m.dropped_volume_mm3,
        m.voxel_volume_mm3
    );
    assert!(skin_n > 500 && bone_n > 500 && cut_n > 100);
    assert!(((q.volume_mm3 + m.dropped_volume_mm3) / m.voxel_volume_mm3 - 1.0).abs() < 0.03);
    // Every soft label of the phantom occurs (skin, fat, muscle).
    for l in [SKIN, MUSCLE] {
        assert!(m.tissue.contains(&l), "label {l} missing");
    }
    assert!(m.tissue.contains(&FAT_DARK) || m.tissue.contains(&FAT_BRIGHT));

    // Skin and bone nodes: the field interpolates to the iso-value there, and they lie within
    // half a voxel of the pipeline's marching-tetrahedra surfaces.
    let half_voxel = 0.5 * vol.spacing.iter().copied().fold(f64::INFINITY, f64::min);
    for (field, iso, kind, name) in [
        (
            seg.skin_field(&vol),
            seg.windows.head_threshold,
            from_ct::NodeKind::Skin,
            "skin",
        ),
        (
            seg.bone_field(&vol),
            seg.windows.bone,
            from_ct::NodeKind::Bone,
            "bone",
        ),
    ] {
        let pts: Vec<[f64; 3]> = m
            .nodes
            .iter()
            .zip(&m.kind)
            .filter(|(_, k)| **k == kind)
            .map(|(p, _)| *p)
            .collect();
        let worst_hu = pts
            .iter()
            .map(|p| (sample_field(&field, vol.dims, vol.to_voxel(*p), -1024.0) as f64 - iso).abs())
            .fold(0.0, f64::max);
        let surface = marching::extract(&vol, &field, iso as f32);
        let d = distances(&surface, &pts, 4.0);
        let worst = d.iter().copied().fold(0.0, f64::max);
        println!(
            "{name}: {} nodes, |field − iso| ≤ {worst_hu:.3} HU, distance to the marching surface ≤ {worst:.3} mm (half voxel {half_voxel} mm)",
            pts.len()
        );
        assert!(
            worst_hu < 1.0,
            "{name}: a node {worst_hu} HU off the iso-value"
        );
        assert!(
            worst <= half_voxel,
            "{name}: a node {worst} mm off the surface"
        );
    }

    // Cut nodes lie on the box's faces: lo exactly, hi rounded up to whole cubes of the
    // coarsest size (skin size × 2 here).
    let h = 2.0 * p.skin_size_mm;
    let hi = [0, 1, 2].map(|a| roi.0[a] + ((roi.1[a] - roi.0[a]) / h - 1e-9).ceil() * h);
    for (q, k) in m.nodes.iter().zip(&m.kind) {
        assert!((0..3).all(|a| q[a] >= roi.0[a] - 1e-9 && q[a] <= hi[a] + 1e-9));
        if *k == from_ct::NodeKind::Cut {
            assert!(
                (0..3).any(|a| (q[a] - roi.0[a]).abs() < 1e-9 || (q[a] - hi[a]).abs() < 1e-9),
                "cut node {q:?} off the box"
            );
        }
    }

    // A region without soft tissue is a one-line configuration error.
    let far = ([300.0; 3], [320.0; 3]);
    match from_ct::soft_tissue(&vol, &seg, far, &p) {
        Err(facesim::error::Error::Config(msg)) => assert!(msg.contains("no soft tissue"), "{msg}"),
        other => panic!("expected a configuration error, got {:?}", other.err()),
    }
}

#[test]
fn real_ct_soft_tissue_around_the_maxilla_meshes_with_bounded_angles() {
    let vol = facesim::volume::read_volume(&common::real_ct()).unwrap();
    let seg = segmented(&vol);
    // About 120 × 110 × 90 mm around the maxilla, nose and lips (data-samples/real/case.toml:
    // the maxilla box x 80..170, y 25..95, z −5..22; the face at small y).
    let roi = ([65.0, -5.0, -30.0], [185.0, 105.0, 60.0]);
    for (size, deep) in [(2.5, 2.5), (2.5, 10.0), (2.0, 8.0)] {
        let p = MeshParams {
            skin_size_mm: size,
            deep_size_mm: deep,
            margin_mm: 0.0,
        };
        let t0 = std::time::Instant::now();
        let m = from_ct::soft_tissue(&vol, &seg, roi, &p).unwrap();
        let wall = t0.elapsed().as_secs_f64();
        assert_ct_mesh(&m);
        let count = |k: from_ct::NodeKind| m.kind.iter().filter(|x| **x == k).count();
        let q = &m.quality;
        let labels: Vec<usize> = (1..5u8)
            .map(|l| m.tissue.iter().filter(|x| **x == l).count())
            .collect();
        println!(
            "real CT, {size}..{deep} mm: {} nodes ({} skin, {} bone, {} cut), {} tets in {wall:.2} s; dihedral {:.2}°..{:.2}°, worst ratio {:.2}; volume {:.0} mm³ + {:.0} enclosed left out (voxels {:.0}); tets skin/fat dark/fat bright/muscle {labels:?}, {} fallbacks, {} flattened slivers left out",
            q.nodes,
            count(from_ct::NodeKind::Skin),
            count(from_ct::NodeKind::Bone),
            count(from_ct::NodeKind::Cut),
            q.tets,
            q.min_dihedral_deg,
            q.max_dihedral_deg,
            q.worst_aspect_ratio,
            q.volume_mm3,
            m.dropped_volume_mm3,
            m.voxel_volume_mm3,
            m.tissue_fallbacks,
            m.flattened
        );
        assert!(count(from_ct::NodeKind::Skin) > 1000 && count(from_ct::NodeKind::Bone) > 1000);
        assert!(((q.volume_mm3 + m.dropped_volume_mm3) / m.voxel_volume_mm3 - 1.0).abs() < 0.1);
        scan_end_is_bone_only_where_the_last_slice_is(&vol, &seg, &m);
    }
}

/// The box reaches below the CT, whose last slice cuts through the upper lip and the teeth
/// (z = 0). A bone node is on bone: where the scan ends, only where the bone field of the last
/// slice reaches the bone window (the lip's cut face, tissue at 0–100 HU, is the tissue's free
/// surface, skin-kind). Were the cut face's nodes to take whichever field lay nearer
/// its iso-value, deep tissue's would be the bone's: on this CT ~1 400 bone nodes under the lip,
/// bonded to the maxilla's segment.
fn scan_end_is_bone_only_where_the_last_slice_is(
    vol: &Volume,
    seg: &Segmentation,
    m: &SoftTissueMesh,
) {
    let (first, last) = vol.bounds();
    let bone = seg.bone_field(vol);
    let mut end = (0, 0);
    for (q, k) in m.nodes.iter().zip(&m.kind) {
        if !facesim::volume::past_scan_end((first, last), *q) {
            continue;
        }
        let on_last: [f64; 3] = std::array::from_fn(|a| q[a].clamp(first[a], last[a]));
        let hu = sample_field(&bone, vol.dims, vol.to_voxel(on_last), -1024.0) as f64;
        match k {
            from_ct::NodeKind::Bone => {
                end.0 += 1;
                assert!(
                    hu >= seg.windows.bone - 1.0,
                    "bone node {q:?} past the scan's end over {hu:.0} HU (bone from {:.0})",
                    seg.windows.bone
                );
            }
            from_ct::NodeKind::Skin => end.1 += 1,
            _ => {}
        }
    }
    println!(
        "  the scan's end: {} bone nodes, {} skin (free surface)",
        end.0, end.1
    );
    assert!(end.1 > 100, "the lip's cut face: {end:?}");
}

/// Distance from the cube (lo, hi) to the sphere |p| = r.
fn cube_to_sphere(lo: [f64; 3], hi: [f64; 3], r: f64) -> f64 {
    let near = norm([0, 1, 2].map(|a| 0f64.clamp(lo[a], hi[a])));
    let far = norm([0, 1, 2].map(|a| lo[a].abs().max(hi[a].abs())));
    if near <= r && r <= far {
        0.0
    } else {
        (near - r).abs().min((far - r).abs())
    }
}

#[test]
fn grading_keeps_the_surfaces_fine_and_coarsens_between_them() {
    use facesim::tet::graded;
    let (r1, r2) = (1.0, 10.0);
    let f = shell(r1, r2);
    let h = 0.5;
    let exact = 4.0 / 3.0 * PI * (r2.powi(3) - r1.powi(3));
    // Fine (h) at both spheres, the size growing with the distance from them: coarse between.
    let size = move |lo: [f64; 3], hi: [f64; 3]| {
        let d = cube_to_sphere(lo, hi, r2).min(cube_to_sphere(lo, hi, r1));
        (d - h).max(h)
    };
    let uniform = stuffing::stuff(&f, [-11.0; 3], [11.0; 3], h).unwrap();
    let bg = graded::background([-11.0; 3], [11.0; 3], h, 3, &size).unwrap();
    let m = graded::stuff_graded(&f, &bg).unwrap();
    let q = Quality::of(&m.nodes, &m.tets);
    let qu = Quality::of(&uniform.nodes, &uniform.tets);
    let boundary = check_conforming(&m.tets, true);
    for b in &boundary {
        let r: Vec<f64> = b.iter().map(|v| norm(m.nodes[*v as usize])).collect();
        assert!(
            r.iter().all(|x| (x - r1).abs() < 1e-3) || r.iter().all(|x| (x - r2).abs() < 1e-3),
            "boundary face with radii {r:?}"
        );
    }
    // Boundary triangles keep the fine size; the tissue half-way between is coarser.
    let longest_edge = |t: &[u32]| {
        let mut l: f64 = 0.0;
        for i in 0..t.len() {
            for j in i + 1..t.len() {
                l = l.max(norm(sub(m.nodes[t[i] as usize], m.nodes[t[j] as usize])));
            }
        }
        l
    };
    let boundary_edge = boundary.iter().map(|b| longest_edge(b)).fold(0.0, f64::max);
    let middle_edge = m
        .tets
        .iter()
        .filter(|t| {
            let c = [0, 1, 2].map(|a| t.iter().map(|v| m.nodes[*v as usize][a]).sum::<f64>() / 4.0);
            (norm(c) - 0.5 * (r1 + r2)).abs() < 0.5
        })
        .map(|t| longest_edge(t))
        .fold(0.0, f64::max);
    let e = (q.volume_mm3 - exact).abs() / exact;
    println!(
        "graded shell h = {h}, 3 levels: {} nodes, {} tets (uniform {} / {}), dihedral {:.2}°..{:.2}° (uniform {:.2}°..{:.2}°), worst ratio {:.2}, volume error {e:.3e}; longest edge on the boundary {:.2}, half-way between {:.2} mm",
        q.nodes,
        q.tets,
        qu.nodes,
        qu.tets,
        q.min_dihedral_deg,
        q.max_dihedral_deg,
        qu.min_dihedral_deg,
        qu.max_dihedral_deg,
        q.worst_aspect_ratio,
        boundary_edge,
        middle_edge
    );
    assert_eq!(q.inverted, 0);
    assert_bounds(&q);
    // Both spheres stay at the finest size (the angle bounds need the surfaces in the uniform
    // lattice), so only the tissue between them coarsens: here 28 % fewer tetrahedra.
    assert!(q.tets * 4 < qu.tets * 3, "grading saved too little");
    assert!(boundary_edge < 1.5 * h && middle_edge > 3.0 * h);
    // The coarse upper half is a coarser inscribed polyhedron: a larger but still small error.
    assert!(e < 2e-2, "{e}");
    // With no coarsening asked for, the graded background is the BCC lattice itself.
    let fine = |_: [f64; 3], _: [f64; 3]| 0.0;
    let bg0 = graded::background([-11.0; 3], [11.0; 3], 1.0, 2, &fine).unwrap();
    let m0 = graded::stuff_graded(&f, &bg0).unwrap();
    let u1 = stuffing::stuff(&f, [-11.0; 3], [11.0; 3], 1.0).unwrap();
    let (q0, q1) = (
        Quality::of(&m0.nodes, &m0.tets),
        Quality::of(&u1.nodes, &u1.tets),
    );
    println!(
        "graded with nothing to coarsen: {} tets, {} mm³; uniform {} tets, {} mm³",
        q0.tets, q0.volume_mm3, q1.tets, q1.volume_mm3
    );
    assert_eq!(q0.tets, q1.tets);
    assert!((q0.volume_mm3 - q1.volume_mm3).abs() < 1e-9 * q1.volume_mm3);
}

//! Tetrahedral meshing by isosurface stuffing (Labelle & Shewchuk 2007): analytic spheres and
//! shells checked against exact volumes, surfaces and the paper's proven angle bounds; the box
//! restriction; the phantom's and the real CT's soft tissue.

use facesim::tet::quality::Quality;
use facesim::tet::stuffing::{self, MAX_DIHEDRAL_BOUND_DEG, MIN_DIHEDRAL_BOUND_DEG, NodeKind};
use std::collections::HashMap;
use std::f64::consts::PI;

fn norm(p: [f64; 3]) -> f64 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

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
        assert_eq!(bad, 0, "{bad} boundary edges not shared by exactly two faces");
    }
    boundary
}

fn assert_bounds(q: &Quality) {
    assert_eq!(q.inverted, 0);
    assert!(
        q.min_dihedral_deg >= MIN_DIHEDRAL_BOUND_DEG && q.max_dihedral_deg <= MAX_DIHEDRAL_BOUND_DEG,
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
    assert!(errors[0] < 1e-2 && errors[1] < errors[0] / 2f64.powf(1.7), "{errors:?}");
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
        worst = (worst.0.min(q.min_dihedral_deg), worst.1.max(q.max_dihedral_deg));
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

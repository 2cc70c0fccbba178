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

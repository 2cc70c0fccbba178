//! The linear tetrahedral element of the volumetric model , on a
//! cube meshed into Kuhn tetrahedra: the patch test, exact rigid motions in heterogeneous
//! material, exact linearity in the prescribed move, and a refused inverted element.

use facesim::error::{Error, NumericalKind};
use facesim::tet::{TetMesh, TissueElastic};

use crate::tet_grid;
use tet_grid::{cube, kuhn_cell};

const FAT: TissueElastic = TissueElastic {
    youngs_kpa: 3.0,
    poisson: 0.45,
};
const MUSCLE: TissueElastic = TissueElastic {
    youngs_kpa: 15.0,
    poisson: 0.3,
};

fn on_boundary(p: [f64; 3], m: &TetMesh) -> bool {
    let span = m.nodes.iter().map(|q| q[2]).fold(0.0, f64::max);
    // Undo the grid's shear to test the cube's faces in grid coordinates.
    let z = p[2];
    let y = p[1] - 0.05 * z;
    let x = p[0] - 0.1 * y;
    [x, y, z]
        .iter()
        .any(|v| v.abs() < 1e-9 || (v - span).abs() < 1e-9)
}

fn linear_field(a: [[f64; 3]; 3], b: [f64; 3]) -> impl Fn([f64; 3]) -> [f64; 3] {
    move |p| std::array::from_fn(|i| b[i] + (0..3).map(|j| a[i][j] * p[j]).sum::<f64>())
}

fn solve_with(m: &TetMesh, f: &dyn Fn([f64; 3]) -> [f64; 3]) -> Vec<[f64; 3]> {
    let prescribed: Vec<Option<[f64; 3]>> = m
        .nodes
        .iter()
        .map(|p| on_boundary(*p, m).then(|| f(*p)))
        .collect();
    assert!(
        prescribed.iter().any(|p| p.is_none()),
        "the cube has interior nodes"
    );
    m.solve_linear(&prescribed).unwrap()
}

fn worst(m: &TetMesh, u: &[[f64; 3]], f: &dyn Fn([f64; 3]) -> [f64; 3]) -> f64 {
    m.nodes
        .iter()
        .zip(u)
        .map(|(p, d)| {
            let e = f(*p);
            (0..3).map(|c| (d[c] - e[c]).abs()).fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

#[test]
fn patch_test_a_linear_field_is_reproduced_exactly() {
    let m = cube(4, 2.5, MUSCLE, MUSCLE);
    let f = linear_field(
        [
            [0.01, -0.02, 0.005],
            [0.03, -0.01, 0.02],
            [-0.015, 0.01, 0.04],
        ],
        [0.3, -0.2, 0.1],
    );
    let u = solve_with(&m, &f);
    let w = worst(&m, &u, &f);
    assert!(w < 1e-12, "patch test off by {w} mm");
}

#[test]
fn rigid_moves_are_exact_in_heterogeneous_tissue() {
    let m = cube(4, 2.5, FAT, MUSCLE);
    // A translation and an infinitesimal rotation (skew A): zero strain in every material.
    for f in [
        linear_field([[0.0; 3]; 3], [1.0, -6.0, 0.5]),
        linear_field(
            [[0.0, -0.02, 0.01], [0.02, 0.0, -0.03], [-0.01, 0.03, 0.0]],
            [0.0; 3],
        ),
    ] {
        let u = solve_with(&m, &f);
        let w = worst(&m, &u, &f);
        assert!(w < 1e-9, "rigid move off by {w} mm");
    }
}

#[test]
fn the_solution_is_linear_in_the_prescribed_move() {
    let m = cube(3, 3.0, FAT, MUSCLE);
    // Boundary moves that are not linear fields, so the interior really solves something.
    let f1 = |p: [f64; 3]| [0.01 * p[1] * p[1], 0.0, 0.02 * p[0] * p[2]];
    let f2 = |p: [f64; 3]| [(0.3 * p[2]).sin(), 0.05 * p[0], 0.0];
    let (a, b) = (2.5, -0.7);
    let f12 = |p: [f64; 3]| {
        let (x, y) = (f1(p), f2(p));
        std::array::from_fn(|c| a * x[c] + b * y[c])
    };
    let (u1, u2, u12) = (
        solve_with(&m, &f1),
        solve_with(&m, &f2),
        solve_with(&m, &f12),
    );
    let mut interior_move: f64 = 0.0;
    for i in 0..u1.len() {
        for c in 0..3 {
            let d = u12[i][c] - (a * u1[i][c] + b * u2[i][c]);
            assert!(d.abs() < 1e-10, "node {i}: {d}");
            interior_move = interior_move.max(u1[i][c].abs());
        }
    }
    assert!(interior_move > 1e-2);
}

#[test]
fn an_inverted_element_is_a_reported_failure() {
    let mut m = cube(2, 2.0, MUSCLE, MUSCLE);
    m.tets[3].swap(0, 1);
    let held = vec![Some([0.0; 3]); m.nodes.len()];
    match m.solve_linear(&held) {
        Err(Error::Numerical {
            kind: NumericalKind::DegenerateElement,
            msg,
        }) => assert!(msg.contains("tetrahedron 3"), "{msg}"),
        other => panic!(
            "expected a degenerate-element failure, got {:?}",
            other.err()
        ),
    }
    // Nothing held: the tissue would float; refused before any factorisation.
    let free = vec![None; m.nodes.len()];
    let ok = cube(2, 2.0, MUSCLE, MUSCLE);
    assert!(matches!(ok.solve_linear(&free), Err(Error::Config(_))));
}

/// Lamé's thick-walled cylinder in plane strain with prescribed radial displacements u_a at
/// r = a and u_b at r = b: u_r = A r + B / r (any homogeneous material; from the equilibrium
/// equation d/dr (1/r d(r u_r)/dr) = 0). A full annulus of one layer, every node's u_z held at 0;
/// returns the largest nodal error of u_r relative to max |u_r|, and the in-plane mesh size.
fn lame_cylinder(nr: usize, m: TissueElastic) -> (f64, f64) {
    let (a, b, ua, ub) = (10.0, 20.0, 0.5, 0.1);
    let nt = 8 * nr;
    let h = (b - a) / nr as f64;
    let id = |i: usize, j: usize, k: usize| ((k * nt + j % nt) * (nr + 1) + i) as u32;
    let mut nodes = Vec::new();
    for k in 0..2 {
        for j in 0..nt {
            for i in 0..=nr {
                let (r, t) = (
                    a + i as f64 * h,
                    j as f64 * std::f64::consts::TAU / nt as f64,
                );
                nodes.push([r * t.cos(), r * t.sin(), k as f64 * h]);
            }
        }
    }
    let mut tets = Vec::new();
    for j in 0..nt {
        for i in 0..nr {
            tets.extend(kuhn_cell([i, j, 0], &id, &nodes));
        }
    }
    let mesh = TetMesh {
        material: vec![m; tets.len()],
        nodes,
        tets,
    };
    // u_r = A r + B / r through (a, u_a) and (b, u_b).
    let big_a = (ub * b - ua * a) / (b * b - a * a);
    let big_b = a * (ua - big_a * a);
    let exact = |r: f64| big_a * r + big_b / r;
    let n = mesh.ndof();
    let (mut fixed, mut values) = (vec![false; n], vec![0.0; n]);
    for (v, p) in mesh.nodes.iter().enumerate() {
        let r = p[0].hypot(p[1]);
        fixed[3 * v + 2] = true;
        if (r - a).abs() < 1e-9 || (r - b).abs() < 1e-9 {
            for c in 0..2 {
                fixed[3 * v + c] = true;
                values[3 * v + c] = exact(r) * p[c] / r;
            }
        }
    }
    let u = mesh.solve_dofs(&fixed, &values).unwrap();
    let err = mesh
        .nodes
        .iter()
        .enumerate()
        .map(|(v, p)| {
            let r = p[0].hypot(p[1]);
            let ur = (u[3 * v] * p[0] + u[3 * v + 1] * p[1]) / r;
            (ur - exact(r)).abs()
        })
        .fold(0.0, f64::max);
    (err / ua.max(ub), h)
}

#[test]
fn lame_cylinder_converges_at_second_order() {
    // Measured: 0.26 %, 0.064 %, 0.014 % at h = 2.5, 1.25, 0.625 mm (rates 2.05, 2.21); at
    // h = 5 mm (two elements through the wall) the rate is still 1.6, pre-asymptotic.
    let errors: Vec<(f64, f64)> = [4, 8, 16]
        .iter()
        .map(|&nr| lame_cylinder(nr, MUSCLE))
        .collect();
    println!("Lamé cylinder, relative max nodal error of u_r: {errors:?}");
    for w in errors.windows(2) {
        let rate = (w[0].0 / w[1].0).ln() / (w[0].1 / w[1].1).ln();
        assert!(rate > 1.7, "observed rate {rate:.2} ({errors:?})");
    }
    assert!(errors[2].0 < 1e-3, "{errors:?}");
}

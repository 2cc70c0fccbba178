//! Physics of the volumetric model: holds (fixed, sliding, rails) and loads, the
//! neo-Hookean option against exact rigid motion, the linear model and a closed-form uniaxial
//! stretch, reported non-convergence, and volumetric locking of linear tetrahedra shown and cured
//! by quadratic ones on Lamé's thick-walled sphere.

use facesim::error::{Error, NumericalKind};
use facesim::tet::nonlinear::{self, Energy, NeoHooke, Newton};
use facesim::tet::quadratic::{Rule, Tet10Mesh};
use facesim::tet::{Constrained, Hold, Loads, TetMesh, TissueElastic};
use facesim::vec3::dot;

use crate::tet_grid;
use tet_grid::kuhn_cell;

const FAT: TissueElastic = TissueElastic {
    youngs_kpa: 3.0,
    poisson: 0.45,
};
const MUSCLE: TissueElastic = TissueElastic {
    youngs_kpa: 15.0,
    poisson: 0.3,
};

type V3 = [f64; 3];

fn matvec(m: &[[f64; 3]; 3], v: V3) -> V3 {
    std::array::from_fn(|i| dot(m[i], v))
}

/// Rotation by `deg` degrees about `axis` (Rodrigues).
fn rotation(axis: V3, deg: f64) -> [[f64; 3]; 3] {
    let l = dot(axis, axis).sqrt();
    let k = axis.map(|c| c / l);
    let (s, c) = deg.to_radians().sin_cos();
    let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let id = if i == j { 1.0 } else { 0.0 };
            let kk: f64 = (0..3).map(|m| kx[i][m] * kx[m][j]).sum();
            id + s * kx[i][j] + (1.0 - c) * kk
        })
    })
}

/// A Kuhn-tetrahedra grid of n[0]×n[1]×n[2] cells with node (i, j, k) at `pos`; materials by
/// cell checkerboard. Returns the mesh and each node's grid indices.
fn grid(
    n: [usize; 3],
    pos: &dyn Fn(usize, usize, usize) -> V3,
    soft: TissueElastic,
    stiff: TissueElastic,
) -> (TetMesh, Vec<[usize; 3]>) {
    let id = |i: usize, j: usize, k: usize| ((k * (n[1] + 1) + j) * (n[0] + 1) + i) as u32;
    let (mut nodes, mut ijk) = (Vec::new(), Vec::new());
    for k in 0..=n[2] {
        for j in 0..=n[1] {
            for i in 0..=n[0] {
                nodes.push(pos(i, j, k));
                ijk.push([i, j, k]);
            }
        }
    }
    let (mut tets, mut material) = (Vec::new(), Vec::new());
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                for t in kuhn_cell([i, j, k], &id, &nodes) {
                    tets.push(t);
                    material.push(if (i + j + k) % 2 == 0 { soft } else { stiff });
                }
            }
        }
    }
    (
        TetMesh {
            nodes,
            tets,
            material,
        },
        ijk,
    )
}

/// A sheared cube of n³ cells of side h (no element axis-aligned), fat/muscle checkerboard.
fn cube(n: usize, h: f64) -> (TetMesh, Vec<[usize; 3]>) {
    let pos = |i: usize, j: usize, k: usize| {
        let (x, y, z) = (i as f64 * h, j as f64 * h, k as f64 * h);
        [x + 0.1 * y, y + 0.05 * z, z]
    };
    grid([n, n, n], &pos, FAT, MUSCLE)
}

fn max_diff(a: &[V3], b: &[V3]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f64::max)
}

/// The least-squares slope of log y against log x.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let (lx, ly): (Vec<f64>, Vec<f64>) = (
        x.iter().map(|v| v.ln()).collect(),
        y.iter().map(|v| v.ln()).collect(),
    );
    let n = x.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let num: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let den: f64 = lx.iter().map(|a| (a - mx) * (a - mx)).sum();
    num / den
}

/// The bottom layer (k = 0) held on a rigid move x ↦ R x + t, i.e. u = (R − I) x + t.
fn bone_rigid(m: &TetMesh, ijk: &[[usize; 3]], r: &[[f64; 3]; 3], t: V3) -> Vec<Hold> {
    m.nodes
        .iter()
        .zip(ijk)
        .map(|(p, g)| {
            if g[2] == 0 {
                let rp = matvec(r, *p);
                Hold::Fixed(std::array::from_fn(|c| rp[c] - p[c] + t[c]))
            } else {
                Hold::Free
            }
        })
        .collect()
}

fn rigid_field(m: &TetMesh, r: &[[f64; 3]; 3], t: V3) -> Vec<V3> {
    m.nodes
        .iter()
        .map(|p| {
            let rp = matvec(r, *p);
            std::array::from_fn(|c| rp[c] - p[c] + t[c])
        })
        .collect()
}

#[test]
fn rotated_bone_moves_neo_hookean_tissue_rigidly_and_linear_tissue_to_second_order() {
    let (m, ijk) = cube(3, 3.0);
    let axis = [1.0, 2.0, 3.0];
    // 30° about an oblique axis with a translation: every node rigid to 1e-9 mm.
    let (r, t) = (rotation(axis, 30.0), [0.5, -1.0, 2.0]);
    let sol = nonlinear::solve(
        &m,
        &bone_rigid(&m, &ijk, &r, t),
        &Loads::none(),
        &Newton::default(),
    )
    .unwrap();
    let off = max_diff(&sol.displacements, &rigid_field(&m, &r, t));
    println!(
        "neo-Hookean, 30° bone rotation: off rigid by {off:.2e} mm; steps {:?}",
        sol.steps
            .iter()
            .map(|s| (s.load, s.iterations))
            .collect::<Vec<_>>()
    );
    assert!(off < 1e-9, "{off}");
    assert!(sol.steps.len() >= 4 && sol.steps.iter().all(|s| s.iterations >= 1));
    // The linear model deviates from the rigid motion as θ² (its rotations are infinitesimal).
    let angles = [1.0, 2.0, 4.0, 8.0];
    let dev: Vec<f64> = angles
        .iter()
        .map(|&deg| {
            let r = rotation(axis, deg);
            let u = m
                .solve(&bone_rigid(&m, &ijk, &r, [0.0; 3]), &Loads::none())
                .unwrap();
            max_diff(&u, &rigid_field(&m, &r, [0.0; 3]))
        })
        .collect();
    let rate = slope(&angles, &dev);
    println!("linear model, deviation from rigid at θ = {angles:?}°: {dev:.3?} mm, rate {rate:.3}");
    assert!((rate - 2.0).abs() < 0.05, "rate {rate}");
    assert!(dev[0] > 1e-5, "the linear model is not rigid: {dev:?}");
}

#[test]
fn neo_hookean_equals_linear_for_small_moves() {
    let (m, ijk) = cube(3, 3.0);
    // A non-rigid move of the bottom, the top face pulled sideways.
    let g = |p: V3| [0.3 * (p[0] / 4.0).sin(), 0.02 * p[1] * p[0], -0.1 * p[0]];
    let holds = |eps: f64| -> Vec<Hold> {
        m.nodes
            .iter()
            .zip(&ijk)
            .map(|(p, c)| match c[2] {
                0 => Hold::Fixed(g(*p).map(|v| eps * v)),
                3 => Hold::Fixed([eps * 0.5, 0.0, 0.0]),
                _ => Hold::Free,
            })
            .collect()
    };
    let eps = [0.4, 0.2, 0.1, 0.05];
    let diff: Vec<f64> = eps
        .iter()
        .map(|&e| {
            let h = holds(e);
            let lin = m.solve(&h, &Loads::none()).unwrap();
            let opts = Newton {
                tolerance: 1e-12,
                ..Newton::default()
            };
            let nl = nonlinear::solve(&m, &h, &Loads::none(), &opts).unwrap();
            max_diff(&lin, &nl.displacements)
        })
        .collect();
    let rate = slope(&eps, &diff);
    println!("|neo-Hookean − linear| at move scale {eps:?}: {diff:.3?} mm, rate {rate:.3}");
    // Difference / move → 0 linearly: the difference is second order in the move.
    assert!((rate - 2.0).abs() < 0.1, "rate {rate}");
}

#[test]
fn the_tangent_is_the_derivative_of_the_internal_forces() {
    let (m, _) = cube(2, 2.0);
    let u: Vec<V3> = m
        .nodes
        .iter()
        .map(|p| {
            [
                0.1 * p[1] + 0.02 * p[2] * p[2],
                -0.05 * p[0] * p[2] / 4.0,
                0.15 * (p[0] / 3.0).sin(),
            ]
        })
        .collect();
    let k = nonlinear::internal_state(&m, &u, true).unwrap().tangent;
    let n = m.ndof();
    let mut dense = vec![vec![0.0; n]; n];
    for (r, c, v) in k {
        dense[r][c] += v;
        if r != c {
            dense[c][r] += v;
        }
    }
    let scale = dense.iter().flatten().fold(0.0_f64, |a, b| a.max(b.abs()));
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    for j in 0..n {
        let shifted = |s: f64| {
            let mut v = u.clone();
            v[j / 3][j % 3] += s;
            nonlinear::internal_state(&m, &v, false).unwrap().forces
        };
        let (fp, fm) = (shifted(h), shifted(-h));
        for i in 0..n {
            worst = worst.max(((fp[i] - fm[i]) / (2.0 * h) - dense[i][j]).abs() / scale);
        }
    }
    println!("tangent vs central differences: relative {worst:.2e}");
    assert!(worst < 1e-6, "{worst}");
}

/// A sliding plane: normal, value, and whether a point lies on it.
type Plane<'a> = (V3, f64, &'a dyn Fn(V3) -> bool);

/// Holds of a node from the planes it lies on.
fn plane_holds(nodes: &[V3], planes: &[Plane]) -> Vec<Hold> {
    nodes
        .iter()
        .enumerate()
        .map(|(v, p)| {
            let on: Vec<(V3, f64)> = planes
                .iter()
                .filter(|pl| (pl.2)(*p))
                .map(|pl| (pl.0, pl.1))
                .collect();
            Hold::from_planes(&on, v).unwrap()
        })
        .collect()
}

#[test]
fn uniaxial_stretch_of_a_neo_hookean_block_matches_the_closed_form() {
    let (l, n, stretch) = (10.0, 2, 1.6);
    let h = l / n as f64;
    let mat = TissueElastic {
        youngs_kpa: 10.0,
        poisson: 0.45,
    };
    let (m, _) = grid(
        [n, n, n],
        &|i, j, k| [i as f64 * h, j as f64 * h, k as f64 * h],
        mat,
        mat,
    );
    let near = |a: f64, b: f64| (a - b).abs() < 1e-9;
    let holds = plane_holds(
        &m.nodes,
        &[
            ([1.0, 0.0, 0.0], 0.0, &|p: V3| near(p[0], 0.0)),
            ([1.0, 0.0, 0.0], (stretch - 1.0) * l, &|p: V3| near(p[0], l)),
            ([0.0, 1.0, 0.0], 0.0, &|p: V3| near(p[1], 0.0)),
            ([0.0, 0.0, 1.0], 0.0, &|p: V3| near(p[2], 0.0)),
        ],
    );
    let opts = Newton {
        load_steps: 6,
        tolerance: 1e-13,
        energy: Energy::CalculixNeoHooke,
        ..Newton::default()
    };
    let sol = nonlinear::solve(&m, &holds, &Loads::none(), &opts).unwrap();
    // Closed form: F = diag(λ₁, λ₂, λ₂) with zero lateral Cauchy stress,
    // σ₂₂ = μ J^(−5/3) (λ₂² − I₁/3) + K (J − 1) = 0, J = λ₁ λ₂², I₁ = λ₁² + 2 λ₂² (bisection).
    let nh = NeoHooke::from_elastic(mat);
    let sigma = |l2: f64| {
        let (j, i1) = (stretch * l2 * l2, stretch * stretch + 2.0 * l2 * l2);
        nh.mu * j.powf(-5.0 / 3.0) * (l2 * l2 - i1 / 3.0) + nh.kappa * (j - 1.0)
    };
    let (mut lo, mut hi) = (0.3, 1.0);
    assert!(sigma(lo) < 0.0 && sigma(hi) > 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if sigma(mid) < 0.0 { lo = mid } else { hi = mid }
    }
    let l2 = 0.5 * (lo + hi);
    let exact: Vec<V3> = m
        .nodes
        .iter()
        .map(|p| [(stretch - 1.0) * p[0], (l2 - 1.0) * p[1], (l2 - 1.0) * p[2]])
        .collect();
    let off = max_diff(&sol.displacements, &exact);
    println!(
        "uniaxial stretch {stretch}: lateral stretch {l2:.10} (closed form), FE off by {off:.2e} mm"
    );
    assert!(off < 1e-8, "{off}");
    // CalculiX's constants for the same material.
    assert!((nh.c10() - nh.mu / 2.0).abs() < 1e-15 && (nh.d1() * nh.kappa - 2.0).abs() < 1e-15);
}

#[test]
fn a_nonlinear_solve_that_does_not_converge_reports_its_residual_history() {
    let (m, ijk) = cube(3, 3.0);
    // The bottom turned by 170° about the vertical in one step of two Newton iterations, top held.
    let r = rotation([0.0, 0.0, 1.0], 170.0);
    let holds: Vec<Hold> = bone_rigid(&m, &ijk, &r, [0.0; 3])
        .into_iter()
        .zip(&ijk)
        .map(|(h, c)| if c[2] == 3 { Hold::Fixed([0.0; 3]) } else { h })
        .collect();
    let opts = Newton {
        load_steps: 1,
        max_iterations: 2,
        tolerance: 1e-10,
        max_cuts: 0,
        energy: Energy::StableNeoHooke,
    };
    match nonlinear::solve(&m, &holds, &Loads::none(), &opts) {
        Err(Error::Numerical {
            kind: NumericalKind::NotConverged,
            msg,
        }) => {
            println!("{msg}");
            assert!(msg.contains("residual history ["), "{msg}");
            assert!(msg.contains("e"), "{msg}");
        }
        other => panic!("expected non-convergence, got {:?}", other.map(|s| s.steps)),
    }
    // The linear model survives the same move only with inverted elements, which it names.
    let u = m.solve(&holds, &Loads::none()).unwrap();
    let bad = m.inverted_after(&u);
    assert!(!bad.is_empty());
    let small = rotation([0.0, 0.0, 1.0], 5.0);
    let u = m
        .solve(&bone_rigid(&m, &ijk, &small, [0.0; 3]), &Loads::none())
        .unwrap();
    assert!(m.inverted_after(&u).is_empty());
}

/// A block on a "bone" plane (normal Q e_z, its bottom face), with symmetry planes Q e_x and
/// Q e_y through the origin: the holds for a bone moved by `bone` (n · bone on the bottom).
fn sliding_block(q: &[[f64; 3]; 3]) -> (TetMesh, Vec<[usize; 3]>) {
    let h = 2.0;
    grid(
        [3, 3, 3],
        &|i, j, k| matvec(q, [i as f64 * h, j as f64 * h, k as f64 * h]),
        FAT,
        MUSCLE,
    )
}

fn block_holds(m: &TetMesh, ijk: &[[usize; 3]], q: &[[f64; 3]; 3], bottom: f64) -> Vec<Hold> {
    let col = |c: usize| [q[0][c], q[1][c], q[2][c]];
    m.nodes
        .iter()
        .zip(ijk)
        .enumerate()
        .map(|(v, (_, g))| {
            let mut on = Vec::new();
            if g[0] == 0 {
                on.push((col(0), 0.0));
            }
            if g[1] == 0 {
                on.push((col(1), 0.0));
            }
            if g[2] == 0 {
                on.push((col(2), bottom));
            }
            Hold::from_planes(&on, v).unwrap()
        })
        .collect()
}

#[test]
fn sliding_nodes_follow_the_bone_normally_and_not_tangentially() {
    let q = rotation([0.3, -1.0, 0.5], 40.0);
    let (m, ijk) = sliding_block(&q);
    let n = [q[0][2], q[1][2], q[2][2]];
    let tangential = {
        let e0 = [q[0][0], q[1][0], q[2][0]];
        e0.map(|c| 1.5 * c)
    };
    // A tangential bone move: n · move = 0, so the block stays where it is (no drag)…
    let u = m
        .solve(
            &block_holds(&m, &ijk, &q, dot(n, tangential)),
            &Loads::none(),
        )
        .unwrap();
    let still = u.iter().flatten().fold(0.0_f64, |a, b| a.max(b.abs()));
    assert!(still < 1e-12, "{still}");
    // …whereas attached (fixed) bottom nodes drag it along.
    let attached: Vec<Hold> = block_holds(&m, &ijk, &q, 0.0)
        .into_iter()
        .zip(&ijk)
        .map(|(h, g)| {
            if g[2] == 0 {
                Hold::Fixed(tangential)
            } else {
                h
            }
        })
        .collect();
    let dragged = m.solve(&attached, &Loads::none()).unwrap();
    assert!(
        dragged
            .iter()
            .map(|d| dot(*d, tangential))
            .fold(0.0, f64::max)
            > 1.0
    );
    // A normal move of 0.8 mm translates the block: every node by 0.8 n, in both models.
    let holds = block_holds(&m, &ijk, &q, 0.8);
    let translated: Vec<V3> = vec![n.map(|c| 0.8 * c); m.nodes.len()];
    let u = m.solve(&holds, &Loads::none()).unwrap();
    assert!(
        max_diff(&u, &translated) < 1e-12,
        "{}",
        max_diff(&u, &translated)
    );
    let nl = nonlinear::solve(&m, &holds, &Loads::none(), &Newton::default()).unwrap();
    assert!(max_diff(&nl.displacements, &translated) < 1e-9);
}

#[test]
fn sliding_is_exact_frame_invariant_and_factored_once() {
    // A loaded problem: bottom slides with its normal displacement 0.3 mm, the side planes are
    // symmetry planes, pressure on the top face and a force on one top node.
    let solve_in = |q: &[[f64; 3]; 3], bottom: f64, p: f64| {
        let (m, ijk) = sliding_block(q);
        let holds = block_holds(&m, &ijk, q, bottom);
        let top = |i: usize, j: usize| ((3 * 4 + j) * 4 + i) as u32;
        let mut loads = Loads::none();
        for j in 0..3 {
            for i in 0..3 {
                // Outward normal +Q e_z: counter-clockwise seen from above.
                loads
                    .pressure
                    .push(([top(i, j), top(i + 1, j), top(i + 1, j + 1)], p));
                loads
                    .pressure
                    .push(([top(i, j), top(i + 1, j + 1), top(i, j + 1)], p));
            }
        }
        loads
            .nodal
            .push((top(2, 1) as usize, matvec(q, [0.4, -0.2, 0.1])));
        (m, holds, loads)
    };
    let (q1, q2) = (
        rotation([0.3, -1.0, 0.5], 40.0),
        rotation([-2.0, 0.2, 1.0], 115.0),
    );
    let (m1, h1, l1) = solve_in(&q1, 0.3, 2.0);
    let (m2, h2, l2) = solve_in(&q2, 0.3, 2.0);
    let u1 = m1.solve(&h1, &l1).unwrap();
    let u2 = m2.solve(&h2, &l2).unwrap();
    // u₂ = Q₂ Q₁ᵀ u₁.
    let rel: [[f64; 3]; 3] =
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| q2[i][k] * q1[j][k]).sum()));
    let mapped: Vec<V3> = u1.iter().map(|d| matvec(&rel, *d)).collect();
    let size = u1.iter().flatten().fold(0.0_f64, |a, b| a.max(b.abs()));
    assert!(size > 0.1, "{size}");
    let off = max_diff(&u2, &mapped);
    assert!(off < 1e-10 * size, "rotated problem differs by {off}");
    // Each sliding node's normal displacement equals its value.
    for (h, d) in h1.iter().zip(&u1) {
        if let Hold::Slide { normal, value } = h {
            let l = dot(*normal, *normal).sqrt();
            assert!((dot(*normal, *d) / l - value).abs() < 1e-13);
        }
    }
    // One factor, two hold values and loads: the same as two separate solves.
    let (_, h1b, l1b) = solve_in(&q1, -0.1, 0.5);
    let c = Constrained::new(&m1.assemble().unwrap(), &h1, m1.nodes.len()).unwrap();
    let (fa, fb) = (
        l1.vector_linear(&m1.nodes).unwrap(),
        l1b.vector_linear(&m1.nodes).unwrap(),
    );
    let both = c.solve(&[(&h1, &fa), (&h1b, &fb)]).unwrap();
    let ub = m1.solve(&h1b, &l1b).unwrap();
    assert!(max_diff(&both[0], &u1) < 1e-12 && max_diff(&both[1], &ub) < 1e-12);
    // A hold of another kind cannot use that factor.
    let mut other = h1.clone();
    other[5] = Hold::Fixed([0.0; 3]);
    assert!(matches!(c.solve(&[(&other, &fa)]), Err(Error::Config(_))));
}

/// The element used on Lamé's sphere.
#[derive(Clone, Copy, Debug)]
enum Element {
    Linear,
    Quadratic(Rule),
}

/// Lamé's thick-walled sphere (a = 10, b = 20 mm, E = 10 kPa) under internal pressure p = 1 kPa:
/// u_r = p a³ / (E (b³ − a³)) ((1 − 2ν) r + (1 + ν) b³ / (2 r²)). The wedge 0 ≤ y ≤ x,
/// 0 ≤ z ≤ x of the shell (1/24 of it; no pole), n cells radially and n along each angle
/// (equiangular), its four side planes sliding (radial motion is tangent to them). Returns the
/// largest nodal error |u − u_exact| relative to u_r(a), and the radial cell size.
fn lame_sphere(n: usize, nu: f64, element: Element) -> (f64, f64) {
    let (a, b, e, p) = (10.0, 20.0, 10.0, 1.0);
    let m = TissueElastic {
        youngs_kpa: e,
        poisson: nu,
    };
    let quarter = std::f64::consts::FRAC_PI_4;
    let pos = |i: usize, j: usize, k: usize| {
        let r = a + (b - a) * i as f64 / n as f64;
        let (s, t) = (
            (quarter * j as f64 / n as f64).tan(),
            (quarter * k as f64 / n as f64).tan(),
        );
        let l = (1.0 + s * s + t * t).sqrt();
        [r / l, r * s / l, r * t / l]
    };
    let (mesh, ijk) = grid([n, n, n], &pos, m, m);
    let exact = |r: f64| {
        p * a.powi(3) / (e * (b.powi(3) - a.powi(3)))
            * ((1.0 - 2.0 * nu) * r + (1.0 + nu) * b.powi(3) / (2.0 * r * r))
    };
    // Inner faces, wound with their normal towards the centre (outward from the solid).
    let mut loads = Loads::none();
    for t in &mesh.tets {
        for skip in 0..4 {
            let f: Vec<u32> = (0..4).filter(|&c| c != skip).map(|c| t[c]).collect();
            if f.iter().all(|&v| ijk[v as usize][0] == 0) {
                let [x0, x1, x2] = [f[0], f[1], f[2]].map(|v| mesh.nodes[v as usize]);
                let e1 = [0, 1, 2].map(|c| x1[c] - x0[c]);
                let e2 = [0, 1, 2].map(|c| x2[c] - x0[c]);
                let nrm = [
                    e1[1] * e2[2] - e1[2] * e2[1],
                    e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0],
                ];
                let face = if dot(nrm, x0) < 0.0 {
                    [f[0], f[1], f[2]]
                } else {
                    [f[0], f[2], f[1]]
                };
                loads.pressure.push((face, p));
            }
        }
    }
    let tol = 1e-9 * b;
    let planes: [Plane; 4] = [
        ([0.0, 1.0, 0.0], 0.0, &|q: V3| q[1].abs() < tol),
        ([1.0, -1.0, 0.0], 0.0, &|q: V3| (q[1] - q[0]).abs() < tol),
        ([0.0, 0.0, 1.0], 0.0, &|q: V3| q[2].abs() < tol),
        ([1.0, 0.0, -1.0], 0.0, &|q: V3| (q[2] - q[0]).abs() < tol),
    ];
    let (nodes, u) = match element {
        Element::Linear => {
            let holds = plane_holds(&mesh.nodes, &planes);
            (mesh.nodes.clone(), mesh.solve(&holds, &loads).unwrap())
        }
        Element::Quadratic(rule) => {
            let q = Tet10Mesh::from_linear(&mesh, rule);
            let holds = plane_holds(&q.nodes, &planes);
            let u = q.solve(&holds, &loads).unwrap();
            (q.nodes, u)
        }
    };
    let err = nodes
        .iter()
        .zip(&u)
        .map(|(x, d)| {
            let r = dot(*x, *x).sqrt();
            let want = x.map(|c| exact(r) * c / r);
            (0..3).map(|c| (d[c] - want[c]).powi(2)).sum::<f64>().sqrt()
        })
        .fold(0.0, f64::max);
    (err / exact(a), (b - a) / n as f64)
}

fn rates(e: &[(f64, f64)]) -> Vec<f64> {
    e.windows(2)
        .map(|w| (w[0].0 / w[1].0).ln() / (w[0].1 / w[1].1).ln())
        .collect()
}

#[test]
fn linear_tetrahedra_lock_near_incompressibility_and_quadratic_ones_do_not() {
    // Measured (relative max nodal error at h = 5, 2.5, 1.25, 0.625 mm):
    //   linear ν = 0.3: 33 %, 16 %, 6.3 %, 2.1 % (rates 1.03, 1.38, 1.60: towards 2);
    //   linear ν = 0.4999: 59 %, 56 %, 56 %, 55 % (locked: no convergence);
    //   quadratic, mean dilatation, ν = 0.4999: 9.1 %, 2.4 %, 0.61 % (rates 1.94, 1.97);
    //   quadratic, full 4-point rule (C3D10), ν = 0.4999: 9.8 %, 3.2 %, 0.86 % (rates 1.62, 1.88).
    let t0 = std::time::Instant::now();
    let run = |nu: f64, el: Element, ns: &[usize]| -> Vec<(f64, f64)> {
        ns.iter().map(|&n| lame_sphere(n, nu, el)).collect()
    };
    let lin3 = run(0.3, Element::Linear, &[2, 4, 8, 16]);
    let lin5 = run(0.4999, Element::Linear, &[2, 4, 8, 16]);
    let full5 = run(0.4999, Element::Quadratic(Rule::Full), &[2, 4, 8]);
    let mean5 = run(0.4999, Element::Quadratic(Rule::MeanDilatation), &[2, 4, 8]);
    println!("Lamé sphere, relative max nodal error (error, h):");
    println!("  linear ν = 0.3: {lin3:.4?} rates {:.2?}", rates(&lin3));
    println!("  linear ν = 0.4999: {lin5:.4?} rates {:.2?}", rates(&lin5));
    println!(
        "  quadratic full ν = 0.4999: {full5:.4?} rates {:.2?}",
        rates(&full5)
    );
    println!(
        "  quadratic mean dilatation ν = 0.4999: {mean5:.4?} rates {:.2?}",
        rates(&mean5)
    );
    // Compressible: linear tetrahedra converge (pre-asymptotic rates rising towards 2).
    let r = rates(&lin3);
    assert!(
        r.iter().all(|r| *r > 0.9) && r[2] > 1.5 && lin3[3].0 < 0.03,
        "{lin3:?}"
    );
    // Nearly incompressible: locked, over 50 % wrong however fine the mesh.
    assert!(lin5.iter().all(|e| e.0 > 0.5), "{lin5:?}");
    assert!(lin5[3].0 > 0.9 * lin5[0].0, "{lin5:?}");
    // Quadratic tetrahedra: accurate and converging at second order.
    assert!(
        rates(&mean5).iter().all(|r| *r > 1.8) && mean5[2].0 < 0.01,
        "{mean5:?}"
    );
    assert!(
        rates(&full5).iter().all(|r| *r > 1.5) && full5[2].0 < 0.015,
        "{full5:?}"
    );
    // Towards ν = 0.5 the mean-dilatation rule is unaffected (2.38 % at h = 2.5 mm for every ν
    // measured, 0.49 to 0.499999), the full rule slowly stiffens (2.78 %, 3.17 %, 3.26 %, 3.38 %).
    let at = |nu: f64, rule: Rule| lame_sphere(4, nu, Element::Quadratic(rule)).0;
    let (m1, m2) = (
        at(0.4999, Rule::MeanDilatation),
        at(0.499999, Rule::MeanDilatation),
    );
    let (f1, f2) = (at(0.4999, Rule::Full), at(0.499999, Rule::Full));
    println!(
        "  h = 2.5 mm, ν = 0.4999 → 0.499999: mean dilatation {m1:.4} → {m2:.4}, full {f1:.4} → {f2:.4}"
    );
    assert!(
        (m2 - m1).abs() < 0.01 * m1 && f2 > f1,
        "{m1} {m2} {f1} {f2}"
    );
    println!("  ({:.1} s)", t0.elapsed().as_secs_f64());
}

#[test]
fn quadratic_tetrahedra_reproduce_quadratic_equilibrium_fields() {
    // Navier's equations μ Δu + (λ + μ) ∇ div u = 0 hold for u₁ = (xy, (x² − y²)/2, 0)
    // (harmonic, divergence-free) in any one material, and for u₂ = (xy, −(λ + μ) x² / (2μ), 0)
    // (div u₂ = y). Both lie in the quadratic space, so holding the boundary nodes at them gives
    // them exactly; the mean-dilatation rule only for u₁ (its pressure is constant per element).
    let (lin, _) = cube(2, 2.5);
    let mat = MUSCLE;
    let m = TetMesh {
        material: vec![mat; lin.tets.len()],
        ..lin
    };
    let (lambda, mu) = mat.lame();
    let lin_part = |p: V3| [0.01 * p[2] + 0.2, -0.02 * p[0], 0.03 * p[1] - 0.01 * p[2]];
    let u1 = move |p: V3| {
        let l = lin_part(p);
        [
            0.01 * p[0] * p[1] + l[0],
            0.005 * (p[0] * p[0] - p[1] * p[1]) + l[1],
            l[2],
        ]
    };
    let u2 = move |p: V3| {
        [
            0.01 * p[0] * p[1],
            -0.01 * (lambda + mu) / (2.0 * mu) * p[0] * p[0],
            0.0,
        ]
    };
    let span = 5.0;
    for (rule, field, exact_expected) in [
        (Rule::Full, &u1 as &dyn Fn(V3) -> V3, true),
        (Rule::MeanDilatation, &u1, true),
        (Rule::Full, &u2, true),
        (Rule::MeanDilatation, &u2, false),
    ] {
        let q = Tet10Mesh::from_linear(&m, rule);
        let holds: Vec<Hold> = q
            .nodes
            .iter()
            .map(|p| {
                // Undo the cube's shear to find its faces.
                let z = p[2];
                let y = p[1] - 0.05 * z;
                let x = p[0] - 0.1 * y;
                let face = [x, y, z]
                    .iter()
                    .any(|v| v.abs() < 1e-9 || (v - span).abs() < 1e-9);
                if face {
                    Hold::Fixed(field(*p))
                } else {
                    Hold::Free
                }
            })
            .collect();
        assert!(holds.contains(&Hold::Free));
        let u = q.solve(&holds, &Loads::none()).unwrap();
        let want: Vec<V3> = q.nodes.iter().map(|p| field(*p)).collect();
        let off = max_diff(&u, &want);
        println!("{rule:?}: off by {off:.2e} mm");
        if exact_expected {
            assert!(off < 1e-12, "{rule:?}: {off}");
        } else {
            assert!(off > 1e-6, "{rule:?}: {off}");
        }
    }
}

#[test]
fn large_twists_converge_by_cutting_steps_and_do_not_depend_on_the_load_path() {
    let (m, ijk) = cube(3, 3.0);
    // The bottom turned about the cube's vertical axis, the top held.
    let twist = |deg: f64| -> Vec<Hold> {
        let r = rotation([0.0, 0.0, 1.0], deg);
        let rc = matvec(&r, [4.5, 4.5, 0.0]);
        bone_rigid(&m, &ijk, &r, [4.5 - rc[0], 4.5 - rc[1], 0.0])
            .into_iter()
            .zip(&ijk)
            .map(|(h, c)| if c[2] == 3 { Hold::Fixed([0.0; 3]) } else { h })
            .collect()
    };
    // CalculiX's energy: the factored path's step cutting is what this test is about (the
    // stable energy's projected tangent converges only linearly in this factored path).
    let opts = Newton {
        tolerance: 1e-12,
        energy: Energy::CalculixNeoHooke,
        ..Newton::default()
    };
    // A hyperelastic equilibrium does not depend on how the load was applied.
    let h90 = twist(90.0);
    let a = nonlinear::solve(&m, &h90, &Loads::none(), &opts).unwrap();
    let b = nonlinear::solve(
        &m,
        &h90,
        &Loads::none(),
        &Newton {
            load_steps: 11,
            ..opts
        },
    )
    .unwrap();
    let off = max_diff(&a.displacements, &b.displacements);
    println!("90° twist: 4 vs 11 load steps differ by {off:.2e} mm");
    assert!(off < 1e-9, "{off}");
    assert!(m.inverted_after(&a.displacements).is_empty());
    // 170° needs smaller steps: the failing ones are halved, and the solve still converges.
    let s = nonlinear::solve(&m, &twist(170.0), &Loads::none(), &opts).unwrap();
    println!(
        "170° twist: {} cuts, steps (load, iterations) {:?}",
        s.cuts,
        s.steps
            .iter()
            .map(|s| (s.load, s.iterations))
            .collect::<Vec<_>>()
    );
    assert!(s.cuts > 0 && s.steps.last().map(|l| l.load) == Some(1.0));
    assert!(
        s.steps
            .iter()
            .all(|st| st.residuals.last().is_some_and(|r| *r <= 1e-12))
    );
    assert!(m.inverted_after(&s.displacements).is_empty());
}

/// The product's nonlinear path (`tet::newton_krylov`: Newton from the linear answer, the
/// linear factor preconditioning CG) with the stable neo-Hookean energy of Smith, de Goes & Kim
/// 2018 against the closed form of a uniaxial stretch: F = diag(λ₁, λ₂, λ₂) with zero lateral
/// stress, P₂₂ = μ (1 − 1/(I_C + 1)) λ₂ + λ (J − α) λ₁ λ₂ = 0 (bisection on λ₂), and against the
/// factored load-stepped Newton of `tet::nonlinear` with the same energy.
#[test]
fn stable_neo_hookean_newton_krylov_matches_the_closed_form_uniaxial_stretch() {
    use facesim::tet::nonlinear::StableNeoHooke;
    let (l, n, stretch) = (10.0, 2, 1.3);
    let h = l / n as f64;
    let mat = TissueElastic {
        youngs_kpa: 10.0,
        poisson: 0.45,
    };
    let (m, _) = grid(
        [n, n, n],
        &|i, j, k| [i as f64 * h, j as f64 * h, k as f64 * h],
        mat,
        mat,
    );
    let near = |a: f64, b: f64| (a - b).abs() < 1e-9;
    let holds = plane_holds(
        &m.nodes,
        &[
            ([1.0, 0.0, 0.0], 0.0, &|p: V3| near(p[0], 0.0)),
            ([1.0, 0.0, 0.0], (stretch - 1.0) * l, &|p: V3| near(p[0], l)),
            ([0.0, 1.0, 0.0], 0.0, &|p: V3| near(p[1], 0.0)),
            ([0.0, 0.0, 1.0], 0.0, &|p: V3| near(p[2], 0.0)),
        ],
    );
    let c = Constrained::new(&m.assemble().unwrap(), &holds, m.nodes.len()).unwrap();
    let f = vec![0.0; 3 * m.nodes.len()];
    let start = c.solve(&[(&holds, &f)]).unwrap().remove(0);
    let opts = facesim::tet::newton_krylov::Options {
        displacement_tolerance_mm: 0.0,
        tolerance: 1e-12,
        ..Default::default()
    };
    let sol = facesim::tet::newton_krylov::solve(&m, &c, &start, &opts).unwrap();
    let s = StableNeoHooke::from_elastic(mat);
    let p22 = |l2: f64| {
        let (j, ic) = (stretch * l2 * l2, stretch * stretch + 2.0 * l2 * l2);
        s.mu * (1.0 - 1.0 / (ic + 1.0)) * l2 + s.lambda * (j - s.alpha) * stretch * l2
    };
    let (mut lo, mut hi) = (0.3, 1.0);
    assert!(p22(lo) < 0.0 && p22(hi) > 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if p22(mid) < 0.0 { lo = mid } else { hi = mid }
    }
    let l2 = 0.5 * (lo + hi);
    let exact: Vec<V3> = m
        .nodes
        .iter()
        .map(|p| [(stretch - 1.0) * p[0], (l2 - 1.0) * p[1], (l2 - 1.0) * p[2]])
        .collect();
    let off = max_diff(&sol.displacements, &exact);
    let linear_off = max_diff(&start, &exact);
    println!(
        "stable neo-Hookean, stretch {stretch}: lateral {l2:.10} (closed form), Newton–Krylov off by {off:.2e} mm in {:?} (the linear start: {linear_off:.3} mm)",
        sol.steps
            .iter()
            .map(|s| (s.iterations, s.krylov_iterations))
            .collect::<Vec<_>>()
    );
    assert!(off < 1e-8, "{off}");
    assert!(linear_off > 0.1, "the start is not already the answer");
    // The factored, load-stepped Newton with the same energy reaches the same equilibrium.
    let factored = nonlinear::solve(
        &m,
        &holds,
        &Loads::none(),
        &Newton {
            tolerance: 1e-12,
            ..Newton::default()
        },
    )
    .unwrap();
    assert!(max_diff(&factored.displacements, &sol.displacements) < 1e-8);
}

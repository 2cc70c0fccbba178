//! Verification of the C1 triangular element against exact invariants and analytic plates
//! Plates: planar (u, v) = (x, y), bending only unless stated, β11 = β12 = β22 = D.

use facesim::fem::assembly::{FemMesh, System, multiply};
use facesim::fem::element::Material;

/// Deterministic uniform numbers in [−1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

/// Square [0, a]² split into n×n cells, two triangles each (alternating diagonals so the mesh
/// has no preferred direction), interior nodes moved by up to `jitter`·h.
fn square(n: usize, a: f64, jitter: f64, seed: u64) -> FemMesh {
    let h = a / n as f64;
    let mut rng = Lcg(seed);
    let mut uv = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let interior = i > 0 && j > 0 && i < n && j < n;
            let (dx, dy) = if interior {
                (jitter * h * rng.next(), jitter * h * rng.next())
            } else {
                (0.0, 0.0)
            };
            uv.push([i as f64 * h + dx, j as f64 * h + dy]);
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i, j + 1), id(i + 1, j + 1));
            if (i + j) % 2 == 0 {
                tris.push([a, b, d]);
                tris.push([a, d, c]);
            } else {
                tris.push([a, b, c]);
                tris.push([b, d, c]);
            }
        }
    }
    FemMesh::new(uv, tris).unwrap()
}

/// Unit disk: the square [−1, 1]² mapped onto it (Fong's elliptical grid map), n×n cells.
fn disk(n: usize, radius: f64) -> FemMesh {
    let mut m = square(n, 2.0, 0.0, 1);
    for p in &mut m.uv {
        let (x, y) = (p[0] - 1.0, p[1] - 1.0);
        *p = [
            radius * x * (1.0 - y * y / 2.0).sqrt(),
            radius * y * (1.0 - x * x / 2.0).sqrt(),
        ];
    }
    FemMesh::new(m.uv, m.tris).unwrap()
}

fn boundary_vertices(m: &FemMesh) -> Vec<bool> {
    let mut b = vec![false; m.uv.len()];
    for (e, ed) in m.edges.iter().enumerate() {
        if m.edge_tris[e] == 1 {
            b[ed[0] as usize] = true;
            b[ed[1] as usize] = true;
        }
    }
    b
}

/// Clamped: value and gradient fixed at boundary nodes, normal slope fixed on boundary edges.
fn clamped(m: &FemMesh) -> Vec<bool> {
    let bv = boundary_vertices(m);
    let mut fixed = vec![false; m.ndof()];
    for (v, &b) in bv.iter().enumerate() {
        if b {
            fixed[3 * v] = true;
            fixed[3 * v + 1] = true;
            fixed[3 * v + 2] = true;
        }
    }
    for e in 0..m.edges.len() {
        if m.edge_tris[e] == 1 {
            fixed[3 * m.uv.len() + e] = true;
        }
    }
    fixed
}

/// Simply supported square [0, a]²: w = 0 and its tangential slope = 0 on the boundary.
fn simply_supported(m: &FemMesh, a: f64) -> Vec<bool> {
    let mut fixed = vec![false; m.ndof()];
    for (v, p) in m.uv.iter().enumerate() {
        let on_x = p[0].abs() < 1e-12 || (p[0] - a).abs() < 1e-12; // edges u = const: w_v = 0
        let on_y = p[1].abs() < 1e-12 || (p[1] - a).abs() < 1e-12; // edges v = const: w_u = 0
        if on_x || on_y {
            fixed[3 * v] = true;
        }
        if on_x {
            fixed[3 * v + 2] = true;
        }
        if on_y {
            fixed[3 * v + 1] = true;
        }
    }
    fixed
}

fn solve_plate(m: &FemMesh, mat: Material, q: f64, fixed: &[bool]) -> Vec<f64> {
    let (k, f) = m.assemble(&|_| mat, q);
    let sys = System::new(m.ndof(), k, fixed).unwrap();
    sys.solve(&[f], &[vec![0.0; m.ndof()]]).remove(0)
}

/// The value DOF of the vertex nearest (u, v).
fn value_at(m: &FemMesh, a: &[f64], at: [f64; 2]) -> f64 {
    let v = (0..m.uv.len())
        .min_by(|&i, &j| {
            let d = |k: usize| (m.uv[k][0] - at[0]).powi(2) + (m.uv[k][1] - at[1]).powi(2);
            d(i).total_cmp(&d(j))
        })
        .unwrap();
    a[3 * v]
}

#[test]
fn surface_is_c1_across_every_interior_edge_of_an_irregular_mesh() {
    let m = square(6, 3.0, 0.3, 7);
    let mut rng = Lcg(99);
    let a: Vec<f64> = (0..m.ndof()).map(|_| rng.next()).collect();
    let local = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    // Edge → the triangles that share it.
    let mut owners: Vec<Vec<usize>> = vec![Vec::new(); m.edges.len()];
    for (t, te) in m.tri_edges.iter().enumerate() {
        for &e in te {
            owners[e as usize].push(t);
        }
    }
    let (mut worst_w, mut worst_g, mut checked) = (0.0f64, 0.0f64, 0);
    for (e, own) in owners.iter().enumerate() {
        if own.len() != 2 {
            continue;
        }
        let [va, vb] = m.edges[e];
        for tau in [0.1, 0.3, 0.5, 0.77, 0.95] {
            let vals: Vec<[f64; 6]> = own
                .iter()
                .map(|&t| {
                    let tri = m.tris[t];
                    let ia = tri.iter().position(|&v| v == va).unwrap();
                    let ib = tri.iter().position(|&v| v == vb).unwrap();
                    let p = [
                        (1.0 - tau) * local[ia][0] + tau * local[ib][0],
                        (1.0 - tau) * local[ia][1] + tau * local[ib][1],
                    ];
                    m.eval(&a, t, p[0], p[1])
                })
                .collect();
            worst_w = worst_w.max((vals[0][0] - vals[1][0]).abs());
            worst_g = worst_g.max(
                (vals[0][1] - vals[1][1])
                    .abs()
                    .max((vals[0][2] - vals[1][2]).abs()),
            );
            checked += 1;
        }
    }
    println!(
        "C1 check: {checked} edge points, max |Δw| = {worst_w:.2e}, max |Δ∇w| = {worst_g:.2e}"
    );
    assert!(checked > 200);
    assert!(
        worst_w < 1e-10 && worst_g < 1e-10,
        "value jump {worst_w:e}, gradient jump {worst_g:e}"
    );
    // The check can fail: second derivatives do jump across edges (C1, not C2).
}

#[test]
fn patch_tests_linear_and_quadratic_fields_on_an_irregular_mesh() {
    let m = square(5, 2.0, 0.3, 3);
    let area = 4.0;
    let field = |f: &dyn Fn([f64; 2]) -> [f64; 3]| -> Vec<f64> {
        let mut a = vec![0.0; m.ndof()];
        for (v, p) in m.uv.iter().enumerate() {
            let d = f(*p);
            a[3 * v] = d[0];
            a[3 * v + 1] = d[1];
            a[3 * v + 2] = d[2];
        }
        for (e, ed) in m.edges.iter().enumerate() {
            let (p, q) = (m.uv[ed[0] as usize], m.uv[ed[1] as usize]);
            let mid = [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])];
            let n = facesim::fem::element::edge_normal(p, q);
            let d = f(mid);
            a[3 * m.uv.len() + e] = d[1] * n[0] + d[2] * n[1];
        }
        a
    };
    let energy = |mat: Material, a: &[f64]| {
        let (k, _) = m.assemble(&|_| mat, 0.0);
        let ka = multiply(&k, a);
        ka.iter().zip(a).map(|(x, y)| x * y).sum::<f64>()
    };
    let bend = Material {
        alpha: [0.0; 3],
        beta: [1.3, 0.7, 0.9],
        foundation: 0.0,
    };
    let lin = field(&|p| [0.4 + 1.5 * p[0] - 0.8 * p[1], 1.5, -0.8]);
    let e = energy(bend, &lin);
    println!("linear field, bending energy {e:.3e}");
    assert!(e.abs() < 1e-10);
    // Stretching of the linear field: ∫ α11 b² + α12 b c + α22 c² = area (…).
    let stretch = Material {
        alpha: [0.6, 0.2, 0.5],
        beta: [0.0; 3],
        foundation: 0.0,
    };
    let e = energy(stretch, &lin);
    let exact = area * (0.6 * 1.5 * 1.5 + 0.2 * 1.5 * -0.8 + 0.5 * 0.64);
    println!("linear field, stretching energy {e:.12} vs {exact:.12}");
    assert!((e / exact - 1.0).abs() < 1e-10);
    // Constant curvature: w = ½ k1 u² + k12 u v + ½ k2 v².
    let (k1, k12, k2) = (0.9, -0.4, 1.7);
    let quad = field(&|p| {
        [
            0.5 * k1 * p[0] * p[0] + k12 * p[0] * p[1] + 0.5 * k2 * p[1] * p[1],
            k1 * p[0] + k12 * p[1],
            k12 * p[0] + k2 * p[1],
        ]
    });
    let e = energy(bend, &quad);
    let exact = area * (1.3 * k1 * k1 + 2.0 * 0.7 * k12 * k12 + 0.9 * k2 * k2);
    println!("quadratic field, bending energy {e:.12} vs {exact:.12}");
    assert!((e / exact - 1.0).abs() < 1e-10);
    // K annihilates constants.
    let k = m.assemble(&|_| Material::isotropic(0.5, 1.0), 0.0).0;
    let c = field(&|_| [3.0, 0.0, 0.0]);
    let kc = multiply(&k, &c);
    let scale = k.iter().map(|t| t.2.abs()).fold(0.0, f64::max);
    assert!(kc.iter().all(|x| x.abs() < 1e-11 * scale * 3.0));
}

#[test]
fn stiffness_is_singular_when_free_and_positive_definite_with_one_rigid_node() {
    let m = square(4, 1.0, 0.2, 5);
    let mat = |_: usize| Material::isotropic(0.01, 0.02);
    let (k, _) = m.assemble(&mat, 0.0);
    let none = vec![false; m.ndof()];
    let r = m.check_constraints(&mat, &none);
    assert!(r.is_err(), "a free surface must be reported singular");
    assert!(r.err().unwrap().to_string().contains("singular"));
    // Pure bending with only one value fixed still has a tilting null space.
    let bend = |_: usize| Material {
        alpha: [0.0; 3],
        beta: [1.0; 3],
        foundation: 0.0,
    };
    let mut value_only = vec![false; m.ndof()];
    value_only[0] = true;
    assert!(m.check_constraints(&bend, &value_only).is_err());
    let mut one = vec![false; m.ndof()];
    one[..3].iter_mut().for_each(|f| *f = true);
    m.check_constraints(&mat, &one).unwrap();
    m.check_constraints(&bend, &one).unwrap();
    let sys = System::new(m.ndof(), k.clone(), &one).expect("PD once one node is rigid");
    // Positive definite: random free vectors have positive energy.
    let mut rng = Lcg(4);
    for _ in 0..20 {
        let mut x: Vec<f64> = (0..m.ndof()).map(|_| rng.next()).collect();
        x[..3].iter_mut().for_each(|v| *v = 0.0);
        let e: f64 = multiply(&k, &x).iter().zip(&x).map(|(a, b)| a * b).sum();
        assert!(e > 0.0);
    }
    assert_eq!(sys.free.len(), m.ndof() - 3);
}

const CLAMPED_SQUARE: f64 = 0.001265319; // w(centre) / (q a⁴ / D), Timoshenko
const SS_SQUARE: f64 = 0.00406235; // Navier

fn centre_deflection(m: &FemMesh, fixed: &[bool], a: f64) -> f64 {
    let w = solve_plate(
        m,
        Material {
            alpha: [0.0; 3],
            beta: [1.0; 3],
            foundation: 0.0,
        },
        1.0,
        fixed,
    );
    value_at(m, &w, [a / 2.0, a / 2.0])
}

#[test]
fn clamped_square_plate_converges_to_timoshenko() {
    let mut prev_err = f64::NAN;
    let mut rates = Vec::new();
    for n in [4, 8, 16] {
        let m = square(n, 1.0, 0.0, 1);
        let w = centre_deflection(&m, &clamped(&m), 1.0);
        let err = (w / CLAMPED_SQUARE - 1.0).abs();
        if prev_err.is_finite() {
            rates.push((prev_err / err).log2());
        }
        println!(
            "clamped square n = {n}: w = {w:.9}, error {:.4}%",
            100.0 * err
        );
        prev_err = err;
    }
    println!("observed convergence rates: {rates:?}");
    assert!(prev_err < 0.005, "regular 16×16: {:.3}%", 100.0 * prev_err);
    assert!(rates.iter().all(|r| *r > 1.5), "rates {rates:?}");
    // Irregular mesh: interior nodes jittered by up to 25% of h.
    let m = square(16, 1.0, 0.25, 11);
    let w = centre_deflection(&m, &clamped(&m), 1.0);
    let err = (w / CLAMPED_SQUARE - 1.0).abs();
    println!(
        "clamped square, perturbed 16×16: w = {w:.9}, error {:.4}%",
        100.0 * err
    );
    assert!(err < 0.005);
}

#[test]
fn simply_supported_square_plate_matches_navier() {
    let m = square(16, 1.0, 0.0, 1);
    let w = centre_deflection(&m, &simply_supported(&m, 1.0), 1.0);
    let err = (w / SS_SQUARE - 1.0).abs();
    println!(
        "simply supported 16×16: w = {w:.9} vs {SS_SQUARE}, error {:.4}%",
        100.0 * err
    );
    assert!(err < 0.005);
}

#[test]
fn clamped_circular_plate_matches_q_a4_over_64d() {
    let exact = 1.0 / 64.0;
    let m = disk(24, 1.0);
    let w = centre_deflection(&m, &clamped(&m), 0.0);
    let err = (w / exact - 1.0).abs();
    println!(
        "clamped disk: w = {w:.9} vs {exact}, error {:.4}%",
        100.0 * err
    );
    assert!(err < 0.01);
}

/// Navier series for β∇⁴w − α∇²w + c w = q on the simply supported square [0, a]².
fn navier_foundation(a: f64, beta: f64, alpha: f64, c: f64, q: f64, x: f64, y: f64) -> f64 {
    let pi = std::f64::consts::PI;
    let mut w = 0.0;
    for m in (1..400).step_by(2) {
        for n in (1..400).step_by(2) {
            let k2 = (m as f64 * pi / a).powi(2) + (n as f64 * pi / a).powi(2);
            let qmn = 16.0 * q / (pi * pi * m as f64 * n as f64);
            w += qmn / (beta * k2 * k2 + alpha * k2 + c)
                * (m as f64 * pi * x / a).sin()
                * (n as f64 * pi * y / a).sin();
        }
    }
    w
}

#[test]
fn plate_on_an_elastic_foundation_matches_navier() {
    let (beta, alpha, c) = (1.0, 10.0, 500.0);
    let exact = navier_foundation(1.0, beta, alpha, c, 1.0, 0.5, 0.5);
    // The series check: without stretching and foundation it is the plain Navier value.
    assert!((navier_foundation(1.0, 1.0, 0.0, 0.0, 1.0, 0.5, 0.5) / SS_SQUARE - 1.0).abs() < 1e-4);
    let m = square(16, 1.0, 0.0, 1);
    let mat = Material {
        alpha: [alpha, 0.0, alpha],
        beta: [beta; 3],
        foundation: c,
    };
    // α ∫ |∇w|² is the stretching term of eq. 4 with α11 = α22 = α (E-L: −α∇²w); ∫ c w² the foundation.
    let w = solve_plate(&m, mat, 1.0, &simply_supported(&m, 1.0));
    let got = value_at(&m, &w, [0.5, 0.5]);
    let err = (got / exact - 1.0).abs();
    println!(
        "SS plate on foundation: w = {got:.9} vs Navier {exact:.9}, error {:.4}%",
        100.0 * err
    );
    assert!(err < 0.005);
}

//! Preloading (a_init, F_init = K a_init), rigid-node boundary conditions, symbolic reuse and
//! C1 surface sampling.

use crate::common;

use facesim::fem::assembly::{FemMesh, System, multiply, rigid_dofs};
use facesim::fem::element::{Material, edge_normal};
use facesim::fem::preload::{initial_dofs, sample};

fn jittered_grid(n: usize, seed: u64) -> FemMesh {
    let mut s = seed;
    let mut rnd = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let mut uv = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let inner = i > 0 && j > 0 && i < n && j < n;
            let d = if inner {
                [0.5 * rnd(), 0.5 * rnd()]
            } else {
                [0.0, 0.0]
            };
            uv.push([i as f64 + d[0], j as f64 + d[1]]);
        }
    }
    FemMesh::new(uv, common::grid_triangles(n)).unwrap()
}

fn quad(p: [f64; 2]) -> [f64; 3] {
    let (u, v) = (p[0], p[1]);
    [
        2.0 + 0.3 * u - 0.2 * v + 0.05 * u * u - 0.07 * u * v + 0.02 * v * v,
        0.3 + 0.1 * u - 0.07 * v,
        -0.2 - 0.07 * u + 0.04 * v,
    ]
}

#[test]
fn initial_dofs_reproduce_a_quadratic_surface_exactly() {
    let m = jittered_grid(8, 3);
    let values: Vec<f64> = m.uv.iter().map(|p| quad(*p)[0]).collect();
    let a = initial_dofs(&m, &values).unwrap();
    let mut worst = 0.0f64;
    for (v, p) in m.uv.iter().enumerate() {
        let q = quad(*p);
        worst = worst
            .max((a[3 * v + 1] - q[1]).abs())
            .max((a[3 * v + 2] - q[2]).abs());
    }
    for (e, ed) in m.edges.iter().enumerate() {
        let (p, r) = (m.uv[ed[0] as usize], m.uv[ed[1] as usize]);
        let mid = [0.5 * (p[0] + r[0]), 0.5 * (p[1] + r[1])];
        let n = edge_normal(p, r);
        let q = quad(mid);
        worst = worst.max((a[3 * m.uv.len() + e] - (q[1] * n[0] + q[2] * n[1])).abs());
    }
    println!("largest derivative error of the fitted DOFs: {worst:.2e}");
    assert!(worst < 1e-10);
    // Level-1 sampling gives back exactly the mesh's vertices.
    let s = sample(&m, &[a.clone(), a.clone(), a.clone()], 1);
    let mut got: Vec<f64> = s.vertices.iter().map(|p| p[2]).collect();
    let mut want = values.clone();
    got.sort_by(f64::total_cmp);
    want.sort_by(f64::total_cmp);
    assert!(got.iter().zip(&want).all(|(p, v)| (p - v).abs() < 1e-12));
    assert_eq!(s.vertices.len(), m.uv.len());
}

#[test]
fn sampling_shares_edge_vertices_and_follows_the_field() {
    let m = jittered_grid(5, 8);
    let fields: [Vec<f64>; 3] = [
        m.uv.iter().map(|p| p[0]).collect(),
        m.uv.iter().map(|p| p[1]).collect(),
        m.uv.iter().map(|p| quad(*p)[0]).collect(),
    ];
    let a = [0, 1, 2].map(|c| initial_dofs(&m, &fields[c]).unwrap());
    for level in [1, 2, 4] {
        let s = sample(&m, &a, level);
        // Euler: V = nv + ne (level − 1) + nt (level − 1)(level − 2)/2, T = nt level².
        let expect_v = m.uv.len()
            + m.edges.len() * (level - 1)
            + m.tris.len() * (level - 1) * level.saturating_sub(2) / 2;
        assert_eq!(s.vertices.len(), expect_v, "level {level}");
        assert_eq!(s.triangles.len(), m.tris.len() * level * level);
        s.check(std::path::Path::new("sampled")).unwrap();
        // x, y are linear and z quadratic in (u, v): every sample lies on z = quad(x, y).
        let worst = s
            .vertices
            .iter()
            .map(|p| (p[2] - quad([p[0], p[1]])[0]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-10, "level {level}: {worst:e}");
    }
}

#[test]
fn preloaded_phantom_face_returns_its_own_shape() {
    // The phantom's face scan with its cylindrical (u, v), α = 0.01, β = 0.02, rigid outside
    // the case's movable sphere: with no load change the solve must return a_init.
    let scan = facesim::mesh::read_mesh(&common::phantom_dir().join("face.ply")).unwrap();
    let mut mesh = scan.clone();
    facesim::surface::cylindrical_uv(&mut mesh, [0.0, 0.0], facesim_validate::phantom::R_SKIN);
    let col = |n: &str| {
        mesh.vertex_columns
            .iter()
            .find(|c| c.name == n)
            .unwrap()
            .values
            .clone()
    };
    let (u, v) = (col("u"), col("v"));
    let uv: Vec<[f64; 2]> = u.iter().zip(&v).map(|(a, b)| [*a, *b]).collect();
    let m = FemMesh::new(uv, scan.triangles.clone()).unwrap();
    let a_init: Vec<Vec<f64>> = (0..3)
        .map(|c| initial_dofs(&m, &scan.vertices.iter().map(|p| p[c]).collect::<Vec<_>>()).unwrap())
        .collect();
    let centre = [0.0, -60.0, -45.0];
    let rigid: Vec<bool> = scan
        .vertices
        .iter()
        .map(|p| (0..3).map(|k| (p[k] - centre[k]).powi(2)).sum::<f64>() > 70.0f64 * 70.0)
        .collect();
    let fixed = rigid_dofs(&m, &rigid);
    let mat = |_: usize| Material::isotropic(0.01, 0.02);
    m.check_constraints(&mat, &fixed).unwrap();
    let (k, _) = m.assemble(&mat, 0.0);
    let f_init: Vec<Vec<f64>> = a_init.iter().map(|a| multiply(&k, a)).collect();
    let mut sys = System::new(m.ndof(), k.clone(), &fixed).unwrap();
    let a = sys.solve(&f_init, &a_init);
    let mut worst = 0.0f64;
    for c in 0..3 {
        let scale = a_init[c].iter().fold(0.0f64, |s, x| s.max(x.abs()));
        let err = a[c]
            .iter()
            .zip(&a_init[c])
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
            / scale;
        worst = worst.max(err);
    }
    println!(
        "preload: {} DOFs ({} free), {} rigid vertices; max relative |a − a_init| = {worst:.2e}",
        m.ndof(),
        sys.free.len(),
        rigid.iter().filter(|r| **r).count()
    );
    assert!(worst < 1e-9);
    // Reusing the symbolic analysis: doubling K (and the loads) leaves the solution; doubling
    // only K halves the free part of a load response.
    let k2: Vec<(usize, usize, f64)> = k.iter().map(|&(r, c, v)| (r, c, 2.0 * v)).collect();
    let unit: Vec<f64> = (0..m.ndof())
        .map(|i| if fixed[i] { 0.0 } else { 1.0 })
        .collect();
    let zero = vec![0.0; m.ndof()];
    let x1 = sys
        .solve(std::slice::from_ref(&unit), std::slice::from_ref(&zero))
        .remove(0);
    sys.refactor(k2).unwrap();
    let x2 = sys.solve(&[unit], &[zero]).remove(0);
    let worst = x1
        .iter()
        .zip(&x2)
        .map(|(a, b)| (a - 2.0 * b).abs())
        .fold(0.0, f64::max)
        / x1.iter().fold(0.0f64, |s, x| s.max(x.abs()));
    assert!(worst < 1e-9, "{worst:e}");
}

//! The shell embedding (paper 002) that carries a fine skin along a coarse solve:
//! exact invariants — rest shape, rigid motions, the Poisson thickness rule (eq. 2).

use crate::common;

use facesim::embed::Shell;
use facesim::mesh::Mesh;

/// A flat n×n grid of `size` mm in the z = 0 plane, counter-clockwise seen from +z.
fn grid(n: usize, size: f64) -> Mesh {
    let mut v = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            // A slight irregularity so no test passes by symmetry alone.
            let w = 0.07 * ((i * 7 + j * 3) % 5) as f64 / 5.0;
            v.push([
                size * (i as f64 + w) / n as f64,
                size * (j as f64 - w) / n as f64,
                0.0,
            ]);
        }
    }
    Mesh::new(v, common::grid_triangles(n))
}

/// A closed-ish curved patch: the grid wrapped onto a cylinder of radius 40 mm.
fn curved(n: usize) -> Mesh {
    let mut m = grid(n, 60.0);
    for p in &mut m.vertices {
        let a = p[0] / 40.0;
        *p = [40.0 * a.sin(), p[1], 40.0 * (1.0 - a.cos())];
    }
    m
}

/// Points near the base: inside the shell (depth 0.2–2.5 mm) and just outside it (−0.4 mm).
fn points(m: &Mesh, inward: f64) -> Vec<[f64; 3]> {
    let nrm = m.vertex_normals();
    let mut p = Vec::new();
    for (k, t) in m.triangles.iter().enumerate().step_by(3) {
        let w = [0.2 + 0.1 * (k % 4) as f64, 0.3, 0.0];
        let w = [w[0], w[1], 1.0 - w[0] - w[1]];
        let depth = [-0.4, 0.2, 1.0, 2.5][k % 4];
        let mut x = [0.0; 3];
        for c in 0..3 {
            for a in 0..3 {
                x[c] +=
                    w[a] * (m.vertices[t[a] as usize][c] + inward * depth * nrm[t[a] as usize][c]);
            }
        }
        p.push(x);
    }
    p
}

fn worst(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max)
}

#[test]
fn the_rest_shell_gives_back_the_embedded_points() {
    let m = curved(12);
    let shell = Shell::new(&m, 3.0, -1.0, 0.45, &vec![false; m.vertices.len()]).unwrap();
    let p = points(&m, -1.0);
    let e = shell.embed(&p);
    let x = shell.deform(&m.vertices);
    assert!(
        worst(&x, shell.rest()) < 1e-9,
        "offset moved at rest: {}",
        worst(&x, shell.rest())
    );
    let back = shell.carry(&e, &x);
    assert!(worst(&back, &p) < 1e-9, "{}", worst(&back, &p));
}

#[test]
fn a_rigid_motion_of_the_base_moves_embedded_points_rigidly() {
    let m = curved(12);
    let shell = Shell::new(&m, 3.0, -1.0, 0.3, &vec![false; m.vertices.len()]).unwrap();
    let p = points(&m, -1.0);
    let e = shell.embed(&p);
    let (a, b, c) = (0.3f64, -0.5f64, 0.8f64);
    let rot = |v: [f64; 3]| {
        // R = Rz(c) Ry(b) Rx(a), then a translation.
        let v = [
            v[0],
            a.cos() * v[1] - a.sin() * v[2],
            a.sin() * v[1] + a.cos() * v[2],
        ];
        let v = [
            b.cos() * v[0] + b.sin() * v[2],
            v[1],
            -b.sin() * v[0] + b.cos() * v[2],
        ];
        let v = [
            c.cos() * v[0] - c.sin() * v[1],
            c.sin() * v[0] + c.cos() * v[1],
            v[2],
        ];
        [v[0] + 5.0, v[1] - 3.0, v[2] + 11.0]
    };
    let moved: Vec<[f64; 3]> = m.vertices.iter().map(|v| rot(*v)).collect();
    let got = shell.carry(&e, &shell.deform(&moved));
    let want: Vec<[f64; 3]> = p.iter().map(|v| rot(*v)).collect();
    assert!(
        worst(&got, &want) < 1e-8,
        "rigid motion error {}",
        worst(&got, &want)
    );
}

#[test]
fn stretching_the_base_thins_the_shell_by_the_poisson_rule() {
    // Uniform in-plane stretch s of a flat sheet: every reference tetrahedron has the same
    // target gradient diag(s, s, (s²)^{ν/(ν−1)}) (eq. 2), which one affine map meets, so the fit
    // is exact: depth d → d (s²)^{ν/(ν−1)}; ν = 0.5 keeps the shell's volume, ν = 0 its depth.
    let m = grid(10, 50.0);
    let s = 1.2;
    for nu in [0.0, 0.3, 0.5] {
        let shell = Shell::new(&m, 3.0, -1.0, nu, &vec![false; m.vertices.len()]).unwrap();
        let p = points(&m, -1.0);
        let e = shell.embed(&p);
        let moved: Vec<[f64; 3]> = m
            .vertices
            .iter()
            .map(|v| [s * v[0], s * v[1], v[2]])
            .collect();
        let x = shell.deform(&moved);
        let factor = (s * s).powf(nu / (nu - 1.0));
        let got = shell.carry(&e, &x);
        let want: Vec<[f64; 3]> = p
            .iter()
            .map(|v| [s * v[0], s * v[1], factor * v[2]])
            .collect();
        assert!(
            worst(&got, &want) < 1e-9,
            "ν = {nu}: error {}",
            worst(&got, &want)
        );
        let n = m.vertices.len();
        let depth = -x[n][2];
        assert!(
            (depth - 3.0 * factor).abs() < 1e-9,
            "ν = {nu}: shell depth {depth}"
        );
        if nu == 0.5 {
            // Volume kept: area × s², depth ÷ s².
            assert!((depth * s * s - 3.0).abs() < 1e-9);
        }
    }
}

#[test]
fn fixed_offsets_stay_and_bad_parameters_are_refused() {
    let m = curved(8);
    let n = m.vertices.len();
    let fixed: Vec<bool> = m.vertices.iter().map(|v| v[1] > 40.0).collect();
    let shell = Shell::new(&m, 3.0, -1.0, 0.45, &fixed).unwrap();
    let moved: Vec<[f64; 3]> = m
        .vertices
        .iter()
        .map(|v| {
            if v[1] < 20.0 {
                [v[0], v[1] - 2.0, v[2]]
            } else {
                *v
            }
        })
        .collect();
    let x = shell.deform(&moved);
    for i in (0..n).filter(|&i| fixed[i]) {
        assert_eq!(x[n + i], shell.rest()[n + i]);
    }
    assert!(Shell::new(&m, 0.0, -1.0, 0.45, &fixed).is_err());
    assert!(Shell::new(&m, 3.0, -1.0, 0.7, &fixed).is_err());
}

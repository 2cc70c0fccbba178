//! `facesim-lab bench fem`: assembly + factorisation + three solves of the C1 surface system on a
//! planar mesh of a given size (the numbers in docs/design/fem.md).

use facesim::error::{Error, NumericalKind, Result};
use facesim::fem::assembly::{FemMesh, System, rigid_dofs};
use facesim::fem::element::Material;
use serde::Serialize;
use std::time::Instant;

#[derive(Serialize, Debug)]
pub struct FemBench {
    pub triangles: usize,
    pub vertices: usize,
    pub dofs: usize,
    pub free_dofs: usize,
    pub nnz_k_lower: usize,
    pub nnz_l: usize,
    pub fill: f64,
    pub seconds_elements: f64,
    pub seconds_assembly: f64,
    pub seconds_factor: f64,
    pub seconds_three_solves: f64,
    pub seconds_total: f64,
    pub peak_rss_mb: Option<f64>,
    pub threads: usize,
}

/// Peak resident memory of this process (Linux: VmHWM).
pub fn peak_rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// `export`: also write the factored matrix (free–free lower triangle) as Matrix Market, for
/// timing another sparse Cholesky on the same matrix (benches/cholmod_compare.sh).
pub fn run(target_triangles: usize, export: Option<&std::path::Path>) -> Result<FemBench> {
    let n = ((target_triangles as f64 / 2.0).sqrt().round() as usize).max(2);
    let (uv, tris) = jittered_grid(n);
    let t0 = Instant::now();
    let mesh = FemMesh::new(uv, tris)?;
    let t_el = t0.elapsed().as_secs_f64();
    let rigid: Vec<bool> = mesh
        .uv
        .iter()
        .map(|p| p[0] < 0.5 || p[1] < 0.5 || p[0] > n as f64 - 0.5 || p[1] > n as f64 - 0.5)
        .collect();
    let fixed = rigid_dofs(&mesh, &rigid);
    let mat = |_: usize| Material::isotropic(0.01, 0.02);
    let t1 = Instant::now();
    let (k, f) = mesh.assemble(&mat, 1.0);
    let t_as = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let sys = System::new(mesh.ndof(), k, &fixed)?;
    let t_fa = t2.elapsed().as_secs_f64();
    let zero = vec![0.0; mesh.ndof()];
    let t3 = Instant::now();
    let x = sys.solve(
        &[f.clone(), f.clone(), f],
        &[zero.clone(), zero.clone(), zero],
    );
    let t_so = t3.elapsed().as_secs_f64();
    if x.iter().flatten().any(|v| !v.is_finite()) {
        return Err(Error::numerical(
            NumericalKind::Diverged,
            "benchmark solve produced non-finite values",
        ));
    }
    if let Some(path) = export {
        export_matrix(&sys, path)?;
    }
    // Factor size, from a separate symbolic analysis (not timed).
    let lower = sys.nnz_lower;
    let nnz_l = sys.factor_nnz()?;
    Ok(FemBench {
        triangles: mesh.tris.len(),
        vertices: mesh.uv.len(),
        dofs: mesh.ndof(),
        free_dofs: sys.free.len(),
        nnz_k_lower: lower,
        nnz_l,
        fill: nnz_l as f64 / lower as f64,
        seconds_elements: t_el,
        seconds_assembly: t_as,
        seconds_factor: t_fa,
        seconds_three_solves: t_so,
        seconds_total: t_el + t_as + t_fa + t_so,
        peak_rss_mb: peak_rss_mb(),
        threads: rayon::current_num_threads(),
    })
}

/// A jittered planar n × n grid, 1 mm cells, alternating diagonals (a fixed seed, so every run
/// solves the same mesh); the border vertices stay on the square.
fn jittered_grid(n: usize) -> (Vec<[f64; 2]>, Vec<[u32; 3]>) {
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let mut uv = Vec::with_capacity((n + 1) * (n + 1));
    for j in 0..=n {
        for i in 0..=n {
            let inner = i > 0 && j > 0 && i < n && j < n;
            let d = if inner {
                [0.4 * rnd(), 0.4 * rnd()]
            } else {
                [0.0, 0.0]
            };
            uv.push([i as f64 + d[0], j as f64 + d[1]]);
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut tris = Vec::with_capacity(2 * n * n);
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i, j + 1), id(i + 1, j + 1));
            if (i + j) % 2 == 0 {
                tris.extend([[a, b, d], [a, d, c]]);
            } else {
                tris.extend([[a, b, c], [b, d, c]]);
            }
        }
    }
    (uv, tris)
}

/// Write the factored matrix (the free–free lower triangle, 1-based) as Matrix Market.
fn export_matrix(sys: &System, path: &std::path::Path) -> Result<()> {
    let entries: Vec<(usize, usize, f64)> = sys
        .k
        .iter()
        .filter_map(|&(r, c, v)| {
            let (fr, fc) = (sys.free_index[r], sys.free_index[c]);
            (fr != usize::MAX && fc != usize::MAX).then_some((fr, fc, v))
        })
        .collect();
    let nf = sys.free.len();
    facesim::output::write_bytes_atomic(path, |w| {
        writeln!(w, "%%MatrixMarket matrix coordinate real symmetric")?;
        writeln!(w, "{nf} {nf} {}", entries.len())?;
        for (r, c, v) in &entries {
            writeln!(w, "{} {} {v:e}", r + 1, c + 1)?;
        }
        Ok(())
    })
}

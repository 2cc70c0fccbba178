//! Linear elastodynamics for the solver study (Alterovitz & Goldberg 2003, docs/lab/study.md):
//! small-strain FEM of the 2-D block benchmark on bilinear quads in **plane strain**,
//! consistent and lumped mass, Rayleigh damping C = αM + βK, and four integrators — implicit
//! Newmark (average acceleration), explicit Newmark (central difference) with consistent mass,
//! explicit with lumped mass, and quasi-static. Explicit integration that blows up is detected
//! and reported as "diverged at step N (t = …)", never NaN output.
//!
//! Matrices are kept dense for the products (the benchmark grids are small); every linear solve
//! goes through a faer sparse Cholesky factored once per integrator run.

use facesim::fem::cholesky::Cholesky;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Material parameters (SI units: Pa, –, kg/m³).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MaterialSi {
    pub e: f64,
    pub nu: f64,
    pub rho: f64,
}

/// MP1 (E 200 Pa, ν 0.47, ρ 2000) and MP2 (prostate: E 60 kPa, ν 0.495, ρ 1140).
pub const MP1: MaterialSi = MaterialSi {
    e: 200.0,
    nu: 0.47,
    rho: 2000.0,
};
pub const MP2: MaterialSi = MaterialSi {
    e: 60_000.0,
    nu: 0.495,
    rho: 1140.0,
};
/// MP3, the rod (E 7000 Pa, ν 0.2, ρ 10000).
pub const MP3: MaterialSi = MaterialSi {
    e: 7000.0,
    nu: 0.2,
    rho: 10_000.0,
};

/// The 1 m × 1 m block on an n×n grid of bilinear quads: top, bottom and left edges fixed; the
/// needle at the middle node of the right edge moves left at 0.08 m/s for 2 s, then holds.
pub struct Block {
    pub n: usize,
    pub k: DMatrix<f64>,
    pub m_consistent: DMatrix<f64>,
    pub m_lumped: DVector<f64>,
    /// Free DOFs and the needle's DOF (x of the right-edge midpoint; none for the rod).
    pub free: Vec<usize>,
    pub needle: Option<usize>,
    /// Constant body force on every DOF (gravity; zero for the block).
    pub body_force: DVector<f64>,
    /// 2 (block, plane strain) or 3 (rod).
    pub dim: usize,
    /// Undeformed node positions (m; z = 0 in 2-D).
    pub coords: Vec<[f64; 3]>,
    /// Each node's share of the undeformed area/volume (nodal quadrature weights).
    pub node_weights: Vec<f64>,
    /// The boundary: the outline's nodes counter-clockwise (2-D) or triangles (3-D).
    pub outline: Vec<usize>,
    pub boundary_triangles: Vec<[usize; 3]>,
}

impl Block {
    pub fn new(n: usize, mat: MaterialSi) -> Block {
        assert!(
            n >= 2 && n.is_multiple_of(2),
            "an even grid puts a node at the right edge's middle"
        );
        let grid = QuadGrid { n };
        let h = 1.0 / n as f64;
        let nn = (n + 1) * (n + 1);
        let nd = 2 * nn;
        let (ke, me) = quad_element(h, mat);
        let (k, m) = assemble(nd, &ke, &me, grid.element_dofs());
        let m_lumped = row_sums(&m);
        let needle = 2 * grid.node(n, n / 2);
        let node_weights = (0..nn).map(|v| m_lumped[2 * v] / mat.rho).collect();
        Block {
            n,
            k,
            m_consistent: m,
            m_lumped,
            free: grid.free_dofs(needle),
            needle: Some(needle),
            body_force: DVector::zeros(nd),
            dim: 2,
            coords: grid.coords(h),
            node_weights,
            outline: grid.outline(),
            boundary_triangles: Vec::new(),
        }
    }

    /// The 3-D rod (MP3 benchmark): 0.25 × 0.5 × 0.25 m (long along y), trilinear hexes on an
    /// nx × ny × nz grid, the y = 0 face fixed, gravity `g` (m/s²) along −z.
    pub fn rod(nx: usize, ny: usize, nz: usize, mat: MaterialSi, g: f64) -> Block {
        let grid = HexGrid { nx, ny, nz };
        let size = [0.25, 0.5, 0.25];
        let h = [
            size[0] / nx as f64,
            size[1] / ny as f64,
            size[2] / nz as f64,
        ];
        let (ke, me) = hex_element(h, mat);
        let nn = (nx + 1) * (ny + 1) * (nz + 1);
        let nd = 3 * nn;
        let (kg, mg) = assemble(nd, &ke, &me, grid.element_dofs());
        let m_lumped = row_sums(&mg);
        // Gravity: the consistent body force ρ g ∫ N = (row sums of M) · g on the z DOFs.
        let body_force = DVector::from_iterator(
            nd,
            (0..nd).map(|r| if r % 3 == 2 { -g * m_lumped[r] } else { 0.0 }),
        );
        let node_weights = (0..nn).map(|v| m_lumped[3 * v] / mat.rho).collect();
        Block {
            n: ny,
            k: kg,
            m_consistent: mg,
            m_lumped,
            free: grid.free_dofs(),
            needle: None,
            body_force,
            dim: 3,
            coords: grid.coords(h),
            node_weights,
            outline: Vec::new(),
            boundary_triangles: grid.boundary_triangles(),
        }
    }

    /// Deformed node positions for a full displacement vector.
    pub fn deformed(&self, u: &[f64]) -> Vec<[f64; 3]> {
        let d = self.dim;
        self.coords
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let mut q = *p;
                for c in 0..d {
                    q[c] += u[d * v + c];
                }
                q
            })
            .collect()
    }

    /// Needle displacement (x, m) at time t: −0.08 t for t ≤ 2 s, then held at −0.16.
    pub fn needle_at(t: f64) -> f64 {
        -0.08 * t.min(2.0)
    }

    fn sub(&self, a: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(self.free.len(), self.free.len(), |i, j| {
            a[(self.free[i], self.free[j])]
        })
    }

    fn coupling(&self, a: &DMatrix<f64>) -> DVector<f64> {
        match self.needle {
            Some(nd) => {
                DVector::from_iterator(self.free.len(), self.free.iter().map(|&i| a[(i, nd)]))
            }
            None => DVector::zeros(self.free.len()),
        }
    }

    /// Prescribed needle displacement and velocity at t (zero without a needle).
    fn needle_motion(&self, t: f64) -> (f64, f64) {
        match self.needle {
            Some(_) => (Block::needle_at(t), if t < 2.0 { -0.08 } else { 0.0 }),
            None => (0.0, 0.0),
        }
    }
}

/// Adds one Gauss point's contribution to the element matrices: w BᵀDB to `ke` and w ρ NᵢNⱼ to
/// `me` between equal displacement components (`nval.len()` nodes, N / nodes components each).
fn add_gauss_point<const N: usize, const S: usize>(
    ke: &mut [[f64; N]],
    me: &mut [[f64; N]],
    b: &[[f64; N]; S],
    d: &[[f64; S]; S],
    nval: &[f64],
    w: f64,
    rho: f64,
) {
    let dim = N / nval.len();
    for i in 0..N {
        for j in 0..N {
            let mut s = 0.0;
            for p in 0..S {
                for q in 0..S {
                    s += b[p][i] * d[p][q] * b[q][j];
                }
            }
            ke[i][j] += w * s;
            if i % dim == j % dim {
                me[i][j] += w * rho * nval[i / dim] * nval[j / dim];
            }
        }
    }
}

/// Scatters the element matrices into dense global K and M, element by element.
fn assemble<const N: usize>(
    nd: usize,
    ke: &[[f64; N]],
    me: &[[f64; N]],
    elements: impl Iterator<Item = [usize; N]>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut k = DMatrix::zeros(nd, nd);
    let mut m = DMatrix::zeros(nd, nd);
    for dofs in elements {
        for a in 0..N {
            for b in 0..N {
                k[(dofs[a], dofs[b])] += ke[a][b];
                m[(dofs[a], dofs[b])] += me[a][b];
            }
        }
    }
    (k, m)
}

/// Row sums of the consistent mass: the lumped (diagonal) mass.
fn row_sums(m: &DMatrix<f64>) -> DVector<f64> {
    DVector::from_iterator(m.nrows(), (0..m.nrows()).map(|r| m.row(r).sum()))
}

/// Stiffness and consistent mass of one square bilinear quad of side h (plane strain; every
/// element of the block is the same square).
fn quad_element(h: f64, mat: MaterialSi) -> ([[f64; 8]; 8], [[f64; 8]; 8]) {
    let (e, nu) = (mat.e, mat.nu);
    let f = e / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let d = [
        [f * (1.0 - nu), f * nu, 0.0],
        [f * nu, f * (1.0 - nu), 0.0],
        [0.0, 0.0, f * (1.0 - 2.0 * nu) / 2.0],
    ];
    let g = 1.0 / 3f64.sqrt();
    let gauss = [(-g, -g), (g, -g), (g, g), (-g, g)];
    let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    let mut ke = [[0.0; 8]; 8];
    let mut me = [[0.0; 8]; 8];
    let jac = h / 2.0; // dx/dξ
    for &(xi, eta) in &gauss {
        let nvals: Vec<f64> = corners
            .iter()
            .map(|&(a, b)| 0.25 * (1.0 + a * xi) * (1.0 + b * eta))
            .collect();
        let dx: Vec<f64> = corners
            .iter()
            .map(|&(a, b)| 0.25 * a * (1.0 + b * eta) / jac)
            .collect();
        let dy: Vec<f64> = corners
            .iter()
            .map(|&(a, b)| 0.25 * b * (1.0 + a * xi) / jac)
            .collect();
        let w = jac * jac; // weights are 1 for the 2-point rule
        // B: strain (εxx, εyy, γxy) from (u1x, u1y, …).
        let mut b = [[0.0; 8]; 3];
        for a in 0..4 {
            b[0][2 * a] = dx[a];
            b[1][2 * a + 1] = dy[a];
            b[2][2 * a] = dy[a];
            b[2][2 * a + 1] = dx[a];
        }
        add_gauss_point(&mut ke, &mut me, &b, &d, &nvals, w, mat.rho);
    }
    (ke, me)
}

/// Stiffness and consistent mass of one trilinear hex with sides h (2×2×2 Gauss points).
fn hex_element(h: [f64; 3], mat: MaterialSi) -> (Vec<[f64; 24]>, Vec<[f64; 24]>) {
    let d = isotropic_3d(mat.e, mat.nu);
    let gp = 1.0 / 3f64.sqrt();
    let corners: Vec<[f64; 3]> = (0..8)
        .map(|c| {
            [
                if c & 1 != 0 { 1.0 } else { -1.0 },
                if c & 2 != 0 { 1.0 } else { -1.0 },
                if c & 4 != 0 { 1.0 } else { -1.0 },
            ]
        })
        .collect();
    let jac = [h[0] / 2.0, h[1] / 2.0, h[2] / 2.0];
    let w = jac[0] * jac[1] * jac[2];
    let mut ke = vec![[0.0; 24]; 24];
    let mut me = vec![[0.0; 24]; 24];
    for q in &corners {
        let x = [q[0] * gp, q[1] * gp, q[2] * gp];
        let nval: Vec<f64> = corners
            .iter()
            .map(|c| (0..3).map(|a| 0.5 * (1.0 + c[a] * x[a])).product())
            .collect();
        let grad: Vec<[f64; 3]> = corners
            .iter()
            .map(|c| {
                let f = |a: usize| 0.5 * (1.0 + c[a] * x[a]);
                [
                    0.5 * c[0] * f(1) * f(2) / jac[0],
                    0.5 * c[1] * f(0) * f(2) / jac[1],
                    0.5 * c[2] * f(0) * f(1) / jac[2],
                ]
            })
            .collect();
        // B: (εxx, εyy, εzz, γxy, γyz, γzx) from (u1x, u1y, u1z, …).
        let mut b = [[0.0; 24]; 6];
        for a in 0..8 {
            let ba = strain_rows_3d(grad[a]);
            for r in 0..6 {
                b[r][3 * a..3 * a + 3].copy_from_slice(&ba[r]);
            }
        }
        add_gauss_point(&mut ke, &mut me, &b, &d, &nval, w, mat.rho);
    }
    (ke, me)
}

/// The block's n×n quad grid; node (i, j) at (i h, j h).
struct QuadGrid {
    n: usize,
}

impl QuadGrid {
    fn node(&self, i: usize, j: usize) -> usize {
        j * (self.n + 1) + i
    }

    /// Each element's 8 DOFs (corners counter-clockwise, x and y), rows of elements bottom up.
    fn element_dofs(&self) -> impl Iterator<Item = [usize; 8]> + '_ {
        (0..self.n).flat_map(move |j| {
            (0..self.n).map(move |i| {
                let nodes = [
                    self.node(i, j),
                    self.node(i + 1, j),
                    self.node(i + 1, j + 1),
                    self.node(i, j + 1),
                ];
                let mut dofs = [0; 8];
                for (a, v) in nodes.into_iter().enumerate() {
                    dofs[2 * a] = 2 * v;
                    dofs[2 * a + 1] = 2 * v + 1;
                }
                dofs
            })
        })
    }

    /// DOFs not on the fixed top, bottom and left edges, without the prescribed needle DOF.
    fn free_dofs(&self, needle: usize) -> Vec<usize> {
        let n = self.n;
        let mut free = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let fixed_node = j == 0 || j == n || i == 0;
                for c in 0..2 {
                    let dof = 2 * self.node(i, j) + c;
                    if !fixed_node && dof != needle {
                        free.push(dof);
                    }
                }
            }
        }
        free
    }

    fn coords(&self, h: f64) -> Vec<[f64; 3]> {
        let n = self.n;
        (0..(n + 1) * (n + 1))
            .map(|v| [(v % (n + 1)) as f64 * h, (v / (n + 1)) as f64 * h, 0.0])
            .collect()
    }

    /// The boundary nodes counter-clockwise from the origin.
    fn outline(&self) -> Vec<usize> {
        let n = self.n;
        let mut outline: Vec<usize> = (0..=n).map(|i| self.node(i, 0)).collect();
        outline.extend((1..=n).map(|j| self.node(n, j)));
        outline.extend((0..n).rev().map(|i| self.node(i, n)));
        outline.extend((1..n).rev().map(|j| self.node(0, j)));
        outline
    }
}

/// The rod's nx × ny × nz hex grid; node (i, j, k) at (i hx, j hy, k hz).
struct HexGrid {
    nx: usize,
    ny: usize,
    nz: usize,
}

impl HexGrid {
    fn node(&self, i: usize, j: usize, k: usize) -> usize {
        (k * (self.ny + 1) + j) * (self.nx + 1) + i
    }

    /// Each element's 24 DOFs (corner c at offset (c & 1, c >> 1 & 1, c >> 2 & 1), x y z each).
    fn element_dofs(&self) -> impl Iterator<Item = [usize; 24]> + '_ {
        (0..self.nz).flat_map(move |k| {
            (0..self.ny).flat_map(move |j| {
                (0..self.nx).map(move |i| {
                    let mut dofs = [0; 24];
                    for c in 0..8 {
                        let v = self.node(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
                        dofs[3 * c..3 * c + 3].copy_from_slice(&[3 * v, 3 * v + 1, 3 * v + 2]);
                    }
                    dofs
                })
            })
        })
    }

    /// Every DOF off the fixed y = 0 face.
    fn free_dofs(&self) -> Vec<usize> {
        let mut free = Vec::new();
        for k in 0..=self.nz {
            for j in 0..=self.ny {
                for i in 0..=self.nx {
                    if j > 0 {
                        let v = self.node(i, j, k);
                        free.extend([3 * v, 3 * v + 1, 3 * v + 2]);
                    }
                }
            }
        }
        free
    }

    fn coords(&self, h: [f64; 3]) -> Vec<[f64; 3]> {
        let (nx, ny, nz) = (self.nx, self.ny, self.nz);
        (0..(nx + 1) * (ny + 1) * (nz + 1))
            .map(|v| {
                let (i, j, k) = (
                    v % (nx + 1),
                    (v / (nx + 1)) % (ny + 1),
                    v / ((nx + 1) * (ny + 1)),
                );
                [i as f64 * h[0], j as f64 * h[1], k as f64 * h[2]]
            })
            .collect()
    }

    /// Boundary quads of the grid, two triangles each (orientation is irrelevant to the
    /// ray-integrated volumes; `enclosed_volume` takes the absolute value).
    fn boundary_triangles(&self) -> Vec<[usize; 3]> {
        let (nx, ny, nz) = (self.nx, self.ny, self.nz);
        let node = |i, j, k| self.node(i, j, k);
        let mut boundary_triangles = Vec::new();
        let mut quad = |q: [usize; 4]| {
            boundary_triangles.push([q[0], q[1], q[2]]);
            boundary_triangles.push([q[0], q[2], q[3]]);
        };
        for j in 0..ny {
            for k in 0..nz {
                for i in [0, nx] {
                    quad([
                        node(i, j, k),
                        node(i, j + 1, k),
                        node(i, j + 1, k + 1),
                        node(i, j, k + 1),
                    ]);
                }
            }
            for i in 0..nx {
                for k in [0, nz] {
                    quad([
                        node(i, j, k),
                        node(i + 1, j, k),
                        node(i + 1, j + 1, k),
                        node(i, j + 1, k),
                    ]);
                }
            }
        }
        for i in 0..nx {
            for k in 0..nz {
                for j in [0, ny] {
                    quad([
                        node(i, j, k),
                        node(i + 1, j, k),
                        node(i + 1, j, k + 1),
                        node(i, j, k + 1),
                    ]);
                }
            }
        }
        boundary_triangles
    }
}

/// Isotropic linear elasticity in 3-D, Voigt order (εxx, εyy, εzz, γxy, γyz, γzx): Lamé λ, μ
/// from E and ν. Shared by the rod's hexes and the study's tetrahedra.
pub fn isotropic_3d(e: f64, nu: f64) -> [[f64; 6]; 6] {
    let lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let mu = e / (2.0 * (1.0 + nu));
    let mut d = [[0.0; 6]; 6];
    for i in 0..3 {
        for j in 0..3 {
            d[i][j] = lam + if i == j { 2.0 * mu } else { 0.0 };
        }
        d[i + 3][i + 3] = mu;
    }
    d
}

/// One node's 6×3 block of the strain–displacement matrix B (same Voigt order) from the
/// gradient of its shape function.
pub fn strain_rows_3d([gx, gy, gz]: [f64; 3]) -> [[f64; 3]; 6] {
    [
        [gx, 0.0, 0.0],
        [0.0, gy, 0.0],
        [0.0, 0.0, gz],
        [gy, gx, 0.0],
        [0.0, gz, gy],
        [gz, 0.0, gx],
    ]
}

/// A symmetric positive definite matrix factored once by the sparse Cholesky (the benchmark
/// matrices are banded: a dense factor would waste O(n³) on zeros).
struct SpdFactor {
    llt: Cholesky<f64>,
}

impl SpdFactor {
    // The matrices are built by the benchmark itself (no user input) and positive definite by
    // construction; a failure here is a bug, so it may panic.
    #[allow(clippy::expect_used)]
    fn new(m: &DMatrix<f64>) -> SpdFactor {
        use faer::sparse::{SparseColMat, Triplet};
        let n = m.nrows();
        let mut t = Vec::new();
        for c in 0..n {
            for r in c..n {
                if m[(r, c)] != 0.0 {
                    t.push(Triplet::new(r, c, m[(r, c)]));
                }
            }
        }
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t)
            .expect("triplets within bounds");
        let llt = Cholesky::new(a.as_ref())
            .expect("benchmark matrices (K, M, Newmark's K_eff) are positive definite");
        SpdFactor { llt }
    }

    fn solve(&self, b: &DVector<f64>) -> DVector<f64> {
        let mut x = faer::Mat::<f64>::from_fn(b.len(), 1, |i, _| b[i]);
        self.llt.solve_in_place(x.as_mut());
        DVector::from_fn(b.len(), |i, _| x[(i, 0)])
    }
}

/// r ↦ M⁻¹ r.
type MassSolve = Box<dyn Fn(&DVector<f64>) -> DVector<f64>>;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Integrator {
    ImplicitNewmark,
    ExplicitConsistent,
    ExplicitLumped,
    QuasiStatic,
}

impl Integrator {
    /// Every integrator, the implicit reference first.
    pub const ALL: [Integrator; 4] = [
        Integrator::ImplicitNewmark,
        Integrator::ExplicitConsistent,
        Integrator::ExplicitLumped,
        Integrator::QuasiStatic,
    ];
}

#[derive(Clone, Debug, Serialize)]
pub struct Run {
    pub integrator: Integrator,
    pub h: f64,
    /// Full displacement vectors per step (empty when diverged before the first).
    pub history: Vec<Vec<f64>>,
    /// "diverged at step N (t = … s)" when the integration blew up.
    pub diverged: Option<String>,
}

/// The equations of motion restricted to the free DOFs, M ü + C u̇ + K u = load(t), with the
/// needle's prescribed motion moved into the load.
struct FreeSystem<'a> {
    block: &'a Block,
    kff: DMatrix<f64>,
    kfp: DVector<f64>,
    /// Consistent, or lumped (diagonal) for `ExplicitLumped`.
    mff: DMatrix<f64>,
    /// The lumped masses of the free DOFs.
    ml: DVector<f64>,
    cff: DMatrix<f64>,
    cfp: DVector<f64>,
    body: DVector<f64>,
}

impl<'a> FreeSystem<'a> {
    fn new(block: &'a Block, lumped: bool, (ra, rb): (f64, f64)) -> FreeSystem<'a> {
        let nf = block.free.len();
        let kff = block.sub(&block.k);
        let kfp = block.coupling(&block.k);
        let mc = block.sub(&block.m_consistent);
        let mcp = block.coupling(&block.m_consistent);
        let ml = DVector::from_iterator(nf, block.free.iter().map(|&i| block.m_lumped[i]));
        let mff = if lumped {
            DMatrix::from_diagonal(&ml)
        } else {
            mc
        };
        let mfp = if lumped { DVector::zeros(nf) } else { mcp };
        let cff = &mff * ra + &kff * rb;
        let cfp = &mfp * ra + &kfp * rb;
        let body = DVector::from_iterator(nf, block.free.iter().map(|&i| block.body_force[i]));
        FreeSystem {
            block,
            kff,
            kfp,
            mff,
            ml,
            cff,
            cfp,
            body,
        }
    }

    /// Forces on the free DOFs from the prescribed needle (its acceleration is zero between the
    /// start and stop instants).
    fn load(&self, t: f64) -> DVector<f64> {
        let (g, gd) = self.block.needle_motion(t);
        &self.body - (&self.kfp * g) - (&self.cfp * gd)
    }

    /// The full displacement vector: free DOFs from u, the needle at its prescribed place.
    fn full(&self, u: &DVector<f64>, t: f64) -> Vec<f64> {
        let block = self.block;
        let mut x = vec![0.0; block.k.nrows()];
        for (i, &d) in block.free.iter().enumerate() {
            x[d] = u[i];
        }
        if let Some(nd) = block.needle {
            x[nd] = Block::needle_at(t);
        }
        x
    }

    fn quasi_static(&self, run: &mut Run, steps: usize) {
        let kc = SpdFactor::new(&self.kff);
        for s in 1..=steps {
            let t = s as f64 * run.h;
            let (g, _) = self.block.needle_motion(t);
            let u = kc.solve(&(&self.body - (&self.kfp * g)));
            run.history.push(self.full(&u, t));
        }
    }

    /// Average-acceleration Newmark (β = 1/4, γ = 1/2), starting at rest.
    fn implicit_newmark(&self, run: &mut Run, steps: usize) {
        let (kff, cff, mff) = (&self.kff, &self.cff, &self.mff);
        let h = run.h;
        let nf = kff.nrows();
        let (mut u, mut v) = (DVector::<f64>::zeros(nf), DVector::<f64>::zeros(nf));
        let (beta, gamma) = (0.25, 0.5);
        let keff =
            SpdFactor::new(&(kff + cff * (gamma / (beta * h)) + mff * (1.0 / (beta * h * h))));
        let mc0 = SpdFactor::new(mff);
        let mut a = mc0.solve(&(self.load(0.0) - cff * &v - kff * &u));
        for s in 1..=steps {
            let t = s as f64 * h;
            let rhs = self.load(t)
                + mff
                    * (&u * (1.0 / (beta * h * h))
                        + &v * (1.0 / (beta * h))
                        + &a * (1.0 / (2.0 * beta) - 1.0))
                + cff
                    * (&u * (gamma / (beta * h))
                        + &v * (gamma / beta - 1.0)
                        + &a * (h * (gamma / (2.0 * beta) - 1.0)));
            let un = keff.solve(&rhs);
            let an = (&un - &u) * (1.0 / (beta * h * h))
                - &v * (1.0 / (beta * h))
                - &a * (1.0 / (2.0 * beta) - 1.0);
            let vn = &v + &a * (h * (1.0 - gamma)) + &an * (h * gamma);
            u = un;
            v = vn;
            a = an;
            run.history.push(self.full(&u, t));
        }
    }

    /// Central difference: u_{n+1} = u_n + h v_n + h²/2 a_n; damping taken at the predicted
    /// velocity so that lumped mass stays explicit (a diagonal solve). Starts at rest; stops at
    /// the first step that diverges.
    fn central_difference(&self, run: &mut Run, steps: usize, lumped: bool) {
        let (kff, cff) = (&self.kff, &self.cff);
        let h = run.h;
        let nf = kff.nrows();
        let (mut u, mut v) = (DVector::<f64>::zeros(nf), DVector::<f64>::zeros(nf));
        let minv: MassSolve = if lumped {
            let inv = self.ml.map(|x| 1.0 / x);
            Box::new(move |r: &DVector<f64>| r.component_mul(&inv))
        } else {
            let mc0 = SpdFactor::new(&self.mff);
            Box::new(move |r: &DVector<f64>| mc0.solve(r))
        };
        let mut a = minv(&(self.load(0.0) - cff * &v - kff * &u));
        for s in 1..=steps {
            let t = s as f64 * h;
            u = &u + &v * h + &a * (0.5 * h * h);
            let vp = &v + &a * (0.5 * h);
            a = minv(&(self.load(t) - cff * &vp - kff * &u));
            v = vp + &a * (0.5 * h);
            if u.iter().any(|x| !x.is_finite() || x.abs() > 100.0) {
                run.diverged = Some(format!("diverged at step {s} (t = {t:.3} s)"));
                break;
            }
            run.history.push(self.full(&u, t));
        }
    }
}

/// Integrate `steps` steps of size h with Rayleigh damping (α, β). Divergence: a non-finite value
/// or a displacement beyond 100 m (the block is 1 m; the needle moves 0.16 m).
pub fn integrate(
    block: &Block,
    integrator: Integrator,
    h: f64,
    steps: usize,
    rayleigh: (f64, f64),
) -> Run {
    let lumped = integrator == Integrator::ExplicitLumped;
    let system = FreeSystem::new(block, lumped, rayleigh);
    let mut run = Run {
        integrator,
        h,
        history: Vec::with_capacity(steps),
        diverged: None,
    };
    match integrator {
        Integrator::QuasiStatic => system.quasi_static(&mut run, steps),
        Integrator::ImplicitNewmark => system.implicit_newmark(&mut run, steps),
        Integrator::ExplicitConsistent | Integrator::ExplicitLumped => {
            system.central_difference(&mut run, steps, lumped)
        }
    }
    run
}

/// Largest generalised eigenvalue ω² of (K, M) on the free DOFs, by power iteration on M⁻¹K;
/// the undamped central-difference stability limit is h_crit = 2/ω.
pub fn critical_step(block: &Block, lumped: bool) -> f64 {
    let kff = block.sub(&block.k);
    let nf = block.free.len();
    let ml = DVector::from_iterator(nf, block.free.iter().map(|&i| block.m_lumped[i]));
    let mc = SpdFactor::new(&block.sub(&block.m_consistent));
    let mut x = DVector::from_fn(nf, |i, _| 1.0 + ((i * 7919) % 13) as f64 / 13.0);
    let mut lambda = 0.0;
    for _ in 0..2000 {
        let y = &kff * &x;
        let z = if lumped {
            y.component_div(&ml)
        } else {
            mc.solve(&y)
        };
        let l = z.norm() / x.norm();
        x = &z / z.norm();
        if (l - lambda).abs() < 1e-12 * l {
            lambda = l;
            break;
        }
        lambda = l;
    }
    2.0 / lambda.sqrt()
}

/// Relative energy norm ‖u' − u‖_K / ‖u‖_K (Alterovitz & Goldberg's first metric).
pub fn relative_energy_error(block: &Block, u: &[f64], reference: &[f64]) -> f64 {
    let du = DVector::from_iterator(u.len(), u.iter().zip(reference).map(|(a, b)| a - b));
    let r = DVector::from_column_slice(reference);
    ((du.transpose() * &block.k * &du)[0] / (r.transpose() * &block.k * &r)[0].max(1e-300)).sqrt()
}

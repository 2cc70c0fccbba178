//! The full-resolution skin carried along a coarse solve, after Chen et
//! al., "Embedding geometric textures in a shell space" (§1.2 and §2).
//!
//! The solve runs on a coarse copy of the skin (the *base* mesh M_b). A shell S is built
//! between M_b and an *offset* mesh M_o, each base vertex moved inwards by `thickness` along its
//! normal; every base triangle and its offset make a prism, split into three tetrahedra. Each
//! fine skin vertex p is embedded by barycentric coordinates λ in one tetrahedron of the rest
//! shell (p = Φ x). After the solve the base mesh is deformed; the offset mesh follows by the
//! paper's least-squares fit of deformation gradients (eq. 1), with each triangle's target
//! gradient m′ taken from a reference tetrahedron whose fourth node is placed by the Poisson
//! rule (eq. 2): x̂_c + (Â/A)^{ν/(ν−1)} h n̂. The fine vertices then follow as p̂ = Φ x̂.
//!
//! Differences from the paper, and why:
//! - E is uniform (one tissue layer), so the weight √(EV) reduces to √V.
//! - Offset vertices above rigid base vertices may be held at rest (`fixed`): the skin there
//!   cannot move, and without it the least-squares fit would spread a little motion into it.
//! - Fine vertices slightly outside the shell (the coarse skin cuts through the fine one) use
//!   their tetrahedron's affine map extrapolated (λ may be negative); the tetrahedron is chosen
//!   in the prism of the nearest base triangle, with the largest smallest λ.
//! - The dynamic part of the paper (§3, vibration around the goal positions) does not apply to a
//!   static prediction and is not built.

use crate::compare::DistanceStats;
use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::System;
use crate::mesh::Mesh;
use crate::vec3::{add, cross, dot, norm, scale, sub};
use nalgebra::Matrix3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The rest shell and the factorised offset fit (eq. 1), ready to deform many times.
pub struct Shell {
    /// Base vertex count N; shell vertex i < N is base vertex i, N + i is its offset.
    n: usize,
    tris: Vec<[u32; 3]>,
    /// Rest shell vertices (base then offset).
    rest: Vec<[f64; 3]>,
    /// Tetrahedra (shell vertex ids); tetrahedra 3t..3t+3 fill the prism over triangle t.
    tets: Vec<[u32; 4]>,
    /// Per tetrahedron: ∂F/∂q_a (F = Σ_a q_a g_aᵀ) and rest volume.
    grads: Vec<[[f64; 3]; 4]>,
    volumes: Vec<f64>,
    /// Per triangle: rest area A, offset distance h (paper §2), inverse rest reference edges.
    area: Vec<f64>,
    h: Vec<f64>,
    ref_inv: Vec<Matrix3<f64>>,
    /// +1 when the mesh's counter-clockwise normals point inwards, −1 when outwards.
    inward: f64,
    nu: f64,
    system: System,
}

/// Where each fine vertex sits in the rest shell.
pub struct Embedding {
    pub tet: Vec<u32>,
    pub weights: Vec<[f64; 4]>,
    /// Distance from the fine vertex to the base mesh (mm), for the report.
    pub distance: Vec<f64>,
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = norm(v);
    if l > 0.0 { scale(v, 1.0 / l) } else { v }
}

fn columns(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Matrix3<f64> {
    Matrix3::new(a[0], b[0], c[0], a[1], b[1], c[1], a[2], b[2], c[2])
}

/// Reference tetrahedron edges of a triangle (paper §2): the triangle's two edges and the
/// vector from its first corner to x_c + d n (n the inward unit normal, d the height).
fn reference_edges(p: [[f64; 3]; 3], inward: f64, d: f64) -> (Matrix3<f64>, f64) {
    let f = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let area = 0.5 * norm(f);
    let n = scale(unit(f), inward);
    let c = scale(add(add(p[0], p[1]), p[2]), 1.0 / 3.0);
    let top = add(c, scale(n, d));
    (
        columns(sub(p[1], p[0]), sub(p[2], p[0]), sub(top, p[0])),
        area,
    )
}

/// Rest shell vertices: the base vertices, then each one moved `thickness` along its vertex
/// normal on the side `inward` (the offset mesh).
fn rest_vertices(base: &Mesh, thickness: f64, inward: f64) -> Vec<[f64; 3]> {
    let normals = base.vertex_normals();
    let mut rest = base.vertices.clone();
    rest.extend(
        base.vertices
            .iter()
            .zip(&normals)
            .map(|(p, nv)| add(*p, scale(*nv, inward * thickness))),
    );
    rest
}

/// Three tetrahedra per prism (tetrahedra 3t..3t+3 over triangle t); `n` base vertices, so the
/// offset of vertex v is n + v.
fn prism_tetrahedra(tris: &[[u32; 3]], n: usize) -> Vec<[u32; 4]> {
    let mut tets = Vec::with_capacity(3 * tris.len());
    for t in tris {
        // Split with the corners in increasing id, so neighbouring prisms cut their shared
        // quad along the same diagonal (a conforming tetrahedral shell).
        let mut s = *t;
        s.sort_unstable();
        let [a, b, c] = s;
        let o = |v: u32| v + n as u32;
        tets.push([a, b, c, o(a)]);
        tets.push([b, c, o(a), o(b)]);
        tets.push([c, o(a), o(b), o(c)]);
    }
    tets
}

/// Per tetrahedron: the gradients g_a of F = Σ_a q_a g_aᵀ and the rest volume.
struct Gradients {
    grads: Vec<[[f64; 3]; 4]>,
    volumes: Vec<f64>,
}

/// The shell's `Gradients`. Fails on a flat tetrahedron (relative to the shell's thickness).
fn tet_gradients(tets: &[[u32; 4]], rest: &[[f64; 3]], thickness: f64) -> Result<Gradients> {
    let mut grads = Vec::with_capacity(tets.len());
    let mut volumes = Vec::with_capacity(tets.len());
    for (k, tet) in tets.iter().enumerate() {
        let q = tet.map(|v| rest[v as usize]);
        let m = columns(sub(q[0], q[3]), sub(q[1], q[3]), sub(q[2], q[3]));
        let det = m.determinant();
        let inv = m
            .try_inverse()
            .filter(|_| det.abs() > 1e-12 * thickness.powi(3));
        let Some(inv) = inv else {
            return Err(Error::numerical(
                NumericalKind::DegenerateElement,
                format!(
                    "shell embedding: prism tetrahedron {k} (triangle {}) is flat; the coarse skin has a zero-area triangle",
                    k / 3
                ),
            ));
        };
        // F = Σ_{a<3} (q_a − q_3) r_aᵀ with r_a row a of M⁻¹, so g_a = r_a, g_3 = −Σ r_a.
        let r = [0, 1, 2].map(|a| [inv[(a, 0)], inv[(a, 1)], inv[(a, 2)]]);
        let g3 = [0, 1, 2].map(|c| -(r[0][c] + r[1][c] + r[2][c]));
        grads.push([r[0], r[1], r[2], g3]);
        volumes.push(det.abs() / 6.0);
    }
    Ok(Gradients { grads, volumes })
}

/// Per base triangle: rest area A, offset distance h and the inverse edges of its rest reference
/// tetrahedron (paper §2).
struct References {
    area: Vec<f64>,
    h: Vec<f64>,
    ref_inv: Vec<Matrix3<f64>>,
}

/// The shell's `References`; `rest` holds the base vertices then their offsets. Fails on a
/// zero-area triangle.
fn reference_tetrahedra(
    tris: &[[u32; 3]],
    rest: &[[f64; 3]],
    inward: f64,
    thickness: f64,
) -> Result<References> {
    let n = rest.len() / 2;
    let mut area = Vec::with_capacity(tris.len());
    let mut h = Vec::with_capacity(tris.len());
    let mut ref_inv = Vec::with_capacity(tris.len());
    for (ti, t) in tris.iter().enumerate() {
        let p = t.map(|v| rest[v as usize]);
        let o = t.map(|v| rest[n + v as usize]);
        let f = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        let nn = scale(unit(f), inward);
        let oc = scale(add(add(o[0], o[1]), o[2]), 1.0 / 3.0);
        // h: distance from the offset triangle's centre to the base triangle's plane. At a
        // crease of the coarse skin (vertex normals far from the face normal, e.g. at a
        // nostril or an ear on an extracted skin) it can come out tiny or negative; there
        // the reference tetrahedron takes the shell's nominal depth instead.
        let d = dot(sub(oc, p[0]), nn);
        let d = if d > 0.1 * thickness { d } else { thickness };
        let (e, a) = reference_edges(p, inward, d);
        let Some(inv) = e.try_inverse().filter(|_| a > 0.0) else {
            return Err(Error::numerical(
                NumericalKind::DegenerateElement,
                format!("shell embedding: triangle {ti} of the coarse skin has zero area"),
            ));
        };
        area.push(a);
        h.push(d);
        ref_inv.push(inv);
    }
    Ok(References { area, h, ref_inv })
}

/// The factorised offset fit. Eq. 1 per coordinate: Σ_tets V |Σ_a q_a g_a − m′_row|² → L q = b
/// with L_ab = Σ V g_a·g_b (the same matrix for x, y and z). Base vertices are prescribed, and
/// so are the offsets of the `fixed` base vertices.
fn offset_fit(
    n: usize,
    tets: &[[u32; 4]],
    grads: &[[[f64; 3]; 4]],
    volumes: &[f64],
    fixed: &[bool],
) -> Result<System> {
    let mut trip: Vec<(usize, usize, f64)> = Vec::with_capacity(tets.len() * 10);
    for ((tet, g), v) in tets.iter().zip(grads).zip(volumes) {
        for a in 0..4 {
            for b in 0..4 {
                let (ra, rb) = (tet[a] as usize, tet[b] as usize);
                if ra >= rb {
                    trip.push((ra, rb, v * dot(g[a], g[b])));
                }
            }
        }
    }
    let mut fixed_all = vec![true; n];
    fixed_all.extend((0..n).map(|i| fixed.get(i).copied().unwrap_or(false)));
    System::new(2 * n, trip, &fixed_all).map_err(|e| {
        Error::numerical(
            NumericalKind::Singular,
            format!("shell embedding: offset fit is singular ({e})"),
        )
    })
}

impl Shell {
    /// Build the rest shell over `base` (the coarse pre-operative skin), `thickness` mm deep on
    /// the side `inward` (+1: along the counter-clockwise normals, −1: against them), with
    /// Poisson ratio `nu` for the thickness rule, and offset vertices of `fixed` base vertices
    /// held at rest. Fails on a degenerate prism (a fold or a zero-area triangle).
    pub fn new(base: &Mesh, thickness: f64, inward: f64, nu: f64, fixed: &[bool]) -> Result<Shell> {
        let n = base.vertices.len();
        if !(thickness > 0.0) || !(0.0..0.5 + 1e-12).contains(&nu) {
            return Err(Error::config(format!(
                "shell embedding: thickness {thickness} mm must be > 0 and Poisson ratio {nu} in [0, 0.5]"
            )));
        }
        let rest = rest_vertices(base, thickness, inward);
        let tris = base.triangles.clone();
        let tets = prism_tetrahedra(&tris, n);
        let Gradients { grads, volumes } = tet_gradients(&tets, &rest, thickness)?;
        let References { area, h, ref_inv } =
            reference_tetrahedra(&tris, &rest, inward, thickness)?;
        let system = offset_fit(n, &tets, &grads, &volumes, fixed)?;
        Ok(Shell {
            n,
            tris,
            rest,
            tets,
            grads,
            volumes,
            area,
            h,
            ref_inv,
            inward,
            nu,
            system,
        })
    }

    /// Embed `points` (the fine pre-operative skin) in the rest shell.
    pub fn embed(&self, points: &[[f64; 3]]) -> Embedding {
        let base = Mesh::new(self.rest[..self.n].to_vec(), self.tris.clone());
        let index = crate::compare::SurfaceIndex::new(&base);
        let found: Vec<(u32, [f64; 4], f64)> = points
            .par_iter()
            .map(|&p| {
                let (d, _, t) = index.closest_triangle(p);
                let (k, w) = (3 * t..3 * t + 3)
                    .map(|k| (k, self.barycentric(k, p)))
                    .max_by(|a, b| {
                        let m = |w: &[f64; 4]| w.iter().cloned().fold(f64::INFINITY, f64::min);
                        m(&a.1).total_cmp(&m(&b.1))
                    })
                    .unwrap_or((3 * t, [1.0, 0.0, 0.0, 0.0]));
                (k as u32, w, d)
            })
            .collect();
        Embedding {
            tet: found.iter().map(|f| f.0).collect(),
            weights: found.iter().map(|f| f.1).collect(),
            distance: found.iter().map(|f| f.2).collect(),
        }
    }

    /// Barycentric coordinates of p in rest tetrahedron k (p = Σ λ_a q_a, Σ λ_a = 1).
    fn barycentric(&self, k: usize, p: [f64; 3]) -> [f64; 4] {
        // λ_a = g_a · (p − q_3) for a < 3 (the gradients of the linear shape functions).
        let q3 = self.rest[self.tets[k][3] as usize];
        let g = &self.grads[k];
        let d = sub(p, q3);
        let l = [dot(g[0], d), dot(g[1], d), dot(g[2], d)];
        [l[0], l[1], l[2], 1.0 - l[0] - l[1] - l[2]]
    }

    /// The deformed shell (base then offset) for deformed base vertices `base` (eq. 1–2).
    pub fn deform(&self, base: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let n = self.n;
        // Target gradient m′ per triangle from its reference tetrahedron (eq. 2).
        let exponent = self.nu / (self.nu - 1.0);
        let targets: Vec<Matrix3<f64>> = (0..self.tris.len())
            .into_par_iter()
            .map(|t| {
                let p = self.tris[t].map(|v| base[v as usize]);
                let a_hat = 0.5 * norm(cross(sub(p[1], p[0]), sub(p[2], p[0])));
                let ratio = if self.area[t] > 0.0 {
                    a_hat / self.area[t]
                } else {
                    1.0
                };
                let d = ratio.max(1e-12).powf(exponent) * self.h[t];
                let (e, _) = reference_edges(p, self.inward, d);
                e * self.ref_inv[t]
            })
            .collect();
        let mut rhs = [vec![0.0; 2 * n], vec![0.0; 2 * n], vec![0.0; 2 * n]];
        for (k, tet) in self.tets.iter().enumerate() {
            let m = &targets[k / 3];
            let (g, v) = (&self.grads[k], self.volumes[k]);
            for a in 0..4 {
                for (c, r) in rhs.iter_mut().enumerate() {
                    let row = [m[(c, 0)], m[(c, 1)], m[(c, 2)]];
                    r[tet[a] as usize] += v * dot(g[a], row);
                }
            }
        }
        let prescribed: Vec<Vec<f64>> = (0..3)
            .map(|c| {
                (0..2 * n)
                    .map(|i| if i < n { base[i][c] } else { self.rest[i][c] })
                    .collect()
            })
            .collect();
        let x = self.system.solve(&rhs, &prescribed);
        (0..2 * n).map(|i| [x[0][i], x[1][i], x[2][i]]).collect()
    }

    /// The deformed positions of embedded points: p̂ = Σ λ_a x̂_a.
    pub fn carry(&self, e: &Embedding, shell: &[[f64; 3]]) -> Vec<[f64; 3]> {
        e.tet
            .par_iter()
            .zip(&e.weights)
            .map(|(&k, w)| {
                let tet = self.tets[k as usize];
                (0..4).fold([0.0; 3], |acc, a| {
                    add(acc, scale(shell[tet[a] as usize], w[a]))
                })
            })
            .collect()
    }

    /// Carry `fine` (points on or near the pre-operative skin `coarse` that was solved) to where
    /// the solved positions `solved` of `coarse`'s vertices take them: the shell built inward
    /// from `coarse` (depth and Poisson ratio from `[solve]`, `fixed` vertices held), the points
    /// embedded in it at rest and carried with its deformation. Returns the carried points and
    /// the embedding (its distances tell how far the points lay from the coarse skin).
    pub fn carry_skin(
        coarse: &Mesh,
        solved: &[[f64; 3]],
        fine: &[[f64; 3]],
        scene: (&crate::volume::Volume, &[u8]),
        solve: &crate::case::Solve,
        fixed: &[bool],
    ) -> Result<(Vec<[f64; 3]>, Embedding)> {
        let inward = -crate::springs::outward_sign(coarse, scene.0, scene.1);
        let shell = Shell::new(coarse, solve.shell_mm, inward, solve.shell_poisson, fixed)?;
        let e = shell.embed(fine);
        let carried = shell.carry(&e, &shell.deform(solved));
        Ok((carried, e))
    }

    /// The derivative of the carried points with respect to the base vertices at `base`, in the
    /// direction `delta` (one per base vertex): the plan basis's carry of a coarse solve's
    /// linearised response (docs/design/plan-basis.md). The offset fit's targets depend on the deformed
    /// triangles' normals and areas, so the carry is not linear in the base; its derivative is
    /// taken by central differences with the largest step 1e-3 mm (truncation O(step²),
    /// rounding ~1e-13 mm per unit).
    pub(crate) fn carry_derivative(
        &self,
        e: &Embedding,
        base: &[[f64; 3]],
        delta: &[[f64; 3]],
    ) -> Vec<[f64; 3]> {
        let largest = delta.iter().map(|d| norm(*d)).fold(0.0, f64::max);
        if largest == 0.0 {
            return vec![[0.0; 3]; e.tet.len()];
        }
        let h = 1e-3 / largest;
        let moved = |sign: f64| -> Vec<[f64; 3]> {
            let b: Vec<[f64; 3]> = base
                .iter()
                .zip(delta)
                .map(|(p, d)| add(*p, scale(*d, sign * h)))
                .collect();
            self.carry(e, &self.deform(&b))
        };
        let (plus, minus) = (moved(1.0), moved(-1.0));
        plus.iter()
            .zip(&minus)
            .map(|(p, m)| scale(sub(*p, *m), 0.5 / h))
            .collect()
    }

    /// Rest shell vertices (base then offset), e.g. to write the shell for inspection.
    pub fn rest(&self) -> &[[f64; 3]] {
        &self.rest
    }
}

/// The shell embedding that carried the full skin along the coarse answer.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EmbeddingReport {
    pub shell_mm: f64,
    pub poisson: f64,
    pub fine_to_coarse_mm: DistanceStats,
}

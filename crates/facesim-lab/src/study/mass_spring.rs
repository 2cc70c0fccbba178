//! Surface mass-spring baseline (after Punak, docs/lab/study.md): the skin mesh's vertices are masses,
//! its edges are linear springs, and each vertex keeps the same skull springs as the C1 models
//! (same attachments, rest lengths and stiffness k_c k_i c). Rest lengths are the pre-operative
//! ones, so the pre-operative face is an equilibrium (the mass-spring form of preloading).
//!
//! Edge stiffness k_ij = α (cot θ + cot θ')/2 (clamped at 0): the cotangent discretisation of the
//! same stretching energy α/2 ∫|∇x|² the C1 element integrates, so both models share α; springs
//! only resist stretch along the edge. Flexion springs across each interior edge (β/ℓ²) stand
//! in for bending.
//!
//! Equilibrium by damped Verlet (dynamic relaxation): x⁺ = x + (1 − ζ)(x − x⁻) + h² F/m with
//! lumped masses m_i = k_i (area), the step h = 0.9 × 2/√λ_max (λ_max bounded by Gershgorin on
//! the stiffness over mass), iterated until |F| < tol |F₀| — not converging is reported.

use facesim::mesh::Mesh;
use facesim::osteotomy::Plan;
use facesim::springs::SpringSet;
use facesim::vec3::{norm, sub};

pub struct Relaxed {
    pub positions: Vec<[f64; 3]>,
    pub iterations: usize,
    /// Residual |F| / |F₀| at the end.
    pub residual: f64,
    pub converged: bool,
}

fn cot(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    // Cotangent of the angle at a in triangle abc.
    let (u, v) = (sub(b, a), sub(c, a));
    let cr = facesim::vec3::cross(u, v);
    facesim::vec3::dot(u, v) / norm(cr).max(1e-300)
}

/// The surface's springs (a, b, stiffness, rest length), a < b, sorted so that the force sums
/// do not depend on hash-map order: cotangent-weighted edge springs, then flexion springs.
fn surface_springs(skin: &Mesh, alpha: f64, beta: f64) -> Vec<(usize, usize, f64, f64)> {
    let x0 = &skin.vertices;
    // Edge springs with cotangent weights.
    let mut w: std::collections::HashMap<(u32, u32), f64> = std::collections::HashMap::new();
    for t in &skin.triangles {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let key = (b.min(c), b.max(c));
            *w.entry(key).or_insert(0.0) +=
                0.5 * alpha * cot(x0[a as usize], x0[b as usize], x0[c as usize]);
        }
    }
    let mut edges: Vec<(usize, usize, f64, f64)> = w
        .into_iter()
        .map(|((a, b), k)| {
            let (a, b) = (a as usize, b as usize);
            (a, b, k.max(0.0), norm(sub(x0[a], x0[b])))
        })
        .collect();
    // Flexion springs across every interior edge, joining the two opposite vertices: without
    // them a patch with no skull spring (ears, the nose tip) folds freely, since isometric
    // bending costs an edge-only net nothing. Stiffness β/ℓ² (ℓ the shared edge): the bending
    // modulus over the squared length scale, a heuristic stated as such.
    let mut opposite: std::collections::HashMap<(u32, u32), Vec<u32>> =
        std::collections::HashMap::new();
    for t in &skin.triangles {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            opposite.entry((b.min(c), b.max(c))).or_default().push(a);
        }
    }
    for ((b, c), opp) in opposite {
        if let [p, q] = opp[..] {
            let l2 = facesim::vec3::dot(
                sub(x0[b as usize], x0[c as usize]),
                sub(x0[b as usize], x0[c as usize]),
            )
            .max(1e-12);
            let (p, q) = (p.min(q) as usize, p.max(q) as usize);
            edges.push((p, q, beta / l2, norm(sub(x0[p], x0[q]))));
        }
    }
    edges.sort_by(|p, q| (p.0, p.1).cmp(&(q.0, q.1)).then(p.2.total_cmp(&q.2)));
    edges
}

/// The mass-spring system: surface springs, skull springs to the moved bone, lumped masses.
struct Network<'a> {
    /// Skin vertices.
    nv: usize,
    edges: Vec<(usize, usize, f64, f64)>,
    springs: &'a SpringSet,
    /// Skull spring stiffness k_c k_i c, per spring.
    weight: Vec<f64>,
    /// Bone attachment points after the plan.
    bone: Vec<[f64; 3]>,
    mass: Vec<f64>,
    rigid: &'a [bool],
}

impl Network<'_> {
    /// Step 0.9 × 2/√λ_max, with the Gershgorin bound on λ_max(M⁻¹K): row sums of |K| over
    /// the mass.
    fn stable_step(&self) -> f64 {
        let nv = self.nv;
        let mut row = vec![0.0; nv];
        for &(a, b, k, _) in &self.edges {
            row[a] += 2.0 * k;
            row[b] += 2.0 * k;
        }
        for (s, wt) in self.springs.springs.iter().zip(&self.weight) {
            row[s.skin] += wt;
        }
        let lam = (0..nv)
            .filter(|&i| !self.rigid[i])
            .map(|i| row[i] / self.mass[i])
            .fold(0.0, f64::max)
            .max(1e-300);
        0.9 * 2.0 / lam.sqrt()
    }

    /// Spring forces at positions x (zero on rigid vertices).
    fn force(&self, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let mut f = vec![[0.0; 3]; self.nv];
        for &(a, b, k, l0) in &self.edges {
            let d = sub(x[b], x[a]);
            let l = norm(d).max(1e-12);
            let s = k * (l - l0) / l;
            for c in 0..3 {
                f[a][c] += s * d[c];
                f[b][c] -= s * d[c];
            }
        }
        for (sp, wt) in self.springs.springs.iter().zip(&self.weight) {
            let d = sub(x[sp.skin], self.bone[sp.bone]);
            let l = norm(d).max(1e-12);
            let s = wt * (l - sp.rest) / l;
            for c in 0..3 {
                f[sp.skin][c] -= s * d[c];
            }
        }
        for i in 0..self.nv {
            if self.rigid[i] {
                f[i] = [0.0; 3];
            }
        }
        f
    }
}

fn fnorm(f: &[[f64; 3]]) -> f64 {
    f.iter()
        .map(|v| v.iter().map(|x| x * x).sum::<f64>())
        .sum::<f64>()
        .sqrt()
}

#[allow(clippy::too_many_arguments)]
pub fn relax(
    skin: &Mesh,
    springs: &SpringSet,
    plan: &Plan,
    rigid: &[bool],
    alpha: f64,
    beta: f64,
    k_c: f64,
    tolerance: f64,
    max_iterations: usize,
) -> Relaxed {
    let nv = skin.vertices.len();
    let x0 = &skin.vertices;
    // Built in the original order (springs, bone, weights, masses): the study reports peak heap.
    let edges = surface_springs(skin, alpha, beta);
    let (bone, _) = plan.apply(&springs.attachments, 1.0);
    let weight = springs
        .springs
        .iter()
        .map(|s| k_c * springs.k[s.skin] * s.c)
        .collect();
    let mass = springs.k.iter().map(|&k| k.max(1e-12)).collect();
    let net = Network {
        nv,
        edges,
        springs,
        weight,
        bone,
        mass,
        rigid,
    };
    let h = net.stable_step();
    // Damping near critical for the stiffest mode would be too much for the slowest; ζ below is a
    // compromise that converges in a few thousand steps on faces.
    let zeta = 0.02;
    let mut x = x0.clone();
    let mut prev = x0.clone();
    let f0 = fnorm(&net.force(&x)).max(1e-300);
    let mut residual = 1.0;
    let mut it = 0;
    while it < max_iterations {
        it += 1;
        let f = net.force(&x);
        residual = fnorm(&f) / f0;
        if residual < tolerance || !residual.is_finite() {
            break;
        }
        for i in 0..nv {
            if rigid[i] {
                continue;
            }
            let xi = x[i];
            for c in 0..3 {
                x[i][c] =
                    xi[c] + (1.0 - zeta) * (xi[c] - prev[i][c]) + h * h * f[i][c] / net.mass[i];
            }
            prev[i] = xi;
        }
    }
    Relaxed {
        converged: residual < tolerance,
        positions: x,
        iterations: it,
        residual,
    }
}

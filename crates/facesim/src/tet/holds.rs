//! Per-node boundary conditions of the volumetric model and the linear solve that honours them.
//!
//! A hold constrains some components of a node's displacement u along an orthonormal local frame
//! R = [e₀ e₁ e₂] (columns in the global frame) and leaves the others free:
//! - `Free`: nothing held (skin, interior tissue);
//! - `Fixed(d)`: u = d (bone: its segment's rigid move (R_s − I) x + t_s, exact for any rotation);
//! - `Slide { normal, value }`: n · u = value, tangential motion free (mucosa on teeth and bone,
//!   symmetry planes with value 0);
//! - `Rail { direction, offset }`: u = offset + α direction for any α (the intersection of two
//!   sliding planes, e.g. a node on two symmetry planes).
//!
//! Such constraints are linear, so they are imposed by rotating the node's three DOFs into its
//! frame, u = R u′ (K′ = Rᵀ K R, f′ = Rᵀ f per node), where each held component of u′ is an
//! ordinary prescribed DOF of `fem::assembly::System`. The factor depends only on which
//! components are held along which axes, not on the held values: [`Constrained`] factors once and
//! solves any number of hold values and loads (the plan basis: 12 right-hand sides per segment).

use super::iterative::{Iterative, IterativeSolve, NodeFrame};
use crate::error::{Error, NumericalKind, Result};
use crate::fem::assembly::{MAX_FACTOR_BYTES, System};
use crate::fem::cholesky::{Ordering, node_graph_size};
use crate::fem::pmultigrid::TOLERANCE;
use crate::vec3::{cross, dot};

/// A node's boundary condition (displacements in mm, LPS).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Hold {
    Free,
    /// The node's total displacement.
    Fixed([f64; 3]),
    /// n̂ · u = value with n̂ = normal / |normal|; tangential components free.
    Slide {
        normal: [f64; 3],
        value: f64,
    },
    /// u − offset parallel to `direction`: the components across the rail are held.
    Rail {
        direction: [f64; 3],
        offset: [f64; 3],
    },
}

/// A node's local frame (columns e₀, e₁, e₂ in the global frame; None = the identity), how many
/// leading local components are held, and their values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub axes: Option<[[f64; 3]; 3]>,
    pub held: usize,
    pub values: [f64; 3],
}

fn unit(v: [f64; 3], node: usize, what: &str) -> Result<[f64; 3]> {
    let n = dot(v, v).sqrt();
    if !(n > 1e-12) || !n.is_finite() {
        return Err(Error::config(format!(
            "volumetric model: node {node}'s {what} {v:?} is not a direction"
        )));
    }
    Ok(v.map(|c| c / n))
}

/// An orthonormal right-handed frame whose first axis is `n` (unit).
fn frame_from(n: [f64; 3]) -> [[f64; 3]; 3] {
    // The global axis least aligned with n gives a well-conditioned first tangent.
    let k = (0..3)
        .min_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .unwrap_or(0);
    let mut e = [0.0; 3];
    e[k] = 1.0;
    let t1 = cross(n, e);
    let l = dot(t1, t1).sqrt();
    let t1 = t1.map(|c| c / l);
    [n, t1, cross(n, t1)]
}

impl Hold {
    /// The node's local frame and held components; a zero or non-finite direction or value is a
    /// configuration error naming the node.
    pub fn frame(&self, node: usize) -> Result<Frame> {
        let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
        match *self {
            Hold::Free => Ok(Frame {
                axes: None,
                held: 0,
                values: [0.0; 3],
            }),
            Hold::Fixed(d) if finite(&d) => Ok(Frame {
                axes: None,
                held: 3,
                values: d,
            }),
            Hold::Slide { normal, value } if value.is_finite() => {
                let n = unit(normal, node, "sliding normal")?;
                Ok(Frame {
                    axes: Some(frame_from(n)),
                    held: 1,
                    values: [value, 0.0, 0.0],
                })
            }
            Hold::Rail { direction, offset } if finite(&offset) => {
                let d = unit(direction, node, "rail direction")?;
                let [d, t1, t2] = frame_from(d);
                Ok(Frame {
                    axes: Some([t1, t2, d]),
                    held: 2,
                    values: [dot(t1, offset), dot(t2, offset), 0.0],
                })
            }
            _ => Err(Error::config(format!(
                "volumetric model: node {node}'s hold {self:?} is not finite"
            ))),
        }
    }
}

impl Hold {
    /// The hold of a node on up to three sliding planes (unit-normalised normal n̂ₖ, n̂ₖ · u =
    /// valueₖ): none → Free, one → Slide, two → Rail along n̂₁ × n̂₂ through the least-norm
    /// point of both, three → Fixed at their intersection. Parallel planes are refused.
    pub fn from_planes(planes: &[([f64; 3], f64)], node: usize) -> Result<Hold> {
        let unit_planes = planes
            .iter()
            .map(|(n, v)| {
                let l = dot(*n, *n).sqrt();
                unit(*n, node, "sliding normal").map(|u| (u, v / l))
            })
            .collect::<Result<Vec<_>>>()?;
        let parallel = || {
            Error::config(format!(
                "volumetric model: node {node} slides on parallel or too many planes"
            ))
        };
        match unit_planes.as_slice() {
            [] => Ok(Hold::Free),
            [(n, v)] => Ok(Hold::Slide {
                normal: *n,
                value: *v,
            }),
            [(n1, v1), (n2, v2)] => {
                let d = cross(*n1, *n2);
                let c = dot(*n1, *n2);
                let det = 1.0 - c * c;
                if !(det > 1e-12) {
                    return Err(parallel());
                }
                // offset = a n₁ + b n₂ with [1 c; c 1] [a b]ᵀ = [v₁ v₂]ᵀ.
                let (a, b) = ((v1 - c * v2) / det, (v2 - c * v1) / det);
                Ok(Hold::Rail {
                    direction: d,
                    offset: std::array::from_fn(|k| a * n1[k] + b * n2[k]),
                })
            }
            [(n1, v1), (n2, v2), (n3, v3)] => {
                let m = nalgebra::Matrix3::from_rows(&[
                    nalgebra::RowVector3::from(*n1),
                    nalgebra::RowVector3::from(*n2),
                    nalgebra::RowVector3::from(*n3),
                ]);
                if !(m.determinant().abs() > 1e-6) {
                    return Err(parallel());
                }
                let x = m
                    .lu()
                    .solve(&nalgebra::Vector3::new(*v1, *v2, *v3))
                    .ok_or_else(parallel)?;
                Ok(Hold::Fixed([x[0], x[1], x[2]]))
            }
            _ => Err(parallel()),
        }
    }
}

/// Local components of a global vector at a node: Rᵀ v.
pub(crate) fn to_local(axes: &Option<[[f64; 3]; 3]>, v: [f64; 3]) -> [f64; 3] {
    match axes {
        None => v,
        Some(r) => r.map(|e| dot(e, v)),
    }
}

/// The global vector of local components: R v′.
pub(crate) fn to_global(axes: &Option<[[f64; 3]; 3]>, v: [f64; 3]) -> [f64; 3] {
    match axes {
        None => v,
        Some(r) => std::array::from_fn(|c| (0..3).map(|k| r[k][c] * v[k]).sum()),
    }
}

/// Rᵀ K R for a lower-triangle triplet list of a 3-DOF-per-node matrix (duplicates allowed);
/// nodes with the identity frame keep their entries as they are.
pub(crate) fn rotate_lower(
    k: &[(usize, usize, f64)],
    frames: &[Frame],
) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::with_capacity(k.len() + k.len() / 4);
    for &(r, c, v) in k {
        rotate_entry(r, c, frames, |li, lj, w| out.push((li, lj, v * w)));
    }
    out
}

/// Where one lower-triangle entry (r, c) of a global-frame matrix goes in Rᵀ K R: `emit(li, lj,
/// w)` for each local lower entry it adds w times its value to (one, with weight 1, when
/// neither node has a frame of its own).
pub(crate) fn rotate_entry(
    r: usize,
    c: usize,
    frames: &[Frame],
    mut emit: impl FnMut(usize, usize, f64),
) {
    let (fr, fc) = (&frames[r / 3].axes, &frames[c / 3].axes);
    if fr.is_none() && fc.is_none() {
        emit(r, c, 1.0);
        return;
    }
    // Expand the stored entry to (r, c) and its mirror, rotate each, keep the lower half.
    let mirrored: &[(usize, usize)] = if r == c { &[(r, c)] } else { &[(r, c), (c, r)] };
    for &(a, b) in mirrored {
        // Entry (a, b) contributes v R_a[k_a][i] R_b[k_b][j] to local (i, j).
        let ra = row_weights(&frames[a / 3].axes, a % 3);
        let rb = row_weights(&frames[b / 3].axes, b % 3);
        for (i, wa) in ra.iter().enumerate() {
            for (j, wb) in rb.iter().enumerate() {
                let w = wa * wb;
                let (li, lj) = (3 * (a / 3) + i, 3 * (b / 3) + j);
                if w != 0.0 && li >= lj {
                    emit(li, lj, w);
                }
            }
        }
    }
}

/// Row `c` of R (how much of global component c each local component carries).
fn row_weights(axes: &Option<[[f64; 3]; 3]>, c: usize) -> [f64; 3] {
    match axes {
        None => std::array::from_fn(|i| if i == c { 1.0 } else { 0.0 }),
        Some(r) => [r[0][c], r[1][c], r[2][c]],
    }
}

/// The frames of `holds`, refusing a list of the wrong length or nothing held.
pub fn frames(holds: &[Hold], nodes: usize) -> Result<Vec<Frame>> {
    if holds.len() != nodes {
        return Err(Error::config(format!(
            "volumetric model: {} holds for {nodes} nodes",
            holds.len()
        )));
    }
    let f = holds
        .iter()
        .enumerate()
        .map(|(n, h)| h.frame(n))
        .collect::<Result<Vec<_>>>()?;
    if f.iter().all(|f| f.held == 0) {
        return Err(Error::config(
            "volumetric model: no node is held (no bone in the region): the tissue would float",
        ));
    }
    Ok(f)
}

/// The largest Cholesky factor of a 10-node model: a larger one is solved iteratively
/// ([`Constrained::quadratic`]), so that the run stays within 4 GB. The 10-node systems that
/// fit are factored as before (the bundled phantom's at 8/16 mm: 1.3 GB); the real CT's at the
/// default 4/8 mm, 9 GB and more, is solved iteratively (docs/design/pipeline.md "The 10-node
/// solve").
pub const QUADRATIC_DIRECT_BYTES: usize = 2 << 30;

/// Whether a 10-node factor of `factor_nnz` nonzeros is made directly (at most
/// [`QUADRATIC_DIRECT_BYTES`]); the run and `facesim estimate` decide by it.
pub(crate) fn quadratic_factor_fits(factor_nnz: usize) -> bool {
    factor_nnz.saturating_mul(std::mem::size_of::<f64>()) <= QUADRATIC_DIRECT_BYTES
}

/// A stiffness matrix with its holds, factored once in the nodes' local frames (or, for a
/// 10-node model whose factor would not fit, solved by preconditioned conjugate gradients:
/// [`Constrained::quadratic`]).
pub struct Constrained {
    frames: Vec<Frame>,
    solver: Solver,
}

/// How a [`Constrained`] system is solved.
enum Solver {
    /// The sparse Cholesky factor.
    Direct(Box<System>),
    /// PCG with the p-multigrid preconditioner (tet/iterative.rs).
    Iterative(Box<Iterative>),
}

/// How the solved system was solved (report.json `tet.solver`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SolverUsed {
    Direct,
    /// Conjugate gradients with the p-multigrid preconditioner; the last solve's figures.
    PcgPmultigrid(Option<IterativeSolve>),
}

/// The nodes' frames as the iterative solve takes them.
fn node_frames(frames: &[Frame]) -> Vec<NodeFrame> {
    frames
        .iter()
        .map(|f| NodeFrame {
            axes: f.axes,
            held: f.held,
        })
        .collect()
}

impl Constrained {
    /// Factor K (lower triangle, 3 DOFs per node) with the components `holds` constrain held.
    pub fn new(k: &[(usize, usize, f64)], holds: &[Hold], nodes: usize) -> Result<Constrained> {
        Self::ordered(k, holds, nodes, Ordering::NestedDissection)
    }

    /// As `new`, in `ordering` (a mesh's node ordering, shared by its solves).
    pub(crate) fn ordered(
        k: &[(usize, usize, f64)],
        holds: &[Hold],
        nodes: usize,
        ordering: Ordering<'_>,
    ) -> Result<Constrained> {
        Self::factored_within(k, holds, nodes, ordering, MAX_FACTOR_BYTES)
    }

    /// As `ordered`, refusing (`NumericalKind::TooLarge`) a factor of more than `max_bytes`.
    fn factored_within(
        k: &[(usize, usize, f64)],
        holds: &[Hold],
        nodes: usize,
        ordering: Ordering<'_>,
        max_bytes: usize,
    ) -> Result<Constrained> {
        let frames = frames(holds, nodes)?;
        let fixed: Vec<bool> = frames
            .iter()
            .flat_map(|f| std::array::from_fn::<bool, 3, _>(|i| i < f.held))
            .collect();
        let sys = System::within(3 * nodes, rotate_lower(k, &frames), &fixed, ordering, max_bytes).map_err(|e| match e {
            Error::Numerical {
                kind: NumericalKind::Singular,
                ..
            } => Error::numerical(
                NumericalKind::Singular,
                "the tetrahedral stiffness matrix is singular: a piece of tissue is held by no node, or only slides",
            ),
            other => other,
        })?;
        Ok(Constrained {
            frames,
            solver: Solver::Direct(Box::new(sys)),
        })
    }

    /// A 10-node model's system (nodes: the `corners`, then the midpoint of `edges[e]` at node
    /// `corners + e`; `tets` its elements, corners then midpoints): factored
    /// as [`Constrained::ordered`] where the factor takes at most [`QUADRATIC_DIRECT_BYTES`],
    /// else solved by conjugate gradients with the p-multigrid preconditioner
    /// ([`Constrained::iterative`]). The node graph's estimate of the factor decides first
    /// (`fem::cholesky::node_graph_size`: on its unit test's block of 10-node elements 0.5 % over
    /// the DOF-level analysis); only a factor it finds within the limit is analysed at the
    /// DOF level, whose pattern would otherwise set the run's peak memory.
    pub(crate) fn quadratic(
        k: &[(usize, usize, f64)],
        holds: &[Hold],
        (corners, edges, tets): (usize, &[[u32; 2]], &[[u32; 10]]),
        ordering: Ordering<'_>,
    ) -> Result<Constrained> {
        let solved: Vec<bool> = holds.iter().map(|h| !matches!(h, Hold::Fixed(_))).collect();
        let estimate = node_graph_size(&solved, tets.iter().map(|t| &t[..]))
            .map_err(|e| {
                Error::numerical(NumericalKind::Singular, format!("symbolic Cholesky: {e:?}"))
            })?
            .factor_nnz;
        if !quadratic_factor_fits(estimate) {
            return Self::iterative(k, holds, corners, edges);
        }
        match Self::factored_within(k, holds, holds.len(), ordering, QUADRATIC_DIRECT_BYTES) {
            Err(Error::Numerical {
                kind: NumericalKind::TooLarge,
                ..
            }) => Self::iterative(k, holds, corners, edges),
            other => other,
        }
    }

    /// A 10-node model's system solved by conjugate gradients with the p-multigrid
    /// preconditioner (tet/iterative.rs), whatever its size.
    pub(crate) fn iterative(
        k: &[(usize, usize, f64)],
        holds: &[Hold],
        corners: usize,
        edges: &[[u32; 2]],
    ) -> Result<Constrained> {
        let frames = frames(holds, holds.len())?;
        if corners + edges.len() != frames.len() {
            return Err(Error::config(format!(
                "volumetric model: {} corners and {} edge midpoints for {} nodes",
                corners,
                edges.len(),
                frames.len()
            )));
        }
        let it = Iterative::new(k, &node_frames(&frames), corners, edges)?;
        Ok(Constrained {
            frames,
            solver: Solver::Iterative(Box::new(it)),
        })
    }

    /// Nonzeros of the factor (the iterative solve: of its coarse level's).
    pub(crate) fn factor_nnz(&self) -> usize {
        match &self.solver {
            Solver::Direct(sys) => sys.factor_nnz().unwrap_or(0),
            Solver::Iterative(it) => it.factor_nnz(),
        }
    }

    /// How the system is solved, with the last iterative solve's figures.
    pub fn solver_used(&self) -> SolverUsed {
        match &self.solver {
            Solver::Direct(_) => SolverUsed::Direct,
            Solver::Iterative(it) => SolverUsed::PcgPmultigrid(it.last_solve()),
        }
    }

    /// The iterative solve's preconditioner made again for the current frames (nodes freed or
    /// held again); nothing for the factor, which is bordered instead.
    fn holds_changed(&mut self) -> Result<()> {
        if let Solver::Iterative(it) = &mut self.solver {
            it.set_holds(&node_frames(&self.frames))?;
        }
        Ok(())
    }

    /// K u = f in the local frames for each (loads, prescribed values) pair.
    fn solve_frames(
        &self,
        rhs: &[Vec<f64>],
        prescribed: &[Vec<f64>],
        tolerance: f64,
    ) -> Result<Vec<Vec<f64>>> {
        match &self.solver {
            Solver::Direct(sys) => Ok(sys.solve(rhs, prescribed)),
            Solver::Iterative(it) => it.solve_many(rhs, prescribed, tolerance),
        }
    }

    /// Free `nodes` (held or sliding when factored) without refactoring: the factor is bordered
    /// by their held components (`fem::assembly::System::free_more`).
    pub fn free_nodes(&mut self, nodes: &[usize]) -> Result<()> {
        let mut dofs = Vec::new();
        for &n in nodes {
            let f = &mut self.frames[n];
            dofs.extend((0..f.held).map(|i| 3 * n + i));
            f.held = 0;
            f.values = [0.0; 3];
        }
        match &mut self.solver {
            Solver::Direct(sys) => sys.free_more(&dofs),
            Solver::Iterative(_) => self.holds_changed(),
        }
    }

    /// Hold nodes freed by [`Constrained::free_nodes`] again, each by its hold as when factored
    /// (the same frame; its values may differ), without refactoring: their components on the
    /// factor's border are given again (`fem::assembly::System::hold_border`).
    pub(crate) fn rest_nodes(&mut self, rests: &[(usize, Hold)]) -> Result<()> {
        let mut dofs = Vec::new();
        let mut frames = Vec::with_capacity(rests.len());
        for &(n, hold) in rests {
            let again = hold.frame(n)?;
            let f = &self.frames[n];
            if f.held != 0 || f.axes != again.axes {
                return Err(Error::config(format!(
                    "volumetric model: node {n} rests again in another frame than it was factored in, or was not freed"
                )));
            }
            dofs.extend((0..again.held).map(|i| 3 * n + i));
            frames.push((n, again));
        }
        if let Solver::Direct(sys) = &mut self.solver {
            sys.hold_border(&dofs)?;
        }
        for (n, f) in frames {
            self.frames[n] = f;
        }
        self.holds_changed()
    }

    /// The node frames the factor was made in (a freed node: nothing held).
    pub(crate) fn frames(&self) -> &[Frame] {
        &self.frames
    }

    /// Whether `holds` constrain the same components along the same axes as the factor (so
    /// [`Constrained::solve`] takes them).
    pub fn takes(&self, holds: &[Hold]) -> bool {
        frames(holds, self.frames.len()).is_ok_and(|fr| {
            fr.iter()
                .zip(&self.frames)
                .all(|(now, was)| now.held == was.held && (now.held == 0 || now.axes == was.axes))
        })
    }

    /// K⁻¹ r for r in the local frames with the held components' values zero: the linear
    /// model's factor as the preconditioner of a nonlinear tangent (`tet::newton_krylov`).
    /// (An iterative solve that fails gives non-finite values, which the caller refuses.)
    pub(crate) fn solve_local(&self, r: &[f64]) -> Vec<f64> {
        self.solve_frames(&[r.to_vec()], &[vec![0.0; r.len()]], TOLERANCE)
            .map_or_else(|_| vec![f64::NAN; r.len()], |mut u| u.remove(0))
    }

    /// The displacements for each (holds, nodal force vector of length 3 · nodes) pair. The holds
    /// must constrain the same components along the same axes as at construction (their values
    /// may differ).
    pub fn solve(&self, cases: &[(&[Hold], &[f64])]) -> Result<Vec<Vec<[f64; 3]>>> {
        self.solve_to(cases, TOLERANCE)
    }

    /// As [`Constrained::solve`], an iterative solve stopping at the relative residual
    /// `tolerance` instead of [`TOLERANCE`] (a factor solves exactly either way).
    pub(crate) fn solve_to(
        &self,
        cases: &[(&[Hold], &[f64])],
        tolerance: f64,
    ) -> Result<Vec<Vec<[f64; 3]>>> {
        let n = self.frames.len();
        let mut rhs = Vec::with_capacity(cases.len());
        let mut prescribed = Vec::with_capacity(cases.len());
        for (holds, f) in cases {
            if f.len() != 3 * n {
                return Err(Error::config(format!(
                    "volumetric model: a load vector of {} entries for {n} nodes",
                    f.len()
                )));
            }
            let fr = frames(holds, n)?;
            let mut b = vec![0.0; 3 * n];
            let mut p = vec![0.0; 3 * n];
            for (v, (now, was)) in fr.iter().zip(&self.frames).enumerate() {
                // A free node is free in any frame (one freed after factoring keeps its axes).
                if now.held != was.held || (now.held > 0 && now.axes != was.axes) {
                    return Err(Error::config(format!(
                        "volumetric model: node {v}'s hold differs in kind or direction from the factored one"
                    )));
                }
                let fl = to_local(&was.axes, [f[3 * v], f[3 * v + 1], f[3 * v + 2]]);
                b[3 * v..3 * v + 3].copy_from_slice(&fl);
                p[3 * v..3 * v + 3].copy_from_slice(&now.values);
            }
            rhs.push(b);
            prescribed.push(p);
        }
        let solved = self.solve_frames(&rhs, &prescribed, tolerance)?;
        solved
            .into_iter()
            .map(|u| {
                let out: Vec<[f64; 3]> = self
                    .frames
                    .iter()
                    .enumerate()
                    .map(|(v, f)| to_global(&f.axes, [u[3 * v], u[3 * v + 1], u[3 * v + 2]]))
                    .collect();
                if out.iter().flatten().all(|c| c.is_finite()) {
                    Ok(out)
                } else {
                    Err(Error::numerical(
                        NumericalKind::Diverged,
                        "the tetrahedral solve gave non-finite displacements",
                    ))
                }
            })
            .collect()
    }
}

/// Surface and nodal loads: forces (N with kPa and mm: 1 kPa · mm² = 1 mN) on nodes, and a
/// uniform pressure (kPa) on boundary triangles given by three corner nodes, wound
/// counter-clockwise seen from outside the body (pressure pushes inwards, along −n).
#[derive(Clone, Debug, Default)]
pub struct Loads {
    pub nodal: Vec<(usize, [f64; 3])>,
    pub pressure: Vec<([u32; 3], f64)>,
}

impl Loads {
    pub fn none() -> Loads {
        Loads::default()
    }

    /// −p · (area vector) = −p (x₁ − x₀) × (x₂ − x₀) / 2 of each pressure face, with its face.
    pub(crate) fn face_forces<'a>(
        &'a self,
        nodes: &'a [[f64; 3]],
    ) -> impl Iterator<Item = Result<([u32; 3], [f64; 3])>> + 'a {
        self.pressure.iter().map(move |(f, p)| {
            if f.iter().any(|&v| v as usize >= nodes.len()) || !p.is_finite() {
                return Err(Error::config(format!(
                    "volumetric model: pressure face {f:?} names a missing node or a non-finite pressure"
                )));
            }
            let [a, b, c] = f.map(|v| nodes[v as usize]);
            let e1 = [0, 1, 2].map(|k| b[k] - a[k]);
            let e2 = [0, 1, 2].map(|k| c[k] - a[k]);
            Ok((*f, cross(e1, e2).map(|x| -0.5 * p * x)))
        })
    }

    /// The global force vector (3 per node) for linear (3-node) faces: a third of each face's
    /// force on each corner.
    pub fn vector_linear(&self, nodes: &[[f64; 3]]) -> Result<Vec<f64>> {
        let mut f = self.nodal_vector(nodes.len())?;
        for r in self.face_forces(nodes) {
            let (face, force) = r?;
            for v in face {
                for c in 0..3 {
                    f[3 * v as usize + c] += force[c] / 3.0;
                }
            }
        }
        Ok(f)
    }

    /// The nodal forces alone, as a global vector.
    pub(crate) fn nodal_vector(&self, nodes: usize) -> Result<Vec<f64>> {
        let mut f = vec![0.0; 3 * nodes];
        for (v, force) in &self.nodal {
            if *v >= nodes || force.iter().any(|c| !c.is_finite()) {
                return Err(Error::config(format!(
                    "volumetric model: nodal force {force:?} on missing node {v} or not finite"
                )));
            }
            for c in 0..3 {
                f[3 * v + c] += force[c];
            }
        }
        Ok(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_and_carry_the_held_values() {
        let h = Hold::Slide {
            normal: [1.0, 2.0, -2.0],
            value: 0.7,
        };
        let f = h.frame(0).unwrap();
        let r = f.axes.unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let d = dot(r[i], r[j]) - if i == j { 1.0 } else { 0.0 };
                assert!(d.abs() < 1e-15);
            }
        }
        assert!((dot(r[0], [1.0 / 3.0, 2.0 / 3.0, -2.0 / 3.0]) - 1.0).abs() < 1e-15);
        // A displacement with local normal component 0.7 has n·u = 0.7 globally.
        let u = to_global(&f.axes, [0.7, 0.3, -1.1]);
        assert!((dot(u, r[0]) - 0.7).abs() < 1e-15);
        assert_eq!(
            to_local(&f.axes, u).map(|c| (c * 1e12).round()),
            [0.7e12, 0.3e12, -1.1e12]
        );
        let rail = Hold::Rail {
            direction: [0.0, 0.0, 2.0],
            offset: [1.0, 2.0, 3.0],
        }
        .frame(1)
        .unwrap();
        assert_eq!(rail.held, 2);
        let back = to_global(&rail.axes, rail.values);
        assert!((back[0] - 1.0).abs() < 1e-15 && (back[1] - 2.0).abs() < 1e-15);
        assert!(back[2].abs() < 1e-15);
        assert!(
            Hold::Slide {
                normal: [0.0; 3],
                value: 0.0
            }
            .frame(4)
            .is_err()
        );
    }

    #[test]
    fn rotating_the_lower_triangle_equals_the_dense_product() {
        // A dense symmetric 6×6 (two nodes) stored as a duplicated lower triangle.
        let a: Vec<Vec<f64>> = (0..6)
            .map(|i| {
                (0..6)
                    .map(|j| 1.0 / (1.0 + i as f64 + j as f64) + if i == j { 2.0 } else { 0.0 })
                    .collect()
            })
            .collect();
        let mut k = Vec::new();
        for i in 0..6 {
            for j in 0..=i {
                k.push((i, j, 0.25 * a[i][j]));
                k.push((i, j, 0.75 * a[i][j]));
            }
        }
        let frames = [
            Hold::Slide {
                normal: [0.3, -0.2, 0.9],
                value: 0.0,
            }
            .frame(0)
            .unwrap(),
            Hold::Free.frame(1).unwrap(),
        ];
        let mut got = [[0.0; 6]; 6];
        for (r, c, v) in rotate_lower(&k, &frames) {
            assert!(r >= c);
            got[r][c] += v;
        }
        let rot = |i: usize, g: usize| -> f64 {
            // T[g][i]: global DOF g, local DOF i.
            if g / 3 != i / 3 {
                return 0.0;
            }
            row_weights(&frames[g / 3].axes, g % 3)[i % 3]
        };
        for i in 0..6 {
            for j in 0..=i {
                let mut e = 0.0;
                for g in 0..6 {
                    for h in 0..6 {
                        e += rot(i, g) * a[g][h] * rot(j, h);
                    }
                }
                assert!(
                    (got[i][j] - e).abs() < 1e-14,
                    "{i}{j}: {} vs {e}",
                    got[i][j]
                );
            }
        }
    }
}

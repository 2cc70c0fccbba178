//! The certified reduced model of a run's linear model (docs/design/reduced.md): the stiffness split
//! by tissue and Lamé parameter on the run's mesh, holds and face embedding, a greedy basis over
//! the training cases, and the gains that turn its energy-norm bound into bounds in mm on the
//! face and each output.

use super::Volumetric;
use super::rounds::TORN_STIFFNESS;
use crate::case::{Case, Tet};
use crate::error::{Error, Result};
use crate::fem::cholesky::Cholesky;
use crate::model::reduced::{FaceMap, ReducedTet, Training, theta_of};
use crate::pipeline::Scene;
use crate::reduced::dual::{self, DualContext, DualCost, DualForm, DualGreedy};
use crate::reduced::{
    Affine, Basis, DualReport, OutputBound, affine::solve_columns, norm::largest_eigenvalue,
};

impl Volumetric {
    /// The certified reduced model of this linear model for `case`'s sliding state
    /// (docs/design/reduced.md): the stiffness split by tissue and Lamé parameter on the run's mesh,
    /// node roles, mucosa and face embedding; a greedy over `train` (cases differing in tissue
    /// parameters only) from the reference `case`. The linear element and material only: the
    /// neo-Hookean tangent is not affine in the parameters, the 10-node element is not yet split.
    pub fn reduced(
        &self,
        scene: &Scene,
        case: &Case,
        training: &Training,
        progress: &dyn Fn(&str),
    ) -> Result<ReducedTet> {
        let start = std::time::Instant::now();
        let r = &self.reuse;
        if !r.linear_solve || self.quadratic.is_some() {
            return Err(Error::config(
                "the reduced model needs [tet] material = \"linear\" and element = \"linear\"",
            ));
        }
        let sliding = case.tet.sliding;
        let hold = self.holds_for(scene, case, true);
        let slot: Vec<usize> = self.mesh.tissue.iter().map(|l| Tet::slot(*l)).collect();
        let scale: Vec<f64> = r
            .torn
            .iter()
            .map(|t| if *t { TORN_STIFFNESS } else { 1.0 })
            .collect();
        let terms = crate::tet::lame_term_list(&slot);
        let lame = crate::tet::LameTerms::new(&self.mesh.nodes, &self.mesh.tets, &slot, &scale);
        let affine = Affine::new(&lame, &terms, &hold, r.ordering())?;
        drop(lame);
        let theta = |t: &Tet| theta_of(&terms, &t.tissues());
        let train: Vec<Vec<f64>> = training.cases.iter().map(|t| theta(&t.tet)).collect();
        let theta_bar = theta(&case.tet);
        let mut theta_box = [theta_bar.clone(), theta_bar.clone()];
        for t in &train {
            for (q, v) in t.iter().enumerate() {
                theta_box[0][q] = theta_box[0][q].min(*v);
                theta_box[1][q] = theta_box[1][q].max(*v);
            }
        }
        let (mut basis, x) = Basis::build(&affine, &theta_bar, &train, training.greedy, progress)?;
        let face_map = FaceMap {
            tets: self.mesh.tets.clone(),
            cell: r.embedding.tet.clone(),
            weights: r.embedding.weights.clone(),
            still: r.face_still.clone(),
        };
        let zero = vec![0.0; affine.unknowns()];
        // The face of free values (held values zero): a basis vector, a Riesz vector, an error.
        let carry = |v: &[f64]| face_map.carry(&affine.expand(v, false));
        let face = crate::reduced::LinearFace::new(
            face_map.carry(&affine.expand(&zero, true)),
            basis.vectors.iter().map(|v| carry(v)).collect(),
        );
        let sys = System {
            affine: &affine,
            x: &x,
            face_map: &face_map,
            nodes: self.mesh.nodes.len(),
        };
        progress("reduced model: the face's gain");
        let (face_gain, lanczos) = sys.face_gain();
        let (columns, adjoints) = sys.output_columns(training.outputs);
        let output_gains = output_gains(&columns, &adjoints);
        // The face's and each output's images of the Riesz space's vectors, for the bounds
        // through the Riesz representer (`reduced::OutputBound`); then the space is dropped.
        progress("reduced model: the bounds' images");
        let faces: Vec<Vec<[f64; 3]>> = std::mem::take(&mut basis.riesz_space)
            .into_iter()
            .map(|e| carry(&e))
            .collect();
        let output_bounds = output_bounds(training.outputs, output_gains, &faces);
        let face_bound = face_bound(&face_map, face_gain, faces);
        let (duals, dual_report) = match training.dual {
            Some(greedy) => {
                progress("reduced model: the landmarks' dual bases");
                let ctx = DualContext {
                    sys: &affine,
                    x: &x,
                    theta_bar: &theta_bar,
                    primal: &basis,
                };
                let (duals, report) = dual_bases(&ctx, (&columns, &adjoints), &train, greedy)?;
                (duals, Some(report))
            }
            None => (Vec::new(), None),
        };
        drop((columns, adjoints));
        let dual_factorisations = dual_report.as_ref().map_or(0, |d| d.full_factorisations);
        Ok(ReducedTet {
            sliding,
            build: crate::reduced::ReducedReport {
                sliding,
                basis_size: basis.size(),
                full_factorisations: basis.full_factorisations + dual_factorisations,
                reference_solves: basis.riesz_solves + lanczos + 3 * training.outputs.len(),
                cg_iterations: basis.cg_iterations,
                offline_seconds: start.elapsed().as_secs_f64(),
                face_gain,
                greedy: basis.history,
                dual: dual_report,
            },
            form: basis.form,
            terms,
            theta_box,
            face,
            face_bound,
            output_bounds,
            duals,
        })
    }
}

/// The reference system X (its factor `x`) and the face's map from its free values.
struct System<'a> {
    affine: &'a Affine,
    x: &'a Cholesky<f64>,
    face_map: &'a FaceMap,
    nodes: usize,
}

impl System<'_> {
    /// The face of free values `v` (held values zero).
    fn carry(&self, v: &[f64]) -> Vec<[f64; 3]> {
        self.face_map.carry(&self.affine.expand(v, false))
    }

    /// The face's gain σ (σ² the largest eigenvalue of L X⁻¹ Lᵀ, by Lanczos) and the solves it
    /// took.
    fn face_gain(&self) -> (f64, usize) {
        let nv = self.face_map.cell.len();
        let lanczos = std::cell::Cell::new(0usize);
        let gain2 = largest_eigenvalue(3 * nv, 40, &|y: &[f64]| {
            lanczos.set(lanczos.get() + 1);
            let y3: Vec<[f64; 3]> = y.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
            let b = self
                .affine
                .restrict(&self.face_map.carry_transpose(&y3, self.nodes));
            let z = solve_columns(self.x, &[b]).remove(0);
            self.carry(&z).into_iter().flatten().collect()
        });
        (gain2.max(0.0).sqrt(), lanczos.get())
    }

    /// Each output's three components as functionals of the free unknowns, l_j (the
    /// transpose of the face's map applied to the output's weights), and their adjoints at θ̄,
    /// X⁻¹ l_j, solved in blocks (a block of columns costs a fraction of as many single solves).
    fn output_columns(&self, outputs: &[Vec<(usize, f64)>]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let nv = self.face_map.cell.len();
        let mut rhs: Vec<Vec<f64>> = Vec::with_capacity(3 * outputs.len());
        for w in outputs {
            for k in 0..3 {
                let mut y = vec![[0.0; 3]; nv];
                for (v, a) in w {
                    y[*v][k] += a;
                }
                rhs.push(
                    self.affine
                        .restrict(&self.face_map.carry_transpose(&y, self.nodes)),
                );
            }
        }
        // Four outputs' columns a solve: the blocks' cost, with no 3 × outputs columns held
        // three times over at once (the two states build side by side).
        let z: Vec<Vec<f64>> = rhs
            .chunks(12)
            .flat_map(|b| solve_columns(self.x, b))
            .collect();
        (rhs, z)
    }
}

/// Each output's dual basis (three components: its columns l_j and adjoints X⁻¹ l_j), and
/// what they cost.
fn dual_bases(
    ctx: &DualContext,
    (columns, adjoints): (&[Vec<f64>], &[Vec<f64>]),
    train: &[Vec<f64>],
    greedy: DualGreedy,
) -> Result<(Vec<DualForm>, DualReport)> {
    let start = std::time::Instant::now();
    let mut cost = DualCost::default();
    let duals = columns
        .chunks(3)
        .zip(adjoints.chunks(3))
        .map(|(l, z)| dual::build(ctx, l, z, train, greedy, &mut cost))
        .collect::<Result<Vec<_>>>()?;
    let report = DualReport {
        sizes: duals.iter().map(DualForm::size).collect(),
        largest_relative_bound: duals
            .iter()
            .filter_map(|d| d.greedy.last().map(|g| g.1))
            .fold(0.0, f64::max),
        cg_iterations: cost.cg_iterations,
        reference_solves: cost.reference_solves,
        full_factorisations: cost.full_factorisations,
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok((duals, report))
}

/// Each output's gain ρ: ρ² the largest eigenvalue of its 3×3 block of L X⁻¹ Lᵀ, from its
/// columns l_j and adjoints X⁻¹ l_j ([`System::output_columns`]).
fn output_gains(rhs: &[Vec<f64>], z: &[Vec<f64>]) -> Vec<f64> {
    rhs.chunks(3)
        .zip(z.chunks(3))
        .map(|(rhs, z)| {
            let g = nalgebra::Matrix3::from_fn(|i, j| crate::reduced::basis::dot(&rhs[i], &z[j]));
            let g = (g + g.transpose()) * 0.5;
            g.symmetric_eigenvalues().max().max(0.0).sqrt()
        })
        .collect()
}

/// Each output's bound: its gain and its images of the Riesz space's vectors (`faces`).
fn output_bounds(
    outputs: &[Vec<(usize, f64)>],
    gains: Vec<f64>,
    faces: &[Vec<[f64; 3]>],
) -> Vec<OutputBound> {
    outputs
        .iter()
        .zip(gains)
        .map(|(w, g)| {
            let images: Vec<Vec<f64>> = faces
                .iter()
                .map(|f| {
                    let mut y = vec![0.0; 3];
                    for (v, a) in w {
                        for k in 0..3 {
                            y[k] += a * f[*v][k];
                        }
                    }
                    y
                })
                .collect();
            OutputBound::new(g, &images)
        })
        .collect()
}

/// The face's bound: its gain and its Gram matrix over the vertices the tissue can move only
/// (1 015 of 19 260 on the real CT): the others' images are zero, and summing them was most of
/// this stage.
fn face_bound(face_map: &FaceMap, gain: f64, faces: Vec<Vec<[f64; 3]>>) -> OutputBound {
    let moves: Vec<usize> = (0..face_map.cell.len())
        .filter(|v| face_map.cell[*v].is_some() && !face_map.still[*v])
        .collect();
    OutputBound::new(
        gain,
        &faces
            .into_iter()
            .map(|f| moves.iter().flat_map(|v| f[*v]).collect())
            .collect::<Vec<Vec<f64>>>(),
    )
}

//! The volumetric model's certified reduced model (docs/design/reduced.md): built on what a
//! run's linear tetrahedral model holds (`Volumetric::reduced`), it gives the face for any
//! tissue parameters in microseconds, each answer with a bound in mm on its difference from the
//! full model's.

pub mod file;

use crate::case::{Case, Tet, TissueElastic};
use crate::error::{Error, Result};
use crate::reduced::dual::{DualForm, DualGreedy};
use crate::reduced::{LinearFace, OnlineForm, OutputBound, ReducedReport};

/// The reduced model of one sliding state (sliding changes the holds, not a coefficient): all
/// it keeps is independent of the tissue mesh (N×N arrays and N + 1 face fields), so it is
/// what `reduced_model.bin` stores ([`file`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ReducedTet {
    pub sliding: bool,
    /// The online solve and its bound.
    pub form: OnlineForm,
    /// Per term: the tissue slot (`Tet::slot`) and whether it is λ (else μ).
    pub terms: Vec<(usize, bool)>,
    /// The trained box of θ (lowest and highest per term, θ̄ included): a θ outside it is not
    /// answered (no extrapolation; docs/design/reduced.md).
    pub theta_box: [Vec<f64>; 2],
    /// The face displacement of the held values with every free unknown zero (the lift) and
    /// of each basis vector (held values zero): the face is linear in the reduced coefficients.
    pub face: LinearFace,
    /// The face error's bound (mm): its gain σ with ‖face error‖₂ ≤ σ ‖e‖_X (`reduced::norm`)
    /// and its images of the Riesz space ([`OutputBound`]).
    pub face_bound: OutputBound,
    /// Per output of [`Training::outputs`], the same: the gain ρ with |output error|₂ ≤
    /// ρ ‖e‖_X (ρ² the largest eigenvalue of the output's 3×3 block of L X⁻¹ Lᵀ, three solves
    /// with X's factor) and the output's images.
    pub output_bounds: Vec<OutputBound>,
    /// Per output, its dual reduced basis (`reduced::dual`): the correction of the output's
    /// reduced value and the primal–dual bound on the corrected value (empty: a model stored
    /// before them, whose outputs keep `output_bounds`).
    pub duals: Vec<DualForm>,
    /// How it was built (report.json `uncertainty.reduced[]`).
    pub build: ReducedReport,
}

/// The certified bounds of one reduced answer (mm): on the Euclidean norm of the face's error
/// over all vertices (so every vertex too), and per output (landmark) on the error of its
/// corrected displacement: the face's value plus `corrections` (zero for a model without dual
/// bases, whose bound is then the energy norm's).
#[derive(Clone, Debug, PartialEq)]
pub struct Bounds {
    pub face_mm: f64,
    pub landmarks_mm: Vec<f64>,
    /// Per output: ψ_Nᵀ r per component (mm), to add to the displacement the face gives.
    pub corrections: Vec<[f64; 3]>,
}

/// One answer of the reduced model and its certificate.
#[derive(Clone, Debug)]
pub struct ReducedFace {
    /// Face displacement per vertex (mm, LPS).
    pub displacement: Vec<[f64; 3]>,
    /// Bound on the largest difference from the full model's face displacement (mm): it bounds
    /// the Euclidean norm over all face vertices, so every vertex too.
    pub bound_mm: f64,
    /// The energy-norm bound relative to the reduced solution's energy norm.
    pub relative_energy_bound: f64,
    /// Per output the model was built with (the landmarks), the bound on its corrected
    /// displacement's error (mm), and the correction to add to the displacement the face gives
    /// there.
    pub landmark_bounds_mm: Vec<f64>,
    pub landmark_corrections: Vec<[f64; 3]>,
}

impl ReducedTet {
    /// The parameter vector θ of `tet`'s materials, in the terms' order.
    pub fn theta(&self, tet: &Tet) -> Vec<f64> {
        theta_of(&self.terms, &tet.tissues())
    }

    /// θ of the tissues' materials (`Tet::tissues` order).
    pub(crate) fn theta_of(&self, tissues: &[TissueElastic; 4]) -> Vec<f64> {
        theta_of(&self.terms, tissues)
    }

    /// The reduced coefficients with `case`'s tissue parameters (its `[tet] sliding` must be
    /// this model's) and the certified bounds on their face's error.
    pub fn coefficients(&self, case: &Case) -> Result<(Vec<f64>, Bounds)> {
        let theta = self.theta(&case.tet);
        let o = self.solve(case)?;
        Ok((
            o.coefficients.iter().copied().collect(),
            self.bounds(&theta, &o),
        ))
    }

    /// The certified bounds of an online answer at θ (mm). Per output with a dual basis, on
    /// its corrected displacement s_N = face value + ψ_Nᵀ r: the smaller of the primal–dual
    /// bound (the Euclidean norm of its components' ‖r‖_X' ‖r_du‖_X' / α_LB) and the bound on
    /// the face value through the Riesz representer plus |ψ_Nᵀ r| (the triangle inequality);
    /// without one (or where its dual system fails), that bound on the face value alone.
    fn bounds(&self, theta: &[f64], o: &crate::reduced::Online) -> Bounds {
        let mut landmarks_mm = Vec::with_capacity(self.output_bounds.len());
        let mut corrections = Vec::with_capacity(self.output_bounds.len());
        for (k, b) in self.output_bounds.iter().enumerate() {
            let plain = b.bound(o);
            match self.duals.get(k).map(|d| d.answer(theta, o)) {
                Some(Ok(a)) if a.correction.len() == 3 => {
                    let c = [a.correction[0], a.correction[1], a.correction[2]];
                    let dual = a.bound.iter().map(|x| x * x).sum::<f64>().sqrt();
                    landmarks_mm.push(dual.min(plain + crate::vec3::norm(c)));
                    corrections.push(c);
                }
                _ => {
                    landmarks_mm.push(plain);
                    corrections.push([0.0; 3]);
                }
            }
        }
        Bounds {
            face_mm: self.face_bound.bound(o),
            landmarks_mm,
            corrections,
        }
    }

    /// σ: the face error's Euclidean norm (mm) per unit of the energy-norm error.
    pub fn face_gain(&self) -> f64 {
        self.face_bound.gain
    }

    /// Per output, its gain (mm per unit of the energy-norm error).
    pub fn output_gains(&self) -> Vec<f64> {
        self.output_bounds.iter().map(|b| b.gain).collect()
    }

    fn solve(&self, case: &Case) -> Result<crate::reduced::Online> {
        self.check_sliding(case)?;
        self.solve_theta(&self.theta(&case.tet))
    }

    fn check_sliding(&self, case: &Case) -> Result<()> {
        if case.tet.sliding != self.sliding {
            return Err(Error::config(
                "reduced model: asked for the other sliding state than it was built for",
            ));
        }
        Ok(())
    }

    /// The online solve at θ, refused outside the trained box.
    fn solve_theta(&self, theta: &[f64]) -> Result<crate::reduced::Online> {
        if let Some(msg) = self.outside(theta) {
            return Err(Error::config(format!("reduced model: {msg}")));
        }
        self.form.solve(theta)
    }

    /// Why θ is outside the trained box (None: inside, to a relative 1e-9).
    pub fn outside(&self, theta: &[f64]) -> Option<String> {
        let [lo, hi] = &self.theta_box;
        let slack = 1e-9;
        theta.iter().enumerate().find_map(|(q, t)| {
            let (s, l) = self.terms[q];
            let name = format!("{} of {}", if l { "λ" } else { "μ" }, slot_name(s));
            (*t < lo[q] * (1.0 - slack) || *t > hi[q] * (1.0 + slack)).then(|| {
                format!(
                    "{name} = {t:.4} kPa is outside the trained range {:.4}–{:.4} kPa",
                    lo[q], hi[q]
                )
            })
        })
    }

    /// The face displacement with `case`'s tissue parameters and its certified bound.
    pub fn face(&self, case: &Case) -> Result<ReducedFace> {
        self.check_sliding(case)?;
        self.face_of(&case.tet.tissues())
    }

    /// The face displacement for the tissues' materials (`Tet::tissues` order) and its bound.
    pub(crate) fn face_of(&self, tissues: &[TissueElastic; 4]) -> Result<ReducedFace> {
        let theta = self.theta_of(tissues);
        let o = self.solve_theta(&theta)?;
        let c: Vec<f64> = o.coefficients.iter().copied().collect();
        let b = self.bounds(&theta, &o);
        Ok(ReducedFace {
            displacement: self.face.all(&c),
            bound_mm: b.face_mm,
            relative_energy_bound: o.energy_bound / o.energy_norm.max(1e-300),
            landmark_bounds_mm: b.landmarks_mm,
            landmark_corrections: b.corrections,
        })
    }

    pub fn report(&self) -> ReducedReport {
        self.build.clone()
    }
}

/// The face carried by the linear mesh (as `tet::embed::SkinEmbedding::carry` with the run's
/// still vertices: rigid skin and beyond the region), and its transpose.
pub(super) struct FaceMap {
    pub tets: Vec<[u32; 4]>,
    pub cell: Vec<Option<u32>>,
    pub weights: Vec<[f64; 4]>,
    pub still: Vec<bool>,
}

impl FaceMap {
    pub fn carry(&self, u: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.cell
            .iter()
            .zip(&self.weights)
            .zip(&self.still)
            .map(|((c, w), still)| match c {
                Some(t) if !still => {
                    let mut d = [0.0; 3];
                    for (n, wa) in self.tets[*t as usize].iter().zip(w) {
                        for k in 0..3 {
                            d[k] += wa * u[*n as usize][k];
                        }
                    }
                    d
                }
                _ => [0.0; 3],
            })
            .collect()
    }

    /// The transpose of `carry`: face vectors to node vectors on `nodes` nodes.
    pub(crate) fn carry_transpose(&self, y: &[[f64; 3]], nodes: usize) -> Vec<[f64; 3]> {
        let mut out = vec![[0.0; 3]; nodes];
        for (((c, w), still), y) in self.cell.iter().zip(&self.weights).zip(&self.still).zip(y) {
            if let (Some(t), false) = (c, still) {
                for (n, wa) in self.tets[*t as usize].iter().zip(w) {
                    for k in 0..3 {
                        out[*n as usize][k] += wa * y[k];
                    }
                }
            }
        }
        out
    }
}

/// What the greedy trains on and what the bounds are wanted for.
pub struct Training<'a> {
    /// Cases differing from the run's in tissue parameters only.
    pub cases: &'a [Case],
    pub greedy: crate::reduced::Greedy,
    /// Outputs with their own bound: weights on face vertices (a landmark's triangle), whose
    /// weighted displacement is the output.
    pub outputs: &'a [Vec<(usize, f64)>],
    /// The outputs' dual greedy (primal–dual output bounds); None: no dual bases.
    pub dual: Option<DualGreedy>,
}

/// The reduced models a sampling needs: one per sliding state it draws.
pub struct ReducedModels {
    pub models: Vec<ReducedTet>,
    /// Whether the mesh has nodes to slide (else one model serves both states).
    pub sliding_matters: bool,
}

impl ReducedModels {
    /// The model for the sliding state `sliding` (the only one when sliding holds nothing).
    pub fn model(&self, sliding: bool) -> Result<&ReducedTet> {
        Ok(&self.models[pick(&self.models, self.sliding_matters, sliding)?])
    }

    /// The model for `case`'s sliding state (its index) and its coefficients and bounds.
    pub fn solve(&self, case: &Case) -> Result<(usize, Vec<f64>, Bounds)> {
        solve_in(&self.models, self.sliding_matters, case)
    }
}

/// The model of `models` for `case`'s sliding state (its index) and its coefficients and
/// bounds: the run's models ([`ReducedModels::solve`]) or the stored ones (`file`).
pub(crate) fn solve_in(
    models: &[ReducedTet],
    sliding_matters: bool,
    case: &Case,
) -> Result<(usize, Vec<f64>, Bounds)> {
    let i = pick(models, sliding_matters, case.tet.sliding)?;
    let m = &models[i];
    let mut c = case.clone();
    c.tet.sliding = m.sliding;
    let (coefficients, bound) = m.coefficients(&c)?;
    Ok((i, coefficients, bound))
}

/// θ for `terms` (tissue slot, λ or μ) of the tissues' materials (`Tet::tissues` order).
pub(crate) fn theta_of(terms: &[(usize, bool)], tissues: &[TissueElastic; 4]) -> Vec<f64> {
    terms
        .iter()
        .map(|(s, is_lambda)| {
            let (l, mu) = tissues[*s].lame();
            if *is_lambda { l } else { mu }
        })
        .collect()
}

/// The case key of a term's slot, for messages: `[tet.skin]`.
pub(crate) fn slot_name(s: usize) -> String {
    format!("[tet.{}]", Tet::TISSUES[s])
}

/// The index in `models` of the model for the sliding state `sliding`: the one built for it,
/// else the only one when sliding holds no node.
pub(crate) fn pick(models: &[ReducedTet], sliding_matters: bool, sliding: bool) -> Result<usize> {
    match models.iter().position(|m| m.sliding == sliding) {
        Some(i) => Ok(i),
        None if !sliding_matters && !models.is_empty() => Ok(0),
        None => Err(Error::config(format!(
            "reduced model: none for sliding = {sliding} (the run sampled only the other state)"
        ))),
    }
}

//! `reduced_model.bin` (docs/design/reduced.md "The stored model"): the run's reduced models beside
//! plan_basis.bin, in the framing of `crate::stored`:
//!
//! ```text
//! magic   "FSREDUC\0", format FORMAT_VERSION, facesim version, JSON header:
//!         vertices, face_checksum, tissues (the run's [tet.*]), sliding (the run's), models
//!         [{sliding, terms, form, theta_box, face_bound, output_bounds, duals, build}]
//! arrays  per model: the lift, then each of its N face columns: vertices × 3 f64 (LPS mm)
//! ```
//!
//! Reading checks the framing, every size, the online arrays' shapes and, against the face it
//! is to move, the vertex count and a checksum of the pre-operative face: a model from another
//! mesh or version is refused in one line naming the file.

use super::ReducedTet;
use crate::case::TissueElastic;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use crate::reduced::dual::DualForm;
use crate::reduced::{LinearFace, OnlineForm, OutputBound, ReducedReport};
use crate::stored;
use serde::{Deserialize, Serialize};
use std::path::Path;

const MAGIC: &[u8; 8] = b"FSREDUC\0";
/// 2: the bounds through the Riesz representer (`face_bound`, `output_bounds`).
/// 3: the outputs' dual bases (`duals`, primal–dual output bounds).
const FORMAT_VERSION: u32 = 3;
/// The file's name in a run's output directory.
pub const FILE_NAME: &str = "reduced_model.bin";
const KIND: &str = "reduced model";

/// What a run stores: its reduced models and the case they reduce.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredReduced {
    pub models: Vec<ReducedTet>,
    /// The run's tissues (`Tet::tissues` order) and sliding state: the reference θ̄.
    pub tissues: [TissueElastic; 4],
    pub sliding: bool,
    /// Whether the mesh has nodes to slide (else one model serves both states).
    pub sliding_matters: bool,
    /// FNV-1a of the pre-operative face's coordinates (`checksum`).
    pub face_checksum: u64,
}

impl StoredReduced {
    /// The face displacement for `tissues` (`Tet::tissues` order) and sliding state, and its
    /// certified bound; refused (an error saying why) outside the trained box.
    pub fn face(&self, tissues: &[TissueElastic; 4], sliding: bool) -> Result<super::ReducedFace> {
        self.models[super::pick(&self.models, self.sliding_matters, sliding)?].face_of(tissues)
    }

    /// As [`super::ReducedModels::solve`]: the model for `case`'s sliding state (its index),
    /// its coefficients and bounds for `case`'s tissues.
    pub fn solve(&self, case: &crate::case::Case) -> Result<(usize, Vec<f64>, super::Bounds)> {
        super::solve_in(&self.models, self.sliding_matters, case)
    }
}

#[derive(Serialize, Deserialize)]
struct Header {
    vertices: usize,
    face_checksum: String,
    tissues: [TissueElastic; 4],
    sliding: bool,
    sliding_matters: bool,
    models: Vec<ModelHeader>,
}

#[derive(Serialize, Deserialize)]
struct ModelHeader {
    sliding: bool,
    terms: Vec<(usize, bool)>,
    form: OnlineForm,
    theta_box: [Vec<f64>; 2],
    face_bound: OutputBound,
    output_bounds: Vec<OutputBound>,
    duals: Vec<DualForm>,
    build: ReducedReport,
}

/// Write `stored` to `path` (temporary name, then renamed).
pub fn write(path: &Path, stored: &StoredReduced) -> Result<()> {
    let vertices = stored.models.first().map_or(0, |m| m.face.lift.len());
    if stored.models.iter().any(|m| {
        m.face.lift.len() != vertices
            || m.face.columns.len() != m.form.size()
            || m.face.columns.iter().any(|c| c.len() != vertices)
    }) {
        return Err(Error::output(
            path,
            "the reduced models' face fields do not match",
        ));
    }
    let header = Header {
        vertices,
        face_checksum: format!("{:016x}", stored.face_checksum),
        tissues: stored.tissues,
        sliding: stored.sliding,
        sliding_matters: stored.sliding_matters,
        models: stored
            .models
            .iter()
            .map(|m| ModelHeader {
                sliding: m.sliding,
                terms: m.terms.clone(),
                form: m.form.clone(),
                theta_box: m.theta_box.clone(),
                face_bound: m.face_bound.clone(),
                output_bounds: m.output_bounds.clone(),
                duals: m.duals.clone(),
                build: m.build.clone(),
            })
            .collect(),
    };
    let json = serde_json::to_vec(&header).map_err(|e| Error::output(path, e))?;
    write_bytes_atomic(path, |w| {
        w.write_all(&stored::head(
            MAGIC,
            FORMAT_VERSION,
            env!("CARGO_PKG_VERSION"),
            &json,
        ))?;
        for m in &stored.models {
            w.write_all(&stored::point_bytes(&m.face.lift))?;
            for c in &m.face.columns {
                w.write_all(&stored::point_bytes(c))?;
            }
        }
        Ok(())
    })
}

/// Read a file written by this facesim version for the face `face_pre` (the run's
/// pre-operative face, e.g. from its plan_basis.bin).
pub fn read(path: &Path, face_pre: &[[f64; 3]]) -> Result<StoredReduced> {
    let bytes = stored::read_bytes(
        path,
        "no reduced model here (a run that samples with the reduced method writes reduced_model.bin)",
    )?;
    let (mut r, _, header) = stored::Reader::open(path, KIND, &bytes, MAGIC, FORMAT_VERSION)?;
    let header: Header = serde_json::from_slice(header)
        .map_err(|e| Error::input(path, format!("reduced model header: {e}")))?;
    let n = header.vertices;
    let sum = u64::from_str_radix(&header.face_checksum, 16)
        .map_err(|_| Error::input(path, "reduced model: the face checksum is not hexadecimal"))?;
    if n != face_pre.len() || sum != crate::mesh::checksum(face_pre) {
        return Err(Error::input(
            path,
            format!(
                "reduced model of another face ({n} vertices, checksum {sum:016x}; this run's face has {} vertices, checksum {:016x}): run the case again",
                face_pre.len(),
                crate::mesh::checksum(face_pre)
            ),
        ));
    }
    let mut models = Vec::with_capacity(header.models.len());
    for (i, m) in header.models.into_iter().enumerate() {
        let q = m.form.terms();
        if !m.form.consistent()
            || m.terms.len() != q
            || m.terms
                .iter()
                .any(|(s, _)| *s >= crate::case::Tet::TISSUES.len())
            || m.theta_box.iter().any(|b| b.len() != q)
            || std::iter::once(&m.face_bound)
                .chain(&m.output_bounds)
                .any(|b| !b.consistent())
            || !(m.duals.is_empty() || m.duals.len() == m.output_bounds.len())
            || m.duals
                .iter()
                .any(|d| d.components() != 3 || !d.consistent(q, m.form.size()))
        {
            return Err(Error::input(
                path,
                format!(
                    "reduced model {i}: its arrays do not have the sizes N and Q imply (corrupt)"
                ),
            ));
        }
        let lift = r.points(n, &format!("model {i}'s lift"))?;
        let columns = (0..m.form.size())
            .map(|k| r.points(n, &format!("model {i}'s face column {k}")))
            .collect::<Result<Vec<_>>>()?;
        models.push(ReducedTet {
            sliding: m.sliding,
            form: m.form,
            terms: m.terms,
            theta_box: m.theta_box,
            face: LinearFace::new(lift, columns),
            face_bound: m.face_bound,
            output_bounds: m.output_bounds,
            duals: m.duals,
            build: m.build,
        });
    }
    r.finish("the last face column")?;
    if models
        .iter()
        .flat_map(|m| std::iter::once(&m.face.lift).chain(&m.face.columns))
        .flatten()
        .flatten()
        .any(|v| !v.is_finite())
    {
        return Err(Error::input(
            path,
            "reduced model: non-finite values (corrupt)",
        ));
    }
    Ok(StoredReduced {
        models,
        tissues: header.tissues,
        sliding: header.sliding,
        sliding_matters: header.sliding_matters,
        face_checksum: sum,
    })
}

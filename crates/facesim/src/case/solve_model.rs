//! `[solve] model`: which model predicts the face. Its own file so that both the schema and
//! `[uncertainty]` (whose parameters depend on the model) take it without importing each other.

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum SolveModel {
    Equilibrium,
    Koch1996,
    /// The volumetric soft-tissue model (`[tet]`, docs/design/pipeline.md "Volumetric soft tissue").
    Tet,
}

impl SolveModel {
    /// Koch's C1 surface models hang the skin on tissue springs (Koch §2.5–2.6); the volumetric
    /// model meshes the tissue instead. What else differs lives behind `crate::model`.
    pub(crate) fn on_springs(self) -> bool {
        self != SolveModel::Tet
    }

    /// The name case.toml uses (`[solve] model`).
    pub fn name(self) -> &'static str {
        match self {
            SolveModel::Equilibrium => "equilibrium",
            SolveModel::Koch1996 => "koch1996",
            SolveModel::Tet => "tet",
        }
    }
}

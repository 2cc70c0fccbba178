//! `[uncertainty]` in case.toml (docs/guide/uncertainty.md), with the case schema (the sampling is
//! `crate::uncertainty`): how many samples, the seed, and a
//! distribution per tissue parameter. A parameter left out takes its literature default for the
//! case's model; one given that the model does not have is refused, naming the key.

use super::solve_model::SolveModel;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// More samples than this would hold `8 · samples · face vertices` bytes of magnitudes in memory
/// for the percentiles (docs/guide/uncertainty.md): beyond it the band needs streaming quantiles.
pub(crate) const MAX_SAMPLES: usize = 4096;

/// The reduced model's samples are reduced in chunks of vertices (`uncertainty::reduced`), so
/// memory does not grow with the face × samples; this bounds the time (~0.5 ms a sample).
pub(crate) const MAX_REDUCED_SAMPLES: usize = 100_000;

/// Below this many samples `method = "auto"` solves each in full: the reduced model's greedy
/// costs about 12 factorisations per sliding state (docs/design/reduced.md).
pub(crate) const AUTO_REDUCED_FROM: usize = 64;

/// How the samples are solved (`[uncertainty] method`).
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The reduced model when the case's model has one and samples >= 64, else full solves.
    #[default]
    Auto,
    /// The certified reduced model (docs/design/reduced.md); refused for models without one.
    Reduced,
    /// A full solve per distinct sample.
    Full,
}

/// A range: exactly one of `uniform = [min, max]` or `log_uniform = [min, max]` (uniform in the
/// logarithm, for ratios). `min == max` is a point: no spread.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Range {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uniform: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_uniform: Option<[f64; 2]>,
}

impl Range {
    pub const fn uniform(min: f64, max: f64) -> Range {
        Range {
            uniform: Some([min, max]),
            log_uniform: None,
        }
    }

    pub const fn log_uniform(min: f64, max: f64) -> Range {
        Range {
            uniform: None,
            log_uniform: Some([min, max]),
        }
    }

    /// The value at `u` ∈ [0, 1). A point range gives its value exactly.
    pub fn at(&self, u: f64) -> f64 {
        match (self.uniform, self.log_uniform) {
            (Some([a, b]), _) => a + (b - a) * u,
            (None, Some([a, b])) => a * (b / a).powf(u),
            (None, None) => f64::NAN,
        }
    }

    /// Check the range's form and that every value in it satisfies `ok`; errors name `key`.
    fn check(
        &self,
        key: &str,
        what: &str,
        ok: impl Fn(f64) -> bool,
    ) -> std::result::Result<(), String> {
        let (kind, [a, b]) = match (self.uniform, self.log_uniform) {
            (Some(r), None) => ("uniform", r),
            (None, Some(r)) => ("log_uniform", r),
            _ => {
                return Err(format!(
                    "[uncertainty.{key}] needs exactly one of uniform = [min, max] or log_uniform = [min, max]"
                ));
            }
        };
        if !(a.is_finite() && b.is_finite() && a <= b) {
            return Err(format!(
                "[uncertainty.{key}] {kind} = [{a}, {b}]: needs finite min <= max"
            ));
        }
        if kind == "log_uniform" && !(a > 0.0) {
            return Err(format!(
                "[uncertainty.{key}] log_uniform = [{a}, {b}]: a log-uniform range must be positive"
            ));
        }
        if !(ok(a) && ok(b)) {
            return Err(format!("[uncertainty.{key}] {kind} = [{a}, {b}]: {what}"));
        }
        Ok(())
    }
}

/// A yes/no parameter: `probability` of yes, in [0, 1].
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Chance {
    pub probability: f64,
}

/// `[uncertainty]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Uncertainty {
    /// 0: off; N > 0: N samples of the tissue parameters.
    #[serde(default)]
    pub samples: usize,
    /// Full solves or the certified reduced model.
    #[serde(default)]
    pub method: Method,
    #[serde(default = "one")]
    pub seed: u64,
    /// The reduced method: rounds of each soft landmark's dual greedy (primal–dual output
    /// bounds, docs/design/reduced.md); 0: none, the landmarks keep the bound through the
    /// Riesz representer.
    #[serde(default)]
    pub landmark_dual_rounds: usize,
    /// Model tet: the Poisson ratio of every soft tissue.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub poisson: Option<Range>,
    /// Model tet: Young's modulus of muscle over that of (dark) fat.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub muscle_fat: Option<Range>,
    /// Model tet: Young's modulus of skin over that of (dark) fat.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skin_fat: Option<Range>,
    /// Model tet: the probability that the mucosa slides along the bone (else attached).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sliding: Option<Chance>,
    /// C1 models: a factor on the spring stiffness scale (`[solve] k_c`, `koch_k_c`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spring_scale: Option<Range>,
}

/// `landmark_dual_rounds` at most: 12 rounds are 39 adjoint vectors per landmark.
const MAX_DUAL_ROUNDS: usize = 12;

fn one() -> u64 {
    1
}

/// The literature defaults (docs/guide/uncertainty.md gives the sources).
pub mod defaults {
    use super::{Chance, Range};
    /// Soft tissue ν 0.45–0.49.
    pub(crate) const POISSON: Range = Range::uniform(0.45, 0.49);
    /// Muscle 5–15 kPa over fat 1–3 kPa: 5/3 to 15.
    pub(crate) const MUSCLE_FAT: Range = Range::log_uniform(1.7, 15.0);
    /// Skin over fat: Koch's Table 1 spans 10–20; widened to 5–30.
    pub(crate) const SKIN_FAT: Range = Range::log_uniform(5.0, 30.0);
    /// Sliding or attached mucosa: no preference.
    pub(crate) const SLIDING: Chance = Chance { probability: 0.5 };
    /// A factor of 3 overall (√3 either way), the spread of the fat and muscle moduli ranges.
    pub(crate) const SPRING_SCALE: Range =
        Range::log_uniform(0.577_350_269_189_625_8, 1.732_050_807_568_877_2);
}

/// One sampled parameter, in the order of the quasi-random sequence's dimensions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Parameter {
    Poisson,
    MuscleFat,
    SkinFat,
    Sliding,
    SpringScale,
}

impl Parameter {
    pub const ALL: [Parameter; 5] = [
        Parameter::Poisson,
        Parameter::MuscleFat,
        Parameter::SkinFat,
        Parameter::Sliding,
        Parameter::SpringScale,
    ];

    pub fn key(self) -> &'static str {
        match self {
            Parameter::Poisson => "poisson",
            Parameter::MuscleFat => "muscle_fat",
            Parameter::SkinFat => "skin_fat",
            Parameter::Sliding => "sliding",
            Parameter::SpringScale => "spring_scale",
        }
    }

    /// The models the parameter exists in.
    fn applies_to(self, model: SolveModel) -> bool {
        match self {
            Parameter::SpringScale => model.on_springs(),
            _ => !model.on_springs(),
        }
    }

    /// The sequence dimension of the parameter: fixed, so a parameter's draws do not depend on
    /// which others are sampled.
    pub(crate) fn dimension(self) -> usize {
        self as usize
    }
}

/// A parameter's distribution as used.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Distribution {
    Range(Range),
    Chance(Chance),
}

impl Uncertainty {
    fn given(&self, p: Parameter) -> Option<Distribution> {
        match p {
            Parameter::Poisson => self.poisson.map(Distribution::Range),
            Parameter::MuscleFat => self.muscle_fat.map(Distribution::Range),
            Parameter::SkinFat => self.skin_fat.map(Distribution::Range),
            Parameter::Sliding => self.sliding.map(Distribution::Chance),
            Parameter::SpringScale => self.spring_scale.map(Distribution::Range),
        }
    }

    fn default_of(p: Parameter) -> Distribution {
        match p {
            Parameter::Poisson => Distribution::Range(defaults::POISSON),
            Parameter::MuscleFat => Distribution::Range(defaults::MUSCLE_FAT),
            Parameter::SkinFat => Distribution::Range(defaults::SKIN_FAT),
            Parameter::Sliding => Distribution::Chance(defaults::SLIDING),
            Parameter::SpringScale => Distribution::Range(defaults::SPRING_SCALE),
        }
    }

    /// The parameters sampled for `model` and their distributions (given, else the default).
    pub fn parameters(&self, model: SolveModel) -> Vec<(Parameter, Distribution)> {
        Parameter::ALL
            .into_iter()
            .filter(|p| p.applies_to(model))
            .map(|p| (p, self.given(p).unwrap_or_else(|| Self::default_of(p))))
            .collect()
    }

    /// The probability that a sample's mucosa slides (given, else the default).
    pub(crate) fn sliding_probability(&self) -> f64 {
        self.sliding.unwrap_or(defaults::SLIDING).probability
    }

    /// Whether the samples are solved by the reduced model, for a case whose model has
    /// (`reduced_form`) or lacks one.
    pub fn reduced(&self, reduced_form: bool) -> bool {
        match self.method {
            Method::Reduced => true,
            Method::Full => false,
            Method::Auto => reduced_form && self.samples >= AUTO_REDUCED_FROM,
        }
    }

    /// Refuse impossible ranges and parameters the model does not have; errors name `path`
    /// (case.toml) and the key. `reduced_form`: the case's model has the reduced form.
    pub fn validate(&self, model: SolveModel, reduced_form: bool, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        if self.method == Method::Reduced && !reduced_form {
            return bad(
                "[uncertainty] method = \"reduced\": the reduced model needs [solve] model = \"tet\" with [tet] material = \"linear\" and element = \"linear\" (docs/design/reduced.md)".into(),
            );
        }
        let cap = if self.reduced(reduced_form) {
            MAX_REDUCED_SAMPLES
        } else {
            MAX_SAMPLES
        };
        if self.samples > cap {
            return bad(format!(
                "[uncertainty] samples = {}: at most {cap} with {} solves{}",
                self.samples,
                if self.reduced(reduced_form) {
                    "reduced"
                } else {
                    "full"
                },
                if cap == MAX_SAMPLES && reduced_form {
                    " (method = \"reduced\" allows more)"
                } else {
                    ""
                }
            ));
        }
        if self.landmark_dual_rounds > MAX_DUAL_ROUNDS {
            return bad(format!(
                "[uncertainty] landmark_dual_rounds = {}: at most {MAX_DUAL_ROUNDS} (each round adds three snapshots per landmark to the reduced models' build)",
                self.landmark_dual_rounds
            ));
        }
        for p in Parameter::ALL {
            let Some(d) = self.given(p) else { continue };
            if !p.applies_to(model) {
                let why = match p {
                    Parameter::SpringScale => {
                        "it scales the springs of the C1 models (\"equilibrium\", \"koch1996\"); model \"tet\" has no springs"
                    }
                    _ => {
                        "it is a tissue parameter of the volumetric model (\"tet\"); the C1 models have springs (sample spring_scale instead)"
                    }
                };
                return bad(format!(
                    "[uncertainty.{}] does not apply to [solve] model = \"{}\": {why}",
                    p.key(),
                    model.name()
                ));
            }
            let checked = match (p, d) {
                (Parameter::Poisson, Distribution::Range(r)) => r.check(
                    p.key(),
                    "a Poisson ratio must lie in (-1, 0.5) (0.5 is incompressible: no finite bulk modulus)",
                    |v| v > -1.0 && v < 0.5,
                ),
                (Parameter::Sliding, Distribution::Chance(c)) => {
                    if (0.0..=1.0).contains(&c.probability) {
                        Ok(())
                    } else {
                        Err(format!(
                            "[uncertainty.sliding] probability = {}: must lie in [0, 1]",
                            c.probability
                        ))
                    }
                }
                (_, Distribution::Range(r)) => r.check(
                    p.key(),
                    "a ratio of moduli (or a stiffness factor) must be positive",
                    |v| v > 0.0,
                ),
                (_, Distribution::Chance(_)) => Ok(()),
            };
            checked.or_else(bad)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_ranges_give_their_value_exactly() {
        for v in [0.45, 0.3, 5.0, 1e-3, 7.0 / 3.0] {
            for u in [0.0, 0.123, 0.999] {
                assert_eq!(Range::uniform(v, v).at(u), v);
                assert_eq!(Range::log_uniform(v, v).at(u), v);
            }
        }
        assert_eq!(Range::log_uniform(1.0, 100.0).at(0.5), 10.0);
    }

    #[test]
    fn defaults_are_valid_and_hold_the_nominal_values() {
        let p = Path::new("case.toml");
        Uncertainty::default()
            .validate(SolveModel::Tet, true, p)
            .unwrap();
        let inside = |r: Range, v: f64| {
            let [a, b] = r.uniform.or(r.log_uniform).unwrap();
            a <= v && v <= b
        };
        // The nominal [tet] materials (pipeline/defaults.toml): ν 0.45, muscle 10 / fat 2, skin 30 / fat 2.
        assert!(inside(defaults::POISSON, 0.45));
        assert!(inside(defaults::MUSCLE_FAT, 5.0));
        assert!(inside(defaults::SKIN_FAT, 15.0));
        assert!(inside(defaults::SPRING_SCALE, 1.0));
    }
}

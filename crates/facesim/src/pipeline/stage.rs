//! The stage vocabulary: the stages' names ([`Stage`]), their cost table ([`Costs`], report.json
//! `timings` and `stage_costs`), the optional stages that did not run ([`Skipped`]) and the
//! [`Recorder`] every stage reports through.

use crate::error::Result;
use crate::meter::{Meter, StageCost};
use crate::observe::Observer;
use serde::de::{Deserializer, Error as _};
use serde::ser::{SerializeMap, Serializer};
use serde::{Deserialize, Serialize};

/// A pipeline stage, named in report.json's `timings` and `stage_costs` by [`Stage::key`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    ReadCt,
    Segment,
    Surfaces,
    SmoothDecimate,
    ReadScan,
    PlaceScan,
    Coarsen,
    /// The clinical frame, the bony landmarks and the cuts of `[[surgery]]` (docs/guide/planning.md).
    Anatomy,
    Springs,
    TetMesh,
    Solve,
    Embed,
    /// The plan basis: 12 solves per segment on the run's factor (docs/design/plan-basis.md).
    PlanBasis,
    /// Landmarks, measurements and regions (docs/guide/landmarks.md).
    Landmarks,
    /// Sampling the tissue parameters (docs/guide/uncertainty.md).
    Uncertainty,
    Write,
    Total,
}

impl Stage {
    /// Every stage, in pipeline order (reading a report's keys back).
    const ALL: [Stage; 17] = [
        Stage::ReadCt,
        Stage::Segment,
        Stage::Surfaces,
        Stage::SmoothDecimate,
        Stage::ReadScan,
        Stage::PlaceScan,
        Stage::Coarsen,
        Stage::Anatomy,
        Stage::Springs,
        Stage::TetMesh,
        Stage::Solve,
        Stage::Embed,
        Stage::PlanBasis,
        Stage::Landmarks,
        Stage::Uncertainty,
        Stage::Write,
        Stage::Total,
    ];

    pub fn key(self) -> &'static str {
        match self {
            Stage::ReadCt => "read_ct",
            Stage::Segment => "segment",
            Stage::Surfaces => "surfaces",
            Stage::SmoothDecimate => "smooth_decimate",
            Stage::ReadScan => "read_scan",
            Stage::PlaceScan => "place_scan",
            Stage::Coarsen => "coarsen",
            Stage::Anatomy => "anatomy",
            Stage::Springs => "springs",
            Stage::TetMesh => "tet_mesh",
            Stage::Solve => "solve",
            Stage::Embed => "embed",
            Stage::PlanBasis => "plan_basis",
            Stage::Landmarks => "landmarks",
            Stage::Uncertainty => "uncertainty",
            Stage::Write => "write",
            Stage::Total => "total",
        }
    }

    /// The stage named `key` in a report ([`Stage::key`]'s inverse).
    pub(crate) fn from_key(key: &str) -> Option<Stage> {
        Stage::ALL.into_iter().find(|s| s.key() == key)
    }
}

/// Stage costs in the order the stages ran; written as two maps, `timings` (stage → wall
/// seconds) and `stage_costs` (stage → wall, CPU, peak heap).
#[derive(Clone, Debug, Default)]
pub struct Costs(pub Vec<(Stage, StageCost)>);

impl Costs {
    pub fn get(&self, stage: Stage) -> Option<&StageCost> {
        self.0.iter().find(|(s, _)| *s == stage).map(|(_, c)| c)
    }
    /// Count `c` to `stage`: a stage timed in pieces (the face embedded, then carried; the
    /// landmarks located for the model's region, then analysed) is one entry, its wall and CPU
    /// time summed and its peak heap the largest piece's, so that report.json's maps have each
    /// key once.
    pub fn add(&mut self, stage: Stage, c: StageCost) {
        match self.0.iter_mut().find(|(s, _)| *s == stage) {
            Some((_, t)) => {
                t.wall_s += c.wall_s;
                t.cpu_s += c.cpu_s;
                t.peak_heap_mb = match (t.peak_heap_mb, c.peak_heap_mb) {
                    (Some(a), Some(b)) => Some(a.max(b)),
                    (a, b) => a.or(b),
                };
            }
            None => self.0.push((stage, c)),
        }
    }

    /// Wall seconds of `stage` (0 when it did not run).
    pub fn wall_s(&self, stage: Stage) -> f64 {
        self.get(stage).map_or(0.0, |c| c.wall_s)
    }
}

impl Serialize for Costs {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        struct Walls<'a>(&'a [(Stage, StageCost)]);
        impl Serialize for Walls<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
                let mut m = s.serialize_map(Some(self.0.len()))?;
                for (k, c) in self.0 {
                    m.serialize_entry(k.key(), &c.wall_s)?;
                }
                m.end()
            }
        }
        struct Full<'a>(&'a [(Stage, StageCost)]);
        impl Serialize for Full<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
                let mut m = s.serialize_map(Some(self.0.len()))?;
                for (k, c) in self.0 {
                    m.serialize_entry(k.key(), c)?;
                }
                m.end()
            }
        }
        let mut m = s.serialize_map(Some(2))?;
        m.serialize_entry("timings", &Walls(&self.0))?;
        m.serialize_entry("stage_costs", &Full(&self.0))?;
        m.end()
    }
}

/// `stage_costs` back into stages, in the file's order. `timings` repeats each stage's wall
/// seconds; it must name the same stages (a report edited by hand may not).
impl<'de> Deserialize<'de> for Costs {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        struct Maps {
            timings: crate::landmarks::Ordered<f64>,
            stage_costs: crate::landmarks::Ordered<StageCost>,
        }
        let m = Maps::deserialize(d)?;
        let walls = m.timings.0.iter().map(|(k, _)| k);
        if !walls.eq(m.stage_costs.0.iter().map(|(k, _)| k)) {
            return Err(D::Error::custom(
                "`timings` and `stage_costs` name different stages",
            ));
        }
        m.stage_costs
            .0
            .into_iter()
            .map(|(k, c)| {
                Stage::from_key(&k)
                    .map(|s| (s, c))
                    .ok_or_else(|| D::Error::custom(format!("unknown stage '{k}'")))
            })
            .collect::<std::result::Result<_, _>>()
            .map(Costs)
    }
}

/// A stage that did not run for this case, and why.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct Skipped {
    pub stage: String,
    pub reason: String,
}

/// What stages report besides their outputs: progress and cost (to the observer and the cost
/// table), warnings, and the optional stages that did not run.
pub struct Recorder<'a> {
    pub obs: &'a dyn Observer,
    pub costs: Costs,
    pub warnings: Vec<String>,
    pub skipped: Vec<Skipped>,
}

impl<'a> Recorder<'a> {
    pub fn new(obs: &'a dyn Observer) -> Self {
        Recorder {
            obs,
            costs: Costs::default(),
            warnings: Vec::new(),
            skipped: Vec::new(),
        }
    }

    /// Run `f` as `stage`, announced as `what` on the observer, and record its cost.
    pub fn time<T>(
        &mut self,
        stage: Stage,
        what: &str,
        f: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        if !what.is_empty() {
            self.obs.started(what);
        }
        let m = Meter::start(self.obs.heap());
        let r = f()?;
        let c = m.stop();
        self.obs.finished(stage.key(), &c);
        self.costs.add(stage, c);
        Ok(r)
    }

    pub(crate) fn warn(&mut self, w: impl Into<String>) {
        self.warnings.push(w.into());
    }

    pub fn skip(&mut self, stage: Stage, reason: impl Into<String>) {
        self.skipped.push(Skipped {
            stage: stage.key().into(),
            reason: reason.into(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stage_key_reads_back() {
        for s in Stage::ALL {
            assert_eq!(Stage::from_key(s.key()), Some(s));
        }
        assert_eq!(Stage::from_key("nope"), None);
    }

    /// A stage timed in two pieces is one key in each map, its times summed and its peak the
    /// larger piece's (a JSON reader keeps one of two equal keys: it lost the other piece).
    #[test]
    fn a_stage_timed_twice_is_one_entry() {
        let cost = |wall_s, cpu_s, peak| StageCost {
            wall_s,
            cpu_s,
            peak_heap_mb: peak,
        };
        let mut c = Costs::default();
        c.add(Stage::Embed, cost(0.25, 0.5, Some(3.0)));
        c.add(Stage::Solve, cost(1.0, 2.0, None));
        c.add(Stage::Embed, cost(0.5, 0.75, Some(2.0)));
        let json = serde_json::to_string(&c).unwrap();
        assert_eq!(json.matches("\"embed\"").count(), 2, "{json}");
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(v["timings"]["embed"], 0.75);
        assert_eq!(v["stage_costs"]["embed"]["cpu_s"], 1.25);
        assert_eq!(v["stage_costs"]["embed"]["peak_heap_mb"], 3.0);
        let keys: Vec<&String> = v["timings"].as_object().unwrap().keys().collect();
        assert_eq!(keys, ["embed", "solve"]);
    }
}

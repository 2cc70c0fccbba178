//! `facesim sweep OUT_DIR SWEEP.toml --out DIR` (docs/reference/case.md "SWEEP.toml"): many plans from one
//! plan basis, written as `sweep.csv` (per plan: its moves, the face displacement's max, mean and
//! 90th percentile, the same per facial region, each landmark's move and the measurements) and
//! a chart `sweep.svg` (drawn by the caller from the returned rows: crates/facesim-lab
//! `sweep_chart`). Regions and landmarks are the run's (its report.json, which must be there:
//! the landmarks as it found them and the regions derived from them, docs/guide/landmarks.md); a run
//! without landmarks falls back to the profile regions of `landmarks::face_regions::profile`.
//!
//! ```toml
//! [[plan]]                      # any number of listed plans
//! label = "advance 5"
//! [[plan.move]]
//! segment = "maxilla"           # a segment of the run; segments not named stay
//! translate = [0, -5, 0]        # mm, LPS
//! rotate_deg = [0, 0, 0]        # R = Rz·Ry·Rx
//! # pivot = [x, y, z]           # default: the run's pivot of that segment
//!
//! [grid]                        # and/or one grid over one segment's moves
//! segment = "maxilla"
//! translate_y = { from = 0, to = -10, steps = 11 }
//! rotate_x = { from = -5, to = 5, steps = 3 }   # any of translate_x/y/z, rotate_x/y/z
//! ```

use crate::case::Osteotomy;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use crate::plan::{PlanBasis, file};
use crate::report::Report;
use serde::Deserialize;
use std::path::Path;

/// The grid's axes in column order.
pub(crate) const AXES: [&str; 6] = [
    "translate_x",
    "translate_y",
    "translate_z",
    "rotate_x",
    "rotate_y",
    "rotate_z",
];

/// More plans than this is surely a mistake in the file.
const MAX_PLANS: usize = 100_000;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepFile {
    #[serde(default)]
    plan: Vec<ListedPlan>,
    grid: Option<Grid>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ListedPlan {
    label: Option<String>,
    #[serde(default, rename = "move")]
    moves: Vec<Move>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Move {
    segment: String,
    #[serde(default)]
    translate: [f64; 3],
    #[serde(default)]
    rotate_deg: [f64; 3],
    pivot: Option<[f64; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Grid {
    segment: String,
    pivot: Option<[f64; 3]>,
    translate_x: Option<Range>,
    translate_y: Option<Range>,
    translate_z: Option<Range>,
    rotate_x: Option<Range>,
    rotate_y: Option<Range>,
    rotate_z: Option<Range>,
}

#[derive(Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct Range {
    from: f64,
    to: f64,
    steps: usize,
}

impl Range {
    fn values(&self) -> Vec<f64> {
        if self.steps <= 1 {
            return vec![self.from];
        }
        (0..self.steps)
            .map(|i| self.from + (self.to - self.from) * i as f64 / (self.steps - 1) as f64)
            .collect()
    }
}

/// One plan of the sweep.
#[derive(Clone, Debug)]
pub struct SweepPlan {
    pub label: String,
    pub osteotomy: Vec<Osteotomy>,
}

fn osteotomy(basis: &PlanBasis, m: &Move, path: &Path) -> Result<Osteotomy> {
    let s = basis.segment(&m.segment).ok_or_else(|| {
        Error::input(
            path,
            format!(
                "segment '{}' is not a segment of the run (its segments: {})",
                m.segment,
                basis
                    .segments
                    .iter()
                    .map(|s| format!("'{}'", s.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })?;
    Ok(Osteotomy {
        name: s.name.clone(),
        region: s.region.clone(),
        translate: m.translate,
        rotate_deg: m.rotate_deg,
        pivot: m.pivot.unwrap_or(s.pivot),
    })
}

/// The plans of SWEEP.toml at `path`, the listed ones first, then the grid's (the last axis
/// varying fastest).
pub fn read_sweep(path: &Path, basis: &PlanBasis) -> Result<Vec<SweepPlan>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::input(path, e))?;
    sweep_from_text(&text, path, basis)
}

/// The plans of SWEEP.toml text as if read from `path` (errors name `path`).
pub fn sweep_from_text(text: &str, path: &Path, basis: &PlanBasis) -> Result<Vec<SweepPlan>> {
    let file: SweepFile = toml::from_str(text).map_err(|e| Error::input(path, e))?;
    let mut plans = Vec::new();
    for (i, p) in file.plan.iter().enumerate() {
        plans.push(SweepPlan {
            label: p.label.clone().unwrap_or_else(|| format!("plan {}", i + 1)),
            osteotomy: p
                .moves
                .iter()
                .map(|m| osteotomy(basis, m, path))
                .collect::<Result<_>>()?,
        });
    }
    if let Some(g) = &file.grid {
        let axes = [
            g.translate_x,
            g.translate_y,
            g.translate_z,
            g.rotate_x,
            g.rotate_y,
            g.rotate_z,
        ];
        let values: Vec<Vec<f64>> = axes
            .iter()
            .map(|r| r.map_or(vec![0.0], |r| r.values()))
            .collect();
        let count = values.iter().map(Vec::len).product::<usize>();
        if count > MAX_PLANS
            || axes
                .iter()
                .flatten()
                .any(|r| !(r.from.is_finite() && r.to.is_finite()))
        {
            return Err(Error::input(
                path,
                format!(
                    "[grid]: {count} plans or non-finite bounds (at most {MAX_PLANS} finite plans)"
                ),
            ));
        }
        for i in 0..count {
            let mut rest = i;
            let mut v = [0.0; 6];
            for a in (0..6).rev() {
                v[a] = values[a][rest % values[a].len()];
                rest /= values[a].len();
            }
            let m = Move {
                segment: g.segment.clone(),
                translate: [v[0], v[1], v[2]],
                rotate_deg: [v[3], v[4], v[5]],
                pivot: g.pivot,
            };
            plans.push(SweepPlan {
                label: format!("grid {}", i + 1),
                osteotomy: vec![osteotomy(basis, &m, path)?],
            });
        }
    }
    if plans.is_empty() {
        return Err(Error::input(
            path,
            "no [[plan]] and no [grid]: nothing to sweep",
        ));
    }
    Ok(plans)
}

/// Max, mean and 90th percentile of displacement magnitudes (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stats {
    pub max: f64,
    pub mean: f64,
    pub p90: f64,
}

fn stats(d: impl Iterator<Item = f64>) -> Option<Stats> {
    let mut v: Vec<f64> = d.collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(Stats {
        max: v[v.len() - 1],
        mean: v.iter().sum::<f64>() / v.len() as f64,
        p90: v[((v.len() - 1) as f64 * 0.9).round() as usize],
    })
}

/// One row of sweep.csv.
#[derive(Clone, Debug)]
pub struct SweepRow {
    pub plan: SweepPlan,
    pub face: Stats,
    /// Per region of [`REGION_NAMES`] (None: the region is absent on this face).
    pub regions: Vec<Option<Stats>>,
    /// Per landmark of the run that has a position: label and how far the plan moves it (mm).
    pub landmarks: Vec<(String, f64)>,
    /// Per measurement of the run (nasolabial angle, …): name, unit and value after the plan.
    pub measurements: Vec<(String, String, Option<f64>)>,
}

/// The facial regions of the sweep's columns (the landmark regions' names; the fallback
/// `landmarks::face_regions::profile` uses the same names in the same order).
pub const REGION_NAMES: [&str; 5] = crate::landmarks::face_regions::NAMES;

/// Per region of [`REGION_NAMES`], its vertices' flags (None: absent), from the run's
/// landmarks when it has them.
fn region_members(basis: &PlanBasis, run: Option<&RunLandmarks>) -> Vec<Option<Vec<bool>>> {
    if let Some((Some(frame), lms)) = run {
        let pre = crate::landmarks::positions(lms);
        return crate::landmarks::face_regions::regions(&basis.face_pre, frame, &pre).members;
    }
    crate::landmarks::face_regions::profile::regions(&basis.face_pre)
        .map(|r| r.members)
        .unwrap_or_else(|| vec![None; REGION_NAMES.len()])
}

/// Evaluate every plan of `sweep_file` from the basis in `run_dir`; write sweep.csv into `out`
/// (created) and return the rows (the caller draws sweep.svg from them). Nothing is written
/// when the file, a plan or the run's report.json is bad.
pub fn sweep(run_dir: &Path, sweep_file: &Path, out: &Path) -> Result<Vec<SweepRow>> {
    let basis = file::read(&run_dir.join(file::FILE_NAME))?;
    let plans = read_sweep(sweep_file, &basis)?;
    let run = run_landmarks(run_dir)?;
    let rows = evaluate(&basis, plans, sweep_file, run.as_ref())?;
    write(out, &basis, &rows)?;
    Ok(rows)
}

/// The landmarks (and head frame) a run found, from its report.json.
pub(crate) type RunLandmarks = (
    Option<crate::landmarks::HeadFrame>,
    Vec<crate::landmarks::Landmark>,
);

/// `RunLandmarks` of the run in `run_dir` (None: its report has no landmarks); a missing or
/// unreadable report.json is an error naming it.
pub fn run_landmarks(run_dir: &Path) -> Result<Option<RunLandmarks>> {
    Ok(Report::read(&run_dir.join("report.json"))?.located_landmarks())
}

/// Write sweep.csv for evaluated rows into `out`, as one unit (`output::RunDir`: `out` is
/// replaced whole; the command line draws sweep.svg into it afterwards).
pub fn write(out: &Path, basis: &PlanBasis, rows: &[SweepRow]) -> Result<()> {
    let unit = crate::output::RunDir::create(out)?;
    write_csv(&unit.path().join("sweep.csv"), basis, rows)?;
    unit.commit().map(|_| ())
}

/// Each plan's face displacement statistics, whole face and per region, and the run's
/// landmarks carried with it (a bad plan is named as `sweep_file`'s error). Writes nothing.
pub fn evaluate(
    basis: &PlanBasis,
    plans: Vec<SweepPlan>,
    sweep_file: &Path,
    located: Option<&RunLandmarks>,
) -> Result<Vec<SweepRow>> {
    let members = region_members(basis, located);
    let skin = crate::mesh::Mesh::new(basis.face_pre.clone(), basis.triangles.clone());
    let anchors = located
        .map(|(_, lms)| crate::landmarks::anchors(lms, &skin))
        .unwrap_or_default();
    let mut rows = Vec::with_capacity(plans.len());
    for plan in plans {
        let d = super::replan::predict_plan(basis, &plan.osteotomy, sweep_file)?;
        let mag: Vec<f64> = d
            .iter()
            .zip(&basis.face_pre)
            .map(|(a, b)| crate::vec3::norm(crate::vec3::sub(*a, *b)))
            .collect();
        let face = stats(mag.iter().copied()).unwrap_or(Stats {
            max: 0.0,
            mean: 0.0,
            p90: 0.0,
        });
        let regions = members
            .iter()
            .map(|m| {
                m.as_ref()
                    .and_then(|m| stats(mag.iter().zip(m).filter(|(_, i)| **i).map(|(d, _)| *d)))
            })
            .collect();
        let (landmarks, measurements) = match &located {
            Some((frame, lms)) => {
                let post = crate::mesh::Mesh::new(d, basis.triangles.clone());
                let moved = crate::osteotomy::Plan::new(&plan.osteotomy);
                let carried = crate::landmarks::carry_anchored(lms, &anchors, &post, &moved);
                let measurements = frame
                    .as_ref()
                    .map(|f| {
                        crate::landmarks::measure::measure(&carried, f)
                            .0
                            .0
                            .into_iter()
                            .map(|(k, m)| (k, m.unit.to_string(), m.after))
                            .collect()
                    })
                    .unwrap_or_default();
                let lm = carried
                    .into_iter()
                    .filter_map(|c| c.change_mm.map(|d| (c.label, d)))
                    .collect();
                (lm, measurements)
            }
            None => (Vec::new(), Vec::new()),
        };
        rows.push(SweepRow {
            plan,
            face,
            regions,
            landmarks,
            measurements,
        });
    }
    Ok(rows)
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// sweep.csv's numeric column names after `plan` and `label`: per segment its six moves
/// (`{segment}_{axis}`), then `face_{max,mean,p90}_mm`, then the same per facial region, then
/// per landmark `{label}_move_mm` and per measurement `{name}_{unit}` (those of `rows`).
pub fn value_columns(basis: &PlanBasis, rows: &[SweepRow]) -> Vec<String> {
    let slug = |s: &str| s.replace(' ', "_");
    let mut head = Vec::new();
    for s in &basis.segments {
        for a in AXES {
            head.push(format!("{}_{a}", s.name));
        }
    }
    head.extend(["face_max_mm", "face_mean_mm", "face_p90_mm"].map(String::from));
    for r in REGION_NAMES {
        for q in ["max", "mean", "p90"] {
            head.push(format!("{}_{q}_mm", slug(r)));
        }
    }
    // Landmark and measurement columns: those of the first row (every row has the same).
    if let Some(first) = rows.first() {
        for (label, _) in &first.landmarks {
            head.push(format!("{label}_move_mm"));
        }
        for (name, unit, _) in &first.measurements {
            head.push(format!("{name}_{unit}"));
        }
    }
    head
}

/// One row's values in [`value_columns`] order (NaN: the region or measurement is absent).
pub fn row_values(basis: &PlanBasis, row: &SweepRow) -> Vec<f64> {
    let mut v = Vec::new();
    for s in &basis.segments {
        let o = row.plan.osteotomy.iter().find(|o| o.name == s.name);
        let (t, r) = o.map_or(([0.0; 3], [0.0; 3]), |o| (o.translate, o.rotate_deg));
        v.extend(t.iter().chain(&r));
    }
    let f = row.face;
    v.extend([f.max, f.mean, f.p90]);
    for r in &row.regions {
        v.extend(r.map_or([f64::NAN; 3], |s| [s.max, s.mean, s.p90]));
    }
    v.extend(row.landmarks.iter().map(|(_, d)| *d));
    v.extend(
        row.measurements
            .iter()
            .map(|(_, _, m)| m.unwrap_or(f64::NAN)),
    );
    v
}

fn write_csv(path: &Path, basis: &PlanBasis, rows: &[SweepRow]) -> Result<()> {
    let mut head = vec!["plan".to_string(), "label".to_string()];
    head.extend(value_columns(basis, rows).iter().map(|c| csv_field(c)));
    write_bytes_atomic(path, |w| {
        writeln!(w, "{}", head.join(","))?;
        for (i, row) in rows.iter().enumerate() {
            let mut cells = vec![(i + 1).to_string(), csv_field(&row.plan.label)];
            // The moves as given; the statistics to 1 nm, an absent region empty.
            let moves = AXES.len() * basis.segments.len();
            for (j, v) in row_values(basis, row).into_iter().enumerate() {
                cells.push(match () {
                    _ if j < moves => v.to_string(),
                    _ if v.is_nan() => String::new(),
                    _ => format!("{v:.6}"),
                });
            }
            writeln!(w, "{}", cells.join(","))?;
        }
        Ok(())
    })
}

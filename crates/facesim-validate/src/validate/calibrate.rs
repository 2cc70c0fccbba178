//! `facesim calibrate` (docs/lab/validation-notes.md "Calibration
//! on the reduced model"): the tissue parameters fitted to the published soft/hard ratios on one
//! half of the table and checked on the other, the search answered by the certified reduced
//! model and its optimum confirmed by full runs.
//!
//! 1. Every validation run at the defaults, each storing its reduced model (two sliding
//!    states) over the `[uncertainty]` box: `defaults/` (a `facesim validate` output).
//! 2. A grid over that box (ν, muscle/fat, skin/fat, sliding): at each point every row's ratio
//!    from the reduced models, with its certified bound; the point whose fitted half lies least
//!    outside the published ranges is the optimum.
//! 3. Every run again, in full, at the optimum: `optimum/`. Its ratios confirm the reduced ones
//!    (each within its bound) and give the held-out half's verdict: the defaults should change
//!    only if the held-out half improves.

use super::{CaseInfo, Options, Row, RunLandmarks, Validation, rows_of_run, validate_with};
use facesim::case::uncertainty::{Distribution, Parameter};
use facesim::case::{Case, Tet, TissueElastic};
use facesim::error::{Error, Result};
use facesim::landmarks::published::{Published, Surgery};
use facesim::landmarks::{Carried, Kind, SurfaceAnchor};
use facesim::model::reduced::file::{self as stored, StoredReduced};
use facesim::observe::Observer;
use rayon::prelude::*;
use std::path::PathBuf;

/// Which half of the table is fitted (the other is held out).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Half {
    /// Le Fort I advance, impaction and setback.
    Maxillary,
    /// BSSO advance and setback, genioplasty, bimaxillary.
    Mandibular,
}

impl Half {
    pub fn of(s: Surgery) -> Half {
        match s {
            Surgery::LeFortAdvance | Surgery::LeFortImpaction | Surgery::LeFortSetback => {
                Half::Maxillary
            }
            _ => Half::Mandibular,
        }
    }

    pub fn key(self) -> &'static str {
        match self {
            Half::Maxillary => "maxillary",
            Half::Mandibular => "mandibular",
        }
    }

    pub fn from_key(s: &str) -> Option<Half> {
        match s {
            "maxillary" => Some(Half::Maxillary),
            "mandibular" => Some(Half::Mandibular),
            _ => None,
        }
    }
}

/// What to calibrate: the validation's cases and surgeries, the fitted half and the grid.
pub struct CalibrateOptions {
    /// The validation's options; `out` is the calibration's directory (defaults/ and optimum/
    /// inside it hold the two passes), `overrides` are laid under the calibration's own.
    pub validate: Options,
    pub fit: Half,
    /// Points per continuous parameter of the grid (≥ 2: the box's ends are points).
    pub grid: usize,
}

/// One parameter set of the box: ν of every soft tissue, muscle and skin moduli as ratios to
/// the dark fat's (as `[uncertainty]` samples them), and sliding.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    pub poisson: f64,
    pub muscle_fat: f64,
    pub skin_fat: f64,
    pub sliding: bool,
}

/// A half's standing at one point: rows inside / measured, and the distance outside (the sum
/// over measured rows of how far each ratio lies outside its range).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Standing {
    pub inside: usize,
    pub measured: usize,
    pub distance: f64,
}

/// One grid point's standing, by the reduced models.
#[derive(Clone, Debug)]
pub struct GridPoint {
    pub point: Point,
    pub fitted: Standing,
    pub held_out: Standing,
    /// The sum of the fitted rows' ratio bounds: the fitted distance is certain to this.
    pub fitted_bound: f64,
}

/// One row of the table through the calibration.
#[derive(Clone, Debug)]
pub struct CalibratedRow {
    pub half: Half,
    /// The full run at the defaults (defaults/).
    pub defaults: Row,
    /// The reduced model at the defaults and its certified bound on the ratio.
    pub defaults_reduced: Option<(f64, f64)>,
    /// The reduced model at the optimum and its bound.
    pub optimum_reduced: Option<(f64, f64)>,
    /// The full run at the optimum (optimum/): the confirmation.
    pub optimum: Option<Row>,
    /// How the optimum's run tore or lifted off other tissue than the defaults' run, whose
    /// state the reduced models keep (None: the same). A full run chooses that state for
    /// itself, so its difference from the reduced answer may exceed the bound, which is on
    /// the model in the defaults' state.
    pub state_change: Option<String>,
}

/// What a confirmation found: the largest |reduced − full| ratio at the optimum, and the rows
/// outside their certified bound, with and without a change of tissue state to explain them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Confirmation {
    pub worst: f64,
    pub outside_changed_state: usize,
    pub outside_same_state: usize,
}

pub struct Calibration {
    pub defaults: Validation,
    pub optimum_validation: Validation,
    pub grid: Vec<GridPoint>,
    pub optimum: Point,
    /// The defaults as a point of the box.
    pub nominal: Point,
    pub rows: Vec<CalibratedRow>,
    pub fit: Half,
    pub out_dir: PathBuf,
    pub seconds: [f64; 3],
}

impl Calibration {
    /// A half's standing by the full runs at the defaults (false) or at the optimum (true).
    pub fn full(&self, half: Half, optimum: bool) -> Standing {
        standing(self.rows.iter().filter(|r| r.half == half).filter_map(|r| {
            let row = if optimum {
                r.optimum.as_ref()?
            } else {
                &r.defaults
            };
            Some((row.published, row.ratio))
        }))
    }

    /// Whether the held-out half improves at the optimum (less distance outside, no row fewer
    /// inside): the rule for changing the defaults.
    pub fn held_out_improves(&self) -> bool {
        let h = other(self.fit);
        let (a, b) = (self.full(h, false), self.full(h, true));
        b.distance < a.distance - 1e-3 && b.inside >= a.inside
    }

    /// The reduced ratios at the optimum against the full runs'.
    pub fn confirmation(&self) -> Confirmation {
        let mut c = Confirmation {
            worst: 0.0,
            outside_changed_state: 0,
            outside_same_state: 0,
        };
        for r in &self.rows {
            if let (Some((red, bound)), Some(Some(full))) =
                (r.optimum_reduced, r.optimum.as_ref().map(|o| o.ratio))
            {
                let d = (red - full).abs();
                c.worst = c.worst.max(d);
                if d > bound {
                    if r.state_change.is_some() {
                        c.outside_changed_state += 1;
                    } else {
                        c.outside_same_state += 1;
                    }
                }
            }
        }
        c
    }
}

fn other(h: Half) -> Half {
    match h {
        Half::Maxillary => Half::Mandibular,
        Half::Mandibular => Half::Maxillary,
    }
}

/// How far `ratio` lies outside `p`'s range (0 inside, as `Published::contains` reads it).
fn outside_by(p: &Published, ratio: f64) -> f64 {
    if p.contains(ratio) {
        0.0
    } else {
        (p.low - ratio).max(ratio - p.high)
    }
}

fn standing<'a>(rows: impl Iterator<Item = (&'a Published, Option<f64>)>) -> Standing {
    let mut s = Standing::default();
    for (p, r) in rows {
        if let Some(r) = r {
            s.measured += 1;
            s.inside += usize::from(p.contains(r));
            s.distance += outside_by(p, r);
        }
    }
    s
}

/// What the search needs of one run: its reduced models, the face and landmark anchors, and
/// how its rows are measured.
struct Calibrand {
    info: CaseInfo,
    surgery: Surgery,
    models: StoredReduced,
    triangles: Vec<[u32; 3]>,
    /// The run's carried landmarks (bony ones stay as the run carried them).
    carried: Vec<Carried>,
    anchors: Vec<Option<SurfaceAnchor>>,
    /// Per soft landmark label, its index among the reduced model's outputs (landmark bounds).
    outputs: Vec<(String, usize)>,
    face_region: Option<([f64; 3], [f64; 3])>,
    /// The run's case: the nominal parameters the box's ratios scale.
    base: Case,
    /// The run's tissue state, which its reduced models keep.
    state: TissueState,
}

/// What a run's move chose of the tissue: torn elements, lifted-off nodes, and whether it slid
/// (only a sliding run lifts tissue off, and only a sliding re-solve keeps it lifted).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct TissueState {
    torn: usize,
    lifted_off: usize,
    sliding: bool,
}

fn tissue_state(o: &facesim::commands::Outcome) -> TissueState {
    let (torn, lifted_off) = o
        .report
        .tet
        .as_ref()
        .map_or((0, 0), |t| (t.torn_elements, t.lifted_off));
    TissueState {
        torn,
        lifted_off,
        sliding: o.report.parameters.as_ref().is_some_and(|c| c.tet.sliding),
    }
}

impl Calibrand {
    fn of(info: &CaseInfo, surgery: Surgery, o: &facesim::commands::Outcome) -> Result<Calibrand> {
        let path = o.out_dir.join(stored::FILE_NAME);
        let models = stored::read(&path, &o.skin.vertices)?;
        let base =
            o.report.parameters.clone().ok_or_else(|| {
                Error::config("calibrate: the run's report.json has no parameters")
            })?;
        // In the run's order, which the carried landmarks and the reduced model's outputs have.
        let (frame, lms) = o
            .report
            .located_in_run_order()
            .ok_or_else(|| Error::config("calibrate: the run found no landmarks"))?;
        let anchors = facesim::landmarks::anchors(&lms, &o.skin);
        let analysis = facesim::landmarks::analyse_located(
            &o.skin,
            &o.face_post,
            frame,
            lms,
            &facesim::osteotomy::Plan::new(&[]),
        );
        let labels = facesim::uncertainty::reduced::landmark_output_labels(&analysis);
        let outputs = labels
            .into_iter()
            .enumerate()
            .map(|(i, l)| (l, i))
            .collect();
        Ok(Calibrand {
            info: info.clone(),
            surgery,
            models,
            triangles: o.skin.triangles.clone(),
            carried: o
                .report
                .landmarks
                .0
                .iter()
                .map(|(_, c)| c.clone())
                .collect(),
            anchors,
            outputs,
            face_region: o.report.tet.as_ref().map(|t| t.region),
            base,
            state: tissue_state(o),
        })
    }

    /// The rows of this run at `p` by the reduced model, each with the certified bound on its
    /// ratio (None: not measured, or the reduced model does not answer there).
    fn rows_at(&self, p: &Point) -> Result<Vec<(Row, Option<f64>)>> {
        let case = apply(&self.base, p);
        let f = self.models.face(&case.tet.tissues(), case.tet.sliding)?;
        let mut carried = self.carried.clone();
        let mut bound_of = std::collections::HashMap::new();
        for (c, a) in carried.iter_mut().zip(&self.anchors) {
            let (Kind::Soft, Some(a), Some(pre)) = (c.kind, a, c.pre) else {
                continue;
            };
            let tri = self.triangles[a.triangle as usize];
            let mut d = [0.0; 3];
            for (v, w) in tri.iter().zip(a.weights) {
                let u = f.displacement[*v as usize];
                for k in 0..3 {
                    d[k] += w * u[k];
                }
            }
            // A landmark with its own output takes the model's correction (zero without a dual
            // basis): its bound is on the corrected displacement, not on the face's value.
            let output = self
                .outputs
                .iter()
                .find(|(l, _)| *l == c.label)
                .map(|o| o.1);
            if let Some(k) = output.and_then(|i| f.landmark_corrections.get(i)) {
                d = facesim::vec3::add(d, *k);
            }
            let post = facesim::vec3::add(pre, d);
            c.post = Some(post);
            c.change_mm = Some(facesim::vec3::norm(d));
            let b = output
                .and_then(|i| f.landmark_bounds_mm.get(i).copied())
                .unwrap_or(f.bound_mm);
            bound_of.insert(c.label.clone(), b);
        }
        let rows = rows_of_run(
            &self.info,
            self.surgery,
            Ok(RunLandmarks {
                carried,
                face_region: self.face_region,
                // A grid point's face: no band.
                published: Vec::new(),
            }),
        );
        Ok(rows
            .into_iter()
            .map(|r| {
                let b = r.ratio.map(|_| {
                    r.published
                        .terms
                        .iter()
                        .map(|(l, w)| w.abs() * bound_of.get(*l).copied().unwrap_or(f.bound_mm))
                        .sum::<f64>()
                        / r.move_mm.abs()
                });
                (r, b)
            })
            .collect())
    }
}

/// Every run's rows at `p` by the reduced models, each with its ratio's bound.
fn rows_at(calibrands: &[Calibrand], p: &Point) -> Result<Vec<(Row, Option<f64>)>> {
    let mut rows = Vec::new();
    for c in calibrands {
        rows.extend(c.rows_at(p)?);
    }
    Ok(rows)
}

/// The nominal case at point `p` of the box (as `[uncertainty]` applies a draw).
fn apply(base: &Case, p: &Point) -> Case {
    facesim::uncertainty::run::Draw {
        poisson: Some(p.poisson),
        muscle_fat: Some(p.muscle_fat),
        skin_fat: Some(p.skin_fat),
        sliding: Some(p.sliding),
        spring_scale: None,
    }
    .apply(base)
}

/// The box's grid: `k` points per continuous parameter (its ends included; log-uniform ranges
/// spaced evenly in the log), both sliding states when the box draws sliding.
fn grid(base: &Case, k: usize) -> Result<Vec<Point>> {
    let params = base.uncertainty.parameters(facesim::case::SolveModel::Tet);
    let mut values: [Vec<f64>; 3] = Default::default();
    let mut sliding = vec![base.tet.sliding];
    for (p, d) in &params {
        let slot = match p {
            Parameter::Poisson => 0,
            Parameter::MuscleFat => 1,
            Parameter::SkinFat => 2,
            Parameter::Sliding => {
                if let Distribution::Chance(c) = d
                    && c.probability > 0.0
                    && c.probability < 1.0
                {
                    sliding = vec![true, false];
                }
                continue;
            }
            Parameter::SpringScale => continue,
        };
        let Distribution::Range(r) = d else {
            continue;
        };
        values[slot] = (0..k).map(|i| r.at(i as f64 / (k - 1) as f64)).collect();
    }
    let nominal = nominal_point(base);
    for (slot, v) in values.iter_mut().enumerate() {
        if v.is_empty() {
            // Not in the box: the nominal value only.
            *v = vec![[nominal.poisson, nominal.muscle_fat, nominal.skin_fat][slot]];
        }
    }
    let mut points = Vec::new();
    for &s in &sliding {
        for &nu in &values[0] {
            for &m in &values[1] {
                for &sk in &values[2] {
                    points.push(Point {
                        poisson: nu,
                        muscle_fat: m,
                        skin_fat: sk,
                        sliding: s,
                    });
                }
            }
        }
    }
    if points.is_empty() {
        return Err(Error::config("calibrate: the [uncertainty] box is empty"));
    }
    Ok(points)
}

/// The defaults as a point: ν of the skin (the box sets every tissue's), the ratios to the
/// dark fat's modulus.
fn nominal_point(base: &Case) -> Point {
    let t = &base.tet;
    Point {
        poisson: t.skin.poisson,
        muscle_fat: t.muscle.youngs_kpa / t.fat_dark.youngs_kpa,
        skin_fat: t.skin.youngs_kpa / t.fat_dark.youngs_kpa,
        sliding: t.sliding,
    }
}

/// `--set` keys for the case at `p`: every tissue's modulus and ν, and sliding.
fn overrides_at(base: &Case, p: &Point) -> toml::Table {
    let c = apply(base, p);
    let mut tet = toml::Table::new();
    for (name, m) in Tet::TISSUES.iter().zip(c.tet.tissues()) {
        let TissueElastic {
            youngs_kpa,
            poisson,
        } = m;
        let mut t = toml::Table::new();
        t.insert("youngs_kpa".into(), toml::Value::Float(youngs_kpa));
        t.insert("poisson".into(), toml::Value::Float(poisson));
        tet.insert((*name).into(), toml::Value::Table(t));
    }
    tet.insert("sliding".into(), toml::Value::Boolean(p.sliding));
    let mut o = toml::Table::new();
    o.insert("tet".into(), toml::Value::Table(tet));
    o
}

/// The row key across the passes.
fn key(r: &Row) -> (String, Surgery, &'static str) {
    (r.case.clone(), r.published.surgery, r.published.soft)
}

/// `facesim calibrate`.
pub fn calibrate(opts: &CalibrateOptions, obs: &dyn Observer) -> Result<Calibration> {
    if opts.grid < 2 {
        return Err(Error::config("calibrate: --grid must be at least 2"));
    }
    let unit = facesim::output::RunDir::create(&opts.validate.out)?;
    let dir = unit.path().to_path_buf();
    let t0 = std::time::Instant::now();
    // Pass 1: the defaults, each run storing its reduced model over the box.
    let mut first = opts.validate.overrides.clone();
    let reduced: toml::Table =
        toml::from_str("[uncertainty]\nsamples = 64\nmethod = \"reduced\"\n")
            .map_err(|e| Error::config(e.to_string()))?;
    facesim::case::merge(&mut first, reduced);
    let mut calibrands: Vec<Calibrand> = Vec::new();
    let defaults = validate_with(
        &Options {
            out: dir.join("defaults"),
            overrides: first,
            ..opts.validate.clone()
        },
        obs,
        &mut |info, s, o| {
            calibrands.push(Calibrand::of(info, s, o)?);
            Ok(())
        },
    )?;
    let t1 = std::time::Instant::now();
    let Some(base) = calibrands.first().map(|c| c.base.clone()) else {
        return Err(Error::config(
            "calibrate: no run stored a reduced model (no case ran, or none has the linear tetrahedral model)",
        ));
    };
    if let Some(c) = calibrands.iter().find(|c| {
        c.base.tet.tissues() != base.tet.tissues() || c.base.uncertainty != base.uncertainty
    }) {
        return Err(Error::config(format!(
            "calibrate: {} has other tissue parameters or another [uncertainty] box than {}: the calibration fits one set",
            c.info.name, calibrands[0].info.name
        )));
    }
    // Pass 2: the grid, on the reduced models.
    let points = grid(&base, opts.grid)?;
    obs.started(&format!(
        "calibrate: {} grid points × {} runs on the reduced models",
        points.len(),
        calibrands.len()
    ));
    let evaluated: Vec<Result<GridPoint>> = points
        .par_iter()
        .map(|p| {
            let rows = rows_at(&calibrands, p)?;
            let of = |h: Half| {
                standing(
                    rows.iter()
                        .filter(|(r, _)| Half::of(r.published.surgery) == h)
                        .map(|(r, _)| (r.published, r.ratio)),
                )
            };
            Ok(GridPoint {
                point: *p,
                fitted: of(opts.fit),
                held_out: of(other(opts.fit)),
                fitted_bound: rows
                    .iter()
                    .filter(|(r, _)| Half::of(r.published.surgery) == opts.fit)
                    .filter_map(|(_, b)| *b)
                    .sum(),
            })
        })
        .collect();
    let grid: Vec<GridPoint> = evaluated.into_iter().collect::<Result<_>>()?;
    let nominal = nominal_point(&base);
    // The least distance outside; among equals (to 1e-6), more rows inside, then the nearest
    // to the defaults.
    let near = |p: &Point| {
        ((p.poisson - nominal.poisson) / 0.04).powi(2)
            + (p.muscle_fat / nominal.muscle_fat).ln().powi(2)
            + (p.skin_fat / nominal.skin_fat).ln().powi(2)
            + f64::from(u8::from(p.sliding != nominal.sliding))
    };
    let best = grid
        .iter()
        .min_by(|a, b| {
            let d = a.fitted.distance - b.fitted.distance;
            if d.abs() > 1e-6 {
                return d.total_cmp(&0.0);
            }
            b.fitted
                .inside
                .cmp(&a.fitted.inside)
                .then(near(&a.point).total_cmp(&near(&b.point)))
        })
        .map(|g| g.point)
        .ok_or_else(|| Error::config("calibrate: the grid has no points"))?;
    // Pass 3: every run in full at the optimum.
    let mut over = opts.validate.overrides.clone();
    facesim::case::merge(&mut over, overrides_at(&base, &best));
    let t2 = std::time::Instant::now();
    let mut states = std::collections::HashMap::new();
    let optimum_validation = validate_with(
        &Options {
            out: dir.join("optimum"),
            overrides: over,
            ..opts.validate.clone()
        },
        obs,
        &mut |info, s, o| {
            states.insert((info.name.clone(), s), tissue_state(o));
            Ok(())
        },
    )?;
    let t3 = std::time::Instant::now();
    // The rows side by side.
    let (at_nominal, at_best) = (
        rows_at(&calibrands, &nominal)?,
        rows_at(&calibrands, &best)?,
    );
    let find = |v: &[(Row, Option<f64>)], r: &Row| {
        v.iter()
            .find(|(x, _)| key(x) == key(r))
            .and_then(|(x, b)| x.ratio.zip(*b))
    };
    let rows: Vec<CalibratedRow> = defaults
        .rows
        .iter()
        .map(|r| CalibratedRow {
            half: Half::of(r.published.surgery),
            defaults: r.clone(),
            defaults_reduced: find(&at_nominal, r),
            optimum_reduced: find(&at_best, r),
            optimum: optimum_validation
                .rows
                .iter()
                .find(|x| key(x) == key(r))
                .cloned(),
            state_change: state_change(
                calibrands
                    .iter()
                    .find(|c| c.info.name == r.case && c.surgery == r.published.surgery)
                    .map(|c| c.state),
                states.get(&(r.case.clone(), r.published.surgery)).copied(),
            ),
        })
        .collect();
    let c = Calibration {
        defaults,
        optimum_validation,
        grid,
        optimum: best,
        nominal,
        rows,
        fit: opts.fit,
        out_dir: opts.validate.out.clone(),
        seconds: [
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            (t3 - t2).as_secs_f64(),
        ],
    };
    obs.started("writing calibration.md and calibration.csv");
    facesim::output::write_bytes_atomic(&dir.join("calibration.csv"), |w| {
        w.write_all(rows_csv(&c).as_bytes())
    })?;
    facesim::output::write_bytes_atomic(&dir.join("calibration_grid.csv"), |w| {
        w.write_all(grid_csv(&c).as_bytes())
    })?;
    facesim::output::write_bytes_atomic(&dir.join("calibration.md"), |w| {
        w.write_all(markdown(&c, opts).as_bytes())
    })?;
    let out_dir = unit.commit()?;
    obs.done();
    // The passes' directories, where they are now.
    let mut c = c;
    c.defaults.out_dir = out_dir.join("defaults");
    c.optimum_validation.out_dir = out_dir.join("optimum");
    c.out_dir = out_dir;
    Ok(c)
}

/// How the optimum's run state differs from what the reduced models keep of the defaults' run:
/// its torn elements, and its lifted-off nodes when both slide.
fn state_change(defaults: Option<TissueState>, optimum: Option<TissueState>) -> Option<String> {
    let (d, o) = (defaults?, optimum?);
    let lift_differs = d.sliding && o.sliding && d.lifted_off != o.lifted_off;
    (d.torn != o.torn || lift_differs).then(|| {
        format!(
            "the run at the optimum tore {} tetrahedra and lifted off {} nodes, the defaults' run (whose state the reduced models keep) {} and {}",
            o.torn, o.lifted_off, d.torn, d.lifted_off
        )
    })
}

/// A bound in scientific notation (they span 1e-12 to 1).
fn e(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.2e}")).unwrap_or_default()
}

fn point_text(p: &Point) -> String {
    format!(
        "ν {:.3}, muscle/fat {:.2}, skin/fat {:.2}, sliding {}",
        p.poisson,
        p.muscle_fat,
        p.skin_fat,
        if p.sliding { "on" } else { "off" }
    )
}

/// calibration.csv: per case, surgery and published row, the ratio at the defaults and at the
/// optimum, by the reduced model (with its bound) and by the full run.
fn rows_csv(c: &Calibration) -> String {
    let mut s = String::from(
        "case,surgery,landmark,half,published_low,published_high,defaults_full,defaults_reduced,defaults_bound,optimum_reduced,optimum_bound,optimum_full,inside_defaults,inside_optimum,note\n",
    );
    let yes = |r: Option<bool>| match r {
        Some(true) => "yes",
        Some(false) => "no",
        None => "",
    };
    for r in &c.rows {
        let p = r.defaults.published;
        let fields = [
            r.defaults.case.clone(),
            p.surgery.key().into(),
            p.soft.into(),
            if r.half == c.fit {
                "fitted"
            } else {
                "held out"
            }
            .into(),
            format!("{}", p.low),
            format!("{}", p.high),
            super::num(r.defaults.ratio, 5),
            super::num(r.defaults_reduced.map(|x| x.0), 5),
            e(r.defaults_reduced.map(|x| x.1)),
            super::num(r.optimum_reduced.map(|x| x.0), 5),
            e(r.optimum_reduced.map(|x| x.1)),
            super::num(r.optimum.as_ref().and_then(|o| o.ratio), 5),
            yes(r.defaults.inside()).into(),
            yes(r.optimum.as_ref().and_then(|o| o.inside())).into(),
            [r.defaults.why.clone(), r.state_change.clone()]
                .into_iter()
                .flatten()
                .collect::<Vec<_>>()
                .join("; "),
        ];
        let line: Vec<String> = fields.iter().map(|f| super::csv_field(f)).collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    s
}

/// calibration_grid.csv: every grid point's standing by the reduced models.
fn grid_csv(c: &Calibration) -> String {
    let mut s = String::from(
        "poisson,muscle_fat,skin_fat,sliding,fitted_inside,fitted_measured,fitted_distance,fitted_bound,held_out_inside,held_out_measured,held_out_distance\n",
    );
    for g in &c.grid {
        let p = g.point;
        s.push_str(&format!(
            "{:.4},{:.4},{:.4},{},{},{},{:.4},{:.4},{},{},{:.4}\n",
            p.poisson,
            p.muscle_fat,
            p.skin_fat,
            p.sliding,
            g.fitted.inside,
            g.fitted.measured,
            g.fitted.distance,
            g.fitted_bound,
            g.held_out.inside,
            g.held_out.measured,
            g.held_out.distance
        ));
    }
    s
}

fn standing_text(s: Standing) -> String {
    format!(
        "{} / {} inside, distance {:.3}",
        s.inside, s.measured, s.distance
    )
}

/// calibration.md: the command, the box and grid, the optimum, the two halves at the defaults
/// and at the optimum, the confirmation and the verdict, then the rows.
fn markdown(c: &Calibration, opts: &CalibrateOptions) -> String {
    let fit = c.fit;
    let held = other(fit);
    let mut s =
        String::from("# facesim calibrate: tissue parameters against the published ratios\n\n");
    s.push_str(&format!(
        "- command: `{}`\n- facesim {}\n- machine: {}\n- time: {:.0} s (runs at the defaults with their reduced models), {:.1} s (the grid on the reduced models), {:.0} s (the confirming full runs)\n\n",
        opts.validate.command,
        env!("CARGO_PKG_VERSION"),
        super::machine(),
        c.seconds[0],
        c.seconds[1],
        c.seconds[2]
    ));
    s.push_str(&format!(
        "Fitted: the {} moves; held out: the {} moves. Grid: {} points over the `[uncertainty]` box ({} per continuous parameter), each row's ratio from the run's reduced model with its certified bound. Defaults: {}.\n\n",
        fit.key(),
        held.key(),
        c.grid.len(),
        opts.grid,
        point_text(&c.nominal)
    ));
    s.push_str(&format!(
        "**Optimum** (least distance outside on the fitted half): {}.\n\n",
        point_text(&c.optimum)
    ));
    s.push_str("| half | defaults (full runs) | optimum (full runs) |\n|---|---|---|\n");
    for h in [fit, held] {
        s.push_str(&format!(
            "| {} ({}) | {} | {} |\n",
            h.key(),
            if h == fit { "fitted" } else { "held out" },
            standing_text(c.full(h, false)),
            standing_text(c.full(h, true))
        ));
    }
    let k = c.confirmation();
    let mut how = Vec::new();
    if k.outside_same_state == 0 && k.outside_changed_state == 0 {
        how.push("every row is within its certified bound".to_string());
    }
    if k.outside_changed_state > 0 {
        how.push(format!(
            "{} rows are outside their bound, each from a run that tore or lifted off other tissue than the defaults' run whose state the reduced models keep (calibration.csv `note`): the bound is on the model in that state",
            k.outside_changed_state
        ));
    }
    if k.outside_same_state > 0 {
        how.push(format!(
            "**{} rows are outside their certified bound with the same tissue state** (calibration.csv)",
            k.outside_same_state
        ));
    }
    s.push_str(&format!(
        "\n**Confirmation.** At the optimum the reduced models' ratios and the full runs' differ by {:.2e} at most; {}.\n\n",
        k.worst,
        how.join("; ")
    ));
    s.push_str(&format!(
        "**Verdict.** The held-out half {}: {}.\n\n",
        if c.held_out_improves() {
            "improves"
        } else {
            "does not improve"
        },
        if c.held_out_improves() {
            "by the held-out rule the optimum is a candidate for the defaults"
        } else {
            "by the held-out rule the defaults stay"
        }
    ));
    s.push_str("| case | surgery | landmark | half | published | defaults | optimum, reduced ± bound | optimum, full |\n|---|---|---|---|---|---|---|---|\n");
    for r in &c.rows {
        let p = r.defaults.published;
        let mark = |x: Option<f64>| match x {
            Some(v) if p.contains(v) => format!("{v:.3}*"),
            Some(v) => format!("{v:.3}"),
            None => "—".into(),
        };
        s.push_str(&format!(
            "| {} | {} | {} | {} | {}–{} | {} | {} | {} |\n",
            r.defaults.case,
            p.surgery.key(),
            p.soft,
            if r.half == fit { "fitted" } else { "held out" },
            p.low,
            p.high,
            mark(r.defaults.ratio),
            r.optimum_reduced
                .map(|(v, b)| format!("{v:.3} ± {b:.3}"))
                .unwrap_or_else(|| "—".into()),
            mark(r.optimum.as_ref().and_then(|o| o.ratio)),
        ));
    }
    s.push_str("\n(* inside the published range.)\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_spans_the_box_ends_and_both_sliding_states() {
        let base = Case::default();
        let g = grid(&base, 3).unwrap();
        assert_eq!(g.len(), 2 * 27);
        let nu: Vec<f64> = g.iter().map(|p| p.poisson).collect();
        let lo = nu.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = nu.iter().copied().fold(0.0, f64::max);
        assert!(
            (lo - 0.45).abs() < 1e-12 && (hi - 0.49).abs() < 1e-12,
            "{lo} {hi}"
        );
        // Log-uniform: the middle point is the geometric mean of the ends.
        let m: Vec<f64> = g.iter().map(|p| p.muscle_fat).collect();
        let mid = m.iter().copied().find(|x| *x > 1.8 && *x < 14.0).unwrap();
        assert!((mid - (1.7f64 * 15.0).sqrt()).abs() < 1e-9, "{mid}");
    }

    #[test]
    fn a_point_becomes_every_tissue_as_the_samples_set_it() {
        let base = Case::default();
        let p = Point {
            poisson: 0.47,
            muscle_fat: 4.0,
            skin_fat: 10.0,
            sliding: false,
        };
        let o = overrides_at(&base, &p);
        let mut c = base.clone();
        let applied = apply(&base, &p);
        let t = o["tet"].as_table().unwrap();
        assert_eq!(t["sliding"].as_bool(), Some(false));
        for (name, m) in Tet::TISSUES.iter().zip(applied.tet.tissues()) {
            assert_eq!(t[*name]["youngs_kpa"].as_float(), Some(m.youngs_kpa));
            assert_eq!(t[*name]["poisson"].as_float(), Some(0.47));
        }
        c.tet.muscle.youngs_kpa = 4.0 * c.tet.fat_dark.youngs_kpa;
        assert_eq!(applied.tet.muscle.youngs_kpa, c.tet.muscle.youngs_kpa);
        assert_eq!(nominal_point(&applied).skin_fat, 10.0);
    }

    #[test]
    fn the_distance_outside_is_zero_inside_and_grows_outside() {
        let p = facesim::landmarks::published::rows_of(Surgery::LeFortAdvance)
            .next()
            .unwrap();
        assert_eq!(outside_by(p, (p.low + p.high) / 2.0), 0.0);
        assert!((outside_by(p, p.high + 0.1) - 0.1).abs() < 1e-12);
        assert!((outside_by(p, p.low - 0.2) - 0.2).abs() < 1e-12);
        let s = standing([(p, Some(p.high + 0.1)), (p, None), (p, Some(p.low))].into_iter());
        assert_eq!((s.inside, s.measured), (1, 2));
    }
}

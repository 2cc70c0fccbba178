//! `facesim validate` (docs/validation.md): every surgery type of the published table
//! (`landmarks::published`) run with the product's defaults on every real sample that has the
//! bone and on a seeded cohort of jaws phantoms; per soft landmark the predicted ratio beside the
//! published range. Writes validation.csv and validation.md as one unit (`output::RunDir`), with
//! each run's report.json, landmarks and faces under `runs/`; the chart (validation.svg) is the
//! caller's (crates/facesim-lab `validation_chart`).

use crate::error::{Error, Result};
use crate::landmarks::measure::along;
use crate::landmarks::published::{PUBLISHED, Published, Surgery};
use crate::landmarks::{Carried, HeadFrame};
use crate::observe::Observer;
use crate::phantom_jaws::{JawsOptions, Shape};
use crate::pipeline::{Recorder, inputs, surfaces, tissues};
use crate::vec3::{add, scale};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What to validate and where.
#[derive(Clone)]
pub struct Options {
    /// The output directory (validation.csv, validation.md, runs/, phantoms/).
    pub out: PathBuf,
    /// The samples directory: each sub-directory with a case.toml and a validation.toml is a case.
    pub samples: PathBuf,
    /// Jaws phantoms in the cohort (soft tissue spread evenly over −2..+4 mm).
    pub phantoms: usize,
    /// The cohort's seed (the other shape parameters are drawn from it).
    pub seed: u64,
    /// The phantoms' voxel size (mm).
    pub phantom_spacing_mm: f64,
    /// The phantoms' noses hollow (`phantom_jaws::Shape::nasal_passages`; the CLI's default),
    /// not solid.
    pub phantom_nasal_passages: bool,
    /// Only these surgeries (empty: all).
    pub surgeries: Vec<Surgery>,
    /// Only these cases: sample directory names and/or "phantom" (empty: all).
    pub cases: Vec<String>,
    /// Laid over every run's case after the surgery's plan (`case::overrides_table`, the CLI's
    /// `--set`): other tissue parameters for the same table. Empty: the product's defaults.
    pub overrides: toml::Table,
    /// Keep every output of each run under runs/ (false: only [`KEPT`]).
    pub keep_runs: bool,
    /// The command line, for validation.md's header.
    pub command: String,
}

/// The moves, in the head's directions: advance and setback along its forward axis, impaction
/// along its up axis. Sizes are those of common plans (docs/validation.md, "What was compared").
/// The output's validation.md lists them under "The moves".
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Toward {
    Forward,
    Back,
    Up,
    /// The mandible's autorotation: turned about the condyles (a lateral axis through the
    /// case's pivot) until its incisal edge has risen the mm along up, closing onto the
    /// impacted maxilla. Only where the case has a mandible; else the step is left out.
    Closing,
}

/// (segment, direction, mm) per surgery, in the order they apply: each segment moves the points
/// inside its region at their current position, so the mandible goes before the maxilla (a
/// forward move of a pitched head's maxilla takes it down, into the mandible's region) — except
/// the impaction's autorotation, which closes the lower teeth up into where the upper were, so
/// the maxilla must have left first.
///
/// A Le Fort I impaction always turns the mandible: with nothing holding it open, it closes
/// about the condyles until the teeth meet again (autorotation), and the published impaction
/// ratios are measured on such patients; the upper lip's shortening comes largely from the
/// lower lip rising under it.
pub fn moves(s: Surgery) -> &'static [(&'static str, Toward, f64)] {
    use Toward::*;
    match s {
        Surgery::LeFortAdvance => &[("maxilla", Forward, 5.0)],
        Surgery::LeFortImpaction => &[("maxilla", Up, 4.0), ("mandible", Closing, 4.0)],
        Surgery::LeFortSetback => &[("maxilla", Back, 4.0)],
        Surgery::BssoAdvance => &[("mandible", Forward, 5.0)],
        Surgery::BssoSetback => &[("mandible", Back, 4.0)],
        Surgery::Genioplasty => &[("chin", Forward, 6.0)],
        Surgery::Bimaxillary => &[("mandible", Forward, 5.0), ("maxilla", Forward, 5.0)],
    }
}

/// One published row on one case.
#[derive(Clone, Debug)]
pub struct Row {
    pub case: String,
    pub published: &'static Published,
    /// The segment's move (mm).
    pub move_mm: f64,
    /// The soft displacement along the move (mm).
    pub along_mm: Option<f64>,
    /// The soft displacement along the head's forward and up axes (mm; single landmarks).
    pub forward_mm: Option<f64>,
    pub up_mm: Option<f64>,
    pub ratio: Option<f64>,
    /// Why there is no ratio, or what bears on it (a landmark near the tissue mesh's held faces).
    pub why: Option<String>,
}

impl Row {
    /// Inside the published range; None when not measured.
    pub fn inside(&self) -> Option<bool> {
        self.ratio.map(|r| self.published.contains(r))
    }
}

/// A case, or a surgery on it, not run, and why.
#[derive(Clone, Debug)]
pub struct Skip {
    pub case: String,
    pub surgery: Option<Surgery>,
    pub why: String,
}

/// How a case was set up: its head directions and segments.
#[derive(Clone, Debug)]
pub struct CaseInfo {
    pub name: String,
    pub about: String,
    pub pitch_deg: f64,
    pub forward: [f64; 3],
    pub up: [f64; 3],
    /// (segment, region as written in case.toml syntax, how it was placed).
    pub segments: Vec<(String, String, String)>,
    /// The mandible's autorotation (condylar pivot and lower incisal edge, how placed); None
    /// where the case has no mandible.
    pub autorotation: Option<Autorotation>,
    /// A phantom built in the skeletal class of the patients a surgery's ratios were measured
    /// on ([`class_of`]); None: a real CT, or a phantom as its seed drew it.
    pub class: Option<SkeletalClass>,
    pub seconds: f64,
}

/// The skeletal class a surgery corrects, and so the class of the patients the published
/// ratios were measured on: a mandibular setback and a maxillary advance treat Class III
/// (the mandible ahead of the maxilla), a mandibular advance and a maxillary setback Class II
/// (behind it). The phantoms of those surgeries are built in that class (their prognathism,
/// drawn from ±3 mm, given its sign); the impaction (vertical excess, either class), the
/// genioplasty and the bimaxillary advance run on the phantoms as drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SkeletalClass {
    II,
    III,
}

impl SkeletalClass {
    /// The phantom's prognathism (mm, `phantom_jaws::Shape` mandible_mm) in this class: the
    /// drawn size, with the class's sign.
    fn mandible_mm(self, drawn: f64) -> f64 {
        match self {
            SkeletalClass::II => -drawn.abs(),
            SkeletalClass::III => drawn.abs(),
        }
    }

    fn name(self) -> &'static str {
        match self {
            SkeletalClass::II => "Class II",
            SkeletalClass::III => "Class III",
        }
    }

    /// The phantom directory's suffix.
    fn key(self) -> &'static str {
        match self {
            SkeletalClass::II => "class-ii",
            SkeletalClass::III => "class-iii",
        }
    }

    fn mandible_relation(self) -> &'static str {
        match self {
            SkeletalClass::II => "behind the maxilla",
            SkeletalClass::III => "ahead of the maxilla",
        }
    }
}

/// The class of the patients a surgery's published ratios come from ([`SkeletalClass`]).
pub fn class_of(s: Surgery) -> Option<SkeletalClass> {
    match s {
        Surgery::LeFortAdvance | Surgery::BssoSetback => Some(SkeletalClass::III),
        Surgery::LeFortSetback | Surgery::BssoAdvance => Some(SkeletalClass::II),
        Surgery::LeFortImpaction | Surgery::Genioplasty | Surgery::Bimaxillary => None,
    }
}

/// Where the mandible turns in an impaction's autorotation (LPS mm).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Autorotation {
    /// On the condylar axis, in the midsagittal plane: the axis is the head's lateral one
    /// through it.
    pub pivot: [f64; 3],
    /// The lower incisal edge, whose rise the turn matches to the maxilla's.
    pub incisal: [f64; 3],
    pub placed: String,
}

pub struct Validation {
    pub rows: Vec<Row>,
    pub skipped: Vec<Skip>,
    pub cases: Vec<CaseInfo>,
    pub out_dir: PathBuf,
}

/// validation.toml beside a sample's case.toml (docs/validation.md, "What was compared"; the
/// output's validation.md lists each case under "The cases").
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CaseFile {
    about: String,
    /// The head's pitch in the CT (degrees, face down +): forward and up are the landmark
    /// frame's anterior and vertical turned by it about the frame's lateral axis.
    #[serde(default)]
    pitch_deg: f64,
    #[serde(default)]
    pitch_note: String,
    /// The skin that may move, when case.toml's leaves out what a surgery type moves (the nose).
    #[serde(default)]
    movable: Option<toml::Value>,
    #[serde(default)]
    movable_note: String,
    #[serde(default)]
    segments: BTreeMap<String, SegmentFile>,
    /// Segments this CT cannot have, and why.
    #[serde(default)]
    missing: BTreeMap<String, String>,
    /// The mandible's autorotation, required with a mandible segment.
    #[serde(default)]
    autorotation: Option<Autorotation>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentFile {
    region: toml::Value,
    placed: String,
}

/// A case ready to run: its directory, directions and segment regions.
struct Prepared {
    info: CaseInfo,
    dir: PathBuf,
    regions: BTreeMap<String, toml::Value>,
    missing: BTreeMap<String, String>,
    /// `[surface] movable` over case.toml's.
    movable: Option<toml::Value>,
}

/// An observer that names the case and surgery in front of each stage and leaves the display
/// to the caller's between runs.
struct Prefixed<'a> {
    inner: &'a dyn Observer,
    prefix: String,
}

impl Observer for Prefixed<'_> {
    fn started(&self, what: &str) {
        self.inner.started(&format!("{} {what}", self.prefix));
    }
    fn warn(&self, msg: &str) {
        self.inner.warn(&format!("{} {msg}", self.prefix));
    }
    fn heap(&self) -> Option<&dyn crate::meter::HeapProbe> {
        self.inner.heap()
    }
}

pub mod calibrate;

/// Called with each run's outcome before its files are pruned ([`calibrate`] reads the reduced
/// model the run stored); its error is the run's.
type OnRun<'a> = dyn FnMut(&CaseInfo, Surgery, &super::Outcome) -> Result<()> + 'a;

/// `facesim validate`.
pub fn validate(opts: &Options, obs: &dyn Observer) -> Result<Validation> {
    validate_with(opts, obs, &mut |_, _, _| Ok(()))
}

/// [`validate`], calling `on_run` with each run's outcome.
fn validate_with(opts: &Options, obs: &dyn Observer, on_run: &mut OnRun) -> Result<Validation> {
    if opts.phantoms > 0 && !(opts.phantom_spacing_mm >= 0.5 && opts.phantom_spacing_mm <= 4.0) {
        return Err(Error::config(format!(
            "validate: --phantom-spacing {} mm must be in [0.5, 4]",
            opts.phantom_spacing_mm
        )));
    }
    let surgeries: Vec<Surgery> = if opts.surgeries.is_empty() {
        Surgery::ALL.to_vec()
    } else {
        opts.surgeries.clone()
    };
    let wanted = |name: &str| opts.cases.is_empty() || opts.cases.iter().any(|c| c == name);
    let unit = crate::output::RunDir::create(&opts.out)?;
    let dir = unit.path().to_path_buf();
    let mut skipped = Vec::new();
    let mut todo: Vec<Todo> = Vec::new();
    for (name, case_dir) in samples(&opts.samples)? {
        if !wanted(&name) {
            continue;
        }
        match fetched(&case_dir) {
            Ok(()) => todo.push((name, case_dir, None, surgeries.clone())),
            Err(why) => skipped.push(Skip {
                case: name.clone(),
                surgery: None,
                why: format!(
                    "{why}; fetch it with {}",
                    opts.samples.join(format!("fetch-{name}.sh")).display()
                ),
            }),
        }
    }
    for c in &opts.cases {
        if c != "phantom"
            && !todo.iter().any(|t| &t.0 == c)
            && !skipped.iter().any(|s| &s.case == c)
        {
            return Err(Error::config(format!(
                "validate: no case '{c}' (the cases are the directories of {} with a validation.toml, and 'phantom')",
                opts.samples.display()
            )));
        }
    }
    if wanted("phantom") {
        for (k, (name, drawn)) in cohort(opts.phantoms, opts.seed).into_iter().enumerate() {
            for (class, shape, only) in in_classes(&drawn, &surgeries) {
                let dir_name = match class {
                    Some(c) if shape.values() != drawn.values() => {
                        format!("{name}-{}", c.key())
                    }
                    _ => name.clone(),
                };
                obs.started(&format!(
                    "writing phantom {} of {} ({dir_name})",
                    k + 1,
                    opts.phantoms
                ));
                let case_dir = dir.join("phantoms").join(&dir_name);
                let jaws = JawsOptions {
                    phantom: crate::phantom::PhantomOptions {
                        spacing: [opts.phantom_spacing_mm; 3],
                        ..Default::default()
                    },
                    solve_model: None,
                };
                let shape = Shape {
                    nasal_passages: opts.phantom_nasal_passages,
                    ..shape
                };
                crate::phantom_jaws::write_shaped_case(&case_dir, &jaws, &shape)?;
                todo.push((name.clone(), case_dir, Some((shape, class)), only));
            }
        }
    }
    let total_runs: usize = todo.iter().map(|t| t.3.len()).sum();
    let mut done = 0;
    let mut rows = Vec::new();
    let mut cases = Vec::new();
    for (name, case_dir, shape, surgeries) in todo {
        let started = std::time::Instant::now();
        let prefix = format!("[{}/{total_runs}] {name}:", done + 1);
        let frame = head_frame(
            &case_dir,
            &Prefixed {
                inner: obs,
                prefix: prefix.clone(),
            },
        )?;
        let mut case = match &shape {
            Some((s, class)) => phantom_case(&name, &case_dir, s, (*class, &surgeries), &frame),
            None => sample_case(&name, &case_dir, &frame)?,
        };
        for &s in &surgeries {
            done += 1;
            let prefix = format!("[{done}/{total_runs}] {name} {}:", s.key());
            if let Some((seg, why)) = moves(s)
                .iter()
                .filter(|(_, t, _)| *t != Toward::Closing)
                .find(|(seg, _, _)| !case.regions.contains_key(*seg))
                .map(|(seg, _, _)| {
                    let why =
                        case.missing.get(*seg).cloned().unwrap_or_else(|| {
                            "no such segment in the case's validation.toml".into()
                        });
                    (seg, why)
                })
            {
                skipped.push(Skip {
                    case: name.clone(),
                    surgery: Some(s),
                    why: format!("needs the {seg} segment: {why}"),
                });
                continue;
            }
            let run_dir = dir.join("runs").join(&name).join(s.key());
            let result = run_one(
                &case,
                s,
                &run_dir,
                &opts.overrides,
                opts.keep_runs,
                &Prefixed { inner: obs, prefix },
                on_run,
            );
            rows.extend(rows_of_run(&case.info, s, result));
        }
        case.info.seconds = started.elapsed().as_secs_f64();
        cases.push(case.info);
    }
    // A phantom's rows in the surgeries' order, whichever class each ran in (the sort is stable:
    // the rows of one run keep their order).
    let rank = |c: &str| cases.iter().position(|i| i.name == c).unwrap_or(usize::MAX);
    rows.sort_by_key(|r| {
        let s = Surgery::ALL.iter().position(|s| *s == r.published.surgery);
        (rank(&r.case), s)
    });
    // A failed run's message names its outputs under the temporary directory, which becomes
    // `opts.out` at the commit below: name them where they will be.
    let (tmp, out) = (dir.display().to_string(), opts.out.display().to_string());
    for r in &mut rows {
        if let Some(why) = &mut r.why {
            *why = why.replace(&tmp, &out);
        }
    }
    let v = Validation {
        rows,
        skipped,
        cases,
        out_dir: opts.out.clone(),
    };
    obs.started("writing validation.csv and validation.md");
    crate::output::write_bytes_atomic(&dir.join("validation.csv"), |w| {
        w.write_all(csv(&v).as_bytes())
    })?;
    crate::output::write_bytes_atomic(&dir.join("validation.md"), |w| {
        w.write_all(markdown(&v, opts).as_bytes())
    })?;
    let out_dir = unit.commit()?;
    obs.done();
    Ok(Validation { out_dir, ..v })
}

/// The sample directories holding a validation.toml, by name.
fn samples(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    if !dir.is_dir() {
        return Err(Error::input(dir, "samples directory not found"));
    }
    let mut out: Vec<(String, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| Error::input(dir, e))?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.join("validation.toml").is_file() && p.join("case.toml").is_file())
        .map(|p| {
            (
                p.file_name().unwrap_or_default().to_string_lossy().into(),
                p,
            )
        })
        .collect();
    out.sort();
    Ok(out)
}

/// Whether the CT a sample's case.toml names is there.
fn fetched(case_dir: &Path) -> std::result::Result<(), String> {
    let (case, _) = crate::case::Case::load(case_dir).map_err(|e| e.to_string())?;
    if case.ct.path.exists() {
        Ok(())
    } else {
        Err(format!("its CT {} is not fetched", case.ct.path.display()))
    }
}

/// The phantom cohort: soft tissue spread evenly over the cohort's −2..+4 mm, the other shape
/// parameters drawn from the seed (`phantom_cohort`).
fn cohort(n: usize, seed: u64) -> Vec<(String, Shape)> {
    (0..n)
        .map(|k| {
            let soft = if n == 1 {
                1.0
            } else {
                -2.0 + 6.0 * k as f64 / (n - 1) as f64
            };
            let soft = (soft * 100.0).round() / 100.0;
            let shape = crate::phantom_cohort::draw(
                crate::phantom_cohort::case_seed(seed, k),
                [None, Some(soft), None, None, None],
            );
            (format!("phantom{:02}", k + 1), shape)
        })
        .collect()
}

/// A validation entry: (case name, case directory, the phantom's shape and class, the surgeries
/// run on it).
type Todo = (
    String,
    PathBuf,
    Option<(Shape, Option<SkeletalClass>)>,
    Vec<Surgery>,
);

/// A drawn phantom in the classes `surgeries` need ([`class_of`]): one shape per distinct
/// prognathism, with its class (None: as drawn) and the surgeries run on it, in `surgeries`'
/// order. A class whose sign the draw already has is the drawn phantom itself.
fn in_classes(
    drawn: &Shape,
    surgeries: &[Surgery],
) -> Vec<(Option<SkeletalClass>, Shape, Vec<Surgery>)> {
    let mut out: Vec<(Option<SkeletalClass>, Shape, Vec<Surgery>)> = Vec::new();
    for &s in surgeries {
        let class = class_of(s);
        let mut v = drawn.values();
        if let Some(c) = class {
            v[2] = c.mandible_mm(v[2]);
        }
        match out.iter_mut().find(|(_, sh, _)| sh.values() == v) {
            Some((c, _, only)) => {
                *c = c.or(class);
                only.push(s);
            }
            None => out.push((class, Shape::from_values(v), vec![s])),
        }
    }
    out
}

/// The head frame of a case's pre-operative skin, as `facesim run`'s landmark stage finds it
/// (report.json `head_frame`): the stages up to the skin, no model.
fn head_frame(case_dir: &Path, obs: &dyn Observer) -> Result<HeadFrame> {
    let mut rec = Recorder::new(obs);
    let (inputs, files) = inputs::read_with(case_dir, &toml::Table::new(), &mut rec)?;
    let inputs::Inputs { case, ct, scan } = inputs;
    let seg = tissues(&ct, &case, &mut rec)?;
    let field = seg.bone_field(&ct);
    let surf = surfaces::extract(&ct, &seg, &field, &case, &mut rec)?;
    let face = crate::pipeline::face::place(surf, scan, &ct, &case, &mut rec)?;
    crate::landmarks::head_frame(&face.skin).ok_or_else(|| {
        Error::input(
            &files.case_file,
            "validate: no head frame (the skin is empty)",
        )
    })
}

/// Forward and up of the head: the frame's anterior and vertical turned face-down by `pitch`.
fn directions(frame: &HeadFrame, pitch_deg: f64) -> ([f64; 3], [f64; 3]) {
    let (s, c) = pitch_deg.to_radians().sin_cos();
    (
        add(scale(frame.anterior, c), scale(frame.vertical, -s)),
        add(scale(frame.vertical, c), scale(frame.anterior, s)),
    )
}

fn region_text(v: &toml::Value) -> String {
    v.to_string()
}

fn sample_case(name: &str, dir: &Path, frame: &HeadFrame) -> Result<Prepared> {
    let file = dir.join("validation.toml");
    let text = std::fs::read_to_string(&file).map_err(|e| Error::input(&file, e))?;
    let cf: CaseFile = toml::from_str(&text).map_err(|e| Error::input(&file, e.message()))?;
    if !cf.pitch_deg.is_finite() || cf.pitch_deg.abs() > 60.0 {
        return Err(Error::input(&file, "pitch_deg must be within ±60 degrees"));
    }
    for seg in cf.segments.keys() {
        if !["maxilla", "mandible", "chin"].contains(&seg.as_str()) {
            return Err(Error::input(
                &file,
                format!("segment '{seg}': the segments are maxilla, mandible and chin"),
            ));
        }
    }
    if cf.segments.contains_key("mandible") != cf.autorotation.is_some() {
        return Err(Error::input(
            &file,
            "a mandible segment needs [autorotation] (pivot, incisal, placed: where the mandible turns as it closes after an impaction), and [autorotation] a mandible",
        ));
    }
    let (forward, up) = directions(frame, cf.pitch_deg);
    let mut about = cf.about;
    if !cf.pitch_note.is_empty() {
        about = format!("{about} Pitch: {}", cf.pitch_note);
    }
    if let Some(m) = &cf.movable {
        about = format!(
            "{about} Movable skin: `{}` over case.toml's: {}",
            region_text(m),
            cf.movable_note
        );
    }
    Ok(Prepared {
        info: CaseInfo {
            name: name.into(),
            about,
            pitch_deg: cf.pitch_deg,
            forward,
            up,
            segments: cf
                .segments
                .iter()
                .map(|(k, s)| (k.clone(), region_text(&s.region), s.placed.clone()))
                .collect(),
            autorotation: cf.autorotation,
            class: None,
            seconds: 0.0,
        },
        dir: dir.to_path_buf(),
        regions: cf
            .segments
            .into_iter()
            .map(|(k, s)| (k, s.region))
            .collect(),
        missing: cf.missing,
        movable: cf.movable,
    })
}

/// The standard head's genioplasty level (mm): below the lower vestibule's sulcus (z −45) and
/// the B-point dip (−42), above the bony pogonion (−55); the phantom's teeth have no roots.
const PHANTOM_CHIN_CUT_Z: f64 = -48.0;

fn box_value(b: [[f64; 3]; 2]) -> toml::Value {
    let arr = |p: [f64; 3]| {
        toml::Value::Array(
            p.iter()
                .map(|x| toml::Value::Float((x * 10.0).round() / 10.0))
                .collect(),
        )
    };
    let mut inner = toml::Table::new();
    inner.insert("min".into(), arr(b[0]));
    inner.insert("max".into(), arr(b[1]));
    let mut t = toml::Table::new();
    t.insert("box".into(), toml::Value::Table(inner));
    toml::Value::Table(t)
}

fn phantom_case(
    name: &str,
    dir: &Path,
    shape: &Shape,
    (class, runs): (Option<SkeletalClass>, &[Surgery]),
    frame: &HeadFrame,
) -> Prepared {
    let [front, _back, maxilla] = shape.boxes();
    let mut chin = front;
    chin[1][2] = PHANTOM_CHIN_CUT_Z * shape.scale;
    let segs = [
        (
            "maxilla",
            maxilla,
            "the phantom's maxilla box (Shape::boxes): the occlusal plane to the Le Fort I gap, in front of the rami",
        ),
        (
            "mandible",
            front,
            "the distal segment of a sagittal split: the phantom's mandible-front box (Shape::boxes), below the occlusal plane in front of the rami; the rami stay",
        ),
        (
            "chin",
            chin,
            "the mandible-front box below z = −48 mm (scaled): under the lower sulcus and the B-point dip, above pogonion",
        ),
    ];
    let (forward, up) = directions(frame, 0.0);
    let v = shape.values();
    // The phantom case's movable sphere (centre (0, −30, −35) mm, radius 85 mm, scaled) has the
    // nose tip on its edge; 10 mm more takes it in, as the Le Fort I types need.
    let centre = [0.0, -30.0 * shape.scale, -35.0 * shape.scale];
    let radius = 95.0 * shape.scale;
    let movable: toml::Value = toml::from_str::<toml::Table>(&format!(
        "v = {{ sphere = {{ center = [{:.1}, {:.1}, {:.1}], radius = {radius:.1} }} }}",
        centre[0], centre[1], centre[2]
    ))
    .ok()
    .and_then(|mut t| t.remove("v"))
    .unwrap_or(toml::Value::Boolean(false));
    Prepared {
        info: CaseInfo {
            name: name.into(),
            about: format!(
                "{}jaws phantom (scale {}, soft tissue {:+} mm, mandible {:+} mm, chin {:+} mm, midline {:+} mm; {}); built upright, pitch 0. Movable skin: `{}` (the case's sphere, 10 mm larger to take in the nose tip).",
                match class {
                    Some(c) => {
                        let of: Vec<&str> = runs
                            .iter()
                            .filter(|s| class_of(**s) == Some(c))
                            .map(|s| s.key())
                            .collect();
                        format!(
                            "{} (the mandible {}), the class of the patients of {}: ",
                            c.name(),
                            c.mandible_relation(),
                            of.join(" and ")
                        )
                    }
                    None => String::new(),
                },
                v[0],
                v[1],
                v[2],
                v[3],
                v[4],
                if shape.nasal_passages {
                    "a hollow nose: two nasal passages beside a septum"
                } else {
                    "a solid nose"
                },
                region_text(&movable)
            ),
            pitch_deg: 0.0,
            forward,
            up,
            segments: segs
                .iter()
                .map(|(n, b, how)| (n.to_string(), region_text(&box_value(*b)), how.to_string()))
                .collect(),
            autorotation: Some(Autorotation {
                pivot: shape.condylar_pivot(),
                incisal: shape.landmark("lower incisor tip").unwrap_or(front[1]),
                placed: "the phantom's condylar pivot (midway between the condyle centres) and its lower incisor's incisal edge".into(),
            }),
            class,
            seconds: 0.0,
        },
        dir: dir.to_path_buf(),
        regions: segs
            .iter()
            .map(|(n, b, _)| (n.to_string(), box_value(*b)))
            .collect(),
        missing: BTreeMap::new(),
        movable: Some(movable),
    }
}

/// The unit vector of a move toward `t` (a closing turn's: up, where its incisal edge goes).
fn unit_of(info: &CaseInfo, t: Toward) -> [f64; 3] {
    match t {
        Toward::Forward => info.forward,
        Toward::Back => scale(info.forward, -1.0),
        Toward::Up | Toward::Closing => info.up,
    }
}

/// The plan's angles (degrees, `osteotomy::rotation`'s order) of a turn by `angle_rad` (|θ| ≤ π)
/// about the unit `axis`, right-handed: the versor (unit quaternion) axis · sin(θ/2), as an ITK
/// transform file gives it.
fn rotate_deg_about(axis: [f64; 3], angle_rad: f64) -> Result<[f64; 3]> {
    use crate::slicer::itk_transform::{euler_xyz_deg, versor};
    let [x, y, z] = scale(axis, (0.5 * angle_rad).sin());
    Ok(euler_xyz_deg(versor(x, y, z).map_err(Error::config)?))
}

/// The plan's `rotate_deg` of the autorotation that raises the incisal edge by `rise_mm` along
/// up: a turn θ about the lateral axis f × u through the pivot (which turns forward into up) moves
/// an edge a mm in front of the pivot and b mm below it up by a sin θ + b (1 − cos θ).
fn closing_turn(info: &CaseInfo, a: &Autorotation, rise_mm: f64) -> Result<[f64; 3]> {
    let d = crate::vec3::sub(a.incisal, a.pivot);
    let (front, below) = (
        crate::vec3::dot(d, info.forward),
        -crate::vec3::dot(d, info.up),
    );
    if front < 20.0 {
        return Err(Error::config(format!(
            "validate: case {}: the autorotation's incisal edge lies {front:.1} mm in front of its pivot (the condyles lie 80-100 mm behind the incisors)",
            info.name
        )));
    }
    // a sin θ − b cos θ = rise − b, i.e. h sin(θ − φ) with h = √(a² + b²), φ = atan2(b, a).
    let h = front.hypot(below);
    let theta = below.atan2(front) + ((rise_mm - below) / h).clamp(-1.0, 1.0).asin();
    let lateral = crate::vec3::cross(info.forward, info.up);
    let lateral = scale(lateral, 1.0 / crate::vec3::norm(lateral));
    rotate_deg_about(lateral, theta)
}

/// One surgery on one case through `facesim run`'s library call, with the product's defaults
/// except the discretisation-error estimate (a second solve at twice the element size that
/// reports, and does not change, the face). Returns the carried landmarks.
fn run_one(
    case: &Prepared,
    s: Surgery,
    run_dir: &Path,
    overrides: &toml::Table,
    keep_runs: bool,
    obs: &dyn Observer,
    on_run: &mut OnRun,
) -> Result<RunLandmarks> {
    let mut osteotomies = Vec::new();
    let floats =
        |v: [f64; 3]| toml::Value::Array(v.iter().map(|x| toml::Value::Float(*x)).collect());
    for (seg, toward, mm) in moves(s) {
        let Some(region) = case.regions.get(*seg) else {
            continue; // an autorotation where the CT has no mandible (the skip check holds the rest)
        };
        let mut o = toml::Table::new();
        o.insert("name".into(), toml::Value::String(seg.to_string()));
        o.insert("region".into(), region.clone());
        match (toward, &case.info.autorotation) {
            (Toward::Closing, Some(a)) => {
                let deg = closing_turn(&case.info, a, *mm)?;
                o.insert("rotate_deg".into(), floats(deg));
                o.insert("pivot".into(), floats(a.pivot));
            }
            (Toward::Closing, None) => continue,
            _ => {
                o.insert(
                    "translate".into(),
                    floats(scale(unit_of(&case.info, *toward), *mm)),
                );
            }
        }
        osteotomies.push(toml::Value::Table(o));
    }
    let mut over = toml::Table::new();
    over.insert(
        "name".into(),
        toml::Value::String(format!("validate-{}-{}", case.info.name, s.key())),
    );
    over.insert("osteotomy".into(), toml::Value::Array(osteotomies));
    if let Some(m) = &case.movable {
        let mut surface = toml::Table::new();
        surface.insert("movable".into(), m.clone());
        over.insert("surface".into(), toml::Value::Table(surface));
    }
    let mut tet = toml::Table::new();
    tet.insert("error_estimate".into(), toml::Value::Boolean(false));
    over.insert("tet".into(), toml::Value::Table(tet));
    crate::case::merge(&mut over, overrides.clone());
    let outcome = super::run_with(&case.dir, Some(run_dir), &over, obs)?;
    on_run(&case.info, s, &outcome)?;
    if !keep_runs {
        prune(&outcome.out_dir);
    }
    let face_region = outcome.report.tet.as_ref().map(|t| t.region);
    Ok(RunLandmarks {
        carried: outcome
            .report
            .landmarks
            .0
            .into_iter()
            .map(|(_, c)| c)
            .collect(),
        face_region,
    })
}

/// What a run tells about its landmarks: where they went, and the face region (report.json
/// `tet.region`: the moved bone's box grown by `[tet] margin_mm`; the face beyond it is not
/// carried by the tissue mesh, which reaches `margin_mm` further to its held faces).
struct RunLandmarks {
    carried: Vec<Carried>,
    face_region: Option<([f64; 3], [f64; 3])>,
}

/// A landmark nearer than this to the face region's edge is noted: the face beyond the edge
/// stays, so the edge, not the tissue, may set its move.
const NEAR_REGION_EDGE_MM: f64 = 10.0;

/// Distance (mm) from p inside the box to its nearest face; negative outside.
fn depth_in(b: &([f64; 3], [f64; 3]), p: [f64; 3]) -> f64 {
    (0..3)
        .map(|a| (p[a] - b.0[a]).min(b.1[a] - p[a]))
        .fold(f64::INFINITY, f64::min)
}

/// The files of a run kept under runs/: its report, landmarks and faces (the rest, ~35 MB a run,
/// `facesim run` on the same case and plan writes again).
const KEPT: [&str; 5] = [
    "report.json",
    "landmarks_pre.mrk.json",
    "landmarks_post.mrk.json",
    "face_pre.ply",
    "face_post.ply",
];

fn prune(dir: &Path) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let keep = KEPT.iter().any(|k| e.file_name() == *k);
            if !keep && e.path().is_file() {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// The published rows of a surgery measured on a run (or each saying why not).
fn rows_of_run(info: &CaseInfo, s: Surgery, run: Result<RunLandmarks>) -> Vec<Row> {
    crate::landmarks::published::rows_of(s)
        .map(|p| {
            let (_, toward, mm) = moves(s)
                .iter()
                .find(|(seg, _, _)| *seg == p.segment)
                .copied()
                .unwrap_or(("", Toward::Forward, f64::NAN));
            let mut row = Row {
                case: info.name.clone(),
                published: p,
                move_mm: mm,
                along_mm: None,
                forward_mm: None,
                up_mm: None,
                ratio: None,
                why: None,
            };
            if let Some(u) = p.unmeasured {
                row.why = Some(u.to_string());
                return row;
            }
            let (carried, face_region) = match &run {
                Ok(r) => (&r.carried, r.face_region),
                Err(e) => {
                    row.why = Some(format!("the run failed: {e}"));
                    return row;
                }
            };
            // A landmark held still by construction (rigid skin, no tissue mesh under it) has
            // no predicted ratio: say so rather than report 0.
            let still = p.terms.iter().find(|(label, _)| {
                carried
                    .iter()
                    .any(|c| c.label == *label && c.change_mm.is_some_and(|d| d < 1e-6))
            });
            let depth = |label: &str| -> Option<f64> {
                let p = carried.iter().find(|c| c.label == label)?.pre?;
                Some(depth_in(face_region.as_ref()?, p))
            };
            if let Some((label, _)) = still {
                row.why = Some(match depth(label) {
                    Some(d) if d < 0.0 => format!(
                        "{label} did not move: it lies {:.1} mm outside the face region (the moved bone's box grown by [tet] margin_mm; report.json tet.region), whose face stays",
                        -d
                    ),
                    _ => format!(
                        "{label} did not move (< 1e-6 mm): the model holds the skin there still (rigid skin outside [surface] movable)"
                    ),
                });
                return row;
            }
            let near: Vec<String> = p
                .terms
                .iter()
                .filter_map(|(label, _)| {
                    let d = depth(label)?;
                    (d < NEAR_REGION_EDGE_MM).then(|| {
                        format!("{label} is {d:.1} mm from the face region's edge (report.json tet.region), beyond which the face stays")
                    })
                })
                .collect();
            if !near.is_empty() {
                row.why = Some(near.join("; "));
            }
            // A width (lateral row) across the face, over the move; else along the move.
            let soft_dir = match p.axis {
                crate::landmarks::published::Axis::Lateral => {
                    let l = crate::vec3::cross(info.up, info.forward);
                    scale(l, 1.0 / crate::vec3::norm(l))
                }
                _ => unit_of(info, toward),
            };
            match along(carried, p.terms, soft_dir) {
                Ok(d) => {
                    row.along_mm = Some(d);
                    row.ratio = Some(d / mm);
                    row.forward_mm = along(carried, p.terms, info.forward).ok();
                    row.up_mm = along(carried, p.terms, info.up).ok();
                }
                Err(why) => row.why = Some(why),
            }
            row
        })
        .map(|mut row| {
            let closes = moves(s).iter().any(|(_, t, _)| *t == Toward::Closing);
            if closes && info.autorotation.is_none() {
                let note = "no mandible in this CT: the maxilla moved alone, without the autorotation";
                row.why = Some(match row.why.take() {
                    Some(w) => format!("{w}; {note}"),
                    None => note.into(),
                });
            }
            row
        })
        .collect()
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn num(x: Option<f64>, digits: usize) -> String {
    x.map(|v| format!("{v:.digits$}")).unwrap_or_default()
}

/// validation.csv: one row per case, surgery and published row.
pub fn csv(v: &Validation) -> String {
    let mut s = String::from(
        "case,surgery,landmark,hard_reference,segment,axis,move_mm,soft_along_mm,soft_forward_mm,soft_up_mm,predicted_ratio,published_low,published_high,inside,range_note,source,note\n",
    );
    for r in &v.rows {
        let p = r.published;
        let inside = match r.inside() {
            Some(true) => "yes",
            Some(false) => "no",
            None => "",
        };
        let fields = [
            r.case.clone(),
            p.surgery.key().into(),
            p.soft.into(),
            p.hard.into(),
            p.segment.into(),
            p.axis.name().into(),
            format!("{}", r.move_mm),
            num(r.along_mm, 3),
            num(r.forward_mm, 3),
            num(r.up_mm, 3),
            num(r.ratio, 3),
            format!("{}", p.low),
            format!("{}", p.high),
            inside.into(),
            p.range_note.into(),
            p.source.into(),
            r.why.clone().unwrap_or_default(),
        ];
        let line: Vec<String> = fields.iter().map(|f| csv_field(f)).collect();
        s.push_str(&line.join(","));
        s.push('\n');
    }
    s
}

/// This machine, for validation.md's header: the CPU model and the cores.
fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, m)| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!(
        "{cpu}, {cores} cores available, {} {}",
        std::env::consts::OS,
        std::env::consts::ARCH
    )
}

fn v3(a: [f64; 3]) -> String {
    format!("({:.3}, {:.3}, {:.3})", a[0], a[1], a[2])
}

/// validation.md: the header, the moves, the cases, then per surgery the table.
pub fn markdown(v: &Validation, opts: &Options) -> String {
    let mut s = String::from(
        "# facesim validate: predicted soft/hard ratios against the published ranges\n\n",
    );
    s.push_str(&format!(
        "- command: `{}`\n- facesim {}\n- machine: {}\n- time: {:.0} s\n\n",
        opts.command,
        env!("CARGO_PKG_VERSION"),
        machine(),
        v.cases.iter().map(|c| c.seconds).sum::<f64>()
    ));
    if !opts.overrides.is_empty() {
        s.push_str(&format!(
            "**Not the product's defaults**: every run with `{}` laid over its case.

",
            toml::to_string(&opts.overrides)
                .unwrap_or_default()
                .trim()
                .replace('\n', "; ")
        ));
    }
    let (inside, outside, none) = v
        .rows
        .iter()
        .fold((0, 0, 0), |(a, b, c), r| match r.inside() {
            Some(true) => (a + 1, b, c),
            Some(false) => (a, b + 1, c),
            None => (a, b, c + 1),
        });
    s.push_str(&format!(
        "**{inside} inside their published range, {outside} outside, {none} not measured** (each below, with why).\n\n"
    ));
    s.push_str("Ratio = the soft landmark's displacement along the bone's move ÷ the move (a pure translation moves every bone point by the plan's translation). Every run uses the product's defaults except `[tet] error_estimate = false` (the estimate solves again at twice the element size and reports, without changing, the face). Forward and up are the head's (below, per case).\n\n## The moves\n\n| surgery | segments moved |\n|---|---|\n");
    for srg in Surgery::ALL {
        let m: Vec<String> = moves(srg)
            .iter()
            .map(|(seg, t, mm)| match t {
                Toward::Closing => format!(
                    "{seg} turned about the condyles until its incisal edge has risen {mm} mm (autorotation; where the CT has a mandible)"
                ),
                _ => format!("{seg} {mm} mm {}", format!("{t:?}").to_lowercase()),
            })
            .collect();
        s.push_str(&format!("| {} | {} |\n", srg.title(), m.join(", then ")));
    }
    s.push_str("\n## The cases\n\n");
    for c in &v.cases {
        s.push_str(&format!(
            "### {}{}\n\n{}\n\n- forward {} and up {} (LPS; pitch {}°); {:.0} s\n",
            c.name,
            c.class
                .map_or(String::new(), |k| format!(" ({})", k.name())),
            c.about,
            v3(c.forward),
            v3(c.up),
            c.pitch_deg,
            c.seconds
        ));
        for (seg, region, how) in &c.segments {
            s.push_str(&format!("- {seg}: `{region}`: {how}\n"));
        }
        if let Some(a) = &c.autorotation {
            s.push_str(&format!(
                "- autorotation: pivot {}, lower incisal edge {}: {}\n",
                v3(a.pivot),
                v3(a.incisal),
                a.placed
            ));
        }
        s.push('\n');
    }
    if !v.skipped.is_empty() {
        s.push_str("## Not run\n\n");
        for k in &v.skipped {
            let what = k
                .surgery
                .map(|x| format!("{} ", x.title()))
                .unwrap_or_default();
            s.push_str(&format!("- {} {what}: {}\n", k.case, k.why));
        }
        s.push('\n');
    }
    for srg in Surgery::ALL {
        let rows: Vec<&Row> = v
            .rows
            .iter()
            .filter(|r| r.published.surgery == srg)
            .collect();
        if rows.is_empty() {
            continue;
        }
        s.push_str(&format!(
            "## {}\n\n| case | soft (hard ref.) | axis | predicted | published | | soft fwd / up mm | note |\n|---|---|---|---|---|---|---|---|\n",
            srg.title()
        ));
        for r in rows {
            let p = r.published;
            let verdict = match r.inside() {
                Some(true) => "inside",
                Some(false) => "**OUTSIDE**",
                None => "not measured",
            };
            let fwd_up = match (r.forward_mm, r.up_mm) {
                (Some(f), Some(u)) => format!("{f:+.2} / {u:+.2}"),
                _ => String::new(),
            };
            let mut note = r.why.clone().unwrap_or_default();
            if !p.range_note.is_empty() {
                if !note.is_empty() {
                    note.push_str("; ");
                }
                note.push_str("range: ");
                note.push_str(p.range_note);
            }
            s.push_str(&format!(
                "| {} | {} ({}) | {} | {} | {}–{} | {verdict} | {fwd_up} | {} |\n",
                r.case,
                p.soft,
                p.hard,
                p.axis.name(),
                num(r.ratio, 2),
                p.low,
                p.high,
                note.replace('|', "/")
            ));
        }
        s.push('\n');
    }
    s.push_str("## Sources\n\n");
    for p in &PUBLISHED {
        s.push_str(&format!(
            "- {} {} ({}): {}–{}: {}\n",
            p.surgery.title(),
            p.soft,
            p.hard,
            p.low,
            p.high,
            p.source
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vec3::dot;

    fn row(p: &'static Published, ratio: Option<f64>) -> Row {
        Row {
            case: "c".into(),
            published: p,
            move_mm: 5.0,
            along_mm: ratio.map(|r| r * 5.0),
            forward_mm: None,
            up_mm: None,
            ratio,
            why: ratio.is_none().then(|| "Me' not found: no skin".into()),
        }
    }

    #[test]
    fn a_ratio_outside_its_range_is_flagged_in_the_table_and_the_page() {
        let pog = PUBLISHED
            .iter()
            .find(|p| p.surgery == Surgery::BssoAdvance && p.soft == "Pog'")
            .unwrap();
        let v = Validation {
            rows: vec![row(pog, Some(1.5)), row(pog, Some(1.0)), row(pog, None)],
            skipped: vec![],
            cases: vec![],
            out_dir: PathBuf::new(),
        };
        assert_eq!(
            v.rows.iter().map(Row::inside).collect::<Vec<_>>(),
            [Some(false), Some(true), None]
        );
        let table = csv(&v);
        let lines: Vec<&str> = table.lines().collect();
        assert!(lines[1].contains(",1.500,0.8,1.33,no,"), "{}", lines[1]);
        assert!(lines[2].contains(",1.000,0.8,1.33,yes,"), "{}", lines[2]);
        assert!(lines[3].ends_with("Me' not found: no skin"), "{}", lines[3]);
        let opts = Options {
            out: PathBuf::new(),
            samples: PathBuf::new(),
            phantoms: 0,
            seed: 1,
            phantom_spacing_mm: 2.0,
            phantom_nasal_passages: true,
            surgeries: vec![],
            cases: vec![],
            overrides: toml::Table::new(),
            keep_runs: false,
            command: "facesim validate".into(),
        };
        let md = markdown(&v, &opts);
        assert!(md.contains("| 1.50 | 0.8–1.33 | **OUTSIDE** |"), "{md}");
        assert!(md.contains("1 inside their published range, 1 outside, 1 not measured"));
    }

    /// Each advance's partner setback treats the other class, and a drawn phantom is built in
    /// each class its surgeries need: the drawn prognathism's size with the class's sign, one
    /// phantom per distinct shape, the drawn one itself where its sign is the class's.
    #[test]
    fn each_surgery_runs_on_a_phantom_of_its_patients_class() {
        use SkeletalClass::*;
        assert_eq!(class_of(Surgery::BssoAdvance), Some(II));
        assert_eq!(class_of(Surgery::BssoSetback), Some(III));
        assert_eq!(class_of(Surgery::LeFortAdvance), Some(III));
        assert_eq!(class_of(Surgery::LeFortSetback), Some(II));
        assert_eq!(class_of(Surgery::LeFortImpaction), None);
        for drawn_mm in [-2.5, 1.75] {
            let mut v = crate::phantom_jaws::Shape::default().values();
            v[2] = drawn_mm;
            let drawn = Shape::from_values(v);
            let built = in_classes(&drawn, &Surgery::ALL);
            assert_eq!(built.len(), 2, "{drawn_mm}");
            let mut all: Vec<Surgery> = built.iter().flat_map(|b| b.2.clone()).collect();
            all.sort_by_key(|s| s.key());
            let mut want = Surgery::ALL.to_vec();
            want.sort_by_key(|s| s.key());
            assert_eq!(all, want, "every surgery runs once");
            for (class, shape, only) in &built {
                let mandible = shape.values()[2];
                assert_eq!(mandible.abs(), drawn_mm.abs());
                // The other parameters are the draw's.
                for k in [0, 1, 3, 4] {
                    assert_eq!(shape.values()[k], v[k]);
                }
                for s in only {
                    match class_of(*s) {
                        Some(II) => assert!(mandible < 0.0, "{s:?} on {mandible}"),
                        Some(III) => assert!(mandible > 0.0, "{s:?} on {mandible}"),
                        // As drawn.
                        None => assert_eq!(mandible, drawn_mm, "{s:?}"),
                    }
                }
                assert_eq!(
                    *class,
                    Some(if mandible > 0.0 { III } else { II }),
                    "the phantom is labelled with its class"
                );
            }
        }
    }

    #[test]
    fn the_pitch_turns_forward_down_and_keeps_the_axes_orthonormal() {
        let f = HeadFrame::from_plane([0.0; 3], [1.0, 0.0, 0.0], 0.0);
        let (fwd, up) = directions(&f, 16.0);
        assert!((dot(fwd, fwd) - 1.0).abs() < 1e-12 && (dot(up, up) - 1.0).abs() < 1e-12);
        assert!(dot(fwd, up).abs() < 1e-12);
        // Face down: forward points anterior (−y) and down (−z).
        assert!(fwd[1] < -0.95 && (fwd[2] + 16f64.to_radians().sin()).abs() < 1e-12);
        assert_eq!(directions(&f, 0.0), (f.anterior, f.vertical));
    }

    #[test]
    fn a_turn_about_an_oblique_axis_keeps_the_axis_and_turns_a_normal_by_the_angle() {
        let n = 3f64.sqrt();
        let axis = [1.0 / n, -1.0 / n, 1.0 / n];
        let angle = 0.7f64;
        let r = crate::osteotomy::rotation(rotate_deg_about(axis, angle).unwrap());
        let apply = |v: [f64; 3]| [0, 1, 2].map(|a| (0..3).map(|k| r[a][k] * v[k]).sum::<f64>());
        let a = apply(axis);
        assert!((0..3).all(|i| (a[i] - axis[i]).abs() < 1e-12), "{a:?}");
        // A unit vector normal to the axis turns by the angle, right-handed: v × Rv ∥ +axis.
        let v = [1.0 / 2f64.sqrt(), 1.0 / 2f64.sqrt(), 0.0];
        let w = apply(v);
        let dot: f64 = (0..3).map(|i| v[i] * w[i]).sum();
        assert!((dot - angle.cos()).abs() < 1e-12, "{dot}");
        let cross = crate::vec3::cross(v, w);
        let along: f64 = (0..3).map(|i| cross[i] * axis[i]).sum();
        assert!((along - angle.sin()).abs() < 1e-12, "{along}");
    }

    #[test]
    fn the_closing_turn_raises_the_incisal_edge_by_the_impaction_about_the_condyles() {
        let f = HeadFrame::from_plane([0.0; 3], [1.0, 0.0, 0.0], 0.0);
        let (forward, up) = directions(&f, 16.0);
        let info = CaseInfo {
            name: "t".into(),
            about: String::new(),
            pitch_deg: 16.0,
            forward,
            up,
            segments: Vec::new(),
            autorotation: None,
            class: None,
            seconds: 0.0,
        };
        // headsq's pivot and incisal edge.
        let a = Autorotation {
            pivot: [108.0, -96.0, -42.0],
            incisal: [97.6, -154.0, -103.5],
            placed: String::new(),
        };
        let r = crate::osteotomy::rotation(closing_turn(&info, &a, 4.0).unwrap());
        let turned = |p: [f64; 3]| {
            let d = crate::vec3::sub(p, a.pivot);
            let rd = [0, 1, 2].map(|i| (0..3).map(|k| r[i][k] * d[k]).sum::<f64>());
            crate::vec3::add(rd, a.pivot)
        };
        let moved = crate::vec3::sub(turned(a.incisal), a.incisal);
        assert!((dot(moved, up) - 4.0).abs() < 1e-9, "{moved:?}");
        // About the lateral axis: nothing moves sideways, the pivot stays, and the chin comes
        // forward as it closes.
        let lateral = crate::vec3::cross(forward, up);
        assert!(dot(moved, lateral).abs() < 1e-9);
        assert!(crate::vec3::norm(crate::vec3::sub(turned(a.pivot), a.pivot)) < 1e-12);
        assert!(dot(moved, forward) > 0.5);
        // An edge behind its pivot is refused.
        let behind = Autorotation {
            incisal: a.pivot,
            ..a
        };
        assert!(closing_turn(&info, &behind, 4.0).is_err());
    }

    #[test]
    fn the_cohort_spans_thin_to_thick_soft_tissue() {
        let c = cohort(4, 1);
        let soft: Vec<f64> = c.iter().map(|(_, s)| s.soft_mm).collect();
        assert_eq!(soft, [-2.0, 0.0, 2.0, 4.0]);
        assert!(c.iter().all(|(_, s)| s.validate().is_ok()));
        assert_ne!(c[0].1.scale, c[1].1.scale);
    }
}

//! `facesim validate` (docs/guide/validation.md): every surgery type of the published table
//! (`landmarks::published`) run with the product's defaults on every real sample that has the
//! bone and on a seeded cohort of jaws phantoms; per soft landmark the predicted ratio beside the
//! published range. Writes validation.csv and validation.md as one unit (`output::RunDir`), with
//! each run's report.json, landmarks and faces under `runs/`; the chart (validation.svg) is the
//! caller's (crates/facesim-charts `validation.rs`).

use crate::phantom_jaws::{JawsOptions, Shape};
use facesim::anatomy::Anatomy;
use facesim::error::{Error, Result};
use facesim::landmarks::Carried;
use facesim::landmarks::clinic::ClinicRow;
use facesim::landmarks::measure::along;
use facesim::landmarks::published::{PUBLISHED, Published, Surgery, Verdict};
use facesim::observe::Observer;
use facesim::pipeline::{Recorder, inputs, surfaces, tissues};
use facesim::vec3::scale;
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
    /// Jaws phantoms in the cohort (a Latin hypercube in soft tissue and vertical pattern; `cohort`).
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
    /// Each ratio's band: the tissue parameters sampled this many times over the
    /// `[uncertainty]` box (the reduced model from 64 on), and the ratio on the mesh of twice
    /// the element size (`[tet] error_estimate`). 0: the ratio alone.
    pub band_samples: usize,
    /// The impaction's autorotation where the CT allows it (false: the maxilla moves alone; for
    /// judging the mechanism by the protocol's rule).
    pub autorotation: bool,
    /// The command line, for validation.md's header.
    pub command: String,
}

/// The moves, in the head's directions: advance and setback along its forward axis, impaction
/// along its up axis. Sizes are those of common plans (docs/guide/validation.md, "What was compared").
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
    /// The ratio's 5th and 95th percentiles over the sampled tissue parameters.
    pub tissue_band: Option<[f64; 2]>,
    /// The ratio on the mesh of twice the element size.
    pub coarse_mesh: Option<f64>,
    /// The band: the smallest interval holding the tissue band, the ratio and the coarse mesh's
    /// (report.json `published_ratios` `band`).
    pub band: Option<[f64; 2]>,
    /// Why there is no ratio, or what bears on it (a landmark near the tissue mesh's held faces).
    pub why: Option<String>,
}

impl Row {
    /// Inside the published range; None when not measured.
    pub fn inside(&self) -> Option<bool> {
        self.ratio.map(|r| self.published.contains(r))
    }

    /// The band against the range (docs/guide/validation.md "The protocol"); without a band, the
    /// ratio alone read as a band of no width. None when not measured.
    pub fn verdict(&self) -> Option<Verdict> {
        let r = self.ratio?;
        let [lo, hi] = self.band.unwrap_or([r, r]);
        Some(self.published.verdict(lo, hi))
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
    /// How the clinical frame was found (report.json `clinical_frame.why`).
    pub frame_why: String,
    /// (segment, the cut, its bone or why the CT cannot have it), as `[[surgery]]` finds them.
    pub segments: Vec<(String, String, String)>,
    /// The mandible's autorotation about the condyles found from the CT; None where the CT
    /// has no mandible (why).
    pub autorotation: std::result::Result<(), String>,
    /// A phantom built in the skeletal class of the patients a surgery's ratios were measured
    /// on ([`class_of`]); None: a real CT, or a phantom as its seed drew it.
    pub class: Option<SkeletalClass>,
    /// A real CT from the samples (each one independent source of evidence); false: a phantom.
    pub real_ct: bool,
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

pub struct Validation {
    pub rows: Vec<Row>,
    pub skipped: Vec<Skip>,
    pub cases: Vec<CaseInfo>,
    pub out_dir: PathBuf,
}

/// validation.toml beside a sample's case.toml (docs/guide/validation.md, "What was compared"; the
/// output's validation.md lists each case under "The cases").
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CaseFile {
    about: String,
    /// The skin that may move, when case.toml's leaves out what a surgery type moves (the nose).
    #[serde(default)]
    movable: Option<toml::Value>,
    #[serde(default)]
    movable_note: String,
}

/// A case ready to run: its directory, directions and which segments its CT can have.
struct Prepared {
    info: CaseInfo,
    dir: PathBuf,
    /// Per segment (maxilla, mandible, chin): Ok, or why the CT cannot have it.
    possible: Possible,
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
    fn heap(&self) -> Option<&dyn facesim::meter::HeapProbe> {
        self.inner.heap()
    }
}

pub mod calibrate;

/// Called with each run's outcome before its files are pruned ([`calibrate`] reads the reduced
/// model the run stored); its error is the run's.
type OnRun<'a> = dyn FnMut(&CaseInfo, Surgery, &facesim::commands::Outcome) -> Result<()> + 'a;

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
    let unit = facesim::output::RunDir::create(&opts.out)?;
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
        let anatomy = anatomy_of(
            &case_dir,
            &Prefixed {
                inner: obs,
                prefix: prefix.clone(),
            },
        )?;
        let mut case = match &shape {
            Some((s, class)) => phantom_case(&name, &case_dir, s, (*class, &surgeries), &anatomy),
            None => sample_case(&name, &case_dir, &anatomy)?,
        };
        if !opts.autorotation {
            case.info.autorotation = Err("off (--no-autorotation)".into());
        }
        for &s in &surgeries {
            done += 1;
            let prefix = format!("[{done}/{total_runs}] {name} {}:", s.key());
            if let Some((seg, why)) = moves(s)
                .iter()
                .filter(|(_, t, _)| *t != Toward::Closing)
                .find_map(|(seg, _, _)| match case.possible.get(*seg) {
                    Some(Ok(())) => None,
                    Some(Err(why)) => Some((seg, why.clone())),
                    None => Some((seg, "no such segment".to_string())),
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
                opts,
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
    facesim::output::write_bytes_atomic(&dir.join("validation.csv"), |w| {
        w.write_all(csv(&v).as_bytes())
    })?;
    facesim::output::write_bytes_atomic(&dir.join("validation.md"), |w| {
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
    let (case, _) = facesim::case::Case::load(case_dir).map_err(|e| e.to_string())?;
    if case.ct.path.exists() {
        Ok(())
    } else {
        Err(format!("its CT {} is not fetched", case.ct.path.display()))
    }
}

/// The phantom cohort, a Latin hypercube in soft-tissue thickness and vertical pattern: each
/// of the two ranges (`phantom_cohort` DRAW_RANGES: soft tissue −2..+4 mm, vertical −5..+7 mm)
/// is cut into n equal strata and each stratum holds one phantom, at the stratum's centre
/// (rounded to 0.01; n = 1: the ranges' centres). Phantom k has the k-th thinnest soft tissue;
/// which vertical stratum goes with it is a permutation drawn from `seed`. The other shape
/// parameters are drawn from each phantom's own case seed.
fn cohort(n: usize, seed: u64) -> Vec<(String, Shape)> {
    use crate::phantom_cohort::{case_seed, draw, permutation, stratum_centre};
    let pairing = permutation(seed, n);
    (0..n)
        .map(|k| {
            let soft = stratum_centre(1, k, n);
            let vertical = stratum_centre(5, pairing[k], n);
            let shape = draw(
                case_seed(seed, k),
                [None, Some(soft), None, None, None, Some(vertical)],
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

/// The clinical frame and bony landmarks of a case, as `facesim run`'s anatomy stage finds
/// them: the stages up to the skin, the landmarks, no model.
fn anatomy_of(case_dir: &Path, obs: &dyn Observer) -> Result<Anatomy> {
    let mut rec = Recorder::new(obs);
    let (inputs, files) = inputs::read_with(case_dir, &toml::Table::new(), &mut rec)?;
    let inputs::Inputs { case, ct, scan } = inputs;
    let seg = tissues(&ct, &case, &mut rec)?;
    let field = seg.bone_field(&ct);
    let surf = surfaces::extract(&ct, &seg, &field, &case, &mut rec)?;
    let face = facesim::pipeline::face::place(surf, scan, &ct, &case, &mut rec)?;
    let (frame, soft) =
        facesim::landmarks::locate(&face.skin, Some(&face.skull), &[], &files.case_file)?;
    let frame = frame.ok_or_else(|| {
        Error::input(
            &files.case_file,
            "validate: no head frame (the skin is empty)",
        )
    })?;
    let bone = facesim::anatomy::Bone {
        vol: &ct,
        labels: &seg.labels,
    };
    facesim::anatomy::find(&bone, &frame, &soft, &case.head.clone().unwrap_or_default())
        .map_err(|e| Error::input(&files.case_file, format!("[head]: {e}")))
}

/// Per segment (maxilla, mandible, chin): Ok, or why the CT cannot have it.
type Possible = BTreeMap<String, std::result::Result<(), String>>;

/// The segments `[[surgery]]` would cut on this anatomy: (name, cut, how) for the case's
/// description, and per segment whether the CT can have it.
fn segments_of(a: &Anatomy) -> (Vec<(String, String, String)>, Possible) {
    use facesim::anatomy::cuts::{Found, cut};
    use facesim::case::SurgeryKind;
    let f = Found {
        landmarks: &a.landmarks,
    };
    let mut described = Vec::new();
    let mut possible = BTreeMap::new();
    for (kind, what) in [
        (SurgeryKind::LeFortI, "le-fort-i"),
        (SurgeryKind::Bsso, "bsso"),
        (SurgeryKind::Genioplasty, "genioplasty"),
    ] {
        let name = facesim::anatomy::surgery::default_name(kind).to_string();
        let r = cut(kind, &f, &a.frame.frame).map(|_| ());
        described.push((
            name.clone(),
            format!("[[surgery]] kind = \"{what}\""),
            match &r {
                Ok(()) => {
                    "cut from the bony landmarks found on the CT (docs/guide/planning.md \"The cuts\")"
                        .to_string()
                }
                Err(why) => format!("not possible on this CT: {why}"),
            },
        ));
        possible.insert(name, r);
    }
    (described, possible)
}

fn region_text(v: &toml::Value) -> String {
    v.to_string()
}

/// The mandible's autorotation as the CT allows it: Ok, or why not.
fn autorotation_of(a: &Anatomy) -> std::result::Result<(), String> {
    let f = facesim::anatomy::cuts::Found {
        landmarks: &a.landmarks,
    };
    facesim::anatomy::cuts::mandible(&f, &a.frame.frame).map(|_| ())
}

fn sample_case(name: &str, dir: &Path, anatomy: &Anatomy) -> Result<Prepared> {
    let file = dir.join("validation.toml");
    let text = std::fs::read_to_string(&file).map_err(|e| Error::input(&file, e))?;
    let cf: CaseFile = toml::from_str(&text).map_err(|e| Error::input(&file, e.message()))?;
    let mut about = cf.about;
    if let Some(m) = &cf.movable {
        about = format!(
            "{about} Movable skin: `{}` over case.toml's: {}",
            region_text(m),
            cf.movable_note
        );
    }
    let (segments, possible) = segments_of(anatomy);
    let f = &anatomy.frame;
    Ok(Prepared {
        info: CaseInfo {
            name: name.into(),
            about,
            pitch_deg: f.pitch_deg + f.correction_deg,
            forward: f.frame.anterior,
            up: f.frame.vertical,
            frame_why: f.why.clone(),
            segments,
            autorotation: autorotation_of(anatomy),
            class: None,
            real_ct: true,
            seconds: 0.0,
        },
        dir: dir.to_path_buf(),
        possible,
        movable: cf.movable,
    })
}

fn phantom_case(
    name: &str,
    dir: &Path,
    shape: &Shape,
    (class, runs): (Option<SkeletalClass>, &[Surgery]),
    anatomy: &Anatomy,
) -> Prepared {
    let (segments, possible) = segments_of(anatomy);
    let v = shape.values();
    // The phantom case's movable sphere (centre (0, −30, −35) mm of the standard head, through
    // the shape's world_of; radius 85 mm, scaled) has the nose tip on its edge; 10 mm more
    // takes it in, as the Le Fort I types need.
    let centre = shape.world_of([0.0, -30.0, -35.0]);
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
                "{}jaws phantom (scale {}, soft tissue {:+} mm, mandible {:+} mm, chin {:+} mm, midline {:+} mm, vertical {:+} mm; {}); built upright. Movable skin: `{}` (the case's sphere, 10 mm larger to take in the nose tip).",
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
                v[5],
                if shape.nasal_passages {
                    "a hollow nose: two nasal passages beside a septum"
                } else {
                    "a solid nose"
                },
                region_text(&movable)
            ),
            pitch_deg: anatomy.frame.pitch_deg + anatomy.frame.correction_deg,
            forward: anatomy.frame.frame.anterior,
            up: anatomy.frame.frame.vertical,
            frame_why: anatomy.frame.why.clone(),
            segments,
            autorotation: autorotation_of(anatomy),
            class,
            real_ct: false,
            seconds: 0.0,
        },
        dir: dir.to_path_buf(),
        possible,
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

/// One surgery on one case through `facesim run`'s library call, with the product's defaults
/// except the discretisation-error estimate (a second solve at twice the element size that
/// reports, and does not change, the face). Returns the carried landmarks.
fn run_one(
    case: &Prepared,
    s: Surgery,
    run_dir: &Path,
    opts: &Options,
    obs: &dyn Observer,
    on_run: &mut OnRun,
) -> Result<RunLandmarks> {
    // One `[[surgery]]` per segment moved, in the head's terms; the impaction's autorotation
    // where the CT has the mandible's condyles.
    let mut entries: Vec<(String, toml::Table)> = Vec::new();
    for (seg, toward, mm) in moves(s) {
        let kind = match *seg {
            "maxilla" => "le-fort-i",
            "mandible" => "bsso",
            _ => "genioplasty",
        };
        if *toward == Toward::Closing {
            if case.info.autorotation.is_ok()
                && let Some((_, lf)) = entries.iter_mut().find(|(k, _)| k == "le-fort-i")
            {
                lf.insert("autorotate".into(), toml::Value::Boolean(true));
            }
            continue;
        }
        let mut e = toml::Table::new();
        e.insert("kind".into(), toml::Value::String(kind.into()));
        let (key, v) = match toward {
            Toward::Forward => ("advance_mm", *mm),
            Toward::Back => ("advance_mm", -*mm),
            _ => ("up_mm", *mm),
        };
        e.insert(key.into(), toml::Value::Float(v));
        entries.push((kind.into(), e));
    }
    let surgeries = entries
        .into_iter()
        .map(|(_, e)| toml::Value::Table(e))
        .collect();
    let mut over = toml::Table::new();
    over.insert(
        "name".into(),
        toml::Value::String(format!("validate-{}-{}", case.info.name, s.key())),
    );
    over.insert("surgery".into(), toml::Value::Array(surgeries));
    over.insert("osteotomy".into(), toml::Value::Array(Vec::new()));
    if let Some(m) = &case.movable {
        let mut surface = toml::Table::new();
        surface.insert("movable".into(), m.clone());
        over.insert("surface".into(), toml::Value::Table(surface));
    }
    // The band: the coarse mesh's solve and the sampled tissue parameters; else neither.
    let mut tet = toml::Table::new();
    tet.insert(
        "error_estimate".into(),
        toml::Value::Boolean(opts.band_samples > 0),
    );
    over.insert("tet".into(), toml::Value::Table(tet));
    if opts.band_samples > 0 {
        let mut u = toml::Table::new();
        u.insert(
            "samples".into(),
            toml::Value::Integer(opts.band_samples as i64),
        );
        over.insert("uncertainty".into(), toml::Value::Table(u));
    }
    facesim::case::merge(&mut over, opts.overrides.clone());
    let outcome = facesim::commands::run_with(&case.dir, Some(run_dir), &over, obs)?;
    on_run(&case.info, s, &outcome)?;
    if !opts.keep_runs {
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
        published: outcome
            .report
            .published_ratios
            .map(|c| c.rows)
            .unwrap_or_default(),
    })
}

/// What a run tells about its landmarks: where they went, and the face region (report.json
/// `tet.region`: the moved bone's box grown by `[tet] margin_mm`; the face beyond it is not
/// carried by the tissue mesh, which reaches `margin_mm` further to its held faces).
struct RunLandmarks {
    carried: Vec<Carried>,
    face_region: Option<([f64; 3], [f64; 3])>,
    /// The run's own published rows (report.json `published_ratios`), with their bands.
    published: Vec<ClinicRow>,
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
    facesim::landmarks::published::rows_of(s)
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
                tissue_band: None,
                coarse_mesh: None,
                band: None,
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
                        "{label} did not move: it lies {:.1} mm outside the face region (the moved bone's box grown by [tet] margin_mm; report.json tet.region), past which the face follows the mesh only where it holds free skin",
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
                        format!("{label} is {d:.1} mm from the face region's edge (report.json tet.region), beyond which the face fades with the mesh")
                    })
                })
                .collect();
            if !near.is_empty() {
                row.why = Some(near.join("; "));
            }
            // A width (lateral row) across the face, over the move; else along the move.
            let soft_dir = match p.axis {
                facesim::landmarks::published::Axis::Lateral => {
                    let l = facesim::vec3::cross(info.up, info.forward);
                    scale(l, 1.0 / facesim::vec3::norm(l))
                }
                _ => unit_of(info, toward),
            };
            match along(carried, p.terms, soft_dir) {
                Ok(d) => {
                    row.along_mm = Some(d);
                    row.ratio = Some(d / mm);
                    if let Some(b) = run.as_ref().ok().and_then(|r| band_of(&r.published, p, d / mm)) {
                        (row.tissue_band, row.coarse_mesh, row.band) = b;
                    }
                    row.forward_mm = along(carried, p.terms, info.forward).ok();
                    row.up_mm = along(carried, p.terms, info.up).ok();
                }
                Err(why) => row.why = Some(why),
            }
            row
        })
        .map(|mut row| {
            let closes = moves(s).iter().any(|(_, t, _)| *t == Toward::Closing);
            if let (true, Err(why)) = (closes, &info.autorotation) {
                let note = format!("the maxilla moved alone, without the autorotation: {why}");
                row.why = Some(match row.why.take() {
                    Some(w) => format!("{w}; {note}"),
                    None => note,
                });
            }
            row
        })
        .collect()
}

/// The run's band of row `p` about `ratio` (validate's own ratio; the run's report measures the
/// same move at the same landmarks, so the two agree but for rounding): each figure keeps its
/// offset from the report's predicted ratio.
#[allow(clippy::type_complexity)]
fn band_of(
    published: &[ClinicRow],
    p: &Published,
    ratio: f64,
) -> Option<(Option<[f64; 2]>, Option<f64>, Option<[f64; 2]>)> {
    let c = published
        .iter()
        .find(|c| c.soft == p.soft && c.axis == p.axis.name())?;
    let at = c.predicted?;
    let shift = |x: f64| ratio + (x - at);
    let pair = |b: [f64; 2]| [shift(b[0]), shift(b[1])];
    Some((
        c.tissue_band.map(pair),
        c.coarse_mesh.map(shift),
        c.band.map(pair),
    ))
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
        "case,surgery,landmark,hard_reference,segment,axis,move_mm,soft_along_mm,soft_forward_mm,soft_up_mm,predicted_ratio,tissue_p05,tissue_p95,coarse_mesh_ratio,band_low,band_high,published_low,published_high,inside,verdict,distance,range_note,source,evidence,note\n",
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
            num(r.tissue_band.map(|b| b[0]), 3),
            num(r.tissue_band.map(|b| b[1]), 3),
            num(r.coarse_mesh, 3),
            num(r.band.map(|b| b[0]), 3),
            num(r.band.map(|b| b[1]), 3),
            format!("{}", p.low),
            format!("{}", p.high),
            inside.into(),
            r.verdict().map_or("", Verdict::name).into(),
            num(r.ratio.map(|x| p.distance(x)), 3),
            p.range_note.into(),
            p.source.into(),
            p.evidence.into(),
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

/// Rows inside, consistent, outside and not measured.
pub fn verdict_counts(rows: &[Row]) -> [usize; 4] {
    let mut n = [0; 4];
    for r in rows {
        n[match r.verdict() {
            Some(Verdict::Inside) => 0,
            Some(Verdict::Consistent) => 1,
            Some(Verdict::Outside) => 2,
            None => 3,
        }] += 1;
    }
    n
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
    let [inside, consistent, outside, none] = verdict_counts(&v.rows);
    if opts.band_samples > 0 {
        s.push_str(&format!(
            "**With their bands: {inside} inside their published range, {consistent} consistent with it, {outside} outside, {none} not measured** (each below, with why). The ratios alone: {} inside, {} outside.\n\n",
            v.rows.iter().filter(|r| r.inside() == Some(true)).count(),
            v.rows.iter().filter(|r| r.inside() == Some(false)).count(),
        ));
        s.push_str(&format!("Ratio = the soft landmark's displacement along the bone's move ÷ the move (a pure translation moves every bone point by the plan's translation). Every run uses the product's defaults, with `[uncertainty] samples = {}` and `[tet] error_estimate = true`. Its band: the smallest interval holding the ratio's 5th–95th percentiles over the tissue parameters sampled from the `[uncertainty]` box, the ratio itself and the ratio on the mesh of twice the element size; **inside** when the band lies within the published range (holds a single published value), **consistent** when it overlaps the range, **outside** when it is clear of it (docs/guide/validation.md, \"The protocol\"). Forward and up are the head's (below, per case).\n\n## The moves", opts.band_samples));
    } else {
        s.push_str(&format!(
            "**{inside} inside their published range, {outside} outside, {none} not measured** (each below, with why; no bands: `--band-samples 0`).\n\n"
        ));
        s.push_str("Ratio = the soft landmark's displacement along the bone's move ÷ the move (a pure translation moves every bone point by the plan's translation). Every run uses the product's defaults except `[tet] error_estimate = false` (the estimate solves again at twice the element size and reports, without changing, the face). Forward and up are the head's (below, per case).\n\n## The moves");
    }
    s.push_str("\n\n| surgery | segments moved |\n|---|---|\n");
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
            "### {}{}\n\n{}\n\n- forward {} and up {} (LPS; pitch {:.1}° face-down from the CT's axes: {}); {:.0} s\n",
            c.name,
            c.class
                .map_or(String::new(), |k| format!(" ({})", k.name())),
            c.about,
            v3(c.forward),
            v3(c.up),
            c.pitch_deg,
            c.frame_why,
            c.seconds
        ));
        for (seg, region, how) in &c.segments {
            s.push_str(&format!("- {seg}: `{region}`: {how}\n"));
        }
        match &c.autorotation {
            Ok(()) => s.push_str(
                "- autorotation: about the condyles Co-R and Co-L found on the CT
",
            ),
            Err(why) => s.push_str(&format!(
                "- autorotation: not possible: {why}
"
            )),
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
            "## {}\n\n| case | soft (hard ref.) | axis | predicted | band | published | | soft fwd / up mm | note |\n|---|---|---|---|---|---|---|---|---|\n",
            srg.title()
        ));
        for r in rows {
            let p = r.published;
            let verdict = match (r.verdict(), r.ratio) {
                (Some(Verdict::Outside), Some(x)) => {
                    format!("**OUTSIDE** by {:.2}", p.distance(x))
                }
                (Some(v), _) => v.name().to_string(),
                _ => "not measured".to_string(),
            };
            let band = r
                .band
                .map_or(String::new(), |b| format!("{:.2}–{:.2}", b[0], b[1]));
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
            if !note.is_empty() {
                note.push_str("; ");
            }
            note.push_str("evidence: ");
            note.push_str(p.evidence);
            s.push_str(&format!(
                "| {} | {} ({}) | {} | {} | {band} | {} | {verdict} | {fwd_up} | {} |\n",
                r.case,
                p.soft,
                p.hard,
                p.axis.name(),
                num(r.ratio, 2),
                p.printed(),
                note.replace('|', "/")
            ));
        }
        s.push('\n');
    }
    s.push_str("## Sources\n\n");
    for p in &PUBLISHED {
        s.push_str(&format!(
            "- {} {} ({}): {}: {} ({})\n",
            p.surgery.title(),
            p.soft,
            p.hard,
            p.printed(),
            p.source,
            p.evidence
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(p: &'static Published, ratio: Option<f64>) -> Row {
        Row {
            case: "c".into(),
            published: p,
            move_mm: 5.0,
            along_mm: ratio.map(|r| r * 5.0),
            forward_mm: None,
            up_mm: None,
            ratio,
            tissue_band: None,
            coarse_mesh: None,
            band: None,
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
        // Without a band: the ratio, five empty band columns, the range, inside and verdict.
        assert!(
            lines[1].contains(",1.500,,,,,,0.8,1.33,no,outside,"),
            "{}",
            lines[1]
        );
        assert!(
            lines[2].contains(",1.000,,,,,,0.8,1.33,yes,inside,"),
            "{}",
            lines[2]
        );
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
            band_samples: 0,
            autorotation: true,
            command: "facesim validate".into(),
        };
        let md = markdown(&v, &opts);
        assert!(
            md.contains("| 1.50 |  | 0.8–1.33 | **OUTSIDE** by 0.17 |"),
            "{md}"
        );
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

    /// Soft tissue and the vertical pattern each span their draw range, one phantom per
    /// stratum at its centre, paired by the seed's permutation.
    #[test]
    fn the_cohort_spans_thin_to_thick_soft_tissue() {
        let c = cohort(4, 1);
        let soft: Vec<f64> = c.iter().map(|(_, s)| s.soft_mm).collect();
        // −2..+4 mm in strata of 1.5 mm: thin to thick, phantom 1 to 4.
        assert_eq!(soft, [-1.25, 0.25, 1.75, 3.25]);
        // −5..+7 mm in strata of 3 mm, each used once.
        let vertical: Vec<f64> = c.iter().map(|(_, s)| s.vertical_mm).collect();
        let mut sorted = vertical.clone();
        sorted.sort_by(f64::total_cmp);
        assert_eq!(sorted, [-3.5, -0.5, 2.5, 5.5]);
        // Seed 1 pairs them other than thin with short and thick with long.
        assert_ne!(vertical, sorted, "the pairing is the identity");
        assert!(c.iter().all(|(_, s)| s.validate().is_ok()));
        assert_ne!(c[0].1.scale, c[1].1.scale);
        // Another seed pairs them differently; the other parameters are still drawn.
        let other: Vec<f64> = (2..10)
            .map(|seed| cohort(4, seed))
            .flat_map(|c| c.into_iter().map(|(_, s)| s.vertical_mm))
            .collect();
        assert!(other.chunks(4).any(|v| v != vertical), "{other:?}");
        // One phantom: the ranges' centres.
        let one = cohort(1, 1);
        assert_eq!((one[0].1.soft_mm, one[0].1.vertical_mm), (1.0, 1.0));
        // Many: every stratum of each range holds exactly one phantom.
        let n = 9;
        let c = cohort(n, 1);
        for (k, lo, hi) in [(1, -2.0, 4.0), (5, -5.0, 7.0)] {
            let mut used = vec![0; n];
            for (_, s) in &c {
                let v = s.values()[k];
                let i = ((v - lo) / (hi - lo) * n as f64) as usize;
                used[i] += 1;
            }
            assert!(used.iter().all(|&u| u == 1), "parameter {k}: {used:?}");
        }
    }

    /// A thin Class III phantom of the cohort (phantom 1 of seed 1, as `facesim validate`
    /// builds it for a Le Fort I advance) whose nasal floor, followed forward, climbed onto the
    /// cranium: ANS was found 34 mm up, on the nasal bones, and the Le Fort I cut 3 mm above it
    /// moved the nose with the maxilla (77 ml of bone against 23–34 ml on the other phantoms).
    /// ANS lies at the nasal floor's level, below the skull base (the phantom's z 4.5 mm).
    #[test]
    fn ans_is_found_at_the_nasal_floor_not_on_the_nasal_bones() {
        let shape = Shape {
            nasal_passages: true,
            ..Shape::from_values([0.98, -1.25, 2.53, -0.87, 0.56, -0.5])
        };
        let dir = std::env::temp_dir().join(format!("facesim-ans-{}", std::process::id()));
        let jaws = JawsOptions {
            phantom: crate::phantom::PhantomOptions {
                spacing: [2.0; 3],
                ..Default::default()
            },
            solve_model: None,
        };
        crate::phantom_jaws::write_shaped_case(&dir, &jaws, &shape).unwrap();
        let anatomy = anatomy_of(&dir, &facesim::observe::Quiet).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        let ans = anatomy
            .landmarks
            .iter()
            .find(|l| l.label == "ANS")
            .and_then(|l| l.position)
            .expect("ANS found");
        let a = shape.landmark("A point").unwrap();
        assert!(
            ans[2] < 4.5 && ans[2] > a[2],
            "ANS at z {:.1} (A point at {:.1}, the skull base at 4.5)",
            ans[2],
            a[2]
        );
    }
}

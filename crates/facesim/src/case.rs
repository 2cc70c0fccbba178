//! The case directory (docs/case.md): case.toml merged over pipeline/defaults.toml, validated.
//!
//! Unknown keys and wrong types are errors that name case.toml and the key; relative paths are
//! resolved against the case directory.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The documented defaults, compiled in so the binary works from any directory.
pub const DEFAULTS_TOML: &str = include_str!("../../../pipeline/defaults.toml");

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Case {
    #[serde(default)]
    pub name: Option<String>,
    pub ct: PathSection,
    #[serde(default)]
    pub skin: Option<PathSection>,
    #[serde(default)]
    pub registration: Option<Registration>,
    pub tissue: Tissue,
    pub extract: Extract,
    pub springs: Springs,
    pub surface: Surface,
    #[serde(default)]
    pub osteotomy: Vec<Osteotomy>,
    pub solve: Solve,
    pub tet: Tet,
    pub output: Output,
    /// `[uncertainty]`: sampling the tissue parameters (docs/uncertainty.md).
    #[serde(default)]
    pub uncertainty: crate::uncertainty::Uncertainty,
    /// User landmarks (`[[landmark]]` label and LPS position), overriding detection
    /// (docs/landmarks.md).
    #[serde(default, rename = "landmark")]
    pub landmark: Vec<UserLandmark>,
    /// Which series of a DICOM directory holding several is the CT (`[dicom] series`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dicom: Option<Dicom>,
    /// A 3D Slicer markups file of user landmarks (`landmarks = "file.mrk.json"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landmarks: Option<PathBuf>,
}

/// `[dicom]`: `series` is a SeriesInstanceUID, or a SeriesNumber, of the series to read from a
/// `[ct] path` directory holding several (docs/dicom.md). Without it the largest CT series is
/// read, with a warning.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Dicom {
    pub series: String,
}

/// One `[[landmark]]`: a label (docs/landmarks.md) and its position (LPS mm).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct UserLandmark {
    pub label: String,
    pub position: [f64; 3],
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PathSection {
    pub path: PathBuf,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Registration {
    pub scan: Vec<[f64; 3]>,
    pub ct: Vec<[f64; 3]>,
    #[serde(default)]
    pub scale: bool,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TissueMethod {
    Windows,
    Fit,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Stiffness {
    pub skin: f64,
    pub muscle: f64,
    pub fat_dark: f64,
    pub fat_bright: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Tissue {
    pub method: TissueMethod,
    pub head_threshold: f64,
    pub skin_thickness_mm: f64,
    pub min_bone_component_mm3: f64,
    pub fat_dark: f64,
    pub fat_bright: f64,
    pub soft: f64,
    pub bone: f64,
    pub stiffness: Stiffness,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ExtractMethod {
    Rangescan,
    Marching,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Extract {
    pub method: ExtractMethod,
    pub angle_step_deg: f64,
    pub z_step_mm: f64,
    pub smooth_iterations: usize,
    pub decimate_target: usize,
    pub decimate_max_error_mm: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Springs {
    pub max_length_mm: f64,
    pub struts: bool,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Parameterization {
    Cylindrical,
    Planar,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Surface {
    pub alpha: f64,
    pub beta: f64,
    pub parameterization: Parameterization,
    #[serde(default)]
    pub movable: Option<Region>,
    /// Per-region stretching/bending (`[[surface.region]]`), applied by triangle centroid; later
    /// entries win where regions overlap.
    #[serde(default, rename = "region")]
    pub regions: Vec<SurfaceRegion>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceRegion {
    pub shape: Region,
    pub alpha: f64,
    pub beta: f64,
}

/// Region shapes (docs/case.md), used by `movable` and `osteotomy.region`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Region {
    Box {
        min: [f64; 3],
        max: [f64; 3],
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    HalfSpace {
        point: [f64; 3],
        normal: [f64; 3],
    },
    Mask(Mask),
    /// Inside a closed surface (`surface = "maxilla.stl"`: STL, PLY, OBJ, VTK; docs/slicer.md).
    Surface(SurfaceFile),
}

/// A `surface = "file.stl"` region: its path as written in case.toml and, once read
/// (`Case::read_masks`, at the input edge), the closed surface. Serialised as the path alone.
#[derive(Clone, Deserialize, Serialize)]
#[serde(from = "PathBuf", into = "PathBuf")]
pub struct SurfaceFile {
    pub path: PathBuf,
    pub surface: Option<std::sync::Arc<crate::mesh::inside::ClosedSurface>>,
}

impl From<PathBuf> for SurfaceFile {
    fn from(path: PathBuf) -> SurfaceFile {
        SurfaceFile {
            path,
            surface: None,
        }
    }
}

impl From<SurfaceFile> for PathBuf {
    fn from(s: SurfaceFile) -> PathBuf {
        s.path
    }
}

impl std::fmt::Debug for SurfaceFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Surface({:?})", self.path)
    }
}

impl SurfaceFile {
    fn contains(&self, p: [f64; 3]) -> bool {
        let Some(s) = &self.surface else {
            // Read before any stage runs, like masks (Case::read_masks).
            debug_assert!(
                false,
                "region surface {} used before it was read",
                self.path.display()
            );
            return false;
        };
        s.contains(p)
    }
}

/// A `mask = "file.nii.gz"` region: its path as written in case.toml and, once the pipeline has
/// read it (`Case::read_masks`, at the input edge), its voxels. Serialised as the path alone.
#[derive(Clone, Deserialize, Serialize)]
#[serde(from = "PathBuf", into = "PathBuf")]
pub struct Mask {
    pub path: PathBuf,
    pub voxels: Option<std::sync::Arc<crate::volume::Volume>>,
}

impl From<PathBuf> for Mask {
    fn from(path: PathBuf) -> Mask {
        Mask { path, voxels: None }
    }
}

impl From<Mask> for PathBuf {
    fn from(m: Mask) -> PathBuf {
        m.path
    }
}

impl std::fmt::Debug for Mask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Mask({:?})", self.path)
    }
}

impl Mask {
    /// Non-zero voxel nearest to p; false outside the mask's grid.
    fn contains(&self, p: [f64; 3]) -> bool {
        let Some(m) = &self.voxels else {
            // Masks are read before any stage runs (Case::read_masks); an unread mask selecting
            // nothing would silently make every vertex rigid, as it once did.
            debug_assert!(
                false,
                "mask {} used before it was read",
                self.path.display()
            );
            return false;
        };
        let c = m.to_voxel(p).map(|x| x.round());
        if (0..3).any(|a| c[a] < 0.0 || c[a] >= m.dims[a] as f64) {
            return false;
        }
        m.data[m.idx(c[0] as usize, c[1] as usize, c[2] as usize)] != 0.0
    }
}

/// Read the voxels of every mask region and the closed surface of every surface region in
/// `regions` that has not been read yet (a mask file once, however many regions name it).
pub fn read_region_files<'a>(regions: impl Iterator<Item = &'a mut Region>) -> Result<()> {
    let mut read: Vec<(PathBuf, std::sync::Arc<crate::volume::Volume>)> = Vec::new();
    for r in regions {
        if let Region::Surface(s) = r
            && s.surface.is_none()
        {
            if !s.path.is_file() {
                return Err(Error::input(&s.path, "region surface file not found"));
            }
            let mesh = crate::mesh::model_file::read_model(&s.path)?;
            let closed = crate::mesh::inside::ClosedSurface::new(&mesh, &s.path)?;
            s.surface = Some(std::sync::Arc::new(closed));
            continue;
        }
        let Region::Mask(m) = r else { continue };
        if m.voxels.is_some() {
            continue;
        }
        if !m.path.is_file() {
            return Err(Error::input(&m.path, "region mask file not found"));
        }
        let v = match read.iter().find(|(p, _)| *p == m.path) {
            Some((_, v)) => v.clone(),
            None => {
                let v = std::sync::Arc::new(crate::volume::read_volume(&m.path)?);
                read.push((m.path.clone(), v.clone()));
                v
            }
        };
        m.voxels = Some(v);
    }
    Ok(())
}

impl Region {
    /// Whether p (LPS mm) is inside; a mask must have been read (`Case::read_masks`).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        match self {
            Region::Box { min, max } => (0..3).all(|a| p[a] >= min[a] && p[a] <= max[a]),
            Region::Sphere { center, radius } => {
                let d: f64 = (0..3).map(|a| (p[a] - center[a]).powi(2)).sum();
                d <= radius * radius
            }
            Region::HalfSpace { point, normal } => {
                (0..3).map(|a| (p[a] - point[a]) * normal[a]).sum::<f64>() >= 0.0
            }
            Region::Mask(m) => m.contains(p),
            Region::Surface(s) => s.contains(p),
        }
    }

    fn validate(&self, what: &str) -> Result<()> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let ok = match self {
            Region::Box { min, max } => {
                finite(min) && finite(max) && (0..3).all(|a| min[a] <= max[a])
            }
            Region::Sphere { center, radius } => {
                finite(center) && radius.is_finite() && *radius > 0.0
            }
            Region::HalfSpace { point, normal } => {
                finite(point) && finite(normal) && normal.iter().any(|x| *x != 0.0)
            }
            Region::Mask(_) | Region::Surface(_) => true,
        };
        if ok {
            Ok(())
        } else {
            Err(Error::config(format!(
                "case.toml: {what}: region {self:?} is empty or not finite"
            )))
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Osteotomy {
    pub name: String,
    pub region: Region,
    #[serde(default)]
    pub translate: [f64; 3],
    #[serde(default)]
    pub rotate_deg: [f64; 3],
    #[serde(default)]
    pub pivot: [f64; 3],
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum SolveModel {
    Equilibrium,
    Koch1996,
    /// The volumetric soft-tissue model (`[tet]`, docs/pipeline.md "Volumetric soft tissue").
    Tet,
}

impl SolveModel {
    /// The name case.toml uses (`[solve] model`).
    pub fn name(self) -> &'static str {
        match self {
            SolveModel::Equilibrium => "equilibrium",
            SolveModel::Koch1996 => "koch1996",
            SolveModel::Tet => "tet",
        }
    }
}

/// The volumetric model's constitutive law.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum TetMaterial {
    /// Small-strain isotropic linear elasticity.
    Linear,
    /// Compressible neo-Hookean (CalculiX's NEO HOOKE form), geometrically nonlinear: exact
    /// for rigid moves of any size.
    NeoHookean,
}

/// The volumetric model's element.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum TetElement {
    /// 4-node tetrahedra (locks as ν → 0.5).
    Linear,
    /// 10-node tetrahedra (CalculiX C3D10), which do not lock; linear material only.
    Quadratic,
}

/// Young's modulus (kPa) and Poisson ratio of one tissue.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TissueElastic {
    pub youngs_kpa: f64,
    pub poisson: f64,
}

/// `[tet]`: the volumetric model (used when `[solve] model = "tet"`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Tet {
    pub material: TetMaterial,
    pub element: TetElement,
    /// Newton load steps of the nonlinear material.
    pub load_steps: usize,
    /// Mucosa (tissue surface facing a cavity, e.g. the inner lip across the vestibule) within
    /// `mucosa_gap_mm` of the skull: true slides along the bone (its normal displacement follows
    /// the bone, tangential free), false is attached (moves with the bone).
    pub sliding: bool,
    pub mucosa_gap_mm: f64,
    /// Element edge length (mm) at the skin inside the region the plan reaches.
    pub skin_size_mm: f64,
    /// Element edge length (mm) deep in the tissue and far from the moved bone.
    pub deep_size_mm: f64,
    /// The modelled region: the box around the moved bone grown by this much (mm); its cut
    /// faces are held fixed.
    pub margin_mm: f64,
    pub skin: TissueElastic,
    pub muscle: TissueElastic,
    pub fat_dark: TissueElastic,
    pub fat_bright: TissueElastic,
}

impl Tet {
    /// The material of a tissue label of `crate::segment` (soft labels; anything else is
    /// muscle, the bulk of the face's soft tissue).
    pub fn elastic(&self, label: u8) -> TissueElastic {
        use crate::segment::{FAT_BRIGHT, FAT_DARK, SKIN};
        match label {
            SKIN => self.skin,
            FAT_DARK => self.fat_dark,
            FAT_BRIGHT => self.fat_bright,
            _ => self.muscle,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Solve {
    pub model: SolveModel,
    pub steps: usize,
    /// Spring stiffness per unit relative stiffness c per mm² (equilibrium model).
    pub k_c: f64,
    /// Force scale k_c of eq. 20 for the koch1996 model (forces are loads there, not springs,
    /// so the scale is a different quantity; docs/pipeline.md).
    pub koch_k_c: f64,
    /// Solve only on the movable skin and its ring of rigid neighbours (exact: elements whose
    /// DOFs are all fixed add nothing). Off solves on the whole skin.
    pub restrict: bool,
    /// Solve on a copy of the skin decimated to this many triangles and carry the full skin
    /// along by shell embedding (paper 002), when the skin has more than twice as many.
    /// 0 = always solve on the skin as given.
    pub coarse_triangles: usize,
    /// Depth of the embedding shell below the coarse skin (mm).
    pub shell_mm: f64,
    /// Poisson ratio of the shell's thickness rule (paper 002 eq. 2), in [0, 0.5].
    pub shell_poisson: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    pub subdivide: usize,
}

// Rust defaults, equal to pipeline/defaults.toml (tested): a caller builds a case in memory with
// `Case { ct: PathSection { path }, ..Case::default() }` and no case.toml.
impl Default for Case {
    fn default() -> Case {
        Case {
            name: None,
            ct: PathSection {
                path: PathBuf::new(),
            },
            skin: None,
            registration: None,
            tissue: Tissue::default(),
            extract: Extract::default(),
            springs: Springs::default(),
            surface: Surface::default(),
            osteotomy: Vec::new(),
            solve: Solve::default(),
            tet: Tet::default(),
            output: Output::default(),
            uncertainty: Default::default(),
            landmark: Vec::new(),
            dicom: None,
            landmarks: None,
        }
    }
}

impl Default for Tissue {
    fn default() -> Tissue {
        Tissue {
            method: TissueMethod::Windows,
            head_threshold: -500.0,
            skin_thickness_mm: 2.0,
            min_bone_component_mm3: 500.0,
            fat_dark: -190.0,
            fat_bright: -100.0,
            soft: -30.0,
            bone: 300.0,
            stiffness: Stiffness {
                skin: 200.0,
                muscle: 100.0,
                fat_dark: 10.0,
                fat_bright: 20.0,
            },
        }
    }
}

impl Default for Extract {
    fn default() -> Extract {
        Extract {
            method: ExtractMethod::Rangescan,
            angle_step_deg: 2.0,
            z_step_mm: 0.0,
            smooth_iterations: 0,
            decimate_target: 0,
            decimate_max_error_mm: 0.5,
        }
    }
}

impl Default for Springs {
    fn default() -> Springs {
        Springs {
            max_length_mm: 40.0,
            struts: true,
        }
    }
}

impl Default for Surface {
    fn default() -> Surface {
        Surface {
            alpha: 0.01,
            beta: 0.02,
            parameterization: Parameterization::Cylindrical,
            movable: None,
            regions: Vec::new(),
        }
    }
}

impl Default for Solve {
    fn default() -> Solve {
        Solve {
            model: SolveModel::Tet,
            steps: 4,
            k_c: 2.5e-6,
            koch_k_c: 1e-8,
            restrict: true,
            coarse_triangles: 0,
            shell_mm: 3.0,
            shell_poisson: 0.45,
        }
    }
}

impl Default for Tet {
    fn default() -> Tet {
        let e = |youngs_kpa, poisson| TissueElastic {
            youngs_kpa,
            poisson,
        };
        Tet {
            material: TetMaterial::Linear,
            element: TetElement::Linear,
            load_steps: 4,
            sliding: true,
            mucosa_gap_mm: 3.0,
            skin_size_mm: 4.0,
            deep_size_mm: 8.0,
            margin_mm: 30.0,
            skin: e(30.0, 0.45),
            muscle: e(10.0, 0.45),
            fat_dark: e(2.0, 0.45),
            fat_bright: e(3.0, 0.45),
        }
    }
}

impl Default for Output {
    fn default() -> Output {
        Output { subdivide: 2 }
    }
}

/// Recursively lay `over` on top of `base` (tables merge, everything else replaces).
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// `KEY=VALUE` overrides (the CLI's `run --set tet.sliding=false`, docs/case.md) as a table to
/// lay over a case file: a dotted key names nested tables; the value is TOML, and a bare word
/// that is not TOML is a string (`solve.model=tet`).
pub fn overrides_table(sets: &[String]) -> Result<toml::Table> {
    let mut out = toml::Table::new();
    for set in sets {
        let Some((key, value)) = set.split_once('=') else {
            return Err(Error::config(format!(
                "--set {set}: expected KEY=VALUE (e.g. tet.sliding=false)"
            )));
        };
        let keys: Vec<&str> = key.trim().split('.').map(str::trim).collect();
        if keys.iter().any(|k| k.is_empty()) {
            return Err(Error::config(format!("--set {set}: empty key")));
        }
        let value = value.trim();
        let parsed = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        let mut table = &mut out;
        for k in &keys[..keys.len() - 1] {
            let entry = table
                .entry(k.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            let toml::Value::Table(t) = entry else {
                return Err(Error::config(format!(
                    "--set {set}: {k} is already set to a value"
                )));
            };
            table = t;
        }
        table.insert(keys[keys.len() - 1].to_string(), parsed);
    }
    Ok(out)
}

impl Case {
    /// Parse case text (as if from `path`) over the defaults.
    pub fn parse(text: &str, path: &Path) -> Result<Case> {
        Case::parse_with(text, path, &toml::Table::new())
    }

    /// Parse case text over the defaults, then lay `overrides` (`overrides_table`) on top.
    pub fn parse_with(text: &str, path: &Path, overrides: &toml::Table) -> Result<Case> {
        let mut base: toml::Table = toml::from_str(DEFAULTS_TOML)
            .map_err(|e| Error::config(format!("pipeline/defaults.toml: {e}")))?;
        let mut over: toml::Table =
            toml::from_str(text).map_err(|e| Error::input(path, e.message()))?;
        // Slicer's files in the plan (transform files, markups planes) become plan keys.
        let dir = path.parent().unwrap_or(Path::new(""));
        crate::slicer::resolve_plan_files(&mut over, dir, path)?;
        merge(&mut base, over);
        merge(&mut base, overrides.clone());
        let case: Case = toml::Value::Table(base)
            .try_into()
            .map_err(|e: toml::de::Error| Error::input(path, e.message()))?;
        case.validate(path)?;
        Ok(case)
    }

    /// Load `CASE_DIR/case.toml` (or a .toml file given directly), resolving paths.
    pub fn load(case: &Path) -> Result<(Case, PathBuf)> {
        Case::load_with(case, &toml::Table::new())
    }

    /// `load` with `overrides` laid over the case file.
    pub fn load_with(case: &Path, overrides: &toml::Table) -> Result<(Case, PathBuf)> {
        let (file, dir) = if case.is_dir() {
            (case.join("case.toml"), case.to_path_buf())
        } else {
            (
                case.to_path_buf(),
                case.parent().map(Path::to_path_buf).unwrap_or_default(),
            )
        };
        let text = std::fs::read_to_string(&file).map_err(|e| Error::input(&file, e))?;
        Ok((Case::from_text_with(&text, &file, &dir, overrides)?, dir))
    }

    /// Parse case text as if read from `file`, resolving relative paths against `dir` (what
    /// [`Case::load`] does after reading the file; bindings use it for a case given as a table).
    pub fn from_text(text: &str, file: &Path, dir: &Path) -> Result<Case> {
        Case::from_text_with(text, file, dir, &toml::Table::new())
    }

    /// [`Case::from_text`] with `overrides` laid over the text.
    pub fn from_text_with(
        text: &str,
        file: &Path,
        dir: &Path,
        overrides: &toml::Table,
    ) -> Result<Case> {
        let mut c = Case::parse_with(text, file, overrides)?;
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        };
        resolve(&mut c.ct.path);
        if let Some(s) = &mut c.skin {
            resolve(&mut s.path);
        }
        if let Some(l) = &mut c.landmarks {
            resolve(l);
        }
        for r in c.regions_mut() {
            match r {
                Region::Mask(m) => resolve(&mut m.path),
                Region::Surface(s) => resolve(&mut s.path),
                _ => {}
            }
        }
        Ok(c)
    }

    /// The user landmarks: `[[landmark]]` entries, then the markups file's points (a label
    /// given twice: the later wins). Errors name case.toml or the markups file.
    pub fn user_landmarks(&self) -> Result<Vec<(String, [f64; 3])>> {
        let mut out: Vec<(String, [f64; 3])> = Vec::new();
        let mut add = |label: String, p: [f64; 3]| match out.iter_mut().find(|(l, _)| *l == label) {
            Some(e) => e.1 = p,
            None => out.push((label, p)),
        };
        for l in &self.landmark {
            add(l.label.clone(), l.position);
        }
        if let Some(path) = &self.landmarks {
            for (label, p) in crate::landmarks::markups::read(path)? {
                add(label, p);
            }
        }
        Ok(out)
    }

    /// The regions that may be masks: `[surface] movable` and each osteotomy's region.
    fn regions_mut(&mut self) -> impl Iterator<Item = &mut Region> {
        self.surface
            .movable
            .iter_mut()
            .chain(self.osteotomy.iter_mut().map(|o| &mut o.region))
    }

    /// Read every mask region's voxels (once per file) and every surface region's closed
    /// surface: the pipeline's input edge, so that no stage reads files and `Region::contains`
    /// is right for masks and surfaces.
    pub fn read_masks(&mut self) -> Result<()> {
        read_region_files(self.regions_mut())
    }

    /// Check every value's range; errors name `path` (case.toml) and the key.
    pub fn validate(&self, path: &Path) -> Result<()> {
        let bad = |msg: String| Err(Error::input(path, msg));
        for l in &self.landmark {
            if l.label.trim().is_empty() || l.position.iter().any(|x| !x.is_finite()) {
                return bad(format!(
                    "[[landmark]] '{}' needs a label and a finite position",
                    l.label
                ));
            }
        }
        let t = &self.tissue;
        let bounds = [t.head_threshold, t.fat_dark, t.fat_bright, t.soft, t.bone];
        if bounds.iter().any(|b| !b.is_finite()) || bounds.windows(2).any(|w| w[0] >= w[1]) {
            return bad(format!(
                "[tissue] needs head_threshold < fat_dark < fat_bright < soft < bone, got {bounds:?}"
            ));
        }
        if !(t.skin_thickness_mm > 0.0) {
            return bad("[tissue] skin_thickness_mm must be positive".into());
        }
        let s = &t.stiffness;
        if [s.skin, s.muscle, s.fat_dark, s.fat_bright]
            .iter()
            .any(|k| !(k.is_finite() && *k > 0.0))
        {
            return bad("[tissue.stiffness] values must be finite and positive".into());
        }
        let e = &self.extract;
        let ok = e.angle_step_deg > 0.0
            && e.angle_step_deg <= 30.0
            && e.z_step_mm >= 0.0
            && e.decimate_max_error_mm > 0.0;
        if !ok {
            return bad("[extract] angle_step_deg must be in (0, 30], z_step_mm >= 0, decimate_max_error_mm > 0".into());
        }
        if !(self.springs.max_length_mm > 0.0) {
            return bad("[springs] max_length_mm must be positive".into());
        }
        if !(self.surface.alpha.is_finite()
            && self.surface.alpha >= 0.0
            && self.surface.beta.is_finite()
            && self.surface.beta >= 0.0)
        {
            return bad("[surface] alpha and beta must be finite and >= 0".into());
        }
        if !(self.solve.k_c.is_finite()
            && self.solve.k_c > 0.0
            && self.solve.koch_k_c.is_finite()
            && self.solve.koch_k_c > 0.0)
        {
            return bad("[solve] k_c and koch_k_c must be finite and positive".into());
        }
        if !(self.solve.shell_mm > 0.0
            && self.solve.shell_mm.is_finite()
            && (0.0..=0.5).contains(&self.solve.shell_poisson))
        {
            return bad("[solve] shell_mm must be positive and shell_poisson in [0, 0.5]".into());
        }
        if self.solve.coarse_triangles > 0 && self.solve.coarse_triangles < 200 {
            return bad("[solve] coarse_triangles must be 0 (off) or at least 200".into());
        }
        if self.solve.steps == 0 {
            return bad("[solve] steps must be at least 1".into());
        }
        let t = &self.tet;
        if !(t.skin_size_mm > 0.0
            && t.deep_size_mm >= t.skin_size_mm
            && t.deep_size_mm.is_finite()
            && t.margin_mm >= 0.0
            && t.margin_mm.is_finite())
        {
            return bad(
                "[tet] needs 0 < skin_size_mm <= deep_size_mm (finite) and margin_mm >= 0".into(),
            );
        }
        if t.material == TetMaterial::NeoHookean && t.element == TetElement::Quadratic {
            return bad(
                "[tet] material \"neo-hookean\" runs on element \"linear\" (no nonlinear 10-node tetrahedron yet)"
                    .into(),
            );
        }
        if !(t.mucosa_gap_mm >= 0.0 && t.mucosa_gap_mm.is_finite()) {
            return bad("[tet] mucosa_gap_mm must be finite and >= 0".into());
        }
        if t.load_steps == 0 {
            return bad("[tet] load_steps must be at least 1".into());
        }
        for (name, m) in [
            ("skin", t.skin),
            ("muscle", t.muscle),
            ("fat_dark", t.fat_dark),
            ("fat_bright", t.fat_bright),
        ] {
            if !(m.youngs_kpa > 0.0 && m.youngs_kpa.is_finite()) {
                return bad(format!(
                    "[tet.{name}] youngs_kpa must be positive and finite"
                ));
            }
            if !(m.poisson > -1.0 && m.poisson < 0.5) {
                return bad(format!(
                    "[tet.{name}] poisson must lie in (-1, 0.5) (0.5 is incompressible: no finite bulk modulus)"
                ));
            }
        }
        self.uncertainty.validate(self.solve.model, path)?;
        if let Some(r) = &self.registration {
            if r.scan.len() != r.ct.len() || r.scan.len() < 3 {
                return bad(format!(
                    "[registration] needs >= 3 landmark pairs, got {} scan and {} ct points",
                    r.scan.len(),
                    r.ct.len()
                ));
            }
            if r.scan.iter().chain(&r.ct).flatten().any(|x| !x.is_finite()) {
                return bad("[registration] landmarks must be finite".into());
            }
        }
        if let Some(m) = &self.surface.movable {
            m.validate("[surface] movable")?;
        }
        for r in &self.surface.regions {
            r.shape.validate("[[surface.region]] shape")?;
            if !(r.alpha.is_finite() && r.alpha >= 0.0 && r.beta.is_finite() && r.beta >= 0.0) {
                return bad("[[surface.region]] alpha and beta must be finite and >= 0".into());
            }
            if matches!(r.shape, Region::Mask(_) | Region::Surface(_)) {
                return bad("[[surface.region]] takes box, sphere or half_space shapes".into());
            }
        }
        for o in &self.osteotomy {
            o.region.validate(&format!("osteotomy '{}'", o.name))?;
            if o.translate
                .iter()
                .chain(&o.rotate_deg)
                .chain(&o.pivot)
                .any(|x| !x.is_finite())
            {
                return bad(format!(
                    "osteotomy '{}': translate, rotate_deg and pivot must be finite",
                    o.name
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str = "[ct]\npath = \"ct.nii.gz\"\n";

    #[test]
    fn rust_defaults_equal_defaults_toml() {
        let parsed = Case::parse(MIN, Path::new("case.toml")).unwrap();
        let built = Case {
            ct: PathSection {
                path: "ct.nii.gz".into(),
            },
            ..Case::default()
        };
        let json = |c: &Case| serde_json::to_value(c).unwrap();
        assert_eq!(json(&built), json(&parsed));
        built.validate(Path::new("in memory")).unwrap();
    }

    #[test]
    fn defaults_fill_in_and_overrides_apply() {
        let c = Case::parse(
            &format!("{MIN}[tissue]\nmethod = \"fit\"\n"),
            Path::new("case.toml"),
        )
        .unwrap();
        assert_eq!(c.tissue.method, TissueMethod::Fit);
        assert_eq!(c.tissue.bone, 300.0);
        assert_eq!(c.solve.model, SolveModel::Tet);
    }

    #[test]
    fn unknown_keys_and_wrong_types_name_the_key() {
        let e = Case::parse(
            &format!("{MIN}[springs]\nmax_lenght_mm = 3.0\n"),
            Path::new("case.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("case.toml") && e.contains("max_lenght_mm"),
            "{e}"
        );
        let e = Case::parse(
            &format!("{MIN}[surface]\nalpha = \"x\"\n"),
            Path::new("case.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("case.toml"), "{e}");
        assert!(!e.contains('\n'));
    }

    #[test]
    fn regions_parse_and_select() {
        let c = Case::parse(
            &format!(
                "{MIN}[[osteotomy]]\nname = \"m\"\nregion = {{ half_space = {{ point = [0,0,0], normal = [0,0,-1] }} }}\ntranslate = [0,-6,0]\n"
            ),
            Path::new("case.toml"),
        )
        .unwrap();
        assert!(c.osteotomy[0].region.contains([0.0, 0.0, -1.0]));
        assert!(!c.osteotomy[0].region.contains([0.0, 0.0, 1.0]));
        let e = Case::parse(
            &format!("{MIN}[[osteotomy]]\nname = \"m\"\nregion = {{ sphere = {{ center = [0,0,0], radius = -1 }} }}\n"),
            Path::new("case.toml"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("osteotomy 'm'"));
    }
}

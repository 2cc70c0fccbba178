//! The input edge: the case file, the CT, a face scan and region masks are read here and
//! nowhere else, after checking that every named file exists (a missing scan is reported before
//! the CT is read).

use super::stage::Recorder;
use crate::case::{Case, Region};
use crate::error::{Error, Result};
use crate::mesh::{self, Mesh};
use crate::pipeline::stage::Stage;
use crate::volume::{self, Volume};
use std::path::{Path, PathBuf};

/// What the stages start from: the case (with its mask regions read), the CT in HU and LPS mm,
/// and the face scan as given (not yet registered).
pub struct Inputs {
    pub case: Case,
    pub ct: Volume,
    pub scan: Option<Mesh>,
}

/// Where a case came from, for naming files in errors and in the report.
#[derive(Clone, Debug)]
pub struct CaseFiles {
    pub dir: PathBuf,
    /// case.toml (or the .toml file given).
    pub case_file: PathBuf,
    /// The file the skin comes from: the face scan, else the CT it is extracted from.
    pub skin_source: PathBuf,
}

impl CaseFiles {
    /// For a case built in memory: no case file; the directory is the working directory.
    pub fn in_memory(case: &Case) -> CaseFiles {
        CaseFiles {
            dir: PathBuf::from("."),
            case_file: PathBuf::from("the case (built in memory)"),
            skin_source: case
                .skin
                .as_ref()
                .map_or(&case.ct.path, |s| &s.path)
                .clone(),
        }
    }
}

/// Load `CASE_DIR/case.toml` (or a .toml file) and read everything it names.
pub fn read(case_path: &Path, rec: &mut Recorder) -> Result<(Inputs, CaseFiles)> {
    read_with(case_path, &toml::Table::new(), rec)
}

/// `read` with `overrides` (`case::overrides_table`) laid over the case file.
pub fn read_with(
    case_path: &Path,
    overrides: &toml::Table,
    rec: &mut Recorder,
) -> Result<(Inputs, CaseFiles)> {
    let (case, dir) = Case::load_with(case_path, overrides)?;
    let case_file = if case_path.is_dir() {
        case_path.join("case.toml")
    } else {
        case_path.to_path_buf()
    };
    let files = CaseFiles {
        dir,
        case_file,
        ..CaseFiles::in_memory(&case)
    };
    Ok((read_case(case, rec)?, files))
}

/// Read the files a case built in memory names (paths absolute or relative to the working
/// directory).
pub(crate) fn read_case(mut case: Case, rec: &mut Recorder) -> Result<Inputs> {
    read_masks(&mut case)?;
    if let Some(skin) = &case.skin
        && !skin.path.is_file()
    {
        return Err(Error::input(&skin.path, "face scan not found"));
    }
    let series = case.dicom.as_ref().map(|d| d.series.as_str());
    let (mut ct, notes) = rec.time(Stage::ReadCt, "reading CT", || {
        volume::read_ct(&case.ct.path, series)
    })?;
    // What the file does not say, the case states (`[ct] axes`, `[ct] intercept`).
    if let Some(code) = case.ct.axes.as_deref() {
        ct.direction = volume::axes_code(code)
            .ok_or_else(|| Error::Config(format!("[ct] axes = \"{code}\" is not an axes code")))?;
    }
    if let Some(b) = case.ct.intercept {
        ct.data.iter_mut().for_each(|v| *v += b as f32);
    }
    for w in notes {
        rec.warn(w);
    }
    let scan = match &case.skin {
        // Any model format; not checked here: a skin from another program is cleaned to its
        // outer face once it is in the CT frame (pipeline::face).
        Some(s) => Some(rec.time(Stage::ReadScan, "reading face scan", || read_skin(&s.path))?),
        None => None,
    };
    Ok(Inputs { case, ct, scan })
}

/// A skin file (.ply, .obj, .stl, .vtk, .vtp) in LPS, with every triangle's indices in range.
fn read_skin(path: &Path) -> Result<Mesh> {
    let m = mesh::model_file::read_model(path)?;
    let nv = m.vertices.len();
    if let Some((t, bad)) = m
        .triangles
        .iter()
        .enumerate()
        .find_map(|(t, tri)| tri.iter().find(|&&i| i as usize >= nv).map(|&i| (t, i)))
    {
        return Err(Error::input(
            path,
            format!("triangle {t} uses vertex index {bad}, but there are {nv} vertices"),
        ));
    }
    if m.triangles.is_empty() {
        return Err(Error::input(path, "empty mesh (no triangles)"));
    }
    Ok(m)
}

/// Read every mask region's voxels (once per file) and every surface region's closed surface
/// of `case` (`[surface] movable`, the osteotomies): so that no stage reads files and
/// `Region::contains` is right for masks and surfaces.
pub fn read_masks(case: &mut Case) -> Result<()> {
    read_region_files(case.regions_mut())
}

/// Read the voxels of every mask region and the closed surface of every surface region in
/// `regions` that has not been read yet (a mask file once, however many regions name it).
pub(crate) fn read_region_files<'a>(regions: impl Iterator<Item = &'a mut Region>) -> Result<()> {
    let mut read: Vec<(PathBuf, std::sync::Arc<Volume>)> = Vec::new();
    for r in regions {
        if let Region::Surface(s) = r
            && s.surface.is_none()
        {
            if !s.path.is_file() {
                return Err(Error::input(&s.path, "region surface file not found"));
            }
            let mesh = mesh::model_file::read_model(&s.path)?;
            let closed = mesh::inside::ClosedSurface::new(&mesh, &s.path)?;
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
                let v = std::sync::Arc::new(volume::read_volume(&m.path)?);
                read.push((m.path.clone(), v.clone()));
                v
            }
        };
        m.voxels = Some(v);
    }
    Ok(())
}

/// The user landmarks of `case`: `[[landmark]]` entries, then the points of its markups file
/// (`landmarks = "file.mrk.json"`, read here; a label given twice: the later wins). Errors name
/// case.toml or the markups file.
pub fn user_landmarks(case: &Case) -> Result<Vec<(String, [f64; 3])>> {
    let mut out: Vec<(String, [f64; 3])> = Vec::new();
    let mut add = |label: String, p: [f64; 3]| match out.iter_mut().find(|(l, _)| *l == label) {
        Some(e) => e.1 = p,
        None => out.push((label, p)),
    };
    for l in &case.landmark {
        add(l.label.clone(), l.position);
    }
    if let Some(path) = &case.landmarks {
        for (label, p) in crate::landmarks::markups::read(path)? {
            add(label, p);
        }
    }
    Ok(out)
}

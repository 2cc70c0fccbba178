//! The input edge: the case file, the CT, a face scan and region masks are read here and
//! nowhere else, after checking that every named file exists (a missing scan is reported before
//! the CT is read).

use super::Recorder;
use crate::case::Case;
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
pub fn read_case(mut case: Case, rec: &mut Recorder) -> Result<Inputs> {
    case.read_masks()?;
    if let Some(skin) = &case.skin
        && !skin.path.is_file()
    {
        return Err(Error::input(&skin.path, "face scan not found"));
    }
    let series = case.dicom.as_ref().map(|d| d.series.as_str());
    let (ct, notes) = rec.time(Stage::ReadCt, "reading CT", || {
        volume::read_ct(&case.ct.path, series)
    })?;
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

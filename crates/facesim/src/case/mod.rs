//! The case directory (docs/reference/case.md): case.toml merged over pipeline/defaults.toml, validated.
//!
//! Unknown keys and wrong types are errors that name case.toml and the key; relative paths are
//! resolved against the case directory.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

mod defaults;
mod region;
mod schema;
mod solve_model;
mod surgery;
pub mod uncertainty;
mod validate;

pub use defaults::DEFAULTS_TOML;
pub use region::{Mask, Region, SurfaceFile};
pub use schema::*;
pub use surgery::{MAX_MOVE_MM, MAX_TURN_DEG, check_surgeries};
pub use uncertainty::Uncertainty;

/// Recursively lay `over` on top of `base` (tables merge, everything else replaces): how a case
/// file lies over the defaults and `--set` overrides over a case file.
pub fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// `KEY=VALUE` overrides (the CLI's `run --set tet.sliding=false`, docs/reference/case.md) as a table to
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

/// A case (`table`: case.toml's, or the `--set` overrides) that sets a key of a retired `[tet]`
/// mechanism ([`RETIRED_TET_KEYS`]) is refused in one line naming `path` and the key: serde's
/// unknown-field message would list every `[tet]` key instead, and a report.json's parameters
/// (which still carry them from before) must read back, so `Tet` itself ignores them.
fn refuse_retired(table: &toml::Table, path: &Path) -> Result<()> {
    let Some(toml::Value::Table(tet)) = table.get("tet") else {
        return Ok(());
    };
    match RETIRED_TET_KEYS.iter().find(|k| tet.contains_key(**k)) {
        Some(key) => Err(Error::input(
            path,
            format!(
                "[tet] {key} is no longer a key: the mechanism failed the validation gate and was retired (docs/lab/retired-mechanisms.md); remove it"
            ),
        )),
        None => Ok(()),
    }
}

impl Case {
    /// Whether the case's model has the certified reduced form (docs/design/reduced.md): the
    /// volumetric model with the linear material and the 4-node element, whose stiffness is
    /// affine in the tissues' Lamé parameters.
    pub(crate) fn reduced_form(&self) -> bool {
        !self.solve.model.on_springs()
            && self.tet.material == TetMaterial::Linear
            && self.tet.element == TetElement::Linear
    }

    /// Parse case text (as if from `path`) over the defaults.
    pub fn parse(text: &str, path: &Path) -> Result<Case> {
        Case::parse_with(text, path, &toml::Table::new())
    }

    /// Parse case text over the defaults, then lay `overrides` (`overrides_table`) on top.
    pub(crate) fn parse_with(text: &str, path: &Path, overrides: &toml::Table) -> Result<Case> {
        let mut base: toml::Table = toml::from_str(DEFAULTS_TOML)
            .map_err(|e| Error::config(format!("pipeline/defaults.toml: {e}")))?;
        let mut over: toml::Table =
            toml::from_str(text).map_err(|e| Error::input(path, e.message()))?;
        // Slicer's files in the plan (transform files, markups planes) become plan keys.
        let dir = path.parent().unwrap_or(Path::new(""));
        crate::slicer::resolve_plan_files(&mut over, dir, path)?;
        refuse_retired(&over, path)?;
        refuse_retired(overrides, path)?;
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
    pub(crate) fn load_with(case: &Path, overrides: &toml::Table) -> Result<(Case, PathBuf)> {
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
    pub(crate) fn from_text_with(
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

    /// The regions that may be masks or surfaces: `[surface] movable` and each osteotomy's
    /// region (their files are read by `pipeline::inputs::read_masks`).
    pub(crate) fn regions_mut(&mut self) -> impl Iterator<Item = &mut Region> {
        self.surface
            .movable
            .iter_mut()
            .chain(self.osteotomy.iter_mut().map(|o| &mut o.region))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str = "[ct]\npath = \"ct.nii.gz\"\n";

    /// The minimal case with one `--set KEY=VALUE` laid over it.
    fn with_set(set: &str) -> Result<Case> {
        Case::parse_with(
            MIN,
            Path::new("case.toml"),
            &overrides_table(&[set.to_string()]).unwrap(),
        )
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
    fn degloved_maxilla_and_chin_are_auto_true_or_false_and_nothing_else() {
        let parse = |v: &str| with_set(&format!("tet.degloved_maxilla={v}"));
        assert_eq!(
            Case::parse(MIN, Path::new("case.toml"))
                .unwrap()
                .tet
                .degloved_maxilla,
            Degloved::Off
        );
        assert_eq!(parse("auto").unwrap().tet.degloved_maxilla, Degloved::Auto);
        assert_eq!(parse("true").unwrap().tet.degloved_maxilla, Degloved::On);
        assert_eq!(parse("false").unwrap().tet.degloved_maxilla, Degloved::Off);
        let e = parse("yes").unwrap_err().to_string();
        assert!(
            e.contains("case.toml") && e.contains("true, false or \"auto\""),
            "{e}"
        );
        // As used, in report.json's parameters: the word a user would write.
        let json = |d: Degloved| serde_json::to_string(&d).unwrap();
        assert_eq!(
            (json(Degloved::Auto).as_str(), json(Degloved::On).as_str()),
            ("\"auto\"", "true")
        );
        // `true` refuses what "auto" steps aside from, naming the option; both approaches.
        for option in ["degloved_maxilla", "degloved_chin"] {
            for (off, words) in [
                ("tet.sliding=false", "sliding and release_cuts"),
                ("tet.element=quadratic", "4-node element"),
            ] {
                let e = Case::parse_with(
                    MIN,
                    Path::new("case.toml"),
                    &overrides_table(&[format!("tet.{option}=true"), off.into()]).unwrap(),
                )
                .unwrap_err()
                .to_string();
                assert!(
                    e.contains(&format!("[tet] {option} = true")) && e.contains(words),
                    "{e}"
                );
            }
        }
        assert_eq!(
            Case::parse(MIN, Path::new("case.toml"))
                .unwrap()
                .tet
                .degloved_chin,
            Degloved::Auto
        );
        let c = Case::parse_with(
            MIN,
            Path::new("case.toml"),
            &overrides_table(&["tet.sliding=false".into()]).unwrap(),
        );
        assert!(c.is_ok());
    }

    /// The retired mechanisms' keys (docs/lab/retired-mechanisms.md) are refused in one line
    /// naming case.toml and the key, from the file and from `--set`; a report.json's parameters
    /// written while they existed still read back.
    #[test]
    fn retired_keys_are_refused_naming_case_toml_and_the_key() {
        for (key, value) in [
            ("nose_youngs_kpa", "3000.0"),
            ("nose_base_above_sn_mm", "2.5"),
            ("septum_detached", "false"),
        ] {
            let e = Case::parse(
                &format!("{MIN}[tet]\n{key} = {value}\n"),
                Path::new("case.toml"),
            )
            .unwrap_err()
            .to_string();
            assert!(
                e.starts_with("case.toml")
                    && e.contains(&format!("[tet] {key} is no longer a key"))
                    && e.contains("retired-mechanisms.md"),
                "{e}"
            );
            assert!(!e.contains('\n') && !e.contains("expected one of"), "{e}");
            let e = with_set(&format!("tet.{key}={value}"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("case.toml") && e.contains(key), "{e}");
        }
        let default = Case::parse(MIN, Path::new("case.toml")).unwrap();
        let mut tet = serde_json::to_value(&default.tet).unwrap();
        assert!(RETIRED_TET_KEYS.iter().all(|k| tet.get(k).is_none()));
        let old = tet.as_object_mut().unwrap();
        old.insert("nose_youngs_kpa".into(), 0.0.into());
        old.insert("nose_base_above_sn_mm".into(), 2.5.into());
        old.insert("septum_detached".into(), false.into());
        let old: Tet = serde_json::from_value(tet).unwrap();
        assert_eq!(old.skin, default.tet.skin);
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

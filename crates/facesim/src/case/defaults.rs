//! The defaults of every case.toml key, read from pipeline/defaults.toml (compiled in): a caller
//! builds a case in memory with `Case { ct: CtSection::new(path), ..Case::default() }` and no
//! case.toml.

use super::schema::*;

/// The documented defaults, compiled in so the binary works from any directory.
pub const DEFAULTS_TOML: &str = include_str!("../../../../pipeline/defaults.toml");

// `Case::default()` is derived: every section's default is pipeline/defaults.toml's section,
// so a default is written once, in the file users read.

/// The documented section `name` of pipeline/defaults.toml as its schema type. The file is
/// compiled in and held to the schema by the test below, so a failure here is a build defect.
fn documented<T: serde::de::DeserializeOwned>(name: &str) -> T {
    let table: toml::Table = toml::from_str(DEFAULTS_TOML)
        .unwrap_or_else(|e| panic!("pipeline/defaults.toml (compiled in): {e}"));
    let section = table
        .get(name)
        .cloned()
        .unwrap_or_else(|| panic!("pipeline/defaults.toml (compiled in) has no [{name}]"));
    section
        .try_into()
        .unwrap_or_else(|e| panic!("pipeline/defaults.toml (compiled in), [{name}]: {e}"))
}

macro_rules! documented_default {
    ($($ty:ty => $section:literal),* $(,)?) => {$(
        impl Default for $ty {
            fn default() -> $ty {
                documented($section)
            }
        }
    )*};
}

documented_default! {
    Tissue => "tissue",
    Extract => "extract",
    Springs => "springs",
    Surface => "surface",
    Solve => "solve",
    Tet => "tet",
    Output => "output",
    super::uncertainty::Uncertainty => "uncertainty",
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const MIN: &str = "[ct]\npath = \"ct.nii.gz\"\n";

    #[test]
    fn rust_defaults_equal_defaults_toml() {
        let parsed = Case::parse(MIN, Path::new("case.toml")).unwrap();
        let built = Case {
            ct: CtSection::new("ct.nii.gz"),
            ..Case::default()
        };
        let json = |c: &Case| serde_json::to_value(c).unwrap();
        assert_eq!(json(&built), json(&parsed));
        built.validate(Path::new("in memory")).unwrap();
    }
}

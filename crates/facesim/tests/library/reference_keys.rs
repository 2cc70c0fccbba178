//! docs/reference/case-toml.md against pipeline/defaults.toml: every key with a documented
//! default has exactly one row, whose default is the file's value, and no row documents a default
//! for a key the file does not have (a removed or renamed key would leave one behind).

use std::collections::BTreeMap;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

/// Every leaf of a TOML table as (dotted key, value).
fn leaves(prefix: &str, t: &toml::Table, out: &mut BTreeMap<String, toml::Value>) {
    for (k, v) in t {
        let key = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(inner) => leaves(&key, inner, out),
            _ => {
                out.insert(key, v.clone());
            }
        }
    }
}

/// The page's rows: (key, default cell).
fn rows(page: &str) -> Vec<(String, String)> {
    page.lines()
        .filter(|l| l.starts_with("| `"))
        .map(|l| {
            let cells: Vec<&str> = l.split(" | ").collect();
            let key = cells[0]
                .trim_start_matches("| ")
                .trim_matches('`')
                .to_string();
            (key, cells[1].trim().to_string())
        })
        .collect()
}

fn same(a: &toml::Value, b: &toml::Value) -> bool {
    match (
        a.as_float().or(a.as_integer().map(|i| i as f64)),
        b.as_float().or(b.as_integer().map(|i| i as f64)),
    ) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

#[test]
fn every_defaulted_key_has_one_row_with_the_default_of_defaults_toml() {
    let defaults: toml::Table = std::fs::read_to_string(root().join("pipeline/defaults.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let mut keys = BTreeMap::new();
    leaves("", &defaults, &mut keys);
    assert!(keys.len() > 50, "{} keys", keys.len());
    let page = std::fs::read_to_string(root().join("docs/reference/case-toml.md")).unwrap();
    let rows = rows(&page);
    let mut seen = BTreeMap::new();
    for (key, _) in &rows {
        *seen.entry(key.clone()).or_insert(0) += 1;
    }
    let twice: Vec<_> = seen.iter().filter(|(_, n)| **n > 1).collect();
    assert!(twice.is_empty(), "keys with more than one row: {twice:?}");
    for (key, value) in &keys {
        let Some((_, cell)) = rows.iter().find(|(k, _)| k == key) else {
            panic!("docs/reference/case-toml.md has no row for {key} (default {value})");
        };
        let documented: toml::Table = format!("v = {cell}").parse().unwrap_or_else(|e| {
            panic!("{key}: the default cell {cell:?} is not a TOML value: {e}")
        });
        assert!(
            same(&documented["v"], value),
            "{key}: the page says {cell}, pipeline/defaults.toml {value}"
        );
    }
    // A row in a section defaults.toml fills, with a default of its own, must be one of its keys
    // (the distributions of [uncertainty] are the model's literature defaults, stated in prose).
    let filled: Vec<&str> = defaults.keys().map(String::as_str).collect();
    for (key, cell) in &rows {
        let section = key.split('.').next().unwrap();
        let distribution = key.starts_with("uncertainty.") && !keys.contains_key(key);
        if filled.contains(&section) && cell != "—" && !cell.starts_with("— ") && !distribution
        {
            assert!(
                keys.contains_key(key),
                "docs/reference/case-toml.md documents a default for {key}, which pipeline/defaults.toml does not have"
            );
        }
    }
}

#[test]
fn the_optional_keys_documented_are_ones_the_schema_accepts() {
    // The optional rows' keys, set over a minimal case, parse and pass the range checks.
    let examples: [(&str, &str); 8] = [
        ("name", "name = \"x\""),
        ("ct.axes", "[ct]\npath = \"ct.nii.gz\"\naxes = \"LPS\""),
        (
            "ct.intercept",
            "[ct]\npath = \"ct.nii.gz\"\nintercept = -1024.0",
        ),
        ("dicom.series", "[dicom]\nseries = \"3\""),
        ("skin.path", "[skin]\npath = \"face.ply\""),
        (
            "head.frame",
            "[head]\nframe = \"facial-plane\"\npitch_deg = 2.0",
        ),
        (
            "surgery.kind",
            "[[surgery]]\nkind = \"le-fort-i\"\nadvance_mm = 5.0\nup_mm = 1.0\nleft_mm = 0.5\npitch_deg = 1.0\nroll_deg = 1.0\nyaw_deg = 1.0\npivot = \"U1\"\nautorotate = true\nname = \"mx\"",
        ),
        (
            "osteotomy.name",
            "[[osteotomy]]\nname = \"m\"\nregion = { box = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] } }\ntranslate = [1.0, 0.0, 0.0]\nrotate_deg = [0.0, 0.0, 1.0]\npivot = [0.0, 0.0, 0.0]",
        ),
    ];
    for (key, text) in examples {
        let text = if text.contains("[ct]") {
            text.to_string()
        } else if text.starts_with("name") {
            format!("{text}\n[ct]\npath = \"ct.nii.gz\"")
        } else {
            format!("[ct]\npath = \"ct.nii.gz\"\n{text}")
        };
        if let Err(e) = facesim::case::Case::parse(&text, Path::new("case.toml")) {
            panic!("{key}: the documented keys are refused: {e}\n{text}");
        }
    }
}

//! The code cites only what the repository holds: every `docs/…`, `benches/…`, `pipeline/…` or
//! `data-samples/…` path named in a source file exists, and no source cites design notes outside
//! the repository (their content the code relies on is in docs/reference/case.md and docs/design/pipeline.md).

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            sources(&p, out);
        } else if p
            .extension()
            .is_some_and(|x| x == "rs" || x == "toml" || x == "sh")
        {
            out.push(p);
        }
    }
}

/// Repository paths named in `text`: a known top folder followed by path characters.
fn cited_paths(text: &str) -> Vec<String> {
    let mut found = Vec::new();
    for top in ["docs/", "benches/", "pipeline/", "data-samples/"] {
        let mut from = 0;
        while let Some(i) = text[from..].find(top) {
            let start = from + i;
            from = start + top.len();
            // Only a path that starts the token (not e.g. "../docs/" inside a longer path).
            let before = text[..start].chars().last();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '/' || c == '_' || c == '.') {
                continue;
            }
            let path: String = text[start..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || "/._-".contains(*c))
                .collect();
            let path = path.trim_end_matches(['.', '/']).to_string();
            // A bare folder, or a path built at run time ("data-samples/{name}"), is not a cite.
            if path.contains('.') {
                found.push(path);
            }
        }
    }
    found
}

#[test]
fn cited_repository_files_exist_and_no_design_notes_outside_are_cited() {
    let mut files = Vec::new();
    sources(&root().join("crates"), &mut files);
    sources(&root().join("pipeline"), &mut files);
    assert!(files.len() > 50, "found only {} source files", files.len());
    let mut missing = Vec::new();
    let mut outside = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        for p in cited_paths(&text) {
            if !root().join(&p).exists() {
                missing.push(format!("{}: {p}", f.display()));
            }
        }
        for (n, line) in text.lines().enumerate() {
            if line.contains("MODEL.md")
                || line.contains("CASE.md")
                || line.contains("shared/design")
            {
                outside.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
            }
        }
    }
    // This file names the patterns it looks for; skip its own lines.
    outside.retain(|l| !l.contains("references.rs"));
    assert!(
        missing.is_empty(),
        "cited files that do not exist:\n{}",
        missing.join("\n")
    );
    assert!(
        outside.is_empty(),
        "sources cite design notes outside the repository (cite docs/ instead):\n{}",
        outside.join("\n")
    );
}

#[test]
fn the_reference_finder_finds_paths_and_skips_folders() {
    assert_eq!(
        cited_paths(
            "see docs/design/pipeline.md §1 and (benches/cholmod_compare.sh), docs/ and ../x/docs/a.md"
        ),
        ["docs/design/pipeline.md", "benches/cholmod_compare.sh"]
    );
}

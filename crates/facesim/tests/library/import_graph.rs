//! The import-cycle check (docs/design/architecture.md "Import cycles"): reads
//! crates/facesim/src/**/*.rs, builds the graph of which module file uses which, and fails
//! naming the cycle when (a) top-level modules form a cycle or (b) files do, unless the cycle
//! is in [`ALLOWED_MODULE_CYCLES`] / [`ALLOWED_FILE_CYCLES`]. An allowed cycle that no longer
//! exists fails too, so the lists only shrink.
//!
//! An edge is a path in code (comments and strings are skipped): `crate::a::b`, `super::x`,
//! `self::x`, a `use` tree under them (`use crate::{a, b::c}`), and a bare path starting with a
//! child module of the file's module (`inputs::read` in crates/facesim/src/pipeline/mod.rs). A path resolves to
//! the longest prefix that is a module file. Paths inside inline `mod … { }` blocks resolve
//! from that block; `#[cfg(test)] mod … { }` blocks are skipped (test code is not the library's
//! layering). Paths that
//! only go through a re-export or a `use` alias are seen at the `use`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Top-level modules still in a cycle, each a strongly connected set. Remove an entry when
/// the work it names lands (the test says when one no longer exists).
const ALLOWED_MODULE_CYCLES: &[&[&str]] = &[];

/// Files still in a cycle, each a strongly connected set (module paths). None: a folder's
/// shared types live in a child file its siblings take them from (mesh's `surface.rs`,
/// volume's `grid.rs`, landmarks' `landmark.rs`, model's `predicted.rs`, the volumetric model's
/// `state.rs`, the pipeline's `stage.rs`, the C1 solve's `problem.rs`), and its mod.rs only
/// declares, re-exports and dispatches.
const ALLOWED_FILE_CYCLES: &[&[&str]] = &[];

/// Module path (`pipeline::inputs`; `crate` for lib.rs) → file, for every file under `src`.
fn module_files(src: &Path) -> BTreeMap<String, PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(src, &mut files);
    files
        .into_iter()
        .filter_map(|f| {
            let rel = f.strip_prefix(src).unwrap().with_extension("");
            let mut parts: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if parts.last().is_some_and(|p| p == "mod") {
                parts.pop();
            }
            if parts == ["lib"] {
                return Some(("crate".to_string(), f));
            }
            // Binaries and other roots are not modules of the library.
            if parts.first().is_some_and(|p| p == "bin" || p == "main") {
                return None;
            }
            // A file its parent declares `#[cfg(test)] mod name;` is test code, as a
            // `#[cfg(test)] mod … { }` block is.
            if test_only(&f) {
                return None;
            }
            Some((parts.join("::"), f))
        })
        .collect()
}

/// Whether the module file `f` is declared `#[cfg(test)] mod name;` by its parent (the
/// sibling mod.rs, or the file named like its folder).
fn test_only(f: &Path) -> bool {
    let name = f.file_stem().unwrap().to_string_lossy().into_owned();
    if name == "mod" || name == "lib" {
        return false;
    }
    let dir = f.parent().unwrap();
    let parents = [
        dir.join("mod.rs"),
        dir.join("lib.rs"),
        dir.with_extension("rs"),
    ];
    parents.iter().any(|p| {
        std::fs::read_to_string(p).is_ok_and(|text| {
            let toks = tokens(&text);
            toks.windows(10)
                .any(|w| w.join("") == format!("#[cfg(test)]mod{name};"))
        })
    })
}

/// The code of a Rust file as tokens: identifiers, `::` and single punctuation, with comments,
/// string and char literals and lifetimes dropped.
fn tokens(text: &str) -> Vec<String> {
    let c: Vec<char> = text.chars().collect();
    let (mut i, mut out) = (0, Vec::new());
    while i < c.len() {
        let ch = c[i];
        if ch == '/' && c.get(i + 1) == Some(&'/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && c.get(i + 1) == Some(&'*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if ch == 'r' && (c.get(i + 1) == Some(&'"') || c.get(i + 1) == Some(&'#')) {
            // A raw string r"…" / r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while c.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if c.get(j) != Some(&'"') {
                out.push("r".into());
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= c.len() {
                    break;
                }
                if c[j] == '"' && (0..hashes).all(|k| c.get(j + 1 + k) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            i = j;
        } else if ch == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
        } else if ch == '\'' {
            // A char literal ('x', '\n', '\u{..}') or a lifetime ('a).
            if c.get(i + 1) == Some(&'\\') {
                i += 3;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if c.get(i + 2) == Some(&'\'') {
                i += 3;
            } else {
                i += 1;
                while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                    i += 1;
                }
            }
        } else if ch.is_alphabetic() || ch == '_' {
            let s = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            out.push(c[s..i].iter().collect());
        } else if ch == ':' && c.get(i + 1) == Some(&':') {
            out.push("::".into());
            i += 2;
        } else if ch.is_whitespace() || ch.is_ascii_digit() {
            i += 1;
        } else {
            out.push(ch.to_string());
            i += 1;
        }
    }
    out
}

fn is_ident(t: &str) -> bool {
    t.chars()
        .next()
        .is_some_and(|c| c.is_alphabetic() || c == '_')
}

/// Every module path a file names: (absolute path segments) per path or use-tree leaf.
fn named_paths(
    toks: &[String],
    module: &[String],
    modules: &BTreeMap<String, PathBuf>,
) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    // The inline module blocks open at each point: (their path, the brace depth they close at,
    // whether they are `#[cfg(test)]`).
    let mut scope: Vec<(Vec<String>, usize, bool)> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < toks.len() {
        let here = scope
            .last()
            .map_or_else(|| module.to_vec(), |(p, _, _)| p.clone());
        let in_test = scope.iter().any(|(_, _, test)| *test);
        let t = toks[i].as_str();
        match t {
            "{" => depth += 1,
            "}" => {
                if scope.last().is_some_and(|(_, d, _)| *d == depth) {
                    scope.pop();
                }
                depth = depth.saturating_sub(1);
            }
            "mod" if toks.get(i + 2).is_some_and(|x| x == "{") => {
                let mut p = here.clone();
                p.push(toks[i + 1].clone());
                let test = i >= 7 && toks[i - 7..i].join("") == "#[cfg(test)]";
                scope.push((p, depth + 1, test));
            }
            _ => {}
        }
        let prev_is_sep = i > 0 && toks[i - 1] == "::";
        let starts = !prev_is_sep && toks.get(i + 1).is_some_and(|x| x == "::");
        let base: Option<Vec<String>> = match t {
            "crate" if starts => Some(Vec::new()),
            "self" if starts => Some(here.clone()),
            "super" if starts => {
                let mut p = here.clone();
                p.pop();
                Some(p)
            }
            _ if starts && is_ident(t) => {
                // A child module of the current one named bare.
                let mut p = here.clone();
                p.push(t.to_string());
                modules.contains_key(&p.join("::")).then_some(here.clone())
            }
            _ => None,
        };
        let Some(mut base) = base else {
            i += 1;
            continue;
        };
        let keyword = matches!(t, "crate" | "self" | "super");
        // After a keyword the tree starts at its `::`; a bare child's name is its first segment.
        let mut j = if keyword { i + 1 } else { i };
        // `super::super::…`
        if t == "super" {
            while toks.get(j).is_some_and(|x| x == "::")
                && toks.get(j + 1).is_some_and(|x| x == "super")
            {
                base.pop();
                j += 2;
            }
        }
        let (paths, end) = tree(toks, j, &base, !keyword);
        if !in_test {
            out.extend(paths);
        }
        i = end.max(i + 1);
    }
    out
}

/// Parse a path or use tree at `toks[j]` (at `::` after a root keyword, or at the first
/// segment when `at_segment`): the leaf paths below `base`, and where it ended.
fn tree(
    toks: &[String],
    mut j: usize,
    base: &[String],
    at_segment: bool,
) -> (Vec<Vec<String>>, usize) {
    let mut path = base.to_vec();
    let mut first = at_segment;
    loop {
        if !first {
            if toks.get(j).map(String::as_str) != Some("::") {
                return (vec![path], j);
            }
            j += 1;
        }
        first = false;
        match toks.get(j).map(String::as_str) {
            Some("{") => {
                j += 1;
                let mut out = Vec::new();
                loop {
                    match toks.get(j).map(String::as_str) {
                        Some("}") | None => return (out, j + 1),
                        Some(",") => j += 1,
                        Some("self") => {
                            out.push(path.clone());
                            j += 1;
                        }
                        Some("*") => {
                            out.push(path.clone());
                            j += 1;
                        }
                        Some("as") => j += 2, // `x as y`: the rename
                        Some(s) if is_ident(s) => {
                            let (p, e) = tree(toks, j, &path, true);
                            out.extend(p);
                            j = e.max(j + 1);
                        }
                        Some(_) => j += 1, // `as`, renames and the like
                    }
                }
            }
            Some("*") => return (vec![path], j + 1),
            Some(s) if is_ident(s) && s != "as" => {
                path.push(s.to_string());
                j += 1;
            }
            _ => return (vec![path], j),
        }
    }
}

/// The file module a path lands in: its longest prefix that is a module file.
fn resolve(path: &[String], modules: &BTreeMap<String, PathBuf>) -> Option<String> {
    (1..=path.len())
        .rev()
        .map(|n| path[..n].join("::"))
        .find(|m| modules.contains_key(m))
}

type Graph = BTreeMap<String, BTreeSet<String>>;

/// The file graph (module path → module paths it names) of the library.
fn file_graph() -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let modules = module_files(&src);
    let mut g = Graph::new();
    for (m, f) in &modules {
        let text = std::fs::read_to_string(f).unwrap();
        let module: Vec<String> = if m == "crate" {
            Vec::new()
        } else {
            m.split("::").map(str::to_string).collect()
        };
        let edges = g.entry(m.clone()).or_default();
        for p in named_paths(&tokens(&text), &module, &modules) {
            if let Some(to) = resolve(&p, &modules)
                && to != *m
            {
                edges.insert(to);
            }
        }
    }
    g
}

/// The top-level module graph: each file's edges between the first segments of the paths.
fn module_graph(files: &Graph) -> Graph {
    let top = |m: &str| m.split("::").next().unwrap_or(m).to_string();
    let mut g = Graph::new();
    for (from, tos) in files {
        let e = g.entry(top(from)).or_default();
        for to in tos {
            if top(to) != top(from) && to != "crate" && from != "crate" {
                e.insert(top(to));
            }
        }
    }
    g
}

/// Strongly connected components with more than one member (Tarjan), each sorted.
fn cycles(g: &Graph) -> BTreeSet<Vec<String>> {
    struct T<'a> {
        g: &'a Graph,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        out: BTreeSet<Vec<String>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a str) {
        let n = t.index.len();
        t.index.insert(v, n);
        t.low.insert(v, n);
        t.stack.push(v);
        t.on.insert(v);
        for w in t.g.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !t.index.contains_key(w) {
                visit(t, w);
                let l = t.low[w].min(t.low[v]);
                t.low.insert(v, l);
            } else if t.on.contains(w) {
                let l = t.index[w].min(t.low[v]);
                t.low.insert(v, l);
            }
        }
        if t.low[v] == t.index[v] {
            let mut c = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on.remove(w);
                c.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if c.len() > 1 {
                c.sort();
                t.out.insert(c);
            }
        }
    }
    let mut t = T {
        g,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: BTreeSet::new(),
    };
    for v in g.keys() {
        if !t.index.contains_key(v.as_str()) {
            visit(&mut t, v);
        }
    }
    t.out
}

/// One concrete cycle through `set`'s first member (for naming it in a failure).
fn one_cycle(g: &Graph, set: &[String]) -> String {
    let inside: BTreeSet<&str> = set.iter().map(String::as_str).collect();
    let start = set[0].as_str();
    // Breadth-first back to `start` inside the set.
    let mut prev: BTreeMap<&str, &str> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(v) = queue.pop_front() {
        for w in g.get(v).into_iter().flatten().map(String::as_str) {
            if !inside.contains(w) {
                continue;
            }
            if w == start {
                let mut path = vec![v];
                let mut x = v;
                while let Some(p) = prev.get(x) {
                    path.push(p);
                    x = p;
                }
                path.reverse();
                if path[0] != start {
                    path.insert(0, start);
                }
                path.push(start);
                return path.join(" → ");
            }
            if !prev.contains_key(w) && w != start {
                prev.insert(w, v);
                queue.push_back(w);
            }
        }
    }
    set.join(", ")
}

/// The difference between found and allowed cycles, as failure lines.
fn check(g: &Graph, allowed: &[&[&str]], what: &str) -> Vec<String> {
    let found = cycles(g);
    let allowed: BTreeSet<Vec<String>> = allowed
        .iter()
        .map(|c| {
            let mut v: Vec<String> = c.iter().map(|s| s.to_string()).collect();
            v.sort();
            v
        })
        .collect();
    let mut bad = Vec::new();
    for c in found.difference(&allowed) {
        bad.push(format!(
            "{what} cycle not allowed: {} (members: {})",
            one_cycle(g, c),
            c.join(", ")
        ));
    }
    for c in allowed.difference(&found) {
        bad.push(format!(
            "allowed {what} cycle no longer exists (remove or shrink its entry): {}",
            c.join(", ")
        ));
    }
    bad
}

#[test]
fn no_import_cycles_beyond_the_allowed_list() {
    let files = file_graph();
    assert!(files.len() > 50, "read {} files only", files.len());
    let modules = module_graph(&files);
    let mut bad = check(&modules, ALLOWED_MODULE_CYCLES, "top-level module");
    bad.extend(check(&files, ALLOWED_FILE_CYCLES, "file"));
    assert!(bad.is_empty(), "\n{}", bad.join("\n"));
}

#[test]
fn the_parser_sees_paths_use_trees_and_skips_comments() {
    let modules: BTreeMap<String, PathBuf> = ["crate", "a", "a::b", "c", "d", "e"]
        .iter()
        .map(|m| (m.to_string(), PathBuf::new()))
        .collect();
    let text = r#"
        // use crate::e;   (a comment)
        /* crate::e */
        use crate::{c, a::b::{Thing, self}};
        use super::d as D;
        fn f() { let s = "crate::e"; crate::d::g(); b::h(); }
        mod inner { use super::*; }
        #[cfg(test)]
        mod tests { use crate::e; }
    "#;
    let module = vec!["a".to_string()];
    let got: BTreeSet<String> = named_paths(&tokens(text), &module, &modules)
        .iter()
        .filter_map(|p| resolve(p, &modules))
        .collect();
    let want: BTreeSet<String> = ["c", "a::b", "d", "a"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(got, want);
    // A cycle is found and named.
    let g: Graph = [("x", "y"), ("y", "z"), ("z", "x"), ("z", "w")]
        .iter()
        .fold(Graph::new(), |mut g, (a, b)| {
            g.entry(a.to_string()).or_default().insert(b.to_string());
            g
        });
    let c = cycles(&g);
    assert_eq!(c.len(), 1);
    let named = one_cycle(&g, c.iter().next().unwrap());
    assert_eq!(named, "x → y → z → x");
}

//! Running the `facesim` binary in tests, and what a clean failure looks like (one line naming
//! the file and the problem).
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

pub struct CliResult {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

pub fn facesim(args: &[&str]) -> CliResult {
    let out = Command::new(env!("CARGO_BIN_EXE_facesim"))
        .args(args)
        .output()
        .unwrap();
    CliResult {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// `facesim phantom DIR --anatomy jaws --nose hollow --spacing 2` and `more` options: the jaws
/// head with a CT's hollow nose (docs/design/phantom.md "Nasal passages"); asserts it was written.
pub fn hollow_jaws_phantom(dir: &Path, more: &[&str]) {
    let head = [
        "phantom",
        dir.to_str().unwrap(),
        "--anatomy",
        "jaws",
        "--nose",
        "hollow",
        "--spacing",
        "2",
    ];
    let r = facesim(&[&head[..], more].concat());
    assert_eq!(r.code, 0, "{}", r.stderr);
}

/// Assert the CLI failed with one line on stderr that names `file` and contains `problem`.
pub fn assert_clean_failure(r: &CliResult, file: &str, problem: &str) {
    assert_ne!(r.code, 0, "expected failure, got success: {}", r.stdout);
    let lines: Vec<&str> = r.stderr.lines().collect();
    assert_eq!(
        lines.len(),
        1,
        "expected one error line, got: {:?}",
        r.stderr
    );
    assert!(
        lines[0].contains(file),
        "error does not name {file}: {}",
        lines[0]
    );
    assert!(
        lines[0].to_lowercase().contains(&problem.to_lowercase()),
        "error does not say '{problem}': {}",
        lines[0]
    );
    assert!(!lines[0].contains("internal error"), "{}", lines[0]);
}

/// `facesim run CASE --out OUT --set …` (each of `sets` a KEY=VALUE), which must exit 0; its
/// report.json.
pub fn run_ok(case: &Path, out: &Path, sets: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "run",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    for s in sets {
        args.extend(["--set", s]);
    }
    let r = facesim(&args);
    assert_eq!(r.code, 0, "facesim run {sets:?} failed: {}", r.stderr);
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

/// displacement.csv's pre and post positions per face vertex (columns x_pre.. and x_post..).
pub fn face_positions(out: &Path) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let csv = std::fs::read_to_string(out.join("displacement.csv")).unwrap();
    csv.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            ([v[1], v[2], v[3]], [v[4], v[5], v[6]])
        })
        .unzip()
}

/// A CSV file as maps column → value (a small quoted-CSV reader: fields may hold commas).
pub fn read_csv(path: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let split = |line: &str| -> Vec<String> {
        let (mut out, mut cur, mut quoted, mut chars) =
            (Vec::new(), String::new(), false, line.chars().peekable());
        while let Some(c) = chars.next() {
            match (c, quoted) {
                ('"', true) if chars.peek() == Some(&'"') => {
                    cur.push('"');
                    chars.next();
                }
                ('"', _) => quoted = !quoted,
                (',', false) => out.push(std::mem::take(&mut cur)),
                _ => cur.push(c),
            }
        }
        out.push(cur);
        out
    };
    let mut lines = text.lines();
    let head = split(lines.next().unwrap());
    lines
        .map(|l| {
            let f = split(l);
            assert_eq!(f.len(), head.len(), "{l}");
            head.iter().cloned().zip(f).collect()
        })
        .collect()
}

//! Running the `facesim` binary in tests, and what a clean failure looks like (one line naming
//! the file and the problem).
#![allow(dead_code)]

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

//! `facesim --help` is a table of contents: one line per command, each short enough for an
//! 100-column terminal; the details are under `facesim CMD --help`. The lab's commands are not
//! the product's (`facesim bench` is only the cross-check against CalculiX).

use crate::cli;

use cli::facesim;

/// The commands listed by `--help`: (name, its one-line summary).
fn commands(help: &str) -> Vec<(String, String)> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .map(|l| {
            let l = l.trim_start();
            let (name, rest) = l.split_once(' ').unwrap_or((l, ""));
            (name.to_string(), rest.trim().to_string())
        })
        .collect()
}

#[test]
fn help_gives_one_short_line_per_command_and_details_under_each_command() {
    let r = facesim(&["--help"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let listed = commands(&r.stdout);
    let names: Vec<&str> = listed.iter().map(|(n, _)| n.as_str()).collect();
    for expected in [
        "run",
        "estimate",
        "replan",
        "sweep",
        "landmarks",
        "validate",
        "phantom",
        "inspect",
    ] {
        assert!(names.contains(&expected), "{expected} missing: {names:?}");
    }
    // The lab's benchmarks and study are `facesim-lab`'s. `facesim bench` holds only the
    // product's own comparison with the peer engine, `crosscheck`.
    assert!(
        !names.contains(&"study"),
        "the lab's study is listed: {names:?}"
    );
    let bench = facesim(&["bench", "--help"]);
    assert_eq!(bench.code, 0, "{}", bench.stderr);
    let benches: Vec<String> = commands(&bench.stdout)
        .into_iter()
        .map(|(n, _)| n)
        .filter(|n| n != "help")
        .collect();
    assert_eq!(benches, ["crosscheck"], "{}", bench.stdout);
    for line in r.stdout.lines() {
        assert!(
            line.chars().count() <= 100,
            "a --help line of {} characters: {line}",
            line.chars().count()
        );
    }
    for (name, summary) in &listed {
        assert!(!summary.is_empty(), "{name}: no summary");
        if name == "help" {
            continue;
        }
        // The command's own help says more than its summary line.
        let own = facesim(&[name, "--help"]);
        assert_eq!(own.code, 0, "{name}: {}", own.stderr);
        assert!(
            own.stdout.contains(summary.trim_end_matches('.')),
            "{name} --help does not start from its summary: {}",
            own.stdout
        );
    }
    let run = facesim(&["run", "--help"]);
    assert!(run.stdout.contains("report.html"), "{}", run.stdout);
}

//! `facesim bench crosscheck` (docs/design/crosscheck.md "Speed against CalculiX"): the run and
//! CalculiX's solve of the mesh it built are both timed, and the two answers agree at the free
//! nodes far below the 1e-6 the command demands; a bad option is one line and writes nothing.

use std::process::Command;

fn facesim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_facesim"))
}

#[test]
fn crosscheck_times_the_run_beside_calculix_and_the_answers_agree() {
    let ct = crate::common::real_ct();
    let real = ct.parent().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cc");
    let o = facesim()
        .args(["--threads", "2", "bench", "crosscheck"])
        .arg(real)
        .arg("--out")
        .arg(&out)
        .args(["--repeat", "1"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    println!("{stdout}");
    let c: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("crosscheck.json")).unwrap()).unwrap();
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("run/report.json")).unwrap()).unwrap();
    // CalculiX was given the very mesh of the run, and solved it.
    assert_eq!(c["nodes"], r["tet"]["nodes"]);
    assert_eq!(c["cells"], r["tet"]["tets"]);
    assert_eq!(c["element"], "C3D4");
    assert!(c["free_nodes"].as_u64().unwrap() > 1000);
    // Its answer at the free nodes is facesim's: both solve the same linear system exactly.
    let agreement = c["agreement"].as_f64().unwrap();
    assert!(agreement < 1e-9, "{agreement:e}");
    let (run, ccx) = (&c["facesim_run"], &c["calculix_solve"]);
    let (tr, tc) = (
        run["median_wall_s"].as_f64().unwrap(),
        ccx["median_wall_s"].as_f64().unwrap(),
    );
    assert!(tr > 0.0 && tc > 0.0);
    assert!((c["ratio_wall"].as_f64().unwrap() - tr / tc).abs() < 1e-12);
    assert!(run["cpu_s"][0].as_f64().unwrap() > 0.0);
    assert!(ccx["cpu_s"][0].as_f64().unwrap() > 0.0);
    assert!(stdout.contains("ratio (facesim ÷ CalculiX)"), "{stdout}");
}

#[test]
fn crosscheck_without_a_repeat_is_one_line_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cc");
    let o = facesim()
        .args([
            "bench",
            "crosscheck",
            "data-samples/real",
            "--repeat",
            "0",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--repeat"), "{err}");
    assert!(!out.exists());
}

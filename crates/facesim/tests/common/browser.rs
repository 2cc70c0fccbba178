//! Driving report.html in headless Chromium (web/test/page.test.mjs) for the browser tests.
#![allow(dead_code)]

use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::Command;

pub fn web_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../web")
}

/// Run the page script on `html` with `plans`; the screenshot is kept as `target/test-artefacts/NAME`.
pub fn drive(html: &Path, plans: &Value, name: &str) -> Value {
    let chromium = std::env::var("FACESIM_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    let node_ok = Command::new("node").arg("--version").output().is_ok();
    assert!(
        node_ok && Path::new(&chromium).is_file() && web_dir().join("node_modules").is_dir(),
        "report.html's browser test needs node, {chromium} and web/node_modules: run scripts/test-setup.sh"
    );
    let dir = html.parent().unwrap();
    let plans_file = dir.join("plans.json");
    std::fs::write(&plans_file, plans.to_string()).unwrap();
    let out = dir.join("browser.json");
    let shot = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("../test-artefacts")
        .join(name);
    let run = Command::new("node")
        .current_dir(web_dir())
        .arg("test/page.test.mjs")
        .args([html, &plans_file, &out, &shot])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "page.test.mjs failed: {}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(shot.is_file(), "no screenshot at {}", shot.display());
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    for k in ["console_errors", "page_errors", "outside_requests"] {
        assert_eq!(r[k], json!([]), "{k} in {}", html.display());
    }
    // The canvas shows something: a good share of drawn pixels in many shades.
    let c = &r["canvas_final"];
    let (px, drawn, colours) = (
        c["pixels"].as_f64().unwrap(),
        c["drawn"].as_f64().unwrap(),
        c["colours"].as_f64().unwrap(),
    );
    assert!(
        drawn > 0.05 * px && colours > 100.0,
        "blank canvas: {c} (screenshot {})",
        shot.display()
    );
    // Slider frames draw the static skull from a cached picture (web/src/frame_cache.js): in
    // Chromium the cache is used, and its frames equal frames drawn whole, pixel for pixel.
    let cache = &r["cache_check"];
    if !cache.is_null() {
        assert_eq!(
            cache["frame_cache"],
            json!(true),
            "the frame cache is off: {cache}"
        );
        assert!(
            cache["frames"].as_u64().unwrap() > 0,
            "no frame compared: {cache}"
        );
        assert_eq!(
            cache["differing"],
            json!(0),
            "cached frames differ from whole ones: {cache}"
        );
    }
    r
}

pub fn flat(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

pub fn max_diff(page: &[f64], expected: &[[f64; 3]]) -> f64 {
    assert_eq!(page.len(), 3 * expected.len());
    expected
        .iter()
        .flatten()
        .zip(page)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

// Drives report.html's plan in the clinical frame for crates/facesim/tests/library/report_page.rs:
//   node test/clinical.test.mjs REPORT.html STEPS.json OUT.json SCREENSHOT.png
// First, as the page opens (the default view): info(), frame(), viewFrame(), the sliders
// (sliders()), camera(), landmarks(), each landmark label's box and whether it is shown, and a
// screenshot. Then STEPS.json, a list of [api, argument] (e.g. ["setPlanClinical", {...}],
// ["setPlan", {...}]): after each, the error it threw (or null), faceVertices(), planMatrices(),
// sliders() and landmarks(). The Rust test judges.
import { openReport } from "./browser.mjs";
import { readFileSync, writeFileSync, mkdirSync } from "node:fs";
import { dirname } from "node:path";

const [html, stepsFile, outFile, shot] = process.argv.slice(2);
const steps = JSON.parse(readFileSync(stepsFile, "utf8"));
const { browser, page, problems } = await openReport(html, { width: 1000, height: 700 });
try {
  const result = await page.evaluate(() => {
    const api = window.facesim;
    const view = document.getElementById("view").getBoundingClientRect();
    const labels = {};
    for (const e of document.querySelectorAll("#labels .lm")) {
      const r = e.getBoundingClientRect();
      labels[e.dataset.label] = { shown: !e.hidden && r.width > 0, box: [r.left - view.left, r.top - view.top, r.width, r.height] };
    }
    return {
      info: api.info(),
      frame: api.frame(),
      view_frame: api.viewFrame(),
      sliders: api.sliders(),
      slider_labels: [...document.querySelectorAll("#plan label.slider")].map((l) => l.firstChild.textContent.trim()),
      camera: api.camera(),
      landmarks: api.landmarks(),
      labels,
    };
  });
  mkdirSync(dirname(shot), { recursive: true });
  await page.screenshot({ path: shot });
  result.steps = [];
  for (const [fn, arg] of steps) {
    const r = await page.evaluate(
      (fn, arg) => {
        const api = window.facesim;
        let error = null;
        try {
          api[fn](arg);
        } catch (e) {
          error = String(e.message || e);
        }
        return { error, vertices: api.faceVertices(), matrices: api.planMatrices(), sliders: api.sliders(), landmarks: api.landmarks() };
      },
      fn,
      arg,
    );
    result.steps.push(r);
  }
  Object.assign(result, problems);
  writeFileSync(outFile, JSON.stringify(result));
} finally {
  await browser.close();
}

// Drives report.html in headless Chromium for crates/facesim/tests/library/report_page.rs:
//   node test/page.test.mjs REPORT.html PLANS.json OUT.json SCREENSHOT.png
// PLANS.json is a list of plans; OUT.json gets the problems seen (console errors, page errors,
// requests leaving the file), canvas statistics, faceVertices() before any plan and after each
// setPlan (with landmarks() and regions()), the page's info(), and the frame cache check: a slider frame drawn with the static skull
// from the cache against the same frame drawn whole (pixels that differ). The Rust test judges them.
import { openReport, canvasStats } from "./browser.mjs";
import { readFileSync, writeFileSync, mkdirSync } from "node:fs";
import { dirname } from "node:path";

const [html, plansFile, outFile, shot] = process.argv.slice(2);
const plans = JSON.parse(readFileSync(plansFile, "utf8"));
const { browser, page, problems } = await openReport(html);
try {
  const result = { info: await page.evaluate(() => window.facesim.info()), frame: await page.evaluate(() => window.facesim.frame()) };
  result.canvas_initial = await canvasStats(page);
  result.vertices_initial = await page.evaluate(() => window.facesim.faceVertices());
  result.vertices = [];
  result.set_plan_errors = [];
  result.landmarks = [];
  result.regions = [];
  for (const p of plans) {
    try {
      await page.evaluate((p) => window.facesim.setPlan(p), p);
    } catch (e) {
      result.set_plan_errors.push(String(e.message || e));
    }
    result.vertices.push(await page.evaluate(() => window.facesim.faceVertices()));
    result.landmarks.push(await page.evaluate(() => window.facesim.landmarks()));
    result.regions.push(await page.evaluate(() => window.facesim.regions()));
  }
  result.cache_check = await page.evaluate((plans) => {
    const api = window.facesim;
    if (!api.info().basis) return null;
    const gl = document.querySelector("#view canvas").getContext("webgl2");
    const pixels = () => {
      const px = new Uint8Array(gl.drawingBufferWidth * gl.drawingBufferHeight * 4);
      gl.readPixels(0, 0, gl.drawingBufferWidth, gl.drawingBufferHeight, gl.RGBA, gl.UNSIGNED_BYTE, px);
      return px;
    };
    // The static skull is what the cache holds: show it (seen through the skin).
    const skull = document.getElementById("skull");
    if (!skull.checked) skull.click();
    const out = { frame_cache: api.info().frame_cache, frames: 0, differing: 0 };
    for (const p of plans) {
      try {
        api.options.cache = true;
        api.setPlan(p); // (re)fills the cache when the view changed
        api.setPlan(p); // drawn from it
        const cached = pixels();
        api.options.cache = false;
        api.setPlan(p);
        const whole = pixels();
        out.frames++;
        for (let k = 0; k < whole.length; k++) if (cached[k] !== whole[k]) out.differing++;
      } catch {
        // an unknown segment: refused, as checked above
      }
    }
    api.options.cache = true;
    return out;
  }, plans);
  // With an uncertainty band: colour by it, and back.
  result.band_shown = await page.evaluate(() => {
    const box = document.getElementById("band");
    if (!box) return null;
    box.click();
    window.facesim.render();
    const title = document.querySelector("#legend .title").textContent;
    box.click();
    return title;
  });
  // The "against the clinic" table: each row's class (inside / outside / unmeasured) and text.
  result.clinic = await page.evaluate(() =>
    Array.from(document.querySelectorAll("table.clinic tr")).map((tr) => [tr.className, tr.textContent]),
  );
  // The Sobol table (rows: label, cells; the bold cell's column) and the certificate line.
  result.sensitivity = await page.evaluate(() =>
    Array.from(document.querySelectorAll("table.sensitivity tbody tr")).map((tr) => [
      tr.children[0].textContent,
      Array.from(tr.children).slice(1).map((c) => c.textContent),
      Array.from(tr.children).findIndex((c) => c.classList.contains("top")),
    ]),
  );
  result.certified = await page.evaluate(() => document.querySelector("p.certified")?.textContent ?? null);
  // The full-resolution frame that follows a drag, drawn now rather than after its delay.
  await page.evaluate(() => window.facesim.render());
  result.canvas_final = await canvasStats(page);
  mkdirSync(dirname(shot), { recursive: true });
  await page.screenshot({ path: shot });
  Object.assign(result, problems);
  writeFileSync(outFile, JSON.stringify(result));
} finally {
  await browser.close();
}

// Drives report.html in headless Chromium for crates/facesim/tests/report_page.rs:
//   node test/page.test.mjs REPORT.html PLANS.json OUT.json SCREENSHOT.png
// PLANS.json is a list of plans; OUT.json gets the problems seen (console errors, page errors,
// requests leaving the file), canvas statistics, faceVertices() before any plan and after each
// setPlan, and the page's info(). The Rust test judges them.
import { openReport, canvasStats } from "./browser.mjs";
import { readFileSync, writeFileSync, mkdirSync } from "node:fs";
import { dirname } from "node:path";

const [html, plansFile, outFile, shot] = process.argv.slice(2);
const plans = JSON.parse(readFileSync(plansFile, "utf8"));
const { browser, page, problems } = await openReport(html);
try {
  const result = { info: await page.evaluate(() => window.facesim.info()) };
  result.canvas_initial = await canvasStats(page);
  result.vertices_initial = await page.evaluate(() => window.facesim.faceVertices());
  result.vertices = [];
  result.set_plan_errors = [];
  for (const p of plans) {
    try {
      await page.evaluate((p) => window.facesim.setPlan(p), p);
    } catch (e) {
      result.set_plan_errors.push(String(e.message || e));
    }
    result.vertices.push(await page.evaluate(() => window.facesim.faceVertices()));
  }
  result.canvas_final = await canvasStats(page);
  mkdirSync(dirname(shot), { recursive: true });
  await page.screenshot({ path: shot });
  Object.assign(result, problems);
  writeFileSync(outFile, JSON.stringify(result));
} finally {
  await browser.close();
}

// Screenshots of a report.html for docs/guide/report-page.md (docs/img/report-*.png):
//   node test/shots.mjs REPORT.html OUT_PREFIX
// writes OUT_PREFIX-profile.png (the page as it opens), OUT_PREFIX-three-quarter-both.png and
// OUT_PREFIX-front-before.png, 1000 × 700 CSS px; with tissue sliders (a run with the reduced
// model) also OUT_PREFIX-tissue.png: muscle/fat and skin/fat moved, the panel scrolled to them.
import { openReport } from "./browser.mjs";

const [html, prefix] = process.argv.slice(2);
const { browser, page, problems } = await openReport(html, { width: 1000, height: 700 });
try {
  const shot = async (view, mode, name) => {
    await page.evaluate((v, m) => {
      window.facesim.setView(v);
      window.facesim.setMode(m);
      window.facesim.settle();
    }, view, mode);
    await page.screenshot({ path: `${prefix}-${name}.png` });
  };
  await shot("profile-right", "after", "profile");
  await shot("three-quarter", "both", "three-quarter-both");
  await shot("front", "before", "front-before");
  if (await page.evaluate(() => window.facesim.info().tissue)) {
    await page.evaluate(() => {
      const move = (key, v) => {
        const r = document.querySelector(`input[data-tissue=${key}]`);
        if (!r) return;
        r.value = String(v);
        r.dispatchEvent(new Event("input"));
      };
      move("muscle_fat", 190);
      move("skin_fat", 10);
      window.facesim.setTissue({});
      window.facesim.setView("profile-right");
      window.facesim.setMode("both");
      window.facesim.settle();
      document.getElementById("tissue").scrollIntoView();
    });
    await page.screenshot({ path: `${prefix}-tissue.png` });
  }
  const bad = Object.values(problems).flat();
  if (bad.length > 0) throw new Error(`the page reported problems: ${JSON.stringify(problems)}`);
} finally {
  await browser.close();
}

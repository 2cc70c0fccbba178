// Drives report.html's views for crates/facesim/tests/library/report_page.rs (the Rust test judges):
//   node test/views.test.mjs REPORT.html PLAN.json OUT.json SHOT_DIR
// For each view (front, profile right / left, three-quarter) and face (before, after, both): a
// screenshot SHOT_DIR/VIEW-FACE.png, the camera (position, target, up, fov, CSS size), the canvas'
// background mask (base64, one byte per pixel: 1 drawn, 0 background), its number of colours, each
// landmark label's box (relative to the picture) and whether it is shown, and the canvas'
// aria-label. Then: the profile tracing's SVG path data (before, after) for the run's plan and
// after setPlan(PLAN) with the page's faceVertices(); the PNG export; keyboard use (Tab order,
// arrow keys and digits on the picture); the accessible names of every control; and the print
// layout (what print media hides, page.pdf()'s page count, and a picture of it: print.png).
import { openReport } from "./browser.mjs";
import { readFileSync, writeFileSync, mkdirSync } from "node:fs";
import { join } from "node:path";

const [html, planFile, outFile, shots] = process.argv.slice(2);
const plan = JSON.parse(readFileSync(planFile, "utf8"));
mkdirSync(shots, { recursive: true });
const { browser, page, problems } = await openReport(html, { width: 1000, height: 700 });
try {
  const result = {
    info: await page.evaluate(() => window.facesim.info()),
    frame: await page.evaluate(() => window.facesim.frame()),
    view_frame: await page.evaluate(() => window.facesim.viewFrame()),
  };
  result.default_view = result.info.view;

  /** What the picture shows now (see the header). */
  const grab = () =>
    page.evaluate(() => {
      const c = document.querySelector("#view canvas");
      const t = document.createElement("canvas");
      t.width = c.width;
      t.height = c.height;
      const g = t.getContext("2d");
      g.drawImage(c, 0, 0);
      const px = g.getImageData(0, 0, t.width, t.height).data;
      const mask = new Uint8Array(px.length / 4);
      const colours = new Set();
      for (let i = 0, p = 0; i < px.length; i += 4, p++) {
        mask[p] = px[i] !== 0xf4 || px[i + 1] !== 0xf4 || px[i + 2] !== 0xf4 ? 1 : 0;
        colours.add((px[i] << 16) | (px[i + 1] << 8) | px[i + 2]);
      }
      let bin = "";
      for (let i = 0; i < mask.length; i += 8192) bin += String.fromCharCode(...mask.subarray(i, i + 8192));
      const view = document.getElementById("view").getBoundingClientRect();
      const labels = [...document.querySelectorAll("#labels .lm")].map((e) => {
        const r = e.getBoundingClientRect();
        const s = getComputedStyle(e);
        return {
          label: e.dataset.label,
          shown: !e.hidden && s.display !== "none" && s.visibility === "visible" && Number(s.opacity) > 0.5 && r.width > 0,
          box: [r.left - view.left, r.top - view.top, r.width, r.height],
          text: e.textContent,
        };
      });
      return {
        width: t.width,
        height: t.height,
        mask: btoa(bin),
        colours: colours.size,
        camera: window.facesim.camera(),
        labels,
        aria: c.getAttribute("aria-label"),
        info: window.facesim.info(),
        landmarks: window.facesim.landmarks(),
      };
    });

  result.views = [];
  for (const view of ["front", "profile-right", "profile-left", "three-quarter"])
    for (const mode of ["before", "after", "both"]) {
      // Through the buttons, as a user would.
      await page.click(`button[data-view="${view}"]`);
      await page.click(`button[data-mode="${mode}"]`);
      await page.evaluate(() => window.facesim.settle());
      const g = await grab();
      await page.screenshot({ path: join(shots, `${view}-${mode}.png`) });
      result.views.push({ view, mode, ...g });
    }

  // The profile tracing: the run's plan, then another plan.
  const tracing = () =>
    page.evaluate(() => {
      const svg = document.querySelector("#profile svg");
      return {
        before: svg.querySelector("path.before").getAttribute("d"),
        after: svg.querySelector("path.after").getAttribute("d"),
        title: svg.querySelector("title")?.textContent || "",
        desc: svg.querySelector("desc")?.textContent || "",
        role: svg.getAttribute("role"),
        view_box: svg.getAttribute("viewBox"),
        shown: svg.getBoundingClientRect().width > 100,
      };
    });
  await page.click('button[data-mode="after"]');
  result.tracing_run = await tracing();
  result.plan_error = null;
  try {
    await page.evaluate((p) => {
      window.facesim.setPlan(p);
      window.facesim.settle();
    }, plan);
  } catch (e) {
    result.plan_error = String(e.message || e);
  }
  result.tracing_plan = await tracing();
  result.vertices_plan = await page.evaluate(() => window.facesim.faceVertices());
  await page.evaluate(() => window.facesim.setView("profile-right"));
  await page.screenshot({ path: join(shots, "replanned.png") });

  // PNG export: decoded by the browser itself; the bytes for the Rust test.
  result.png = await page.evaluate(async () => {
    const url = window.facesim.png();
    const img = new Image();
    img.src = url;
    await img.decode();
    const c = document.querySelector("#view canvas");
    return { url, natural: [img.naturalWidth, img.naturalHeight], canvas: [c.width, c.height] };
  });

  // Keyboard: Tab from the start reaches every control and the picture; on the picture the arrow
  // keys turn the view and the digits choose views.
  result.controls = await page.evaluate(() =>
    [...document.querySelectorAll("button, input, select, textarea, canvas, [tabindex]")].map((e) => {
      const name = (e.getAttribute("aria-label") || (e.labels && e.labels[0] ? e.labels[0].textContent : "") || e.textContent || "").trim();
      return { tag: e.tagName.toLowerCase(), type: e.type || "", id: e.id, name, tab_index: e.tabIndex, disabled: !!e.disabled };
    }),
  );
  await page.evaluate(() => document.activeElement && document.activeElement.blur());
  result.tab_order = [];
  for (let i = 0; i < 80; i++) {
    await page.keyboard.press("Tab");
    result.tab_order.push(
      await page.evaluate(() => {
        const e = document.activeElement;
        return e ? `${e.tagName.toLowerCase()}${e.dataset.view ? `:${e.dataset.view}` : e.dataset.mode ? `:${e.dataset.mode}` : e.id ? `#${e.id}` : ""}` : "";
      }),
    );
  }
  await page.evaluate(() => window.facesim.setView("profile-right"));
  await page.focus("#view canvas");
  result.keys_start = await page.evaluate(() => window.facesim.camera());
  result.keys = [];
  for (const key of ["ArrowRight", "ArrowRight", "ArrowUp", "-", "1", "3", "4", "2"]) {
    await page.keyboard.press(key);
    result.keys.push({ key, camera: await page.evaluate(() => window.facesim.camera()), view: await page.evaluate(() => window.facesim.info().view), aria: await page.evaluate(() => document.querySelector("#view canvas").getAttribute("aria-label")) });
  }
  result.tables = await page.evaluate(() =>
    [...document.querySelectorAll("table")].map((t) => ({ caption: t.caption ? t.caption.textContent : "", rows: t.tBodies[0] ? t.tBodies[0].rows.length : 0, text: t.textContent })),
  );

  // Print: one page, controls hidden, the picture, the tracing and the tables shown.
  await page.evaluate(() => window.facesim.setView("profile-right"));
  await page.emulateMediaType("print");
  result.print = await page.evaluate(() => {
    const shown = (sel) => [...document.querySelectorAll(sel)].some((e) => e.getBoundingClientRect().width > 0 && getComputedStyle(e).display !== "none");
    return {
      controls_shown: ["#toolbar", "#side fieldset", "#side button", "input"].filter(shown),
      parts_shown: ["#view canvas", "#profile svg", "#summary table"].filter(shown),
    };
  });
  const pdf = await page.pdf({ format: "A4", printBackground: true });
  // The print layout as a picture (A4's printable width at 96 dpi) for docs/guide/report-page.md.
  await page.setViewport({ width: 726, height: 1047 });
  await page.screenshot({ path: join(shots, "print.png") });
  await page.emulateMediaType("screen");
  writeFileSync(join(shots, "summary.pdf"), pdf);
  const text = Buffer.from(pdf).toString("latin1");
  result.pdf_pages = (text.match(/\/Type\s*\/Page(?![a-zA-Z])/g) || []).length;
  result.pdf_bytes = pdf.length;
  Object.assign(result, problems);
  writeFileSync(outFile, JSON.stringify(result));
} finally {
  await browser.close();
}

// Drives report.html's tissue sliders in headless Chromium for crates/facesim/tests/library/report_page.rs
// (the Rust test judges against the Rust reduced model):
//   node test/tissue_page.mjs REPORT.html STEPS.json OUT.json SHOT.png [RATE_SECONDS]
// STEPS.json: {tissues: [setTissue arguments, in order], plan: a plan other than the run's}.
// OUT.json: the problems seen; info(); tissue() and faceVertices() at the start and after each
// setTissue; what keyboard use of the muscle/fat slider does (ArrowRight on the focused slider:
// its value text, the face's change, tissue()); the sliding box, the reset button; tissue()
// after setPlan(plan) (the note for another plan); and the update rate of a tissue slider drag
// (input events on the slider, each applied and drawn as a frame is, then a 1-pixel read-back).
import { openReport } from "./browser.mjs";
import { readFileSync, writeFileSync, mkdirSync } from "node:fs";
import { dirname } from "node:path";

const [html, stepsFile, outFile, shot, rateSeconds = "3"] = process.argv.slice(2);
const steps = JSON.parse(readFileSync(stepsFile, "utf8"));
const { browser, page, problems } = await openReport(html);
try {
  const api = (f, ...a) => page.evaluate(f, ...a);
  const result = { info: await api(() => window.facesim.info()) };
  result.initial = { tissue: await api(() => window.facesim.tissue()), vertices: await api(() => window.facesim.faceVertices()) };
  result.steps = [];
  for (const t of steps.tissues) {
    let error = null;
    try {
      await api((t) => window.facesim.setTissue(t), t);
    } catch (e) {
      error = String(e.message || e);
    }
    result.steps.push({
      error,
      tissue: await api(() => window.facesim.tissue()),
      vertices: await api(() => window.facesim.faceVertices()),
      landmarks: await api(() => window.facesim.landmarks()),
    });
  }
  // The keyboard: Tab reaches the tissue sliders; arrows on the focused slider move it, and the
  // next animation frame re-solves.
  await api(() => window.facesim.setTissue({ poisson: null, muscle_fat: null, skin_fat: null, sliding: null }));
  result.keyboard = await api(async () => {
    const r = document.querySelector("input[data-tissue=muscle_fat]");
    const controls = [...document.querySelectorAll("#tissue input, #tissue button")].map((e) => ({
      tag: e.tagName.toLowerCase(),
      type: e.type,
      tab: e.tabIndex,
      name: (e.closest("label")?.textContent || e.textContent || "").trim(),
    }));
    return { controls, before: r.value, text_before: r.getAttribute("aria-valuetext") };
  });
  await page.focus("input[data-tissue=muscle_fat]");
  for (let i = 0; i < 10; i++) await page.keyboard.press("ArrowRight");
  await api(() => new Promise((ok) => requestAnimationFrame(() => requestAnimationFrame(ok))));
  Object.assign(
    result.keyboard,
    await api(() => {
      const r = document.querySelector("input[data-tissue=muscle_fat]");
      return { after: r.value, text_after: r.getAttribute("aria-valuetext"), focused: document.activeElement === r, tissue: window.facesim.tissue(), vertices: window.facesim.faceVertices() };
    }),
  );
  // Sliding off (when the page offers it), then the run's tissues again.
  result.sliding = await api(() => {
    const c = document.getElementById("tissue-sliding");
    if (!c) return null;
    c.click();
    const t = window.facesim.tissue();
    c.click();
    return t;
  });
  result.reset = await api(() => {
    document.getElementById("tissue-reset").click();
    return { tissue: window.facesim.tissue(), vertices: window.facesim.faceVertices() };
  });
  // Another plan with a tissue change: the note says the change is the run's plan's.
  await api((t) => window.facesim.setTissue(t), steps.tissues[0]);
  await api((p) => window.facesim.setPlan(p), steps.plan);
  result.other_plan = await api(() => window.facesim.tissue());
  await api(() => window.facesim.settle());
  result.aria = await api(() => document.querySelector("#view canvas").getAttribute("aria-label"));
  mkdirSync(dirname(shot), { recursive: true });
  await page.screenshot({ path: shot });
  // The rate of a tissue slider drag: an input event per update (the slider's own handler), then
  // what the page's animation frame does (setTissue({}) applies the values the event set and
  // draws at the dragging resolution), then a 1-pixel read-back so that the frame is really drawn.
  result.rate = await api((ms) => {
    const api = window.facesim;
    document.querySelector("#plan button:last-of-type").click(); // the run's plan
    const gl = document.querySelector("#view canvas").getContext("webgl2");
    const px = new Uint8Array(4);
    const r = document.querySelector("input[data-tissue=muscle_fat]");
    let i = 0;
    const t0 = performance.now();
    while (performance.now() - t0 < ms) {
      r.value = String(Math.round(100 + 90 * Math.sin(0.1 * i++)));
      r.dispatchEvent(new Event("input"));
      api.setTissue({});
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    }
    return { updates: i, wall_ms: performance.now() - t0, per_s: (1000 * i) / (performance.now() - t0), canvas: [gl.drawingBufferWidth, gl.drawingBufferHeight] };
  }, 1000 * Number(rateSeconds));
  Object.assign(result, problems);
  writeFileSync(outFile, JSON.stringify(result));
} finally {
  await browser.close();
}

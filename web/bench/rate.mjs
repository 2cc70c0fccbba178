// The update rate of report.html (docs/performance.md): setPlan + re-render per second in
// headless Chromium (Debian's chromium, SwiftShader WebGL).
//   node bench/rate.mjs REPORT.html [SECONDS]
// Two figures: setPlan alone (the basis sum, normals, colours, upload and the render call), and
// setPlan followed by a 1-pixel read-back, which waits until the GPU process has drawn the frame.
import { openReport } from "../test/browser.mjs";
import { cpus } from "node:os";

const [html, seconds = "4"] = process.argv.slice(2);
const { browser, page, problems } = await openReport(html);
try {
  const result = await page.evaluate(async (ms) => {
    const info = window.facesim.info();
    const plan = (i) => {
      const p = {};
      info.segments.forEach((name, s) => {
        const a = Math.sin(0.1 * i + s);
        p[name] = { translate: [a, -5 + 3 * a, 2 * a], rotate_deg: [5 * a, -3 * a, 2 * a] };
      });
      return p;
    };
    const gl = document.querySelector("#view canvas").getContext("webgl2");
    const px = new Uint8Array(4);
    const rate = (sync) => {
      let i = 0;
      const t0 = performance.now();
      while (performance.now() - t0 < ms) {
        window.facesim.setPlan(plan(i++));
        if (sync) gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
      }
      // Frames still queued in the GPU process count in the time.
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
      return { updates: i, per_s: (1000 * i) / (performance.now() - t0) };
    };
    const timeOne = (f) => {
      const t0 = performance.now();
      for (let i = 0; i < 5; i++) f(i);
      return (performance.now() - t0) / 5;
    };
    rate(true); // warm-up
    const drawn = rate(true);
    // Where the time goes: the basis sum alone (no render), and one render alone.
    const renderer = window.facesim.render;
    // The same with the skull hidden (the face alone, opaque).
    const skullBox = [...document.querySelectorAll("#side input[type=checkbox]")][0];
    skullBox.click();
    const drawnFaceOnly = rate(true);
    skullBox.click();
    return {
      info,
      drawn,
      drawn_face_only: drawnFaceOnly,
      ms_set_plan_and_draw: 1000 / drawn.per_s,
      ms_render_only: renderer ? timeOne(() => { renderer(); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px); }) : null,
    };
  }, 1000 * Number(seconds));
  const canvas = await page.evaluate(() => {
    const c = document.querySelector("#view canvas");
    return [c.width, c.height];
  });
  console.log(
    JSON.stringify({ ...result, canvas, ...problems, cpu: cpus()[0].model, cores: cpus().length, chromium: await browser.version() }, null, 1),
  );
} finally {
  await browser.close();
}

// The update rate of report.html (docs/performance.md): setPlan + re-render per second in
// headless Chromium (Debian's chromium, SwiftShader WebGL).
//   node bench/rate.mjs REPORT.html [SECONDS]
// Each update is setPlan followed by a 1-pixel read-back, which waits until the GPU process has
// drawn the frame. Figures: at the page's dragging resolution (what a slider drag shows) and at
// full resolution (facesim.options.dragPixelRatio = 1), each with the skull shown (the face
// transparent over it) and hidden; setPlan without the read-back; and one full render alone.
import { openReport } from "../test/browser.mjs";
import { cpus, loadavg } from "node:os";

const [html, seconds = "4"] = process.argv.slice(2);
const load = loadavg()[0];
const { browser, page, problems } = await openReport(html);
try {
  const result = await page.evaluate(async (ms) => {
    const api = window.facesim;
    const info = api.info();
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
    const readBack = () => gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const rate = (sync) => {
      let i = 0;
      const t0 = performance.now();
      while (performance.now() - t0 < ms) {
        api.setPlan(plan(i++));
        if (sync) readBack();
      }
      // Frames still queued in the GPU process count in the time.
      readBack();
      return Number(((1000 * i) / (performance.now() - t0)).toFixed(1));
    };
    const timeOne = (f) => {
      const t0 = performance.now();
      for (let i = 0; i < 5; i++) f(i);
      return Number(((performance.now() - t0) / 5).toFixed(1));
    };
    const skullBox = [...document.querySelectorAll("#side input[type=checkbox]")][0];
    const canvasSize = () => [gl.drawingBufferWidth, gl.drawingBufferHeight];
    // Pages from before facesim.options drew every frame at full resolution.
    const opts = api.options || { dragPixelRatio: 1 };
    const dragRatio = opts.dragPixelRatio;
    const out = { info, drag_pixel_ratio: dragRatio };
    rate(true); // warm-up
    out.per_s_drag = rate(true);
    out.canvas_drag = canvasSize();
    skullBox.click();
    out.per_s_drag_face_only = rate(true);
    skullBox.click();
    opts.dragPixelRatio = 1;
    out.per_s_full = rate(true);
    out.canvas_full = canvasSize();
    skullBox.click();
    out.per_s_full_face_only = rate(true);
    skullBox.click();
    opts.dragPixelRatio = dragRatio;
    out.per_s_set_plan_no_readback = rate(false);
    out.ms_render_only = timeOne(() => {
      api.render();
      readBack();
    });
    return out;
  }, 1000 * Number(seconds));
  console.log(
    JSON.stringify(
      { ...result, ...problems, load_average_1min: load, cpu: cpus()[0].model, cores: cpus().length, chromium: await browser.version() },
      null,
      1,
    ),
  );
} finally {
  await browser.close();
}

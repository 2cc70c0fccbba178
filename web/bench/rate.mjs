// The update rate of report.html (docs/lab/performance.md): setPlan + re-render per second in
// headless Chromium (Debian's chromium, SwiftShader WebGL).
//   node bench/rate.mjs REPORT.html [SECONDS]
// Each update is setPlan followed by a 1-pixel read-back, which waits until the GPU process has
// drawn the frame. Cases: at the page's dragging resolution (what a slider drag shows) and at full
// resolution (facesim.options.dragPixelRatio = 1), each with the skull shown (the face transparent
// over it) and hidden; full resolution without the static-skull cache (options.cache = false);
// dragging with every face triangle drawn (options.lod = false: no simplified dragging face);
// then one full render alone; with tissue sliders (a run with the reduced model), a tissue slider
// drag with the skull hidden and shown. Per case: updates per second (wall clock) and
// the CPU time of all Chromium processes per update (utime + stime from /proc), which a loaded
// machine inflates far less than the wall clock.
import { openReport } from "../test/browser.mjs";
import { cpus, loadavg } from "node:os";
import { readdirSync, readFileSync } from "node:fs";

const [html, seconds = "4"] = process.argv.slice(2);
const ms = 1000 * Number(seconds);

/** CPU milliseconds used so far by process `root` and all its descendants (Linux /proc). */
function treeCpuMs(root) {
  const procs = [];
  for (const d of readdirSync("/proc")) {
    if (!/^\d+$/.test(d)) continue;
    try {
      const stat = readFileSync(`/proc/${d}/stat`, "utf8");
      const f = stat.slice(stat.lastIndexOf(")") + 2).split(" ");
      procs.push({ pid: Number(d), ppid: Number(f[1]), ticks: Number(f[11]) + Number(f[12]) });
    } catch {
      // the process ended meanwhile
    }
  }
  const inTree = new Set([root]);
  for (let grown = true; grown; ) {
    grown = false;
    for (const p of procs)
      if (!inTree.has(p.pid) && inTree.has(p.ppid)) {
        inTree.add(p.pid);
        grown = true;
      }
  }
  // USER_HZ is 100 on Linux.
  return 10 * procs.filter((p) => inTree.has(p.pid)).reduce((s, p) => s + p.ticks, 0);
}

const load = loadavg()[0];
const { browser, page, problems } = await openReport(html);
const root = browser.process().pid;
try {
  await page.evaluate(() => {
    const api = window.facesim;
    const info = api.info();
    const gl = document.querySelector("#view canvas").getContext("webgl2");
    const px = new Uint8Array(4);
    const readBack = () => gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const plan = (i) => {
      const p = {};
      info.segments.forEach((name, s) => {
        const a = Math.sin(0.1 * i + s);
        p[name] = { translate: [a, -5 + 3 * a, 2 * a], rotate_deg: [5 * a, -3 * a, 2 * a] };
      });
      return p;
    };
    // Pages from before facesim.options drew every frame at full resolution.
    const opts = api.options || { dragPixelRatio: 1 };
    const dragRatio = opts.dragPixelRatio;
    // "see the skull through the skin" (pages before it had the skull box first).
    const skullBox = document.getElementById("skull") || [...document.querySelectorAll("#side input[type=checkbox]")][0];
    window.__bench = {
      info: () => ({ ...info, drag_pixel_ratio: dragRatio }),
      setup(full, skull, cache = true, lod = true) {
        opts.dragPixelRatio = full ? 1 : dragRatio;
        if ("cache" in opts) opts.cache = cache;
        if ("lod" in opts) opts.lod = lod;
        if (skullBox.checked !== skull) skullBox.click();
      },
      rate(ms) {
        let i = 0;
        const t0 = performance.now();
        while (performance.now() - t0 < ms) {
          api.setPlan(plan(i++));
          readBack();
        }
        return { updates: i, wall_ms: performance.now() - t0, canvas: [gl.drawingBufferWidth, gl.drawingBufferHeight] };
      },
      // A tissue slider drag (docs/guide/report-page.md "Tissue sliders"): an input event on the
      // muscle/fat slider, then what the page's animation frame does (setTissue({}) applies
      // it and draws at the dragging resolution); pages without a reduced model: null.
      tissueRate(ms) {
        const r = document.querySelector("input[data-tissue=muscle_fat]");
        if (!r || !api.setTissue) return null;
        let i = 0;
        const t0 = performance.now();
        while (performance.now() - t0 < ms) {
          r.value = String(Math.round(100 + 90 * Math.sin(0.1 * i++)));
          r.dispatchEvent(new Event("input"));
          api.setTissue({});
          readBack();
        }
        return { updates: i, wall_ms: performance.now() - t0, canvas: [gl.drawingBufferWidth, gl.drawingBufferHeight] };
      },
      render(k) {
        const t0 = performance.now();
        for (let i = 0; i < k; i++) {
          api.render();
          readBack();
        }
        return { updates: k, wall_ms: performance.now() - t0, canvas: [gl.drawingBufferWidth, gl.drawingBufferHeight] };
      },
    };
  });
  const measure = async (what, ...args) => {
    const c0 = treeCpuMs(root);
    const r = await page.evaluate((what, args) => window.__bench[what](...args), what, args);
    const cpu = treeCpuMs(root) - c0;
    return { per_s: Number(((1000 * r.updates) / r.wall_ms).toFixed(1)), cpu_ms_per_update: Number((cpu / r.updates).toFixed(1)), canvas: r.canvas };
  };
  const out = { info: await page.evaluate(() => window.__bench.info()) };
  await page.evaluate(() => window.__bench.rate(500)); // warm-up
  for (const [name, full, skull, cache, lod] of [
    ["drag", false, true, true],
    ["drag_no_lod", false, true, true, false],
    ["drag_face_only", false, false, true],
    ["full", true, true, true],
    ["full_no_cache", true, true, false],
    ["full_face_only", true, false, true],
  ]) {
    await page.evaluate((...a) => window.__bench.setup(...a), full, skull, cache, lod ?? true);
    out[name] = await measure("rate", ms);
  }
  if (out.info.tissue) {
    for (const [name, full, skull] of [
      ["tissue_drag_face_only", false, false],
      ["tissue_drag", false, true],
    ]) {
      await page.evaluate((...a) => window.__bench.setup(...a), full, skull);
      out[name] = await measure("tissueRate", ms);
    }
  }
  await page.evaluate(() => window.__bench.setup(false, true));
  out.render_only_full = await measure("render", 5);
  console.log(
    JSON.stringify(
      { ...out, ...problems, load_average_1min: load, cpu: cpus()[0].model, cores: cpus().length, chromium: await browser.version() },
      null,
      1,
    ),
  );
} finally {
  await browser.close();
}

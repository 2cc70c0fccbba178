// Headless Chromium for report.html's tests and benchmark: Debian's chromium (never a downloaded
// browser), software WebGL (SwiftShader), the page opened from disk.
import puppeteer from "puppeteer-core";
import { existsSync } from "node:fs";
import { pathToFileURL } from "node:url";

export const CHROMIUM = process.env.FACESIM_CHROMIUM || "/usr/bin/chromium";

/** Open `html` (a path); collect console errors, page errors and requests that leave the file. */
export async function openReport(html, { width = 1000, height = 700 } = {}) {
  if (!existsSync(CHROMIUM)) throw new Error(`${CHROMIUM}: no chromium; run scripts/test-setup.sh`);
  const browser = await puppeteer.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-first-run"],
  });
  const page = await browser.newPage();
  await page.setViewport({ width, height });
  const problems = { console_errors: [], page_errors: [], outside_requests: [] };
  const url = pathToFileURL(html).href;
  page.on("console", (m) => m.type() === "error" && problems.console_errors.push(m.text()));
  page.on("pageerror", (e) => problems.page_errors.push(String(e)));
  page.on("request", (r) => {
    const u = r.url();
    if (u !== url && !u.startsWith("data:") && !u.startsWith("blob:")) problems.outside_requests.push(u);
  });
  await page.goto(url, { waitUntil: "load", timeout: 60000 });
  await page.waitForFunction(() => document.body.dataset.ready === "1" || window.__failed, { timeout: 60000 });
  return { browser, page, problems };
}

/** Pixels of the WebGL canvas that are not the background, and how many colours they have. */
export async function canvasStats(page) {
  return page.evaluate(() => {
    const c = document.querySelector("#view canvas");
    const t = document.createElement("canvas");
    t.width = c.width;
    t.height = c.height;
    const g = t.getContext("2d");
    g.drawImage(c, 0, 0);
    const px = g.getImageData(0, 0, t.width, t.height).data;
    let drawn = 0;
    const colours = new Set();
    for (let i = 0; i < px.length; i += 4) {
      if (px[i] !== 0xf4 || px[i + 1] !== 0xf4 || px[i + 2] !== 0xf4) drawn++;
      colours.add((px[i] << 16) | (px[i + 1] << 8) | px[i + 2]);
    }
    return { pixels: px.length / 4, drawn, colours: colours.size };
  });
}

// Bundle src/report.js (three.js included) into crates/facesim/assets/report.bundle.js, which
// facesim embeds in every report.html. Deterministic: same sources and lockfile, same bytes.
// `node build.mjs --check` builds in memory and fails when the committed bundle differs.
import * as esbuild from "esbuild";
import { readFileSync, writeFileSync } from "node:fs";
import { fileURLToPath } from "node:url";

const out = fileURLToPath(new URL("../crates/facesim/assets/report.bundle.js", import.meta.url));
const result = await esbuild.build({
  entryPoints: [fileURLToPath(new URL("src/report.js", import.meta.url))],
  bundle: true,
  minify: true,
  format: "iife",
  target: "es2020",
  legalComments: "eof",
  charset: "utf8",
  write: false,
  logLevel: "warning",
});
const code = result.outputFiles[0].text;
if (/<\/script/i.test(code)) throw new Error("the bundle contains '</script', which would end the inline script");
if (process.argv.includes("--check")) {
  let committed = "";
  try {
    committed = readFileSync(out, "utf8");
  } catch {}
  if (committed !== code) {
    console.error(`${out}: differs from a fresh build; run 'npm run build' in web/`);
    process.exit(1);
  }
  console.log("report.bundle.js is up to date");
} else {
  writeFileSync(out, code);
  console.log(`wrote ${out} (${code.length} bytes)`);
}

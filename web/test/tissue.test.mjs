// Unit tests of web/src/tissue.js (the tissue sliders' online solve and bound), with node:
//   node --test test/tissue.test.mjs
// Analytic cases always; with FACESIM_TISSUE_FIXTURE=FILE.json also the answers of the Rust
// `OnlineForm::solve` for the same forms and θ (crates/facesim/tests/library/report_page.rs writes the
// file: {cases: [{form, theta, coefficients, residual, alpha, energy_bound, energy_norm}]}).
import { test } from "node:test";
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { lame, materials, theta, outside, cholesky, choleskySolve, solveOnline, outputBound, dualAnswer, faceValueBound, reducedFace, rangeAt, rangeFraction, rangeWith } from "../src/tissue.js";

const close = (a, b, rel, what) => assert.ok(Math.abs(a - b) <= rel * Math.max(Math.abs(a), Math.abs(b), 1e-300), `${what}: ${a} vs ${b}`);

test("cholesky factors a known SPD matrix and solves with it", () => {
  // A = L Lᵀ with L = [[2,0,0],[1,3,0],[−1,2,4]].
  const l = [2, 0, 0, 1, 3, 0, -1, 2, 4];
  const a = new Float64Array(9);
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) for (let k = 0; k < 3; k++) a[3 * i + j] += l[3 * i + k] * l[3 * j + k];
  const f = cholesky(a, 3);
  assert.equal(f, true);
  for (let i = 0; i < 9; i++) close(a[i] + 1, l[i] + 1, 1e-15, `L[${i}]`);
  // A x = b for x = (1, −2, 3).
  const x = [1, -2, 3];
  const aa = new Float64Array(9);
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) for (let k = 0; k < 3; k++) aa[3 * i + j] += l[3 * i + k] * l[3 * j + k];
  const b = [0, 1, 2].map((i) => aa[3 * i] * x[0] + aa[3 * i + 1] * x[1] + aa[3 * i + 2] * x[2]);
  const got = choleskySolve(a, 3, b);
  for (let i = 0; i < 3; i++) close(got[i], x[i], 1e-14, `x[${i}]`);
  // Not positive definite.
  assert.equal(cholesky(new Float64Array([1, 2, 2, 1]), 2), false);
});

test("the online solve and its bound on an analytic two-term form", () => {
  // Q = 2, N = 2: M_0 = I, M_1 = [[2, 1], [1, 2]], F_0 = (1, 0), F_1 = (0, 1). Riesz coordinates
  // are unit vectors (the Euclidean norm of the weights is the residual), one ragged column.
  const form = {
    theta_bar: [1, 2],
    matrices: [
      [1, 0, 0, 1],
      [2, 1, 1, 2],
    ],
    loads: [
      [1, 0],
      [0, 1],
    ],
    riesz: [[1], [0, 1], [0, 0, 1], [0, 0, 0, 1], [0, 0, 0, 0, 1], [0, 0, 0, 0, 0, 1]],
    riesz_norms: [1, 1, 1, 1, 1, 1],
    unknowns: 0,
  };
  const th = [3, 0.5];
  // A = [[4, 0.5], [0.5, 4]], f = (3, 0.5): c = A⁻¹ f.
  const det = 16 - 0.25;
  const c = [(4 * 3 - 0.5 * 0.5) / det, (4 * 0.5 - 0.5 * 3) / det];
  const o = solveOnline(form, th);
  close(o.coefficients[0], c[0], 1e-14, "c0");
  close(o.coefficients[1], c[1], 1e-14, "c1");
  // w = (θ_0, θ_1, −c_0 θ_0, −c_0 θ_1, −c_1 θ_0, −c_1 θ_1); residual = ‖w‖ (unknowns 0).
  const w = [3, 0.5, -c[0] * 3, -c[0] * 0.5, -c[1] * 3, -c[1] * 0.5];
  const norm = Math.hypot(...w);
  close(o.residual, norm, 1e-14, "residual");
  close(o.alpha, 0.25, 1e-15, "α = min(3/1, 0.5/2)");
  close(o.energyBound, norm / 0.25, 1e-14, "Δ");
  close(o.energyNorm, Math.hypot(...c), 1e-14, "‖c‖");
  // The round-off floor: unknowns · ε · Σ|w_j| ‖ρ_j‖.
  const o2 = solveOnline({ ...form, unknowns: 1000, riesz_norms: [2, 2, 2, 2, 2, 2] }, th);
  const floor = 1000 * Number.EPSILON * 2 * w.reduce((s, x) => s + Math.abs(x), 0);
  close(o2.residual, norm + floor, 1e-14, "residual with floor");
  assert.throws(() => solveOnline(form, [1, 0]), /positive/);
  assert.throws(() => solveOnline(form, [1]), /positive/);
  assert.throws(() => solveOnline({ ...form, matrices: [[1, 0, 0, -1], [0, 0, 0, 0]] }, [1, 1]), /positive definite/);
});

test("materials and θ follow Draw::apply and TissueElastic::lame", () => {
  const [l, m] = lame(10, 0.45);
  close(l, (10 * 0.45) / (1.45 * 0.1), 1e-15, "λ");
  close(m, 10 / 2.9, 1e-15, "μ");
  const nominal = [
    { youngs_kpa: 30, poisson: 0.47 },
    { youngs_kpa: 10, poisson: 0.47 },
    { youngs_kpa: 2, poisson: 0.47 },
    { youngs_kpa: 3, poisson: 0.46 },
  ];
  assert.deepEqual(materials(nominal, {}), nominal);
  const mats = materials(nominal, { poisson: 0.49, muscle_fat: 4, skin_fat: 7 });
  assert.deepEqual(mats, [
    { youngs_kpa: 14, poisson: 0.49 },
    { youngs_kpa: 8, poisson: 0.49 },
    { youngs_kpa: 2, poisson: 0.49 },
    { youngs_kpa: 3, poisson: 0.49 },
  ]);
  const th = theta([[1, true], [1, false], [3, false]], mats);
  assert.deepEqual(th, [lame(8, 0.49)[0], lame(8, 0.49)[1], lame(3, 0.49)[1]]);
  const terms = [[0, true], [2, false]];
  assert.equal(outside(terms, [[1, 1], [2, 2]], [1.5, 2 * (1 + 1e-10)]), null);
  assert.match(outside(terms, [[1, 1], [2, 2]], [1.5, 2.1]), /μ of \[tet.fat_dark\] = 2.1000 kPa is outside the trained range 1.0000–2.0000 kPa/);
  assert.match(outside(terms, [[1, 1], [2, 2]], [0.9, 1.5]), /λ of \[tet.skin\]/);
});

test("ranges map slider fractions as Range::at and back", () => {
  const log = { log_uniform: [1.7, 15] };
  close(rangeAt(log, 0), 1.7, 1e-15, "log 0");
  close(rangeAt(log, 1), 15, 1e-15, "log 1");
  close(rangeAt(log, 0.5), Math.sqrt(1.7 * 15), 1e-15, "log ½");
  close(rangeFraction(log, Math.sqrt(1.7 * 15)), 0.5, 1e-14, "log back");
  const uni = { uniform: [0.45, 0.49] };
  close(rangeAt(uni, 0.25), 0.46, 1e-15, "uniform");
  close(rangeFraction(uni, 0.46), 0.25, 1e-13, "uniform back");
  assert.deepEqual(rangeWith(uni, 0.4), { uniform: [0.4, 0.49] });
  assert.deepEqual(rangeWith(log, 20), { log_uniform: [1.7, 20] });
  assert.equal(rangeFraction({ uniform: [0.45, 0.45] }, 0.45), 0);
});

test("the reduced face is lift + Σ c_n columns_n", () => {
  const lift = [1, 2, 3];
  const columns = [1, 0, 0, 0, 1, 0];
  assert.deepEqual(Array.from(reducedFace(lift, columns, [2, -1])), [3, 1, 3]);
});

const fixture = process.env.FACESIM_TISSUE_FIXTURE;
test("the online solve equals Rust's OnlineForm::solve for the same θ", { skip: !fixture && "FACESIM_TISSUE_FIXTURE not set" }, () => {
  const cases = JSON.parse(readFileSync(fixture, "utf8")).cases;
  assert.ok(cases.length > 0);
  for (const [i, k] of cases.entries()) {
    const o = solveOnline(k.form, k.theta);
    const what = `case ${i}`;
    assert.equal(o.coefficients.length, k.coefficients.length, what);
    const scale = Math.max(...k.coefficients.map(Math.abs));
    for (let j = 0; j < k.coefficients.length; j++) assert.ok(Math.abs(o.coefficients[j] - k.coefficients[j]) <= 1e-10 * scale, `${what} c[${j}]: ${o.coefficients[j]} vs ${k.coefficients[j]}`);
    // The residual is a small difference of large terms only through c: relative 1e-8.
    close(o.residual, k.residual, 1e-8, `${what} residual`);
    close(o.alpha, k.alpha, 1e-15, `${what} α`);
    close(o.energyBound, k.energy_bound, 1e-8, `${what} Δ`);
    close(o.energyNorm, k.energy_norm, 1e-12, `${what} ‖c‖`);
    close(o.gamma, k.gamma, 1e-15, `${what} γ`);
    // The output's bound through the Riesz representer, as reduced::OutputBound::bound.
    close(outputBound(k.output, o), k.output_bound, 1e-8, `${what} output bound`);
    assert.ok(outputBound(k.output, o) <= k.output_plain * (1 + 1e-12), `${what}: above g Δ`);
    // A landmark's dual answer, as reduced::dual::DualForm::answer.
    const d = dualAnswer(k.dual, k.theta, o);
    const cScale = Math.max(...k.dual_correction.map(Math.abs));
    k.dual_correction.forEach((c, j) => assert.ok(Math.abs(d.correction[j] - c) <= 1e-9 * cScale, `${what} correction ${j}: ${d.correction[j]} vs ${c}`));
    k.dual_bound.forEach((b, j) => close(d.bound[j], b, 1e-8, `${what} dual bound ${j}`));
    const len = (v) => Math.hypot(...v);
    close(faceValueBound(1e9, d), len(d.correction) + len(d.bound), 1e-15, `${what} face value`);
    assert.equal(faceValueBound(1e-9, d), 1e-9);
  }
});

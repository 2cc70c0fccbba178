// The tissue sliders' maths (docs/guide/report-page.md "Tissue sliders"): the run's certified reduced
// model (docs/design/reduced.md) solved in the page, as crates/facesim/src/reduced/basis.rs
// `OnlineForm::solve` solves it, with its certified bound; the sampled tissue parameters mapped
// to materials as crates/facesim/src/uncertainty/run.rs `Draw::apply` maps them. Pure functions
// over plain arrays (no DOM, no three.js): web/test/tissue.test.mjs tests them with node.

/** Lamé's (λ, μ) of Young's modulus E (kPa) and Poisson's ratio ν, as `TissueElastic::lame`. */
export function lame(e, nu) {
  return [(e * nu) / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))];
}

/** The four tissues' materials (`Tet::TISSUES` order: skin, muscle, fat_dark, fat_bright; each
 *  {youngs_kpa, poisson}) for the sampled parameters `p` ({poisson, muscle_fat, skin_fat}; a
 *  parameter null or absent keeps the run's), as `Draw::apply`: ν for every soft tissue, muscle
 *  and skin moduli as ratios to the dark fat's, the fats' moduli kept. */
export function materials(nominal, p) {
  const m = nominal.map((t) => ({ youngs_kpa: t.youngs_kpa, poisson: t.poisson }));
  if (p.poisson != null) for (const t of m) t.poisson = p.poisson;
  const fat = m[2].youngs_kpa;
  if (p.muscle_fat != null) m[1].youngs_kpa = p.muscle_fat * fat;
  if (p.skin_fat != null) m[0].youngs_kpa = p.skin_fat * fat;
  return m;
}

/** θ in a model's term order: terms[q] = [slot, isLambda], slot the tissue's index in `mats`. */
export function theta(terms, mats) {
  return terms.map(([slot, isLambda]) => {
    const [l, mu] = lame(mats[slot].youngs_kpa, mats[slot].poisson);
    return isLambda ? l : mu;
  });
}

const TISSUE_NAMES = ["skin", "muscle", "fat_dark", "fat_bright"];
/** A slot's case key, as `model::reduced::slot_name`. */
const slotName = (slot) => `[tet.${TISSUE_NAMES[slot]}]`;
/** Relative slack of the trained box, as `ReducedTet::outside`. */
const SLACK = 1e-9;

/** Why θ is outside the trained box [lo, hi] (null: inside), as `ReducedTet::outside`. */
export function outside(terms, box, th) {
  const [lo, hi] = box;
  for (let q = 0; q < th.length; q++) {
    if (th[q] < lo[q] * (1 - SLACK) || th[q] > hi[q] * (1 + SLACK)) {
      const [slot, isLambda] = terms[q];
      return `${isLambda ? "λ" : "μ"} of ${slotName(slot)} = ${th[q].toFixed(4)} kPa is outside the trained range ${lo[q].toFixed(4)}–${hi[q].toFixed(4)} kPa`;
    }
  }
  return null;
}

/** In place: the lower Cholesky factor L (row-major n×n, A = L Lᵀ) of the symmetric `a`; false
 *  when `a` is not positive definite. */
export function cholesky(a, n) {
  for (let j = 0; j < n; j++) {
    let d = a[j * n + j];
    for (let k = 0; k < j; k++) d -= a[j * n + k] * a[j * n + k];
    if (!(d > 0)) return false;
    d = Math.sqrt(d);
    a[j * n + j] = d;
    for (let i = j + 1; i < n; i++) {
      let s = a[i * n + j];
      for (let k = 0; k < j; k++) s -= a[i * n + k] * a[j * n + k];
      a[i * n + j] = s / d;
    }
    for (let i = 0; i < j; i++) a[i * n + j] = 0;
  }
  return true;
}

/** x with L Lᵀ x = b (L from `cholesky`). */
export function choleskySolve(l, n, b) {
  const x = Float64Array.from(b);
  for (let i = 0; i < n; i++) {
    let s = x[i];
    for (let k = 0; k < i; k++) s -= l[i * n + k] * x[k];
    x[i] = s / l[i * n + i];
  }
  for (let i = n - 1; i >= 0; i--) {
    let s = x[i];
    for (let k = i + 1; k < n; k++) s -= l[k * n + i] * x[k];
    x[i] = s / l[i * n + i];
  }
  return x;
}

/** The reduced solution at θ and its certified bound, as `OnlineForm::solve`:
 *  A_N = Σ θ_q M_q, f_N = Σ θ_q F_q, A_N c = f_N; the residual's Riesz representer
 *  Σ_j w_j ρ_j with w = (θ, −c_n θ_q), its norm plus the round-off floor
 *  unknowns · ε · Σ|w_j| ‖ρ_j‖; α = min_q θ_q / θ̄_q; Δ = residual / α bounds ‖u − u_N‖_X.
 *  Returns {coefficients, residual, alpha, gamma, energyBound, energyNorm, coordinates, floor}
 *  (γ = max_q θ_q / θ̄_q; the residual's coordinates and its floor, for `outputBound`); throws
 *  when θ is not Q positive values or A_N is not positive definite. */
export function solveOnline(form, th) {
  const q = form.theta_bar.length;
  const n = form.loads.length ? form.loads[0].length : 0;
  if (th.length !== q || th.some((t) => !(t > 0 && Number.isFinite(t)))) throw new Error(`reduced model: parameters [${th.join(", ")}] are not ${q} positive values`);
  const a = new Float64Array(n * n);
  const f = new Float64Array(n);
  for (let k = 0; k < q; k++) {
    const m = form.matrices[k];
    const t = th[k];
    for (let i = 0; i < n * n; i++) a[i] += t * m[i];
    for (let i = 0; i < n; i++) f[i] += t * form.loads[k][i];
  }
  if (!cholesky(a, n)) throw new Error("reduced model: the reduced system is not positive definite");
  const c = choleskySolve(a, n, f);
  // X⁻¹ r = Σ_j w_j ρ_j, w = (θ_0 … θ_{Q−1}, then −c_n θ_q for n, q).
  const w = new Float64Array(q * (n + 1));
  for (let k = 0; k < q; k++) w[k] = th[k];
  for (let i = 0; i < n; i++) for (let k = 0; k < q; k++) w[q + i * q + k] = -c[i] * th[k];
  const r = rieszCombination(form, w);
  let alpha = Infinity;
  let gamma = 0;
  for (let k = 0; k < q; k++) {
    alpha = Math.min(alpha, th[k] / form.theta_bar[k]);
    gamma = Math.max(gamma, th[k] / form.theta_bar[k]);
  }
  let cc = 0;
  for (let i = 0; i < n; i++) cc += c[i] * c[i];
  return { coefficients: c, residual: r.norm, alpha, gamma, energyBound: r.norm / alpha, energyNorm: Math.sqrt(cc), coordinates: r.coordinates, floor: r.floor };
}

/** Σ_j w_j ρ_j for Riesz representers kept as coordinates in an X-orthonormal basis
 *  (`f.riesz`, ragged columns, with their norms `f.riesz_norms`): its coordinates, its norm
 *  plus the round-off floor unknowns · ε · Σ_j |w_j| ‖ρ_j‖, and that floor. The primal's
 *  residual (`solveOnline`) and a landmark's dual residual (`dualAnswer`) alike. */
function rieszCombination(f, w) {
  let rows = 0;
  for (const col of f.riesz) rows = Math.max(rows, col.length);
  const y = new Float64Array(rows);
  let sum = 0;
  for (let j = 0; j < w.length; j++) {
    const col = f.riesz[j];
    const wj = w[j];
    for (let i = 0; i < col.length; i++) y[i] += wj * col[i];
    sum += Math.abs(wj) * f.riesz_norms[j];
  }
  let yy = 0;
  for (let i = 0; i < rows; i++) yy += y[i] * y[i];
  const floor = f.unknowns * Number.EPSILON * sum;
  return { coordinates: y, norm: Math.sqrt(yy) + floor, floor };
}

/** An output's certified bound (mm) for the answer `o` of `solveOnline`, as
 *  `reduced::OutputBound::bound`: with c = (1/α + 1/γ)/2, c (‖F y‖ + g · floor) +
 *  g (1/α − 1/γ)/2 · residual, never above g Δ. `b` = {gain, factor (rows × k, row-major), rows}. */
export function outputBound(b, o) {
  const plain = b.gain * o.energyBound;
  if (!b.rows || !(Number.isFinite(o.gamma) && o.alpha > 0)) return plain;
  const cols = b.factor.length / b.rows;
  const len = Math.min(cols, o.coordinates.length);
  let ss = 0;
  for (let r = 0; r < b.rows; r++) {
    let s = 0;
    for (let j = 0; j < len; j++) s += b.factor[r * cols + j] * o.coordinates[j];
    ss += s * s;
  }
  const a = 1 / o.alpha;
  const g = 1 / o.gamma;
  const split = 0.5 * (a + g) * (Math.sqrt(ss) + b.gain * o.floor) + b.gain * 0.5 * (a - g) * o.residual;
  return Math.min(split, plain);
}

/** A landmark's dual form as report.html carries it (crates/facesim/src/report_page.rs
 *  `dual_json`: m, unknowns, each array's parts as one Float64Array, the Riesz columns with their
 *  lengths) back in `DualForm`'s shape for `dualAnswer`; null for a landmark without one. */
export function unpackDual(j, f64) {
  if (!j || !j.m) return null;
  const m = j.m;
  const split = (flat, len) => {
    const parts = [];
    for (let at = 0; at < flat.length; at += len) parts.push(flat.subarray(at, at + len));
    return parts;
  };
  const matrices = split(f64(j.matrices), m * m);
  const q = matrices.length;
  const coupling = f64(j.coupling);
  const riesz = [];
  const flat = f64(j.riesz);
  let at = 0;
  for (const len of j.riesz_lengths) {
    riesz.push(flat.subarray(at, at + len));
    at += len;
  }
  return {
    matrices,
    outputs: split(f64(j.outputs), m),
    loads: split(f64(j.loads), m),
    coupling: split(coupling, coupling.length / q),
    riesz,
    riesz_norms: j.riesz_norms,
    unknowns: j.unknowns,
  };
}

/** A landmark's dual answer at θ for the primal answer `o` of `solveOnline` (the same θ), as
 *  crates/facesim/src/reduced/dual.rs `DualForm::answer`: per component j the correction
 *  ψ_Nᵀ r to add to the face's value and the bound ‖r‖_X' ‖r_du,j‖_X' / α_LB plus the
 *  correction's round-off. `d` = {matrices, outputs, loads, coupling, riesz, riesz_norms,
 *  unknowns} (a `DualForm`); throws when its reduced system is not positive definite. */
export function dualAnswer(d, th, o) {
  const q = th.length;
  const m = d.outputs.length ? d.outputs[0].length : 0;
  const comps = d.outputs.length;
  const c = o.coefficients;
  const n = c.length;
  const a = new Float64Array(m * m);
  for (let k = 0; k < q; k++) for (let i = 0; i < m * m; i++) a[i] += th[k] * d.matrices[k][i];
  if (!cholesky(a, m)) throw new Error("reduced model: the dual reduced system is not positive definite");
  // Wᵀ r(θ) = Σ_q θ_q (Wᵀ f_q − Wᵀ A_q V c), and its terms' magnitudes for the round-off.
  const wr = new Float64Array(m);
  const wrAbs = new Float64Array(m);
  for (let k = 0; k < q; k++) {
    for (let i = 0; i < m; i++) {
      let avc = 0;
      let mag = 0;
      for (let j = 0; j < n; j++) {
        const x = d.coupling[k][i * n + j] * c[j];
        avc += x;
        mag += Math.abs(x);
      }
      wr[i] += th[k] * (d.loads[k][i] - avc);
      wrAbs[i] += th[k] * (Math.abs(d.loads[k][i]) + mag);
    }
  }
  const eps = (d.unknowns + m + n) * Number.EPSILON;
  const correction = [];
  const bound = [];
  for (let j = 0; j < comps; j++) {
    const phi = choleskySolve(a, m, d.outputs[j]);
    // X⁻¹ r_du = ρ(l_j) − Σ_{n,q} φ_n θ_q ρ(A_q w_n).
    const w = new Float64Array(comps + m * q);
    w[j] = 1;
    for (let i = 0; i < m; i++) for (let k = 0; k < q; k++) w[comps + i * q + k] = -phi[i] * th[k];
    const residual = rieszCombination(d, w).norm;
    let corr = 0;
    let round = 0;
    for (let i = 0; i < m; i++) {
      corr += phi[i] * wr[i];
      round += Math.abs(phi[i]) * wrAbs[i];
    }
    correction.push(corr);
    bound.push((o.residual * residual) / o.alpha + eps * round);
  }
  return { correction, bound };
}

/** Landmark `i`'s bound on the face's value (mm) by model `m` at θ `th` with its answer `o`
 *  there: through the Riesz representer, or with the landmark's dual form the smaller of that
 *  and `faceValueBound`'s. */
export function landmarkBound(m, i, th, o) {
  const d = m.duals && m.duals[i];
  return faceValueBound(outputBound(m.output_bounds[i], o), d ? dualAnswer(d, th, o) : null);
}

/** The bound on a landmark's displacement as the face shows it (mm): `plain`, its bound through
 *  the Riesz representer, or with a dual answer the correction's length plus the primal–dual
 *  bound (the face's value is the corrected one less the correction), whichever is smaller. */
export function faceValueBound(plain, dual) {
  if (!dual) return plain;
  const len = (v) => Math.sqrt(v.reduce((s, x) => s + x * x, 0));
  return Math.min(plain, len(dual.correction) + len(dual.bound));
}

/** out = lift + Σ_n c_n columns_n (float64), the face fields each `len` values long, the
 *  columns one after another in `columns`. */
export function reducedFace(lift, columns, c, out = new Float64Array(lift.length)) {
  const len = lift.length;
  for (let a = 0; a < len; a++) out[a] = lift[a];
  for (let k = 0; k < c.length; k++) {
    const ck = c[k];
    const off = k * len;
    for (let a = 0; a < len; a++) out[a] += ck * columns[off + a];
  }
  return out;
}

/** A slider's value at u ∈ [0, 1] of a distribution {uniform: [a, b]} or {log_uniform: [a, b]},
 *  as `Range::at`; and back. */
export function rangeAt(range, u) {
  if (range.log_uniform) {
    const [a, b] = range.log_uniform;
    return a * (b / a) ** u;
  }
  const [a, b] = range.uniform;
  return a + (b - a) * u;
}
export function rangeFraction(range, v) {
  if (range.log_uniform) {
    const [a, b] = range.log_uniform;
    return b > a ? Math.log(v / a) / Math.log(b / a) : 0;
  }
  const [a, b] = range.uniform;
  return b > a ? (v - a) / (b - a) : 0;
}

/** A range widened to hold `v` (the run's own value may lie outside `[uncertainty]`'s range;
 *  the trained box holds both). */
export function rangeWith(range, v) {
  const key = range.log_uniform ? "log_uniform" : "uniform";
  const [a, b] = range[key];
  return { [key]: [Math.min(a, v), Math.max(b, v)] };
}

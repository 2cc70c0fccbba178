// Landmarks and facial regions in the page (docs/guide/report-page.md, docs/guide/landmarks.md): the run's
// landmarks carried with a plan exactly as `facesim replan` carries them — a soft-tissue one as a
// material point of the face (barycentric weights on a face_pre triangle plus its offset), a bony
// one by its segment's rigid move — and per-region displacement statistics with report.json's
// definitions (mean, 90th percentile = sorted[round(0.9·(n − 1))], max).

/** Write each landmark's position for the face `face` (flat, face_pre order) and the segments'
 *  plan matrices `mats` (null: the segment stays) into `out` (3 per landmark). */
export function placeLandmarks(landmarks, faceTris, face, mats, out) {
  landmarks.forEach((l, i) => {
    const o = 3 * i;
    if (l.anchor) {
      const t = 3 * l.anchor.triangle;
      const w = l.anchor.weights;
      for (let k = 0; k < 3; k++)
        out[o + k] =
          w[0] * face[3 * faceTris[t] + k] + w[1] * face[3 * faceTris[t + 1] + k] + w[2] * face[3 * faceTris[t + 2] + k] + l.anchor.offset[k];
    } else {
      const m = l.segment < mats.length ? mats[l.segment] : null;
      const [x, y, z] = l.pre;
      for (let k = 0; k < 3; k++) out[o + k] = l.pre[k] + (m ? m[4 * k] * x + m[4 * k + 1] * y + m[4 * k + 2] * z + m[4 * k + 3] : 0);
    }
  });
  return out;
}

/** Per region name: {vertices, mean, p90, max} of `dist` over the vertices whose `regionOf` is the
 *  region's index; absent regions (no vertex) are left out. */
export function regionStats(names, regionOf, dist) {
  const values = names.map(() => []);
  for (let v = 0; v < regionOf.length; v++) if (regionOf[v] < names.length) values[regionOf[v]].push(dist[v]);
  const out = {};
  names.forEach((name, k) => {
    const d = Float64Array.from(values[k]).sort();
    const n = d.length;
    if (n === 0) return;
    let sum = 0;
    for (const x of d) sum += x;
    out[name] = { vertices: n, mean: sum / n, p90: d[Math.round(0.9 * (n - 1))], max: d[n - 1] };
  });
  return out;
}

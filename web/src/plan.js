// A plan in the page (docs/report-page.md): a segment's rigid map x ↦ R (x − pivot) + pivot + t
// with R = Rz·Ry·Rx (rotate about x, then y, then z; degrees), as crates/facesim/src/osteotomy.rs.
// Written as x ↦ x + M·[x; 1] with M = [R − I | (I − R)·pivot + t], the face displacement of a
// linear model is d = Σ_k m_k · column_k (k = 4·i + j, row-major), so the basis columns give the
// face for any plan, large rotations included.

/** R = Rz·Ry·Rx for angles in degrees, as a row-major 3×3 array of rows. */
export function rotation(deg) {
  const [a, b, c] = deg.map((d) => (d * Math.PI) / 180);
  const [ca, sa, cb, sb, cc, sc] = [Math.cos(a), Math.sin(a), Math.cos(b), Math.sin(b), Math.cos(c), Math.sin(c)];
  // Rz·Ry·Rx multiplied out.
  return [
    [cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa],
    [sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa],
    [-sb, cb * sa, cb * ca],
  ];
}

/** The 12 entries of M = [R − I | t′] (row-major) of one segment's move; zeros when absent. */
export function planMatrix(move, pivot) {
  const m = new Float64Array(12);
  if (!move) return m;
  const t = move.translate || [0, 0, 0];
  const r = rotation(move.rotate_deg || [0, 0, 0]);
  for (let i = 0; i < 3; i++) {
    let rp = 0;
    for (let j = 0; j < 3; j++) {
      m[4 * i + j] = r[i][j] - (i === j ? 1 : 0);
      rp += r[i][j] * pivot[j];
    }
    m[4 * i + 3] = pivot[i] - rp + t[i];
  }
  return m;
}

/** out = face_pre + Σ_segments Σ_k m_k · columns_k; columns are 12 blocks of 3·n floats. */
export function predictFace(facePre, segments, plan, out) {
  const len = facePre.length;
  for (let a = 0; a < len; a++) out[a] = facePre[a];
  for (const s of segments) {
    const m = planMatrix(plan[s.name], s.pivot);
    for (let k = 0; k < 12; k++) {
      const w = m[k];
      if (w === 0) continue;
      const col = s.columns.subarray(k * len, (k + 1) * len);
      for (let a = 0; a < len; a++) out[a] += w * col[a];
    }
  }
  return out;
}

/** Move points rigidly: point v by the matrix of segment `which[v]` (255 or null: stays). */
export function moveRigid(points, which, mats, out) {
  for (let v = 0; v < points.length / 3; v++) {
    const x = points[3 * v];
    const y = points[3 * v + 1];
    const z = points[3 * v + 2];
    const m = which[v] < mats.length ? mats[which[v]] : null;
    if (!m) {
      out[3 * v] = x;
      out[3 * v + 1] = y;
      out[3 * v + 2] = z;
      continue;
    }
    for (let i = 0; i < 3; i++) {
      const p = i === 0 ? x : i === 1 ? y : z;
      out[3 * v + i] = p + m[4 * i] * x + m[4 * i + 1] * y + m[4 * i + 2] * z + m[4 * i + 3];
    }
  }
  return out;
}

// A plan in the page (docs/guide/report-page.md): a segment's rigid map x ↦ R (x − pivot) + pivot + t
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

/** The right-handed rotation by `deg` degrees about the unit axis `u` (Rodrigues), rows; as
 *  crates/facesim/src/anatomy/moves.rs `about_axis`. */
export function aboutAxis(u, deg) {
  const a = (deg * Math.PI) / 180;
  const [s, c] = [Math.sin(a), Math.cos(a)];
  const k = [
    [0, -u[2], u[1]],
    [u[2], 0, -u[0]],
    [-u[1], u[0], 0],
  ];
  const r = [[], [], []];
  for (let i = 0; i < 3; i++)
    for (let j = 0; j < 3; j++) {
      let kk = 0;
      for (let m = 0; m < 3; m++) kk += k[i][m] * k[m][j];
      r[i][j] = (i === j ? 1 : 0) + s * k[i][j] + (1 - c) * kk;
    }
  return r;
}

function mul(a, b) {
  const r = [[], [], []];
  for (let i = 0; i < 3; i++)
    for (let j = 0; j < 3; j++) r[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
  return r;
}

/** The six clinical moves (docs/guide/planning.md "Signs") as the page's move in LPS: R = R_yaw·R_roll·
 *  R_pitch, right-handed about the frame's left, forward and up axes, t = advance·forward +
 *  up·up + left·left (p' = R (p − pivot) + pivot + t). `frame`: {forward, up, left} (LPS units);
 *  a key left out is 0. */
export function clinicalMove(moves, frame) {
  const v = (k) => Number(moves[k] || 0);
  const rot = mul(aboutAxis(frame.up, v("yaw_deg")), mul(aboutAxis(frame.forward, v("roll_deg")), aboutAxis(frame.left, v("pitch_deg"))));
  const translate = [0, 1, 2].map((i) => v("advance_mm") * frame.forward[i] + v("up_mm") * frame.up[i] + v("left_mm") * frame.left[i]);
  return { translate, rotation: rot };
}

/** A move's rotation matrix (rows): `rotation` when given, else from `rotate_deg`. */
export function moveRotation(move) {
  return move.rotation || rotation(move.rotate_deg || [0, 0, 0]);
}

/** The clinical moves of an LPS move (translate, rotation), as moves.rs `read_back`. */
export function readBack(move, frame) {
  const t = move.translate || [0, 0, 0];
  const r = moveRotation(move);
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  // R in the frame's basis (x left, y up, z forward): Ry(yaw) Rz(roll) Rx(pitch).
  const axes = [frame.left, frame.up, frame.forward];
  const m = axes.map((a) => axes.map((b) => dot(a, [0, 1, 2].map((i) => dot(r[i], b)))));
  const deg = (x) => (x * 180) / Math.PI;
  return {
    advance_mm: dot(t, frame.forward),
    up_mm: dot(t, frame.up),
    left_mm: dot(t, frame.left),
    pitch_deg: deg(Math.atan2(-m[1][2], m[1][1])),
    roll_deg: deg(Math.asin(Math.min(Math.max(m[1][0], -1), 1))),
    yaw_deg: deg(Math.atan2(-m[2][0], m[0][0])),
  };
}

/** The 12 entries of M = [R − I | t′] (row-major) of one segment's move; zeros when absent. A
 *  move is {translate, rotate_deg} (R = Rz·Ry·Rx) or {translate, rotation} (R's rows). */
export function planMatrix(move, pivot, m = new Float64Array(12)) {
  m.fill(0);
  if (!move) return m;
  const t = move.translate || [0, 0, 0];
  const r = moveRotation(move);
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

/** The basis as the page keeps it: `columns` (12 blocks of `len` floats, column k at k·len) with
 *  the 12 values of each coordinate side by side (entry 12·a + k), so the sum below reads one
 *  array front to back instead of twelve. */
export function interleaveColumns(columns, len) {
  const out = new Float32Array(12 * len);
  for (let k = 0; k < 12; k++) {
    const col = columns.subarray(k * len, (k + 1) * len);
    for (let a = 0; a < len; a++) out[12 * a + k] = col[a];
  }
  return out;
}

const scratch = new Float64Array(12);

/** out = face_pre + Σ_segments Σ_k m_k · column_k; each segment's `columns` interleaved
 *  (interleaveColumns). `out` may be a Float32Array (the page's vertex buffer). */
export function predictFace(facePre, segments, plan, out) {
  const len = facePre.length;
  out.set(facePre);
  for (const s of segments) {
    if (!plan[s.name]) continue;
    const [m0, m1, m2, m3, m4, m5, m6, m7, m8, m9, m10, m11] = planMatrix(plan[s.name], s.pivot, scratch);
    const c = s.columns;
    for (let a = 0, b = 0; a < len; a++, b += 12)
      out[a] +=
        m0 * c[b] + m1 * c[b + 1] + m2 * c[b + 2] + m3 * c[b + 3] + m4 * c[b + 4] + m5 * c[b + 5] +
        m6 * c[b + 6] + m7 * c[b + 7] + m8 * c[b + 8] + m9 * c[b + 9] + m10 * c[b + 10] + m11 * c[b + 11];
  }
  return out;
}

/** Move points [0, count) rigidly: point v by the matrix of segment `which[v]` (255 or null:
 *  stays). */
export function moveRigid(points, which, mats, out, count = points.length / 3) {
  for (let v = 0; v < count; v++) {
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

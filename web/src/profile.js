// The midsagittal profile (the cephalometric tracing view): the face cut by the head frame's
// midsagittal plane, as polylines in the head's (front, up) coordinates, mm from the frame's
// origin. Each triangle that straddles the plane gives one segment between the points where two
// of its edges cross it; segments sharing an edge point are chained.

/** Polylines [[f0, u0, f1, u1, …], …] of the cut of `pos` (flat xyz) / `tris` (flat indices) by
 *  the plane through `frame.origin` with normal `frame.left`. */
export function midsagittalCut(pos, tris, frame) {
  const [o, f, u, l] = [frame.origin, frame.front, frame.up, frame.left];
  const nv = pos.length / 3;
  const side = new Float64Array(nv);
  for (let v = 0; v < nv; v++)
    side[v] = (pos[3 * v] - o[0]) * l[0] + (pos[3 * v + 1] - o[1]) * l[1] + (pos[3 * v + 2] - o[2]) * l[2];
  // A vertex exactly on the plane counts as on the positive side, so every crossing is on an edge.
  const pos0 = (v) => side[v] >= 0;
  const point = new Map(); // edge key → [f, u]
  const links = new Map(); // edge key → neighbouring edge keys
  const crossing = (a, b) => {
    const key = a < b ? a * nv + b : b * nv + a;
    if (!point.has(key)) {
      const t = side[a] / (side[a] - side[b]);
      const p = [0, 1, 2].map((k) => pos[3 * a + k] + t * (pos[3 * b + k] - pos[3 * a + k]) - o[k]);
      point.set(key, [p[0] * f[0] + p[1] * f[1] + p[2] * f[2], p[0] * u[0] + p[1] * u[1] + p[2] * u[2]]);
      links.set(key, []);
    }
    return key;
  };
  for (let t = 0; t < tris.length; t += 3) {
    const c = [tris[t], tris[t + 1], tris[t + 2]];
    const keys = [];
    for (let e = 0; e < 3; e++) {
      const a = c[e];
      const b = c[(e + 1) % 3];
      if (pos0(a) !== pos0(b)) keys.push(crossing(a, b));
    }
    if (keys.length === 2) {
      links.get(keys[0]).push(keys[1]);
      links.get(keys[1]).push(keys[0]);
    }
  }
  const used = new Set();
  const lines = [];
  const walk = (start) => {
    const line = [];
    let prev = -1;
    let at = start;
    while (at !== undefined && !used.has(at)) {
      used.add(at);
      line.push(...point.get(at));
      const next = links.get(at).find((k) => k !== prev && !used.has(k));
      prev = at;
      at = next;
    }
    // A closed loop: end where it began.
    if (line.length > 4 && links.get(start).includes(prev) && prev !== start) line.push(line[0], line[1]);
    if (line.length >= 4) lines.push(line);
  };
  // Open chains from their ends first, then closed loops.
  for (const [k, n] of links) if (n.length === 1 && !used.has(k)) walk(k);
  for (const k of links.keys()) if (!used.has(k)) walk(k);
  return lines;
}

/** The facial part of a cut: points within `depth` mm behind the most anterior one; polylines are
 *  split where they leave it (a whole head's cut also runs round the back of the skull). */
export function facialPart(lines, depth = 90) {
  let front = -Infinity;
  for (const l of lines) for (let i = 0; i < l.length; i += 2) front = Math.max(front, l[i]);
  const out = [];
  for (const l of lines) {
    let cur = [];
    for (let i = 0; i < l.length; i += 2) {
      if (l[i] >= front - depth) cur.push(l[i], l[i + 1]);
      else {
        if (cur.length >= 4) out.push(cur);
        cur = [];
      }
    }
    if (cur.length >= 4) out.push(cur);
  }
  return out;
}

/** SVG path data of polylines, x = front, y = −up (mm; SVG's y points down). */
export function pathData(lines) {
  return lines
    .map((l) => {
      let d = "";
      for (let i = 0; i < l.length; i += 2) d += `${i === 0 ? "M" : "L"}${l[i].toFixed(2)} ${(-l[i + 1]).toFixed(2)}`;
      return d;
    })
    .join("");
}

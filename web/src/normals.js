// Vertex normals in typed-array loops (three.js' computeVertexNormals allocates and goes through
// Vector3 accessors; this is what every slider move recomputes). Area-weighted like three.js: each
// triangle adds its unnormalised cross product to its corners; then each normal is made unit.

function accumulate(pos, tris, t, out, limit) {
  const a = 3 * tris[t];
  const b = 3 * tris[t + 1];
  const c = 3 * tris[t + 2];
  const ux = pos[b] - pos[a];
  const uy = pos[b + 1] - pos[a + 1];
  const uz = pos[b + 2] - pos[a + 2];
  const vx = pos[c] - pos[a];
  const vy = pos[c + 1] - pos[a + 1];
  const vz = pos[c + 2] - pos[a + 2];
  const nx = uy * vz - uz * vy;
  const ny = uz * vx - ux * vz;
  const nz = ux * vy - uy * vx;
  if (a < limit) add(out, a, nx, ny, nz);
  if (b < limit) add(out, b, nx, ny, nz);
  if (c < limit) add(out, c, nx, ny, nz);
}

function add(out, p, x, y, z) {
  out[p] += x;
  out[p + 1] += y;
  out[p + 2] += z;
}

function normalise(out, end) {
  for (let p = 0; p < end; p += 3) {
    const x = out[p];
    const y = out[p + 1];
    const z = out[p + 2];
    const l = Math.sqrt(x * x + y * y + z * z);
    if (l > 0) {
      out[p] = x / l;
      out[p + 1] = y / l;
      out[p + 2] = z / l;
    }
  }
}

/** Unit vertex normals of the mesh (`pos` flat xyz, `tris` flat indices) into `out`. */
export function vertexNormals(pos, tris, out) {
  out.fill(0);
  for (let t = 0; t < tris.length; t += 3) accumulate(pos, tris, t, out, out.length);
  normalise(out, out.length);
}

/** The normals of vertices [0, count) only; `tris` must hold every triangle with a corner below
 *  `count` (it may hold others). The other normals are left as they are. */
export function leadingVertexNormals(pos, tris, count, out) {
  const end = 3 * count;
  out.fill(0, 0, end);
  for (let t = 0; t < tris.length; t += 3) accumulate(pos, tris, t, out, end);
  normalise(out, end);
}

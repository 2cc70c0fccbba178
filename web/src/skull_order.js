// The skull's vertices reordered so that one slider move touches one leading range of the buffers:
// first the vertices a plan can move, then the static ones that share a triangle with a moved one
// (their normals change), then the rest. Positions are uploaded for the first range only and
// normals recomputed and uploaded for the first two; the far larger rest of the skull is never
// touched again. The order is the page's own: nothing outside the page sees it.

/** `which[v]`: the segment of vertex v; `movable(s)`: can a plan move segment s. Returns `order`
 *  (new index → old), `moved` and `dirty` (the ends of the two leading ranges) and the remapped
 *  triangles in two sets: `movingTris`, those with a corner below `dirty` (their shape or shading
 *  follows the plan), and `staticTris`, the rest. */
export function orderSkull(which, movable, tris) {
  const count = which.length;
  const moving = new Uint8Array(count);
  for (let v = 0; v < count; v++) moving[v] = movable(which[v]) ? 1 : 0;
  const touched = new Uint8Array(count);
  for (let t = 0; t < tris.length; t += 3) {
    const [a, b, c] = [tris[t], tris[t + 1], tris[t + 2]];
    if (moving[a] || moving[b] || moving[c]) touched[a] = touched[b] = touched[c] = 1;
  }
  const order = new Uint32Array(count);
  let k = 0;
  for (let v = 0; v < count; v++) if (moving[v]) order[k++] = v;
  const moved = k;
  for (let v = 0; v < count; v++) if (!moving[v] && touched[v]) order[k++] = v;
  const dirty = k;
  for (let v = 0; v < count; v++) if (!touched[v] && !moving[v]) order[k++] = v;
  const inverse = new Uint32Array(count);
  for (let i = 0; i < count; i++) inverse[order[i]] = i;
  const movingTris = [];
  const still = [];
  for (let t = 0; t < tris.length; t += 3) {
    const [a, b, c] = [inverse[tris[t]], inverse[tris[t + 1]], inverse[tris[t + 2]]];
    (Math.min(a, b, c) < dirty ? movingTris : still).push(a, b, c);
  }
  return { order, moved, dirty, movingTris: Uint32Array.from(movingTris), staticTris: Uint32Array.from(still) };
}

/** `values` (`width` numbers per vertex) in the new order. */
export function reorder(values, order, width) {
  const out = new values.constructor(order.length * width);
  for (let i = 0; i < order.length; i++)
    for (let j = 0; j < width; j++) out[width * i + j] = values[width * order[i] + j];
  return out;
}

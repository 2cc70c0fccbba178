// Viridis (matplotlib's, 9 control points, linear in between), the same table as
// crates/facesim/src/pipeline/outputs.rs uses for face_displacement.ply.
const C = [
  [68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
  [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37],
];

/** RGB (0–255) at t ∈ [0, 1]. */
export function viridis(t) {
  const x = Math.min(Math.max(t, 0), 1) * 8;
  const i = Math.min(Math.floor(x), 7);
  const f = x - i;
  return [0, 1, 2].map((k) => Math.round(C[i][k] + f * (C[i + 1][k] - C[i][k])));
}

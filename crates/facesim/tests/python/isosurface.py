"""An iso-surface of a CT as another program exports it (the fixture of crates/facesim/tests/library/foreign_skin.rs).

scikit-image's marching cubes (Lewiner) on the whole volume at one level: the skin with the
airway, sinuses and every other air/tissue boundary inside the head, no cleaning. Written as a
binary STL, which has no shared vertices (each triangle repeats its corners), the way 3D Slicer
and most segmentation programs export a model.

Usage: isosurface.py RAW JSON LEVEL OUT.stl
RAW: float32 little-endian HU, x fastest (dims [nx, ny, nz]); JSON: {"dims", "spacing",
"origin", "direction"} with direction[a] the LPS unit vector of voxel axis a (facesim's Volume).
(Or an indexed OBJ when OUT ends in .obj.)
"""
import json
import sys

import numpy as np
from skimage.measure import marching_cubes

raw, meta_path, level, out = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
meta = json.load(open(meta_path))
nx, ny, nz = meta["dims"]
vol = np.fromfile(raw, dtype="<f4").reshape(nz, ny, nx)
verts, faces, _, _ = marching_cubes(vol, level=level)
# verts are (k, j, i) voxel indices; world = origin + sum_a idx_a * spacing_a * direction_a.
idx = verts[:, ::-1]
sp = np.asarray(meta["spacing"], dtype=float)
d = np.asarray(meta["direction"], dtype=float)
world = np.asarray(meta["origin"], dtype=float) + (idx * sp) @ d
tri = world[faces]
normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
rec = np.zeros(len(faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
rec["n"] = normals
rec["v"] = tri
if out.endswith(".obj"):
    # Indexed (shared vertices), for readers of OBJ only.
    with open(out, "w") as f:
        np.savetxt(f, world, fmt="v %.5f %.5f %.5f")
        np.savetxt(f, faces + 1, fmt="f %d %d %d")
    print(len(faces))
    sys.exit(0)
with open(out, "wb") as f:
    f.write(b"skimage marching_cubes iso-surface SPACE=LPS".ljust(80, b" "))
    f.write(np.uint32(len(faces)).tobytes())
    f.write(rec.tobytes())
print(len(faces))

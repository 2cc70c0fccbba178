"""A case's size as the cohort workflow sizes its jobs (docs/guide/cohort.md, "Resources from the
model", its fallback formula): the CT's voxel count and the skin scan's vertex count, read from the files' headers
without loading them, and the resources a `facesim run` of that size needs. Standard library
only; imported by workflow/Snakefile and workflow/scripts/size_figures.py.

    python3 case_size.py PLAN.toml   # prints voxels, vertices, mem_mb, runtime (minutes)
"""

import gzip
import json
import math
import os
import struct
import subprocess
import sys
import tomllib

from replacing import write_json


def _nifti_voxels(path):
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rb") as f:
        head = f.read(348)
    if len(head) < 348:
        return None
    for endian in "<>":
        (size,) = struct.unpack(endian + "i", head[:4])
        if size == 348:
            dims = struct.unpack(endian + "8h", head[40:56])
            n = 1
            for d in dims[1 : 1 + max(1, min(dims[0], 7))]:
                n *= max(int(d), 1)
            return n
    return None


def _nrrd_voxels(path):
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("latin-1").strip()
            if not line:
                break
            if line.lower().startswith("sizes:"):
                n = 1
                for d in line.split(":", 1)[1].split():
                    n *= int(d)
                return n
    return None


def ct_voxels(path):
    """The CT's voxel count: exact from a NIfTI or NRRD header, otherwise estimated as the
    bytes on disk over 2 (16-bit samples: a DICOM series, uncompressed) — an underestimate for
    compressed DICOM, which the formula's margin covers up to 2:1."""
    p = path.lower()
    try:
        if p.endswith((".nii", ".nii.gz")):
            return _nifti_voxels(path)
        if p.endswith((".nrrd", ".nhdr")):
            return _nrrd_voxels(path)
    except (OSError, ValueError, struct.error):
        return None
    total = 0
    if os.path.isdir(path):
        for d, _, files in os.walk(path):
            total += sum(os.path.getsize(os.path.join(d, f)) for f in files)
    elif os.path.isfile(path):
        total = os.path.getsize(path)
    return total // 2 or None


def mesh_vertices(path):
    """Vertices of a skin scan: a PLY's `element vertex`, an OBJ's `v` lines; None for the
    other formats (the formula then goes by the CT alone)."""
    p = path.lower()
    try:
        if p.endswith(".ply"):
            with open(path, "rb") as f:
                for raw in f:
                    line = raw.decode("latin-1").strip()
                    if line.startswith("element vertex"):
                        return int(line.split()[2])
                    if line == "end_header":
                        return None
        if p.endswith(".obj"):
            with open(path, "rb") as f:
                return sum(1 for line in f if line.startswith(b"v "))
    except (OSError, ValueError, IndexError):
        return None
    return None


def case_size(plan):
    """(CT voxels, skin vertices) of a plan file; either None when unknown."""
    try:
        with open(plan, "rb") as f:
            case = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError):
        return None, None
    here = os.path.dirname(os.path.abspath(plan))

    def path_of(section):
        p = (case.get(section) or {}).get("path")
        return os.path.join(here, p) if isinstance(p, str) else None

    ct = path_of("ct")
    skin = path_of("skin")
    return (ct_voxels(ct) if ct else None), (mesh_vertices(skin) if skin else None)


# The formula (docs/guide/cohort.md gives the measurements behind it, from size_figures.py and
# docs/lab/performance.md). Peak memory of the default (tet) model, the most expensive one, is
# about 1.35–1.45 GB on every jaws phantom from 0.26 to 2 M voxels and 1.68 GB on the 106 M-voxel
# phantom: a fixed 1 400 MB plus the CT's float copy (4 bytes a voxel) plus the skin scan; times
# MEM_MARGIN. Wall time: 9 s on a quiet core for the 2 mm phantom and 9.3 s for 106 M voxels,
# up to 6× that on a loaded or slow machine; times RUNTIME_MARGIN, whole minutes, at least
# MIN_RUNTIME_MIN (a scheduler's kill is expensive, an over-long request costs only backfill).
MEM_BASE_MB = 1400
MEM_MB_PER_MVOXEL = 4
MEM_MB_PER_KVERTEX = 10
MEM_MARGIN = 1.5
SECONDS_BASE = 10
SECONDS_PER_MVOXEL = 0.1
SECONDS_PER_KVERTEX = 0.2
RUNTIME_MARGIN = 10
MIN_RUNTIME_MIN = 5
# What a case of unknown size gets (the configuration's old fixed figures).
UNKNOWN_MEM_MB = 4000
UNKNOWN_RUNTIME_MIN = 30


def resources_for(voxels, vertices):
    """(mem_mb, runtime minutes) for a case of this size."""
    if not voxels:
        return UNKNOWN_MEM_MB, UNKNOWN_RUNTIME_MIN
    mvox = voxels / 1e6
    kvert = (vertices or 0) / 1e3
    mem = MEM_MARGIN * (MEM_BASE_MB + MEM_MB_PER_MVOXEL * mvox + MEM_MB_PER_KVERTEX * kvert)
    sec = RUNTIME_MARGIN * (SECONDS_BASE + SECONDS_PER_MVOXEL * mvox + SECONDS_PER_KVERTEX * kvert)
    return int(math.ceil(mem / 100.0) * 100), max(MIN_RUNTIME_MIN, int(math.ceil(sec / 60.0)))


# Resources from the model itself (docs/guide/cohort.md "Resources from the model"): `facesim estimate`
# builds the run's mesh and analyses its factor symbolically, and predicts the run's peak memory
# and wall time. A job holds more than facesim (the job script, Snakemake's job step): JOB_MB on
# top. Its time is the prediction for a quiet machine like docs/guide/cohort.md's, times
# ESTIMATE_RUNTIME_MARGIN for a loaded or slower node, at least MIN_RUNTIME_MIN.
JOB_MB = 300
ESTIMATE_RUNTIME_MARGIN = 4


def estimate(facesim, plan, sets, threads, cache):
    """`facesim estimate`'s JSON for a plan with the variant's --set arguments (a list), kept in
    the file `cache` (None: not kept, as in a dry run) so the job step and later invocations
    read it instead of asking again; None if the estimate fails (a broken case: the run will
    say why)."""

    if cache is not None:
        try:
            with open(cache) as f:
                return json.load(f)
        except (OSError, ValueError):
            pass
    cmd = [facesim, "--threads", str(threads), "estimate", plan, *sets]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if out.returncode != 0:
        return None
    try:
        e = json.loads(out.stdout)
    except ValueError:
        return None
    if cache is None:
        return e
    try:
        write_json(cache, e)
    except OSError:
        pass
    return e


def resources_from_estimate(e):
    """(mem_mb, runtime minutes) from `facesim estimate`'s JSON."""
    mem = e["peak_mem_mb"] + JOB_MB
    sec = ESTIMATE_RUNTIME_MARGIN * e["wall_s"]
    return int(math.ceil(mem / 100.0) * 100), max(MIN_RUNTIME_MIN, int(math.ceil(sec / 60.0)))


if __name__ == "__main__":
    for plan in sys.argv[1:]:
        v, n = case_size(plan)
        print(plan, v, n, *resources_for(v, n))

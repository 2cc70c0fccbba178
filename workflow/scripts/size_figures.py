#!/usr/bin/env python3
"""The figures behind the workflow's resource formula (docs/guide/cohort.md, "Resources from the
model", its fallback formula): one jaws phantom per voxel size, each run with the models given, one after the other;
prints CT voxels, skin-scan vertices, wall seconds and peak resident memory per run as CSV.

    size_figures.py FACESIM WORK [--spacings 3,2.5,2,1.5] [--models tet,equilibrium]

Standard library only; the size readers are the Snakefile's (workflow/scripts/case_size.py)."""

import argparse
import os
import resource
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from case_size import case_size  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("facesim")
    ap.add_argument("work")
    ap.add_argument("--spacings", default="3,2.5,2,1.5")
    ap.add_argument("--models", default="tet,equilibrium")
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    print("spacing_mm,model,ct_voxels,face_vertices,seconds,peak_mem_mb", flush=True)
    for s in a.spacings.split(","):
        case = os.path.join(a.work, f"s{s}")
        if not os.path.isdir(case):
            subprocess.run([a.facesim, "phantom-cohort", case, "--cases", "1", "--seed", "1",
                            "--spacing", s, "--slice", s], check=True, capture_output=True)
        plan = os.path.join(case, "case001", "case.toml")
        voxels, vertices = case_size(plan)
        for model in a.models.split(","):
            # A fresh process per run, so its children's peak RSS is this run's alone.
            code = (
                "import resource, subprocess, sys, time\n"
                "t = time.monotonic()\n"
                "subprocess.run(sys.argv[1:], check=True, capture_output=True)\n"
                "print(time.monotonic() - t,"
                " resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)\n"
            )
            out = subprocess.run(
                [sys.executable, "-c", code, a.facesim, "--threads", str(a.threads), "run",
                 plan, "--out", os.path.join(case, f"out-{model}"),
                 "--set", f'solve.model="{model}"'],
                check=True, capture_output=True, text=True).stdout.split()
            print(f"{s},{model},{voxels},{vertices},{float(out[0]):.1f},{float(out[1]):.0f}",
                  flush=True)


if __name__ == "__main__":
    sys.exit(main())

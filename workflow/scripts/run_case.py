#!/usr/bin/env python3
"""One cohort run (docs/cohort.md): `facesim run PLAN --out OUT [--set K=V ...]`, timed, and its
result.json — status "ok" or facesim's one-line error, wall seconds, peak memory of the
facesim process. Exits 0 whether facesim succeeded or not, so one broken case does not stop the
cohort; only a failure of this script itself (e.g. an unwritable output) is an error.
Standard library only."""

import argparse
import json
import os
import resource
import subprocess
import sys
import time


def one_line_error(stderr: str, code: int) -> str:
    """facesim's one-line error: its last line starting "facesim:", else the last line."""
    lines = [l.strip() for l in stderr.splitlines() if l.strip()]
    for line in reversed(lines):
        if line.startswith("facesim:"):
            return line
    return lines[-1] if lines else f"facesim exited with status {code} and no message"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--facesim", required=True)
    ap.add_argument("--case", required=True, help="the plan's .toml file")
    ap.add_argument("--out", required=True, help="facesim's output directory")
    ap.add_argument("--result", required=True, help="result.json to write")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--name", required=True, help="the case's name")
    ap.add_argument("--plan", required=True)
    ap.add_argument("--variant", required=True)
    ap.add_argument("--set", action="append", default=[], dest="sets")
    a = ap.parse_args()

    cmd = [a.facesim]
    if a.threads > 0:
        cmd += ["--threads", str(a.threads)]
    cmd += ["run", a.case, "--out", a.out]
    for s in a.sets:
        cmd += ["--set", s]
    print("$", " ".join(cmd), flush=True)
    start = time.monotonic()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True)
        code, stdout, stderr = p.returncode, p.stdout, p.stderr
    except OSError as e:
        code, stdout, stderr = -1, "", f"facesim: cannot run {a.facesim}: {e.strerror}"
    seconds = time.monotonic() - start
    # This script starts one child: the children's peak RSS is facesim's (KiB on Linux).
    peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    sys.stdout.write(stdout)
    sys.stdout.write(stderr)
    result = {
        "case": a.name,
        "plan": a.plan,
        "variant": a.variant,
        "case_file": a.case,
        "overrides": a.sets,
        "status": "ok" if code == 0 else one_line_error(stderr, code),
        "exit_code": code,
        "seconds": seconds,
        "peak_mem_mb": peak_kib / 1024.0,
        "out_dir": os.path.relpath(a.out, os.path.dirname(a.result) or "."),
    }
    os.makedirs(os.path.dirname(a.result) or ".", exist_ok=True)
    tmp = a.result + ".tmp"
    with open(tmp, "w") as f:
        json.dump(result, f, indent=1)
    os.replace(tmp, a.result)
    return 0


if __name__ == "__main__":
    sys.exit(main())

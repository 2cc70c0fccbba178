#!/usr/bin/env python3
"""One cohort run (docs/cohort.md): `facesim run PLAN --out OUT [--set K=V ...]`, timed, and its
result.json — status "ok" or facesim's one-line error, wall seconds, peak memory of the
facesim process, and its provenance (facesim's version and binary hash, the case's hash).
Exits 0 whether facesim succeeded or not, so one broken case does not stop the cohort; only a
failure of this script itself (e.g. an unwritable output) is an error.

Under Slurm (SLURM_JOB_ID set) each attempt appends its job id to --jobs-file. A retry
(--attempt 2, 3, …) first asks Slurm how the previous attempt's job ended: killed for its memory
or time limit (OUT_OF_MEMORY, TIMEOUT), the same limits would kill it again, so the retry records
Slurm's reason as the run's status instead of running facesim; any other end (cancelled, node
lost) runs it again. Standard library only."""

import argparse
import hashlib
import json
import os
import resource
import shutil
import subprocess
import sys
import time
import tomllib

# Slurm job states a retry with the same request would meet again.
LIMIT_STATES = ("OUT_OF_MEMORY", "TIMEOUT")


def one_line_error(stderr: str, code: int) -> str:
    """facesim's one-line error: its last line starting "facesim:", else the last line."""
    lines = [l.strip() for l in stderr.splitlines() if l.strip()]
    for line in reversed(lines):
        if line.startswith("facesim:"):
            return line
    return lines[-1] if lines else f"facesim exited with status {code} and no message"


def file_sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def case_sha256(plan: str) -> str:
    """The case's hash: the plan file and every file or directory its TOML names (the CT, a
    skin scan, masks, transforms), by relative name and content, in name order. Empty when the
    plan cannot be read."""
    try:
        with open(plan, "rb") as f:
            doc = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError):
        return ""
    here = os.path.dirname(os.path.abspath(plan))
    names = set()

    def walk(v):
        if isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)
        elif isinstance(v, str) and v and os.path.exists(os.path.join(here, v)):
            p = os.path.join(here, v)
            if os.path.isdir(p):
                for d, _, files in os.walk(p):
                    names.update(os.path.join(d, f) for f in files)
            else:
                names.add(p)

    walk(doc)
    h = hashlib.sha256()
    h.update(b"plan\0" + file_sha256(plan).encode() + b"\n")
    for p in sorted(names):
        rel = os.path.relpath(p, here)
        h.update(rel.encode() + b"\0" + file_sha256(p).encode() + b"\n")
    return h.hexdigest()


def facesim_provenance(facesim: str):
    """(`facesim --version`, sha256 of the binary) — the version names the release, the hash
    the exact build."""
    path = shutil.which(facesim) or facesim
    try:
        version = subprocess.run([path, "--version"], capture_output=True, text=True,
                                 timeout=60).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        version = ""
    try:
        digest = file_sha256(path)
    except OSError:
        digest = ""
    return version, digest


def slurm_job_end(job_id: str):
    """How a finished Slurm job ended: (state, details), None when Slurm no longer knows it.

    With an accounting database, sacct gives every step's state. Without one, scontrol gives
    the job's (slurmctld keeps a finished job for MinJobAge). Through the executor plugin the
    run is step 0 of the job (srun inside sbatch): over its memory the step ends OUT_OF_MEMORY
    but the job FAILED, so a FAILED job's Slurm log (its StdOut) is read for slurmstepd's
    oom-kill line and srun's "Out Of Memory"."""
    try:
        p = subprocess.run(
            ["sacct", "-j", job_id, "-n", "-P",
             "-o", "JobID,State,ExitCode,Elapsed,Timelimit,ReqMem"],
            capture_output=True, text=True, timeout=60)
        lines = [l.split("|") for l in p.stdout.strip().splitlines()] if p.returncode == 0 else []
        if lines:
            states = [(l + [""] * 6)[1].split()[0] for l in lines]
            job = (lines[0] + [""] * 6)
            state = next((s for s in states if s in LIMIT_STATES), states[0])
            return state, (f"job {job[1]}, steps {' '.join(states[1:]) or '-'}, exit code "
                           f"{job[2]}, ran {job[3]} of {job[4]}, memory {job[5]}")
    except (OSError, subprocess.TimeoutExpired, IndexError):
        pass
    try:
        p = subprocess.run(["scontrol", "-o", "show", "job", job_id],
                           capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if p.returncode != 0 or not p.stdout.strip():
        return None
    kv = dict(w.split("=", 1) for w in p.stdout.split() if "=" in w)
    state = kv.get("JobState", "UNKNOWN")
    mem = kv.get("MinMemoryNode") or kv.get("MinMemoryCPU", "")
    details = (f"reason {kv.get('Reason', '?')}, exit code {kv.get('ExitCode', '?')}, "
               f"ran {kv.get('RunTime', '?')} of {kv.get('TimeLimit', '?')}, memory {mem}")
    if state == "FAILED" and kv.get("StdOut"):
        try:
            with open(kv["StdOut"], errors="replace") as f:
                said = [l.strip() for l in f
                        if "oom-kill event" in l or "Out Of Memory" in l or "TIME LIMIT" in l]
        except OSError:
            said = []
        if said:
            state = "TIMEOUT" if "TIME LIMIT" in said[0] else "OUT_OF_MEMORY"
            details = f"job FAILED, {said[0]}; {details}"
    return state, details


def record_attempt(jobs_file: str, attempt: int):
    """Under Slurm: the previous attempt's job id (None on the first), then this attempt's id
    appended to jobs_file (which the first attempt starts afresh)."""
    job_id = os.environ.get("SLURM_JOB_ID")
    if not jobs_file or not job_id:
        return None
    previous = None
    if attempt > 1 and os.path.exists(jobs_file):
        with open(jobs_file) as f:
            lines = [l.split() for l in f if l.strip()]
        previous = lines[-1][0] if lines else None
    os.makedirs(os.path.dirname(jobs_file) or ".", exist_ok=True)
    with open(jobs_file, "w" if attempt <= 1 else "a") as f:
        f.write(f"{job_id} {attempt}\n")
    return previous


def write_result(path: str, result: dict):
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(result, f, indent=1)
    os.replace(tmp, path)


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
    ap.add_argument("--attempt", type=int, default=1, help="Snakemake's attempt (retries)")
    ap.add_argument("--jobs-file", default="", help="the Slurm job ids of this run's attempts")
    a = ap.parse_args()

    version, binary_sha = facesim_provenance(a.facesim)
    result = {
        "case": a.name,
        "plan": a.plan,
        "variant": a.variant,
        "case_file": a.case,
        "overrides": a.sets,
        "facesim_version": version,
        "facesim_sha256": binary_sha,
        "case_sha256": case_sha256(a.case),
        "slurm_job": os.environ.get("SLURM_JOB_ID", ""),
        "attempt": a.attempt,
        "out_dir": os.path.relpath(a.out, os.path.dirname(a.result) or "."),
    }
    previous = record_attempt(a.jobs_file, a.attempt)
    if previous:
        end = slurm_job_end(previous)
        print(f"attempt {a.attempt}; previous attempt: Slurm job {previous}: {end}", flush=True)
        if end and end[0] in LIMIT_STATES:
            # The same request would be killed again: the run's status is Slurm's reason.
            result.update(status=f"slurm: job {previous} {end[0]} ({end[1]})", exit_code=None,
                          seconds=0.0, peak_mem_mb=0.0, slurm_job=previous)
            write_result(a.result, result)
            return 0

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
    result.update(
        status="ok" if code == 0 else one_line_error(stderr, code),
        exit_code=code,
        seconds=seconds,
        peak_mem_mb=peak_kib / 1024.0,
    )
    write_result(a.result, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())

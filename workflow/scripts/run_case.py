#!/usr/bin/env python3
"""One cohort run (docs/guide/cohort.md): `facesim run PLAN --out OUT [--set K=V ...]`, timed, and its
result.json — status "ok" or facesim's one-line error, wall seconds, peak memory of the
facesim process, and its provenance (facesim's version and binary hash, the case's hash).
Exits 0 whether facesim succeeded or not, so one broken case does not stop the cohort; only a
failure of this script itself (e.g. an unwritable output) is an error.

Under Slurm (SLURM_JOB_ID set) each attempt appends its job id to --jobs-file. Every attempt
also keeps a record beside it (JOBS without ".jobs" + ".attempt-N.json": its job, the memory and
time Slurm granted, facesim's peak memory so far, kept up to date while facesim runs), so an
attempt Slurm kills still leaves what it asked for and what it used. A retry (--attempt 2, 3, …)
asks Slurm how each earlier attempt's job ended and lists them in result.json
("earlier_attempts"). The Snakefile asks Slurm too, and gives a retry after OUT_OF_MEMORY or
TIMEOUT more memory or time (docs/guide/cohort.md, "Retries that grow"); a retry whose request did not
grow (at the configured maximum) would be killed again, so it records Slurm's reason as the run's
status instead of running facesim. Standard library only."""

import argparse
import hashlib
import json
import os
import resource
import shutil
import subprocess
import sys
import threading
import time
import tomllib

from replacing import write_json

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


def mem_mb(text: str):
    """Slurm's memory figure ("1234K", "300M", "2G", "0") in MB; None when empty."""
    text = text.strip()
    if not text:
        return None
    scale = {"K": 1 / 1024, "M": 1.0, "G": 1024.0, "T": 1024.0 ** 2}
    try:
        if text[-1].upper() in scale:
            return float(text[:-1]) * scale[text[-1].upper()]
        return float(text) / 1024 ** 2  # bytes
    except ValueError:
        return None


def minutes(text: str):
    """Slurm's time limit ("1:00", "2:00:00", "1-00:00:00") in minutes; None for UNLIMITED or
    anything else."""
    days, _, rest = text.strip().rpartition("-")
    try:
        parts = [int(x) for x in rest.split(":")]
        day = int(days) if days else 0
    except ValueError:
        return None
    if len(parts) == 3:
        h, m, sec = parts
    elif len(parts) == 2:
        h, m, sec = (0, *parts) if not days else (*parts, 0)
    elif len(parts) == 1:
        h, m, sec = (0, parts[0], 0) if not days else (parts[0], 0, 0)
    else:
        return None
    return day * 1440 + h * 60 + m + sec / 60


def slurm_job_end(job_id: str):
    """How a finished Slurm job ended: (state, details, peak MB or None), None when Slurm no
    longer knows it. The peak is sacct's MaxRSS over the job's steps (accounting only).

    With an accounting database, sacct gives every step's state. Without one, scontrol gives
    the job's (slurmctld keeps a finished job for MinJobAge). Through the executor plugin the
    run is step 0 of the job (srun inside sbatch): over its memory the step ends OUT_OF_MEMORY
    but the job FAILED, so a FAILED job's Slurm log (its StdOut) is read for slurmstepd's
    oom-kill line and srun's "Out Of Memory"."""
    try:
        p = subprocess.run(
            ["sacct", "-j", job_id, "-n", "-P",
             "-o", "JobID,State,ExitCode,Elapsed,Timelimit,ReqMem,MaxRSS"],
            capture_output=True, text=True, timeout=60)
        lines = [l.split("|") for l in p.stdout.strip().splitlines()] if p.returncode == 0 else []
        if lines:
            states = [(l + [""] * 7)[1].split()[0] for l in lines]
            job = (lines[0] + [""] * 7)
            state = next((s for s in states if s in LIMIT_STATES), states[0])
            peaks = [mem_mb((l + [""] * 7)[6]) for l in lines]
            peaks = [x for x in peaks if x is not None]
            return state, (f"job {job[1]}, steps {' '.join(states[1:]) or '-'}, exit code "
                           f"{job[2]}, ran {job[3]} of {job[4]}, memory {job[5]}"), \
                (max(peaks) if peaks else None)
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
    return state, details, None


def memory_cgroup_dirs(pid: str = "self"):
    """The memory cgroup directories whose limit can end this process: its own and, under
    Slurm, each ancestor up to the job's (job_N), not the node's or the user's, which other
    jobs share. cgroup v1 (the memory controller's mount) and v2 (the unified mount)."""
    mounts = {}
    try:
        with open("/proc/mounts") as f:
            for line in f:
                field = line.split()
                if len(field) > 3 and field[2] == "cgroup2":
                    mounts.setdefault("", field[1])
                elif len(field) > 3 and field[2] == "cgroup" and "memory" in field[3].split(","):
                    mounts["memory"] = field[1]
        with open(f"/proc/{pid}/cgroup") as f:
            lines = [l.rstrip("\n").split(":", 2) for l in f]
    except OSError:
        return []
    rel = next((l[2] for l in lines if len(l) == 3 and "memory" in l[1].split(",")), None)
    root = mounts.get("memory")
    if rel is None or root is None:
        rel = next((l[2] for l in lines if len(l) == 3 and l[0] == "0" and l[1] == ""), None)
        root = mounts.get("")
    if rel is None or root is None:
        return []
    parts = [p for p in rel.split("/") if p]
    job = next((i for i, p in enumerate(parts) if p.startswith("job_")), None)
    first = job if job is not None else len(parts)
    return [os.path.join(root, *parts[:n]) for n in range(len(parts), first - 1, -1)
            if n > 0 or job is None]


def oom_kill_counts(dirs):
    """Each directory's count of processes its out-of-memory killer ended (v1:
    memory.oom_control, v2: memory.events, "oom_kill N"); directories without one left out."""
    counts = {}
    for d in dirs:
        for name in ("memory.events", "memory.oom_control"):
            try:
                with open(os.path.join(d, name)) as f:
                    n = next((int(l.split()[1]) for l in f if l.startswith("oom_kill ")), None)
            except (OSError, ValueError, IndexError):
                continue
            if n is not None:
                counts[d] = n
                break
    return counts


def oom_killed(before, after, code: int):
    """Why facesim's end was its memory limit's out-of-memory killer, or None. Evidence: an
    oom_kill counter of its cgroups that grew while it ran. A cgroup that holds the wrapper too
    may kill only its largest process, facesim, and leave this script to report a plain
    SIGKILL; that is a memory limit, which a retry with more memory can pass."""
    if code != -9:
        return None
    grew = [f"{d}: oom_kill {before.get(d, 0)} -> {n}" for d, n in after.items()
            if n > before.get(d, 0)]
    if grew:
        return "facesim killed by the cgroup's out-of-memory killer (oom-kill event; " + \
            "; ".join(grew) + ")"
    if os.environ.get("SLURM_JOB_ID") and not after:
        return ("facesim killed by SIGKILL under Slurm, its cgroup's oom-kill counters "
                "unreadable: taken as its memory limit (oom-kill event assumed)")
    return None


def attempt_end(jobs_file: str, attempt: int, job_id: str):
    """How an attempt's Slurm job ended (slurm_job_end), with the attempt's own record: a job
    whose facesim the cgroup's out-of-memory killer ended, while this script lived on and
    exited non-zero, ended OUT_OF_MEMORY even where Slurm calls it FAILED."""
    end = slurm_job_end(job_id) if job_id else None
    rec = read_json(attempt_record_path(jobs_file, attempt)) or {}
    why = rec.get("oom_kill")
    if why and (end is None or end[0] not in LIMIT_STATES):
        slurm = f"; Slurm: {end[0]}, {end[1]}" if end else ""
        return "OUT_OF_MEMORY", f"{why}{slurm}", end[2] if end else None
    return end


def slurm_request(job_id: str):
    """The memory (MB) and time limit (minutes) Slurm gave this job, from scontrol (MinMemoryNode,
    or MinMemoryCPU × NumCPUs; TimeLimit), else SLURM_MEM_PER_NODE; None for what neither says.
    (The executor plugin's job step strips SLURM_* variables from the srun it runs this under.)"""
    kv = {}
    try:
        p = subprocess.run(["scontrol", "-o", "show", "job", job_id],
                           capture_output=True, text=True, timeout=60)
        kv = dict(w.split("=", 1) for w in p.stdout.split() if "=" in w)
    except (OSError, subprocess.TimeoutExpired):
        pass
    mem = mem_mb(kv.get("MinMemoryNode", ""))
    if mem is None and kv.get("MinMemoryCPU"):
        cpu = mem_mb(kv["MinMemoryCPU"])
        n = kv.get("NumCPUs", "")
        mem = cpu * int(n) if cpu is not None and n.isdigit() else None
    if mem is None and os.environ.get("SLURM_MEM_PER_NODE", "").isdigit():
        mem = float(os.environ["SLURM_MEM_PER_NODE"])
    return mem, minutes(kv.get("TimeLimit", ""))


def attempt_record_path(jobs_file: str, attempt: int) -> str:
    base = jobs_file[: -len(".jobs")] if jobs_file.endswith(".jobs") else jobs_file
    return f"{base}.attempt-{attempt}.json"


def read_json(path: str):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def earlier_attempts(jobs_file: str, attempt: int):
    """The run's attempts before this one, as their records and Slurm tell: attempt, Slurm job,
    requested memory and time, peak memory (sacct's MaxRSS, else facesim's peak the attempt
    recorded), Slurm's state and the run's status for it."""
    out = []
    for n in range(1, attempt):
        rec = read_json(attempt_record_path(jobs_file, n)) or {}
        job = rec.get("slurm_job") or ""
        end = attempt_end(jobs_file, n, job) if job else None
        peak = end[2] if end and end[2] is not None else rec.get("peak_mem_mb")
        state = end[0] if end else ""
        if end:
            status = f"slurm: job {job} {end[0]} ({end[1]})"
        elif rec and job:
            status = f"attempt {n} ended without a result (Slurm no longer knows job {job})"
        elif rec:
            status = f"attempt {n} ended without a result"
        else:
            status = f"attempt {n} ended before run_case.py started"
        out.append({
            "attempt": n,
            "slurm_job": job,
            "requested_mem_mb": rec.get("requested_mem_mb"),
            "requested_runtime_min": rec.get("requested_runtime_min"),
            "peak_mem_mb": peak,
            "slurm_state": state,
            "status": status,
        })
    return out


class PeakWatch:
    """Keeps the attempt's record up to date with facesim's peak resident memory (VmHWM, read
    from /proc every quarter second while it runs), so a job Slurm kills leaves its peak."""

    def __init__(self, path: str, record: dict, pid: int):
        self.path, self.record, self.pid = path, record, pid
        self.done = threading.Event()
        self.thread = threading.Thread(target=self.watch, daemon=True)
        self.thread.start()

    def watch(self):
        written = self.record.get("peak_mem_mb") or 0.0
        while not self.done.wait(0.25):
            try:
                with open(f"/proc/{self.pid}/status") as f:
                    kib = next((int(l.split()[1]) for l in f if l.startswith("VmHWM:")), 0)
            except (OSError, ValueError, IndexError):
                continue
            if kib / 1024.0 >= written + 1.0:
                written = kib / 1024.0
                self.record["peak_mem_mb"] = written
                try:
                    write_json(self.path, self.record)
                except OSError:
                    pass

    def stop(self):
        self.done.set()
        self.thread.join()


def report_peak_heap(out_dir: str):
    """The largest peak heap (MB) of report.json's stage_costs, None without one."""
    rep = read_json(os.path.join(out_dir, "report.json")) or {}
    peaks = [c.get("peak_heap_mb") for c in (rep.get("stage_costs") or {}).values()
             if isinstance(c, dict)]
    peaks = [x for x in peaks if isinstance(x, (int, float))]
    return max(peaks) if peaks else None


def record_attempt(jobs_file: str, attempt: int):
    """Under Slurm: this attempt's job id appended to jobs_file (which the first attempt starts
    afresh)."""
    job_id = os.environ.get("SLURM_JOB_ID")
    if not jobs_file or not job_id:
        return
    os.makedirs(os.path.dirname(jobs_file) or ".", exist_ok=True)
    with open(jobs_file, "w" if attempt <= 1 else "a") as f:
        f.write(f"{job_id} {attempt}\n")


def write_result(path: str, result: dict):
    write_json(path, result)


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
    ap.add_argument("--mem-mb", type=float, default=None,
                    help="the memory Snakemake asked for (recorded when not under Slurm)")
    ap.add_argument("--runtime-min", type=float, default=None,
                    help="the time Snakemake asked for (recorded when not under Slurm)")
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
    job = os.environ.get("SLURM_JOB_ID", "")
    mem, limit = slurm_request(job) if job else (None, None)
    record = {
        "attempt": a.attempt,
        "slurm_job": job,
        "requested_mem_mb": mem if mem is not None else a.mem_mb,
        "requested_runtime_min": limit if limit is not None else a.runtime_min,
        "peak_mem_mb": None,
    }
    result.update((k, record[k]) for k in ("requested_mem_mb", "requested_runtime_min"))
    result["slurm_state"] = ""
    record_attempt(a.jobs_file, a.attempt)
    record_path = attempt_record_path(a.jobs_file, a.attempt) if a.jobs_file else ""
    if record_path:
        if a.attempt <= 1:
            # A new run: records of an earlier run of this case, plan and variant are stale.
            base = os.path.basename(attempt_record_path(a.jobs_file, 0))[: -len("0.json")]
            d = os.path.dirname(record_path) or "."
            for name in os.listdir(d):
                if name.startswith(base) and name.endswith(".json"):
                    os.unlink(os.path.join(d, name))
        write_json(record_path, record)
    earlier = earlier_attempts(a.jobs_file, a.attempt) if a.jobs_file else []
    result["earlier_attempts"] = earlier
    if earlier:
        previous = earlier[-1]
        print(f"attempt {a.attempt}; earlier attempts: {earlier}", flush=True)
        # Over a limit, a retry runs only if that limit grew (the Snakefile grows it up to the
        # configured maximum): the same request would be killed again.
        limit_key = {"OUT_OF_MEMORY": "requested_mem_mb",
                     "TIMEOUT": "requested_runtime_min"}.get(previous["slurm_state"])
        if limit_key:
            before, now = previous.get(limit_key), record.get(limit_key)
            if before is None or now is None or now <= before:
                # The run's outcome is that attempt's: its status is Slurm's reason.
                result.update({k: v for k, v in previous.items() if k != "status"})
                what = "memory" if limit_key == "requested_mem_mb" else "time limit"
                result.update(
                    status=f"{previous['status']}; not retried: the {what} cannot grow",
                    exit_code=None, seconds=0.0, earlier_attempts=earlier[:-1])
                if result.get("peak_mem_mb") is None:
                    result["peak_mem_mb"] = 0.0
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
    cgroups = memory_cgroup_dirs() if job else []
    oom_before = oom_kill_counts(cgroups)
    try:
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        watch = PeakWatch(record_path, record, p.pid) if record_path else None
        stdout, stderr = p.communicate()
        code = p.returncode
        if watch:
            watch.stop()
    except OSError as e:
        code, stdout, stderr = -1, "", f"facesim: cannot run {a.facesim}: {e.strerror}"
    seconds = time.monotonic() - start
    # The children's peak RSS (KiB on Linux) is facesim's: the other children (facesim
    # --version, scontrol) are small.
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    if not peak_mb:
        peak_mb = report_peak_heap(a.out) or 0.0
    sys.stdout.write(stdout)
    sys.stdout.write(stderr)
    oom = oom_killed(oom_before, oom_kill_counts(cgroups), code) if job else None
    if record_path:
        record["peak_mem_mb"] = peak_mb
        if oom:
            record["oom_kill"] = oom
        write_json(record_path, record)
    if oom:
        # Over its memory: no result, and a failed job, so Snakemake retries with more memory
        # (the Snakefile reads this attempt's record through attempt_end).
        print(f"run_case: {oom}", file=sys.stderr, flush=True)
        return 1
    result.update(
        status="ok" if code == 0 else one_line_error(stderr, code),
        exit_code=code,
        seconds=seconds,
        peak_mem_mb=peak_mb,
    )
    write_result(a.result, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())

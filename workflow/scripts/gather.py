#!/usr/bin/env python3
"""The cohort table (docs/guide/cohort.md): one row per case, plan, variant and region of the
result.json files given (run_case.py) and their runs' report.json — region "face" for the whole
face, then report.json's facial regions. A failed run has one row, region "face", its status
facesim's one-line error (or Slurm's reason, "slurm: job N OUT_OF_MEMORY (…)") and the figures
empty; every earlier attempt of a run Slurm retried has such a row too (its attempt, request,
peak and Slurm's state); --failures writes those rows alone (the failure table). Every row carries its
provenance: facesim's version and binary hash, the case's hash, the overrides and the hash of
the run's full parameters (report.json "parameters", written once per hash under --parameters).
Standard library only."""

import argparse
import csv
import hashlib
import json
import os
import sys

from replacing import replacing

BASE = [
    "case", "plan", "variant", "region", "status", "vertices", "mean_mm", "p90_mm",
    "max_mm", "seconds", "facesim_seconds", "peak_mem_mb", "model",
]
PROVENANCE = [
    "facesim_version", "facesim_sha256", "case_sha256", "overrides", "parameters_sha256",
    "slurm_job",
]
# Which attempt a row is of (the run's outcome is its rows whose attempt is `attempts`), what
# it asked the scheduler for and how Slurm ended it (empty for an attempt that ran to its end).
ATTEMPT = ["attempt", "attempts", "requested_mem_mb", "requested_runtime_min", "slurm_state"]
FAILURES = [
    "case", "plan", "variant", "status", "slurm_job", "log", "attempt", "requested_mem_mb",
    "requested_runtime_min", "peak_mem_mb", "slurm_state",
]


def p90(values):
    """The 90th percentile as facesim's report.json regions take it (nearest rank on
    round(0.9 (n - 1)))."""
    d = sorted(values)
    return d[round(0.9 * (len(d) - 1))]


def face_distances(out_dir):
    with open(os.path.join(out_dir, "displacement.csv"), newline="") as f:
        return [float(r["dist"]) for r in csv.DictReader(f)]


def ratio_column(key):
    """report.json soft_hard_ratios key "Pog'/Pog" → column "ratio_Pog_Pog"."""
    return "ratio_" + key.replace("'", "").replace("/", "_")


def canonical_sha256(value):
    """sha256 of a JSON value written canonically (sorted keys, no spaces)."""
    text = json.dumps(value, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest(), text


def figure(value, digits):
    """A number as the table writes it; empty for none."""
    return "" if value is None else f"{value:.{digits}f}"


def attempt_rows(res, base):
    """One row (region "face", figures empty) per attempt before the one `res` describes."""
    rows = []
    for e in res.get("earlier_attempts") or []:
        rows.append(dict(
            {k: base[k] for k in ("case", "plan", "variant", "attempts")},
            region="face", status=e.get("status", ""), slurm_job=e.get("slurm_job", ""),
            attempt=e.get("attempt", 0), requested_mem_mb=figure(e.get("requested_mem_mb"), 0),
            requested_runtime_min=figure(e.get("requested_runtime_min"), 0),
            peak_mem_mb=figure(e.get("peak_mem_mb"), 1), slurm_state=e.get("slurm_state", ""),
            facesim_version=base["facesim_version"], facesim_sha256=base["facesim_sha256"],
            case_sha256=base["case_sha256"], overrides=base["overrides"]))
    return rows


def rows_of(result_path, parameters_dir=None):
    with open(result_path) as f:
        res = json.load(f)
    base = {k: res.get(k) for k in ("case", "plan", "variant", "status")}
    base["seconds"] = f"{res['seconds']:.3f}"
    base["peak_mem_mb"] = figure(res.get("peak_mem_mb"), 1)
    base["attempt"] = res.get("attempt", 1)
    base["attempts"] = base["attempt"]
    base["requested_mem_mb"] = figure(res.get("requested_mem_mb"), 0)
    base["requested_runtime_min"] = figure(res.get("requested_runtime_min"), 0)
    base["slurm_state"] = res.get("slurm_state", "")
    base["facesim_version"] = res.get("facesim_version", "")
    base["facesim_sha256"] = res.get("facesim_sha256", "")
    base["case_sha256"] = res.get("case_sha256", "")
    base["overrides"] = "; ".join(res.get("overrides") or [])
    base["slurm_job"] = res.get("slurm_job", "")
    earlier = attempt_rows(res, base)
    if res["status"] != "ok":
        return earlier + [dict(base, region="face")], {}
    out_dir = os.path.join(os.path.dirname(result_path), res["out_dir"])
    with open(os.path.join(out_dir, "report.json")) as f:
        rep = json.load(f)
    digest, text = canonical_sha256(rep.get("parameters"))
    base["parameters_sha256"] = digest
    if parameters_dir:
        os.makedirs(parameters_dir, exist_ok=True)
        target = os.path.join(parameters_dir, f"{digest}.json")
        if not os.path.exists(target):
            with replacing(target) as f:
                f.write(text + "\n")
    base["facesim_seconds"] = f"{rep['timings']['total']:.3f}"
    base["model"] = rep["parameters"]["solve"]["model"]
    extra = {}
    for key, r in (rep.get("soft_hard_ratios") or {}).items():
        extra[ratio_column(key)] = "" if r.get("ratio") is None else f"{r['ratio']:.4f}"
    for key, m in (rep.get("measurements") or {}).items():
        if isinstance(m, dict) and m.get("change") is not None:
            extra[f"{key}_change"] = f"{m['change']:.4f}"
    base.update(extra)
    dist = face_distances(out_dir)
    rows = [dict(base, region="face", vertices=len(dist),
                 mean_mm=f"{sum(dist) / len(dist):.6f}", p90_mm=f"{p90(dist):.6f}",
                 max_mm=f"{max(dist):.6f}")]
    for name, s in (rep.get("regions") or {}).items():
        if not s.get("vertices"):
            continue
        rows.append(dict(base, region=name, vertices=s["vertices"],
                         mean_mm=f"{s['mean']:.6f}", p90_mm=f"{s['p90']:.6f}",
                         max_mm=f"{s['max']:.6f}"))
    return earlier + rows, extra


def write_csv(path, columns, rows):
    with replacing(path) as f:
        w = csv.DictWriter(f, fieldnames=columns, restval="", extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", required=True, help="cohort.csv to write")
    ap.add_argument("--failures", help="failures.csv to write: the runs whose status is not ok")
    ap.add_argument("--parameters", help="directory for each distinct parameters set, by hash")
    ap.add_argument("results", nargs="+", help="result.json files")
    a = ap.parse_args()
    rows, extra_cols = [], []
    for path in a.results:
        r, extra = rows_of(path, a.parameters)
        rows += r
        extra_cols += [c for c in extra if c not in extra_cols]
    rows.sort(key=lambda r: (r["case"], r["plan"], r["variant"], r["attempt"],
                             r["region"] != "face"))
    write_csv(a.out, BASE + extra_cols + PROVENANCE + ATTEMPT, rows)
    if a.failures:
        # The run's log, relative to OUT.
        failed = [
            dict(r, log=os.path.join("logs", r["case"], r["plan"], f"{r['variant']}.log"))
            for r in rows if r["status"] != "ok"
        ]
        write_csv(a.failures, FAILURES, failed)
    failed = sum(1 for r in rows if r["status"] != "ok" and r["attempt"] == r["attempts"])
    print(f"{a.out}: {len(rows)} rows, {len(a.results)} runs, {failed} failed")


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""compare-outputs.py A B (scripts/outputs-set.sh makes A and B): every output file of run directories A and B identical, or numbers within
1e-9 (mm) where float summation order may change; report.json/report.html volatile figures
(timings, stage costs, memory, seconds, paths) ignored; the set's own input files (*.toml) are
not outputs."""
import json, os, re, sys
A, B = sys.argv[1], sys.argv[2]
VOL = {"timings", "stage_costs", "max_rss_mb", "seconds", "seconds_per_sample", "seconds_per_solve", "wall_s", "from", "case", "plan"}
def strip(o):
    if isinstance(o, dict):
        return {k: strip(v) for k, v in o.items() if k not in VOL}
    if isinstance(o, list):
        return [strip(v) for v in o]
    return o
num = re.compile(rb"-?\d+\.?\d*(?:[eE][-+]?\d+)?")
def close(a, b):
    ta, tb = num.split(a), num.split(b)
    if ta != tb: return False
    na, nb = num.findall(a), num.findall(b)
    if len(na) != len(nb): return False
    return all(abs(float(x) - float(y)) <= 1e-9 * max(1, abs(float(x))) for x, y in zip(na, nb))
def jclose(a, b):
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(jclose(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(jclose(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, (int, float)):
        return abs(a - b) <= 1e-9 * max(1, abs(a))
    return a == b
bad = 0; n = 0
for root, _, files in os.walk(A):
    for f in files:
        if f.endswith('.toml'): continue
        pa = os.path.join(root, f); pb = os.path.join(B, os.path.relpath(pa, A))
        n += 1
        if not os.path.exists(pb): print("missing", pb); bad += 1; continue
        a, b = open(pa, "rb").read(), open(pb, "rb").read()
        if a == b: continue
        if f == "report.json":
            if jclose(strip(json.loads(a)), strip(json.loads(b))): continue
            ja, jb = strip(json.loads(a)), strip(json.loads(b))
            for k in ja:
                if ja.get(k) != jb.get(k): print("  report key differs:", k)
        elif f == "report.html":
            # the embedded report carries timings: compare with numbers inside timing maps ignored
            sa = re.sub(rb'"(timings|stage_costs)":\{[^{}]*(\{[^{}]*\}[^{}]*)*\}', b"", a)
            sb = re.sub(rb'"(timings|stage_costs)":\{[^{}]*(\{[^{}]*\}[^{}]*)*\}', b"", b)
            sa = re.sub(rb'"(max_rss_mb|seconds[a-z_]*|wall_s|cpu_s|peak_heap_mb)":[-0-9.e+]+', b"", sa)
            sb = re.sub(rb'"(max_rss_mb|seconds[a-z_]*|wall_s|cpu_s|peak_heap_mb)":[-0-9.e+]+', b"", sb)
            sa = re.sub(rb'\["(time|memory|cpu)[^"]*","[^"]*"\]', b"", sa)
            sb = re.sub(rb'\["(time|memory|cpu)[^"]*","[^"]*"\]', b"", sb)
            if sa == sb or close(sa, sb): continue
        elif not f.endswith((".bin", ".gz", ".stl", ".svg")) and close(a, b):
            print("within 1e-9:", pa); continue
        print("DIFFERS", pa); bad += 1
for root, _, files in os.walk(B):
    for f in files:
        if f.endswith('.toml'): continue
        if not os.path.exists(os.path.join(A, os.path.relpath(os.path.join(root, f), B))):
            print("extra", os.path.join(root, f)); bad += 1
print(f"{n} files compared, {bad} differ")
sys.exit(1 if bad else 0)

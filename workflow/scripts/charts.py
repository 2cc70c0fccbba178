#!/usr/bin/env python3
"""The cohort's charts from cohort.csv (docs/guide/cohort.md), PNG, with matplotlib:
region_mean_mm.png — mean displacement per facial region, one dot per run, per variant;
soft_hard_ratios.png — soft/hard tissue ratios per case and variant;
seconds.png — wall time and peak memory of each run.
Failed runs are left out (their rows carry no figures)."""

import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: charts.py COHORT.csv OUT_DIR")
    src, out = sys.argv[1], sys.argv[2]
    with open(src, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["status"] == "ok"]
    os.makedirs(out, exist_ok=True)
    variants = sorted({r["variant"] for r in rows})
    regions = []
    for r in rows:
        if r["region"] not in regions:
            regions.append(r["region"])
    colours = {v: f"C{i}" for i, v in enumerate(variants)}

    # Mean displacement per region: dots per run, offset per variant.
    fig, ax = plt.subplots(figsize=(max(6, 1.2 * len(regions)), 4))
    width = 0.8 / max(1, len(variants))
    for vi, v in enumerate(variants):
        for ri, region in enumerate(regions):
            ys = [float(r["mean_mm"]) for r in rows if r["variant"] == v and r["region"] == region]
            xs = [ri - 0.4 + width * (vi + 0.5)] * len(ys)
            ax.scatter(xs, ys, s=14, color=colours[v], label=v if ri == 0 else None)
    ax.set_xticks(range(len(regions)), regions, rotation=20)
    ax.set_ylabel("mean displacement (mm)")
    ax.set_title("Predicted displacement per facial region (one dot per run)")
    if variants:
        ax.legend(title="variant")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "region_mean_mm.png"), dpi=110)
    plt.close(fig)

    # Soft/hard tissue ratios: one panel per ratio, one bar per run.
    face = [r for r in rows if r["region"] == "face"]
    ratio_cols = [c for c in (face[0].keys() if face else []) if c.startswith("ratio_")]
    ratio_cols = [c for c in ratio_cols if any(r[c] for r in face)]
    fig, axes = plt.subplots(1, max(1, len(ratio_cols)), figsize=(4 * max(1, len(ratio_cols)), 4),
                             squeeze=False)
    for ax, col in zip(axes[0], ratio_cols):
        runs = [r for r in face if r[col]]
        labels = [f"{r['case']}\n{r['plan']}" for r in runs]
        ax.bar(range(len(runs)), [float(r[col]) for r in runs],
               color=[colours[r["variant"]] for r in runs])
        ax.set_xticks(range(len(runs)), labels, rotation=60, fontsize=7)
        ax.set_title(col[len("ratio_"):].replace("_", " / ", 1))
        ax.set_ylabel("soft / hard tissue move")
    if not ratio_cols:
        axes[0][0].text(0.5, 0.5, "no soft/hard ratio in these runs", ha="center")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "soft_hard_ratios.png"), dpi=110)
    plt.close(fig)

    # Cost per run.
    fig, ax = plt.subplots(figsize=(6, 4))
    for v in variants:
        runs = [r for r in face if r["variant"] == v]
        ax.scatter([float(r["seconds"]) for r in runs], [float(r["peak_mem_mb"]) for r in runs],
                   color=colours[v], label=v)
    ax.set_xlabel("wall time per run (s)")
    ax.set_ylabel("peak memory (MB)")
    ax.set_title("Cost of each run")
    if variants:
        ax.legend(title="variant")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "seconds.png"), dpi=110)
    plt.close(fig)
    print(f"charts in {out}")


if __name__ == "__main__":
    main()

#!/usr/bin/env bash
# Cohort throughput locally and through a real Slurm (docs/lab/cohort-measured.md "Throughput on Slurm",
# docs/lab/performance.md "Cohorts on Slurm"): N jaws phantoms (2 mm, seed 11, plan case.toml,
# one variant of MODEL, one thread a run) through workflow/Snakefile with --cores $(nproc), then
# on a throw-away one-node cluster (scripts/slurm-cluster.sh) one Slurm job per run, then in job
# groups of G runs (one core a group job, its runs one after the other). Prints wall time, cases per hour, and the overhead per job against the local
# run. The Slurm jobs are counted from the executor plugin's log ("submitted with SLURM
# jobid"), retries included; the grouped run must need fewer jobs than runs, else the script
# fails. Needs root, scripts/test-setup.sh's packages and venv, a release build.
#
#   workflow/bench-slurm.sh [N=40] [MODEL=equilibrium] [G=10] [WORK=target/tmp/slurm-bench]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
n="${1:-40}"
model="${2:-equilibrium}"
group="${3:-10}"
work="${4:-$root/target/tmp/slurm-bench}"
facesim="${FACESIM:-$root/target/release/facesim}"
snakemake="$root/target/slicer-venv/bin/snakemake"
cores="$(nproc)"
# The Python environment running Snakemake (the venv may be a link to another checkout's).
venv="$(dirname "$(dirname "$(readlink -f "$snakemake")")")"
rm -rf "$work" && mkdir -p "$work"
work="$(cd "$work" && pwd)"
"$facesim" phantom-cohort "$work/cases" --cases "$n" --seed 11 --spacing 2 --slice 2 >/dev/null
cat >"$work/config.yaml" <<EOF
variants:
  $model: {"solve.model": "$model"}
threads: 1
shared_storage: ["$root", "$work", "$(dirname "$(readlink -f "$facesim")")", "$venv"]
EOF
now() { date +%s.%N; }
snake() { # out extra…
  local out="$1"
  shift
  (cd "$work" && "$snakemake" -s "$root/workflow/Snakefile" --configfile "$work/config.yaml" \
    --config cohort="$work/cases" out="$work/$out" facesim="$facesim" "$@" >"$work/$out.log" 2>&1)
}
# Slurm jobs a run submitted, from the plugin's log.
submitted() { grep -c "submitted with SLURM jobid" "$work/$1.log" || true; }
# The run's figures must be there: a failed Snakemake stops the script (set -e), a run facesim
# refused is counted here.
oks() { awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "status") s = i; next }
  $s == "ok" { k[$1 FS $2 FS $3] = 1 } END { print length(k) }' "$work/$1/cohort.csv"; }
report() { # label seconds jobs [local-seconds]
  awk -v l="$1" -v s="$2" -v n="$n" -v j="$3" -v base="${4:-}" -v c="$cores" 'BEGIN {
    o = base == "" ? "" : sprintf(", %+.2f s per job over the local run (%d jobs, %d at a time)",
      (s - base) * c / j, j, c);
    printf "%-40s %7.1f s  %6.0f cases/h%s\n", l, s, 3600 * n / s, o }'
}

echo "$(date -u '+%F %H:%M UTC'): cohort of $n jaws phantoms (2 mm), model $model, $cores cores," \
  "$(awk '/^MemTotal:/ { printf "%.1f GB", $2 / 1048576 }' /proc/meminfo), load $(cut -d' ' -f1-3 /proc/loadavg)"
t0=$(now)
snake local --cores "$cores"
local_s=$(awk -v a="$(now)" -v b="$t0" 'BEGIN { print a - b }')
report "local, --cores $cores" "$local_s" "$n"
echo "  runs ok: $(oks local) of $n"

cluster="$(mktemp -d /tmp/facesim-slurm-bench.XXXXXX)"
rmdir "$cluster"
trap '"$root/scripts/slurm-cluster.sh" stop "$cluster"' EXIT
eval "$("$root/scripts/slurm-cluster.sh" start "$cluster" $$)"
slurm=(--workflow-profile "$root/workflow/profiles/slurm"
  --default-resources slurm_partition=cohort mem_mb=1000 runtime=10
  --slurm-status-command squeue --slurm-init-seconds-before-status-checks 2)
t0=$(now)
snake slurm "${slurm[@]}"
slurm_s=$(awk -v a="$(now)" -v b="$t0" 'BEGIN { print a - b }')
jobs=$(submitted slurm)
report "Slurm, one job per run" "$slurm_s" "$jobs" "$local_s"
echo "  runs ok: $(oks slurm) of $n; load $(cut -d' ' -f1-3 /proc/loadavg)"
t0=$(now)
# --cores is a group job's width: one core, its G runs one after the other inside it.
snake slurm-grouped "${slurm[@]}" --groups run=cases --group-components "cases=$group" --cores 1
grouped_s=$(awk -v a="$(now)" -v b="$t0" 'BEGIN { print a - b }')
jobs=$(submitted slurm-grouped)
report "Slurm, groups of $group runs" "$grouped_s" "$jobs" "$local_s"
echo "  runs ok: $(oks slurm-grouped) of $n; load $(cut -d' ' -f1-3 /proc/loadavg)"
# Each group job's request, as Slurm holds it (slurmctld keeps finished jobs for MinJobAge).
squeue --states=all --noheader --format='  job %i %j: %T, %C CPUs, %m memory, time limit %l' |
  sort -n -k2 | tail -n "$jobs"
if [ "$jobs" -ge "$n" ]; then
  echo "bench-slurm: the grouped run submitted $jobs Slurm jobs for $n runs" >&2
  exit 1
fi

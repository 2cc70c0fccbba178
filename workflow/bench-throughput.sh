#!/usr/bin/env bash
# Cohort throughput (docs/guide/cohort.md, docs/lab/performance.md): N jaws phantoms run one after the
# other with `facesim run`, then through workflow/Snakefile with --cores 1 and --cores 2 (one
# 2-thread job at a time, or two 1-thread jobs side by side). Prints one line per setting:
# seconds, cases per hour, and the overhead against the single runs.
#
#   workflow/bench-throughput.sh [N=4] [MODEL=tet] [WORK=target/tmp/cohort-bench]
#
# Needs the venv scripts/test-setup.sh makes (snakemake) and a release build of facesim.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
n="${1:-4}"
model="${2:-tet}"
work="${3:-$root/target/tmp/cohort-bench}"
facesim="$root/target/release/facesim"
snakemake="$root/target/slicer-venv/bin/snakemake"
rm -rf "$work" && mkdir -p "$work"
"$facesim" phantom-cohort "$work/cases" --cases "$n" --seed 11 --spacing 2 --slice 2 >/dev/null
printf 'variants:\n  %s: {"solve.model": "%s"}\n' "$model" "$model" >"$work/variants.yaml"

now() { date +%s.%N; }
report() { # label seconds threads-per-run
  awk -v l="$1" -v s="$2" -v n="$n" -v base="${3:-}" 'BEGIN {
    o = base == "" ? "" : sprintf(", %+.1f %% vs the single runs", 100 * (s / base - 1));
    printf "%-34s %7.1f s  %6.0f cases/h%s\n", l, s, 3600 * n / s, o }'
}

# N single runs, one after the other, with 1 and with 2 threads.
for threads in 1 2; do
  t0=$(now)
  for c in "$work"/cases/case*/; do
    "$facesim" --threads "$threads" run "$c" --set "solve.model=\"$model\"" --out "$work/single$threads/$(basename "$c")" >/dev/null 2>&1
  done
  eval "single$threads=$(awk -v a="$(now)" -v b="$t0" 'BEGIN { print a - b }')"
done

snake() { # cores threads-per-job
  local out="$work/out-c$1-t$2"
  local t0
  t0=$(now)
  (cd "$work" && "$snakemake" -s "$root/workflow/Snakefile" --cores "$1" --quiet all \
    --configfile "$work/variants.yaml" \
    --config cohort="$work/cases" out="$out" facesim="$facesim" threads="$2" >/dev/null 2>&1)
  awk -v a="$(now)" -v b="$t0" 'BEGIN { print a - b }'
}

echo "cohort of $n jaws phantoms (2 mm), model $model, $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
report "single runs, --threads 1" "$single1"
report "single runs, --threads 2" "$single2"
report "snakemake --cores 1" "$(snake 1 1)" "$single1"
report "snakemake --cores 2, 2 jobs x 1 thread" "$(snake 2 1)" "$single1"
report "snakemake --cores 2, 1 job x 2 threads" "$(snake 2 2)" "$single2"

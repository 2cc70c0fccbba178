#!/usr/bin/env bash
# The neo-Hookean material against the linear default on the same case, alternating runs on the
# same machine (the target: at most 5x the linear run). Usage:
#   benches/nonlinear.sh [CASE_DIR] [RUNS]     (default data-samples/real, 2)
# Prints wall and user seconds per run, the Newton and CG iterations, and the ratio of the means.
set -euo pipefail
cd "$(dirname "$0")/.."
case_dir=${1:-data-samples/real}
runs=${2:-2}
cargo build --release -q
bin=target/release/facesim
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
declare -A total=([linear]=0 [neo-hookean]=0)
for _ in $(seq "$runs"); do
  for m in linear neo-hookean; do
    t=$( { /usr/bin/time -f "%e %U" "$bin" run "$case_dir" --out "$out/$m" --set tet.material=$m >/dev/null 2>&1; } 2>&1 | tail -1)
    wall=${t% *}
    total[$m]=$(python3 -c "print(${total[$m]} + $wall)")
    newton=$(python3 -c "import json;r=json.load(open('$out/$m/report.json'));n=r['tet'].get('newton');print(n[0] if n else '-')")
    echo "$m: wall ${wall} s, user ${t#* } s, newton $newton"
  done
done
echo "ratio neo-hookean / linear (mean wall): $(python3 -c "print(round(${total[neo-hookean]} / ${total[linear]}, 2))")"

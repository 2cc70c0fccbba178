#!/usr/bin/env bash
# The comparison set for a refactor that must not change behaviour: every
# output of `facesim run` on the bundled and the real sample with each model, with uncertainty
# sampling, a replan and a sweep.
#   scripts/outputs-set.sh BIN DEST      e.g. a build from before the change, then after it
#   scripts/compare-outputs.py DEST_BEFORE DEST_AFTER
set -euo pipefail
[ $# = 2 ] || { echo "usage: $0 FACESIM_BINARY DEST_DIR" >&2; exit 2; }
bin=$(realpath "$1"); dest=$2
root="$(cd "$(dirname "$0")/.." && pwd)"
samples="$root/data-samples"
mkdir -p "$dest"
run() { echo "+ facesim $*" >&2; "$bin" "$@" >/dev/null; }
run run "$samples/phantom" --out "$dest/phantom-tet"
run run "$samples/phantom" --out "$dest/phantom-eq" --set solve.model=equilibrium
run run "$samples/phantom" --out "$dest/phantom-koch" --set solve.model=koch1996
run run "$samples/phantom" --out "$dest/phantom-unc" --set uncertainty.samples=3
run run "$samples/real" --out "$dest/real-tet"
run run "$samples/real" --out "$dest/real-eq" --set solve.model=equilibrium
cat > "$dest/plan2.toml" <<'PLAN'
[[osteotomy]]
name = "mandible"
region = { box = { min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] } }
translate = [0.0, -4.0, 1.0]
rotate_deg = [2.0, 0.0, 0.0]
PLAN
run replan "$dest/phantom-tet" "$dest/plan2.toml" --out "$dest/phantom-tet-replan"
printf '[grid]\nsegment = "mandible"\ntranslate_y = { from = 0, to = -8, steps = 3 }\n' > "$dest/sweep.toml"
run sweep "$dest/phantom-tet" "$dest/sweep.toml" --out "$dest/sweep"

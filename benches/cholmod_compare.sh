#!/usr/bin/env bash
# Benchmark-only: faer vs CHOLMOD on the same C1 surface matrix (docs/design/fem.md).
# Installs Debian's libsuitesparse-dev if needed; not part of the tests.
set -euo pipefail
cd "$(dirname "$0")/.."
tri="${1:-40000}"
[ -f /usr/include/suitesparse/cholmod.h ] || { apt-get update -qq >/dev/null; apt-get install -y -qq libsuitesparse-dev >/dev/null; }
work="$(mktemp -d)"; trap 'rm -rf "$work"' EXIT
gcc -O2 -I/usr/include/suitesparse benches/cholmod_compare.c -lcholmod -o "$work/cholmod_compare"
cargo build --release -q
echo "faer:"
./target/release/facesim-lab bench fem --triangles "$tri" --export "$work/K.mtx"
echo "CHOLMOD (SuiteSparse $(dpkg-query -W -f='${Version}' libsuitesparse-dev 2>/dev/null || echo '?')):"
"$work/cholmod_compare" "$work/K.mtx"

#!/usr/bin/env bash
# Fetch the real sample CT (ProMED CT 0051, 256x256x108, 0.957x0.957x1.5 mm) from Debian's
# invesalius-examples package (GPL-2 data: fetched, never committed) into data-samples/real/.
# Idempotent: does nothing when the file is already there.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
dest="$here/real/Cranium.inv3"
[ -s "$dest" ] && exit 0
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
if ! apt-get download invesalius-examples >/dev/null 2>&1; then
  # A fresh machine has no package lists yet.
  if [ "$(id -u)" = 0 ]; then apt-get update -qq >/dev/null; else sudo apt-get update -qq >/dev/null; fi
  apt-get download invesalius-examples >/dev/null
fi
dpkg -x invesalius-examples_*.deb x
src="$(find x -name Cranium.inv3 | head -n 1)"
[ -n "$src" ] || { echo "fetch-real.sh: Cranium.inv3 not found in invesalius-examples" >&2; exit 1; }
cp "$src" "$dest.partial" && mv "$dest.partial" "$dest"
echo "fetched $(du -h "$dest" | cut -f1) into $dest"

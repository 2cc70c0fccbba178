#!/usr/bin/env bash
# Fetch a real 3D face scan with human-placed landmarks: "james" from the menpo3d 0.8.6 source
# package on PyPI (BSD-3-Clause, Imperial College London): menpo3d/data/james.obj (a textured
# face scan, 6 393 vertices, mm) and james.ljson (68 landmarks in the iBUG layout: nose, lips,
# mouth corners, chin). Fetched, never committed, into data-samples/face-scan/ with menpo3d's
# licence; the archive is checked against its pinned sha256. Idempotent.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
dest="$here/face-scan"
[ -s "$dest/james.obj" ] && [ -s "$dest/james.ljson" ] && exit 0
url="https://files.pythonhosted.org/packages/cf/3b/1490a36682e1a5da3703efc1c7af3f1d07c1247477b699b980a3b5eb9a20/menpo3d-0.8.6.tar.gz"
sha="96ad2c8b55b74e026cdc190cf6b1564ad7c8e6c53976cf897d6a1bf4940f084a"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
python3 - "$url" "$work/menpo3d.tar.gz" <<'PY'
import sys, urllib.request
urllib.request.urlretrieve(sys.argv[1], sys.argv[2])
PY
[ "$(sha256sum "$work/menpo3d.tar.gz" | cut -d' ' -f1)" = "$sha" ] ||
  { echo "fetch-face-scan.sh: menpo3d-0.8.6.tar.gz does not match its sha256" >&2; exit 1; }
tar xzf "$work/menpo3d.tar.gz" -C "$work" menpo3d-0.8.6/menpo3d/data/james.obj \
  menpo3d-0.8.6/menpo3d/data/james.ljson menpo3d-0.8.6/LICENSE.txt
rm -rf "$dest.partial" && mkdir -p "$dest.partial"
cp "$work"/menpo3d-0.8.6/menpo3d/data/james.{obj,ljson} "$dest.partial/"
cp "$work/menpo3d-0.8.6/LICENSE.txt" "$dest.partial/LICENSE-menpo3d.txt"
rm -rf "$dest" && mv "$dest.partial" "$dest"
echo "fetched $(du -sh "$dest" | cut -f1) into $dest"

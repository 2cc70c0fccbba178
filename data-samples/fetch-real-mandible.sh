#!/usr/bin/env bash
# Fetch the second real sample CT, VTK's classic "headsq" head (64x64x93, 3.2x3.2x1.5 mm, int16
# = HU + 1024, with the mandible), from npm package vtk.js@6.4.1 (BSD-3-Clause, Kitware), where
# it is shipped as a vtk.js dataset folder: Data/volume/headsq.vti/{index.json, data/<md5>.gz}.
# Later versions (>= 6.4.24, and @kitware/vtk.js) dropped it. Fetched, never committed: only that
# folder is copied into data-samples/real-mandible/headsq.vti/ (facesim reads it as it is,
# docs/guide/real-ct.md). Idempotent: does nothing when the dataset is already there.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
dest="$here/real-mandible/headsq.vti"
[ -s "$dest/index.json" ] && [ -n "$(ls "$dest/data" 2>/dev/null)" ] && exit 0
command -v npm >/dev/null 2>&1 || { echo "fetch-real-mandible.sh: npm is needed (apt-get install npm)" >&2; exit 1; }
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
npm pack vtk.js@6.4.1 --silent >/dev/null
tar xzf vtk.js-6.4.1.tgz package/Data/volume/headsq.vti package/LICENSE
src="package/Data/volume/headsq.vti"
[ -s "$src/index.json" ] || { echo "fetch-real-mandible.sh: headsq.vti not found in vtk.js@6.4.1" >&2; exit 1; }
# The voxel file is named by the md5 of its uncompressed bytes: check it.
for f in "$src"/data/*.gz; do
  id="$(basename "$f" .gz)"
  [ "$(gzip -dc "$f" | md5sum | cut -d' ' -f1)" = "$id" ] ||
    { echo "fetch-real-mandible.sh: $f does not match its md5 name" >&2; exit 1; }
done
cp package/LICENSE "$src/LICENSE-vtk.js"
rm -rf "$dest.partial" "$dest"
cp -r "$src" "$dest.partial" && mv "$dest.partial" "$dest"
echo "fetched $(du -sh "$dest" | cut -f1) into $dest"

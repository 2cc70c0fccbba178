#!/usr/bin/env bash
# Install what the tests need on a fresh Debian machine, building the tests meanwhile (README's test
# command runs this first).
# Idempotent and quiet when everything is already there. One function per need, so later needs
# (a browser, npm packages, a Python venv) are one more function and one more line at the bottom.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"

# Run as root on a fresh machine; elsewhere through sudo.
as_root() {
  if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi
}

# Install Debian packages that are missing; `apt-get update` only when the install fails for
# lack of package lists (a fresh machine has none).
apt_install() {
  local missing=()
  local p
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ "${#missing[@]}" = 0 ] && return 0
  export DEBIAN_FRONTEND=noninteractive
  if ! as_root apt-get install -y -qq "${missing[@]}" >/dev/null 2>&1; then
    as_root apt-get update -qq >/dev/null
    as_root apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
  echo "test-setup: installed ${missing[*]}"
}

# CalculiX, the independent engine the volumetric model is checked against (docs/design/crosscheck.md).
need_calculix() {
  command -v ccx >/dev/null 2>&1 || apt_install calculix-ccx
}

# Encoders for the compressed-DICOM fixtures (docs/guide/dicom.md): dcmtk's dcmcjpeg, dcmcrle,
# dcmcjpls and gdcm's gdcmconv (JPEG 2000).
need_dicom_tools() {
  command -v dcmcjpeg >/dev/null 2>&1 || apt_install dcmtk
  command -v gdcmconv >/dev/null 2>&1 || apt_install libgdcm-tools
}

# The real sample CT (GPL-2 data, fetched, never committed).
need_real_ct() {
  "$root/data-samples/fetch-real.sh"
}

# The second real sample, VTK's headsq with the mandible (BSD-3 data from npm's vtk.js@6.4.1,
# fetched, never committed); needs npm, so after need_browser.
need_real_mandible() {
  "$root/data-samples/fetch-real-mandible.sh"
}

# A real 3D face scan with human-placed landmarks (menpo3d's "james", BSD-3, from PyPI; fetched,
# never committed) for the face-mesh landmark test (docs/guide/landmarks.md).
need_face_scan() {
  "$root/data-samples/fetch-face-scan.sh"
}

# Headless Chromium for report.html's browser test (Debian's chromium, never a downloaded
# browser), and node/npm to drive it (docs/guide/report-page.md).
need_browser() {
  command -v chromium >/dev/null 2>&1 || apt_install chromium
  command -v node >/dev/null 2>&1 || apt_install nodejs
  command -v npm >/dev/null 2>&1 || apt_install npm
}

# web/'s npm packages (three, esbuild, puppeteer-core) as the lockfile pins them.
need_npm() {
  local web="$root/web"
  if [ ! -d "$web/node_modules" ] || [ "$web/package-lock.json" -nt "$web/node_modules" ]; then
    (cd "$web" && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
    touch "$web/node_modules"
    echo "test-setup: npm ci in web/"
  fi
}

# A Python venv for the tests' Python tools (target/slicer-venv): ctk-cli, the CommonTK parser
# of Slicer Execution Model XML, reads FaceSimPredict --xml (docs/guide/slicer.md). Pinned; more
# packages go in the pip line.
need_python_venv() {
  python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || apt_install python3-venv
  local venv="$root/target/slicer-venv"
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/python" -c 'import ctk_cli' >/dev/null 2>&1 || {
    "$venv/bin/pip" install -q "ctk-cli==1.5"
    echo "test-setup: venv $venv with ctk-cli"
  }
  # The facesim Python package (docs/guide/python.md): maturin builds its wheel, pytest and numpy test
  # it (crates/facesim-cli/tests/e2e/python_package.rs). Pinned.
  "$venv/bin/python" -c 'import maturin, pytest, numpy' >/dev/null 2>&1 || {
    "$venv/bin/pip" install -q "maturin==1.16.0" "pytest==9.2.0" "numpy==2.4.6"
    echo "test-setup: venv $venv with maturin, pytest, numpy"
  }
  # scikit-image's marching cubes makes the "skin from another program" fixture
  # (crates/facesim/tests/library/foreign_skin.rs).
  "$venv/bin/python" -c 'import skimage' >/dev/null 2>&1 || {
    "$venv/bin/pip" install -q "scikit-image==0.26.0"
    echo "test-setup: scikit-image in $venv"
  }
  # highdicom converts a single-frame series into a multi-frame Legacy Converted Enhanced CT
  # object (crates/facesim/tests/library/dicom_codecs.rs, tests/python/legacy_enhanced.py).
  # VTK itself re-saves a model in every encoding its writers have
  # (crates/facesim/tests/library/vtk_files.rs, tests/python/vtk_variants.py).
  "$venv/bin/python" -c 'import vtkmodules.vtkIOXML' >/dev/null 2>&1 || {
    "$venv/bin/pip" install -q "vtk==9.7.2"
    echo "test-setup: vtk in $venv"
  }
  "$venv/bin/python" -c 'import highdicom' >/dev/null 2>&1 || {
    "$venv/bin/pip" install -q "highdicom==0.28.2"
    echo "test-setup: highdicom in $venv"
  }
}

# The cohort workflow's tools in the same venv (docs/guide/cohort.md): Snakemake runs workflow/Snakefile,
# its Slurm executor plugin reads workflow/profiles/slurm (dry runs in the test), matplotlib
# draws the charts. Pinned.
need_cohort_tools() {
  local venv="$root/target/slicer-venv"
  "$venv/bin/python" -c 'import snakemake, snakemake_executor_plugin_slurm, matplotlib' >/dev/null 2>&1 || {
    "$venv/bin/pip" install -q "snakemake==9.27.1" "snakemake-executor-plugin-slurm==2.8.0" \
      "matplotlib==3.11.2"
    echo "test-setup: snakemake, its Slurm plugin and matplotlib in $venv"
  }
}

# A real Slurm for the cohort workflow's cluster test (crates/facesim-cli/tests/e2e/cluster.rs,
# docs/guide/cohort.md "A real Slurm on one machine"): Debian's slurm-wlm 22.05 controller, node
# daemon and client commands, and munge. scripts/slurm-cluster.sh runs them from a temporary
# directory; nothing here configures or starts a service (a container's policy-rc.d keeps apt
# from starting them; elsewhere stop the packaged services: systemctl disable --now slurmctld
# slurmd munge).
need_slurm() {
  local p missing=()
  for p in slurmctld slurmd sbatch munged; do
    command -v "$p" >/dev/null 2>&1 || missing+=("$p")
  done
  [ "${#missing[@]}" = 0 ] || apt_install slurmctld slurmd slurm-client munge
}

# The tests' build needs only the Rust toolchain: it runs while the packages below download,
# and `cargo test --release` then finds it done. Its output goes to target/test-setup-build.log;
# a failed build is left for `cargo test` to report. If a need below fails, the build is
# stopped with the script (`exec`: the background job is cargo itself).
prebuild_tests() {
  mkdir -p "$root/target"
  (cd "$root" && exec cargo test --release --no-run >"$root/target/test-setup-build.log" 2>&1) &
  build_pid=$!
  trap 'kill "$build_pid" 2>/dev/null || true' EXIT
}

prebuild_tests
need_calculix
need_dicom_tools
need_real_ct
need_browser
need_real_mandible
need_face_scan
need_npm
need_python_venv
need_cohort_tools
need_slurm
wait "$build_pid" || echo "test-setup: the tests' build failed (target/test-setup-build.log); cargo test reports it"

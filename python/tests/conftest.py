"""Fixtures for the facesim package's tests (docs/guide/python.md "Tests").

The command line is the independent path: a small phantom case is run by the `facesim` binary
(FACESIM_BIN, set by crates/facesim-cli/tests/e2e/python_package.rs; default `facesim` on PATH) and by
the installed package, and the package's arrays are compared with the files the binary wrote.
"""

import os
import shutil
import subprocess
import threading
import time
from pathlib import Path

import pytest

import facesim


def facesim_bin() -> str:
    exe = os.environ.get("FACESIM_BIN") or shutil.which("facesim")
    if not exe:
        pytest.fail("no facesim binary: set FACESIM_BIN or put facesim on PATH")
    return exe


def cli(*args, check=True):
    """Run the facesim binary; return the completed process."""
    p = subprocess.run([facesim_bin(), *map(str, args)], capture_output=True, text=True)
    if check and p.returncode != 0:
        pytest.fail(f"facesim {' '.join(map(str, args))} failed: {p.stderr}")
    return p


class Ticker:
    """A second Python thread that records when it runs: it can only run while the main
    thread has released the interpreter lock."""

    def __init__(self):
        self.ticks = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self._stop.is_set():
            self.ticks.append(time.perf_counter())
            time.sleep(0.005)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


@pytest.fixture(scope="session")
def case_dir(tmp_path_factory) -> Path:
    """The capsule phantom (a 6 mm mandibular advance, docs/design/phantom.md)."""
    d = tmp_path_factory.mktemp("phantom")
    cli("phantom", d)
    return d


@pytest.fixture(scope="session")
def cli_out(case_dir, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli-out")
    cli("run", case_dir, "--out", out)
    return out


@pytest.fixture(scope="session")
def dict_run(case_dir, tmp_path_factory):
    """The case.toml as a dict (relative paths, base_dir = the case directory), run while a
    second thread ticks: (result, ticks, start, end)."""
    import tomllib

    case = tomllib.loads((case_dir / "case.toml").read_text())
    out = tmp_path_factory.mktemp("py-dict-out")
    with Ticker() as t:
        start = time.perf_counter()
        r = facesim.run(case, out=out, base_dir=case_dir)
        end = time.perf_counter()
    return r, t.ticks, start, end


@pytest.fixture(scope="session")
def path_run(case_dir, tmp_path_factory):
    """The case directory as a path, on one worker thread."""
    out = tmp_path_factory.mktemp("py-path-out")
    return facesim.run(case_dir, out=out, threads=1)

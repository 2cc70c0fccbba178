"""Files the cohort workflow writes whole or not at all. Standard library only; imported by
gather.py, run_case.py and case_size.py (and so by the Snakefile)."""

import json
import os
import tempfile


def umask() -> int:
    """The process's umask, read without changing it (/proc/self/status; 022 if unreadable)."""
    try:
        with open("/proc/self/status") as f:
            return next((int(l.split()[1], 8) for l in f if l.startswith("Umask:")), 0o022)
    except (OSError, ValueError, IndexError):
        return 0o022


class replacing:
    """`with replacing(path) as f:` writes `path` whole or not at all: a temporary of its own
    in the same directory (two writers of one path never share one), renamed over `path` at
    the end, removed on an error. The directory is made if missing."""

    def __init__(self, path):
        self.path = path

    def __enter__(self):
        d = os.path.dirname(self.path) or "."
        os.makedirs(d, exist_ok=True)
        fd, self.tmp = tempfile.mkstemp(
            dir=d, prefix=os.path.basename(self.path) + ".", suffix=".tmp")
        # mkstemp's file is private (0600); the file is as readable as any file written here.
        os.fchmod(fd, 0o666 & ~umask())
        self.f = os.fdopen(fd, "w", newline="")
        return self.f

    def __exit__(self, kind, value, tb):
        self.f.close()
        if kind is None:
            os.replace(self.tmp, self.path)
        else:
            try:
                os.unlink(self.tmp)
            except OSError:
                pass
        return False


def write_json(path: str, value):
    """`value` as JSON into `path`, whole or not at all."""
    with replacing(path) as f:
        json.dump(value, f, indent=1)

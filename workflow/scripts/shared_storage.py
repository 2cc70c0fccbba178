"""Is a path on storage a cluster's nodes share? (docs/guide/cohort.md, "Shared storage".) The
Snakefile asks before it submits anything: the facesim binary, the cohort, OUT, the workflow's
scripts and the Python that runs them must all be visible on the compute nodes. A path counts as
shared when it lies under one of the directories the configuration's `shared_storage` lists
(what the site mounts on every node), or — with no such list — when its file system is a
network or cluster one (NFS, Lustre, GPFS, BeeGFS, CephFS, …; from /proc/self/mountinfo).
Standard library only."""

import os
import shutil

NETWORK_FS = {
    "nfs", "nfs4", "lustre", "gpfs", "beegfs", "cephfs", "ceph", "cifs", "smb3", "smbfs",
    "glusterfs", "fuse.glusterfs", "fuse.cephfs", "fuse.ceph", "panfs", "wekafs", "pvfs2",
    "orangefs", "afs", "fuse.sshfs", "fuse.s3fs", "fuse.juicefs", "quobyte", "fuse.quobyte",
}


def mount_of(path):
    """(mount point, file system type) holding path, from /proc/self/mountinfo."""
    best = ("/", "?")
    try:
        with open("/proc/self/mountinfo") as f:
            for line in f:
                left, _, right = line.partition(" - ")
                point = left.split()[4].replace("\\040", " ")
                fstype = right.split()[0] if right else "?"
                inside = path == point or path.startswith(point.rstrip("/") + "/")
                if inside and len(point) >= len(best[0]):
                    best = (point, fstype)
    except OSError:
        pass
    return best


def check_shared(paths, shared_dirs):
    """None when every path (name → path) is on shared storage; else one line saying which is
    not and what to do."""
    prefixes = [os.path.realpath(os.path.expanduser(str(d))) for d in shared_dirs]
    for name, raw in paths.items():
        path = str(raw)
        if name == "facesim" and os.sep not in path:
            found = shutil.which(path)
            if not found:
                return f"facesim binary {path!r} is not on PATH: give facesim=/shared/path/facesim"
            path = found
        real = os.path.realpath(path)
        if name == "out":
            # OUT may not exist yet: judge the nearest directory that does.
            while not os.path.exists(real) and os.path.dirname(real) != real:
                real = os.path.dirname(real)
        elif not os.path.exists(real):
            return f"{name} {path} does not exist"
        if prefixes:
            if not any(real == p or real.startswith(p.rstrip("/") + "/") for p in prefixes):
                return (
                    f"{name} {path} is not under shared_storage ({', '.join(prefixes)}): "
                    "the compute nodes would not find it; move it there or list its directory "
                    "in shared_storage"
                )
            continue
        point, fstype = mount_of(real)
        if fstype not in NETWORK_FS:
            return (
                f"{name} {path} is on a local file system ({fstype} at {point}), which the "
                "compute nodes do not see: put it on shared storage, or list the directories "
                "every node mounts in shared_storage (docs/guide/cohort.md)"
            )
    return None

"""Type stubs of the facesim package (docs/guide/python.md). Lengths in mm, LPS frame."""

import os
from typing import Any, Dict, List, Mapping, Optional, TypedDict, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, "os.PathLike[str]"]

class FacesimError(Exception):
    """facesim's one-line error: bad input (naming the file and the problem) or a numerical failure."""

class Landmark(TypedDict):
    pre: npt.NDArray[np.float64]  # (3,), LPS mm, on face_pre
    post: npt.NDArray[np.float64]  # (3,), LPS mm, carried to face_post
    change_mm: float
    kind: str  # "soft" or "bone"

class Band(TypedDict):
    mean: npt.NDArray[np.float64]  # (n,), displacement magnitude, mm
    p05: npt.NDArray[np.float64]
    p95: npt.NDArray[np.float64]

class Result:
    """A run's or a replan's face; arrays equal the files the command line writes."""

    @property
    def out_dir(self) -> str: ...
    @property
    def vertices_pre(self) -> npt.NDArray[np.float64]:
        """face_pre's vertices, shape (n, 3), LPS mm."""
    @property
    def vertices_post(self) -> npt.NDArray[np.float64]:
        """face_post's vertices, shape (n, 3), LPS mm, same order as vertices_pre."""
    @property
    def triangles(self) -> npt.NDArray[np.int64]:
        """Triangles shared by face_pre and face_post, shape (m, 3), vertex indices."""
    @property
    def displacement(self) -> npt.NDArray[np.float64]:
        """|vertices_post - vertices_pre| per vertex, shape (n,), mm (displacement.csv's dist)."""
    @property
    def landmarks(self) -> Dict[str, Landmark]:
        """The landmarks found, label -> pre/post; for a replan, the run's landmarks carried with the new plan."""
    @property
    def report(self) -> Dict[str, Any]:
        """report.json as a dict."""
    @property
    def band(self) -> Optional[Band]:
        """The uncertainty band (face_band.ply) when this run sampled [uncertainty], else None."""

def run(
    case: Union[PathLike, Mapping[str, Any]],
    out: Optional[PathLike] = None,
    threads: Optional[int] = None,
    base_dir: Optional[PathLike] = None,
) -> Result:
    """Run the pipeline on a case directory, a case .toml file, or a case.toml as a dict.

    A dict behaves as a case.toml in ``base_dir`` (default: the working directory): relative
    paths resolve there and the default ``out`` is ``base_dir/out``. A path's default ``out`` is
    ``CASE_DIR/out``, as ``facesim run``. ``threads``: worker threads (default: all cores).
    Raises FacesimError on bad input.
    """

def replan(
    out_dir: PathLike,
    plan: Union[PathLike, Mapping[str, Any]],
    out: Optional[PathLike] = None,
) -> Result:
    """The face for a new plan from the plan basis in a run's ``out_dir``, without re-solving.

    ``plan``: a PLAN.toml path or a dict ``{"osteotomy": [{"name": ..., "translate": ...}]}``.
    Writes ``facesim replan``'s files into ``out`` (default ``out_dir/replan``).
    """

def sweep(
    out_dir: PathLike,
    sweep: Union[PathLike, Mapping[str, Any]],
    out: Optional[PathLike] = None,
) -> Dict[str, Union[npt.NDArray[np.float64], npt.NDArray[np.int64], List[str]]]:
    """Many plans from a run's plan basis: sweep.csv's columns (``plan`` int64, ``label`` list
    of str, the rest float64 with NaN for an absent region). With ``out``, also writes
    sweep.csv and sweep.svg there.
    """

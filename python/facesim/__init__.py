"""facesim: predict a patient's face after jaw surgery from a CT (docs/guide/python.md).

``run`` runs the pipeline on a case (a case directory, a case.toml, or the case as a dict),
``replan`` predicts the face for a new plan from a run's plan basis without re-solving, and
``sweep`` evaluates many plans into a table. Arrays are numpy, lengths in millimetres in the
LPS frame (x to the patient's left, y posterior, z superior). The work runs with the
interpreter lock released; facesim's errors raise ``FacesimError``.
"""

from ._facesim import FacesimError, Result, __version__, replan, run, sweep

__all__ = ["FacesimError", "Result", "__version__", "replan", "run", "sweep"]

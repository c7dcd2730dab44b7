"""piecs_bayes: uncertainty-aware process-intermittent error compensation for turning.

Probe points gauged on the machine after a semifinish cut become a compensated
finish cut (NIST PIECS), with the uncertainty of every number.

Conventions (see ``docs/formats.md``): millimetres internally; the turned profile
lives in the XZ half-plane with points stored as ``(x, z)``, x radial (radius,
never diameter, inside the package), z along the spindle axis; feature
parameters are deviations from nominal; float64 everywhere.
"""

from . import _config  # noqa: F401  (x64 before anything else touches jax)
from .errors import AnalysisError, InputError, PiecsError

__version__ = "0.1.0"

__all__ = ["AnalysisError", "InputError", "PiecsError", "__version__"]

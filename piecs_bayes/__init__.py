"""piecs_bayes: uncertainty-aware process-intermittent error compensation for turning.

Probe points gauged on the machine after a semifinish cut become a compensated
finish cut (NIST PIECS), with the uncertainty of every number.

Conventions (see ``docs/formats.md``): millimetres internally; the turned profile
lives in the XZ half-plane with points stored as ``(x, z)``, x radial (radius,
never diameter, inside the package), z along the spindle axis; feature
parameters are deviations from nominal; float64 everywhere.

Importing the package does not import JAX (``piecs-bayes --help`` answers at once):
every subpackage that computes imports `_config` first, which switches JAX to
float64 before any array is made.
"""

from .errors import AnalysisError as AnalysisError
from .errors import InputError as InputError
from .errors import PiecsError as PiecsError

__version__ = "0.1.0"

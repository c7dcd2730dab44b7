"""A general (robust) least-squares engine on optimistix: problems as arrays, solvers,
statistics and results."""

from ... import _config  # noqa: F401  (float64 before any JAX array)
from ._core import is_linear as is_linear
from ._core import solve_arrays as solve_arrays
from ._core import stages as stages
from ._least_squares import flat_structure as flat_structure
from ._least_squares import least_squares as least_squares
from ._options import SolverOptions as SolverOptions
from ._result import LsqResult as LsqResult
from ._result import result_from_arrays as result_from_arrays
from ._statistics import FinalLoss as FinalLoss
from ._statistics import analyse as analyse
from ._statistics import statistics as statistics
from ._types import COV_OK as COV_OK
from ._types import LsqArrays as LsqArrays
from ._types import Status as Status
from .losses import TUNING as TUNING
from .losses import normal_variance_factor as normal_variance_factor

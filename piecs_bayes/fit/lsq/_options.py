"""The least-squares engine's solver settings as one object, [`SolverOptions`][]: which
optimistix solver runs and when it stops (as optimistix's solver objects carry their
tolerances). Checked when made; frozen, so one object serves every solve."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ._types import SOLVERS


@dataclass(frozen=True)
class SolverOptions:
    """The solver of [`least_squares`][] and [`solve_arrays`][].

    **Fields:**

    - `method`: `"lm"` (Levenberg-Marquardt, the default), `"gauss_newton"` or
      `"dogleg"`.
    - `rtol`, `atol`: optimistix's Cauchy termination tolerances (on both the
      parameter and the residual change).
    - `max_steps`: step limit of each stage.

    Raises `ValueError` (an [`InputError`][piecs_bayes.errors.InputError]) for an
    unknown `method` or a `max_steps` that is not a positive integer.
    """

    method: str = "lm"
    rtol: float = 1e-10
    atol: float = 1e-12
    max_steps: int = 1000

    def __post_init__(self) -> None:
        if self.method not in SOLVERS:
            raise InputError(f"unknown solver {self.method!r}; expected one of {SOLVERS}")
        if not (isinstance(self.max_steps, int | np.integer) and self.max_steps > 0):
            raise InputError(f"max_steps must be a positive integer, got {self.max_steps!r}")

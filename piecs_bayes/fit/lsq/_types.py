"""The least-squares engine's codes and array result: [`Status`][] (what a solve
ended with, each member with its message), the covariance codes and their
reasons, and [`LsqArrays`][], the array-only result that passes through
`jax.vmap`."""

from __future__ import annotations

import enum
from typing import NamedTuple

import jax

#: the engine's solvers (optimistix; `_solver`)
SOLVERS = ("lm", "gauss_newton", "dogleg")


class Status(enum.IntEnum):
    """Outcome of a solve. Each member carries a human-readable `message`."""

    SUCCESSFUL = 0
    MAX_STEPS_REACHED = 1
    DIVERGED = 2
    NONFINITE = 3
    SINGULAR = 4
    LINEAR_SOLVE_FAILED = 5
    STALLED = 6
    DEGENERATE = 7

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    Status.SUCCESSFUL: "converged",
    Status.MAX_STEPS_REACHED: "the maximum number of steps was reached before convergence "
    "(raise max_steps, rescale the parameters with x_scale, or start closer)",
    Status.DIVERGED: "the nonlinear solve diverged",
    Status.NONFINITE: "non-finite (inf or nan) values in the residuals or parameters",
    Status.SINGULAR: "a singular linear system was met during the solve",
    Status.LINEAR_SOLVE_FAILED: "the linear solve inside a step failed",
    Status.DEGENERATE: "the robust fit rejected (nearly) all the points: fewer effective "
    "points than parameters + 1 (check the scale and the start)",
    Status.STALLED: "the solver stopped at a point that is not a minimum (a Gauss-Newton "
    "step from it is not negligible): try another start or rescale with x_scale",
}

# covariance codes (LsqArrays.covariance_code)
COV_OK, COV_DOF, COV_SINGULAR, COV_NONFINITE, COV_ROBUST = 0, 1, 2, 3, 4
COV_REASONS = {
    COV_DOF: "no degrees of freedom left to estimate the residual variance (dof <= 0); give sigma",
    COV_SINGULAR: "the weighted Jacobian is singular at the solution "
    "(parameters not identifiable from these points)",
    COV_NONFINITE: "non-finite Jacobian or residuals at the solution",
    COV_ROBUST: "the robust fit gave (nearly) every point zero weight",
}


class LsqArrays(NamedTuple):
    """Array-only result of [`solve_arrays`][] (every field is a JAX array, so it
    passes through `jax.vmap`). Shapes for `n` residuals and `p` parameters."""

    params_flat: jax.Array  # (p,)
    status_code: jax.Array  # () int, a Status value
    residuals: jax.Array  # (n,) raw residuals at the solution
    weights: jax.Array  # (n,) effective weights: user * robust
    robust_weights: jax.Array  # (n,) rho'(z), 1 for the linear loss
    outlier: jax.Array  # (n,) bool
    covariance: jax.Array  # (p, p), NaN when unavailable
    covariance_code: jax.Array  # () int, 0 = ok
    condition: jax.Array  # () condition number of the column-scaled weighted Jacobian
    jacobian: jax.Array  # (n, p) of the raw residuals
    rss: jax.Array  # () sum w r^2
    cost: jax.Array  # () the minimised objective, 0.5 sum s^2 rho(z)
    n_used: jax.Array  # () int, points with non-zero weight
    dof: jax.Array  # () int, n_used - p
    residual_sd: jax.Array  # () sqrt(rss/dof) (linear) or 1.4826 MAD (robust)
    scale: jax.Array  # () loss scale of the last stage (NaN for the linear loss)
    steps: jax.Array  # () int, solver steps over all stages

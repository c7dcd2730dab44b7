"""The optimistix solvers behind [`solve_arrays`][], through optimistix's public API.

- [`make_solver`][] builds the solver by name: optimistix's Gauss-Newton, or a
  Levenberg-Marquardt / Dogleg declared with the rounding-safe trust region
  `SafeTrustRegion` (optimistix composes a Gauss-Newton-type solver from a
  `descent` and a `search`: `TrustRegionSolver` declares that pair).
- [`status_code`][] maps an optimistix `RESULTS` member to a [`Status`][] code,
  by equality with the public members (traceable: it works under `jit`/`vmap`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from ._types import SOLVERS, Status

#: optimistix's outcome -> ours; any other member (a failed linear solve:
#: breakdown, stagnation, conlim, max_steps_reached of an iterative linear
#: solver) is `LINEAR_SOLVE_FAILED`.
_OPTX_TO_STATUS = (
    (optx.RESULTS.successful, Status.SUCCESSFUL),
    (optx.RESULTS.nonlinear_max_steps_reached, Status.MAX_STEPS_REACHED),
    (optx.RESULTS.nonlinear_divergence, Status.DIVERGED),
    (optx.RESULTS.nonfinite, Status.NONFINITE),
    (optx.RESULTS.nonfinite_input, Status.NONFINITE),
    (optx.RESULTS.singular, Status.SINGULAR),
)


def status_code(result) -> jax.Array:
    """The `Status` code (int32) of an optimistix `RESULTS` member `result`."""
    code = jnp.asarray(int(Status.LINEAR_SOLVE_FAILED), dtype=jnp.int32)
    for member, status in _OPTX_TO_STATUS:
        code = jnp.where(result == member, jnp.int32(int(status)), code)
    return code


class _TrustRegionState(eqx.Module):
    step_size: jax.Array


class SafeTrustRegion(optx.AbstractSearch):
    """optimistix's classical trust region, made safe for the last steps.

    At a minimum reached to rounding, every real step is rejected and the region
    shrinks until the step no longer changes `y`. Its cost should then equal the
    current one, but the two evaluations can differ by an ulp (under `vmap` the
    sums run in another order); stock optimistix rejects that step forever and
    the solve spins to `max_steps` at the answer, because the Cauchy termination
    test only runs on accepted steps. Here a step is also accepted when it raises
    the cost by no more than rounding noise (`noise * eps * cost`), and the step
    size (1/damping) is kept above `floor` (damping `finfo.max` would overflow the
    QR of the damped system).

    The update is `ClassicalTrustRegion`'s, term for term, with its cutoffs,
    constants and predicted reduction (`inner`); the state is this search's own.
    """

    inner: optx.ClassicalTrustRegion
    floor: float = 1e-30
    noise: float = 16.0

    def init(self, y, f_info_struct):
        del y, f_info_struct
        return _TrustRegionState(step_size=jnp.array(1.0))

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        tr = self.inner
        y_diff = jax.tree_util.tree_map(lambda a, b: a - b, y_eval, y)
        predicted = tr.predict_reduction(y_diff, f_info)
        f_now = f_info.as_min()
        f_new = f_eval_info.as_min()
        f_diff = f_new - f_now  # negative for a good step
        accept = f_diff <= tr.low_cutoff * predicted
        good = (f_diff < tr.high_cutoff * predicted) & (predicted < 0)
        good = good & jnp.invert(first_step)
        accept = accept | first_step
        mul = jnp.where(good, tr.high_constant, 1)
        mul = jnp.where(accept, mul, tr.low_constant)
        step_size = mul * state.step_size
        # the guard: a step within rounding noise of the cost is not a rejection
        within_noise = f_new - f_now <= self.noise * jnp.finfo(float).eps * jnp.abs(f_now)
        accept = accept | (within_noise & jnp.isfinite(f_new))
        step_size = jnp.maximum(step_size, self.floor)
        return step_size, accept, optx.RESULTS.successful, _TrustRegionState(step_size)


class TrustRegionSolver(optx.AbstractGaussNewton):
    """A Gauss-Newton-type solver: a `descent` (damped Newton for
    Levenberg-Marquardt, dogleg for Dogleg) under a `search` (here
    `SafeTrustRegion`), with optimistix's Cauchy termination (`rtol`, `atol`,
    `norm`). Built by [`make_solver`][]."""

    rtol: float
    atol: float
    norm: Callable[[Any], jax.Array]
    descent: optx.AbstractDescent
    search: optx.AbstractSearch
    verbose: Callable[..., None]


def make_solver(solver: str, rtol: float, atol: float):
    """The optimistix solver `solver` (one of `SOLVERS`); LM and Dogleg keep their
    stock descent, norm and verbosity and get the `SafeTrustRegion`."""
    if solver == "gauss_newton":
        return optx.GaussNewton(rtol=rtol, atol=atol)
    if solver == "lm":
        stock = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    elif solver == "dogleg":
        stock = optx.Dogleg(rtol=rtol, atol=atol)
    else:
        raise ValueError(f"unknown solver {solver!r}; expected one of {SOLVERS}")
    return TrustRegionSolver(
        rtol=stock.rtol,
        atol=stock.atol,
        norm=stock.norm,
        descent=stock.descent,
        search=SafeTrustRegion(optx.ClassicalTrustRegion()),
        verbose=stock.verbose,
    )

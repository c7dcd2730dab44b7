r"""General (robust) nonlinear least squares on optimistix, with a typed result.

[`least_squares`][] is the layer for people over the array-level core
[`solve_arrays`][] (`_core`): a pytree of parameters, input checks, a [`LsqResult`][]
that prints well, and `throw=True` raising
[`AnalysisError`][piecs_bayes.errors.AnalysisError] (carrying the result) on a failed
solve. [`flat_structure`][] gives the names and `unravel` of `p` flat parameters, made once.

The engine's modules, by topic: `_types` (the `Status` codes and the array result),
`_solver` (the optimistix solvers and their status mapping), `_core` (the staged robust
solve and its polishing), `_statistics` (covariance, outliers, the final status) and
`_result` (`LsqResult`); docs/models/least_squares.md.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ...errors import AnalysisError, InputError
from . import losses
from ._core import is_linear, solve_arrays
from ._options import SolverOptions
from ._result import LsqResult, param_names, result_from_arrays
from ._types import Status


def _traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _as_float_tree(y0):
    """`y0`'s leaves as float arrays: NumPy for values (an eager `jnp.asarray` compiles a
    program per shape), JAX for tracers."""

    def leaf(x):
        a = jnp.asarray(x) if _traced(x) else np.asarray(x)
        if not np.issubdtype(a.dtype, np.inexact):
            a = a.astype(float)
        return a

    return jax.tree_util.tree_map(leaf, y0)


def least_squares(
    fn: Callable,
    y0: Any,
    args: Any = None,
    *,
    weights=None,
    loss: str | Callable = "linear",
    scale: float | None = None,
    sigma: float | None = None,
    solver: SolverOptions = SolverOptions(),
    x_scale: None | str | Any = None,
    throw: bool = True,
) -> LsqResult:
    r"""Fit parameters `y` by (robust, weighted) nonlinear least squares.

    Minimises $\tfrac12\sum_i s^2\rho\big(w_i r_i^2/s^2\big)$ with
    $r = $ `fn(y, args)`; for the linear loss this is $\tfrac12\sum_i w_i r_i^2$.

    **Arguments:**

    - `fn`: `fn(y, args) -> (n,)` raw, unweighted residuals; `y` has the structure
      of `y0`. Pure JAX (it is traced and jitted once per shape).
    - `y0`: starting point, any pytree of float arrays or scalars (dicts and
      NamedTuples give good parameter names).
    - `args`: data passed to `fn` (any pytree).
    - `weights`: `(n,)` non-negative inverse-variance weights; zero excludes a point
      (it does not count in `n` or `dof`). Default: ones.
    - `loss`: `"linear" | "huber" | "soft_l1" | "cauchy" | "tukey"` or a callable
      `rho(z)`, `z` the squared scaled residual (SciPy's convention).
    - `scale`: loss scale $s$ in the units of $\sqrt{w}\,r$ (SciPy's `f_scale`).
      `None`: the loss's tuning constant times $1.4826\,\mathrm{MAD}$ of the
      residuals, re-estimated between robust stages.
    - `sigma`: known standard deviation of the weighted residuals (e.g. probe
      repeatability with unit weights). Given: covariance $\sigma^2(J^TWJ)^{-1}$;
      `None`: scaled by the residual variance.
    - `solver`: a [`SolverOptions`][]: the method (`"lm"`, Levenberg-Marquardt, by
      default; `"gauss_newton"` or `"dogleg"`), the tolerances `rtol`, `atol` and the
      step limit `max_steps` of each stage.
    - `x_scale`: parameter scaling for the solver: `None`, `"y0"`, `"jac"` or
      typical magnitudes (a scalar or a pytree like `y0`), see [`solve_arrays`][].
    - `throw`: raise [`AnalysisError`][piecs_bayes.errors.AnalysisError] with the
      status message on failure (the [`LsqResult`][] is its `result`); with
      `False` inspect `result.status`.

    **Returns:**

    A [`LsqResult`][].

    Raises `ValueError` (an [`InputError`][piecs_bayes.errors.InputError]) for an
    unknown `loss` or bad `weights`, `scale`, `sigma` (and `SolverOptions` for an
    unknown method or a bad `max_steps`).
    """
    # Over 80 lines only through its docstring (every argument documented); the
    # body is a short sequence of named steps.
    _check_settings(loss, scale, sigma)
    y0 = _as_float_tree(y0)
    y0_flat, unravel = ravel(y0)
    if y0_flat.size == 0:
        raise InputError("y0 has no parameters to fit")

    def flat_fn(y_flat, a):
        return jnp.asarray(fn(unravel(y_flat), a))

    out = jax.eval_shape(flat_fn, y0_flat, args)
    if len(out.shape) != 1:
        raise InputError(f"fn must return a 1-D residual array, got shape {out.shape}")
    weights = _checked_weights(weights, out.shape[0])
    x_scale = _checked_x_scale(x_scale, y0, y0_flat)
    arr = solve_arrays(
        _FlatFn(fn, unravel),
        y0_flat,
        args,
        weights,
        loss=loss,
        scale=scale,
        sigma=sigma,
        solver=solver,
        x_scale=x_scale,
    )
    arr = jax.tree_util.tree_map(np.asarray, arr)
    res = result_from_arrays(
        arr._asdict(),
        params=jax.tree_util.tree_map(np.asarray, unravel(np.asarray(arr.params_flat))),
        loss=(loss if isinstance(loss, str) else getattr(loss, "__name__", "custom")),
        robust=not is_linear(loss),
        names=param_names(y0),
        unravel=unravel,
    )
    if throw and res.status is not Status.SUCCESSFUL:
        raise AnalysisError(
            f"least-squares fit failed: {res.status.message} (after {res.steps} steps)",
            result=res,
        )
    return res


def _check_settings(loss, scale, sigma) -> None:
    if not (callable(loss) or (isinstance(loss, str) and loss in losses.LOSS_NAMES)):
        raise InputError(
            f"unknown loss {loss!r}; expected one of {losses.LOSS_NAMES} or a callable rho(z)"
        )
    for name, val in (("scale", scale), ("sigma", sigma)):
        if val is not None and not (np.ndim(val) == 0 and np.isfinite(val) and val > 0):
            raise InputError(f"{name} must be a positive finite number or None, got {val!r}")


def _checked_weights(weights, n: int):
    """`weights` as a `(n,)` array (ones when `None`: one compiled solve either way)."""
    if weights is None:
        return np.ones(n)
    if _traced(weights):
        return jnp.asarray(weights, dtype=float)
    w = np.asarray(weights, dtype=float)
    if w.shape != (n,):
        raise InputError(f"weights must have shape ({n},) like the residuals, got {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError("weights must be finite and non-negative")
    return w


def _checked_x_scale(x_scale, y0, y0_flat):
    """`x_scale` as `None`, `"y0"`, `"jac"` or a flat array like `y0_flat`."""
    if x_scale is not None and not isinstance(x_scale, str):
        if jax.tree_util.tree_structure(x_scale) == jax.tree_util.tree_structure(y0):
            x_scale = ravel(x_scale)[0]
        elif np.ndim(x_scale) == 0 or np.shape(x_scale) == y0_flat.shape:
            x_scale = np.asarray(x_scale, float)
        else:
            raise InputError("x_scale must be None, 'y0', 'jac', a scalar or a pytree like y0")
        if not bool(np.all(np.isfinite(x_scale) & (np.asarray(x_scale) > 0))):
            raise InputError("x_scale must be positive and finite")
    elif isinstance(x_scale, str) and x_scale not in ("y0", "jac"):
        raise InputError(f"unknown x_scale {x_scale!r}; expected None, 'y0', 'jac' or an array")
    return x_scale


@dataclasses.dataclass(frozen=True)
class _Unravel:
    """Hashable inverse of `ravel_pytree` (same order), so that repeated fits of one
    structure reuse the compiled solve."""

    treedef: Any
    shapes: tuple[tuple[int, ...], ...]

    def __call__(self, flat):
        xp = np if isinstance(flat, np.ndarray) else jnp  # NumPy in, NumPy out
        leaves, start = [], 0
        for shape in self.shapes:
            size = int(np.prod(shape, dtype=int))
            leaves.append(xp.reshape(flat[start : start + size], shape))
            start += size
        return jax.tree_util.tree_unflatten(self.treedef, leaves)


def ravel(tree):
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    xp = jnp if any(_traced(x) for x in leaves) else np  # values: NumPy, no program
    flat = xp.concatenate([xp.ravel(xp.asarray(x, float)) for x in leaves])
    return flat, _Unravel(treedef, tuple(tuple(np.shape(x)) for x in leaves))


@functools.lru_cache(maxsize=8)
def flat_structure(p: int):
    """Names and `unravel` of `p` flat parameters (as `least_squares` makes them from
    its start `jnp.zeros(p)`), made once, without JAX operations: `ravel`'s would
    compile two small programs in every process."""
    y0 = np.zeros(p)
    leaves, treedef = jax.tree_util.tree_flatten(y0)
    return param_names(y0), _Unravel(treedef, tuple(tuple(np.shape(x)) for x in leaves))


@dataclasses.dataclass(frozen=True)
class _FlatFn:
    """`fn` on flat parameters; hashable by `fn` and structure, so that two calls with
    the same `fn` and structure are one static argument of `filter_jit` and share one
    compiled solve (no array leaves: the whole object is static)."""

    fn: Callable
    unravel: Callable

    def __call__(self, y_flat, args):
        return jnp.asarray(self.fn(self.unravel(y_flat), args))

r"""The array-level least-squares solve, [`solve_arrays`][]: flat parameters in, an
[`LsqArrays`][] out, status as an integer code (it never raises on a failed solve). It is
jit-, `vmap`- and `jacfwd`-friendly: batch many independent problems of one shape with
`jax.vmap`, and differentiate the fitted parameters with respect to the data (`args`)
through optimistix's implicit adjoint.

The objective is $\tfrac12\sum_i s^2\rho\big((\sqrt{w_i}\,r_i/s)^2\big)$ with $r_i$ the
raw residuals from `fn`, $w_i \ge 0$ the weights (inverse variances; zero excludes a
point) and $\rho$ a loss in SciPy's convention (`losses`). A robust loss is solved in
stages (plain, then Huber, then the loss; [`stages`][]), re-estimating the scale between
them when it is not given; up to `POLISH_STEPS` Gauss-Newton steps then take the
solution to full precision. The result's statistics and final status are
[`statistics`][]'s (`_statistics`).

The staged solve: docs/models/least_squares.md.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import losses
from ._options import SolverOptions
from ._statistics import FinalLoss, analyse, statistics
from ._types import LsqArrays

#: rounds (scale, fit) of the Huber and of the final stages of a robust fit
SCALE_ROUNDS = (5, 3)
#: Gauss-Newton polishing steps after the solver.
POLISH_STEPS = 3


def is_linear(loss) -> bool:
    return losses.loss_id(loss) == 0


def stages(loss) -> tuple[np.ndarray, np.ndarray]:
    """Loss index and tuning constant of each stage: plain, Huber, then the loss.

    The Huber and the final stages are repeated (`SCALE_ROUNDS`); with an estimated
    scale, it is re-estimated before each, so that scale and fit reach their joint
    fixed point (a first scale from a fit pulled by the outliers is far too large).
    With a given scale the repeats converge at once. The list is the same for every
    robust loss, given scale or not, so they all share one compiled solve."""
    idx = losses.loss_id(loss)
    c = losses.TUNING[losses.LOSS_NAMES[idx]] if idx < losses.CUSTOM else 1.0
    huber = losses.LOSS_NAMES.index("huber")
    k_huber, k_final = SCALE_ROUNDS
    ids = [0] + [huber] * k_huber + [idx] * k_final
    cs = [1.0] + [losses.TUNING["huber"]] * k_huber + [c] * k_final
    return np.asarray(ids, dtype=np.int32), np.asarray(cs, dtype=float)


def solve_arrays(
    fn: Callable,
    y0_flat,
    args: Any = None,
    weights=None,
    *,
    loss: str | Callable = "linear",
    scale=None,
    sigma=None,
    solver: SolverOptions = SolverOptions(),
    x_scale: None | str | Any = None,
) -> LsqArrays:
    r"""Array-level core of [`least_squares`][]: never raises on a failed solve.

    **Arguments:**

    - `fn`: `fn(y_flat, args) -> (n,)` raw residuals, `y_flat` a 1-D float array.
    - `y0_flat`: `(p,)` starting point.
    - `args`: pytree passed to `fn`; it may be batched by `jax.vmap` and
      differentiated (`jax.jacfwd`) through the implicit function theorem.
    - `weights`: `(n,)` non-negative inverse-variance weights, `None` for ones.
      Zero excludes a point (padding); such points must still give finite residuals
      or they are masked to zero.
    - `loss`, `scale`, `sigma`, `solver`: as in [`least_squares`][]; `scale` and
      `sigma` may be traced arrays.
    - `x_scale`: parameter scaling for the solver (it solves for $z = y/x$):
      `None` (no rescaling, the default and usually best), `"y0"` (typical
      magnitudes $|y_0|$, 1 where $y_0 = 0$), `"jac"` ($1/$column norms of the
      weighted Jacobian at `y0`, like MINPACK's initial diagonal) or an array of
      typical magnitudes. Rescaling changes the Levenberg-Marquardt path, not the
      minimum; try it when parameters differ by orders of magnitude and the plain
      solve runs out of steps.

    **Returns:**

    An [`LsqArrays`][] of arrays; `status_code` holds a [`Status`][] value.
    """
    ids, cs = (None, None) if is_linear(loss) else stages(loss)
    y0_flat = _host(y0_flat)
    p = y0_flat.shape[0]
    xp = jnp if isinstance(y0_flat, jax.core.Tracer) else np
    # None -> arrays (NaN = "not given"), so that every variant shares one compile
    if x_scale is None:
        x_scale = np.ones(p)
    elif isinstance(x_scale, str):
        if x_scale == "y0":
            x_scale = xp.where(y0_flat != 0, xp.abs(y0_flat), 1.0)
        elif x_scale != "jac":
            raise ValueError(f"unknown x_scale {x_scale!r}; expected None, 'y0', 'jac' or an array")
    else:
        x_scale = _host(x_scale)
        x_scale = (jnp if isinstance(x_scale, jax.core.Tracer) else np).broadcast_to(x_scale, (p,))
    # strongly typed float64 scalars: a weak-typed NaN would be another compile
    nan = np.asarray(np.nan, dtype=np.float64)
    return _solve_core(
        fn,
        y0_flat,
        args,
        None if weights is None else _host(weights),
        None if ids is None else (ids, cs),
        nan if scale is None else _host(scale),
        nan if sigma is None else _host(sigma),
        loss if callable(loss) else None,
        solver,
        x_scale,
    )


def _host(x):
    """`x` as float64: NumPy where it is a value (the solve takes NumPy as it takes
    JAX arrays; an eager `jnp.asarray` compiles a program per shape), JAX where it is
    traced (the solve inside `vmap`, `jacfwd` or another jit)."""
    if isinstance(x, jax.core.Tracer):
        return jnp.asarray(x, dtype=jnp.float64)
    return np.asarray(x, dtype=np.float64)


def _lazy_filter_jit(fn):
    """`equinox.filter_jit(fn)`, made on the first call: equinox (~0.1 s to import)
    is loaded only by runs that use the engine, never by the batch kernel's (the CLI's
    fit). A race on the first call makes two equal wrappers; either serves."""
    jitted = None

    @functools.wraps(fn)
    def call(*args, **kwargs):
        nonlocal jitted
        if jitted is None:
            import equinox as eqx

            jitted = eqx.filter_jit(fn)
        return jitted(*args, **kwargs)

    return call


@_lazy_filter_jit
def _solve_core(fn, y0, args, weights, staged, scale, sigma, custom, solver, x_scale):
    """The solve of `solve_arrays`: `staged` is `None` for the linear loss, else the
    stages' loss indices and tuning constants (`stages`); `solver` the
    `SolverOptions` (static: one compile per solver and tolerances)."""
    p = y0.shape[0]
    n = jax.eval_shape(fn, y0, args).shape[0]
    w = jnp.ones(n) if weights is None else jnp.asarray(weights, dtype=float)
    mask = w > 0
    wsqrt = jnp.sqrt(jnp.where(mask, w, 0.0))
    # optimistix on first use: the batch kernel (the CLI's fit) never needs it
    from ._solver import make_solver

    optx_solver = make_solver(solver.method, float(solver.rtol), float(solver.atol))

    def weighted(y, a):
        r = fn(y, a)
        return jnp.where(mask, wsqrt * r, 0.0)

    stage_ids, stage_cs = (None, None) if staged is None else staged
    final = FinalLoss(
        idx=None if staged is None else stage_ids[-1],
        tuning=None if staged is None else stage_cs[-1],
        custom=custom,
        robust=staged is not None,
    )
    xs = _parameter_scale(weighted, y0, args, x_scale)
    z, code, steps, s_final = _staged_solve(
        weighted, xs, y0, args, staged, scale, mask, custom, optx_solver, int(solver.max_steps)
    )
    dof_f = jnp.maximum(jnp.sum(mask) - p, 1).astype(float)
    g_final = _final_residuals(weighted, stage_ids, s_final, final.idx, custom)

    def analyse_at(y):
        return analyse(fn, args, y, mask, wsqrt, s_final, final)

    y, info = _polish(analyse_at, g_final, args, z * xs, dof_f)
    return statistics(info, y, code, steps, s_final, mask, w, sigma, final, float(solver.atol))


def _parameter_scale(weighted, y0, args, x_scale):
    """The solver's parameter scale `xs` (it solves for `z = y / xs`)."""
    if isinstance(x_scale, str):  # "jac"
        d = jnp.linalg.norm(jax.jacfwd(weighted)(y0, args), axis=0)
        d = jnp.where(jnp.isfinite(d) & (d > 0), d, 1.0)
        return jax.lax.stop_gradient(1.0 / d)
    xs = jnp.abs(x_scale)
    return jnp.where(jnp.isfinite(xs) & (xs > 0), xs, 1.0)


def _staged_solve(weighted, xs, y0, args, staged, scale, mask, custom, solver, max_steps):
    """The optimistix solve of every stage (one for the linear loss: `staged` None,
    else the stages' loss indices and tuning constants), each started at the
    previous one's solution: the scaled solution `z`, the last stage's `Status`
    code, the steps of all stages and the last stage's loss scale."""

    def wrapped(z, a):
        user_args, s, idx = a
        e = weighted(z * xs, user_args)
        if idx is None:
            return e
        ratio = losses.rho_over_z(idx, (e / s) ** 2, custom)
        return e * jnp.sqrt(ratio)

    def solve(z_start, s, idx):
        import optimistix as optx

        from ._solver import status_code

        sol = optx.least_squares(
            wrapped, solver, z_start, (args, s, idx), max_steps=max_steps, throw=False
        )
        return sol.value, status_code(sol.result), sol.stats["num_steps"]

    if staged is None:
        z, code, steps = solve(y0 / xs, None, None)
        return z, code, steps, jnp.asarray(jnp.nan)

    def stage(carry, stage_in):
        z, _, steps = carry
        idx, c = stage_in
        e = weighted(z * xs, args)
        s = jnp.where(jnp.isnan(scale), c * losses.mad_sigma(e, mask), scale)
        s = jnp.where(idx == 0, 1.0, s)
        z, code, more = solve(z, s, idx)
        return (z, code, steps + more), s

    init = (y0 / xs, jnp.asarray(0, jnp.int32), jnp.asarray(0))
    (z, code, steps), s_all = jax.lax.scan(stage, init, staged)
    return z, code, steps, s_all[-1]


def _final_residuals(weighted, stage_ids, s, idx, custom):
    """Residuals actually minimised in the last stage, as a function of `(y, args)`."""

    def g(y, a):
        e = weighted(y, a)
        if stage_ids is None:
            return e
        return e * jnp.sqrt(losses.rho_over_z(idx, (e / s) ** 2, custom))

    return g


def _polish(analyse_at, g_final, args, y, dof_f):
    """`POLISH_STEPS` Gauss-Newton steps from the solver's solution `y`, and
    `analyse_at`'s `info` at the final point."""

    def polish(k, carry):
        """Steps after the solver: they take a solution that the solver's Cauchy test
        stopped at ~1e-7 relative to full precision. A step is kept when it does not
        raise the cost by more than 1e-12 relative, or moves every parameter by less
        than 1e-2 (rough) standard errors: near the minimum the change of the cost is
        below the rounding noise of its sum. The last pass only analyses, so that
        `info` describes the final point."""
        y, _ = carry
        info = analyse_at(y)
        # the step carries no derivative: the solver's implicit adjoint is exact
        y_try = y + jax.lax.stop_gradient(info["delta"])
        g_try = g_final(y_try, args)
        c_try = 0.5 * jnp.sum(g_try * g_try)
        se = jnp.sqrt(2.0 * info["cost"] / dof_f * jnp.sum(info["v_scaled"] ** 2, axis=1))
        small = jnp.all(jnp.abs(info["delta"]) <= 1e-2 * se)
        ok = (
            (k < POLISH_STEPS)
            & jnp.all(jnp.isfinite(y_try))
            & jnp.isfinite(c_try)
            & ((c_try <= info["cost"] * (1 + 1e-12)) | small)
        )
        return jnp.where(ok, y_try, y), info

    shapes = jax.eval_shape(analyse_at, y)
    info0 = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes)
    return jax.lax.fori_loop(0, POLISH_STEPS + 1, polish, (y, info0))

r"""General (robust) nonlinear least squares on optimistix, with a typed result.

Two layers:

- [`solve_arrays`][] is the pure array-level core: flat parameters in, a
  `NamedTuple` of arrays out, status as an integer code. It is jit-, `vmap`- and
  `jacfwd`-friendly: batch many independent problems of one shape with
  `jax.vmap`, and differentiate the fitted parameters with respect to the data
  (`args`) through optimistix's implicit adjoint.
- [`least_squares`][] wraps it for people: a pytree of parameters, input checks,
  a [`LsqResult`][] that prints well, and `throw=True` raising
  [`AnalysisError`][piecs_bayes.errors.AnalysisError] on a failed solve.

The objective is $\tfrac12\sum_i s^2\rho\big((\sqrt{w_i}\,r_i/s)^2\big)$ with
$r_i$ the raw residuals from `fn`, $w_i \ge 0$ the weights (inverse variances; zero
excludes a point) and $\rho$ a loss in SciPy's convention (see `_robust.py`).
A robust loss is solved by wrapping the residuals,
$g_i = e_i\sqrt{\rho(z_i)/z_i}$, $z_i=(e_i/s)^2$, so that the plain
Gauss-Newton machinery minimises the robust objective exactly.

Robust stages: a plain fit first, then `SCALE_ROUNDS` Huber fits (convex, so they
give a good start for the redescending Cauchy and Tukey losses), then the requested
loss, also repeated. When the scale is estimated (`scale=None`) it is re-estimated
from the previous stage's residuals before each robust stage, so that scale and fit
reach their joint fixed point; a given scale is used throughout.

After the solver, up to `POLISH_STEPS` Gauss-Newton steps (kept only when they do
not raise the cost beyond rounding noise) take the solution from the solver's
Cauchy tolerance to full precision, and a solution is reported as SUCCESSFUL only
if the step left is negligible (`STATIONARY_RTOL`): a solver that merely stopped
moving is reported as STALLED, never as an answer.

Covariance, with $J_w = \mathrm{diag}(\sqrt{w})J$, $e_i=\sqrt{w_i}\,r_i$,
$W_i=\rho'(z_i)$ the robust (IRLS) weights and $\psi(u)=u\rho'(u^2)$:

- linear loss: $\sigma^2 (J_w^TJ_w)^{-1}$ with `sigma` given, else
  $s^2 (J_w^TJ_w)^{-1}$, $s^2 = \mathrm{RSS}/\mathrm{dof}$;
- robust loss, `sigma=None`: Huber's (1981, sec. 7.6) estimate
  $K^2\,\dfrac{\sum_i (W_i e_i)^2/\mathrm{dof}}{\overline{\psi'}^{\,2}}
  (J_w^TJ_w)^{-1}$, $K = 1 + \tfrac{p}{n}\mathrm{var}(\psi')/\overline{\psi'}^2$
  (calibrated in simulation: 3-sigma coverage 98-99 % with 10-25 % gross outliers);
- robust loss, `sigma` given: weighted least squares with the final weights held
  fixed, $\sigma^2 A^{-1}(J_w^T W^2 J_w)A^{-1}$, $A = J_w^T W J_w$ (1-3 % optimistic
  in the standard error for the 95 %-efficient tunings at the normal).

A point is flagged as an outlier when its robust weight is below the weight the
loss gives to a residual of three robust standard deviations ($3s/c$, $c$ the
loss's tuning constant).
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..errors import AnalysisError, InputError
from . import _robust

__all__ = ["LsqArrays", "LsqResult", "Status", "least_squares", "solve_arrays", "SOLVERS"]

SOLVERS = ("lm", "gauss_newton", "dogleg")
#: condition number (of the column-scaled weighted Jacobian) above which the
#: covariance is flagged as not accurate: its relative error is ~ eps * cond^2.
COND_ACCURATE = 1e6
#: rounds (scale, fit) of the Huber and of the final stages of a robust fit
SCALE_ROUNDS = (5, 3)
#: Gauss-Newton polishing steps after the solver.
POLISH_STEPS = 3
#: a solution is stationary when the Gauss-Newton step left is below this times
#: max(|parameter|, standard error) (+ 10 atol) for every parameter.
STATIONARY_RTOL = 1e-3


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

_OPTX_TO_STATUS = {
    "successful": Status.SUCCESSFUL,
    "nonlinear_max_steps_reached": Status.MAX_STEPS_REACHED,
    "nonlinear_divergence": Status.DIVERGED,
    "nonfinite": Status.NONFINITE,
    "nonfinite_input": Status.NONFINITE,
    "singular": Status.SINGULAR,
}


def _status_table() -> np.ndarray:
    items = optx.RESULTS._name_to_item  # name -> EnumerationItem
    size = 1 + max(int(item._value) for item in items.values())
    table = np.full(size, int(Status.LINEAR_SOLVE_FAILED), dtype=np.int32)
    for name, item in items.items():
        table[int(item._value)] = int(_OPTX_TO_STATUS.get(name, Status.LINEAR_SOLVE_FAILED))
    return table


_STATUS_TABLE = _status_table()

# covariance codes (LsqArrays.covariance_code)
_COV_OK, _COV_DOF, _COV_SINGULAR, _COV_NONFINITE, _COV_ROBUST = 0, 1, 2, 3, 4
_COV_REASONS = {
    _COV_DOF: "no degrees of freedom left to estimate the residual variance (dof <= 0); give sigma",
    _COV_SINGULAR: "the weighted Jacobian is singular at the solution "
    "(parameters not identifiable from these points)",
    _COV_NONFINITE: "non-finite Jacobian or residuals at the solution",
    _COV_ROBUST: "the robust fit gave (nearly) every point zero weight",
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


def _final_residuals(weighted, stage_ids, s, idx, custom):
    """Residuals actually minimised in the last stage, as a function of `(y, args)`."""

    def g(y, a):
        e = weighted(y, a)
        if stage_ids is None:
            return e
        return e * jnp.sqrt(_robust.rho_over_z(idx, (e / s) ** 2, custom))

    return g


class _SafeTrustRegion(optx.AbstractSearch):
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
    """

    inner: optx.ClassicalTrustRegion
    floor: float = 1e-30
    noise: float = 16.0

    def init(self, y, f_info_struct):
        return self.inner.init(y, f_info_struct)

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        step_size, accept, result, state = self.inner.step(
            first_step, y, y_eval, f_info, f_eval_info, state
        )
        f_now = f_info.as_min()
        f_new = f_eval_info.as_min()
        within_noise = f_new - f_now <= self.noise * jnp.finfo(float).eps * jnp.abs(f_now)
        accept = accept | (within_noise & jnp.isfinite(f_new))
        step_size = jnp.maximum(step_size, self.floor)
        state = eqx.tree_at(lambda st: st.step_size, state, step_size)
        return step_size, accept, result, state


def _make_solver(solver: str, rtol: float, atol: float):
    """The optimistix solver; LM and Dogleg get the `_SafeTrustRegion`."""
    if solver == "gauss_newton":
        return optx.GaussNewton(rtol=rtol, atol=atol)
    if solver == "lm":
        base = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    elif solver == "dogleg":
        base = optx.Dogleg(rtol=rtol, atol=atol)
    else:
        raise ValueError(f"unknown solver {solver!r}; expected one of {SOLVERS}")
    search = _SafeTrustRegion(optx.ClassicalTrustRegion())
    return eqx.tree_at(lambda s: s.search, base, search)


def _stages(loss) -> tuple[np.ndarray, np.ndarray]:
    """Loss index and tuning constant of each stage: plain, Huber, then the loss.

    The Huber and the final stages are repeated (`SCALE_ROUNDS`); with an estimated
    scale, it is re-estimated before each, so that scale and fit reach their joint
    fixed point (a first scale from a fit pulled by the outliers is far too large).
    With a given scale the repeats converge at once. The list is the same for every
    robust loss, given scale or not, so they all share one compiled solve."""
    idx = _robust.loss_id(loss)
    c = _robust.TUNING[_robust.LOSS_NAMES[idx]] if idx < _robust.CUSTOM else 1.0
    huber = _robust.LOSS_NAMES.index("huber")
    k_huber, k_final = SCALE_ROUNDS
    ids = [0] + [huber] * k_huber + [idx] * k_final
    cs = [1.0] + [_robust.TUNING["huber"]] * k_huber + [c] * k_final
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
    solver: str = "lm",
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 1000,
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
    - `loss`, `scale`, `sigma`, `solver`, `rtol`, `atol`, `max_steps`: as in
      [`least_squares`][]; `scale` and `sigma` may be traced arrays.
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
    ids, cs = (None, None) if _is_linear(loss) else _stages(loss)
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; expected one of {SOLVERS}")
    y0_flat = jnp.asarray(y0_flat, dtype=float)
    p = y0_flat.shape[0]
    # None -> arrays (NaN = "not given"), so that every variant shares one compile
    if x_scale is None:
        x_scale = jnp.ones(p)
    elif isinstance(x_scale, str):
        if x_scale == "y0":
            x_scale = jnp.where(y0_flat != 0, jnp.abs(y0_flat), 1.0)
        elif x_scale != "jac":
            raise ValueError(f"unknown x_scale {x_scale!r}; expected None, 'y0', 'jac' or an array")
    else:
        x_scale = jnp.broadcast_to(jnp.asarray(x_scale, float), (p,))
    # strongly typed float64 scalars: a weak-typed NaN would be another compile
    nan = jnp.asarray(np.nan, dtype=jnp.float64)
    return _solve_core(
        fn,
        y0_flat,
        args,
        None if weights is None else jnp.asarray(weights, dtype=float),
        None if ids is None else jnp.asarray(ids),
        None if cs is None else jnp.asarray(cs),
        nan if scale is None else jnp.asarray(scale, dtype=jnp.float64),
        nan if sigma is None else jnp.asarray(sigma, dtype=jnp.float64),
        loss if callable(loss) else None,
        solver,
        float(rtol),
        float(atol),
        int(max_steps),
        x_scale,
        None if cs is None else jnp.asarray(cs[-1]),
        None if ids is None else jnp.asarray(ids[-1]),
    )


def _is_linear(loss) -> bool:
    return _robust.loss_id(loss) == 0


def _analyse(fn, args, y, mask, wsqrt, s_final, final_id, custom, robust):
    """Residuals, Jacobian, robust weights and the SVD of the column-scaled
    weighted Jacobian at `y`, and the step `-(J_w^T J_w)^-1 J_w^T W e` (the
    Gauss-Newton step for the linear loss; zero exactly where the gradient
    `J_w^T W e` of the robust objective is zero)."""
    n, p = mask.shape[0], y.shape[0]
    eps = jnp.finfo(float).eps
    r = fn(y, args)
    jac = jax.jacfwd(fn)(y, args)
    e = jnp.where(mask, wsqrt * r, 0.0)
    jw = jnp.where(mask[:, None], wsqrt[:, None] * jac, 0.0)
    if robust:
        zz = (e / s_final) ** 2
        rw = jnp.where(mask, _robust.rho_prime(final_id, zz, custom), 0.0)
        cost = 0.5 * jnp.sum(e * e * _robust.rho_over_z(final_id, zz, custom))
    else:
        rw = mask.astype(float)
        cost = 0.5 * jnp.sum(e * e)
    colnorm = jnp.linalg.norm(jw, axis=0)
    colnorm_safe = jnp.where(colnorm > 0, colnorm, 1.0)
    finite = jnp.all(jnp.isfinite(jw)) & jnp.all(jnp.isfinite(e))
    b = jnp.where(finite, jw / colnorm_safe, 0.0)
    u_mat, sv, vt = jnp.linalg.svd(b, full_matrices=False)
    keep = sv > sv[0] * max(n, p) * eps
    sinv = jnp.where(keep, 1.0 / jnp.where(keep, sv, 1.0), 0.0)
    v_scaled = vt.T * sinv / colnorm_safe[:, None]  # (J_w^T J_w)^+ = v v^T
    delta = -v_scaled @ (u_mat.T @ jnp.where(finite, rw * e, 0.0))
    info = dict(r=r, jac=jac, e=e, jw=jw, rw=rw, cost=cost, colnorm=colnorm, b=b)
    info.update(sv=sv, keep=keep, v_scaled=v_scaled, delta=delta, finite=finite)
    return info


def _statistics(
    info, y, code, steps, s_final, mask, w, sigma, final_id, tuning, custom, robust, atol
):
    """The result at the solution `y` from `_analyse`'s `info`: outliers, covariance
    (linear or Huber's robust sandwich, or from a known `sigma`) with its code,
    residual SD, and the final status (non-finite, degenerate, stalled). Shared by
    `_solve_core` and the batch kernel, so both report the same numbers."""
    n, p = mask.shape[0], y.shape[0]
    eps = jnp.finfo(float).eps
    n_used = jnp.sum(mask).astype(jnp.int32)
    dof = n_used - p
    dof_f = jnp.maximum(dof, 1).astype(float)
    n_f = jnp.maximum(n_used, 1).astype(float)
    r, jac, e, jw, rw = (info[k] for k in ("r", "jac", "e", "jw", "rw"))
    cost, finite, keep, sv = info["cost"], info["finite"], info["keep"], info["sv"]
    v_scaled, colnorm = info["v_scaled"], info["colnorm"]
    rss = jnp.sum(e * e)
    if robust:
        dpsi = _robust.psi_prime(final_id, e / s_final, custom)
        w3 = _robust.rho_prime(final_id, jnp.asarray((3.0 / tuning) ** 2), custom)
        outlier = mask & (rw < w3)
    else:
        outlier = jnp.zeros(n, dtype=bool)

    singular = ~keep[-1] | jnp.any(colnorm == 0)
    cond = jnp.where(singular, jnp.inf, sv[0] / jnp.where(sv[-1] > 0, sv[-1], 1.0))
    a_inv = v_scaled @ v_scaled.T  # (J_w^T J_w)^-1
    robust_ok = jnp.asarray(True)
    sigma_given = jnp.isfinite(sigma)
    if not robust:
        factor = jnp.where(sigma_given, sigma**2, rss / dof_f)
    else:
        # Huber (1981, sec. 7.6): K^2 [sum psi^2/dof] / [mean psi']^2 (J^T J)^-1
        mean_dpsi = jnp.sum(jnp.where(mask, dpsi, 0.0)) / n_f
        var_dpsi = jnp.sum(jnp.where(mask, (dpsi - mean_dpsi) ** 2, 0.0)) / n_f
        safe_mean = jnp.where(mean_dpsi > 0, mean_dpsi, 1.0)
        k_corr = 1.0 + p / n_f * var_dpsi / safe_mean**2
        tau2 = jnp.sum((rw * e) ** 2) / dof_f
        factor = k_corr**2 * tau2 / safe_mean**2
        # fewer effective points than parameters: (nearly) everything rejected
        robust_ok = (mean_dpsi > 0) & (jnp.sum(rw) >= p + 1)
    cov = factor * a_inv
    if robust:
        # known sigma: weighted least squares with the final weights held fixed,
        # sigma^2 (J^T W J)^-1 (J^T W^2 J) (J^T W J)^-1
        bw = jnp.sqrt(rw)[:, None] * info["b"]
        _, sv_w, vt_w = jnp.linalg.svd(bw, full_matrices=False)
        keep_w = sv_w > sv_w[0] * max(n, p) * eps
        singular = singular | (sigma_given & ~keep_w[-1])
        inv_w = jnp.where(keep_w, 1.0 / jnp.where(keep_w, sv_w, 1.0), 0.0)
        vw = vt_w.T * inv_w / jnp.where(colnorm > 0, colnorm, 1.0)[:, None]
        aw_inv = vw @ vw.T
        meat = jw.T @ ((rw**2)[:, None] * jw)
        cov = jnp.where(sigma_given, sigma**2 * aw_inv @ meat @ aw_inv, cov)
    cov = 0.5 * (cov + cov.T)
    cov_code = jnp.where(
        ~finite,
        _COV_NONFINITE,
        jnp.where(
            singular,
            _COV_SINGULAR,
            jnp.where(
                (dof <= 0) & ~sigma_given,
                _COV_DOF,
                jnp.where(robust_ok, _COV_OK, _COV_ROBUST),
            ),
        ),
    ).astype(jnp.int32)
    cov = jnp.where(cov_code == _COV_OK, cov, jnp.nan)

    if robust:
        # reported, not used as a scale: an exact fit reports 0, never a placeholder
        resid_sd = _robust.mad_sigma(e, mask, fallback=False)
    else:
        resid_sd = jnp.where(dof > 0, jnp.sqrt(rss / dof_f), jnp.nan)
    all_finite = jnp.all(jnp.isfinite(y)) & jnp.all(jnp.isfinite(e))
    code = jnp.where(all_finite, code, int(Status.NONFINITE))
    code = jnp.where((code == Status.SUCCESSFUL) & ~robust_ok, int(Status.DEGENERATE), code)
    # never report a non-stationary point as a success: the step left (see
    # `_analyse`) must be negligible against the parameter and its standard error
    se = jnp.sqrt(jnp.where(cov_code == _COV_OK, jnp.abs(jnp.diagonal(cov)), 0.0))
    tol = STATIONARY_RTOL * jnp.maximum(jnp.abs(y), se) + 10.0 * atol
    stalled = ~jnp.all(jnp.abs(info["delta"]) <= tol)
    code = jnp.where((code == Status.SUCCESSFUL) & stalled, int(Status.STALLED), code)
    code = code.astype(jnp.int32)
    return LsqArrays(
        params_flat=y,
        status_code=code,
        residuals=r,
        weights=w * rw,
        robust_weights=rw,
        outlier=outlier,
        covariance=cov,
        covariance_code=cov_code,
        condition=cond,
        jacobian=jac,
        rss=rss,
        cost=cost,
        n_used=n_used,
        dof=dof,
        residual_sd=resid_sd,
        scale=s_final,
        steps=jnp.asarray(steps, dtype=jnp.int32),
    )


@eqx.filter_jit
def _solve_core(
    fn,
    y0,
    args,
    weights,
    stage_ids,
    stage_cs,
    scale,
    sigma,
    custom,
    solver_name,
    rtol,
    atol,
    max_steps,
    x_scale,
    tuning,
    final_id,
):
    p = y0.shape[0]
    n = jax.eval_shape(fn, y0, args).shape[0]
    w = jnp.ones(n) if weights is None else jnp.asarray(weights, dtype=float)
    mask = w > 0
    wsqrt = jnp.sqrt(jnp.where(mask, w, 0.0))
    solver = _make_solver(solver_name, rtol, atol)

    def weighted(y, a):
        r = fn(y, a)
        return jnp.where(mask, wsqrt * r, 0.0)

    # parameter scaling: y = xs * z
    if isinstance(x_scale, str):  # "jac"
        d = jnp.linalg.norm(jax.jacfwd(weighted)(y0, args), axis=0)
        d = jnp.where(jnp.isfinite(d) & (d > 0), d, 1.0)
        xs = jax.lax.stop_gradient(1.0 / d)
    else:
        xs = jnp.abs(x_scale)
        xs = jnp.where(jnp.isfinite(xs) & (xs > 0), xs, 1.0)

    def wrapped(z, a):
        user_args, s, idx = a
        e = weighted(z * xs, user_args)
        if idx is None:
            return e
        ratio = _robust.rho_over_z(idx, (e / s) ** 2, custom)
        return e * jnp.sqrt(ratio)

    def solve(z_start, s, idx):
        sol = optx.least_squares(
            wrapped, solver, z_start, (args, s, idx), max_steps=max_steps, throw=False
        )
        code = jnp.asarray(_STATUS_TABLE)[sol.result._value]
        return sol.value, code, sol.stats["num_steps"]

    if stage_ids is None:
        z, code, steps = solve(y0 / xs, None, None)
        s_final = jnp.asarray(jnp.nan)
    else:

        def stage(carry, stage_in):
            z, _, steps = carry
            idx, c = stage_in
            e = weighted(z * xs, args)
            s = jnp.where(jnp.isnan(scale), c * _robust.mad_sigma(e, mask), scale)
            s = jnp.where(idx == 0, 1.0, s)
            z, code, more = solve(z, s, idx)
            return (z, code, steps + more), s

        init = (y0 / xs, jnp.asarray(0, jnp.int32), jnp.asarray(0))
        (z, code, steps), s_all = jax.lax.scan(stage, init, (stage_ids, stage_cs))
        s_final = s_all[-1]

    dof_f = jnp.maximum(jnp.sum(mask) - p, 1).astype(float)
    robust = stage_ids is not None
    g_final = _final_residuals(weighted, stage_ids, s_final, final_id, custom)

    def analyse(y):
        return _analyse(fn, args, y, mask, wsqrt, s_final, final_id, custom, robust)

    def polish(k, carry):
        """Steps after the solver: they take a solution that the solver's Cauchy test
        stopped at ~1e-7 relative to full precision. A step is kept when it does not
        raise the cost by more than 1e-12 relative, or moves every parameter by less
        than 1e-2 (rough) standard errors: near the minimum the change of the cost is
        below the rounding noise of its sum. The last pass only analyses, so that
        `info` describes the final point."""
        y, _ = carry
        info = analyse(y)
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

    y = z * xs
    shapes = jax.eval_shape(analyse, y)
    info0 = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes)
    y, info = jax.lax.fori_loop(0, POLISH_STEPS + 1, polish, (y, info0))
    return _statistics(
        info, y, code, steps, s_final, mask, w, sigma, final_id, tuning, custom, robust, atol
    )


# --------------------------------------------------------------------------- #
# The user-facing layer: pytrees, checks, a result that prints well.


def _key_name(k) -> str:
    tu = jax.tree_util
    if isinstance(k, tu.DictKey):
        return str(k.key)
    if isinstance(k, tu.GetAttrKey):
        return k.name
    if isinstance(k, tu.SequenceKey):
        return str(k.idx)
    if isinstance(k, tu.FlattenedIndexKey):
        return str(k.key)
    return str(k)


def _param_names(y0) -> tuple[str, ...]:
    """Names of the flat parameters, in `ravel_pytree` order."""
    leaves, _ = jax.tree_util.tree_flatten_with_path(y0)
    names: list[str] = []
    for path, leaf in leaves:
        base = ".".join(_key_name(k) for k in path) or "y"
        size = int(np.size(leaf))
        if np.ndim(leaf) == 0:
            names.append(base)
        else:
            names += [f"{base}[{','.join(map(str, ix))}]" for ix in np.ndindex(np.shape(leaf))][
                :size
            ]
    return tuple(names)


@dataclasses.dataclass(frozen=True, eq=False)
class LsqResult:
    """Result of [`least_squares`][]. Immutable; arrays are NumPy.

    **Attributes:**

    - `params`: fitted parameters, a pytree like `y0`.
    - `status`: a [`Status`][]; `message` is its text.
    - `residuals`: raw (unweighted) residuals at the solution, `(n,)`.
    - `weights`: effective weights, user weight times robust weight, `(n,)`.
    - `robust_weights`: $\\rho'(z_i)$ of the final stage (ones for the linear loss).
    - `rss`: $\\sum_i w_i r_i^2$ at the solution. `cost`: the minimised objective.
    - `n`: points with non-zero weight. `dof`: `n - p`.
    - `residual_sd`: $\\sqrt{\\mathrm{RSS}/\\mathrm{dof}}$ (linear loss) or
      $1.4826\\,\\mathrm{MAD}$ of the weighted residuals (robust losses).
    - `covariance`: `(p, p)` in `ravel_pytree` order (see `param_names`), or `None`
      with the reason in `covariance_reason`.
    - `param_names`: names of the flat parameters, from the pytree keys.
    - `jacobian`: `(n, p)` Jacobian of the raw residuals at the solution.
    - `steps`: solver steps (all stages together).
    - `loss`, `scale`: the loss and the scale used (`nan` for the linear loss).
    - `condition_number`: of the column-scaled weighted Jacobian.
    - `outliers`: indices of the flagged points; `outlier_weights`: their robust
      weights.

    Properties: `converged`, `covariance_accurate`, `std_errors` (pytree like
    `y0`), `correlation`.
    """

    params: Any
    status: Status
    residuals: np.ndarray
    weights: np.ndarray
    robust_weights: np.ndarray
    rss: float
    cost: float
    n: int
    dof: int
    residual_sd: float
    covariance: np.ndarray | None
    covariance_reason: str | None
    param_names: tuple[str, ...]
    jacobian: np.ndarray
    steps: int
    loss: str
    scale: float
    condition_number: float
    outliers: tuple[int, ...]
    outlier_weights: np.ndarray
    params_flat: np.ndarray
    _unravel: Callable = dataclasses.field(repr=False)

    @property
    def message(self) -> str:
        return self.status.message

    @property
    def converged(self) -> bool:
        return self.status is Status.SUCCESSFUL

    @property
    def covariance_accurate(self) -> bool:
        """Covariance exists, the solve converged and the column-scaled Jacobian is
        well conditioned (condition number below 1e6)."""
        return (
            self.covariance is not None
            and self.converged
            and bool(self.condition_number < COND_ACCURATE)
        )

    @property
    def std_errors_flat(self) -> np.ndarray | None:
        if self.covariance is None:
            return None
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def std_errors(self):
        se = self.std_errors_flat
        return None if se is None else jax.tree_util.tree_map(np.asarray, self._unravel(se))

    @property
    def correlation(self) -> np.ndarray | None:
        se = self.std_errors_flat
        if se is None:
            return None
        safe = np.where(se > 0, se, np.nan)
        return self.covariance / np.outer(safe, safe)

    def __repr__(self) -> str:
        return _result_text(self)

    def _repr_html_(self) -> str:
        return _result_html(self)


def _summary_items(res: LsqResult) -> list[tuple[str, str]]:
    items = [
        ("status", res.status.name + ("" if res.converged else f" ({res.message})")),
        ("loss", res.loss + ("" if res.loss == "linear" else f" (scale {res.scale:.4g})")),
        ("n", str(res.n)),
        ("dof", str(res.dof)),
        ("rss", f"{res.rss:.6g}"),
        ("residual_sd", f"{res.residual_sd:.4g}"),
        ("steps", str(res.steps)),
        ("covariance_accurate", str(res.covariance_accurate)),
    ]
    if res.covariance_reason is not None:
        items.append(("covariance", f"None: {res.covariance_reason}"))
    if res.loss != "linear":
        items.append(("outliers", str(list(res.outliers))))
    return items


def _param_rows(res: LsqResult) -> list[tuple[str, str, str]]:
    se = res.std_errors_flat
    rows = []
    for i, name in enumerate(res.param_names):
        err = "-" if se is None else f"{se[i]:.4g}"
        rows.append((name, f"{res.params_flat[i]:.10g}", err))
    return rows


def _result_text(res: LsqResult) -> str:
    head = ", ".join(f"{k}={v}" for k, v in _summary_items(res))
    rows = [("parameter", "value", "std error"), *_param_rows(res)]
    widths = [max(len(r[j]) for r in rows) for j in range(3)]
    lines = [f"LsqResult({head})"]
    for r in rows:
        lines.append(
            "  "
            + "  ".join(
                c.rjust(w) if j else c.ljust(w)
                for j, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
    return "\n".join(lines)


def _result_html(res: LsqResult) -> str:
    from html import escape

    summary = "".join(
        f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td></tr>"
        for k, v in _summary_items(res)
    )
    params = "".join(
        f"<tr><td>{escape(n)}</td><td>{escape(v)}</td><td>{escape(e)}</td></tr>"
        for n, v, e in _param_rows(res)
    )
    return (
        "<div><b>LsqResult</b><table>" + summary + "</table>"
        "<table><tr><th>parameter</th><th>value</th><th>std error</th></tr>"
        + params
        + "</table></div>"
    )


def _as_float_tree(y0):
    def leaf(x):
        a = jnp.asarray(x)
        if not jnp.issubdtype(a.dtype, jnp.inexact):
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
    solver: str = "lm",
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 1000,
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
    - `solver`: `"lm"` (Levenberg-Marquardt), `"gauss_newton"` or `"dogleg"`.
    - `rtol`, `atol`: optimistix's Cauchy termination tolerances (on both the
      parameter and the residual change).
    - `max_steps`: step limit of each stage.
    - `x_scale`: parameter scaling for the solver: `None`, `"y0"`, `"jac"` or
      typical magnitudes (a scalar or a pytree like `y0`), see [`solve_arrays`][].
    - `throw`: raise [`AnalysisError`][piecs_bayes.errors.AnalysisError] with the
      status message on failure; with `False` inspect `result.status`.

    **Returns:**

    A [`LsqResult`][].

    Raises `ValueError` (an [`InputError`][piecs_bayes.errors.InputError]) for an
    unknown `loss` or `solver` or bad `weights`, `scale`, `sigma`.
    """
    if not (callable(loss) or (isinstance(loss, str) and loss in _robust.LOSS_NAMES)):
        raise InputError(
            f"unknown loss {loss!r}; expected one of {_robust.LOSS_NAMES} or a callable rho(z)"
        )
    if solver not in SOLVERS:
        raise InputError(f"unknown solver {solver!r}; expected one of {SOLVERS}")
    for name, val in (("scale", scale), ("sigma", sigma)):
        if val is not None and not (np.ndim(val) == 0 and np.isfinite(val) and val > 0):
            raise InputError(f"{name} must be a positive finite number or None, got {val!r}")
    if not (isinstance(max_steps, int | np.integer) and max_steps > 0):
        raise InputError(f"max_steps must be a positive integer, got {max_steps!r}")

    y0 = _as_float_tree(y0)
    y0_flat, unravel = _ravel(y0)
    if y0_flat.size == 0:
        raise InputError("y0 has no parameters to fit")

    def flat_fn(y_flat, a):
        return jnp.asarray(fn(unravel(y_flat), a))

    out = jax.eval_shape(flat_fn, y0_flat, args)
    if len(out.shape) != 1:
        raise InputError(f"fn must return a 1-D residual array, got shape {out.shape}")
    n = out.shape[0]
    if weights is not None:
        w = np.asarray(weights, dtype=float)
        if w.shape != (n,):
            raise InputError(f"weights must have shape ({n},) like the residuals, got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise InputError("weights must be finite and non-negative")
        weights = jnp.asarray(w)
    else:
        weights = jnp.ones(n)  # one compiled solve with or without weights
    if x_scale is not None and not isinstance(x_scale, str):
        if jax.tree_util.tree_structure(x_scale) == jax.tree_util.tree_structure(y0):
            x_scale = _ravel(x_scale)[0]
        elif np.ndim(x_scale) == 0 or np.shape(x_scale) == y0_flat.shape:
            x_scale = jnp.asarray(x_scale, float)
        else:
            raise InputError("x_scale must be None, 'y0', 'jac', a scalar or a pytree like y0")
        if not bool(jnp.all(jnp.isfinite(x_scale) & (x_scale > 0))):
            raise InputError("x_scale must be positive and finite")
    elif isinstance(x_scale, str) and x_scale not in ("y0", "jac"):
        raise InputError(f"unknown x_scale {x_scale!r}; expected None, 'y0', 'jac' or an array")

    arr = solve_arrays(
        _FlatFn(fn, unravel),
        y0_flat,
        args,
        weights,
        loss=loss,
        scale=scale,
        sigma=sigma,
        solver=solver,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        x_scale=x_scale,
    )
    arr = jax.tree_util.tree_map(np.asarray, arr)
    status = Status(int(arr.status_code))
    cov_code = int(arr.covariance_code)
    cov = None if cov_code != _COV_OK else np.array(arr.covariance)
    robust = not _is_linear(loss)
    outliers = tuple(int(i) for i in np.flatnonzero(arr.outlier))
    res = LsqResult(
        params=jax.tree_util.tree_map(np.asarray, unravel(jnp.asarray(arr.params_flat))),
        status=status,
        residuals=arr.residuals,
        weights=arr.weights,
        robust_weights=arr.robust_weights,
        rss=float(arr.rss),
        cost=float(arr.cost),
        n=int(arr.n_used),
        dof=int(arr.dof),
        residual_sd=float(arr.residual_sd),
        covariance=cov,
        covariance_reason=None if cov is not None else _COV_REASONS[cov_code],
        param_names=_param_names(y0),
        jacobian=arr.jacobian,
        steps=int(arr.steps),
        loss=(loss if isinstance(loss, str) else getattr(loss, "__name__", "custom")),
        scale=float(arr.scale) if robust else float("nan"),
        condition_number=float(arr.condition),
        outliers=outliers,
        outlier_weights=arr.robust_weights[list(outliers)],
        params_flat=arr.params_flat,
        _unravel=unravel,
    )
    if throw and status is not Status.SUCCESSFUL:
        raise AnalysisError(f"least-squares fit failed: {status.message} (after {res.steps} steps)")
    return res


@dataclasses.dataclass(frozen=True)
class _Unravel:
    """Hashable inverse of `ravel_pytree` (same order), so that repeated fits of one
    structure reuse the compiled solve."""

    treedef: Any
    shapes: tuple[tuple[int, ...], ...]

    def __call__(self, flat):
        leaves, start = [], 0
        for shape in self.shapes:
            size = int(np.prod(shape, dtype=int))
            leaves.append(jnp.reshape(flat[start : start + size], shape))
            start += size
        return jax.tree_util.tree_unflatten(self.treedef, leaves)


def _ravel(tree):
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    flat = jnp.concatenate([jnp.ravel(jnp.asarray(x, float)) for x in leaves])
    return flat, _Unravel(treedef, tuple(tuple(np.shape(x)) for x in leaves))


class _FlatFn(eqx.Module):
    """`fn` on flat parameters; an equinox Module so that two calls with the same
    `fn` and structure hash equal and share one compiled solve."""

    fn: Callable = eqx.field(static=True)
    unravel: Callable = eqx.field(static=True)

    def __call__(self, y_flat, args):
        return jnp.asarray(self.fn(self.unravel(y_flat), args))

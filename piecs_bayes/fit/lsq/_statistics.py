r"""What a least-squares solution says: the Jacobian and its SVD at the solution
([`analyse`][]), then the covariance, outlier flags, residual SD and the final
status ([`statistics`][]). Shared by `_solve_core` and the batch kernel, so both
report the same numbers.

The covariance is $\sigma^2 (J_w^TJ_w)^{-1}$ for the linear loss (with the residual
variance when `sigma` is not given); for a robust loss Huber's (1981) estimate without
`sigma`, and with it the sandwich with the final weights held fixed, scaled to the
M-estimator's variance at the normal (`losses.fixed_weight_factor`). A point is an
outlier when its robust weight is below the weight of a residual of three robust
standard deviations. A solution is SUCCESSFUL only if the Gauss-Newton step left is
negligible (`STATIONARY_RTOL`): a solver that merely stopped moving is STALLED, never an
answer.

The formulas: docs/models/least_squares.md, "What a solution says".
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from . import losses
from ._types import COV_DOF, COV_NONFINITE, COV_OK, COV_ROBUST, COV_SINGULAR, LsqArrays, Status

#: a solution is stationary when the Gauss-Newton step left is below this times
#: max(|parameter|, standard error) (+ 10 atol) for every parameter.
STATIONARY_RTOL = 1e-3


class FinalLoss(NamedTuple):
    """The loss of a solve's last stage as the statistics read it: its index in
    `losses.LOSS_NAMES` (`None` for the linear loss), its tuning constant, the custom
    `rho` (or `None`) and whether it is robust (not the linear loss)."""

    idx: Any
    tuning: Any
    custom: Any
    robust: bool


def analyse(fn, args, y, mask, wsqrt, s_final, loss: FinalLoss):
    """Residuals, Jacobian, robust weights and the SVD of the column-scaled
    weighted Jacobian at `y`, and the step `-(J_w^T J_w)^-1 J_w^T W e` (the
    Gauss-Newton step for the linear loss; zero exactly where the gradient
    `J_w^T W e` of the robust objective is zero)."""
    n, p = mask.shape[0], y.shape[0]
    eps = jnp.finfo(float).eps
    final_id, custom = loss.idx, loss.custom
    r = fn(y, args)
    jac = jax.jacfwd(fn)(y, args)
    e = jnp.where(mask, wsqrt * r, 0.0)
    jw = jnp.where(mask[:, None], wsqrt[:, None] * jac, 0.0)
    if loss.robust:
        zz = (e / s_final) ** 2
        rw = jnp.where(mask, losses.rho_prime(final_id, zz, custom), 0.0)
        cost = 0.5 * jnp.sum(e * e * losses.rho_over_z(final_id, zz, custom))
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


def statistics(info, y, code, steps, s_final, mask, w, sigma, loss: FinalLoss, atol):
    """The result at the solution `y` from [`analyse`][]'s `info`: outliers,
    covariance (linear or Huber's robust sandwich, or from a known `sigma`) with its
    code, residual SD, and the final status (non-finite, degenerate, stalled)."""
    n, p = mask.shape[0], y.shape[0]
    robust = loss.robust
    n_used = jnp.sum(mask).astype(jnp.int32)
    dof = n_used - p
    dof_f = jnp.maximum(dof, 1).astype(float)
    e, rw = info["e"], info["rw"]
    rss = jnp.sum(e * e)
    if robust:
        w3 = losses.rho_prime(loss.idx, jnp.asarray((3.0 / loss.tuning) ** 2), loss.custom)
        outlier = mask & (rw < w3)
    else:
        outlier = jnp.zeros(n, dtype=bool)
    cov, cov_code, cond, robust_ok = _covariance(info, mask, sigma, s_final, loss, dof, rss)
    if robust:
        # reported, not used as a scale: an exact fit reports 0, never a placeholder
        resid_sd = losses.mad_sigma(e, mask, fallback=False)
    else:
        resid_sd = jnp.where(dof > 0, jnp.sqrt(rss / dof_f), jnp.nan)
    code = _final_status(code, y, e, robust_ok, cov, cov_code, info["delta"], atol)
    return LsqArrays(
        params_flat=y,
        status_code=code,
        residuals=info["r"],
        weights=w * rw,
        robust_weights=rw,
        outlier=outlier,
        covariance=cov,
        covariance_code=cov_code,
        condition=cond,
        jacobian=info["jac"],
        rss=rss,
        cost=info["cost"],
        n_used=n_used,
        dof=dof,
        residual_sd=resid_sd,
        scale=s_final,
        steps=jnp.asarray(steps, dtype=jnp.int32),
    )


def _covariance(info, mask, sigma, s_final, loss: FinalLoss, dof, rss):
    """Covariance (NaN unless its code is `COV_OK`), its code, the condition number
    and whether the robust fit kept enough points (see the module docstring)."""
    n, p = mask.shape[0], info["v_scaled"].shape[0]
    n_used = jnp.sum(mask).astype(jnp.int32)
    dof_f = jnp.maximum(dof, 1).astype(float)
    keep, sv, colnorm = info["keep"], info["sv"], info["colnorm"]
    v_scaled = info["v_scaled"]
    singular = ~keep[-1] | jnp.any(colnorm == 0)
    cond = jnp.where(singular, jnp.inf, sv[0] / jnp.where(sv[-1] > 0, sv[-1], 1.0))
    a_inv = v_scaled @ v_scaled.T  # (J_w^T J_w)^-1
    robust_ok = jnp.asarray(True)
    sigma_given = jnp.isfinite(sigma)
    if not loss.robust:
        factor = jnp.where(sigma_given, sigma**2, rss / dof_f)
    else:
        n_f = jnp.maximum(n_used, 1).astype(float)
        factor, robust_ok = _huber_factor(info, mask, s_final, loss, p, n_f, dof_f)
    cov = factor * a_inv
    if loss.robust:
        # known sigma: weighted least squares with the final weights held fixed,
        # scaled to the M-estimator's variance at the normal
        sandwich, singular_w = _fixed_weight_sandwich(info, sigma, n, p)
        sandwich = losses.fixed_weight_factor_of(loss.idx) * sandwich
        singular = singular | (sigma_given & singular_w)
        cov = jnp.where(sigma_given, sandwich, cov)
    cov = 0.5 * (cov + cov.T)
    cov_code = jnp.where(
        ~info["finite"],
        COV_NONFINITE,
        jnp.where(
            singular,
            COV_SINGULAR,
            jnp.where(
                (dof <= 0) & ~sigma_given,
                COV_DOF,
                jnp.where(robust_ok, COV_OK, COV_ROBUST),
            ),
        ),
    ).astype(jnp.int32)
    cov = jnp.where(cov_code == COV_OK, cov, jnp.nan)
    return cov, cov_code, cond, robust_ok


def _huber_factor(info, mask, s_final, loss: FinalLoss, p, n_f, dof_f):
    """Huber (1981, sec. 7.6): the factor $K^2 [\\sum\\psi^2/dof] / [mean\\,\\psi']^2$ of
    $(J^TJ)^{-1}$, and whether enough points kept weight (fewer effective points
    than parameters: (nearly) everything rejected)."""
    e, rw = info["e"], info["rw"]
    dpsi = losses.psi_prime(loss.idx, e / s_final, loss.custom)
    mean_dpsi = jnp.sum(jnp.where(mask, dpsi, 0.0)) / n_f
    var_dpsi = jnp.sum(jnp.where(mask, (dpsi - mean_dpsi) ** 2, 0.0)) / n_f
    safe_mean = jnp.where(mean_dpsi > 0, mean_dpsi, 1.0)
    k_corr = 1.0 + p / n_f * var_dpsi / safe_mean**2
    tau2 = jnp.sum((rw * e) ** 2) / dof_f
    factor = k_corr**2 * tau2 / safe_mean**2
    robust_ok = (mean_dpsi > 0) & (jnp.sum(rw) >= p + 1)
    return factor, robust_ok


def _fixed_weight_sandwich(info, sigma, n, p):
    """$\\sigma^2 (J^TWJ)^{-1} (J^TW^2J) (J^TWJ)^{-1}$ with the final weights held
    fixed, and whether $J^TWJ$ is singular."""
    eps = jnp.finfo(float).eps
    rw, jw, colnorm = info["rw"], info["jw"], info["colnorm"]
    bw = jnp.sqrt(rw)[:, None] * info["b"]
    _, sv_w, vt_w = jnp.linalg.svd(bw, full_matrices=False)
    keep_w = sv_w > sv_w[0] * max(n, p) * eps
    inv_w = jnp.where(keep_w, 1.0 / jnp.where(keep_w, sv_w, 1.0), 0.0)
    vw = vt_w.T * inv_w / jnp.where(colnorm > 0, colnorm, 1.0)[:, None]
    aw_inv = vw @ vw.T
    meat = jw.T @ ((rw**2)[:, None] * jw)
    return sigma**2 * aw_inv @ meat @ aw_inv, ~keep_w[-1]


def _final_status(code, y, e, robust_ok, cov, cov_code, delta, atol):
    """The solver's `code`, overridden by NONFINITE, DEGENERATE (robust fit without
    enough points) and STALLED: a non-stationary point is never a success; the
    step left (see [`analyse`][]) must be negligible against the parameter and its
    standard error."""
    all_finite = jnp.all(jnp.isfinite(y)) & jnp.all(jnp.isfinite(e))
    code = jnp.where(all_finite, code, int(Status.NONFINITE))
    code = jnp.where((code == Status.SUCCESSFUL) & ~robust_ok, int(Status.DEGENERATE), code)
    se = jnp.sqrt(jnp.where(cov_code == COV_OK, jnp.abs(jnp.diagonal(cov)), 0.0))
    tol = STATIONARY_RTOL * jnp.maximum(jnp.abs(y), se) + 10.0 * atol
    stalled = ~jnp.all(jnp.abs(delta) <= tol)
    code = jnp.where((code == Status.SUCCESSFUL) & stalled, int(Status.STALLED), code)
    return code.astype(jnp.int32)

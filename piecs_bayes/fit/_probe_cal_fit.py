r"""The probe calibration fit: the effective radius $r(\theta)$ from the recorded ball
centres on a certified artefact (`piecs-bayes calibrate-probe`).

[`fit_probe_calibration`][] takes the artefact with its certificate (sphere, ring,
diameter, optionally a face pair), the recorded ball centres (mm, part frame, radius X)
and their approach directions, and returns a [`ProbeCalibration`][]: the coefficients
of $r(\theta) = r_0 + \sum_k a_k \cos k\theta + b_k \sin k\theta$ ($k$ in 2, 3; or one
radius per axis, $r_0 + a_2 \cos 2\theta$), their covariance and dof, conditional on
the certified size, whose certificate's u enters the covariance (`method="bayes"`:
the size under its certificate's prior). Orders the directions cannot separate are
refused (`check_orders`); `"auto"` chooses by the u of $r(\theta)$ at the directions
the parts are probed from (`choose_orders`). [`repeatability_check`][] warns when the
residual sd does not fit the declared repeatability. docs/uncertainty.md, section 5.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..io import PER_AXIS, CalibrationArtefact, ProbeCalibration
from ._options import CALIBRATION_SAMPLING, CalibrationOptions
from ._probe_cal_design import CalibrationDesign, check_orders, model_terms, term_basis
from ._probe_cal_orders import choose_orders
from .lsq import TUNING, least_squares
from .mcmc import SamplerOptions, gaussian_loglik, sample_posterior


def _residuals(y, args, sizes=None):
    """The residuals (mm) of `y` = (free centre offsets, coefficients) given the sizes
    of each group (`args["S"]` when `sizes` is None)."""
    nc = args["E"].shape[1]
    c = args["c0"] + args["E"] @ y[:nc]
    r = args["basis"] @ y[nc:]
    d = args["p"] - c
    size = (args["S"] if sizes is None else sizes)[args["idx"]]
    dist = jnp.where(args["sphere"], jnp.sqrt(jnp.sum(d * d, axis=1)),
                     -args["s"] * jnp.sum(args["u"] * d, axis=1))  # fmt: skip
    return dist - (size + args["s"] * r)


def _lsq_fn(y, args):
    return _residuals(y, args)


def fit_probe_calibration(
    artefact: CalibrationArtefact,
    centres,
    approach,
    *,
    sigma_declared: float,
    options: CalibrationOptions = CalibrationOptions(),
    face=None,
    sampling: SamplerOptions = CALIBRATION_SAMPLING,
    directions=None,
) -> ProbeCalibration:
    r"""Fit the effective radius $r(\theta)$ on a certified artefact (module docstring).

    **Arguments:**

    - `artefact`: the artefact and its certificate (`piecs_bayes.io.CalibrationArtefact`).
    - `centres` ``(n, 2)``: recorded ball centres (mm, x radius, z, part frame).
    - `approach` ``(n, 2)``: approach directions (normalised here).
    - `sigma_declared`: the probe's declared repeatability (mm).
    - `options`: the [`CalibrationOptions`][]: the `orders` (``"auto"``: chosen by
      [`choose_orders`][] at `directions`; a tuple of orders in (2, 3), ``()``: one
      radius; ``"a2"``: one radius per axis, r0 + a2 cos 2 theta), what the declared
      value is worth (`sigma_dof`), whether it is known (`sigma_known`), the
      `method` (``"lsq"``, (robust) least squares with `loss`, or ``"bayes"``, the
      certificate a normal prior on the sizes, started at the fit) and the `loss`.
    - `face` ``(n,)`` bool: which points are the face pair's (default: the approach
      is nearer Z than X).
    - `sampling`: the sampler's settings (``"bayes"``: `sample_posterior`; by
      default `CALIBRATION_SAMPLING`: 3,000 steps of the lockstep sampler with its
      differential-evolution mixture, never emcee's snooker move, no progress bar).
    - `directions`: the approach angles (degrees) the parts are probed from, where
      ``"auto"`` judges the orders (default: the lathe's +X, +Z, -X, -Z,
      `LATHE_DIRECTIONS`).

    **Returns:** a `ProbeCalibration` (no probe, date, feed or inputs: the job's), with
    its distinct `directions` and, for ``"auto"``, the `orders_choice`.
    """
    if not (math.isfinite(sigma_declared) and sigma_declared > 0):
        raise InputError(f"sigma_declared must be > 0 (mm), got {sigma_declared!r}")
    design = CalibrationDesign(artefact, centres, approach, face)
    spec, choice = options.orders, None
    if spec == "auto":
        spec, choice = choose_orders(design, sigma_declared, targets_deg=directions,
                                     sigma_known=options.sigma_known)  # fmt: skip
    terms = model_terms(spec)  # refuses an unknown spec
    spec = spec if spec == PER_AXIS else tuple(sorted(spec))
    check_orders(design, spec, sigma_known=options.sigma_known)
    terms = model_terms(spec)
    y, cov, dof, resid_sd = _least_squares(design, terms, sigma_declared, options)
    if options.method == "bayes":
        args = design.args(terms) | {"S": jnp.asarray(design.sizes)}
        y, cov, dof = _bayes(design, args, y, resid_sd, sigma_declared, options, sampling)
    nc = len(design.free)
    coef, ccov = y[nc:], cov[nc:, nc:]
    radii = term_basis(design.theta[design.distinct()], terms) @ coef
    orders, coef, ccov, fixed = _embed(spec, coef, ccov)
    deg = np.unique(np.round(np.degrees(design.theta), 6))
    return ProbeCalibration(
        orders=orders, coefficients=coef, cov=ccov, dof=dof, residual_sd=resid_sd,
        probing_error=float(radii.max() - radii.min()), artefact=artefact.to_json(),
        n_points=len(design), fixed=fixed, directions=tuple(deg), orders_choice=choice,
    )  # fmt: skip


def _least_squares(design: CalibrationDesign, terms, sigma_declared, options):
    """(Robust) least squares of the model of `terms`: the estimate of (free centre,
    r0, terms), its covariance with the certificates' u, dof and the residual sd."""
    sigma_known, loss = options.sigma_known, options.loss
    args = design.args(terms) | {"S": jnp.asarray(design.sizes)}
    y0 = design.linear_start(terms)
    if len(design) - y0.size < 3:
        loss = "linear"
    # the robust scale as the part fits take it (jobs.robust_scale): the declared
    # repeatability times the loss's tuning; a MAD of a few points can collapse to 0
    scale = TUNING.get(loss, 1.0) * sigma_declared if loss != "linear" else None
    res = least_squares(_lsq_fn, jnp.asarray(y0), args, loss=loss, scale=scale,
                        sigma=sigma_declared if sigma_known else None)  # fmt: skip
    y, cov = np.asarray(res.params_flat), np.asarray(res.covariance)
    J, w = np.asarray(res.jacobian), np.asarray(res.weights)
    dS = -design.size_onehot()
    G = -np.linalg.solve(J.T @ (w[:, None] * J), J.T @ (w[:, None] * dS))
    cov = cov + G @ np.diag(design.size_u**2) @ G.T
    dof = math.inf if sigma_known else float(res.dof)
    return y, cov, dof, float(res.residual_sd)


def _embed(spec, coef, ccov):
    """The coefficients of model `spec` as a `ProbeCalibration` holds them: one radius
    per axis is orders (2,) with b2 held at zero (no variance)."""
    if spec != PER_AXIS:
        return spec, coef, ccov, ()
    keep = [0, 1]  # r0, a2 of r0, a2, b2
    full = np.zeros((3, 3))
    full[np.ix_(keep, keep)] = ccov
    return (2,), np.r_[coef, 0.0], full, ("b2",)


def _log_post(theta, args):
    """Flat priors on the centre and the coefficients, the certificates' normal priors
    on the sizes, the scaled-inverse-chi^2 prior (`ScaledInvChi2(nu, s)`, up to its
    constant) on sigma when it is sampled (``args["nu"] > 0``), a Gaussian likelihood."""
    m = args["S"].shape[0]
    y, sizes = theta[: theta.shape[0] - m - 1], theta[theta.shape[0] - m - 1 : -1]
    sampled = args["nu"] > 0
    sigma = jnp.where(sampled, theta[-1], args["sigma"])
    lp = -0.5 * jnp.sum(((sizes - args["S"]) / args["uS"]) ** 2)
    safe = jnp.where(sigma > 0, sigma, 1.0)
    lp_sigma = -(args["nu"] + 1.0) * jnp.log(safe) - 0.5 * args["nu"] * args["s2"] / safe**2
    lp = lp + jnp.where(sampled, lp_sigma, -0.5 * (theta[-1] - args["sigma"]) ** 2)
    ll = gaussian_loglik(_residuals(y, args, sizes), safe)
    return jnp.where(sigma > 0, lp + ll, -jnp.inf)


def _bayes(design, args, y, resid_sd, sigma_declared, options: CalibrationOptions,
           sampling: SamplerOptions):  # fmt: skip
    """The posterior mean and covariance of (centre, coefficients) and their dof: the
    residuals' dof plus the declared value's (the marginal of a normal linear model
    under the conjugate prior), infinite with a known sigma. With a known sigma the
    last parameter is a dummy N(sigma, 1) draw, so that one log posterior serves both."""
    sigma_known, sigma_dof = options.sigma_known, options.sigma_dof
    s0 = sigma_declared if sigma_known else float(max(resid_sd, 1e-6))
    x0 = np.r_[y, design.sizes, s0]
    names = tuple(f"y{i}" for i in range(y.size)) + tuple(design.size_names) + ("sigma",)
    bargs = args | {
        "uS": jnp.asarray(design.size_u), "nu": jnp.asarray(0.0 if sigma_known else sigma_dof),
        "s2": jnp.asarray(sigma_declared**2), "sigma": jnp.asarray(sigma_declared),
    }  # fmt: skip
    post = sample_posterior(_log_post, x0, names=names, args=bargs, options=sampling)
    k = y.size
    dof = math.inf if sigma_known else float(len(design) - y.size) + float(sigma_dof)
    return np.asarray(post.mean)[:k], np.asarray(post.cov)[:k, :k], dof


def repeatability_check(cal: ProbeCalibration, declared: float, *, p: float = 0.99) -> str | None:
    """A warning when the residual sd is not what the declared repeatability makes
    likely: outside the two-sided `p` interval of $s^2/\\sigma^2 \\sim \\chi^2_\\nu/\\nu$
    ($\\nu$ = n - p of the fit); None when it is."""
    from scipy import stats

    art = cal.artefact
    nc = 2 if art.get("kind") == "sphere" or art.get("face") else 1
    nu = cal.n_points - (cal.coefficients.size - len(cal.fixed)) - nc
    if nu < 1 or not math.isfinite(cal.residual_sd):
        return None
    lo, hi = (math.sqrt(stats.chi2.ppf(q, nu) / nu) for q in ((1 - p) / 2, (1 + p) / 2))
    ratio = cal.residual_sd / declared
    if lo <= ratio <= hi:
        return None
    return (f"the residual sd {cal.residual_sd * 1e3:.2f} um is {ratio:.2f} x the declared "
            f"repeatability {declared * 1e3:.2f} um (outside [{lo:.2f}, {hi:.2f}], the "
            f"{p:.0%} range at {nu} dof): check the repeatability, the artefact and its "
            "clamping, or the orders")  # fmt: skip

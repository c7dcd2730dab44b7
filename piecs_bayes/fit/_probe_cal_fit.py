r"""The probe calibration fit: the effective radius $r(\theta)$ from the recorded ball
centres on a certified artefact (`piecs-bayes calibrate-probe`).

[`fit_probe_calibration`][] takes the artefact with its certificate (sphere, ring,
diameter, optionally a face pair), the recorded ball centres (mm, part frame, radius X)
and their approach directions, and returns a [`ProbeCalibration`][]: the coefficients
of $r(\theta) = r_0 + \sum_k a_k \cos k\theta + b_k \sin k\theta$ ($k$ in 2, 3; order 1
is the probe's offset, absorbed by the free centre), their covariance and dof. The fit
is conditional on the certified size (not separable from $r_0$), whose certificate's
uncertainty enters the covariance; `method="bayes"` samples the same model with the size
under its certificate's prior. Orders the directions cannot separate are refused
([`check_orders`][], `COND_LIMIT`); `"auto"` takes the highest of `AUTO_ORDERS` they
separate. [`repeatability_check`][] warns when the residual sd does not fit the
declared repeatability. The model and its coverage: docs/uncertainty.md, section 5.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..io import CalibrationArtefact, ProbeCalibration, approach_angle, lobe_basis
from ._options import CALIBRATION_SAMPLING, CalibrationOptions
from .lsq import TUNING, least_squares
from .mcmc import SamplerOptions, gaussian_loglik, sample_posterior

#: the condition number (unit-scaled design over the distinct directions) beyond
#: which orders are refused: a coefficient's uncertainty would be amplified more than
#: this many times over what the same points evenly spread give
COND_LIMIT = 100.0
#: the candidates of ``orders="auto"``, highest first
AUTO_ORDERS = ((2, 3), (2,), ())
#: an approach of a ring, diameter or face within this angle of its axis (rad)
_AXIS_TOL = math.radians(2.0)


class _Design:
    """The data arranged for the model: per point its centre, approach, angle, the
    group's sign (+1 outside, -1 inside), whether it is a sphere's point, the axis of a
    line point, the index of its certified size; the sizes with their u; the free
    centre coordinates."""

    def __init__(self, artefact: CalibrationArtefact, centres, approach, face=None):
        p = np.asarray(centres, dtype=float).reshape(-1, 2)
        a = np.asarray(approach, dtype=float).reshape(-1, 2)
        if p.shape != a.shape or not (np.all(np.isfinite(p)) and np.all(np.isfinite(a))):
            raise InputError(f"centres {p.shape} and approach {a.shape}: expected two finite "
                             "(n, 2) arrays of the same shape")  # fmt: skip
        norm = np.hypot(a[:, 0], a[:, 1])
        if np.any(norm < 1e-9):
            i = int(np.argmin(norm))
            raise InputError(f"point {i + 1}: the approach direction is zero", value=a[i].tolist())
        a = a / norm[:, None]
        n = len(p)
        self.centres, self.approach, self.theta = p, a, approach_angle(a)
        self.centre0 = np.asarray(artefact.centre, dtype=float)
        self.sphere = np.full(n, artefact.kind == "sphere")
        self.sign = np.full(n, -1.0 if artefact.kind == "ring" else 1.0)
        self.axis = np.zeros((n, 2))
        self.size_index = np.zeros(n, dtype=int)
        self.sizes = [artefact.diameter / 2.0]
        self.size_u = [artefact.radius_u]
        self.size_names = ["radius"]
        if artefact.kind == "sphere":
            self.free = (0, 1)
        else:
            on_face = (np.abs(a[:, 1]) > np.abs(a[:, 0])) if face is None else np.asarray(face)
            on_face = on_face.astype(bool).reshape(n)
            if artefact.face_width is None and on_face.any():
                i = int(np.flatnonzero(on_face)[0])
                raise InputError(f"point {i + 1}: approach {a[i].tolist()} is along Z, but the "
                                 f"{artefact.kind} has no face pair ([artefact.face])")  # fmt: skip
            self._line_axes(on_face, artefact.kind)
            self.free = (0,)
            if artefact.face_width is not None:
                self.sign[on_face] = 1.0
                self.size_index[on_face] = 1
                self.sizes.append(artefact.face_width / 2.0)
                self.size_u.append(artefact.face_half_width_u)
                self.size_names.append("half_width")
                self.free = (0, 1)
        self.sizes, self.size_u = np.asarray(self.sizes), np.asarray(self.size_u)

    def _line_axes(self, on_face, kind) -> None:
        a = self.approach
        for i in range(len(a)):
            j = 1 if on_face[i] else 0
            if abs(a[i, 1 - j]) > math.sin(_AXIS_TOL):
                what = "a face pair along Z" if j else f"a {kind} along X"
                raise InputError(
                    f"point {i + 1}: approach {a[i].round(4).tolist()} is not along an "
                    f"axis: {what} is probed within 2 degrees of it"
                )
            self.axis[i, j] = math.copysign(1.0, a[i, j])

    def __len__(self) -> int:
        return len(self.centres)

    @property
    def embed(self) -> np.ndarray:
        """``(2, nc)``: the free centre coordinates into (x, z)."""
        return np.eye(2)[:, list(self.free)]

    def args(self, orders) -> dict:
        return {
            "p": jnp.asarray(self.centres), "basis": jnp.asarray(lobe_basis(self.theta, orders)),
            "c0": jnp.asarray(self.centre0), "E": jnp.asarray(self.embed),
            "sphere": jnp.asarray(self.sphere), "s": jnp.asarray(self.sign),
            "u": jnp.asarray(self.axis), "idx": jnp.asarray(self.size_index),
        }  # fmt: skip

    def distinct(self) -> np.ndarray:
        """Indices of one point per distinct (direction, size) pair."""
        key = np.c_[np.round(np.degrees(self.theta), 3) % 360.0, self.size_index]
        return np.unique(key, axis=0, return_index=True)[1]

    def _rows(self, orders, i) -> np.ndarray:
        dc = np.where(self.sphere[i, None], self.approach[i], self.sign[i, None] * self.axis[i])
        basis = lobe_basis(self.theta[i], orders)
        return np.c_[dc[:, list(self.free)], -self.sign[i, None] * basis]

    def nominal_design(self, orders) -> np.ndarray:
        """The linearised design at the nominal over the distinct directions."""
        return self._rows(orders, self.distinct())

    def linear_start(self, orders) -> np.ndarray:
        """The least-squares solution of the model linearised at the nominal centre
        (exact for a ring, a diameter or faces: their model is linear)."""
        d = self.centres - self.centre0
        dist = np.where(self.sphere, np.hypot(d[:, 0], d[:, 1]),
                        -self.sign * np.sum(self.axis * d, axis=1))  # fmt: skip
        e0 = dist - self.sizes[self.size_index]
        return np.linalg.lstsq(self._rows(orders, np.arange(len(self))), -e0, rcond=None)[0]

    def angles_text(self) -> str:
        deg = np.unique(np.round(np.degrees(self.theta) % 360.0, 1))
        shown = ", ".join(f"{d:g}" for d in deg[:12]) + (", ..." if deg.size > 12 else "")
        return f"{shown} degrees{' only' if deg.size <= 12 else ''} ({deg.size} distinct)"


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


def check_orders(design: _Design, orders, *, sigma_known: bool = False) -> float:
    """The condition number of the nominal design of `orders`; `InputError` when the
    directions cannot separate them (module docstring) or leave no dof."""
    x = design.nominal_design(orders)
    p = x.shape[1]
    x = x / np.maximum(np.linalg.norm(x, axis=0), 1e-300)
    sv = np.linalg.svd(x, compute_uv=False)
    rank = int(np.sum(sv > 1e-9 * sv[0]))
    cond = math.inf if rank < p else float(sv[0] / sv[-1])
    label = f"order {max(orders)}" if orders else "one radius (K = 0)"
    if rank < p or cond > COND_LIMIT:
        many = max(p + 1, 2 * max(orders, default=1) + 2)
        step = 360.0 / many
        why = f"rank {rank} of {p}" if rank < p else f"condition number {cond:.3g} > {COND_LIMIT:g}"
        hint = (
            f"approach directions spread over at least {p} distinct angles around the circle, "
            f"e.g. every {step:g} degrees ({', '.join(f'{k * step:g}' for k in range(many))})"
            if design.sphere.all() else
            "a sphere probed around the circle (a ring, diameter or face is probed along the "
            "axes only: 0, 90, 180, 270 degrees at most)"
        )  # fmt: skip
        raise InputError(f"{label} needs {hint}; the data have {design.angles_text()} ({why})")
    dof = len(design) - p
    if dof < (0 if sigma_known else 1):
        raise InputError(f"{label}: {len(design)} points for {p} unknowns leave no degree of "
                         "freedom to estimate the probe's sigma: probe more points "
                         "(or repeat directions)")  # fmt: skip
    return cond


def auto_orders(design: _Design, *, sigma_known: bool = False) -> tuple[int, ...]:
    """The highest of `AUTO_ORDERS` that `check_orders` accepts."""
    for orders in AUTO_ORDERS:
        try:
            check_orders(design, orders, sigma_known=sigma_known)
        except InputError:
            if not orders:
                raise
            continue
        return orders
    raise AssertionError("unreachable")


def fit_probe_calibration(
    artefact: CalibrationArtefact,
    centres,
    approach,
    *,
    sigma_declared: float,
    options: CalibrationOptions = CalibrationOptions(),
    face=None,
    sampling: SamplerOptions = CALIBRATION_SAMPLING,
) -> ProbeCalibration:
    r"""Fit the effective radius $r(\theta)$ on a certified artefact (module docstring).

    **Arguments:**

    - `artefact`: the artefact and its certificate (`piecs_bayes.io.CalibrationArtefact`).
    - `centres` ``(n, 2)``: recorded ball centres (mm, x radius, z, part frame).
    - `approach` ``(n, 2)``: approach directions (normalised here).
    - `sigma_declared`: the probe's declared repeatability (mm).
    - `options`: the [`CalibrationOptions`][]: the `orders` (``"auto"`` or a tuple
      of orders in (2, 3), ``()``: one radius), what the declared value is worth
      (`sigma_dof`), whether it is known (`sigma_known`), the `method` (``"lsq"``,
      (robust) least squares with `loss`, or ``"bayes"``, the certificate a normal
      prior on the sizes, started at the fit) and the `loss`.
    - `face` ``(n,)`` bool: which points are the face pair's (default: the approach
      is nearer Z than X).
    - `sampling`: the sampler's settings (``"bayes"``: `sample_posterior`; by
      default `CALIBRATION_SAMPLING`: 3,000 steps of the lockstep sampler with its
      differential-evolution mixture, never emcee's snooker move, no progress bar).

    **Returns:** a `ProbeCalibration` (no probe, date, feed or inputs: the job's).
    """
    sigma_known, loss = options.sigma_known, options.loss
    if not (math.isfinite(sigma_declared) and sigma_declared > 0):
        raise InputError(f"sigma_declared must be > 0 (mm), got {sigma_declared!r}")
    design = _Design(artefact, centres, approach, face)
    orders = options.orders
    if orders == "auto":
        orders = auto_orders(design, sigma_known=sigma_known)
    orders = tuple(sorted(orders))
    check_orders(design, orders, sigma_known=sigma_known)
    args = design.args(orders) | {"S": jnp.asarray(design.sizes)}
    nc = len(design.free)
    y0 = design.linear_start(orders)
    if len(design) - y0.size < 3:
        loss = "linear"
    # the robust scale as the part fits take it (jobs.robust_scale): the declared
    # repeatability times the loss's tuning; a MAD of a few points can collapse to 0
    scale = TUNING.get(loss, 1.0) * sigma_declared if loss != "linear" else None
    res = least_squares(_lsq_fn, jnp.asarray(y0), args, loss=loss, scale=scale,
                        sigma=sigma_declared if sigma_known else None)  # fmt: skip
    y, cov = np.asarray(res.params_flat), np.asarray(res.covariance)
    J, w = np.asarray(res.jacobian), np.asarray(res.weights)
    dS = -(design.size_index[:, None] == np.arange(design.sizes.size)[None]).astype(float)
    G = -np.linalg.solve(J.T @ (w[:, None] * J), J.T @ (w[:, None] * dS))
    cov = cov + G @ np.diag(design.size_u**2) @ G.T
    dof = math.inf if sigma_known else float(res.dof)
    resid_sd = float(res.residual_sd)
    if options.method == "bayes":
        y, cov, dof = _bayes(design, args, y, res, sigma_declared, options, sampling)
    coef, ccov = y[nc:], cov[nc:, nc:]
    radii = lobe_basis(design.theta[design.distinct()], orders) @ coef
    return ProbeCalibration(
        orders=orders, coefficients=coef, cov=ccov, dof=dof, residual_sd=resid_sd,
        probing_error=float(radii.max() - radii.min()), artefact=artefact.to_json(),
        n_points=len(design),
    )  # fmt: skip


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


def _bayes(design, args, y, res, sigma_declared, options: CalibrationOptions,
           sampling: SamplerOptions):  # fmt: skip
    """The posterior mean and covariance of (centre, coefficients) and their dof: the
    residuals' dof plus the declared value's (the marginal of a normal linear model
    under the conjugate prior), infinite with a known sigma. With a known sigma the
    last parameter is a dummy N(sigma, 1) draw, so that one log posterior serves both."""
    sigma_known, sigma_dof = options.sigma_known, options.sigma_dof
    s0 = sigma_declared if sigma_known else float(max(res.residual_sd, 1e-6))
    x0 = np.r_[y, design.sizes, s0]
    names = tuple(f"y{i}" for i in range(y.size)) + tuple(design.size_names) + ("sigma",)
    bargs = args | {
        "uS": jnp.asarray(design.size_u), "nu": jnp.asarray(0.0 if sigma_known else sigma_dof),
        "s2": jnp.asarray(sigma_declared**2), "sigma": jnp.asarray(sigma_declared),
    }  # fmt: skip
    post = sample_posterior(_log_post, x0, names=names, args=bargs, options=sampling)
    k = y.size
    dof = math.inf if sigma_known else float(res.dof) + float(sigma_dof)
    return np.asarray(post.mean)[:k], np.asarray(post.cov)[:k, :k], dof


def repeatability_check(cal: ProbeCalibration, declared: float, *, p: float = 0.99) -> str | None:
    """A warning when the residual sd is not what the declared repeatability makes
    likely: outside the two-sided `p` interval of $s^2/\\sigma^2 \\sim \\chi^2_\\nu/\\nu$
    ($\\nu$ = n - p of the fit); None when it is."""
    from scipy import stats

    art = cal.artefact
    nc = 2 if art.get("kind") == "sphere" or art.get("face") else 1
    nu = cal.n_points - cal.coefficients.size - nc
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

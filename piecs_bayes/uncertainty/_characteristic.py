r"""The characteristic of a feature: its normal deviation at a nominal point, with its
uncertainty. One model for the decisions, capability studies (one part or a batch of
parts), the error specification, tool offsets, posterior draws and the figures.

The characteristic is the *normal deviation* $\delta(q)$: the distance from a nominal
point $q$ of the feature to the fitted feature along the nominal outward normal,
positive outside the material (for a diameter the radius error). [`feature_characteristic`][]
returns a [`Characteristic`][] with $u_\text{fit}$, linearised from the fit covariance
(`jax.jacfwd` of the fit's own model), and $u_\text{sys}$ from the systematic sources
that more probe points do not reduce ([`u_systematic`][]); [`characteristic_arrays`][]
does the same for every part of a batch. Where $q$ lies (`at`): `"start"`, `"mid"`,
`"end"` (fraction 0, 0.5, 1 of the nominal feature), or `"worst"`: of the start,
mid-point and end (lines; nine points along arcs) the one with the largest $|\delta|$.

The model and the sources' sensitivities: docs/uncertainty.md, section 6.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import AnalysisError, InputError
from ..fit import (
    CALIBRATION_SOURCE,
    arc_distance,
    effective_dof,
    geometry_args,
    line_distance,
    padded_size,
)
from ..geometry import Line, drawn_scale

#: the fixed characteristic points, as fractions of the nominal feature
AT_FRACTION = {"start": 0.0, "mid": 0.5, "end": 1.0}


def at_fractions(feature, at: str) -> np.ndarray:
    """The candidate fractions of `feature` for the characteristic point `at`."""
    if at == "worst":
        return np.array([0.0, 0.5, 1.0]) if isinstance(feature, Line) else np.linspace(0, 1, 9)
    if at in AT_FRACTION:
        return np.array([AT_FRACTION[at]])
    raise InputError(
        f"characteristic must be 'worst', 'mid', 'start' or 'end', got {at!r}", value=at
    )


def at_label(t: float) -> str:
    for k, v in AT_FRACTION.items():
        if t == v:
            return k
    return f"t={t:.3g}"


def normal_deviation(feature, dev, t):
    """Normal deviation $\\delta$ (mm) of the feature deviated by `dev` at the nominal
    point at fraction(s) `t` of the feature (JAX, differentiable in `dev`)."""
    return normal_deviation_at(feature, dev, feature.point_at(jnp.asarray(t, dtype=float)))


def normal_deviation_at(feature, dev, q):
    """Normal deviation $\\delta$ (mm) of the feature deviated by `dev` at nominal
    points `q` (part frame, radius X; `(2,)` or `(n, 2)`)."""
    return -feature.signed_distance(jnp.asarray(q, dtype=float), jnp.asarray(dev, dtype=float))


@functools.lru_cache(maxsize=4096)
def nominal_points(feature, ts: tuple[float, ...]):
    """Nominal points, outward normals and model geometry of `feature` at `ts` (cached)."""
    q, n = feature.drawn_at(np.asarray(ts, dtype=float))  # NumPy: no eager JAX per shape
    return q, np.array(n), geometry_args(feature)


def _delta(kind):
    distance = line_distance if kind == "line" else arc_distance

    def f(q, geom, d):
        return -distance(q, geom, d)

    return f


@functools.partial(jax.jit, static_argnums=0)
def _one(kind, q, geom, dev):
    f = functools.partial(_delta(kind), q, geom)
    return f(dev), jax.jacfwd(f)(dev)


@functools.partial(jax.jit, static_argnums=0)
def _many(kind, q, geom, devs):
    f = functools.partial(_delta(kind), q, geom)
    return jax.vmap(f)(devs), jax.vmap(jax.jacfwd(f))(devs)


def deviation_and_jacobian(feature, dev, ts):
    """$\\delta$ at the fractions `ts` and its Jacobian with respect to the deviation
    parameters `dev` (`(k,)` and `(k, p)`); with `dev` of shape `(P, p)` (several
    parts or posterior draws): `(P, k)` and `(P, k, p)`, one compiled `vmap`."""
    q, _, geom = nominal_points(feature, tuple(float(t) for t in np.atleast_1d(ts)))
    dev = np.asarray(dev, dtype=float)  # NumPy in: no eager transfer compiled per shape
    kernel = _many if dev.ndim == 2 else _one
    # the points padded to a bucket (the last repeated; every point is computed on
    # its own): one compiled kernel per bucket, not per count of fractions
    k = q.shape[0]
    q_pad = np.concatenate([q, np.repeat(q[-1:], padded_size(k) - k, axis=0)])
    val, jac = kernel(feature.kind, q_pad, geom, dev)
    return np.asarray(val)[..., :k], np.asarray(jac)[..., :k, :]


def normal_deviation_draws(feature, draws, t: float) -> np.ndarray:
    """$\\delta$ at fraction `t` for each row of deviation draws `(S, p)` (mm)."""
    return deviation_and_jacobian(feature, np.asarray(draws, dtype=float), [t])[0][:, 0]


def u_systematic(feature, ts, sds: Mapping[str, float]) -> np.ndarray:
    """$u_\\text{sys}$ of $\\delta$ at the nominal points `ts` (see the module docstring).
    A probe calibration is the entry ``"probe calibration"``, its
    `fit.RadiusComponents`: the radius's uncertainty at each point's approach (the
    inward normal), its components' variances summed there."""
    ts = np.atleast_1d(np.asarray(ts, dtype=float))
    if not sds:
        return np.zeros(ts.size)
    q, n, _ = nominal_points(feature, tuple(float(t) for t in ts))
    x, z, nx, nz = q[:, 0], q[:, 1], n[:, 0], n[:, 1]
    sens = {
        "ball_radius": np.ones_like(x),
        "pretravel": np.ones_like(x),
        "x_centre": nx,
        "z_offset": nz,
        "scale_x": nx * x,
        "scale_z": nz * z,
        "rotation": nx * z - nz * x,
    }
    var = sum((sens[k] * sd) ** 2 for k, sd in sds.items() if k in sens)
    radius = sds.get(CALIBRATION_SOURCE)
    if radius is not None:
        e = np.asarray(radius.effects(jnp.asarray(-n)))
        var = var + np.sum((e * np.asarray(radius.sds)) ** 2, axis=1)
    return np.sqrt(np.asarray(var, dtype=float) + np.zeros(ts.size))


@dataclass(frozen=True)
class Characteristic:
    """The normal deviation of one feature at one nominal point, with its uncertainty.

    `mean` (mm) and `sd` $= \\sqrt{u_\\text{fit}^2 + u_\\text{sys}^2}$ are what a
    decision needs (a posterior can replace them); `at` says where: `"start"`,
    `"mid"`, `"end"` or `"t=0.25"` (fraction of the nominal feature), `point` and
    `normal` the nominal point and outward normal (part frame, radius X).
    `tolerance` limits the normal deviation; `coordinate` is what the drawing
    tolerances (`"diameter"`, `"radius"`, `"length"` or `"normal"`) and `scale` the
    drawn deviation per unit of normal deviation (`geometry.drawn_scale`):
    `drawn_mean`, `drawn_sd` and `drawn_tolerance` are the same numbers as drawn.
    """

    feature: str
    at: str
    t: float
    point: tuple[float, float]
    normal: tuple[float, float]
    mean: float
    u_fit: float
    u_systematic: float
    tolerance: tuple[float, float]
    n_points: int | None = None
    dof_fit: float = math.inf
    coordinate: str = "normal"
    scale: float = 1.0

    @property
    def sd(self) -> float:
        return math.hypot(self.u_fit, self.u_systematic)

    @property
    def drawn_mean(self) -> float:
        return self.scale * self.mean

    @property
    def drawn_sd(self) -> float:
        return abs(self.scale) * self.sd

    @property
    def drawn_tolerance(self) -> tuple[float, float]:
        lo, hi = sorted((self.scale * self.tolerance[0], self.scale * self.tolerance[1]))
        return lo, hi

    @property
    def dof(self) -> float:
        """Welch-Satterthwaite effective degrees of freedom of `sd`: `u_fit` carries the
        probe sigma's `dof_fit`, the systematic sources are Type B (infinite)."""
        return float(effective_dof(self.sd, self.u_fit, self.dof_fit))

    def __repr__(self) -> str:
        return (
            f"Characteristic({self.feature!r} at {self.at}: {self.mean * 1e3:+.2f} um, "
            f"u {self.sd * 1e3:.2f} um (fit {self.u_fit * 1e3:.2f}, systematic "
            f"{self.u_systematic * 1e3:.2f}), tolerance [{self.tolerance[0] * 1e3:+g}, "
            f"{self.tolerance[1] * 1e3:+g}] um)"
        )


def feature_characteristic(
    fit,
    *,
    at: str = "mid",
    sources: Mapping[str, float] | None = None,
    dof: float = math.inf,
) -> Characteristic:
    """The [`Characteristic`][] of one `FeatureFit`.

    **Arguments:**

    - `fit`: a `FeatureFit` (values and covariance).
    - `at`: `"mid"`, `"start"`, `"end"` or `"worst"` (see the module docstring).
    - `sources`: standard deviations of the systematic sources by name (mm, 1, rad);
      `None`: none.
    - `dof`: degrees of freedom of the probe sigma the fit covariance was scaled by
      (`ProfileFit.sigma.dof`; `inf` when known).
    """
    f = fit.feature
    ts = at_fractions(f, at)
    val, jac = deviation_and_jacobian(f, fit.values, ts)
    i = int(np.argmax(np.abs(val))) if at == "worst" else 0
    cov = fit.covariance
    if cov is None:
        raise AnalysisError(
            f"feature {f.id!r}: the fit has no covariance (too few points or a singular fit); "
            "no uncertainty, no decision"
        )
    g = jac[i]
    u_fit = float(math.sqrt(max(float(g @ np.asarray(cov) @ g), 0.0)))
    u_sys = float(u_systematic(f, ts[i : i + 1], sources or {})[0])
    qs, ns, _ = nominal_points(f, tuple(float(t) for t in ts))
    q, n = qs[i], ns[i]
    return Characteristic(
        feature=f.id,
        at=at_label(float(ts[i])),
        t=float(ts[i]),
        point=(float(q[0]), float(q[1])),
        normal=(float(n[0]), float(n[1])),
        mean=float(val[i]),
        u_fit=u_fit,
        u_systematic=u_sys,
        tolerance=tuple(map(float, f.tolerance)),
        n_points=int(fit.n - len(fit.outliers)),
        dof_fit=float(dof),
        coordinate=f.tolerance_on,
        scale=drawn_scale(f),
    )


def characteristic_arrays(batch, feature_id: str, *, at: str = "mid", sources=None):
    """Characteristics of one feature over all parts of a `BatchFit`: the vectorised
    [`feature_characteristic`][] (the same model, one compiled call).

    **Returns:** `(mean, u_fit, u_systematic, t)`, each `(P,)`; `NaN` where the part
    did not measure the feature or its fit has no covariance.
    """
    f = batch.profile[feature_id]
    ts = at_fractions(f, at)
    values = batch.values(feature_id)
    cov = batch.covariance(feature_id)
    measured = np.all(np.isfinite(values), axis=1)
    devs = np.where(measured[:, None], values, 0.0)
    val, jac = deviation_and_jacobian(f, devs, ts)
    i = np.argmax(np.abs(val), axis=1) if at == "worst" else np.zeros(len(val), dtype=int)
    rows = np.arange(len(val))
    g = jac[rows, i]
    u2 = np.einsum("pi,pij,pj->p", g, cov, g)
    u_fit = np.sqrt(np.maximum(u2, 0.0))
    u_fit = np.where(np.isfinite(u2), u_fit, np.nan)
    u_sys_t = u_systematic(f, ts, dict(sources or {}))
    mean = np.where(measured, val[rows, i], np.nan)
    return mean, np.where(measured, u_fit, np.nan), u_sys_t[i], ts[i]

"""Feature models of a turned profile, fitted through :func:`least_squares`.

The model of a probe trigger is exact for a ball probe: the ball centre lies
on the feature offset outward by the ball radius, so the residual of a trigger
is its signed distance to the deviated feature minus the ball radius
(positive = outside the material). Parameters are deviations from nominal:

- line: ``offset`` (mm, along the outward normal), ``rotation`` (rad, CCW in
  the drawing frame, about the nominal mid-point);
- arc: ``center_x``, ``center_z`` (mm), ``radius`` (mm); fixing ``radius``
  (`FitOptions.fix`) gives the fixed-radius arc.

The joint profile fit (:func:`fit_profile_joint`) shares the machine-to-part
transform parameters (centre-line offset, Z shift, X and Z scale errors) over
all features; any of them, and any feature parameter, can be fixed.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..geometry import Feature, machine_to_part, rotate
from ._failure import fit_failure
from ._options import FitOptions
from .lsq import LsqResult, Status, least_squares


def geometry_args(feature: Feature):
    """Nominal geometry of a feature as arrays (data, not static structure), so one
    compiled model serves every feature of a kind."""
    # NumPy from the drawing's numbers (the values of `feature.midpoint`, `.normal`):
    # no eager JAX operation when a study is fitted
    if feature.kind == "line":
        p0, p1 = np.asarray(feature.p0, dtype=float), np.asarray(feature.p1, dtype=float)
        d = p1 - p0
        d = d / np.sqrt(np.sum(d**2))
        normal = feature.side * np.array([d[1], -d[0]])  # left_normal, outward side
        return ((p0 + p1) / 2, normal, np.asarray(0.0), np.asarray(1.0))
    return (
        np.asarray(feature.center, dtype=float),
        np.zeros(2),
        np.asarray(float(feature.radius)),
        np.asarray(float(feature.sense)),
    )


def line_distance(points, geom, dev):
    """Signed distance of `points` to a line deviated by `dev` (offset, rotation),
    `geom` from [`geometry_args`][] (positive outward)."""
    mid, normal, _, _ = geom
    return (points - mid - dev[0] * normal) @ rotate(normal, dev[1])


def arc_distance(points, geom, dev):
    """Signed distance of `points` to an arc deviated by `dev` (centre x, z,
    radius), `geom` from [`geometry_args`][] (positive outward)."""
    centre, _, radius, sense = geom
    v = points - centre - dev[:2]
    return sense * (jnp.sqrt(jnp.sum(v * v, axis=-1)) - (radius + dev[2]))


@functools.cache
def feature_residuals(kind: str, free: tuple[int, ...]):
    """Residual function ``fn(y, args)`` of a feature kind (``"line"``/``"arc"``).

    ``y`` holds the free parameters (indices ``free`` into the kind's parameter
    vector; the others stay zero); ``args = (points, geometry, ball_radius)``
    with ``points`` ``(n, 2)`` ball centres in the part frame and ``geometry``
    from the nominal feature. The function object is cached, so every fit of a
    kind with the same point count reuses one compiled solve.
    """
    nparams = 2 if kind == "line" else 3
    distance = line_distance if kind == "line" else arc_distance
    idx = jnp.array(free, dtype=int)

    def fn(y, args):
        points, geom, ball_radius = args
        dev = jnp.zeros(nparams).at[idx].set(y)
        return distance(points, geom, dev) - ball_radius

    fn.__name__ = f"{kind}_residuals"
    return fn


def surface_and_nominal(feature: Feature, centres, values, ball_radius):
    """Measured surface points (ball-corrected along the fitted feature's outward
    normal) and their nearest nominal points, `(n, 2)` each: what
    `feature.outward_normal(centres, values)` and `feature.closest_point` give, in
    NumPy (closed forms: a JAX program compiled per feature and count cost more)."""
    p = np.asarray(centres, dtype=float)
    values = np.asarray(values, dtype=float)
    if feature.kind == "line":
        (mid,), (normal,) = feature.drawn_at(np.array([0.5]))
        fitted = feature.drawn_at(np.array([0.5]), values)[1][0]
        surface = p - ball_radius * fitted
        return surface, surface - ((surface - mid) @ normal)[:, None] * normal
    centre = np.asarray(feature.center, dtype=float)
    v = p - (centre + values[:2])
    surface = p - ball_radius * feature.sense * v / np.linalg.norm(v, axis=-1, keepdims=True)
    u = surface - centre
    return surface, centre + feature.radius * u / np.linalg.norm(u, axis=-1, keepdims=True)


def padded_size(n: int) -> int:
    """Point-count bucket: the next power of two, at least 8 (fewer compilations)."""
    return max(8, 1 << (int(n) - 1).bit_length())


@dataclass(frozen=True, eq=False)
class FeatureFit:
    """Fitted deviation of one feature, its uncertainty and its diagnostics.

    ``values``/``std_errors``/``covariance`` are over all the feature's
    parameters (fixed ones have value 0 and zero variance). ``lines`` are the
    probe-file lines of the points; ``outliers`` indices into them.
    ``error_vectors`` are measured surface points minus their nominal points
    (part frame, mm).
    """

    feature: Feature
    values: np.ndarray
    std_errors: np.ndarray | None
    covariance: np.ndarray | None
    points: np.ndarray
    residuals: np.ndarray
    weights: np.ndarray
    outliers: np.ndarray
    lines: np.ndarray
    nominal_points: np.ndarray
    error_vectors: np.ndarray
    method: str
    result: LsqResult = field(repr=False)
    fixed: tuple[str, ...] = ()

    @property
    def id(self) -> str:
        return self.feature.id

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.feature.param_names

    @property
    def n(self) -> int:
        return len(self.points)

    @property
    def residual_dof(self) -> int:
        """Degrees of freedom of this feature's own residuals: inliers minus free parameters."""
        return int(self.n - len(self.outliers) - (len(self.values) - len(self.fixed)))

    @property
    def residual_sd(self) -> float:
        """This feature's own residual sd, $\\sqrt{\\sum r_i^2/\\nu}$ over its inliers
        (mm; NaN without degrees of freedom). A diagnostic only: the covariance of a
        profile fit is scaled by the part's pooled probe sigma (`ProfileFit.sigma`)."""
        dof = self.residual_dof
        if dof <= 0:
            return float("nan")
        keep = np.ones(self.n, dtype=bool)
        keep[np.asarray(self.outliers, dtype=int)] = False
        return float(np.sqrt(np.sum(np.asarray(self.residuals)[keep] ** 2) / dof))

    @property
    def converged(self) -> bool:
        return bool(self.result.converged)

    def as_dict(self) -> dict:
        se = self.std_errors if self.std_errors is not None else [None] * len(self.values)
        return {
            "feature": self.id,
            "type": self.feature.kind,
            "method": self.method,
            "n_points": self.n,
            "parameters": {
                name: {"value": float(v), "std_error": None if s is None else float(s)}
                for name, v, s in zip(self.param_names, self.values, se, strict=True)
            },
            "fixed": list(self.fixed),
            "residual_sd": self.residual_sd if np.isfinite(self.residual_sd) else None,
            "residual_dof": self.residual_dof,
            "outlier_lines": [int(self.lines[i]) for i in self.outliers],
            "covariance": None if self.covariance is None else np.asarray(self.covariance).tolist(),
            "status": self.result.status.name,
        }

    def __repr__(self) -> str:
        body = ", ".join(
            f"{n}={v * (1 if n != 'rotation' else 1):+.6g}"
            + ("" if self.std_errors is None else f"±{s:.2g}")
            for n, v, s in zip(
                self.param_names,
                self.values,
                self.std_errors if self.std_errors is not None else self.values * 0,
                strict=True,
            )
        )
        n_out = len(self.outliers)
        return f"FeatureFit({self.id!r}, {self.method}, n={self.n}, {body}, outliers={n_out})"


def fit_feature(
    feature: Feature,
    centres,
    *,
    ball_radius: float,
    options: FitOptions = FitOptions(),
    lines=None,
    throw: bool = True,
) -> FeatureFit:
    """Fit one feature's deviation to ball-centre points in the part frame.

    **Arguments:**

    - `feature`: a nominal Line or Arc.
    - `centres`: ``(n, 2)`` ball centres, part frame, mm, radius X.
    - `ball_radius`: stylus ball radius (mm).
    - `options`: the [`FitOptions`][]: `method` ``"lsq"`` (plain) or ``"robust"``
      (uses `loss`, `scale`); `sigma`, the known probe repeatability, scales the
      covariance instead of the residual variance; the feature's entry of `fix`,
      parameter names held at zero (``{"fillet": ("radius",)}`` for a fixed-radius
      arc); `rtol`, `atol`, `max_steps`. One solve of the engine's
      Levenberg-Marquardt, whatever its `solver`.
    - `lines`: file line per point, kept for reports.

    **Returns:** a :class:`FeatureFit`.
    """
    fix = options.fix.get(feature.id, ())
    free = free_parameters(feature, fix)
    centres = np.asarray(centres, dtype=float)
    n = len(centres)
    check_point_count(feature, n, len(free))
    fn = feature_residuals(feature.kind, tuple(free))
    n_pad = padded_size(n)
    padded = np.vstack([centres, np.repeat(centres[:1], n_pad - n, axis=0)])
    weights = np.r_[np.ones(n), np.zeros(n_pad - n)]
    res = least_squares(
        fn,
        np.zeros(len(free)),  # NumPy: the solve takes it as it is (no program to convert)
        (padded, geometry_args(feature), np.asarray(float(ball_radius))),
        weights=weights,
        loss=options.solve_loss,
        scale=options.scale,
        sigma=options.sigma,
        solver=options.engine_solver(),
        throw=False,
    )
    if throw and res.status is not Status.SUCCESSFUL:
        raise fit_failure(feature, res, np.arange(1, n + 1) if lines is None else lines)
    values, cov = embed_free(feature.nparams, free, res.params, res.covariance)
    se = None if cov is None else np.sqrt(np.diag(cov))
    surface, nominal = map(
        np.asarray, surface_and_nominal(feature, centres, values, float(ball_radius))
    )
    weights = np.asarray(res.weights)[:n]
    outliers = np.asarray(res.outliers, dtype=int)
    return FeatureFit(
        feature=feature,
        values=values,
        std_errors=se,
        covariance=cov,
        points=centres,
        residuals=np.asarray(res.residuals)[:n],
        weights=weights,
        outliers=outliers,
        lines=np.arange(1, n + 1) if lines is None else np.asarray(lines),
        nominal_points=nominal,
        error_vectors=surface - nominal,
        method=options.method if options.method == "lsq" else f"robust/{options.loss}",
        result=res,
        fixed=tuple(fix),
    )


def embed_free(nparams: int, free, params, cov=None):
    """Values `(nparams,)` and covariance `(nparams, nparams)` (or None) over all of
    a feature's parameters from those of its `free` ones (fixed ones 0)."""
    free = list(free)
    values = np.zeros(nparams)
    values[free] = np.asarray(params)
    if cov is None:
        return values, None
    full = np.zeros((nparams, nparams))
    full[np.ix_(free, free)] = np.asarray(cov)
    return values, full


def free_parameters(feature: Feature, fix: Sequence[str]) -> list[int]:
    """Indices of the parameters not in `fix`; every fixed name must exist."""
    for name in fix:
        if name not in feature.param_names:
            raise InputError(
                f"cannot fix {name!r}: parameters are {', '.join(feature.param_names)}",
                feature=feature.id,
                value=name,
            )
    return [i for i, n in enumerate(feature.param_names) if n not in fix]


def check_point_count(feature: Feature, n: int, n_free: int) -> None:
    """`n` points must leave at least one degree of freedom."""
    if n <= n_free:
        raise InputError(
            f"{n} points are too few to fit {n_free} parameters with an uncertainty "
            f"(need at least {n_free + 1})",
            feature=feature.id,
            value=n,
        )


def to_part_frame(study_transform, machine_points):
    """Ball centres in the part frame from machine coordinates (radius X); concrete
    points take `geometry.machine_to_part`'s NumPy path (no JAX dispatch)."""
    return np.asarray(machine_to_part(np.asarray(machine_points, dtype=float), study_transform))

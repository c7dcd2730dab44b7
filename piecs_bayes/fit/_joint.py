"""Joint fit of a whole profile with shared machine-to-part parameters.

All features are fitted at once together with corrections to the transform
parameters (centre-line offset ``x_centre``, work offset ``z_offset``, axis
scale errors ``scale_x``/``scale_z``, ``rotation``) that every point shares.
Transform parameters are fixed unless freed; any feature parameter can be
fixed (``"fillet.radius"``). Freeing ``x_centre`` together with every diameter
offset is singular (they move the same way): the result then has no
covariance and says why, so fix a reference feature.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..geometry import MachineTransform, Profile, machine_to_part
from ._features import FeatureFit
from ._options import FitOptions
from ._profile_result import ProfileFit
from ._sigma import probe_sigma
from .lsq import least_squares

TRANSFORM_PARAMS = ("x_centre", "z_offset", "scale_x", "scale_z", "rotation")


def _parse_fix(profile: Profile, fix: dict) -> dict[str, set]:
    """`FitOptions.fix` as a set of names per feature; every feature and name must be
    the profile's."""
    out: dict[str, set] = {f.id: set() for f in profile.features}
    for fid, names in fix.items():
        for name in names:
            item = f"{fid}.{name}"
            if fid not in out:
                raise InputError(
                    f"cannot fix {item!r}: unknown feature {fid!r}; "
                    f"the profile has {', '.join(profile.ids)}",
                    feature=fid,
                    value=item,
                )
            if name not in profile[fid].param_names:
                raise InputError(
                    f"cannot fix {item!r}: {fid!r} has parameters "
                    f"{', '.join(profile[fid].param_names)}",
                    feature=fid,
                    value=item,
                )
            out[fid].add(name)
    return out


def fit_profile_joint(
    profile: Profile,
    feature_ids,
    machine_points,
    *,
    ball_radius: float,
    transform: MachineTransform = MachineTransform(),
    free_transform=(),
    options: FitOptions = FitOptions(),
    lines=None,
    part: str | None = None,
) -> ProfileFit:
    """Fit every feature and the freed transform parameters together.

    **Arguments:**

    - `feature_ids`, `machine_points`: per point, its feature and its ball
      centre in **machine** coordinates (radius X, mm).
    - `transform`: the nominal machine->part transform (the study's).
    - `free_transform`: names from ``TRANSFORM_PARAMS`` to estimate.
    - `options`: the [`FitOptions`][]: `method` (``"lsq"``, the default: the linear
      loss; ``"robust"``: `loss` with the scale `scale`, as for
      :func:`least_squares`), `fix` (feature parameters held at nominal, every one
      the profile's), the probe sigma rule of :func:`fit_profile` (`sigma` known,
      else the residuals of the whole joint fit with the `declared` repeatability as
      prior worth `declared_dof`) and the engine's tolerances.

    **Returns:** a :class:`ProfileFit` whose ``transform`` holds the estimated
    transform corrections with standard uncertainties, and whose feature fits
    carry their blocks of the joint covariance.
    """
    _check_free_transform(free_transform)
    loss = options.solve_loss
    feature_ids = np.asarray(feature_ids).astype(str)
    pts = np.asarray(machine_points, dtype=float)
    lines = np.arange(1, len(pts) + 1) if lines is None else np.asarray(lines)
    fixed = _parse_fix(profile, options.fix)
    measured = [f for f in profile.features if np.any(feature_ids == f.id)]
    unmeasured = tuple(f.id for f in profile.features if f not in measured)
    order = np.concatenate([np.flatnonzero(feature_ids == f.id) for f in measured])
    groups = _groups(measured, feature_ids, fixed)
    free_t = tuple(TRANSFORM_PARAMS.index(n) for n in free_transform)
    base = transform.as_numpy()  # NumPy here (no program per operation), JAX in the trace
    y0 = {
        "features": {f.id: np.zeros(len(free)) for f, _, free in groups},
        "transform": np.zeros(len(free_t)),
    }
    n_par = sum(len(fr) for _, _, fr in groups) + len(free_t)
    if len(order) <= n_par:
        raise InputError(f"{len(order)} points are too few for a joint fit of {n_par} parameters")
    ref = options.reference_sigma
    res = least_squares(
        _joint_residuals(groups, free_t, base),
        y0,
        (pts[order], np.asarray(float(ball_radius))),
        loss=loss,
        scale=options.scale if loss != "linear" else None,
        sigma=ref,  # covariance at a reference sigma, rescaled to the probe sigma below
        solver=options.engine_solver(),
    )
    ps = _probe_sigma(res, n_par, options, part)
    cov = None if res.covariance is None else np.asarray(res.covariance) * (ps.value / ref) ** 2
    t_final = _final_transform(base, free_t, res)
    fits = {}
    for f, sl, free in groups:
        centres = machine_to_part(pts[order][sl], t_final)
        fits[f.id] = _feature_fit(
            f, sl, free, res, cov, centres, lines[order][sl], ball_radius, loss, fixed[f.id]
        )
    out = ProfileFit(profile, fits, "joint", unmeasured, part, sigma=ps)
    object.__setattr__(out, "transform", _transform_info(free_transform, res, cov))
    object.__setattr__(out, "result", res)
    return out


def _check_free_transform(free_transform) -> None:
    for name in free_transform:
        if name not in TRANSFORM_PARAMS:
            raise InputError(
                f"unknown transform parameter {name!r}; "
                f"expected one of {', '.join(TRANSFORM_PARAMS)}",
                value=name,
            )


def _probe_sigma(res, n_par, options: FitOptions, part):
    """The probe sigma rule of `fit_profile` on the joint fit's inlier residuals."""
    sigma, declared, declared_dof = options.sigma, options.declared, options.declared_dof
    inl = np.ones(len(res.residuals), dtype=bool)
    inl[list(res.outliers)] = False
    return probe_sigma(
        float(np.sum(np.asarray(res.residuals)[inl] ** 2)), int(inl.sum()) - n_par,
        declared=declared if sigma is None else sigma, declared_dof=declared_dof,
        known=sigma is not None, what=f"part {part!r}" if part is not None else "part",
    )  # fmt: skip


def _groups(measured, feature_ids, fixed) -> list[tuple]:
    """`(feature, slice of its points in the fit's point order, free indices)`."""
    groups, start = [], 0
    for f in measured:
        k = int(np.sum(feature_ids == f.id))
        free = tuple(i for i, n in enumerate(f.param_names) if n not in fixed[f.id])
        groups.append((f, slice(start, start + k), free))
        start += k
    return groups


def _joint_residuals(groups, free_t, base):
    """`fn(y, (points, ball_radius))` of the joint fit: every feature's residuals
    (its points in the machine->part transform `base` + the freed corrections)."""

    def fn(y, args):
        points, rb = args
        t = jnp.asarray(base)
        t = t.at[np.array(free_t, dtype=int)].add(y["transform"]) if free_t else t
        part_pts = machine_to_part(points, t)
        res = []
        for f, sl, free in groups:
            dev = jnp.zeros(f.nparams).at[jnp.array(free, dtype=int)].set(y["features"][f.id])
            res.append(f.signed_distance(part_pts[sl], dev) - rb)
        return jnp.concatenate(res)

    return fn


def _feature_fit(f, sl, free, res, cov, centres, lines, ball_radius, loss, fixed) -> FeatureFit:
    """The `FeatureFit` of feature `f` (points `sl` of the joint fit `res`, part-frame
    `centres` under the fitted transform) with its block of the joint covariance
    `cov` (ravel order: features by sorted id, then the transform)."""
    names = res.param_names
    values = np.zeros(f.nparams)
    values[list(free)] = np.asarray(res.params["features"][f.id])
    fcov = None
    if cov is not None:
        idx = [names.index(f"features.{f.id}[{j}]") for j in range(len(free))]
        fcov = np.zeros((f.nparams, f.nparams))
        fcov[np.ix_(free, free)] = cov[np.ix_(idx, idx)]
    surface = centres - ball_radius * np.asarray(
        f.outward_normal(jnp.asarray(centres), jnp.asarray(values))
    )
    nominal = np.asarray(f.closest_point(jnp.asarray(surface)))
    outl = set(res.outliers)
    local_out = np.array([i - sl.start for i in range(sl.start, sl.stop) if i in outl], dtype=int)
    return FeatureFit(
        feature=f,
        values=values,
        std_errors=None if fcov is None else np.sqrt(np.diag(fcov)),
        covariance=fcov,
        points=centres,
        residuals=np.asarray(res.residuals)[sl],
        weights=np.asarray(res.weights)[sl],
        outliers=local_out,
        lines=lines,
        nominal_points=nominal,
        error_vectors=surface - nominal,
        method="joint/" + (loss if loss != "linear" else "lsq"),
        result=res,
        fixed=tuple(sorted(fixed)),
    )


def _transform_info(free_transform, res, cov) -> dict:
    """`{name: {"value", "std_error"}}` of the freed transform corrections."""
    tvals = np.asarray(res.params["transform"])
    tinfo = {}
    for k, name in enumerate(free_transform):
        se = None
        if cov is not None:
            i = res.param_names.index(f"transform[{k}]")
            se = float(np.sqrt(cov[i, i]))
        tinfo[name] = {"value": float(tvals[k]), "std_error": se}
    return tinfo


def _final_transform(base, free_t, res):
    """The fitted transform, a `MachineTransform` (NumPy arithmetic: loading data)."""
    t = np.array(base, dtype=float)
    if free_t:
        t[list(free_t)] += np.asarray(res.params["transform"])
    return MachineTransform(*map(float, t))

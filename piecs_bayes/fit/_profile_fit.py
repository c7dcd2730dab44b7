"""Fit every feature of a profile from one part's probe points."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np

from ..errors import AnalysisError, InputError
from ..geometry import Profile
from ._failure import fit_failure
from ._features import fit_feature
from ._options import FitOptions
from ._part_fit import check_feature_ids, fit_part
from ._profile_result import ProfileFit
from ._sigma import pooled_residuals, probe_sigma


def fit_profile(
    profile: Profile,
    feature_ids,
    centres,
    *,
    ball_radius: float,
    options: FitOptions = FitOptions(),
    lines=None,
    file: str | None = None,
    part: str | None = None,
) -> ProfileFit:
    """Fit each feature of ``profile`` to its points.

    **Arguments:**

    - `feature_ids`: ``(n,)`` feature id of each point.
    - `centres`: ``(n, 2)`` ball centres in the part frame (mm, radius X).
    - `ball_radius`: the stylus ball radius (mm).
    - `options`: the [`FitOptions`][]: method, loss and scale, the probe sigma rule
      (`sigma` known; else, the default, the covariances are scaled by the residual
      sd **pooled over every feature** of the part, combined with the `declared`
      repeatability as a prior worth `declared_dof` degrees of freedom,
      `piecs_bayes.fit._sigma`; never by one feature's own residuals, which say
      little with few points), `fix`, `min_points` (fewer, but some, points on a
      feature is an error) and the solver: ``"auto"`` (the default): the batch
      path's kernel (`fit_profiles(solver="auto")`: the same objective, statistics
      and LM retries), every feature of the part in one compiled call whose trace
      is kept across processes (`_config.persisted`); the same results to the
      solvers' precision, ~40x faster than ``"lm"`` on the demo part
      (`_part_fit`); ``"lm"`` (the reference): each feature by `least_squares`
      (the engine's Levenberg-Marquardt), one solve per feature. With neither
      `sigma` nor `declared`, ``"auto"`` is ``"lm"`` (its two passes).
    - `file`, `lines`: where the points came from, for messages and reports.

    **Returns:** a :class:`ProfileFit`; features with no points are listed as
    unmeasured (they are left as drawn by compensation).
    """
    solver, sigma, declared = options.solver, options.sigma, options.declared
    if solver not in ("lm", "auto"):
        raise InputError(f"unknown solver {solver!r}; expected 'lm' or 'auto'")
    feature_ids = np.asarray(feature_ids).astype(str)
    centres = np.asarray(centres, dtype=float)
    lines = np.arange(1, len(centres) + 1) if lines is None else np.asarray(lines)
    # the reference sigma of the solves: the known or declared one (it also sets the
    # scale of the stationarity test, so it should be realistic); with neither, a first
    # pass at 1 mm gives the pooled residual sd and the solves are repeated at it
    ref = options.reference_sigma
    if solver == "auto" and (sigma is not None or declared is not None):
        return fit_part(profile, feature_ids, centres, lines, options, file, part, ref,
                        ball_radius)  # fmt: skip
    check_feature_ids(profile, feature_ids, lines, file)
    data = (profile, feature_ids, centres, lines, file, ball_radius, part)
    fits, unmeasured = _fit_features(data, options, ref)
    if sigma is None and declared is None and fits:
        ss, dof = pooled_residuals(fits.values())
        if dof > 0 and ss > 0:
            ref = float(np.sqrt(ss / dof))
            fits, _ = _fit_features(data, options, ref)
    if not fits:
        raise InputError("no probe point belongs to any profile feature", file=file)
    ss, dof = pooled_residuals(fits.values())
    try:
        ps = probe_sigma(
            ss, dof, declared=declared if sigma is None else sigma,
            declared_dof=options.declared_dof, known=sigma is not None,
            what=f"part {part!r}" if part is not None else "part",
        )  # fmt: skip
    except InputError as exc:
        raise InputError(str(exc), file=file) from None
    return ProfileFit(
        profile,
        scale_fits(fits, ps.value / ref),
        options.method,
        tuple(unmeasured),
        part,
        sigma=ps,
    )


def _fit_features(data, options: FitOptions, ref: float):
    """Every measured feature fitted with covariances at the reference sigma `ref`;
    `data` = `(profile, feature_ids, centres, lines, file, ball_radius, part)`; a
    failed feature raises `fit_failure`'s error, naming the part and the file."""
    profile, feature_ids, centres, lines, file, ball_radius, part = data
    at_ref = replace(options, sigma=ref)
    fits, unmeasured = {}, []
    for f in profile.features:
        m = feature_ids == f.id
        k = int(m.sum())
        if k == 0:
            unmeasured.append(f.id)
            continue
        need = options.min_points[f.kind]
        if k < need:
            raise InputError(
                f"{k} point(s) are too few for a {f.kind}: at least {need} are needed",
                file=file,
                feature=f.id,
                value=k,
            )
        try:
            fits[f.id] = fit_feature(
                f, centres[m], ball_radius=ball_radius, options=at_ref, lines=lines[m]
            )
        except AnalysisError as exc:
            raise fit_failure(f, exc.result, lines[m], part=part, file=file) from None
    return fits, unmeasured


def scale_fits(fits: dict, factor: float) -> dict:
    """Feature fits with their covariances multiplied by `factor`**2 (the part's probe
    sigma over the sigma the solves used)."""
    out = {}
    for fid, f in fits.items():
        cov = None if f.covariance is None else np.asarray(f.covariance) * factor**2
        se = None if cov is None else np.sqrt(np.diag(cov))
        out[fid] = dataclasses.replace(f, covariance=cov, std_errors=se)
    return out

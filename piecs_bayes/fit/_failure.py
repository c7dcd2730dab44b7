"""The error of a feature fit that gave no trustworthy answer, naming what to do.

A robust fit that down-weights a point of a feature probed at its minimum count (a
line's 3 points with a chip under one) keeps fewer effective points than its
parameters plus one: no residual is left to judge the points by, and no covariance.
[`fit_failure`][] says so with the feature, the part, the file, the down-weighted
points by line with their residuals and weights, and the ways out.
"""

from __future__ import annotations

import numpy as np

from ..errors import AnalysisError, shown_files
from .lsq import LsqResult, Status

DOWN_WEIGHTED = 0.5
"""A point whose robust weight is below this is named as down-weighted."""


def fit_failure(feature, res: LsqResult, lines, *, part=None, file=None) -> AnalysisError:
    """The `AnalysisError` (with `res` as its result) for `feature`'s failed fit;
    `lines`: the probe file's line of each of its points."""
    where = [f"feature {feature.id!r}"]
    if part is not None:
        where.append(f"part {part!r}")
    if file:
        where.append(f"probe file {shown_files(file)}")
    head = ", ".join(where)
    if res.status is Status.DEGENERATE:
        return AnalysisError(f"{head}: {_degenerate(feature, res, lines)}", result=res)
    return AnalysisError(
        f"{head}: least-squares fit failed: {res.status.message} (after {res.steps} steps)",
        result=res,
    )


def _degenerate(feature, res: LsqResult, lines) -> str:
    lines = np.asarray(lines)
    n = len(lines)
    rw = np.asarray(res.robust_weights, dtype=float)[:n]
    e = np.asarray(res.residuals, dtype=float)[:n]
    p = len(res.param_names)
    low = np.flatnonzero(rw < DOWN_WEIGHTED)
    shown = ", ".join(
        f"line {int(lines[i])} (residual {1e3 * e[i]:+.1f} um, weight {rw[i]:.2f})"
        for i in low[np.argsort(rw[low])][:3]
    )
    named = f"; down-weighted: {shown}" if shown else ""
    setting = f"[fit] min_points_{feature.kind}"
    return (
        f"the robust fit keeps {rw.sum():.2f} effective points of {n} for {p} parameters"
        f"{named}: no residual is left to judge the points by, so neither the fit nor its "
        f"uncertainty can be trusted. Re-probe the feature, probe more points on it "
        f'({setting} sets the least), or fit with [fit] method = "lsq" to keep every '
        "point at full weight"
    )

"""Stability of a process in time order: individuals and moving-range charts.

Individuals chart $\\bar y \\pm 3\\overline{MR}/d_2(2)$, moving-range
chart upper limit $D_4\\overline{MR}$ ($D_4 = 1 + 3d_3/d_2 = 3.267$); rule 1 (a point
beyond 3 sigma), a run of `run_length` (8) points on one side of the centre line, a
trend of `trend_length` (7) points steadily rising or falling; moving ranges above
their limit (reported); and the most likely step position (two-sample t over all split
points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import AnalysisError, InputError
from ._sigma import d3_constant

#: the run rule's points on one side of the centre line (Western Electric)
RUN_LENGTH = 8
#: the trend rule's points steadily rising or falling (AIAG)
TREND_LENGTH = 7


@dataclass(frozen=True)
class StabilityResult:
    """Individuals / moving-range chart of values in time order, with rule violations.

    Index tuples refer to positions in the input. `step_index` is the first index
    of the most likely second segment, `step_t` its two-sample t statistic
    (using the moving-range sigma); a value above ~4 is a clear step.
    """

    n: int
    center: float
    sigma: float
    lcl: float
    ucl: float
    mr_center: float
    mr_ucl: float
    beyond_limits: tuple[int, ...]
    run_points: tuple[int, ...]
    trend_points: tuple[int, ...]
    mr_beyond: tuple[int, ...]
    runs: tuple[tuple[int, int], ...]
    trends: tuple[tuple[int, int], ...]
    step_index: int | None
    step_size: float
    step_t: float
    run_length: int
    trend_length: int

    @property
    def out_of_control(self) -> tuple[int, ...]:
        """Indices flagged by any rule (sorted)."""
        return tuple(
            sorted(set(self.beyond_limits) | set(self.run_points) | set(self.trend_points))
        )

    @property
    def in_control(self) -> bool:
        """True when no individuals-chart rule fires (moving ranges are only reported)."""
        return not self.out_of_control

    def reasons(self) -> list[str]:
        """Human-readable list of violations."""
        out = []
        if self.beyond_limits:
            out.append(
                f"{len(self.beyond_limits)} point(s) beyond 3 sigma: {list(self.beyond_limits)}"
            )
        for a, b in self.runs:
            out.append(f"run of {b - a + 1} points on one side of the centre line: {a}..{b}")
        for a, b in self.trends:
            out.append(f"trend of {b - a + 1} points steadily rising or falling: {a}..{b}")
        if self.mr_beyond:
            out.append(f"moving range above its limit at {list(self.mr_beyond)}")
        if self.step_index is not None and abs(self.step_t) > 4.0:
            out.append(
                f"likely step of {self.step_size:+.4g} before index {self.step_index}"
                f" (t = {self.step_t:.1f})"
            )
        return out

    def __repr__(self) -> str:
        state = "in control" if self.in_control else "OUT OF CONTROL"
        head = (
            f"StabilityResult(n={self.n}, {state}, centre={self.center:.6g}, "
            f"limits=[{self.lcl:.6g}, {self.ucl:.6g}], MR UCL={self.mr_ucl:.4g})"
        )
        return "\n".join([head, *(f"  - {r}" for r in self.reasons())])


def _runs(mask: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    """Maximal runs of True in `mask` with length >= `min_len` as (start, end) inclusive."""
    out = []
    start = None
    for i, v in enumerate(np.append(mask, False)):
        if v and start is None:
            start = i
        elif not v and start is not None:
            if i - start >= min_len:
                out.append((start, i - 1))
            start = None
    return out


def stability_check(
    values,
    *,
    center: float | None = None,
    sigma: float | None = None,
    run_length: int = RUN_LENGTH,
    trend_length: int = TREND_LENGTH,
) -> StabilityResult:
    """Individuals and moving-range chart with Western Electric / Nelson rules.

    **Arguments:**

    - `values`: one value per part, in production order.
    - `center`, `sigma`: known centre line and sigma (Phase II); by default the mean
      and $\\overline{MR}/d_2(2)$ of `values` (Phase I).
    - `run_length`: points in a row on one side of the centre line that signal a
      shift (8, Western Electric; Nelson uses 9); `trend_length`: points in a row
      steadily rising or falling (7, as AIAG; Nelson's 6 raises ~6 % false alarms in
      30 stable points).

    Moving ranges above $D_4\\overline{MR}$ are reported but do not make the process
    "out of control": about 1 % of the moving ranges of a stable process exceed the
    limit, so a long run almost always has one.

    **Returns:** a [`StabilityResult`][] with the limits, flagged indices and the
    most likely step position.
    """
    y = _checked_values(values, run_length, trend_length)
    mr = np.abs(np.diff(y))
    mr_bar = float(mr.mean())
    d2 = 2.0 / math.sqrt(math.pi)
    d4 = 1.0 + 3.0 * d3_constant(2) / d2
    c = float(y.mean()) if center is None else float(center)
    s = mr_bar / d2 if sigma is None else float(sigma)
    if not s > 0.0:
        raise AnalysisError("the moving-range sigma is zero: all values are equal")
    lcl, ucl = c - 3 * s, c + 3 * s
    beyond = tuple(int(i) for i in np.flatnonzero((y > ucl) | (y < lcl)))
    runs, run_pts = _run_rule(y, c, run_length)
    trends, trend_pts = _trend_rule(y, trend_length)
    mr_ucl = d4 * (mr_bar if sigma is None else s * d2)
    mr_beyond = tuple(int(i) + 1 for i in np.flatnonzero(mr > mr_ucl))
    step_index, step_size, step_t = _likely_step(y, s)
    return StabilityResult(
        n=int(y.size),
        center=c,
        sigma=s,
        lcl=lcl,
        ucl=ucl,
        mr_center=mr_bar,
        mr_ucl=mr_ucl,
        beyond_limits=beyond,
        run_points=run_pts,
        trend_points=trend_pts,
        mr_beyond=mr_beyond,
        runs=tuple(runs),
        trends=tuple(trends),
        step_index=step_index,
        step_size=step_size,
        step_t=step_t,
        run_length=int(run_length),
        trend_length=int(trend_length),
    )


def _checked_values(values, run_length: int, trend_length: int) -> np.ndarray:
    """The values as a finite 1-D array of at least 3; the rule lengths checked."""
    y = np.asarray(values, dtype=float).ravel()
    if y.size < 3:
        raise InputError(f"a stability check needs at least 3 values, got {y.size}")
    if not np.all(np.isfinite(y)):
        bad = int(np.flatnonzero(~np.isfinite(y))[0])
        raise InputError(
            f"value {bad} is not a finite number: {float(y[bad])!r}", value=float(y[bad])
        )
    if run_length < 2 or trend_length < 3:
        raise InputError(
            f"run_length must be >= 2 and trend_length >= 3, got {run_length}, {trend_length}"
        )
    return y


def _run_rule(y, c, run_length):
    """Runs of `run_length` points on one side of the centre line `c`, and their points."""
    runs = _runs(y > c, run_length) + _runs(y < c, run_length)
    runs.sort()
    run_pts = tuple(sorted({i for a, b in runs for i in range(a, b + 1)}))
    return runs, run_pts


def _trend_rule(y, trend_length):
    """Runs of `trend_length` points steadily rising or falling, and their points."""
    d = np.diff(y)
    trends = _runs(d > 0, trend_length - 1) + _runs(d < 0, trend_length - 1)
    trends = sorted((a, b + 1) for a, b in trends)  # diff index i links points i and i+1
    trend_pts = tuple(sorted({i for a, b in trends for i in range(a, b + 1)}))
    return trends, trend_pts


def _likely_step(y, s) -> tuple[int | None, float, float]:
    """First index, size and two-sample t of the most likely step (sigma `s`)."""
    n = y.size
    step_index, step_size, step_t = None, 0.0, 0.0
    if n >= 4:
        k = np.arange(2, n - 1)
        csum = np.cumsum(y)
        m1 = csum[k - 1] / k
        m2 = (csum[-1] - csum[k - 1]) / (n - k)
        t = (m2 - m1) / (s * np.sqrt(1.0 / k + 1.0 / (n - k)))
        j = int(np.argmax(np.abs(t)))
        step_index, step_size, step_t = int(k[j]), float(m2[j] - m1[j]), float(t[j])
    return step_index, step_size, step_t

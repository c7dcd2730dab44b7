r"""Probe points corrected to a calibrated probe, and the calibration as a source.

With `[probe] calibration`, the distance from a ball centre to the surface is the
calibrated effective radius $r(\theta)$, not one radius. [`calibrated_points`][] moves
every point along its contact normal by $r(\theta) - r_0$ when it is read, so that every
fit, with one radius $r_0$, sees the surface where the calibration puts it. A probe
lobes at the contact normal, the part's actual surface's: a first pass corrects along
the probe file's approach or the nominal inward normal ([`approach_directions`][]), a
second along the normals of each part's features fitted to those points
([`contact_directions`][]). [`radius_components`][] gives the calibration's
uncertainty as independent components (`fit.RadiusComponents`), one systematic source
correlated over every point; [`lobing_pretravel`][] is a lobing probe for the
simulator; [`calibration_warnings`][] what outputs say of a calibration made at another
feed or too old. The correction and its accuracy: docs/uncertainty.md, section 5.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..fit import RadiusComponents, to_part_frame
from ..io import ProbeCalibration, approach_angle


def approach_directions(profile, feature_ids, machine_points, transform, approach=None):
    """Unit approach directions ``(n, 2)``: `approach` when given, else the nominal
    feature's inward normal at each point (part frame, radius X)."""
    if approach is not None:
        a = np.asarray(approach, dtype=float)
        return a / np.linalg.norm(a, axis=1, keepdims=True)
    ids = np.asarray(feature_ids).astype(str)
    part = to_part_frame(transform, machine_points)
    out = np.zeros_like(part)
    for f in profile.features:
        rows = ids == f.id
        if rows.any():
            out[rows] = -f.drawn_normal(part[rows])
    missing = sorted(set(ids) - set(profile.ids))
    if missing:
        raise InputError(f"points of unknown feature {missing[0]!r}", feature=missing[0])
    return out


def calibrated_points(
    profile, feature_ids, machine_points, transform, calibration: ProbeCalibration,
    approach=None, parts=None,
) -> np.ndarray:  # fmt: skip
    """The ball centres moved along their contact normal by $r(\\theta) - r_0$
    (machine frame, radius X): what a probe of one radius $r_0$ would have recorded.

    Two passes (module docstring): along `approach` (or the nominal normals), then
    along each part's fitted normals (`parts`: a part id per point; None: one part).
    """
    pts = np.asarray(machine_points, dtype=float)
    a = approach_directions(profile, feature_ids, pts, transform, approach)
    first = pts + _shift(calibration, a)[:, None] * a
    a = contact_directions(profile, feature_ids, to_part_frame(transform, first), a, parts)
    return pts + _shift(calibration, a)[:, None] * a


def _shift(calibration: ProbeCalibration, a) -> np.ndarray:
    return calibration.radius(approach_angle(a)) - calibration.r0


MAX_TURN = 0.25
"""rad: a fitted normal further than this from the first pass's is not used (a fit
of a few points gone astray); the point keeps its first-pass direction."""


def contact_directions(profile, feature_ids, part_points, first, parts=None) -> np.ndarray:
    """Unit inward contact normals ``(n, 2)`` of each point from its feature fitted to
    the points of its part (`part_points`, part frame): a line's normal from a total
    least squares line through the ball centres (at least 2 points), an arc's from a
    geometric circle fit of them (at least 4 points, its radius within half of the
    nominal centre-path radius). Where a feature has fewer points, the fit fails, or a
    normal turns more than `MAX_TURN` from `first`, `first` is kept."""
    ids = np.asarray(feature_ids).astype(str)
    pts = np.asarray(part_points, dtype=float)
    out = np.array(first, dtype=float, copy=True)
    groups = np.zeros(len(ids), dtype=np.int64) if parts is None else np.unique(
        np.asarray(parts).astype(str), return_inverse=True)[1]  # fmt: skip
    for f in profile.features:
        rows = np.flatnonzero(ids == f.id)
        if rows.size == 0:
            continue
        g = np.unique(groups[rows], return_inverse=True)[1]
        fit = _line_normals if f.kind == "line" else _arc_normals
        inward = fit(f, pts[rows], g)
        turn = np.arccos(np.clip(np.sum(inward * out[rows], axis=1), -1.0, 1.0))
        ok = np.isfinite(turn) & (turn <= MAX_TURN)
        out[rows[ok]] = inward[ok]
    return out


def _sums(g, *columns) -> list[np.ndarray]:
    return [np.bincount(g, weights=c) for c in columns]


def _gsum(g, w, k) -> np.ndarray:
    return np.bincount(g, weights=w, minlength=k)


def _line_normals(f, p, g) -> np.ndarray:
    """Per group: the normal of the total least squares line, on the nominal side."""
    n, sx, sz = _sums(g, np.ones(len(g)), p[:, 0], p[:, 1])
    mx, mz = sx / n, sz / n
    dx, dz = p[:, 0] - mx[g], p[:, 1] - mz[g]
    cxx, czz, cxz = _sums(g, dx * dx, dz * dz, dx * dz)
    phi = 0.5 * np.arctan2(2.0 * cxz, cxx - czz)  # the direction of largest spread
    normal = np.stack([np.cos(phi + np.pi / 2), np.sin(phi + np.pi / 2)], axis=1)
    nominal = np.asarray(f.normal, dtype=float)
    normal *= np.where(normal @ nominal < 0.0, -1.0, 1.0)[:, None]
    normal[n < 2] = np.nan
    return -normal[g]


def _arc_normals(f, p, g, iterations: int = 30) -> np.ndarray:
    """Per group: the normal from a geometric circle fit (Gauss-Newton from the
    nominal centre) of the ball centres, on the nominal side."""
    k = int(g.max()) + 1
    c = np.tile(np.asarray(f.center, dtype=float), (k, 1))
    for _ in range(iterations):
        step = _circle_step(p, g, c, k)
        c = c - step
        if np.all(np.abs(step[np.isfinite(step)]) < 1e-13 * (1.0 + f.radius)):
            break
    v = p - c[g]
    d = np.hypot(v[:, 0], v[:, 1])
    n = np.bincount(g, minlength=k)
    rho = np.bincount(g, weights=d, minlength=k) / n
    bad = (n < 4) | ~np.isfinite(rho) | (np.abs(rho - _centre_path(f, p, g, k)) > 0.5 * f.radius)
    out = -f.sense * v / d[:, None]
    out[bad[g]] = np.nan
    return out


def _circle_step(p, g, c, k) -> np.ndarray:
    """One Gauss-Newton step of each group's centre for the residuals ``|p - c| -
    rho`` with the radius rho eliminated (the mean distance, given the centre)."""
    v = p - c[g]
    d = np.hypot(v[:, 0], v[:, 1])
    u = v / d[:, None]
    n = np.bincount(g, minlength=k).astype(float)
    r = d - (_gsum(g, d, k) / n)[g]
    j = -(u - np.stack([_gsum(g, u[:, 0], k), _gsum(g, u[:, 1], k)], axis=1)[g] / n[g, None])
    a, b, e = _gsum(g, j[:, 0] ** 2, k), _gsum(g, j[:, 0] * j[:, 1], k), _gsum(g, j[:, 1] ** 2, k)
    r0, r1 = _gsum(g, j[:, 0] * r, k), _gsum(g, j[:, 1] * r, k)
    with np.errstate(divide="ignore", invalid="ignore"):
        det = a * e - b * b
        return np.stack([(e * r0 - b * r1) / det, (a * r1 - b * r0) / det], axis=1)


def _centre_path(f, p, g, k) -> np.ndarray:
    """The nominal radius of the path of the ball centres (the arc's radius plus or
    minus the ball's, from the points' mean distance to the nominal centre)."""
    d = np.hypot(*(p - np.asarray(f.center, dtype=float)).T)
    return np.bincount(g, weights=d, minlength=k) / np.bincount(g, minlength=k)


def lobing_pretravel(probe: ProbeCalibration, ball_radius: float):
    """A simulated probe whose effective radius is `probe`'s r(theta): the pretravel of
    `jobs.simulate_gauge` (a function of the angle ``atan2(u_x, u_z)`` of the touch)
    that makes a ball of `ball_radius` trip r(theta) from the surface, theta the
    contact normal's angle."""
    import math

    def pretravel(angle: float) -> float:
        theta = math.atan2(math.cos(angle), math.sin(angle))  # u = (sin, cos) of it
        return float(ball_radius - probe.radius([theta])[0])

    return pretravel


def radius_components(calibration: ProbeCalibration | None) -> RadiusComponents | None:
    """The calibration's covariance as the independent sources the propagations take."""
    return None if calibration is None else RadiusComponents.from_calibration(calibration)


def calibration_warnings(probe, today=None) -> list[str]:
    """What the outputs and the report must say of a study's calibration
    (`io.ProbeSpec`): made at another probing feed than `[probe] feed` (a calibration
    holds at its feed only: the pretravel grows with it), or older than
    `[probe] calibration_max_age_days`. Empty without a calibration."""
    cal = probe.calibration
    if cal is None:
        return []
    out, name = [], cal.source or "the probe calibration"
    if (
        cal.feed is not None
        and probe.feed is not None
        and abs(cal.feed - probe.feed) > 1e-6 * probe.feed
    ):
        out.append(
            f"{name} was made at a probing feed of {cal.feed:g} mm/min, the study probes at "
            f"{probe.feed:g} mm/min ([probe] feed): the pretravel depends on the feed; "
            "calibrate at the gauging feed"
        )
    age = cal.age_days(today)
    if age is not None and age > probe.calibration_max_age_days:
        out.append(
            f"{name} is {age:g} days old (made {cal.date}), more than "
            f"[probe] calibration_max_age_days = {probe.calibration_max_age_days:g}: "
            "re-qualify the probe"
        )
    return out

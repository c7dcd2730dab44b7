r"""Probe points corrected to a calibrated probe, and the calibration as a source.

With `[probe] calibration`, the distance from a recorded ball centre to the surface is
the calibrated effective radius $r(\theta)$ at the point's approach angle, not one
radius. [`calibrated_points`][] moves every point along its approach by
$r(\theta) - r_0$ when it is read, so that every fit, with its one radius $r_0$, sees
the surface where the calibration puts it; the approach is the probe file's or the
nominal feature's inward normal ([`approach_directions`][]).
[`radius_components`][] gives the calibration's uncertainty as independent components
(`fit.RadiusComponents`), one systematic source correlated over every point, for the
linearised propagation, the budget and the Bayesian fit; [`lobing_pretravel`][] is the
pretravel of a lobing probe for the simulator; [`calibration_warnings`][] what the
outputs must say of a calibration made at another feed or too old.

The correction and its accuracy: docs/uncertainty.md, section 5.
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
            out[rows] = -np.asarray(f.outward_normal(part[rows]))
    missing = sorted(set(ids) - set(profile.ids))
    if missing:
        raise InputError(f"points of unknown feature {missing[0]!r}", feature=missing[0])
    return out


def calibrated_points(
    profile, feature_ids, machine_points, transform, calibration: ProbeCalibration, approach=None
) -> np.ndarray:
    """The ball centres moved along their approach by $r(\\theta) - r_0$ (machine
    frame, radius X): what a probe of one radius $r_0$ would have recorded."""
    a = approach_directions(profile, feature_ids, machine_points, transform, approach)
    shift = calibration.radius(approach_angle(a)) - calibration.r0
    return np.asarray(machine_points, dtype=float) + shift[:, None] * a


def lobing_pretravel(probe: ProbeCalibration, ball_radius: float):
    """A simulated probe whose effective radius is `probe`'s r(theta): the pretravel of
    `jobs.simulate_gauge` (a function of its angle ``atan2(u_x, u_z)`` of the move)
    that makes a ball of `ball_radius` trip r(theta) from the surface."""
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

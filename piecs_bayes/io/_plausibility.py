"""Plausibility of probe points before any fit: no number from data that could not be right.

A fit always returns numbers, even for points a metre off their feature, for a file read
with the wrong X mode or units, or for a profile probed on the wrong side. So
[`check_probe_data`][] checks every point against its nominal feature (part frame, ball
centre one ball radius outside the surface) before fitting: its distance from where it
should be (`max_distance`, default 3 x (`max_correction` + the feature's largest
tolerance), at least `FLOOR_MM` = 0.5 mm so that a chip stays an outlier for the robust
fit; [`feature_limits`][]), how far it lies beyond either end of its feature
(`max_outside`), and duplicates ([`drop_duplicates`][]: `"drop"` keeps the first and
warns with a [`PlausibilityWarning`][], `"error"` refuses). A point beyond a limit is an
`InputError` naming file, line, feature and distance, with the likely cause found by
trying the usual setup mistakes on every point of the part.

The limits and the causes tried: docs/formats.md, "Plausibility, before any fit".
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..errors import InputError
from ..geometry import machine_to_part, profile_kind

#: the smallest default distance limit (mm): a chip under the stylus (0.1-0.3 mm) is an
#: outlier for the robust fit, not an error; setup mistakes move points by a ball
#: radius or more (1-2 mm), a diameter read as a radius by the radius itself
FLOOR_MM = 0.5


class PlausibilityWarning(UserWarning):
    """Probe data that were used, but not as written (duplicates dropped)."""


def feature_limits(profile, max_correction: float, settings=None) -> dict[str, tuple]:
    """`{feature id: (max_distance, max_outside)}` in mm (see the module doc)."""
    settings = dict(settings or {})
    out = {}
    for f in profile.features:
        d = settings.get("max_distance")
        if d is None:
            d = max(3.0 * (max_correction + max(abs(t) for t in f.tolerance)), FLOOR_MM)
        out[f.id] = (float(d), float(settings.get("max_outside", d)))
    return out


def _measure(f, pts: np.ndarray, ball_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Per point: distance of the ball centre from its nominal place (signed: + outside),
    and how far (mm) it lies beyond the ends of the feature along it."""
    if f.kind == "line":
        p0, p1 = np.asarray(f.p0), np.asarray(f.p1)
        u = (p1 - p0) / f.length
        n = f.side * np.array([u[1], -u[0]])  # side * left normal of travel (`left_normal`)
        d = (pts - (p0 + p1) / 2) @ n
        s = (pts - p0) @ u
        beyond = np.maximum(np.maximum(-s, s - f.length), 0.0)
        return d - ball_radius, beyond
    c = np.asarray(f.center)
    v = pts - c
    rho = np.hypot(v[:, 0], v[:, 1])
    d = f.sense * (rho - f.radius)
    a0, sweep = f._angles()
    ang = np.arctan2(v[:, 0], v[:, 1])
    delta = np.mod((ang - a0) * math.copysign(1.0, sweep), 2 * math.pi)
    span = abs(sweep)
    out = np.where(delta > span, np.minimum(delta - span, 2 * math.pi - delta), 0.0)
    return d - ball_radius, out * f.radius


def _violations(profile, feature, pts, ball_radius, limits):
    """Boolean mask of implausible points and the (distance, beyond) arrays."""
    dist = np.zeros(len(pts))
    beyond = np.zeros(len(pts))
    bad = np.zeros(len(pts), dtype=bool)
    for f in profile.features:
        m = feature == f.id
        if not m.any():
            continue
        d, b = _measure(f, pts[m], ball_radius)
        lim_d, lim_o = limits[f.id]
        dist[m], beyond[m] = d, b
        bad[m] = (np.abs(d) > lim_d) | (b > lim_o) | ~np.isfinite(d)
    return bad, dist, beyond


#: the likely cause that is the study's `[profile] kind` (named with the study file)
_KIND_CAUSE = (
    "the ball centres lie on the material side of the profile: check [profile] kind "
    "(external for a shaft, internal for a bore)"
)


def _likely_cause(profile, feature, machine, transform, ball_radius, limits, dist) -> str:
    """The setup mistake that explains the data, tried on every point of the part."""
    t = transform
    base = np.asarray(machine_to_part(machine, t))
    candidates = [
        ("X is written as a radius, not a diameter: check [probe] x_mode", machine * [2.0, 1.0]),
        ("X is written as a diameter, not a radius: check [probe] x_mode", machine * [0.5, 1.0]),
        ("the file is in inches: check [study] units", machine * 25.4),
        ("the file is in mm: check [study] units", machine / 25.4),
    ]
    for text, m in candidates:
        pts = np.asarray(machine_to_part(m, t))
        if not _violations(profile, feature, pts, ball_radius, limits)[0].any():
            return text
    if t.z_offset != 0.0:
        pts = base + [0.0, 2.0 * t.z_offset]
        if not _violations(profile, feature, pts, ball_radius, limits)[0].any():
            return "the Z work offset has the wrong sign: check [machine] z_offset"
    inside = np.abs(dist + 2.0 * ball_radius) <= 0.5 * ball_radius  # centres inside
    if np.mean(inside) > 0.5:
        return _KIND_CAUSE
    for f in profile.features:
        m = feature == f.id
        if f.kind == "arc" and m.any() and np.median(np.abs(dist[m] + 2 * ball_radius)) < 0.05:
            return f"the ball centres lie on the material side of arc {f.id!r}: check its direction"
    return (
        "a chip or dirt under the stylus, a point filed under the wrong feature, or a wrong "
        "work offset; remove the line or raise [plausibility] max_distance"
    )


def _hash(strings: np.ndarray) -> np.ndarray:
    """A uint64 hash of each string of a ``<U`` array (equal strings, equal hashes)."""
    a = np.ascontiguousarray(strings, dtype=str)
    codes = a.view(np.uint32).reshape(len(a), -1)
    h = np.zeros(len(a), dtype=np.uint64)
    for k in range(codes.shape[1]):
        h = h * np.uint64(1000003) ^ codes[:, k]
    return h


def drop_duplicates(probe, *, policy: str = "drop"):
    """`probe` without repeated triggers (same part, feature and coordinates)."""
    # only rows of equal hashes can repeat a trigger: sort the hashes (a million rows in
    # a fraction of a second), then compare those rows' records
    if len(probe) < 2:
        return probe
    x, z = probe.points[:, 0], probe.points[:, 1]
    key = _hash(probe.part) ^ (_hash(probe.feature) * np.uint64(0x9E3779B97F4A7C15))
    for v in (x, z):
        key = key * np.uint64(1000003) ^ (v + 0.0).view(np.uint64)  # + 0.0: -0.0 is 0.0
    ordered = np.sort(key)
    same = ordered[1:] == ordered[:-1]
    if not same.any():
        return probe
    cand = np.isin(key, ordered[1:][same])
    rows = np.flatnonzero(cand)
    key = np.rec.fromarrays([probe.part[rows], probe.feature[rows], x[rows], z[rows]])
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    dup = np.zeros(len(probe), dtype=bool)
    dup[rows] = True
    dup[rows[first]] = False
    if not dup.any():
        return probe
    i = int(np.flatnonzero(dup)[0])
    j = int(rows[first[inverse.reshape(-1)[np.searchsorted(rows, i)]]])
    where = f"line {int(probe.lines[i])} repeats line {int(probe.lines[j])}"
    fid = str(probe.feature[i])
    if policy == "error":
        raise InputError(
            f"{int(dup.sum())} repeated trigger(s) ({where}, feature {fid!r}): a "
            "trigger counted twice shrinks every uncertainty; remove them or set "
            '[plausibility] duplicates = "drop"',
            file=probe.file,
            feature=fid,
        )
    warnings.warn(
        f"{probe.file_text}: dropped {int(dup.sum())} repeated trigger(s) with identical "
        f"coordinates ({where}, feature {fid!r}); each counts once",
        PlausibilityWarning,
        stacklevel=2,
    )
    return probe.select(~dup)


def _as_written(point, x_mode: str, units: str) -> str:
    """A machine point (mm, radius X) as the probe file writes it."""
    k = 25.4 if units == "in" else 1.0
    x, z = float(point[0]) / k, float(point[1]) / k
    if x_mode == "diameter":
        return f"x = {2.0 * x:.10g} (a diameter), z = {z:.10g} in the file"
    return f"x = {x:.10g} (a radius), z = {z:.10g} in the file"


def check_probe_data(
    probe,
    profile,
    *,
    transform,
    ball_radius,
    max_correction,
    settings=None,
    study_file=None,
    x_mode: str = "radius",
    units: str = "mm",
):
    """Duplicates handled (see `drop_duplicates`), then every point checked (module doc).

    `study_file` names the study in an error whose likely cause is its `[profile]
    kind`; `x_mode` and `units` (the study's `[probe] x_mode` and `[study] units`) say
    how the file wrote the point a message quotes.

    **Returns:** the probe data to fit. **Raises:** `InputError` for an implausible point
    (naming the study file and `profile.kind` first when that is the likely cause).
    """
    settings = dict(settings or {})
    probe = drop_duplicates(probe, policy=settings.get("duplicates", "drop"))
    limits = feature_limits(profile, max_correction, settings)
    pts = np.asarray(machine_to_part(probe.points, transform))
    bad, dist, beyond = _violations(profile, probe.feature, pts, ball_radius, limits)
    if not bad.any():
        return probe
    # the worst offender, located, with the likely cause over its part
    score = np.where(bad, np.abs(dist) + beyond, -1.0)
    i = int(np.argmax(score))
    part = probe.part[i]
    sel = probe.part == part
    cause = _likely_cause(
        profile, probe.feature[sel], probe.points[sel], transform, ball_radius, limits, dist[sel]
    )
    fid = str(probe.feature[i])
    lim_d, lim_o = limits[fid]
    if abs(dist[i]) > lim_d or not np.isfinite(dist[i]):
        why = (
            "[plausibility] max_distance"
            if "max_distance" in settings
            else "the larger of 0.5 mm and 3 x (max_correction + tolerance)"
        )
        what = f"ball centre {dist[i]:+.4g} mm from its nominal place (limit {lim_d:.3g} mm: {why})"
    else:
        what = f"point {beyond[i]:.4g} mm beyond the end of the feature (limit {lim_o:.3g} mm)"
    what = f"{_as_written(probe.points[i], x_mode, units)}: {what}"
    n_bad, n_part = int(bad[sel].sum()), int(sel.sum())
    if cause == _KIND_CAUSE and study_file is not None:
        kind = profile_kind(profile)
        other = "internal" if kind == "external" else "external"
        raise InputError(
            f"profile.kind: {kind!r} does not fit the probe data: the ball centres of part "
            f"{str(part)!r} lie on the material side of an {kind} profile ({n_bad} of "
            f"{n_part} points beyond the limits; the worst at {probe.file_text}:"
            f"{int(probe.lines[i])}, feature {fid!r}: {what}); for "
            f'{"a bore" if other == "internal" else "a shaft"}, write [profile] kind = "{other}"',
            file=study_file,
            value=kind,
        )
    raise InputError(
        f"implausible probe point of part {str(part)!r}: {what}; {n_bad} of {n_part} points "
        f"of the part are beyond the limits; likely cause: {cause}",
        file=probe.file,
        line=int(probe.lines[i]),
        feature=fid,
        value=float(dist[i]),
    )

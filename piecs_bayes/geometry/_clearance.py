r"""Where a probe ball can touch a turned profile, and how far a path keeps from it.

A ball of radius $r$ touches a feature at a nominal contact point $q$ with its centre at
$c = q + r\,n$ ([`ball_centres`][]). [`probe_window`][] gives the usable fractions
`(t0, t1)` of a feature (the longest run of them; None when the ball cannot touch it
anywhere): the ball at contact keeps `end_clearance` from every other feature and does
not cut into its own, the point lies $r$ + `end_clearance` from a sharp or free end and
`end_clearance` from a tangent junction, and (with `standoff`) the probe move's start
keeps as far from every feature. [`point_distance`][] and [`path_distance`][] measure
how far a point or a straight move keeps from a profile's polylines
([`feature_polyline`][]): exact between segments, arcs sampled with a chord error under
0.1 µm (`CHORD_ERROR_MM`).

The rules: docs/models/gauging.md, "Where a ball can touch a profile".
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ._curves import Arc, Feature

#: largest distance of an arc's polyline from the arc (mm)
CHORD_ERROR_MM = 1e-4
_WINDOW_SAMPLES = 257


def feature_polyline(f: Feature) -> np.ndarray:
    """The feature as a polyline `(m, 2)` (lines: the two ends)."""
    if not isinstance(f, Arc):
        return np.array([f.p0, f.p1], dtype=float)
    sweep = f.length / f.radius
    step = 2.0 * math.acos(max(1.0 - CHORD_ERROR_MM / f.radius, -1.0))
    m = max(8, int(math.ceil(sweep / max(step, 1e-6))) + 1)
    return np.asarray(f.point_at(np.linspace(0.0, 1.0, m)), dtype=float)


def ball_centres(f: Feature, t, ball_radius: float):
    """Nominal contact points, outward normals and ball centres at fractions `t`
    (NumPy: the nominal geometry of `Line` and `Arc`, without a JAX dispatch)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if isinstance(f, Arc):
        a0, sweep = f._angles()
        ang = a0 + t * sweep
        radial = np.stack([np.sin(ang), np.cos(ang)], axis=-1)
        q = np.asarray(f.center, dtype=float) + f.radius * radial
        n = f.sense * radial
    else:
        p0, p1 = np.asarray(f.p0, dtype=float), np.asarray(f.p1, dtype=float)
        q = p0 + t[:, None] * (p1 - p0)
        n = np.broadcast_to(_line_normal(f), q.shape)
    return q, n, q + ball_radius * n


@functools.lru_cache(maxsize=1024)
def _line_normal(f) -> np.ndarray:
    """A line's outward normal, from its own model (once per line)."""
    mid = 0.5 * (np.asarray(f.p0, dtype=float) + np.asarray(f.p1, dtype=float))
    n = np.asarray(f.outward_normal(mid[None]), dtype=float)[0]
    n.flags.writeable = False
    return n


def point_distance(p, polyline: np.ndarray) -> np.ndarray:
    """Distance of each point `(k, 2)` to a polyline `(m, 2)`."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
    a, b = polyline[:-1], polyline[1:]
    d = b - a
    dd = np.maximum(np.sum(d * d, axis=1), 1e-300)
    w = p[:, None, :] - a[None]
    s = np.clip(np.sum(w * d[None], axis=2) / dd[None], 0.0, 1.0)
    gap = w - s[..., None] * d[None]
    return np.sqrt(np.min(np.sum(gap * gap, axis=2), axis=1))


def _cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def path_distance(p0, p1, polyline: np.ndarray) -> float:
    """Smallest distance between the segment `p0`-`p1` and a polyline (0 where they cross)."""
    p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
    a, b = polyline[:-1], polyline[1:]
    r, s = p1 - p0, b - a
    den = _cross(r[None], s)
    qp = a - p0[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross(qp, s) / den
        u = _cross(qp, r[None]) / den
    crossing = (den != 0.0) & (t >= 0.0) & (t <= 1.0) & (u >= 0.0) & (u <= 1.0)
    if np.any(crossing):
        return 0.0
    ends = min(point_distance(np.stack([p0, p1]), polyline))
    seg = np.stack([p0, p1])
    back = min(point_distance(polyline, seg))
    return float(min(ends, back))


def _usable(profile, index: int, t, ball_radius, end_clearance, standoff, polys):
    """Which fractions `t` of feature `index` are usable contact points (module doc)."""
    f = profile.features[index]
    t = np.atleast_1d(np.asarray(t, dtype=float))
    _, n, c = ball_centres(f, t, ball_radius)
    s = c + standoff * n
    ok = np.ones(t.size, dtype=bool)
    slack = 2.0 * CHORD_ERROR_MM  # the chords of a concave arc lie inside it
    for j, poly in enumerate(polys):
        d = point_distance(c, poly)
        ok &= d >= (ball_radius - slack if j == index else ball_radius + end_clearance)
        if standoff > 0.0:
            ok &= point_distance(s, poly) >= ball_radius + standoff - slack
    along = t * f.length
    last = len(profile.features) - 1
    start_kind = profile.junctions[index - 1] if index > 0 else "free"
    end_kind = profile.junctions[index] if index < last else "free"

    def margin(kind):
        return end_clearance if kind == "tangent" else ball_radius + end_clearance

    ok &= along >= margin(start_kind) - 1e-12
    ok &= f.length - along >= margin(end_kind) - 1e-12
    return ok


def probe_window(
    profile, index: int, ball_radius: float, end_clearance: float, standoff: float = 0.0
):
    """The usable fractions `(t0, t1)` of feature `index` of `profile` (see the module
    docstring), or None when the ball cannot touch it anywhere. With `standoff` > 0 the
    probe move's start, `standoff` beyond the ball at contact along the normal, must
    also keep `standoff` from every feature (a concave corner narrows the window).

    The longest run of usable fractions on a grid of 257, its edges then found by
    bisection to 1e-6 of the feature."""
    polys = [feature_polyline(g) for g in profile.features]

    def usable(t):
        return _usable(profile, index, t, ball_radius, end_clearance, standoff, polys)

    t = np.linspace(0.0, 1.0, _WINDOW_SAMPLES)
    ok = usable(t)
    if not np.any(ok):
        return None
    edges = np.diff(np.concatenate([[0], ok.astype(int), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    k = int(np.argmax(stops - starts))
    lo_i, hi_i = int(starts[k]), int(stops[k])

    def edge(inside, outside):
        for _ in range(20):
            mid = 0.5 * (inside + outside)
            inside, outside = (mid, outside) if usable(mid)[0] else (inside, mid)
        return inside

    t0 = float(t[lo_i]) if lo_i == 0 else edge(float(t[lo_i]), float(t[lo_i - 1]))
    t1 = float(t[hi_i]) if hi_i == t.size - 1 else edge(float(t[hi_i]), float(t[hi_i + 1]))
    return t0, t1

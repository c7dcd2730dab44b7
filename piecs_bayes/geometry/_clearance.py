r"""Where a probe ball can touch a turned profile, and how far a path keeps from it.

A ball of radius $r$ touches a feature at a nominal contact point $q$, centre
$c = q + r\,n$ ([`ball_centres`][]), coming along $-n$ from $s = c + \text{standoff}\,n$.
[`probe_window`][] gives the usable fractions `(t0, t1)` of a feature (None: none):
the ball does not cut into its feature; along its move it keeps `end_clearance` from
the parts of other features above the tangent at $q$ ([`rising_distance`][]; the rest
cannot be touched first) and from its feature's junction points ([`junction_points`][]);
the point keeps `end_clearance` along the feature from a junction, $r$ more from a free
end ([`end_margins`][]); the ball at $s$ keeps `standoff` from every feature. Checked
against the exact contact (`first_contact`). [`point_distance`][], [`path_distance`][]:
distances to polylines ([`feature_polyline`][]), arcs within 0.1 µm (`CHORD_ERROR_MM`).

The rules and their reasons: docs/models/gauging.md, "Where a ball can touch a profile".
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
    return f.drawn_at(np.linspace(0.0, 1.0, m))[0]


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
    n = np.array(f.drawn_at(0.5)[1])
    n.flags.writeable = False
    return n


def point_distance(p, polyline: np.ndarray) -> np.ndarray:
    """Distance of each point `(k, 2)` to a polyline `(m, 2)`."""
    return _point_segments(p, polyline[:-1], polyline[1:])


#: segments per array operation in `_usable` (memory: points x this x a few floats)
_SEGMENT_CHUNK = 2048


def _least(distance, a, b) -> np.ndarray:
    """`distance(a, b)` (a distance per point to the nearest segment) over the segments
    `a[m]`-`b[m]` taken `_SEGMENT_CHUNK` at a time: the least per point."""
    parts = [distance(a[i : i + _SEGMENT_CHUNK], b[i : i + _SEGMENT_CHUNK])
             for i in range(0, len(a), _SEGMENT_CHUNK)]  # fmt: skip
    return np.min(parts, axis=0)


def _near(a, b, points, reach):
    """The segments `a[m]`-`b[m]` whose bounding box comes nearer than `reach` (+1 nm)
    to the bounding box of `points`: the others are at least `reach` from every point
    and every segment between them, so a test `distance >= reach` passes without them."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    gap = np.maximum(0.0, np.maximum(np.minimum(a, b) - hi, lo - np.maximum(a, b)))
    keep = np.hypot(gap[:, 0], gap[:, 1]) <= reach + 1e-6
    return a[keep], b[keep]


def _segments(polylines) -> tuple[np.ndarray, np.ndarray]:
    """The segments `(a, b)`, each `(m, 2)`, of polylines, all in one array."""
    return (np.concatenate([p[:-1] for p in polylines]),
            np.concatenate([p[1:] for p in polylines]))  # fmt: skip


def _point_segments(p, a, b) -> np.ndarray:
    """Distance of each point `(k, 2)` to the nearest of the segments `a[m]`-`b[m]`."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
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


def _segment_gaps(p0, p1, a, b) -> np.ndarray:
    """Least distances `(k, m)` between the segments `p0[k]`-`p1[k]` and `a[k, m]`-`b[k, m]`
    (0 where they cross)."""

    def to_segment(p, s0, s1):
        d = s1 - s0
        dd = np.maximum(np.sum(d * d, axis=-1), 1e-300)
        u = np.clip(np.sum((p - s0) * d, axis=-1) / dd, 0.0, 1.0)
        return np.linalg.norm(p - s0 - u[..., None] * d, axis=-1)

    q0, q1 = p0[:, None, :], p1[:, None, :]
    r, s = q1 - q0, b - a
    den = _cross(r, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        t, u = _cross(a - q0, s) / den, _cross(a - q0, r) / den
    crossing = (den != 0.0) & (t >= 0.0) & (t <= 1.0) & (u >= 0.0) & (u <= 1.0)
    ends = np.minimum(to_segment(q0, a, b), to_segment(q1, a, b))
    back = np.minimum(to_segment(a, q0, q1), to_segment(b, q0, q1))
    return np.where(crossing, 0.0, np.minimum(ends, back))


def rising_distance(q, n, start, centre, polyline: np.ndarray) -> np.ndarray:
    """Least distance from each probe move `start[k]`-`centre[k]` to the part of
    `polyline` above the tangent at contact `q[k]` (outward normal `n[k]`): the only
    part the ball can touch before `q[k]` (inf where there is none)."""
    return _rising_segments(q, n, start, centre, polyline[:-1], polyline[1:])


def _rising_segments(q, n, start, centre, a, b) -> np.ndarray:
    """[`rising_distance`][] to the segments `a[m]`-`b[m]` (of one polyline or many:
    the least over all of them)."""
    q, n = np.atleast_2d(q), np.atleast_2d(n)
    a, b = a[None], b[None]
    ha = np.sum((a - q[:, None]) * n[:, None], axis=-1)
    hb = np.sum((b - q[:, None]) * n[:, None], axis=-1)
    rise = hb - ha
    frac = np.divide(_ABOVE - ha, rise, out=np.zeros_like(rise), where=rise != 0.0)
    cut = a + frac[..., None] * (b - a)
    a2 = np.where((ha > _ABOVE)[..., None], a, cut)
    b2 = np.where((hb > _ABOVE)[..., None], b, cut)
    gap = _segment_gaps(np.atleast_2d(start), np.atleast_2d(centre), a2, b2)
    return np.min(np.where((ha > _ABOVE) | (hb > _ABOVE), gap, np.inf), axis=1)


#: mm: a point of another feature this far above the tangent at contact or less is not
#: above it (the edge a convex corner shares with the probed feature)
_ABOVE = 1e-9


def end_margins(profile, index: int, ball_radius: float, end_clearance: float):
    """`(start, end)` distances (mm, along the feature) that a contact point keeps from
    the ends of feature `index`: `end_clearance` from a junction (sharp or tangent),
    the ball radius more from a free end of the profile (what lies beyond is not
    drawn)."""
    last = len(profile.features) - 1
    return tuple(
        end_clearance + (ball_radius if free else 0.0) for free in (index == 0, index == last)
    )


def junction_points(profile, index: int) -> list[np.ndarray]:
    """The ends of feature `index` where another feature joins it: an edge at a sharp
    junction (a burr stands there), a tangent point at a smooth one (a deviated
    neighbour steps there)."""
    f, last = profile.features[index], len(profile.features) - 1
    ends = [f.p0] if index > 0 else []
    ends += [f.p1] if index < last else []
    return [np.asarray(e, dtype=float) for e in ends]


def _usable(profile, index: int, t, ball_radius, end_clearance, standoff, polys):
    """Which fractions `t` of feature `index` are usable contact points (module doc).
    Every other feature's segments are checked in one array (the least distance over
    all of them against one threshold: the same test as feature by feature), those
    too far to fail it left out first (`_near`)."""
    f = profile.features[index]
    t = np.atleast_1d(np.asarray(t, dtype=float))
    q, n, c = ball_centres(f, t, ball_radius)
    s = c + standoff * n
    slack = 2.0 * CHORD_ERROR_MM  # the chords of a concave arc lie inside it
    ok = point_distance(c, polys[index]) >= ball_radius - slack  # not cutting into its own
    others = [poly for j, poly in enumerate(polys) if j != index]
    moves = np.concatenate([s, c])
    if others:
        need = ball_radius + end_clearance - slack
        a, b = _near(*_segments(others), moves, need)
        if len(a):
            ok &= _least(lambda a, b: _rising_segments(q, n, s, c, a, b), a, b) >= need
    if standoff > 0.0:
        need = ball_radius + standoff - slack
        a, b = _near(*_segments(polys), s, need)
        if len(a):
            ok &= _least(lambda a, b: _point_segments(s, a, b), a, b) >= need
    for edge in junction_points(profile, index):
        gap = _segment_gaps(s, c, edge[None, None], edge[None, None])[:, 0]
        ok &= gap >= ball_radius + end_clearance - slack
    along = t * f.length
    lo, hi = end_margins(profile, index, ball_radius, end_clearance)
    ok &= along >= lo - 1e-12
    ok &= f.length - along >= hi - 1e-12
    return ok


def probe_window(
    profile, index: int, ball_radius: float, end_clearance: float, standoff: float = 0.0
):
    """The usable fractions `(t0, t1)` of feature `index` of `profile` (see the module
    docstring), or None when the ball cannot touch it anywhere. With `standoff` > 0 the
    probe move starts `standoff` beyond the ball at contact along the normal, and the
    ball there keeps `standoff` from every feature (a concave corner narrows the
    window).

    The longest run of usable fractions on a grid of 257, its edges then refined to
    1e-8 of the feature."""
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
        for _ in range(4):  # 32 steps a round: as 20 halvings, in 4 calls
            ts = np.linspace(inside, outside, 33)
            k = int(np.argmin(usable(ts)[1:])) + 1  # the first unusable one from inside
            inside, outside = float(ts[k - 1]), float(ts[k])
        return inside

    t0 = float(t[lo_i]) if lo_i == 0 else edge(float(t[lo_i]), float(t[lo_i - 1]))
    t1 = float(t[hi_i]) if hi_i == t.size - 1 else edge(float(t[hi_i]), float(t[hi_i + 1]))
    return t0, t1

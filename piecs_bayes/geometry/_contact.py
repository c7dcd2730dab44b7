r"""Where a ball moving in a straight line first touches a turned profile: exact.

A ball of radius $r$ whose centre moves from $p$ along the unit direction $d$,
$c(s) = p + s\,d$, touches a line segment where its distance to the segment's line is
$r$ with the foot inside the segment, or where it is $r$ from an end point; it touches
an arc where $|c(s) - C| = R \pm r$ with the foot inside the arc's sweep, or at an end
point. Each case is a linear or quadratic equation in $s$; the first contact is the
least root (`first_contact` -> [`Contact`][]). No sampling, no polyline: the reference
that the probe window's distance rule (`_clearance`) is checked against, and the
answer to "what does the ball touch first" along a probe move.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from ._curves import Arc, Feature

#: a root this far (mm) before 0 still counts as a contact at the start
_EPS = 1e-12


@dataclass(frozen=True)
class Contact:
    """The first touch of a moving ball: how far its centre travelled (`distance`,
    mm), the feature touched (`feature`, its id), the contact point on it and the
    ball's centre then (part frame, mm, radius X)."""

    distance: float
    feature: str
    point: tuple[float, float]
    centre: tuple[float, float]


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1])


def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1]


def _roots(p, d, centre, rho) -> list[float]:
    """The `s` at which `|p + s d - centre| = rho` (|d| = 1)."""
    w = _sub(p, centre)
    b = _dot(w, d)
    disc = b * b - (_dot(w, w) - rho * rho)
    if rho < 0.0 or disc < 0.0:
        return []
    root = math.sqrt(disc)
    return [-b - root, -b + root]


def _line_hits(f: Feature, p, d, r):
    """`(s, point)` of every contact of the ball with the segment `f` (its interior and
    its two ends)."""
    a, b = f.p0, f.p1
    length = math.dist(a, b)
    e = ((b[0] - a[0]) / length, (b[1] - a[1]) / length)
    m = (e[1], -e[0])
    h0, dm = _dot(_sub(p, a), m), _dot(d, m)
    hits = []
    if dm != 0.0:
        for side in (1.0, -1.0):
            s = (side * r - h0) / dm
            c = (p[0] + s * d[0], p[1] + s * d[1])
            u = _dot(_sub(c, a), e)
            if 0.0 <= u <= length:
                hits.append((s, (a[0] + u * e[0], a[1] + u * e[1])))
    for end in (a, b):
        hits += [(s, end) for s in _roots(p, d, end, r)]
    return hits


def _on_arc(f: Arc, point) -> bool:
    a0, sweep = math.atan2(f.p0[0] - f.center[0], f.p0[1] - f.center[1]), f.sweep
    ang = math.atan2(point[0] - f.center[0], point[1] - f.center[1])
    turned = (ang - a0) % (2.0 * math.pi) if sweep > 0 else (a0 - ang) % (2.0 * math.pi)
    return turned <= abs(sweep) + 1e-12 or turned >= 2.0 * math.pi - 1e-12


def _arc_hits(f: Arc, p, d, r):
    """`(s, point)` of every contact of the ball with the arc `f` (its interior, from
    outside or inside its circle, and its two ends)."""
    big = f.radius
    hits = []
    for rho in (big + r, big - r):
        for s in _roots(p, d, f.center, rho):
            c = (p[0] + s * d[0], p[1] + s * d[1])
            w = _sub(c, f.center)
            size = math.hypot(*w)
            if size == 0.0:
                continue
            foot = (f.center[0] + big * w[0] / size, f.center[1] + big * w[1] / size)
            if _on_arc(f, foot):
                hits.append((s, foot))
    for end in (f.p0, f.p1):
        hits += [(s, end) for s in _roots(p, d, end, r)]
    return hits


def nearest_point(f: Feature, p) -> tuple[float, float]:
    """The point of feature `f` (its nominal segment or arc, ends included) nearest to
    `p`: exact."""
    if isinstance(f, Arc):
        w = _sub(p, f.center)
        size = math.hypot(*w)
        if size > 0.0:
            foot = (f.center[0] + f.radius * w[0] / size, f.center[1] + f.radius * w[1] / size)
            if _on_arc(f, foot):
                return foot
        return min((f.p0, f.p1), key=lambda e: math.dist(e, p))
    a, b = f.p0, f.p1
    ab = _sub(b, a)
    u = min(max(_dot(_sub(p, a), ab) / _dot(ab, ab), 0.0), 1.0)
    return (a[0] + u * ab[0], a[1] + u * ab[1])


def first_contact(
    features: Iterable[Feature],
    ball_radius: float,
    start,
    direction,
    length: float = math.inf,
) -> Contact | None:
    """Where a ball of `ball_radius` whose centre moves from `start` along `direction`
    (normalised here) for at most `length` first touches one of `features` (a
    `Profile` or any lines and arcs), exactly (module docstring); None when it touches
    none. A ball that already overlaps a feature at `start` touches it at distance 0
    (its nearest point)."""
    p = (float(start[0]), float(start[1]))
    norm = math.hypot(float(direction[0]), float(direction[1]))
    if not norm > 0.0:
        raise ValueError(f"direction {tuple(direction)!r} has no length")
    d = (float(direction[0]) / norm, float(direction[1]) / norm)
    best: Contact | None = None
    for f in features:
        near = nearest_point(f, p)
        if math.dist(near, p) < ball_radius:
            hits = [(0.0, near)]
        else:
            hits = (_arc_hits if isinstance(f, Arc) else _line_hits)(f, p, d, ball_radius)
        for s, point in hits:
            if -_EPS <= s <= length and (best is None or s < best.distance):
                s = max(s, 0.0)
                centre = (p[0] + s * d[0], p[1] + s * d[1])
                best = Contact(s, f.id, (float(point[0]), float(point[1])), centre)
    return best

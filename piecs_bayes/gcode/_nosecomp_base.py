"""Shared by the nose-compensation corner rules: lathe tip offsets, the tool
behind a G41/G42 request, and plane geometry on ``(x, z)`` points (drawing
frame: z right, x up; angles counted counter-clockwise from +z).

:func:`tip_offset` is the offset ``(dx, dz)`` from the nose centre to the controlled
point (the imaginary tip) by LinuxCNC's documented lathe orientations 0-9;
:func:`resolve_setting` the side, radius and orientation of a G41/G42 (tool table)
or G41.1/G42.1 (in the block) request, [`UniformNose`][] one nose radius for every tool.
``_EPS = 1e-12`` is the relative size under which a determinant, a distance between
centres or a sweep counts as zero: far below any length a program can state, far
above float64 round-off of millimetre coordinates.

The orientation table: docs/models/nose_compensation.md.
"""

from __future__ import annotations

import math

from ..errors import InputError

_EPS = 1e-12
_TIP = {
    0: (0, 0),
    1: (-1, 1),
    2: (-1, -1),
    3: (1, -1),
    4: (1, 1),
    5: (0, 1),
    6: (-1, 0),
    7: (0, -1),
    8: (1, 0),
    9: (0, 0),
}


def tip_offset(orientation: int, radius: float) -> tuple[float, float]:
    """``(dx, dz)`` from the nose centre to the imaginary tip for a lathe
    orientation 0-9 (0 and 9: the nose centre itself)."""
    if orientation not in _TIP:
        raise InputError(f"tool orientation must be 0-9, got {orientation!r}")
    dx, dz = _TIP[orientation]
    return (dx * radius, dz * radius)


class UniformNose:
    """Stands in for a tool table: every G41/G42 tool has ``radius`` (mm), orientation 0."""

    def __init__(self, radius: float):
        self.radius = float(radius)


def resolve_setting(setting, tools, name: str | None) -> tuple[str, float, int]:
    """``(side, radius, orientation)`` of a G41/G42/G41.1/G42.1 request.

    A negative diameter puts the tool on the other side; the radius returned
    is never negative. Raises InputError when the tool cannot be found.
    """
    where = {"file": name, "line": setting.line}
    if setting.diameter_mm is not None:
        diameter, orientation = setting.diameter_mm, setting.orientation or 0
    elif isinstance(tools, UniformNose):
        diameter, orientation = 2.0 * tools.radius, 0
    elif tools is None:
        raise InputError(
            f"{setting.code} reads the nose radius from a tool table: pass a tool table "
            "or a nose radius",
            **where,
        )
    elif setting.tool is None:
        raise InputError(f"{setting.code} with no tool loaded (T.. M6) and no D word", **where)
    else:
        entry = tools.get(setting.tool)
        if entry is None:
            raise InputError(f"T{setting.tool} is not in the tool table", **where)
        diameter, orientation = entry.diameter_mm, entry.orientation
    side = setting.side
    if diameter < 0:
        side = "left" if side == "right" else "right"
    return side, abs(diameter) / 2.0, int(orientation)


# -- plane vectors, (x, z) -----------------------------------------------------


def _add(p, v, k: float = 1.0):
    return (p[0] + k * v[0], p[1] + k * v[1])


def _sub(p, q):
    return (p[0] - q[0], p[1] - q[1])


def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1]


def _cross(a, b) -> float:
    """z-up cross product in the drawing frame: > 0 when ``b`` is left of ``a``."""
    return a[1] * b[0] - a[0] * b[1]


def _unit(v):
    n = math.hypot(*v)
    return (v[0] / n, v[1] / n)


def _left(d):
    """Unit normal to the left of travel direction ``d`` (drawing frame)."""
    u = _unit(d)
    return (u[1], -u[0])


def _wrap(a: float) -> float:
    """``a`` brought into (-pi, pi]."""
    a = math.fmod(a, 2 * math.pi)
    if a > math.pi:
        a -= 2 * math.pi
    elif a <= -math.pi:
        a += 2 * math.pi
    return a


def _sweep(start, centre, end, ccw: bool) -> float:
    """Angle swept from ``start`` to ``end`` about ``centre`` in the travel
    direction, in (0, 2 pi] (a full turn when the points coincide in angle)."""
    a0 = math.atan2(start[0] - centre[0], start[1] - centre[1])
    a1 = math.atan2(end[0] - centre[0], end[1] - centre[1])
    d = math.fmod((a1 - a0) if ccw else (a0 - a1), 2 * math.pi)
    return d + 2 * math.pi if d <= 0 else d


# -- intersections: the one nearest ``ref`` ------------------------------------


def _meet_lines(p, d, q, e):
    det = _cross(d, e)
    if abs(det) <= _EPS * math.hypot(*d) * math.hypot(*e):
        return None
    k = _cross(_sub(q, p), e) / det
    return _add(p, d, k)


def _meet_line_circle(p, d, c, rho, ref):
    u = _unit(d)
    w = _sub(p, c)
    b = _dot(w, u)
    disc = b * b - (_dot(w, w) - rho * rho)
    if disc < 0:
        return None
    h = math.sqrt(disc)
    return min((_add(p, u, -b - h), _add(p, u, -b + h)), key=lambda q: math.dist(q, ref))


def _meet_circles(c1, r1, c2, r2, ref):
    dist = math.dist(c1, c2)
    if dist <= _EPS * max(r1, r2):
        return None
    a = (dist * dist + r1 * r1 - r2 * r2) / (2 * dist)
    h2 = r1 * r1 - a * a
    if h2 < 0:
        return None
    e = _unit(_sub(c2, c1))
    base = _add(c1, e, a)
    n = (-e[1], e[0])
    h = math.sqrt(h2)
    return min((_add(base, n, h), _add(base, n, -h)), key=lambda q: math.dist(q, ref))

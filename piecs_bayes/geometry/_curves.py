"""Lines and arcs of a turned profile in the XZ half-plane.

Points are stored ``(x, z)``: x radial (radius), z along the spindle axis. The
*drawing frame* puts z to the right and x up; "counter-clockwise", "left of
travel" and positive rotations are meant in that frame.

A feature is a frozen, hashable description of the nominal geometry (so it can
be a static argument to ``jax.jit``); its deviation is a small float64 vector:
line ``(e, theta)``: shift along the outward normal, rotation (rad, CCW) about the
nominal mid-point; arc ``(dcx, dcz, dr)``: centre shift and radius change.

Zero deviation means "as drawn". Signed distances are positive outside the
material (along the outward normal). ``tolerance`` limits the normal deviation (mm);
``tolerance_on`` says on which coordinate the drawing gives it (`_drawn`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import jax.numpy as jnp
import numpy as np


def left_normal(d):
    """Unit normal to the left of travel direction ``d`` (drawing frame, CCW by 90 deg)."""
    d = jnp.asarray(d)
    return jnp.stack([d[..., 1], -d[..., 0]], axis=-1)


def rotate(v, theta):
    """Rotate ``(x, z)`` vectors by ``theta`` radians, CCW in the drawing frame."""
    v = jnp.asarray(v)
    c, s = jnp.cos(theta), jnp.sin(theta)
    x, z = v[..., 0], v[..., 1]
    return jnp.stack([c * x + s * z, -s * x + c * z], axis=-1)


def _norm(v):
    return jnp.sqrt(jnp.sum(jnp.asarray(v) ** 2, axis=-1))


@dataclass(frozen=True)
class Line:
    """A straight feature from ``p0`` to ``p1`` (travel direction p0 -> p1).

    ``side`` is +1 when the outward normal (away from the material) is to the
    left of travel, -1 when it is to the right.
    """

    id: str
    p0: tuple[float, float]
    p1: tuple[float, float]
    side: int = -1
    tolerance: tuple[float, float] = (-0.01, 0.01)
    tolerance_on: str = "normal"

    kind: ClassVar[str] = "line"
    param_names: ClassVar[tuple[str, ...]] = ("offset", "rotation")
    param_units: ClassVar[tuple[str, ...]] = ("mm", "rad")
    nparams: ClassVar[int] = 2

    def __post_init__(self):
        if self.side not in (-1, 1):
            raise ValueError(f"side must be +1 or -1, got {self.side!r}")
        if math.dist(self.p0, self.p1) <= 0.0:
            raise ValueError(f"line {self.id!r} has zero length")

    @property
    def length(self) -> float:
        return math.dist(self.p0, self.p1)

    @property
    def midpoint(self):
        return jnp.array([(self.p0[0] + self.p1[0]) / 2, (self.p0[1] + self.p1[1]) / 2])

    @property
    def direction(self):
        d = jnp.array(self.p1) - jnp.array(self.p0)
        return d / _norm(d)

    @property
    def normal(self):
        """Nominal outward unit normal."""
        return self.side * left_normal(self.direction)

    def actual(self, dev):
        """``(point, direction, outward normal)`` of the deviated line."""
        dev = jnp.asarray(dev)
        point = self.midpoint + dev[0] * self.normal
        return point, rotate(self.direction, dev[1]), rotate(self.normal, dev[1])

    def signed_distance(self, p, dev=None):
        dev = self.zero() if dev is None else dev
        point, _, n = self.actual(dev)
        return jnp.sum((jnp.asarray(p) - point) * n, axis=-1)

    def closest_point(self, p, dev=None):
        dev = self.zero() if dev is None else dev
        _, _, n = self.actual(dev)
        return jnp.asarray(p) - self.signed_distance(p, dev)[..., None] * n

    def outward_normal(self, p, dev=None):
        dev = self.zero() if dev is None else dev
        _, _, n = self.actual(dev)
        return jnp.broadcast_to(n, jnp.shape(p))

    def tangent_at(self, which: str):
        """Unit travel direction at the start (``"start"``) or end (``"end"``)."""
        return self.direction

    def point_at(self, t, dev=None):
        """Point at fraction ``t`` in [0, 1] of the nominal length, on the deviated line."""
        dev = self.zero() if dev is None else dev
        t = jnp.asarray(t)
        nominal = jnp.array(self.p0) + t[..., None] * (jnp.array(self.p1) - jnp.array(self.p0))
        return self.closest_point(nominal, dev)

    def zero(self):
        return jnp.zeros(self.nparams)

    def drawn_at(self, t, dev=None):
        """``(points, outward normals)`` at fractions ``t``, in NumPy: of the nominal
        line, or with ``dev`` (``(p,)``, or ``(..., p)`` for several deviations: results
        ``(..., k, 2)``) what ``point_at(t, dev)`` and its ``outward_normal`` give.
        Geometry read outside a trace (figures, the tool-path grid, clearance, the
        probe plan, simulated probing), without the dozen JAX operations that
        `point_at` and `outward_normal` dispatch one by one, each compiled for
        every new shape."""
        t = np.asarray(t, dtype=float)[..., None]
        p0, p1 = np.asarray(self.p0, dtype=float), np.asarray(self.p1, dtype=float)
        q = p0 + t * (p1 - p0)
        n = self._nominal_normal()
        if dev is None:
            return q, np.broadcast_to(n, q.shape)
        dev = np.asarray(dev, dtype=float)
        e, theta = dev[..., 0, None, None], dev[..., 1, None, None]
        c, s = np.cos(theta), np.sin(theta)
        n_dev = np.concatenate([c * n[0] + s * n[1], -s * n[0] + c * n[1]], axis=-1)
        dist = np.sum((q - ((p0 + p1) / 2 + e * n)) * n_dev, axis=-1, keepdims=True)
        q_dev = q - dist * n_dev
        return q_dev, np.broadcast_to(n_dev, q_dev.shape)

    def drawn_distance(self, p, dev):
        """`signed_distance` of points `p` from the line deviated by `dev`, in NumPy
        (as `drawn_at`)."""
        p0, p1 = np.asarray(self.p0, dtype=float), np.asarray(self.p1, dtype=float)
        n = self._nominal_normal()
        e, theta = np.asarray(dev, dtype=float)
        c, s = math.cos(theta), math.sin(theta)
        n_rot = np.array([c * n[0] + s * n[1], -s * n[0] + c * n[1]])
        return (np.asarray(p, dtype=float) - ((p0 + p1) / 2 + e * n)) @ n_rot

    def drawn_normal(self, p):
        """The nominal line's `outward_normal` at points `p` ``(..., 2)``, in NumPy (as
        `drawn_at`)."""
        return np.broadcast_to(self._nominal_normal(), np.shape(p))

    def _nominal_normal(self) -> np.ndarray:
        """The nominal outward normal in NumPy (the `drawn_*` methods')."""
        d = (np.asarray(self.p1, dtype=float) - self.p0) / math.dist(self.p0, self.p1)
        return self.side * np.array([d[1], -d[0]])


@dataclass(frozen=True)
class Arc:
    """A circular feature from ``p0`` to ``p1`` about ``center``.

    ``ccw`` is the travel sense in the drawing frame (z right, x up); ``side``
    as for :class:`Line`. ``convex`` is derived: the outward normal points away
    from the centre on a convex arc (a rounded corner) and towards it on a
    concave one (a fillet in an inside corner).
    """

    id: str
    p0: tuple[float, float]
    p1: tuple[float, float]
    center: tuple[float, float]
    ccw: bool
    side: int = -1
    tolerance: tuple[float, float] = (-0.01, 0.01)
    tolerance_on: str = "normal"

    kind: ClassVar[str] = "arc"
    param_names: ClassVar[tuple[str, ...]] = ("center_x", "center_z", "radius")
    param_units: ClassVar[tuple[str, ...]] = ("mm", "mm", "mm")  # center_x: a radius (X)
    nparams: ClassVar[int] = 3

    def __post_init__(self):
        if self.side not in (-1, 1):
            raise ValueError(f"side must be +1 or -1, got {self.side!r}")
        r0, r1 = math.dist(self.p0, self.center), math.dist(self.p1, self.center)
        if r0 <= 0.0 or abs(r0 - r1) > 1e-6 * max(1.0, r0):
            raise ValueError(
                f"arc {self.id!r}: start and end are not equidistant from the centre "
                f"(radii {r0:.6f} and {r1:.6f} mm)"
            )

    @property
    def radius(self) -> float:
        return math.dist(self.p0, self.center)

    @property
    def sense(self) -> int:
        """+1 for a convex arc, -1 for a concave one (see class docstring)."""
        # Left of CCW travel points to the centre; outward = side * left.
        return 1 if (self.ccw and self.side == -1) or (not self.ccw and self.side == 1) else -1

    @property
    def convex(self) -> bool:
        return self.sense == 1

    def _angles(self):
        a0 = math.atan2(self.p0[0] - self.center[0], self.p0[1] - self.center[1])
        a1 = math.atan2(self.p1[0] - self.center[0], self.p1[1] - self.center[1])
        sweep = a1 - a0
        if self.ccw and sweep <= 0:
            sweep += 2 * math.pi
        if not self.ccw and sweep >= 0:
            sweep -= 2 * math.pi
        return a0, sweep

    @property
    def sweep(self) -> float:
        """Signed swept angle (rad, CCW positive in the drawing frame)."""
        return self._angles()[1]

    @property
    def length(self) -> float:
        return abs(self.sweep) * self.radius

    def actual(self, dev):
        """``(centre, radius)`` of the deviated arc."""
        dev = jnp.asarray(dev)
        return jnp.array(self.center) + dev[:2], self.radius + dev[2]

    def signed_distance(self, p, dev=None):
        dev = self.zero() if dev is None else dev
        c, r = self.actual(dev)
        return self.sense * (_norm(jnp.asarray(p) - c) - r)

    def closest_point(self, p, dev=None):
        dev = self.zero() if dev is None else dev
        c, r = self.actual(dev)
        v = jnp.asarray(p) - c
        return c + r * v / _norm(v)[..., None]

    def outward_normal(self, p, dev=None):
        dev = self.zero() if dev is None else dev
        c, _ = self.actual(dev)
        v = jnp.asarray(p) - c
        return self.sense * v / _norm(v)[..., None]

    def tangent_at(self, which: str):
        p = self.p0 if which == "start" else self.p1
        radial = (jnp.array(p) - jnp.array(self.center)) / self.radius
        # CCW travel: tangent = radial rotated CCW by 90 deg = left_normal(radial).
        t = left_normal(radial)
        return t if self.ccw else -t

    def point_at(self, t, dev=None):
        """Point at fraction ``t`` of the nominal sweep, on the deviated arc."""
        dev = self.zero() if dev is None else dev
        a0, sweep = self._angles()
        ang = a0 + jnp.asarray(t) * sweep
        c, r = self.actual(dev)
        return c + r[..., None] * jnp.stack([jnp.sin(ang), jnp.cos(ang)], axis=-1)

    def zero(self):
        return jnp.zeros(self.nparams)

    def drawn_at(self, t, dev=None):
        """``(points, outward normals)`` at fractions ``t`` of the nominal sweep, in
        NumPy, of the nominal arc or the arc deviated by ``dev`` (as `Line.drawn_at`)."""
        a0, sweep = self._angles()
        ang = a0 + np.asarray(t, dtype=float) * sweep
        u = np.stack([np.sin(ang), np.cos(ang)], axis=-1)
        centre = np.asarray(self.center, dtype=float)
        if dev is None:
            return centre + self.radius * u, self.sense * u
        dev = np.asarray(dev, dtype=float)
        c = centre + dev[..., None, :2]
        q = c + (self.radius + dev[..., 2, None, None]) * u
        v = q - c
        return q, self.sense * v / np.sqrt(np.sum(v * v, axis=-1, keepdims=True))

    def drawn_distance(self, p, dev):
        """`signed_distance` of points `p` from the arc deviated by `dev`, in NumPy
        (as `Line.drawn_at`)."""
        dev = np.asarray(dev, dtype=float)
        v = np.asarray(p, dtype=float) - (np.asarray(self.center, dtype=float) + dev[:2])
        return self.sense * (np.linalg.norm(v, axis=-1) - (self.radius + dev[2]))

    def drawn_normal(self, p):
        """The nominal arc's `outward_normal` at points `p` ``(..., 2)``, in NumPy (as
        `Line.drawn_at`)."""
        v = np.asarray(p, dtype=float) - np.asarray(self.center, dtype=float)
        return self.sense * v / np.linalg.norm(v, axis=-1, keepdims=True)


Feature = Line | Arc

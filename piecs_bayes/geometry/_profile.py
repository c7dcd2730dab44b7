"""A connected turned profile: an ordered chain of lines and arcs.

Which side is material is found once, physically: for an external (OD) profile
the material lies between the profile and the spindle axis, for an internal
(bore) profile outside it. The signed area of the profile closed along the axis
says whether that region is left or right of travel, which fixes every
feature's outward normal.

Junctions between consecutive features are classified from the nominal
tangents: ``"tangent"`` where the direction turns by less than
``tangent_tol_deg`` (a fillet meeting a diameter), ``"sharp"`` otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ._curves import Arc, Feature, Line
from ._drawn import normal_limits

CONNECT_TOL_MM = 1e-6


class ProfileError(ValueError):
    """The profile is not a valid chain; carries the feature id."""

    def __init__(self, message: str, feature: str | None = None):
        self.feature = feature
        super().__init__(message)


def _arc_samples(center, radius, p0, p1, ccw, n=16):
    a0 = math.atan2(p0[0] - center[0], p0[1] - center[1])
    a1 = math.atan2(p1[0] - center[0], p1[1] - center[1])
    sweep = a1 - a0
    if ccw and sweep <= 0:
        sweep += 2 * math.pi
    if not ccw and sweep >= 0:
        sweep -= 2 * math.pi
    ang = a0 + sweep * np.linspace(0.0, 1.0, n)
    return np.stack([center[0] + radius * np.sin(ang), center[1] + radius * np.cos(ang)], 1)


def profile_side(chain: list[dict], internal: bool = False) -> int:
    """Outward-normal side (+1 left of travel, -1 right) for a chain of feature specs.

    Each spec has ``p0``, ``p1`` and, for arcs, ``center`` and ``ccw``.
    """
    pts = []
    for spec in chain:
        if spec.get("center") is not None:
            r = math.dist(spec["p0"], spec["center"])
            pts.extend(_arc_samples(spec["center"], r, spec["p0"], spec["p1"], spec["ccw"]))
        else:
            pts.extend([spec["p0"], spec["p1"]])
    pts = np.asarray(pts, dtype=float)
    closed = np.vstack([pts, [[0.0, pts[-1, 1]], [0.0, pts[0, 1]]]])
    a, b = closed[:, 1], closed[:, 0]  # drawing frame: z right, x up
    area = 0.5 * np.sum(a * np.roll(b, -1) - np.roll(a, -1) * b)
    if area == 0.0:
        raise ProfileError("the profile encloses no area with the spindle axis")
    material_left = area > 0
    if internal:
        material_left = not material_left
    return -1 if material_left else 1


def profile_kind(profile) -> str:
    """The study's declared `[profile] kind` of `profile`: ``"external"`` (a shaft:
    material between the profile and the axis) or ``"internal"`` (a bore). Read back
    from the side its features were built with (`profile_side`), so it holds for any
    shape, a profile made mostly of faces too; not guessed from where the normals
    point."""
    specs = [
        {"p0": f.p0, "p1": f.p1, **({"center": f.center, "ccw": f.ccw} if f.kind == "arc" else {})}
        for f in profile.features
    ]
    return "external" if profile.features[0].side == profile_side(specs) else "internal"


def _tangent(f: Feature, which: str) -> np.ndarray:
    """`f.tangent_at(which)` in NumPy (loading a study dispatches no JAX operation)."""
    if isinstance(f, Arc):
        radial = np.subtract(f.p0 if which == "start" else f.p1, f.center) / f.radius
        t = np.array([radial[1], -radial[0]])  # left_normal
        return t if f.ccw else -t
    d = np.subtract(f.p1, f.p0, dtype=float)
    return d / math.hypot(*d)


def _turn_angle(t0, t1) -> float:
    t0, t1 = np.asarray(t0), np.asarray(t1)
    cross = t0[1] * t1[0] - t0[0] * t1[1]  # drawing frame (z, x) cross product
    return math.degrees(math.atan2(cross, float(np.dot(t0, t1))))


@dataclass(frozen=True)
class Profile:
    """An ordered, connected chain of features (``Line`` / ``Arc``)."""

    features: tuple[Feature, ...]
    tangent_tol_deg: float = 0.5
    junctions: tuple[str, ...] = field(init=False)
    turn_angles_deg: tuple[float, ...] = field(init=False)

    def __post_init__(self):
        if not self.features:
            raise ProfileError("the profile has no features")
        ids = [f.id for f in self.features]
        for fid in ids:
            if ids.count(fid) > 1:
                raise ProfileError(f"feature id {fid!r} is used twice", fid)
        kinds, angles = [], []
        for a, b in zip(self.features[:-1], self.features[1:], strict=True):
            gap = math.dist(a.p1, b.p0)
            if gap > CONNECT_TOL_MM:
                raise ProfileError(
                    f"profile is not connected: {a.id!r} ends at (x={a.p1[0]:g}, z={a.p1[1]:g}) "
                    f"but {b.id!r} starts at (x={b.p0[0]:g}, z={b.p0[1]:g}), gap {gap:.6g} mm",
                    b.id,
                )
            ang = _turn_angle(_tangent(a, "end"), _tangent(b, "start"))
            angles.append(ang)
            kinds.append("tangent" if abs(ang) < self.tangent_tol_deg else "sharp")
        object.__setattr__(self, "junctions", tuple(kinds))
        object.__setattr__(self, "turn_angles_deg", tuple(angles))

    def __len__(self) -> int:
        return len(self.features)

    def __iter__(self):
        return iter(self.features)

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(f.id for f in self.features)

    def index(self, feature_id: str) -> int:
        try:
            return self.ids.index(feature_id)
        except ValueError:
            raise ProfileError(
                f"unknown feature id {feature_id!r}; the profile has {', '.join(self.ids)}",
                feature_id,
            ) from None

    def __getitem__(self, key: int | str) -> Feature:
        return self.features[self.index(key) if isinstance(key, str) else key]

    @property
    def vertices(self) -> np.ndarray:
        """Nominal vertices: start of the first feature, every junction, end of the last."""
        pts = [self.features[0].p0] + [f.p1 for f in self.features]
        return np.asarray(pts, dtype=float)

    def __repr__(self) -> str:
        parts = ", ".join(f"{f.id}:{f.kind}" for f in self.features)
        return f"Profile({parts})"


def make_feature(spec: dict, side: int) -> Feature:
    """Build a Line or Arc from a plain spec dict (``id``, ``p0``, ``p1``, optional
    ``center``/``ccw``, ``tolerance``, ``tolerance_on``).

    With ``tolerance_on`` the ``tolerance`` is as drawn on that coordinate and is
    converted to limits of the normal deviation (`_drawn`); without it, it limits the
    normal deviation. A coordinate that does not fit the feature's form raises
    `ProfileError`.
    """
    tol = tuple(spec.get("tolerance", (-0.01, 0.01)))
    on = spec.get("tolerance_on", "normal")
    if spec.get("center") is not None:
        feat: Feature = Arc(
            id=spec["id"],
            p0=tuple(spec["p0"]),
            p1=tuple(spec["p1"]),
            center=tuple(spec["center"]),
            ccw=bool(spec["ccw"]),
            side=side,
            tolerance=tol,
            tolerance_on=on,
        )
    else:
        feat = Line(
            id=spec["id"], p0=tuple(spec["p0"]), p1=tuple(spec["p1"]), side=side,
            tolerance=tol, tolerance_on=on,
        )  # fmt: skip
    if on == "normal":
        return feat
    try:
        return replace(feat, tolerance=normal_limits(feat, tol))
    except ValueError as exc:
        raise ProfileError(str(exc), spec["id"]) from None

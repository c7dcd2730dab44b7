"""Which features a probe plan can reach, and what would reach the others.

A feature is reachable when its usable window (`geometry.probe_window`, with the
plan's `end_clearance` and a stand-off of stock + clearance) holds the feature's least
count of points at the plan's spacing. [`reach`][] gives the windows of the reachable
features and an [`UnreachableFeature`][] for each other one: why, and the largest
`clearance` (the `end_clearance` kept) and the largest `end_clearance` (the
`clearance` kept) at which it is reached (both shrink the window monotonically, so
bisection finds them), and, where a window is only short, the largest `spacing`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..geometry import ball_centres, feature_polyline, point_distance, probe_window

#: the smallest clearance or spacing a suggestion goes down to (mm)
_LEAST = 1e-3
#: mm: suggestions are found to this, then rounded down to 0.001 mm
_RESOLUTION = 1e-4
#: the settings an `UnreachableFeature` suggests, in the order it says them
SUGGESTED = ("clearance", "end_clearance", "spacing")


@dataclass(frozen=True)
class UnreachableFeature:
    """A feature a plan leaves out (not measured): `reason`, and the largest
    `clearance`, the largest `end_clearance` and (when a window exists but is too short)
    the largest `spacing` at which the plan would reach it, each with the others as
    they are (mm; None: none does); `now`: the plan's own, in that order."""

    feature: str
    reason: str
    clearance: float | None
    end_clearance: float | None
    spacing: float | None
    now: tuple[float, float, float]

    @property
    def remedy(self) -> str:
        """The settings that reach it, in words."""
        ways = [
            f"[plan] {name} = {getattr(self, name):g} (now {now:g})"
            for name, now in zip(SUGGESTED, self.now, strict=True)
            if getattr(self, name) is not None
        ]
        if not ways:
            return "no clearance or end_clearance reaches it (a smaller ball might)"
        return "reached with " + " or ".join(ways)

    @property
    def message(self) -> str:
        """`feature 'id': why; the settings that reach it`."""
        return f"feature {self.feature!r}: {self.reason}; {self.remedy}"


def _window(study, s, index: int):
    r = study.probe.ball_radius
    return probe_window(study.profile, index, r, s.end_clearance, s.stock + s.clearance)


def room(window, length: float, spacing: float) -> int:
    """How many points `window` (fractions of a feature `length` mm long) holds at
    `spacing` mm (0 for no window)."""
    if window is None:
        return 0
    return int(math.floor((window[1] - window[0]) * length / spacing + 1e-6)) + 1


def _reached(study, s, index: int, least: int) -> bool:
    f = study.profile.features[index]
    return room(_window(study, s, index), f.length, s.spacing) >= least


def _largest(ok, lo: float, hi: float) -> float | None:
    """The largest value in `[lo, hi)` where `ok` holds (`ok` true below a threshold,
    false at `hi`), rounded down to 0.001 mm where that still holds; None when `ok(lo)`
    fails."""
    if not ok(lo):
        return None
    least = lo
    while hi - lo > _RESOLUTION:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return _round_down(lo, least, ok)


def _round_down(value: float, least: float, ok) -> float:
    """`value` rounded down to 0.001 mm where `ok` still holds there."""
    nice = round(math.floor(value / 1e-3 + 1e-9) * 1e-3, 3)
    return nice if nice >= least and ok(nice) else math.floor(value / 1e-4) * 1e-4


def _stand_off_neighbour(study, s, index: int, window) -> str:
    """The feature nearest the stand-off in the middle of `window` (without stand-off)."""
    f, r = study.profile.features[index], study.probe.ball_radius
    _, n, c = ball_centres(f, [0.5 * (window[0] + window[1])], r)
    start = c + (s.stock + s.clearance) * n
    gaps = [
        (float(point_distance(start, feature_polyline(g))[0]), g.id)
        for j, g in enumerate(study.profile.features)
        if j != index
    ]
    return min(gaps)[1] if gaps else f.id


def _reason(study, s, index: int, least: int) -> str:
    f, r = study.profile.features[index], study.probe.ball_radius
    window = _window(study, s, index)
    if window is not None:
        width = (window[1] - window[0]) * f.length
        held = room(window, f.length, s.spacing)
        return (
            f"its usable window is {width:.3f} mm long: room for {held} point"
            f"{'s' if held != 1 else ''} at the {s.spacing:g} mm spacing, the fit needs {least}"
        )
    bare = probe_window(study.profile, index, r, s.end_clearance)
    if bare is None:
        return (
            f"the {r:g} mm ball cannot touch it anywhere keeping {s.end_clearance:g} mm "
            "(end_clearance) from its ends and from the features beside it (a groove or "
            "concave arc too narrow for the ball, or a feature shorter than its margins)"
        )
    near = _stand_off_neighbour(study, s, index, bare)
    return (
        f"wherever the {r:g} mm ball can touch it, the probe's stand-off (stock + clearance "
        f"= {s.stock + s.clearance:g} mm out along the normal) comes nearer than that to "
        f"feature {near!r} (a corner or groove too narrow for the ball with stock and "
        "clearance)"
    )


def _largest_spacing(study, s, index: int, least: int) -> float | None:
    """The largest spacing at which the window (as it is) holds `least` points."""
    f = study.profile.features[index]
    window = _window(study, s, index)
    if window is None or least < 2:
        return None
    width = (window[1] - window[0]) * f.length
    value = width / (least - 1)
    if value < _LEAST:
        return None
    return _round_down(value, _LEAST, lambda v: room(window, f.length, v) >= least)


def _unreachable(study, s, index: int, least: int) -> UnreachableFeature:
    def ok(value, key):
        return _reached(study, replace(s, **{key: value}), index, least)

    return UnreachableFeature(
        feature=study.profile.features[index].id,
        reason=_reason(study, s, index, least),
        clearance=_largest(lambda v: ok(v, "clearance"), _LEAST, s.clearance),
        end_clearance=_largest(lambda v: ok(v, "end_clearance"), 0.0, s.end_clearance),
        spacing=_largest_spacing(study, s, index, least),
        now=(s.clearance, s.end_clearance, s.spacing),
    )


def reach(study, s, least: dict[str, int]):
    """`(windows, unreachable)`: the windows `{feature id: (t0, t1)}` of the features
    `s` (the plan's settings) reaches with their least counts `least`, and an
    [`UnreachableFeature`][] for each other one (profile order)."""
    windows, out = {}, []
    for i, f in enumerate(study.profile.features):
        w = _window(study, s, i)
        if room(w, f.length, s.spacing) >= least[f.id]:
            windows[f.id] = w
        else:
            out.append(_unreachable(study, s, i, least[f.id]))
    return windows, tuple(out)

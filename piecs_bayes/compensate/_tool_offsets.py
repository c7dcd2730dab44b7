r"""Tool-offset (wear) updates from measured mean errors (data; `piecs_bayes.export`
writes them as G10 lines and JSON).

The everyday compensation (PIECS option c): correct only the mean error of a tool by
changing its offsets, as the probing cycles of controllers do. [`tool_offset_update`][]
takes the mean errors (mm, measured minus nominal along the machine axis: X of a
diameter as a diameter or a radius per `x_mode`, Z of a face; the nose radius as the
effective minus the tool-table radius) with their standard uncertainties and returns a
[`ToolOffsetUpdate`][]: per axis the correction $-g\,e$ ($+g\,e$ for R) with standard
uncertainty $g\,u$, or no update inside the null band or below `k_significance`
standard uncertainties; an error above `upper_limit` on any axis blocks the whole
update (`blocked=True` with the reason, or `AnalysisError` with `raise_on_block=True`).

Sign convention and rules: docs/errspec.md, "Tool-offset updates".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..errors import AnalysisError, InputError

XMode = Literal["diameter", "radius"]


def _num(name, v, *, low=None, low_open=False, allow_none=False):
    if v is None and allow_none:
        return
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise InputError(f"{name} must be a finite number, got {v!r}", value=v)
    if low is not None and (v <= low if low_open else v < low):
        raise InputError(f"{name} must be {'>' if low_open else '>='} {low}, got {v!r}", value=v)


@dataclass(frozen=True)
class OffsetSettings:
    """Update rules (mm). Defaults: `null_band` 0.002, `feedback_gain` 1.0 (0 < g <= 1),
    `upper_limit` 0.1, `k_significance` 0 (off), `decimals` 4 (0.1 um in the G-code)."""

    null_band: float = 0.002
    feedback_gain: float = 1.0
    upper_limit: float = 0.1
    k_significance: float = 0.0
    decimals: int = 4

    def __post_init__(self):
        _num("null_band", self.null_band, low=0.0)
        _num("feedback_gain", self.feedback_gain, low=0.0, low_open=True)
        if self.feedback_gain > 1.0:
            raise InputError(f"feedback_gain must be <= 1, got {self.feedback_gain!r}")
        _num("upper_limit", self.upper_limit, low=0.0, low_open=True)
        if self.upper_limit <= self.null_band:
            raise InputError(
                f"upper_limit ({self.upper_limit}) must be above null_band ({self.null_band})"
            )
        _num("k_significance", self.k_significance, low=0.0)
        d = self.decimals
        if isinstance(d, bool) or not isinstance(d, int) or not 1 <= d <= 6:
            raise InputError(f"decimals must be an integer 1..6, got {d!r}", value=d)


@dataclass(frozen=True)
class WearOffset:
    """Where an update goes: `tool` (turret station; LinuxCNC's tool-table entry), >= 1;
    `offset`, the wear offset number the controller keeps its wear in (Fanuc
    `G10 P<offset>`), >= 1, default `tool`; `x_mode`, whether the controller states X
    as a diameter (`"diameter"`, default) or a radius; `source`, where the tool number
    came from (written with the update, e.g. the program's T word)."""

    tool: int
    offset: int | None = None
    x_mode: XMode = "diameter"
    source: str = ""

    def __post_init__(self):
        tool = self.tool
        if isinstance(tool, bool) or not isinstance(tool, int) or tool < 1:
            raise InputError(f"tool must be an integer >= 1, got {tool!r}", value=tool)
        offset = tool if self.offset is None else self.offset
        if isinstance(offset, bool) or not isinstance(offset, int) or offset < 1:
            raise InputError(f"offset must be an integer >= 1, got {offset!r}", value=offset)
        object.__setattr__(self, "offset", offset)
        x_mode = self.x_mode
        if x_mode not in ("diameter", "radius"):
            raise InputError(f"x_mode must be 'diameter' or 'radius', got {x_mode!r}", value=x_mode)


@dataclass(frozen=True)
class ToolOffsets:
    """Current tool-table values: X (in the update's `x_mode`), Z, nose radius R (mm)."""

    x: float | None = None
    z: float | None = None
    r: float | None = None


@dataclass(frozen=True)
class AxisCorrection:
    """One axis of an update: the measured error, the correction and why."""

    axis: str
    error: float | None
    u_error: float
    correction: float
    u_correction: float
    status: str
    reason: str

    @property
    def applied(self) -> bool:
        return self.status == "update"

    def __repr__(self) -> str:
        if self.error is None:
            return f"{self.axis.upper()}: not measured"
        return (
            f"{self.axis.upper()}: error {self.error:+.4g} ± {self.u_error:.2g} -> "
            f"correction {self.correction:+.4g} ± {self.u_correction:.2g} ({self.status})"
        )


@dataclass(frozen=True)
class ToolOffsetUpdate:
    """A wear-offset update for one tool; `x`, `z`, `r` are [`AxisCorrection`][]s.

    `tool` is the tool (turret station; LinuxCNC's tool-table entry), `offset` the
    wear offset number the controller keeps its wear in (Fanuc `G10 P<offset>`; the
    `oo` of a `Tttoo` word; the tool number when not given), `source` where the tool
    number came from (e.g. the program's T word).
    """

    tool: int
    x_mode: str
    x: AxisCorrection
    z: AxisCorrection
    r: AxisCorrection
    blocked: bool
    reasons: tuple[str, ...]
    settings: OffsetSettings
    offset: int | None = None
    source: str = ""

    def __post_init__(self):
        if self.offset is None:
            object.__setattr__(self, "offset", self.tool)

    @property
    def axes(self) -> tuple[AxisCorrection, AxisCorrection, AxisCorrection]:
        return (self.x, self.z, self.r)

    @property
    def any_update(self) -> bool:
        """True when at least one axis changes and the update is not blocked."""
        return not self.blocked and any(a.applied for a in self.axes)

    def __repr__(self) -> str:
        state = "BLOCKED" if self.blocked else ("update" if self.any_update else "no change")
        off = "" if self.offset == self.tool else f", wear offset {self.offset}"
        lines = [f"ToolOffsetUpdate(T{self.tool}{off}, {state}, X as {self.x_mode})"]
        lines += [f"  {a!r}" for a in self.axes if a.error is not None]
        lines += [f"  - {r}" for r in self.reasons]
        return "\n".join(lines)


def _axis(axis, error, u, st: OffsetSettings, sign: float) -> AxisCorrection:
    if error is None:
        return AxisCorrection(axis, None, 0.0, 0.0, 0.0, "not measured", "")
    _num(f"{axis} error", error)
    _num(f"u_{axis}", u, low=0.0)
    e, g = float(error), st.feedback_gain
    if abs(e) > st.upper_limit:
        return AxisCorrection(
            axis,
            e,
            u,
            0.0,
            0.0,
            "blocked",
            f"|error| {abs(e):.4g} mm > upper limit {st.upper_limit:g} mm",
        )
    if abs(e) <= st.null_band:
        return AxisCorrection(
            axis,
            e,
            u,
            0.0,
            0.0,
            "null band",
            f"|error| {abs(e):.4g} mm <= null band {st.null_band:g} mm",
        )
    if st.k_significance > 0 and abs(e) <= st.k_significance * u:
        return AxisCorrection(
            axis,
            e,
            u,
            0.0,
            0.0,
            "not significant",
            f"|error| {abs(e):.4g} mm <= {st.k_significance:g} x u ({u:.2g} mm)",
        )
    c = sign * g * e
    return AxisCorrection(
        axis, e, u, c, g * u, "update", f"correction {c:+.4g} mm = {sign * g:+g} x error"
    )


def tool_offset_update(
    target: WearOffset,
    *,
    x_error: float | None = None,
    u_x: float = 0.0,
    z_error: float | None = None,
    u_z: float = 0.0,
    nose_radius_error: float | None = None,
    u_r: float = 0.0,
    settings: OffsetSettings | None = None,
    raise_on_block: bool = False,
) -> ToolOffsetUpdate:
    """Wear-offset corrections for a tool from measured mean errors (see module docstring).

    **Arguments:**

    - `target`: the tool, its wear offset number, the X mode and where the tool number
      came from (a [`WearOffset`][]).
    - `x_error`, `u_x`: mean X error and its standard uncertainty (mm), a diameter error
      when `target.x_mode="diameter"`, radial when `"radius"`.
    - `z_error`, `u_z`: mean Z error (mm); `nose_radius_error`, `u_r`: effective minus
      table nose radius (mm). `None` means not measured (no change).
    - `settings`: null band, feedback gain, upper limit, significance factor.
    - `raise_on_block`: raise `AnalysisError` instead of returning a blocked update.

    **Returns:** a [`ToolOffsetUpdate`][].
    """
    st = settings if settings is not None else OffsetSettings()
    tool = target.tool
    if all(e is None for e in (x_error, z_error, nose_radius_error)):
        raise InputError(f"tool {tool}: no error given (x_error, z_error, nose_radius_error)")
    x = _axis("x", x_error, float(u_x), st, -1.0)
    z = _axis("z", z_error, float(u_z), st, -1.0)
    r = _axis("r", nose_radius_error, float(u_r), st, +1.0)
    blocked_axes = [a for a in (x, z, r) if a.status == "blocked"]
    if blocked_axes:  # the upper limit blocks the whole update (no axis changes)
        names = ", ".join(a.axis.upper() for a in blocked_axes)
        x, z, r = (
            a
            if a.status in ("blocked", "not measured")
            else AxisCorrection(
                a.axis, a.error, a.u_error, 0.0, 0.0, "blocked", f"blocked by {names}"
            )
            for a in (x, z, r)
        )
    reasons = [f"{a.axis.upper()}: {a.reason}" for a in (x, z, r) if a.reason]
    if blocked_axes:
        names = ", ".join(a.axis.upper() for a in blocked_axes)
        msg = (
            f"tool {tool}: update blocked, {names} error above the upper limit "
            f"{st.upper_limit:g} mm; check for a broken insert, a crash or a wrong offset "
            "before changing offsets"
        )
        if raise_on_block:
            raise AnalysisError(msg)
        reasons.insert(0, msg)
    return ToolOffsetUpdate(
        tool=tool,
        x_mode=target.x_mode,
        x=x,
        z=z,
        r=r,
        blocked=bool(blocked_axes),
        reasons=tuple(reasons),
        settings=st,
        offset=target.offset,
        source=str(target.source),
    )

"""Tool-offset (wear) updates from measured mean errors: G10 lines and JSON.

The everyday compensation (PIECS option c): correct only the mean error of a tool by
changing its offsets, the way probing cycles on controllers do it.

**Sign convention.** An *error* is measured minus nominal along the machine axis
(mm): `x_error` of a diameter (in `x_mode="diameter"`: measured diameter minus nominal
diameter; in `"radius"`: the radial error), `z_error` of a face position. For a tool
cutting on the +X side, a diameter that comes out too large is a positive X error (for
a tool at negative X the sign flips). The offset correction is $-g\\,e$ (the controlled
point moves against the error), so the new offset is `current - g * error`; e.g. a
diameter 0.02 too large gives an X wear change of -0.02 (diameter). `nose_radius_error`
is the effective (fitted) nose radius minus the tool-table radius; the radius changes by
$+g\\,e$.

**Rules per axis** (controller practice: Renishaw-style "null band", "feedback
percentage", "upper tolerance limit"):

- $|e| \\le$ `null_band`: no update (status `"null band"`);
- $|e| \\le$ `k_significance`$\\cdot u$: no update (status `"not significant"`; off by default);
- $|e| >$ `upper_limit` on **any** axis: the whole update is blocked (a crash, a
  broken insert or a wrong offset is likelier than wear); `blocked=True` with the
  reason, or `AnalysisError` with `raise_on_block=True`;
- otherwise the correction is $-g\\,e$ ($+g\\,e$ for R) with standard uncertainty $g\\,u$.

**G-code.** LinuxCNC `G10 L1 P<tool> X Z R` *sets* tool-table values (absolute), so the
current offsets are needed. The interpreter reads the X word like any other X word: in
diameter mode (G7) it is a diameter and is halved before it is stored (the table holds
radius values), in G8 it is a radius; the writer therefore emits `G7` or `G8` (and the
units word) on the line before the G10 to fix the meaning of X. R is the tool (nose)
radius. Fanuc-style lathes take `G10 P<offset> X Z R` (absolute) or `G10 P<offset> U W C`
(incremental, used when the current values are not given); `P` 1-64 is the wear offset
number (add 10000 for geometry), X/U is a diameter or a radius depending on the control's
parameter (ORC), so state `x_mode` as the control expects.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from typing import Literal

from ..errors import AnalysisError, InputError

__all__ = [
    "AxisCorrection",
    "OffsetSettings",
    "ToolOffsetUpdate",
    "ToolOffsets",
    "g10_fanuc",
    "g10_linuxcnc",
    "offsets_from_json",
    "offsets_to_json",
    "tool_offset_update",
]

FORMAT_NAME = "piecs-bayes-tool-offsets"
FORMAT_VERSION = 1
XMode = Literal["diameter", "radius"]
_STATUSES = ("update", "null band", "not significant", "blocked", "not measured")


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
    """A wear-offset update for one tool; `x`, `z`, `r` are [`AxisCorrection`][]s."""

    tool: int
    x_mode: str
    x: AxisCorrection
    z: AxisCorrection
    r: AxisCorrection
    blocked: bool
    reasons: tuple[str, ...]
    settings: OffsetSettings

    @property
    def axes(self) -> tuple[AxisCorrection, AxisCorrection, AxisCorrection]:
        return (self.x, self.z, self.r)

    @property
    def any_update(self) -> bool:
        """True when at least one axis changes and the update is not blocked."""
        return not self.blocked and any(a.applied for a in self.axes)

    def __repr__(self) -> str:
        state = "BLOCKED" if self.blocked else ("update" if self.any_update else "no change")
        lines = [f"ToolOffsetUpdate(T{self.tool}, {state}, X as {self.x_mode})"]
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
    tool: int,
    *,
    x_error: float | None = None,
    u_x: float = 0.0,
    z_error: float | None = None,
    u_z: float = 0.0,
    nose_radius_error: float | None = None,
    u_r: float = 0.0,
    settings: OffsetSettings | None = None,
    x_mode: XMode = "diameter",
    raise_on_block: bool = False,
) -> ToolOffsetUpdate:
    """Wear-offset corrections for `tool` from measured mean errors (see module docstring).

    **Arguments:**

    - `tool`: tool (LinuxCNC) or offset (Fanuc) number, >= 1.
    - `x_error`, `u_x`: mean X error and its standard uncertainty (mm), a diameter error
      when `x_mode="diameter"`, radial when `"radius"`.
    - `z_error`, `u_z`: mean Z error (mm); `nose_radius_error`, `u_r`: effective minus
      table nose radius (mm). `None` means not measured (no change).
    - `settings`: null band, feedback gain, upper limit, significance factor.
    - `raise_on_block`: raise `AnalysisError` instead of returning a blocked update.

    **Returns:** a [`ToolOffsetUpdate`][].
    """
    st = settings if settings is not None else OffsetSettings()
    if isinstance(tool, bool) or not isinstance(tool, int) or tool < 1:
        raise InputError(f"tool must be an integer >= 1, got {tool!r}", value=tool)
    if x_mode not in ("diameter", "radius"):
        raise InputError(f"x_mode must be 'diameter' or 'radius', got {x_mode!r}", value=x_mode)
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
        x_mode=x_mode,
        x=x,
        z=z,
        r=r,
        blocked=bool(blocked_axes),
        reasons=tuple(reasons),
        settings=st,
    )


def _fmt(v: float, decimals: int) -> str:
    v = round(float(v), decimals) + 0.0
    return f"{v:.{decimals}f}"


def _refuse_blocked(update: ToolOffsetUpdate):
    if update.blocked:
        raise AnalysisError(f"refusing to write a blocked update: {update.reasons[0]}")


def _u_comment(update: ToolOffsetUpdate, d: int, letters=("X", "Z", "R")) -> str:
    parts = [
        f"{letter} {_fmt(a.u_correction, d)}"
        for letter, a in zip(letters, update.axes, strict=True)
        if a.applied
    ]
    return f"(standard uncertainties mm: {' '.join(parts)})"


def _header(update: ToolOffsetUpdate, controller: str) -> str:
    return f"(piecs-bayes {controller} wear update T{update.tool}, X as {update.x_mode}, mm)"


def g10_linuxcnc(update: ToolOffsetUpdate, *, current: ToolOffsets) -> str:
    """LinuxCNC lines setting the new tool-table values with `G10 L1` (absolute).

    **Arguments:**

    - `update`: from [`tool_offset_update`][]; a blocked update is refused (`AnalysisError`).
    - `current`: the tool's current table values, X in the update's `x_mode`.

    **Returns:** text: a header comment, a comment with the corrections' standard
    uncertainties, `G21 G7` (or `G8` for radius), and `G10 L1 P<tool> X.. Z.. R..` with
    only the changed axes; a comment alone when nothing changes.
    """
    _refuse_blocked(update)
    d = update.settings.decimals
    head = _header(update, "LinuxCNC")
    if not update.any_update:
        return f"{head}\n(no change: {'; '.join(update.reasons) or 'nothing to update'})\n"
    words = []
    for letter, a, cur in zip("XZR", update.axes, (current.x, current.z, current.r), strict=True):
        if not a.applied:
            continue
        if cur is None:
            raise InputError(
                f"LinuxCNC G10 L1 writes absolute values: give the current {letter} of tool "
                f"{update.tool} (current.{letter.lower()})"
            )
        _num(f"current.{letter.lower()}", cur)
        new = cur + a.correction
        if letter == "R" and new < 0:
            raise AnalysisError(f"tool {update.tool}: new nose radius {new:.4g} mm is negative")
        words.append(f"{letter}{_fmt(new, d)}")
    mode = "G7" if update.x_mode == "diameter" else "G8"
    return f"{head}\n{_u_comment(update, d)}\nG21 {mode}\nG10 L1 P{update.tool} {' '.join(words)}\n"


def g10_fanuc(update: ToolOffsetUpdate, *, current: ToolOffsets | None = None) -> str:
    """Fanuc-style lathe lines: `G10 P X Z R` (absolute, with `current`) or
    `G10 P U W C` (incremental, without). P is the wear offset number (the tool
    number of the update). A blocked update is refused (`AnalysisError`)."""
    _refuse_blocked(update)
    d = update.settings.decimals
    head = _header(update, "Fanuc")
    if not update.any_update:
        return f"{head}\n(no change: {'; '.join(update.reasons) or 'nothing to update'})\n"
    words = []
    if current is None:
        for letter, a in zip("UWC", update.axes, strict=True):
            if a.applied:
                words.append(f"{letter}{_fmt(a.correction, d)}")
        letters = ("U", "W", "C")
    else:
        for letter, a, cur in zip(
            "XZR", update.axes, (current.x, current.z, current.r), strict=True
        ):
            if not a.applied:
                continue
            if cur is None:
                raise InputError(
                    f"absolute Fanuc G10 needs the current {letter} of offset {update.tool}; "
                    "or pass current=None for the incremental form"
                )
            _num(f"current.{letter.lower()}", cur)
            words.append(f"{letter}{_fmt(cur + a.correction, d)}")
        letters = ("X", "Z", "R")
    return f"{head}\n{_u_comment(update, d, letters)}\nG10 P{update.tool} {' '.join(words)}\n"


def offsets_to_json(update: ToolOffsetUpdate) -> str:
    """The update as versioned JSON (every axis with error, correction, uncertainties)."""
    doc = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "units": "mm",
        "tool": update.tool,
        "x_mode": update.x_mode,
        "blocked": update.blocked,
        "reasons": list(update.reasons),
        "settings": asdict(update.settings),
        "axes": {
            a.axis: {
                "error": a.error,
                "u_error": a.u_error,
                "correction": a.correction,
                "u_correction": a.u_correction,
                "status": a.status,
                "reason": a.reason,
            }
            for a in update.axes
        },
    }
    return json.dumps(doc, indent=2) + "\n"


def offsets_from_json(text: str, *, file: str | None = None) -> ToolOffsetUpdate:
    """Read JSON written by [`offsets_to_json`][] (validated)."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON: {e.msg}", file=file, line=e.lineno) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
        raise InputError(f"not a {FORMAT_NAME} file", file=file)
    if doc.get("version") != FORMAT_VERSION:
        raise InputError(f"unsupported version {doc.get('version')!r}", file=file)
    try:
        st = OffsetSettings(**doc["settings"])
        axes = {}
        for name in ("x", "z", "r"):
            a = doc["axes"][name]
            if a["status"] not in _STATUSES:
                raise InputError(f"axis {name}: unknown status {a['status']!r}", file=file)
            axes[name] = AxisCorrection(
                name,
                None if a["error"] is None else float(a["error"]),
                float(a["u_error"]),
                float(a["correction"]),
                float(a["u_correction"]),
                a["status"],
                str(a["reason"]),
            )
        return ToolOffsetUpdate(
            tool=int(doc["tool"]),
            x_mode=doc["x_mode"],
            x=axes["x"],
            z=axes["z"],
            r=axes["r"],
            blocked=bool(doc["blocked"]),
            reasons=tuple(doc["reasons"]),
            settings=st,
        )
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(f"malformed tool-offset JSON: {e!r}", file=file) from None

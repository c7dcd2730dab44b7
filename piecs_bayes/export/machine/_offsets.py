"""Tool-offset (wear) updates as G10 lines and JSON.

The update itself ([`tool_offset_update`][piecs_bayes.compensate.tool_offset_update],
its sign convention and rules) is in `piecs_bayes.compensate`; this module writes it:
[`g10_linuxcnc`][] (`G10 L1 P<tool> X Z R`, absolute, so the current offsets are
needed; preceded by `G7`/`G8` and the units word that fix the meaning of X),
[`g10_fanuc`][] (`G10 P<wear offset> X Z R` absolute with the current values, else
`U W C` incremental) and [`offsets_to_json`][] / [`offsets_from_json`][]
(`piecs-bayes-tool-offsets`, version 1). LinuxCNC is addressed by the tool number,
Fanuc-style lathes by the wear offset number (from the program's T word); a comment
under the header says where the number came from. A blocked update is never written
(`AnalysisError`).

The G-code of each controller: docs/errspec.md, "Tool-offset updates".
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict

from ...compensate import AxisCorrection, OffsetSettings, ToolOffsets, ToolOffsetUpdate
from ...errors import AnalysisError, InputError
from ...gcode import comment_text

FORMAT_NAME = "piecs-bayes-tool-offsets"
FORMAT_VERSION = 1
_STATUSES = ("update", "null band", "not significant", "blocked", "not measured")


def _finite(name, v):
    """Refuse anything but a finite number (as the update's own argument checks do)."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise InputError(f"{name} must be a finite number, got {v!r}", value=v)


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
    """The header comment (the Fanuc one names the T word and the wear offset), and a
    comment saying where the tool number came from when the update says."""
    tool, off = update.tool, update.offset
    if controller == "Fanuc":
        word = f"T{tool:02d}{off:02d}: " if tool <= 99 and off <= 99 else ""
        what = f"{word}tool {tool}, wear offset {off}"
    else:
        what = f"T{tool}"
    head = f"(piecs-bayes {controller} wear update {what}, X as {update.x_mode}, mm)"
    if update.source:
        head += f"\n({comment_text('tool from ' + update.source)})"
    return head


def g10_linuxcnc(update: ToolOffsetUpdate, *, current: ToolOffsets) -> str:
    """LinuxCNC lines setting the new tool-table values with `G10 L1` (absolute).

    **Arguments:**

    - `update`: from [`tool_offset_update`][]; a blocked update is refused (`AnalysisError`).
    - `current`: the tool's current table values, X in the update's `x_mode`.

    **Returns:** text: a header comment (and one saying where the tool number came
    from, when the update says), a comment with the corrections' standard
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
        _finite(f"current.{letter.lower()}", cur)
        new = cur + a.correction
        if letter == "R" and new < 0:
            raise AnalysisError(f"tool {update.tool}: new nose radius {new:.4g} mm is negative")
        words.append(f"{letter}{_fmt(new, d)}")
    mode = "G7" if update.x_mode == "diameter" else "G8"
    return f"{head}\n{_u_comment(update, d)}\nG21 {mode}\nG10 L1 P{update.tool} {' '.join(words)}\n"


def g10_fanuc(update: ToolOffsetUpdate, *, current: ToolOffsets | None = None) -> str:
    """Fanuc-style lathe lines: `G10 P X Z R` (absolute, with `current`) or
    `G10 P U W C` (incremental, without). P is the update's wear offset number
    (`offset`: the `oo` of the program's `Tttoo`). A blocked update is refused
    (`AnalysisError`)."""
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
                    f"absolute Fanuc G10 needs the current {letter} of offset {update.offset}; "
                    "or pass current=None for the incremental form"
                )
            _finite(f"current.{letter.lower()}", cur)
            words.append(f"{letter}{_fmt(cur + a.correction, d)}")
        letters = ("X", "Z", "R")
    return f"{head}\n{_u_comment(update, d, letters)}\nG10 P{update.offset} {' '.join(words)}\n"


def offsets_to_json(update: ToolOffsetUpdate) -> str:
    """The update as versioned JSON (every axis with error, correction, uncertainties)."""
    doc = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "units": "mm",
        "tool": update.tool,
        "offset": update.offset,
        "tool_source": update.source,
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
            offset=int(doc.get("offset", doc["tool"])),
            source=str(doc.get("tool_source", "")),
        )
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(f"malformed tool-offset JSON: {e!r}", file=file) from None

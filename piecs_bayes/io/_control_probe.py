"""Probe files as controls write them, read against the probe plan that made them.

A gauging program written by `piecs-bayes plan` probes the plan's points in order and
the control writes one line per touch, so line *k* of its file is point *k* of the plan:
its feature and approach direction come from the plan ([`read_plan_points`][] ->
[`PlanPoints`][]), its ball centre from the file. [`read_control_probe`][] reads one of
`PROBE_FORMATS` but `"csv"`: `"linuxcnc"` (the PROBEOPEN file, X a radius even in G7),
`"linuxcnc-log"` (the LOGOPEN file with each point's number and success flag) or
`"fanuc-dprnt"` (the DPRNT lines, X as the control's X mode says), and returns
`ProbeData` in mm, radius X, the work frame. Refused, naming the file, the line, the
planned point and the value: a line that is not the format, more or fewer points than
the plan, a failed probe, a point farther than `limit_mm` from its planned ball centre.

The formats: docs/models/gauging.md, "The control's file", and docs/formats.md.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._fastcsv import read_rows, split_lines
from ._probe import ProbeData
from ._text import decode, read_bytes

PROBE_FORMATS = ("csv", "linuxcnc", "linuxcnc-log", "fanuc-dprnt")
_MM_PER = {"mm": 1.0, "in": 25.4}
_NUM = r"[+-]?\s*(?:\d+\.?\d*|\.\d+)"
_DPRNT = re.compile(rf"^\s*X\s*({_NUM})\s+Z\s*({_NUM})\s*$")
#: what a control or a CAM system's inspection print puts around the DPRNT lines: Haas's
#: POPEN and PCLOS send DC2 and DC4 on the port, a file captured from it the `%` of the
#: program's tape format; a print of a CAM system heads and ends its points with a word
_PORT_CONTROL = "\x12\x14"
_HEADER = re.compile(r"^[A-Za-z][A-Za-z _:-]*$")


@dataclass(frozen=True, eq=False)
class PlanPoints:
    """What a probe file is read against: the plan's points in program order (mm,
    radius X, part frame = the gauging program's work frame)."""

    file: str
    units: str
    feature: tuple[str, ...]
    centre: np.ndarray
    approach: np.ndarray
    target: np.ndarray
    x_mode: str = "diameter"

    def __len__(self) -> int:
        return len(self.feature)


def read_plan_points(path) -> PlanPoints:
    """The points of a `plan.json` (docs/formats.md)."""
    name = str(path)
    try:
        body = json.loads(decode(read_bytes(path, what="probe plan"), file=name))
        k = _MM_PER[body["units"]]
        if body.get("x") != "radius":
            raise ValueError(f"x is {body.get('x')!r}, expected 'radius'")
        pts = body["points"]
        feature = tuple(str(p["feature"]) for p in pts)

        def arr(key, scale):
            return (
                np.array([[float(v) for v in p[key]] for p in pts], dtype=float).reshape(-1, 2)
                * scale
            )

        plan = PlanPoints(
            name, body["units"], feature, arr("centre", k), arr("approach", 1.0),
            arr("target", k), str(body.get("program_x_mode", "diameter")),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not a probe plan of piecs-bayes: {exc}", file=name) from None
    if not len(plan):
        raise InputError("the probe plan has no points", file=name)
    return plan


def _lines(path) -> list[tuple[int, str]]:
    text = decode(read_bytes(path, what="probe file"), file=str(path))
    return [(i, s) for i, s in enumerate(text.splitlines(), start=1) if s.strip()]


#: the bytes of a LinuxCNC probe file: digits, sign, point, space, line ends
_LINUXCNC_BYTES = np.zeros(256, dtype=bool)
_LINUXCNC_BYTES[np.frombuffer(b"0123456789+-. \n\r", dtype=np.uint8)] = True
_KINDS = ("number", "skip", "number", "skip", "skip", "skip", "skip", "skip", "skip")


def _fast_linuxcnc(data: bytes):
    """X and Z of a plain PROBEOPEN file, a column at a time (`_fastcsv`), or None
    when a byte is not of the format or a line not plain (the line reader then names
    it). The seven other columns are vouched for by their bytes (number characters)."""
    if not _LINUXCNC_BYTES[np.frombuffer(data, dtype=np.uint8)].all():
        return None
    lines = split_lines(data.replace(b" ", b","))
    rows = read_rows(lines, 0, _KINDS)
    if rows.rest:
        return None
    return np.stack([rows.numbers[0], rows.numbers[2]], axis=1), rows.lines


def _parse_linuxcnc(rows, name):
    vals = []
    for i, s in rows:
        parts = s.split()
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            bad = next(p for p in parts if not _is_number(p))
            raise InputError(
                f"not a LinuxCNC probe line: {bad!r} is not a number (expected nine numbers "
                "X Y Z A B C U V W with '.' decimals)",
                file=name,
                line=i,
                value=bad,
            ) from None
        if len(nums) != 9 or not all(math.isfinite(v) for v in nums):
            raise InputError(
                f"not a LinuxCNC probe line: {len(nums)} numbers, expected nine finite ones "
                "(X Y Z A B C U V W)",
                file=name,
                line=i,
                value=s.strip()[:80],
            )
        vals.append((nums[0], nums[2]))
    return np.array(vals, dtype=float).reshape(-1, 2), 1.0


def _parse_log(rows, name):
    vals, flags = [], []
    for j, (i, s) in enumerate(rows):
        parts = s.split()
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            nums = []
        if len(nums) != 4 or not all(math.isfinite(v) for v in nums):
            raise InputError(
                "not a LOG line of the plan's program: expected '<point> <#5070> <X> <Z>' "
                "(four numbers, '.' decimals)",
                file=name,
                line=i,
                value=s.strip()[:80],
            )
        if nums[0] != j + 1:
            raise InputError(
                f"the line logs point {nums[0]:g}, expected point {j + 1} of the plan: a touch "
                "skipped or repeated, or the log of another program",
                file=name,
                line=i,
                value=nums[0],
            )
        flags.append(nums[1])
        vals.append((nums[2], nums[3]))
    return np.array(vals, dtype=float).reshape(-1, 2), np.array(flags, dtype=float)


def _is_number(p: str) -> bool:
    try:
        float(p)
    except ValueError:
        return False
    return True


def _dprnt_lines(path) -> list[tuple[int, str]]:
    """The DPRNT lines of a file captured from a control's port, with their line
    numbers: DC2/DC4 at a line's ends, `%` lines, CR LF ends and header words before the
    first point or after the last (`START`, `END`) are what a port carries and are left
    out; any other control character is refused, naming its line and column."""
    name = str(path)
    text = decode(read_bytes(path, what="probe file"), file=name)
    rows, header, after_points = [], [], False
    for i, raw in enumerate(text.split("\n"), start=1):
        s = raw[:-1] if raw.endswith("\r") else raw
        core = s.strip(_PORT_CONTROL + " \t")
        bad = _stray_control(s)
        if bad is not None:
            raise InputError(
                f"control character 0x{ord(s[bad]):02x} at line {i}, column {bad + 1}: not "
                "a byte of a DPRNT print (DC2 and DC4 are read only where POPEN and "
                "PCLOS send them, at a line's ends)",
                file=name, line=i, value=f"0x{ord(s[bad]):02x}",
            )  # fmt: skip
        if not core or core == "%":
            continue
        if _HEADER.match(core):
            header.append((i, core))
            after_points = bool(rows)
            continue
        if after_points:
            j, word = header[-1]
            raise InputError(
                f"{word!r} between the points (a point follows it at line {i}): a DPRNT "
                "print has its header words before the first point and after the last only",
                file=name, line=j, value=word[:80],
            )  # fmt: skip
        rows.append((i, core))
    return rows


def _stray_control(s: str) -> int | None:
    """The column (from 0) of the first control character of line `s` that a port does
    not send: any but a tab, and DC2/DC4 inside the line rather than at its ends."""
    edge = _PORT_CONTROL + " \t%"
    for c, ch in enumerate(s):
        if (ord(ch) < 32 and ch != "\t") or ord(ch) == 127:
            at_an_end = not s[:c].strip(edge) or not s[c + 1 :].strip(edge)
            if not (ch in _PORT_CONTROL and at_an_end):
                return c
    return None


def _parse_dprnt(rows, name, x_mode):
    vals = []
    for i, s in rows:
        m = _DPRNT.match(s)
        if m is None:
            raise InputError(
                "not a DPRNT line of the plan's program: expected 'X <number> Z <number>' "
                "(DPRNT[X#5061[44]*Z#5062[44]])",
                file=name,
                line=i,
                value=s.strip()[:80],
            )
        vals.append((float(m.group(1).replace(" ", "")), float(m.group(2).replace(" ", ""))))
    return np.array(vals, dtype=float).reshape(-1, 2), (0.5 if x_mode == "diameter" else 1.0)


def read_control_probe(
    path, fmt: str, plan: PlanPoints, *, x_mode: str | None = None, limit_mm: float = 0.5,
    part: str | None = None,
) -> ProbeData:  # fmt: skip
    """Read a control's probe file against its plan (module docstring).

    **Arguments:** `path`; `fmt` one of `PROBE_FORMATS` but ``"csv"``; `plan` (from
    `read_plan_points`); `x_mode`: how a Fanuc file writes X (default: the plan's
    program X mode, the control's setting the program was written for; LinuxCNC's is
    always a radius); `limit_mm`: the largest distance of a ball centre from its
    planned one;
    `part`: the part id (default: the file's stem).

    **Returns:** `ProbeData` in mm, radius X, the work frame, with the plan's
    features and approach directions.
    """
    name = str(path)
    fast = None
    if fmt == "linuxcnc":
        data = read_bytes(path, what="probe file")
        fast = _fast_linuxcnc(data)
    if fast is not None:
        pts, xs = fast[0], 1.0
        lines = np.asarray(fast[1], dtype=np.int64)
    elif fmt == "linuxcnc":
        rows = _lines(path)
        pts, xs = _parse_linuxcnc(rows, name)
        lines = np.array([i for i, _ in rows], dtype=np.int64)
    elif fmt == "linuxcnc-log":
        rows = _lines(path)
        pts, flags = _parse_log(rows, name)
        xs = 1.0
        lines = np.array([i for i, _ in rows], dtype=np.int64)
        failed = np.flatnonzero(flags != 1.0)
        if failed.size and failed[0] < len(plan):
            j = int(failed[0])
            raise InputError(
                f"point {j + 1} of the plan (feature {plan.feature[j]!r}): #5070 is "
                f"{flags[j]:g}, the probe did not trip (a failed probe)",
                file=name,
                line=int(lines[j]),
                feature=plan.feature[j],
            )
    elif fmt == "fanuc-dprnt":
        rows = _dprnt_lines(path)
        pts, xs = _parse_dprnt(rows, name, x_mode or plan.x_mode)
        lines = np.array([i for i, _ in rows], dtype=np.int64)
    else:
        raise InputError(
            f"probe_format: got {fmt!r}, expected one of {', '.join(PROBE_FORMATS)}", value=fmt
        )
    k = _MM_PER[plan.units]
    pts = pts * np.array([xs * k, k])
    if len(pts) != len(plan):
        raise InputError(
            f"{len(pts)} probe points in the file, the plan {Path(plan.file).name} has "
            f"{len(plan)}: line k of the file is point k of the plan, so they must match "
            "(a touch skipped or repeated, or the file of another plan)",
            file=name,
            value=len(pts),
        )
    _check_points(pts, plan, lines, name, k, xs, limit_mm)
    return ProbeData(
        file=(name,),
        feature=np.array(plan.feature),
        points=pts,
        lines=lines,
        part=np.full(len(pts), part if part is not None else Path(name).stem, dtype=object),
        approach=plan.approach.copy(),
    )


def _check_points(pts, plan, lines, name, k, xs, limit_mm) -> None:
    """Refuse the first failed probe and the first point far from its planned centre.

    A failed probe reports the move's end point: the target, to the rounding of the
    program's words (4 decimals in mm, 5 in inches; a diameter word halves it) and of
    the file's."""
    rounding = (10.0 ** -(4 if k == 1.0 else 5) + 10.0 ** -(6 if xs == 1.0 else 4)) * k
    failed = np.hypot(*(pts - plan.target).T) <= 2.0 * rounding
    dist = np.hypot(*(pts - plan.centre).T)
    far = dist > limit_mm
    if not (failed.any() or far.any()):
        return
    j = int(np.flatnonzero(failed | far)[0])
    c, p, t = plan.centre[j], pts[j], plan.target[j]
    where = f"point {j + 1} of the plan (feature {plan.feature[j]!r}"
    if failed[j]:
        raise InputError(
            f"{where}, target X{t[0] / k:.4f} Z{t[1] / k:.4f} as a radius): the probe "
            "reached its target without a trip (a failed probe)",
            file=name,
            line=int(lines[j]),
            feature=plan.feature[j],
        )
    raise InputError(
        f"{where}, planned ball centre X{c[0] / k:.4f} Z{c[1] / k:.4f} as a radius): "
        f"the file's point X{p[0] / k:.4f} Z{p[1] / k:.4f} is {dist[j]:.3f} mm from it "
        f"(limit {limit_mm:g} mm): a point of another feature, or a touch skipped "
        "or repeated before it",
        file=name,
        line=int(lines[j]),
        feature=plan.feature[j],
        value=float(dist[j]),
    )

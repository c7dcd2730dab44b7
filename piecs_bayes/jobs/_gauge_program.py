"""The type-1 study run by the machine: its gauging program and its probe file read
back as readings (`piecs-bayes gauge-study program FILE`).

A gauge-study file's `[type1.program]` ([`Type1Program`][]) says where the reference is
and how to touch it: a ring's bore (outward, +X, at one Z), a master shaft (-X) or a
face facing +Z (-Z, at one X). [`type1_gauging`][] writes the program that touches
there `repeats` times (`gcode.gauging_program`: LinuxCNC or Fanuc) and its plan
(`type1_plan.json`, `plan.json`'s points); [`type1_readings`][] reads the control's
file against it (`io.read_control_probe`: a failed, missing or far touch is refused by
file and line) and turns each ball centre c, approach a, into the contact c + r a
(r: the effective ball radius): twice its X on a bore or shaft, its Z on a face.

The study and the file: docs/msa.md, "The type-1 study on the machine".
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from numbers import Real
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..gcode import CONTROLLERS, GaugingOptions, gauging_program
from ..io import read_control_probe, read_plan_points

#: the surfaces a type-1 reference offers: (approach direction, characteristic)
SURFACES = {
    "bore": ((1.0, 0.0), "diameter"),
    "shaft": ((-1.0, 0.0), "diameter"),
    "face": ((0.0, -1.0), "z"),
}
#: the program's file name by controller, and its plan's
PROGRAM_NAMES = {"linuxcnc": "type1_gauging.ngc", "fanuc": "type1_gauging_fanuc.nc"}
PLAN_NAME = "type1_plan.json"
_FORMAT = "piecs_bayes probe plan 1"
_DEFAULT_FILES = {"linuxcnc": "linuxcnc", "fanuc": "fanuc-dprnt"}


@dataclass(frozen=True)
class Type1Program:
    """How the machine touches the reference (lengths in mm, X a radius).

    - `surface`: `"bore"`, `"shaft"` or `"face"` (`SURFACES`); `nominal`: the
      reference's size (a diameter, or a face's Z), by default its certified value.
    - `at`: Z of the touches on a bore or shaft, X (a radius) on a face.
    - `repeats`: touches (at least 25 for a type-1 study).
    - `ball_diameter`: the probe's effective ball diameter (its qualification).
    - `clearance`, `overtravel`: the start before the surface and the target beyond
      it; `safe`: the Z of the way in and out (default 5 mm above the touches' Z on
      a bore or shaft, above the start on a face).
    - `tool`, `feed`: the probe's tool number and probing feed (mm/min);
      `controller` one of `gcode.CONTROLLERS`, `x_mode` of the program's X words.
    """

    surface: str
    nominal: float
    at: float
    repeats: int
    ball_diameter: float
    clearance: float = 1.0
    overtravel: float = 0.5
    safe: float | None = None
    tool: int = 1
    feed: float = 100.0
    controller: str = "linuxcnc"
    x_mode: str = "diameter"

    @property
    def approach(self) -> tuple[float, float]:
        return SURFACES[self.surface][0]

    @property
    def characteristic(self) -> str:
        return SURFACES[self.surface][1]

    def centre(self) -> tuple[float, float]:
        """The ball centre at contact (radius X, Z)."""
        r = self.ball_diameter / 2.0
        a = self.approach
        if self.characteristic == "diameter":
            return (self.nominal / 2.0 - r * a[0], self.at)
        return (self.at, self.nominal - r * a[1])

    def moves(self) -> tuple[tuple[float, float], list[tuple[str, tuple[float, float]]]]:
        """`(home, path)`: the way in at `safe`, then per touch the start and the probe
        move to the target, and back to the start; out at `safe` at the end."""
        c, a = np.array(self.centre()), np.array(self.approach)
        start = tuple(c - self.clearance * a)
        target = tuple(c + self.overtravel * a)
        if self.characteristic == "diameter":
            home = (start[0], self.safe if self.safe is not None else self.at + 5.0)
        else:
            home = (start[0], self.safe if self.safe is not None else start[1] + 5.0)
        path: list[tuple[str, tuple[float, float]]] = [("rapid", start)]
        for _ in range(self.repeats):
            path += [("probe", target), ("rapid", start)]
        path.append(("rapid", home))
        return home, path


_PROGRAM_KEYS = {
    "surface": str, "nominal": float, "at": float, "repeats": int, "ball_diameter": float,
    "clearance": float, "overtravel": float, "safe": float, "tool": int, "feed": float,
    "controller": str, "x_mode": str,
}  # fmt: skip
_LENGTHS = ("nominal", "at", "ball_diameter", "clearance", "overtravel", "safe", "feed")


def type1_program(table: dict, reference: float, mm: float, file: str) -> Type1Program:
    """The `[type1.program]` table of a gauge-study file (`mm`: mm per unit of the
    file; `reference`: the certified value, mm, the default `nominal`)."""
    where = "[type1.program]"
    for key in table:
        if key not in _PROGRAM_KEYS:
            raise InputError(
                f"{where} unknown key {key!r}; expected one of {', '.join(_PROGRAM_KEYS)}",
                file=file,
            )
    for key in ("surface", "at", "repeats", "ball_diameter"):
        if key not in table:
            raise InputError(f"{where} {key} is missing", file=file)
    kw = {}
    for key, v in table.items():
        kind = _PROGRAM_KEYS[key]
        if kind is str:
            ok = isinstance(v, str)
        elif kind is int:
            ok = isinstance(v, int) and not isinstance(v, bool) and v >= 1
        else:
            ok = isinstance(v, Real) and not isinstance(v, bool) and math.isfinite(v)
        if not ok:
            raise InputError(f"{where} {key}: got {v!r}", file=file, value=v)
        kw[key] = float(v) * mm if key in _LENGTHS else v
    checks = (
        ("surface", kw["surface"] in SURFACES, f"one of {', '.join(SURFACES)}"),
        ("controller", kw.get("controller", "linuxcnc") in CONTROLLERS,
         f"one of {', '.join(CONTROLLERS)}"),
        ("x_mode", kw.get("x_mode", "diameter") in ("diameter", "radius"),
         "'diameter' or 'radius'"),
        ("repeats", kw["repeats"] >= 25, "at least 25 touches (a type-1 study)"),
        ("ball_diameter", kw["ball_diameter"] > 0, "> 0"),
        ("clearance", kw.get("clearance", 1.0) > 0, "> 0"),
        ("overtravel", kw.get("overtravel", 0.5) > 0, "> 0"),
        ("feed", kw.get("feed", 100.0) > 0, "> 0"),
    )  # fmt: skip
    for key, ok, expected in checks:
        if not ok:
            raise InputError(
                f"{where} {key}: expected {expected}, got {table.get(key)!r}",
                file=file,
                value=table.get(key),
            )
    kw.setdefault("nominal", reference)
    return Type1Program(**kw)


@dataclass(frozen=True)
class _Touch:  # what `gauging_program` comments on each probe move
    index: int
    feature: str
    t: float
    contact: tuple[float, float]


def type1_gauging(study) -> tuple[str, str, str]:
    """`(program file name, program text, plan JSON text)` of a gauge-study file's
    type-1 program (a `GaugeStudyFile` whose `[type1]` has a `program`)."""
    t1 = study.type1
    if t1 is None or t1.program is None:
        raise InputError(
            "the file has no [type1.program] table (surface, at, repeats, ball_diameter)",
            file=str(study.path),
        )
    p, mm = t1.program, 1.0 / {"mm": 1.0, "in": 25.4}[study.units]
    home, path = p.moves()
    r = p.ball_diameter / 2.0
    c = np.array(p.centre())
    contact = tuple(c + r * np.array(p.approach))
    touches = [_Touch(k + 1, "reference", 0.5, contact) for k in range(p.repeats)]
    options = GaugingOptions(controller=p.controller, units=study.units, x_mode=p.x_mode,
                             tool=p.tool, feed_mm_min=p.feed)  # fmt: skip
    header = [
        f"piecs_bayes type-1 gauging program: {study.name}",
        f"study {study.path.name}: {p.repeats} touches of the {p.surface}, "
        f"reference {t1.reference.value * mm:g} {study.units}",
    ]
    text = gauging_program(home, path, touches, options=options, header=header)
    _, tgt = next(m for m in path if m[0] == "probe")

    def pt(v):
        return [round(float(v[0]) * mm, 9), round(float(v[1]) * mm, 9)]

    plan = {
        "format": _FORMAT,
        "study": study.path.name,
        "units": study.units,
        "x": "radius",
        "program_x_mode": p.x_mode,
        "controller": p.controller,
        "frame": "the reference's work coordinates",
        "type1": {
            "surface": p.surface,
            "characteristic": p.characteristic,
            "ball_radius": round(r * mm, 9),
            "repeats": p.repeats,
        },  # fmt: skip
        "points": [
            {
                "index": k + 1,
                "feature": "reference",
                "contact": pt(contact),
                "centre": pt(c),
                "approach": list(p.approach),
                "target": pt(tgt),
            }
            for k in range(p.repeats)
        ],  # fmt: skip
    }
    return PROGRAM_NAMES[p.controller], text, json.dumps(plan, indent=2) + "\n"


def type1_readings(probe_file: Path, plan_file: Path, fmt: str | None) -> np.ndarray:
    """The readings (mm) of a type-1 program's probe file, read against its plan: the
    contact c + r a of each touch, twice its X on a diameter, its Z on a face."""
    plan = read_plan_points(plan_file)
    try:
        body = json.loads(Path(plan_file).read_text(encoding="utf-8-sig"))
        t1 = body["type1"]
        r = float(t1["ball_radius"]) * {"mm": 1.0, "in": 25.4}[body["units"]]
        char = str(t1["characteristic"])
        controller = str(body.get("controller", "linuxcnc"))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not a type-1 plan of piecs-bayes: {exc}", file=str(plan_file)) from None
    fmt = fmt or _DEFAULT_FILES.get(controller, "linuxcnc")
    data = read_control_probe(probe_file, fmt, plan)
    contact = data.points + r * data.approach
    return 2.0 * contact[:, 0] if char == "diameter" else contact[:, 1]

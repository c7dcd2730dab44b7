"""Readers of the study file's job sections: `[program]` (adjusting the part
program), `[plausibility]` (the checks made before fitting) and the table-driven
`[decision]`, `[capability]`, `[offsets]` and `[errspec]` (`JOB_KEYS`).

Each takes a [`Reader`][] (which names the file and key path in its errors) and
the length scale to millimetres.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ..geometry import Profile
from ._reader import Reader
from ._settings import PROGRAM_DIALECTS, ProgramSettings

# Keys of the job sections read by piecs_bayes.decisions (see docs/formats.md):
# (kind, bounds) with kind "length" (converted to mm), "number", "int", "bool",
# "choice" (bounds = options), "ids" (feature ids of the profile), "words" (G-code
# words written into a program), "name" (a file name); bounds are
# (low, high, low_open, high_open), None = unbounded. Defaults live where the
# settings are used (DecisionSettings, OffsetSettings, decisions.py).
_GE0 = (0.0, None, False, False)
_GT0 = (0.0, None, True, False)
_GAIN = (0.0, 1.0, True, False)
JOB_KEYS: dict[str, dict[str, tuple]] = {
    "decision": {
        "characteristic": ("choice", ("worst", "mid", "start", "end")),
        "run_index": ("int", (1, None, False, False)),
        "null_band": ("length", _GE0),
        "feedback_gain": ("number", _GAIN),
        "loss_k": ("per_mm2", _GT0),
        "adjustment_cost": ("number", _GE0),
        "out_of_tolerance_cost": ("number", _GE0),
        "adjustment_sd": ("length", _GE0),
        "process_sd": ("length", _GE0),
        "prior_sd": ("length", _GT0),
        "max_correction": ("length", _GT0),
        "p_significant": ("number", (0.5, 1.0, True, True)),
        "coverage_factor": ("number", _GT0),
        "guard_band_factor": ("number", _GE0),
        "parts_per_decision": ("int", (1, None, False, False)),
        "max_points_factor": ("number", (1.0, None, False, False)),
        "require_significance": ("bool", None),
    },
    "capability": {
        "characteristic": ("choice", ("mid", "start", "end")),
        "confidence": ("number", (0.0, 1.0, True, True)),
        "threshold": ("number", _GT0),
        "sigma_method": ("choice", ("auto", "mr", "overall")),
        "subtract_gauge": ("bool", None),
        "gain": ("number", (0.0, 1.0, False, False)),
        "n_draws": ("int", (1000, None, False, False)),
        "run_length": ("int", (2, None, False, False)),
        "trend_length": ("int", (3, None, False, False)),
        "q_mp_limit": ("number", (0.0, 1.0, True, False)),
        "coverage_factor": ("number", _GT0),
    },
    "offsets": {
        "tool": ("int", (1, None, False, False)),
        "x_mode": ("choice", ("diameter", "radius")),
        "null_band": ("length", _GE0),
        "feedback_gain": ("number", _GAIN),
        "upper_limit": ("length", _GT0),
        "k_significance": ("number", _GE0),
        "decimals": ("int", (1, 6, False, False)),
        "nose_radius": ("choice", ("auto", "always", "off")),
        "current_x": ("length", None),
        "current_z": ("length", None),
        "current_r": ("length", _GE0),
        "x_features": ("ids", None),
        "z_features": ("ids", None),
    },
    "errspec": {
        "comp_type": ("int", (0, 1, False, False)),
        "decimals": ("int", (1, 12, False, False)),
        "points_per_feature": ("int", (2, 256, False, False)),
        "machine_units": ("choice", ("mm", "inch")),
    },
    "plan": {
        "points": ("int", (1, 200, False, False)),
        "ratio": ("number", _GT0),
        "clearance": ("length", _GT0),
        "end_clearance": ("length", _GE0),
        "overtravel": ("length", _GT0),
        "spacing": ("length", _GT0),
        "inside_share": ("number", (0.0, 0.5, False, False)),
        "rapid_feed": ("length", _GT0),
        "controller": ("choice", ("linuxcnc", "fanuc")),
        "x_mode": ("choice", ("diameter", "radius")),
        "probe_on": ("words", None),
        "probe_off": ("words", None),
        "probe_file": ("name", None),
        "log_file": ("name", None),
        "program_number": ("int", (1, 9999, False, False)),
    },
}
#: G-code words as a `words` value is written into a program (`M64 P0`, `M19`)
_WORDS = re.compile(r"[A-Z][+-]?[0-9]+(\.[0-9]+)?( [A-Z][+-]?[0-9]+(\.[0-9]+)?)*")
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")


def _bounds_text(b) -> str:
    lo, hi, lo_open, hi_open = b
    if hi is None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if lo is None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def _in_bounds(v, b) -> bool:
    lo, hi, lo_open, hi_open = b
    if lo is not None and (v <= lo if lo_open else v < lo):
        return False
    return not (hi is not None and (v >= hi if hi_open else v > hi))


def read_job_section(r: Reader, tree: dict, name: str, scale: float, profile: Profile) -> dict:
    """Validate one of the job sections (`[decision]`, `[capability]`, `[offsets]`,
    `[errspec]`): known keys only, each of the right type and range; lengths in mm."""
    sec = r.table(tree, name, "")
    spec = JOB_KEYS[name]
    out: dict[str, Any] = {}
    for key, val in sec.items():
        path = f"{name}.{key}"
        if key not in spec:
            raise r.error(
                path, f"unknown key {key!r}; expected one of {', '.join(spec)}", value=val
            )
        kind, bounds = spec[key]
        if kind == "choice":
            if val not in bounds:
                raise r.error(
                    path,
                    f"unknown value {val!r}; expected one of {', '.join(map(repr, bounds))}",
                    value=val,
                )
            out[key] = val
            continue
        if kind in ("words", "name"):
            pattern, what = (
                (_WORDS, "G-code words such as 'M64 P0'")
                if kind == "words"
                else (_NAME, "a file name of letters, digits, '_', '.' and '-'")
            )
            if not isinstance(val, str) or pattern.fullmatch(val) is None:
                raise r.error(path, f"expected {what}, got {val!r}", value=val)
            out[key] = val
            continue
        if kind == "bool":
            if not isinstance(val, bool):
                raise r.error(path, f"expected true or false, got {val!r}", value=val)
            out[key] = val
            continue
        if kind == "ids":
            if not isinstance(val, list) or not all(isinstance(v, str) for v in val):
                raise r.error(path, f"expected a list of feature ids, got {val!r}", value=val)
            for v in val:
                if v not in profile.ids:
                    raise r.error(
                        path,
                        f"unknown feature id {v!r}; the profile has {', '.join(profile.ids)}",
                        feature=v,
                        value=v,
                    )
            out[key] = tuple(val)
            continue
        if kind == "int":
            if isinstance(val, bool) or not isinstance(val, int):
                raise r.error(path, f"expected an integer, got {val!r}", value=val)
        elif isinstance(val, bool) or not isinstance(val, (int, float)):
            raise r.error(path, f"expected a number, got {val!r}", value=val)
        elif not math.isfinite(val):
            raise r.error(path, f"expected a finite number, got {val!r}", value=val)
        if bounds is not None and not _in_bounds(val, bounds):
            raise r.error(path, f"expected a number {_bounds_text(bounds)}, got {val!r}", value=val)
        if kind == "length":
            val = float(val) * scale
        elif kind == "per_mm2":
            val = float(val) / scale**2
        elif kind == "number":
            val = float(val)
        out[key] = val
    return out


def read_plausibility(r: Reader, tree: dict, scale: float) -> dict:
    """`[plausibility]`: limits of the checks made before fitting (docs/formats.md)."""
    out: dict[str, Any] = {}
    for key in ("max_distance", "max_outside"):
        if key in tree:
            out[key] = r.number(tree, key, "plausibility.", positive=True) * scale
    out["duplicates"] = r.choice(tree, "duplicates", "plausibility.", ("drop", "error"), "drop")
    return out


def read_program_settings(
    r: Reader, tree: dict, scale: float, profile: Profile, base: Path
) -> ProgramSettings:
    """`[program]`: the tool-nose radius or tool table, the explicit feature -> lines
    mapping and the on-feature tolerance (mm)."""
    nose = (
        r.number(tree, "nose_radius", "program.", positive=True) * scale
        if "nose_radius" in tree
        else None
    )
    table = tree.get("tool_table")
    if table is not None:
        if not isinstance(table, str):
            raise r.error("program.tool_table", f"expected a file name, got {table!r}", value=table)
        table = base / table
        if not table.is_file():
            raise r.error("program.tool_table", f"tool table not found: {table}", value=str(table))
    mapping = tree.get("mapping", {})
    if not isinstance(mapping, dict):
        raise r.error(
            "program.mapping", f"expected a table {{feature = [line, ...]}}, got {mapping!r}"
        )
    clean = {}
    for fid, lines in mapping.items():
        if fid not in profile.ids:
            raise r.error(
                f"program.mapping.{fid}",
                f"unknown feature id {fid!r}; the profile has {', '.join(profile.ids)}",
                feature=fid,
            )
        if isinstance(lines, int) and not isinstance(lines, bool):
            lines = [lines]
        if (
            not isinstance(lines, list)
            or not lines
            or not all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in lines)
        ):
            raise r.error(
                f"program.mapping.{fid}",
                f"expected program line numbers (positive integers), got {lines!r}",
                feature=fid,
                value=lines,
            )
        clean[fid] = tuple(lines)
    tip = None
    if "path_tip" in tree:
        tip = r.integer(tree, "path_tip", "program.", 0, minimum=0)
        if tip > 9:
            raise r.error("program.path_tip", f"expected a LinuxCNC orientation 0-9, got {tip}",
                          value=tip)  # fmt: skip
        if nose is None:
            raise r.error(
                "program.path_tip", "a tool path needs its nose: give program.nose_radius"
            )
    return ProgramSettings(
        nose_radius=nose,
        path_tip=tip,
        tool_table=table,
        mapping=MappingProxyType(clean),
        tolerance=r.number(tree, "tolerance", "program.", 0.01 / scale, positive=True) * scale,
        stock=r.number(tree, "stock", "program.", 0.5 / scale, nonneg=True) * scale,
        dialect=(
            r.choice(tree, "dialect", "program.", PROGRAM_DIALECTS, None)
            if "dialect" in tree
            else None
        ),
    )

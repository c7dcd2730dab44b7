"""The text of a study file (TOML) written from data: [`study_toml`][].

The inverse of the loader (`_study.load_study`) for what a new study holds:
`[study]`, `[profile]` with its features, `[probe]` and `[program]`, each key
with an optional comment, each feature with comment lines above its table.
Values are given **as the file writes them** (the study's units, X as its
`x_mode` says); the writer only formats them. A number is written as the
shortest decimal that is within 1e-12 (relative) of the value, else with
Python's `repr` (which round-trips exactly), so that the loaded geometry
equals the given one to far better than 1e-9 mm.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Setting:
    """One `key = value` line; `commented` writes it as a comment (a placeholder to
    fill in); `comment` follows the value after `#`."""

    key: str
    value: object
    comment: str = ""
    commented: bool = False


@dataclass(frozen=True)
class FeatureText:
    """One `[[profile.feature]]` as written (the study's units and x mode)."""

    id: str
    type: str
    start: tuple[float, float]
    end: tuple[float, float]
    tolerance: tuple[float, float]
    tolerance_on: str
    center: tuple[float, float] | None = None
    direction: str | None = None
    comments: tuple[str, ...] = ()
    """Lines written as comments above the table (e.g. the program line it comes from)."""
    tolerance_comment: str = ""


@dataclass(frozen=True)
class StudyText:
    """A study file's content: `[study]` (`name`, `units`, `part_program`,
    `probe_files`), `[profile]` (`kind`, `x_mode`, `features`), and the settings
    of `[probe]` and `[program]`; `header` lines open the file as comments."""

    name: str
    units: str
    kind: str
    x_mode: str
    features: tuple[FeatureText, ...]
    part_program: str | None = None
    probe_files: tuple[str, ...] = ()
    header: tuple[str, ...] = ()
    study_comments: dict | None = None
    """key of `[study]` or `[profile]` -> its comment (``"kind"``, ``"probe_files"``)."""
    probe: tuple[Setting, ...] = ()
    program: tuple[Setting, ...] = ()


def toml_number(value: float) -> str:
    """`value` as a TOML float: the shortest decimal within 1e-12 (relative) of it,
    else `repr`; never ``-0.0``."""
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"cannot write {value!r} in a study file")
    if v == 0.0:
        return "0.0"
    tol = 1e-12 * max(1.0, abs(v))
    for k in range(1, 13):
        text = f"{v:.{k}f}"
        if abs(float(text) - v) <= tol:
            return "0.0" if float(text) == 0.0 else text
    return repr(v)


def _string(text: str) -> str:
    clean = str(text).encode("utf-8", "replace").decode("utf-8")
    return json.dumps(clean, ensure_ascii=False)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, (int, float)):
        return toml_number(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} in a study file")


def _comment_text(text: str) -> str:
    """A comment's text on one line, without control characters."""
    clean = str(text).encode("utf-8", "replace").decode("utf-8")
    return " ".join("".join(c if c.isprintable() else " " for c in clean).split())


def _line(key: str, value, comment: str = "", commented: bool = False) -> str:
    text = f"{key} = {_value(value)}"
    if commented:
        text = f"# {text}"
    if comment:
        text = f"{text:<36} # {_comment_text(comment)}"
    return text


def _feature(f: FeatureText) -> list[str]:
    out = [f"# {_comment_text(c)}" for c in f.comments]
    out += ["[[profile.feature]]", _line("id", f.id), _line("type", f.type)]
    out += [_line("start", list(f.start)), _line("end", list(f.end))]
    if f.center is not None:
        out += [_line("center", list(f.center)), _line("direction", f.direction)]
    out += [
        _line("tolerance", list(f.tolerance), f.tolerance_comment),
        _line("tolerance_on", f.tolerance_on),
    ]
    return out


def study_toml(study: StudyText) -> str:
    """The TOML text of `study` (see the module doc); ends with a newline."""
    notes = dict(study.study_comments or {})
    out = [f"# {_comment_text(h)}" if h else "#" for h in study.header]
    if out:
        out.append("")
    out += ["[study]", _line("name", study.name), _line("units", study.units)]
    out.append(_line("probe_files", list(study.probe_files), notes.get("probe_files", "")))
    if study.part_program is not None:
        out.append(_line("part_program", study.part_program, notes.get("part_program", "")))
    out += ["", "[profile]", _line("kind", study.kind, notes.get("kind", ""))]
    out.append(_line("x_mode", study.x_mode, notes.get("x_mode", "")))
    for f in study.features:
        out += ["", *_feature(f)]
    for name, settings in (("probe", study.probe), ("program", study.program)):
        if not settings:
            continue
        out += ["", f"[{name}]"]
        out += [_line(s.key, s.value, s.comment, s.commented) for s in settings]
    return "\n".join(out) + "\n"

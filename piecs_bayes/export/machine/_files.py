"""The machine files of one fitted part, written and read back: the native error
spec (JSON + CSV tables), LinuxCNC joint compensation tables with their INI lines,
and the tool-offset update (JSON, Fanuc and LinuxCNC G10 blocks).

The error spec and the tool-offset update are two routes of one correction
(`jobs.apply_route`): `routes` says which to write, and those in `alternatives`
carry "alternative: do not combine" in their header (`mark_alternative`).
"""

from __future__ import annotations

import json
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

from ...compensate import ErrorSpec, ToolOffsets, ToolOffsetUpdate
from ...errors import AnalysisError, InputError
from ...io import write_text_atomic
from ._errspec import read_errspec, write_errspec
from ._linuxcnc import read_linuxcnc_comp, write_linuxcnc_comp
from ._offsets import g10_fanuc, g10_linuxcnc, offsets_from_json, offsets_to_json

if TYPE_CHECKING:  # the type only: the job computes, this writes
    from ...jobs import MachineData

#: the mark of a file of a route that is not the one to load
ALTERNATIVE = "alternative: do not combine"


def alternative_note(chosen: str) -> str:
    """The header note of an alternative route's files (no parentheses: it goes
    into G-code comments too)."""
    return (
        f"{ALTERNATIVE} with the route chosen, {chosen!r}: each route carries the whole "
        "correction, two together apply it twice"
    )


def mark_alternative(name: str, text: str, note: str) -> str:
    """`text` of file `name` with `note` in its header, in the file's own comment
    syntax: G-code `(...)` after a leading `%` and O-number line, `#` lines for
    INI and diff files, a top-level `"note"` for JSON. LinuxCNC comp tables take
    their notes at the end instead (see `_linuxcnc`)."""
    if name.endswith(".json"):
        return json.dumps({"note": note, **json.loads(text)}, indent=2) + "\n"
    if name.endswith((".ini", ".diff")):
        return f"# {note}\n{text}"
    lines = text.splitlines(keepends=True)
    eol = "\r\n" if lines and lines[0].endswith("\r\n") else "\n"
    i = 1 if lines and lines[0].strip() == "%" else 0
    if i < len(lines) and lines[i].lstrip()[:1] in ("O", "o") and lines[i].lstrip()[1:2].isdigit():
        i += 1
    return "".join([*lines[:i], f"({note}){eol}", *lines[i:]])


@dataclass(frozen=True, eq=False)
class CompensationOutputs:
    """What [`write_compensation_outputs`][] wrote and refused, with notes; `files`
    maps each route written (`"errspec"`, `"tool_offset"`) to its files."""

    errspec: ErrorSpec
    offsets: ToolOffsetUpdate | None
    written: tuple[Path, ...]
    refused: tuple[str, ...]
    notes: tuple[str, ...] = ()
    linuxcnc: Mapping[str, Path] = field(default_factory=dict)
    files: Mapping[str, tuple[Path, ...]] = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = []
        if "errspec" in self.files:
            out.append(f"error spec: {len(self.errspec.tables)} table(s)")
            for name, p in self.linuxcnc.items():
                out.append(f"LinuxCNC comp table {p.name}: {name}")
            out += [f"not written as a LinuxCNC table: {r}" for r in _grouped(self.refused)]
        if self.offsets is not None and "tool_offset" in self.files:
            out += [f"tool offsets: {line}" for line in repr(self.offsets).splitlines()]
        out += [f"note: {n}" for n in self.notes]
        return out


def _ini_text(files: Mapping[str, Path], comp_type: int, units: str, refused, comps) -> str:
    joints = {"x": 0, "z": 1}
    lines = [
        "# LinuxCNC joint compensation written by piecs-bayes: copy into the machine's INI.",
        "# Positions and trims in machine units "
        f"({units}), X as radius. Joint numbers assume an XZ",
        "# lathe (trivkins: X = joint 0, Z = joint 1): check yours. BACKLASH is ignored",
        "# when COMP_FILE is set.",
        "# A table acts on every move of its joint, rapids, cuts and probing moves alike:",
        "# probe points taken with it loaded are shifted by its trim. Outside its range",
        "# LinuxCNC holds the end values (the trim of the first or last entry).",
    ]
    for name, p in files.items():
        axis = "x" if name.startswith("x") else "z"
        lo, hi = comps[name]
        lines += [
            "",
            f"# {p.name}: table {name}, range {lo} to {hi} {units}",
            f"[JOINT_{joints[axis]}]",
            f"COMP_FILE = {p.name}",
            f"COMP_FILE_TYPE = {comp_type}",
        ]
    if refused:
        lines += ["", "# Not written as LinuxCNC tables (the format cannot express them):"]
        lines += [f"#   {r}" for r in _grouped(refused)]
    return "\n".join(lines) + "\n"


def write_compensation_outputs(
    study,
    data: MachineData,
    out,
    *,
    protect=(),
    routes: Collection[str] | None = None,
    alternatives: Collection[str] = (),
    chosen: str | None = None,
) -> CompensationOutputs:
    """Write the error spec (native JSON + CSV), the LinuxCNC table(s) and the
    tool-offset update of one fitted part into folder `out`: `data` as the job
    `jobs.machine_data` made it (for `routes`), `study` for the files' settings.

    Files: `compensation.errspec.json` + `compensation.<table>.csv`;
    `linuxcnc_x.comp`, `linuxcnc_z.comp` (`COMP_FILE_TYPE` from `[errspec] comp_type`,
    default 0; notes after the last entry: range, end values held outside it, every
    move including probing) and `linuxcnc_comp.ini` (the INI lines, the same notes,
    and the tables refused with the reason); `tool_offsets.json`,
    `tool_offsets_fanuc.ngc` (incremental `G10 P U W C`, or absolute with the current
    values) and `tool_offsets_linuxcnc.ngc` (`G10 L1`, absolute: only when `[offsets]`
    gives the current values). Every file is re-read and validated after writing. A
    blocked offset update writes only the JSON (which says why).

    `routes` chooses what is written: `"errspec"` (the error spec and the LinuxCNC
    files), `"tool_offset"` (the offset files); each one `data` was made for (default:
    all of them, `data.routes`).
    The routes in `alternatives` are marked [`ALTERNATIVE`][] in each file's header,
    naming the route `chosen`.
    """
    out = Path(out)
    protect = list(protect)
    routes = data.routes if routes is None else tuple(routes)
    missing = [r for r in routes if r not in data.routes]
    if missing:
        raise ValueError(
            f"no machine data for route(s) {', '.join(map(repr, missing))}: make it with "
            "jobs.machine_data(..., routes=...)"
        )
    note = alternative_note(chosen or "another")
    spec = data.errspec
    written: list[Path] = []
    files: dict[str, tuple[Path, ...]] = {}
    refused: list[str] = []
    comp_files: dict[str, Path] = {}
    if "errspec" in routes:
        marked = note if "errspec" in alternatives else None
        written += _write_errspec_files(study, spec, out, protect, marked, refused, comp_files)
        files["errspec"] = tuple(written)
    notes: list[str] = []
    upd = None
    if "tool_offset" in routes:
        upd = data.offsets
        notes += data.notes
    if upd is not None:
        marked = note if "tool_offset" in alternatives else None
        files["tool_offset"] = tuple(_write_offsets(study, upd, out, protect, notes, marked))
        written += files["tool_offset"]
    return CompensationOutputs(
        errspec=spec,
        offsets=upd,
        written=tuple(written),
        refused=tuple(refused),
        notes=tuple(notes),
        linuxcnc=MappingProxyType(comp_files),
        files=MappingProxyType(files),
    )


def _write_errspec_files(study, spec, out: Path, protect, note, refused, comp_files) -> list:
    """The native error spec (re-read), the LinuxCNC tables that the format can
    express (re-read by LinuxCNC's rules) and `linuxcnc_comp.ini`; `note` (or None)
    marks them as an alternative."""
    cfg = study.errspec
    comp_type = int(cfg.get("comp_type", 0))
    units = cfg.get("machine_units", "mm")
    decimals = int(cfg.get("decimals", 6))
    if note is not None:
        spec = replace(spec, description=f"{note}. {spec.description}".strip())
    written = list(write_errspec(spec, out / "compensation.errspec.json", protect=protect))
    back = read_errspec(out / "compensation.errspec.json")
    if [t.name for t in back.tables] != [t.name for t in spec.tables]:
        raise AnalysisError("the written error spec does not read back as written")
    ranges = {}
    for t in spec.tables:
        try:  # refused before anything is written; re-read by LinuxCNC's rules after
            p = write_linuxcnc_comp(
                out / f"linuxcnc_{t.axis}.comp",
                t,
                comp_type=comp_type,
                decimals=decimals,
                machine_units=units,
                notes=() if note is None else (note,),
                protect=protect,
            )
        except AnalysisError as e:
            refused.append(f"{t.name}: {str(e).split('refused: ', 1)[-1]}")
            continue
        comp = read_linuxcnc_comp(p, comp_type=comp_type)
        ranges[t.name] = tuple(f"{float(v):.{decimals}f}" for v in comp.nominal[[0, -1]])
        comp_files[t.name] = p
        written.append(p)
    ini = _ini_text(comp_files, comp_type, units, refused, ranges)
    if note is not None:
        ini = mark_alternative("linuxcnc_comp.ini", ini, note)
    written.append(write_text_atomic(out / "linuxcnc_comp.ini", ini, protect=protect))
    return written


def _grouped(refused: Sequence[str]) -> list[str]:
    """'name: why' lines with the same reason merged: 'a, b: why'."""
    by: dict[str, list[str]] = {}
    for r in refused:
        name, _, why = r.partition(": ")
        by.setdefault(why, []).append(name)
    return [f"{', '.join(names)}: {why}" for why, names in by.items()]


def _write_offsets(study, upd: ToolOffsetUpdate, out: Path, protect, notes: list, note=None):
    """tool_offsets.json (re-read and validated) and, unless the update is blocked,
    the Fanuc G10 blocks and (with the current values) the LinuxCNC ones; `note`
    (or None) marks them as an alternative."""

    def put(name: str, text: str) -> Path:
        text = text if note is None else mark_alternative(name, text, note)
        return write_text_atomic(out / name, text, protect=protect)

    p = put("tool_offsets.json", offsets_to_json(upd))
    offsets_from_json(p.read_text(), file=str(p))  # re-read and validated
    written = [p]
    if upd.blocked:
        notes.append(f"tool offsets: no G10 written: {upd.reasons[0]}")
        return written
    cur = study.offsets
    current = ToolOffsets(cur.get("current_x"), cur.get("current_z"), cur.get("current_r"))
    has_current = any(v is not None for v in (current.x, current.z, current.r))
    fanuc = g10_fanuc(upd, current=current if has_current else None)
    written.append(put("tool_offsets_fanuc.ngc", fanuc))
    try:
        text = g10_linuxcnc(upd, current=current)
    except InputError as e:
        notes.append(
            f"tool_offsets_linuxcnc.ngc not written: {e.reason} "
            "([offsets] current_x, current_z, current_r)"
        )
    else:
        written.append(put("tool_offsets_linuxcnc.ngc", text))
    return written

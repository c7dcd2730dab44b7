"""The machine files of one fitted part, written and read back: the native error
spec (JSON + CSV tables), LinuxCNC joint compensation tables with their INI lines,
and the tool-offset update (JSON, Fanuc and LinuxCNC G10 blocks).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from ..compensate import ErrorSpec, ToolOffsets, ToolOffsetUpdate
from ..errors import AnalysisError, InputError
from ..io import write_text_atomic
from ..jobs import error_spec, tool_offsets
from ._errspec import read_errspec, write_errspec
from ._linuxcnc import write_linuxcnc_comp
from ._offsets import g10_fanuc, g10_linuxcnc, offsets_from_json, offsets_to_json

__all__ = ["CompensationOutputs", "write_compensation_outputs"]


@dataclass(frozen=True, eq=False)
class CompensationOutputs:
    """What [`write_compensation_outputs`][] wrote and refused, with notes."""

    errspec: ErrorSpec
    offsets: ToolOffsetUpdate | None
    written: tuple[Path, ...]
    refused: tuple[str, ...]
    notes: tuple[str, ...] = ()
    linuxcnc: Mapping[str, Path] = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = [f"error spec: {len(self.errspec.tables)} table(s)"]
        for name, p in self.linuxcnc.items():
            out.append(f"LinuxCNC comp table {p.name}: {name}")
        out += [f"not written as a LinuxCNC table: {r}" for r in _grouped(self.refused)]
        if self.offsets is not None:
            out += [f"tool offsets: {line}" for line in repr(self.offsets).splitlines()]
        out += [f"note: {n}" for n in self.notes]
        return out


def _ini_text(files: Mapping[str, Path], comp_type: int, units: str, refused) -> str:
    joints = {"x": 0, "z": 1}
    lines = [
        "# LinuxCNC joint compensation written by piecs-bayes: copy into the machine's INI.",
        "# Positions and trims in machine units "
        f"({units}), X as radius. Joint numbers assume an XZ",
        "# lathe (trivkins: X = joint 0, Z = joint 1): check yours. BACKLASH is ignored",
        "# when COMP_FILE is set.",
    ]
    for name, p in files.items():
        axis = "x" if name.startswith("x") else "z"
        lines += [
            "",
            f"[JOINT_{joints[axis]}]",
            f"COMP_FILE = {p.name}",
            f"COMP_FILE_TYPE = {comp_type}",
        ]
    if refused:
        lines += ["", "# Not written as LinuxCNC tables (the format cannot express them):"]
        lines += [f"#   {r}" for r in _grouped(refused)]
    return "\n".join(lines) + "\n"


def write_compensation_outputs(study, fit, out, *, gain=None, protect=()) -> CompensationOutputs:
    """Write the error spec (native JSON + CSV), the LinuxCNC table(s) and the
    tool-offset update of one fitted part into folder `out`.

    Files: `compensation.errspec.json` + `compensation.<table>.csv`;
    `linuxcnc_x.comp`, `linuxcnc_z.comp` (`COMP_FILE_TYPE` from `[errspec] comp_type`,
    default 0) and `linuxcnc_comp.ini` (the INI lines, and the tables refused with
    the reason); `tool_offsets.json`, `tool_offsets_fanuc.ngc` (incremental
    `G10 P U W C`, or absolute with the current values) and
    `tool_offsets_linuxcnc.ngc` (`G10 L1`, absolute: only when `[offsets]` gives the
    current values). Every file is re-read and validated after writing. A blocked
    offset update writes only the JSON (which says why).
    """
    out = Path(out)
    protect = list(protect)
    cfg = study.errspec
    comp_type = int(cfg.get("comp_type", 0))
    units = cfg.get("machine_units", "mm")
    decimals = int(cfg.get("decimals", 6))
    spec = error_spec(study, fit, gain=gain)
    written = list(write_errspec(spec, out / "compensation.errspec.json", protect=protect))
    back = read_errspec(out / "compensation.errspec.json")
    if [t.name for t in back.tables] != [t.name for t in spec.tables]:
        raise AnalysisError("the written error spec does not read back as written")
    refused, comp_files = [], {}
    for t in spec.tables:
        try:  # refused before anything is written; re-read by LinuxCNC's rules after
            p = write_linuxcnc_comp(
                out / f"linuxcnc_{t.axis}.comp",
                t,
                comp_type=comp_type,
                decimals=decimals,
                machine_units=units,
                protect=protect,
            )
        except AnalysisError as e:
            refused.append(f"{t.name}: {str(e).split('refused: ', 1)[-1]}")
            continue
        comp_files[t.name] = p
        written.append(p)
    written.append(
        write_text_atomic(
            out / "linuxcnc_comp.ini",
            _ini_text(comp_files, comp_type, units, refused),
            protect=protect,
        )
    )
    notes: list[str] = []
    upd = None
    try:
        upd, onotes = tool_offsets(study, fit)
        notes += onotes
    except AnalysisError as e:
        notes.append(str(e))
    if upd is not None:
        written += _write_offsets(study, upd, out, protect, notes)
    return CompensationOutputs(
        errspec=spec,
        offsets=upd,
        written=tuple(written),
        refused=tuple(refused),
        notes=tuple(notes),
        linuxcnc=MappingProxyType(comp_files),
    )


def _grouped(refused: Sequence[str]) -> list[str]:
    """'name: why' lines with the same reason merged: 'a, b: why'."""
    by: dict[str, list[str]] = {}
    for r in refused:
        name, _, why = r.partition(": ")
        by.setdefault(why, []).append(name)
    return [f"{', '.join(names)}: {why}" for why, names in by.items()]


def _write_offsets(study, upd: ToolOffsetUpdate, out: Path, protect, notes: list) -> list[Path]:
    """tool_offsets.json (re-read and validated) and, unless the update is blocked,
    the Fanuc G10 blocks and (with the current values) the LinuxCNC ones."""
    p = write_text_atomic(out / "tool_offsets.json", offsets_to_json(upd), protect=protect)
    offsets_from_json(p.read_text(), file=str(p))  # re-read and validated
    written = [p]
    if upd.blocked:
        notes.append(f"tool offsets: no G10 written: {upd.reasons[0]}")
        return written
    cur = study.offsets
    current = ToolOffsets(cur.get("current_x"), cur.get("current_z"), cur.get("current_r"))
    has_current = any(v is not None for v in (current.x, current.z, current.r))
    fanuc = g10_fanuc(upd, current=current if has_current else None)
    written.append(write_text_atomic(out / "tool_offsets_fanuc.ngc", fanuc, protect=protect))
    try:
        text = g10_linuxcnc(upd, current=current)
    except InputError as e:
        notes.append(
            f"tool_offsets_linuxcnc.ngc not written: {e.reason} "
            "([offsets] current_x, current_z, current_r)"
        )
    else:
        written.append(write_text_atomic(out / "tool_offsets_linuxcnc.ngc", text, protect=protect))
    return written

"""One route to the machine: write the chosen route's files, and on request the
others marked "alternative: do not combine", and say what to load, where, and
what not to combine.

The routes (`jobs.apply_route` chooses one):

- `"program"`: the adjusted part program (`<stem>_adjusted<suffix>`) with its diff;
- `"errspec"`: the error specification: LinuxCNC joint compensation tables with
  their INI lines, and the same correction as native tables (`compensation.*`);
- `"tool_offset"`: the tool-offset update (`tool_offsets*`: JSON and G10 blocks);
- `"none"`: no machine file.

Each carries the whole correction: loading two applies it twice.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from ...compensate import ToolOffsets
from ...errors import AnalysisError, InputError
from ...io import write_text_atomic
from ._files import (
    ALTERNATIVE,
    CompensationOutputs,
    alternative_note,
    mark_alternative,
    write_compensation_outputs,
)
from ._linuxcnc import linuxcnc_comp_text
from ._offsets import g10_linuxcnc

#: what each route loads, in words
ROUTE_TITLES = {
    "program": "the adjusted part program",
    "errspec": "the error specification (LinuxCNC comp tables, or the native tables)",
    "tool_offset": "the tool-offset update (G10 blocks)",
    "none": "nothing",
}


@dataclass(frozen=True, eq=False)
class MachineFiles:
    """What [`write_machine_files`][] wrote: `route` (the one to load) and `why`,
    `files` by route (the chosen route's and, with alternatives, the others'), the
    notes of the steps, and `compensation` (the error spec and offsets written, or
    `None`). `instructions` say what to load, where, and what not to combine."""

    route: str
    why: str
    out: Path
    files: Mapping[str, tuple[Path, ...]] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    compensation: CompensationOutputs | None = None
    unavailable: Mapping[str, str] = field(default_factory=dict)
    program_source: str = ""

    @property
    def alternatives(self) -> tuple[str, ...]:
        """The routes written besides the chosen one (marked in their files)."""
        return tuple(r for r in self.files if r != self.route)

    @property
    def written(self) -> tuple[Path, ...]:
        return tuple(p for paths in self.files.values() for p in paths)

    def is_alternative(self, path) -> bool:
        """Whether `path` belongs to an alternative route (never to be combined)."""
        path = Path(path)
        return any(path in self.files[r] for r in self.alternatives)

    def _name(self, path: Path) -> str:
        try:
            return path.relative_to(self.out).as_posix()
        except ValueError:
            return str(path)

    def as_dict(self) -> dict:
        """decisions.json's `"apply"`: the route, its files (names in the output
        folder), and each alternative written with its files and the mark."""
        note = alternative_note(self.route)
        return {
            "route": self.route,
            "why": self.why,
            "files": [self._name(p) for p in self.files.get(self.route, ())],
            "alternatives": [
                {"route": r, "files": [self._name(p) for p in self.files[r]], "note": note}
                for r in self.alternatives
            ],
        }

    def lines(self) -> list[str]:
        """What the machine files hold (one line each), for the console."""
        return [] if self.compensation is None else self.compensation.lines()

    def instructions(self) -> list[str]:
        """What to load, where, and what not to combine (console, README, report)."""
        head = f"What to load on the machine: route {self.route!r} ({self.why})"
        if self.route == "none":
            body = ["nothing: the study (or --apply) says 'none'; no machine file is loaded"]
        else:
            why = self.unavailable.get(self.route)
            body = _load_lines(self) or [
                f"nothing to load: {ROUTE_TITLES[self.route]} was not written"
                + (f": {why}" if why else "")
                + (f" ({'; '.join(self.notes)})" if self.route == "tool_offset" else "")
            ]
        others = [ROUTE_TITLES[r] for r in ("program", "errspec", "tool_offset") if r != self.route]
        body.append(
            f"do not combine: {', '.join(others[:-1])} and {others[-1]} carry the same "
            "correction; two routes together apply it twice"
        )
        if self.alternatives:
            body.append(
                f"files marked '{ALTERNATIVE}' ({', '.join(self.alternatives)}) are for "
                "another controller or a later choice, never in addition"
            )
        wrap = textwrap.TextWrapper(width=88, initial_indent="  - ", subsequent_indent="    ")
        return [head, *(line for item in body for line in wrap.wrap(item))]


def _load_lines(mf: MachineFiles) -> list[str]:
    names = {p.name: p for p in mf.files.get(mf.route, ())}
    if mf.route == "program":
        prog = [n for n in names if not n.endswith(".diff")]
        diff = [n for n in names if n.endswith(".diff")]
        if not prog:
            return []
        see = f"; {diff[0]} shows every change" if diff else ""
        source = mf.program_source or "the original program"
        return [
            f"{prog[0]}: load it on the control in place of {source} and run it for the "
            f"finish cut (only finish-cut coordinates differ{see})"
        ]
    if mf.route == "errspec":
        comps = [n for n in names if n.endswith(".comp")]
        out = []
        if comps:
            out.append(
                f"LinuxCNC: {', '.join(comps)} beside the machine's INI file, with the "
                "[JOINT_n] lines of linuxcnc_comp.ini; restart LinuxCNC to load them. They "
                "act on every move of the joint, probing included: unload them before probing"
            )
        if "compensation.errspec.json" in names:
            out.append(
                "other controls: compensation.errspec.json with its compensation.*.csv "
                "tables (the same correction, native format); load one form, not both"
            )
        return out
    if mf.route == "tool_offset":
        if "tool_offsets_linuxcnc.ngc" in names:
            return [
                "LinuxCNC: run tool_offsets_linuxcnc.ngc once (MDI or as a program): "
                "G10 L1 sets the tool's offsets; other controls: tool_offsets_fanuc.ngc"
            ]
        if "tool_offsets_fanuc.ngc" in names:
            return [
                "run tool_offsets_fanuc.ngc once on the control (G10 wear offset; an "
                "incremental update run twice applies it twice)"
            ]
        return []
    return []


def write_machine_files(
    study,
    fit,
    out,
    *,
    route: tuple[str, str],
    alternatives: bool = False,
    program=None,
    program_path=None,
    unavailable: Mapping[str, str] | None = None,
    gain=None,
    protect=(),
) -> MachineFiles:
    """Write the files of `route` (and, with `alternatives`, of the other routes,
    each marked [`ALTERNATIVE`][] in its header) into folder `out`.

    **Arguments:**

    - `study`, `fit`: the study and the fit of the part (error spec, offsets).
    - `route`: `(route, why)`, the route chosen and why, as `jobs.apply_route` gives them.
    - `program`: the `ProgramAdjustment` of the program route, or `None` when there is
      none; `program_path` where it goes (default `out/<stem>_adjusted<suffix>`), its
      diff beside it (`<stem>.diff`, or the path's name + `.diff` when given).
    - `unavailable`: route -> why, for routes whose data the job could not make
      (nothing of them is written; the instructions say why).
    - `gain`, `protect`: the gain per feature for the error spec; files never written.

    **Returns:** a [`MachineFiles`][].
    """
    route, why = route
    out = Path(out)
    protect = list(protect)
    want = (
        ("program", "errspec", "tool_offset")
        if alternatives
        else ((route,) if route != "none" else ())
    )
    unavailable = dict(unavailable or {})
    if program is None and "program" not in unavailable:
        unavailable["program"] = "no adjusted program"
    want = tuple(r for r in want if r not in unavailable)
    alt = {r for r in want if r != route}
    note = alternative_note(route)
    files: dict[str, tuple[Path, ...]] = {}
    if "program" in want:
        files["program"] = _write_program(
            study, program, out, program_path, protect, note if "program" in alt else None
        )
    comp = None
    machine = [r for r in want if r in ("errspec", "tool_offset")]
    if machine:
        comp = write_compensation_outputs(
            study, fit, out, gain=gain, protect=protect, routes=machine, alternatives=alt,
            chosen=route,
        )  # fmt: skip
        files.update(comp.files)
    order = [route, *(r for r in ("program", "errspec", "tool_offset") if r != route)]
    return MachineFiles(
        route=route,
        why=why,
        out=out,
        files=MappingProxyType({r: files[r] for r in order if r in files}),
        notes=() if comp is None else comp.notes,
        compensation=comp,
        unavailable=MappingProxyType(unavailable),
        program_source=study.program.name if study.program is not None else "",
    )


def _write_program(study, adj, out: Path, path, protect, note) -> tuple[Path, Path]:
    """The adjusted program and its diff; `note` (or None) marks both alternative."""
    stem, suffix = study.program.stem, study.program.suffix
    if path is None:
        path, diff = out / f"{stem}_adjusted{suffix}", out / f"{stem}.diff"
    else:
        path = Path(path)
        diff = path.with_name(path.name + ".diff")
    text, dtext = adj.text, adj.diff
    if note is not None:
        text = mark_alternative(path.name, text, note)
        dtext = mark_alternative(diff.name, dtext, note)
    return (
        write_text_atomic(path, text, protect=protect),
        write_text_atomic(diff, dtext, protect=protect),
    )


def route_file_names(res) -> tuple[str, ...]:
    """The files to load of the route of `res` (a `JobResults`: `apply`, `study`,
    `program`, `errspec`, `offsets`), by name, as `demo` writes them: for a report
    that names them without writing them. Empty for `"none"` or a route whose data
    the job could not make."""
    study, route = res.study, getattr(res, "apply", None)
    if route == "program" and res.program is not None:
        return (f"{study.program.stem}_adjusted{study.program.suffix}",)
    if route == "errspec" and res.errspec is not None:
        cfg = study.errspec
        comps = []
        for t in res.errspec.tables:
            try:
                linuxcnc_comp_text(
                    t,
                    comp_type=int(cfg.get("comp_type", 0)),
                    decimals=int(cfg.get("decimals", 6)),
                    machine_units=cfg.get("machine_units", "mm"),
                )
            except AnalysisError:
                continue
            comps.append(f"linuxcnc_{t.axis}.comp")
        ini = ["linuxcnc_comp.ini"] if comps else []
        return (*comps, *ini, "compensation.errspec.json")
    upd = res.offsets
    if route == "tool_offset" and upd is not None and not upd.blocked:
        cur = study.offsets
        try:
            g10_linuxcnc(upd, current=ToolOffsets(*(cur.get(f"current_{a}") for a in "xzr")))
        except (InputError, AnalysisError):
            return ("tool_offsets_fanuc.ngc",)
        return ("tool_offsets_linuxcnc.ngc", "tool_offsets_fanuc.ngc")
    return ()

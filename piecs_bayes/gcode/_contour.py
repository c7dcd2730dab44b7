"""The finish contour of a lathe program: the part's profile as the program cuts it.

With tool-nose compensation on (G41/G42, G41.1/G42.1) a program describes the
**part's edge**, not the tool's path; that edge is the nominal profile of the study.
[`finish_contour`][] reads it from a [`GcodeProgram`][] and returns a
[`FinishContour`][]: the moves of one compensated run strictly between its lead-in and
its exit, one feature each ([`ContourSegment`][]: G1 a line, G2/G3 an arc with its
exact centre), the material side from G41/G42 and the kind (`"external"` or
`"internal"`) that follows. [`compensation_runs`][] lists the runs; a program with
several needs `run=` (1-based). Refused (:class:`~piecs_bayes.errors.InputError` with
the file, the line and why): no G41/G42 at all, a rapid inside the contour, a
full-circle arc, several runs without `run`, a run without features, a contour that
encloses no area with the spindle axis.

The rules: docs/models/part_programs.md, "The finish contour".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..errors import InputError
from ..geometry import ProfileError, profile_side
from ._program import CompSetting, GcodeProgram, Motion

#: the codes of the canned cycles, as ``Motion.via`` names the moves they make
CYCLE_CODES = frozenset(("G70", "G71", "G71.1", "G71.2", "G72", "G72.1", "G72.2", "G73"))


@dataclass(frozen=True)
class ContourSegment:
    """One feature of the contour: ``kind`` ``"line"`` or ``"arc"``; points ``(x, z)``
    in mm with x a radius; ``center``/``ccw`` for arcs (G3: ``ccw=True``); ``line``
    the program line it comes from and ``source`` that line's text (N word removed)."""

    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    line: int
    source: str
    block: str | None = None
    """The line's N word (``"N70"``), or None."""
    center: tuple[float, float] | None = None
    ccw: bool = False

    @property
    def spec(self) -> dict:
        """The plain spec `geometry.make_feature` / `profile_side` take (no id)."""
        spec = {"p0": self.start, "p1": self.end}
        if self.kind == "arc":
            spec.update(center=self.center, ccw=self.ccw)
        return spec

    @property
    def radius(self) -> float | None:
        return None if self.center is None else math.dist(self.center, self.start)


@dataclass(frozen=True)
class FinishContour:
    """The finish contour of one compensation run (see the module doc).

    ``segments`` in program order; ``comp`` the G41/G42 that switched it on;
    ``side`` the outward normal's side of travel (+1 left, -1 right) and ``kind``
    ``"external"`` / ``"internal"``; ``lead_in`` / ``exit`` the lines of the moves
    that are not features; ``off`` the line of G40 (None: the program's end);
    ``units`` the program's units in force over the contour (``"mm"`` / ``"in"``,
    None when they change within it); ``run`` / ``runs`` which run of how many;
    ``title`` the program's name (its O line's comment, else its first comment,
    else its O word; None without any) and ``program`` the file name."""

    segments: tuple[ContourSegment, ...]
    comp: CompSetting
    side: int
    kind: str
    lead_in: int
    exit: int
    off: int | None
    units: str | None
    run: int
    runs: int
    title: str | None
    program: str | None

    def __repr__(self) -> str:
        code = self.comp.code
        return (
            f"FinishContour({len(self.segments)} features, {self.kind}, {code} at line "
            f"{self.comp.line}; lead-in line {self.lead_in}, exit line {self.exit})"
        )


def compensation_runs(program: GcodeProgram) -> tuple[tuple[Motion, ...], ...]:
    """The moves of each compensation run (G41/G42 ... G40), in program order; a
    G41/G42 followed by no move makes no run. A canned cycle's moves are not one: the
    contour of a finish cycle (``GcodeProgram.cycles``: a LinuxCNC G70, a roughing
    cycle no G70 cuts) is, with its blocks' own lines; a Fanuc G70 runs its blocks."""
    found: list[tuple[int, list[Motion]]] = []
    last = -2
    for i, m in enumerate(program.moves):
        if m.comp is None or m.via in CYCLE_CODES:
            continue
        run = found[-1][1] if found else None
        if run is not None and last == i - 1 and run[-1].comp is m.comp and not m.entry:
            run.append(m)
        else:
            found.append((i, [m]))
        last = i
    for c in program.cycles:
        run = [m for m in c.contour if m.comp is not None]
        if c.finish and run:
            found.append((c.move_index, run))
    found.sort(key=lambda item: item[0])
    return tuple(tuple(r) for _, r in found)


def contour_view(program: GcodeProgram) -> GcodeProgram:
    """`program` with its moves as the blocks that describe the part: each canned
    cycle's moves replaced by its finish contour's blocks (``GcodeProgram.cycles``: a
    LinuxCNC G70's O-sub lines, a roughing cycle's P..Q blocks when no G70 cuts them),
    by nothing for a roughing cycle a G70 cuts. What maps and edits blocks in place
    (the adjusted program) reads this; a program without cycles is returned as it is."""
    if not program.cycles and not any(m.via in CYCLE_CODES for m in program.moves):
        return program
    records = {c.move_index: c.contour for c in program.cycles if c.finish}
    out: list[Motion] = []
    for i, m in enumerate(program.moves):
        out.extend(records.get(i, ()))
        if m.via not in CYCLE_CODES:
            out.append(m)
    out.extend(records.get(len(program.moves), ()))
    return replace(program, moves=tuple(out))


def _err(program, msg, line=None, value=None) -> InputError:
    return InputError(msg, file=program.name or "<program>", line=line, value=value)


def _off_line(program: GcodeProgram, comp: CompSetting) -> int | None:
    """The line of the G40 that ends the run switched on by `comp`."""
    on = False
    cycle_events = [e for c in program.cycles for e in c.events]
    for ev in [*program.events, *cycle_events]:
        if hasattr(ev, "kind"):
            continue
        if ev.setting is comp:
            on = True
        elif on and ev.setting is None:
            return ev.line
    return None


def _nose_side(comp: CompSetting) -> str:
    side = comp.side
    if comp.diameter_mm is not None and comp.diameter_mm < 0:
        side = "left" if side == "right" else "right"
    return side


def block_source(program: GcodeProgram, number: int) -> tuple[str, str | None]:
    """Line `number`'s text (its N word taken out, spaces made single) and its N word."""
    src = program.source.line(number)
    n = src.word("N")
    text = src.text
    if n is not None:
        text = text[: n.start] + text[n.end :]
    return " ".join(text.split()), (None if n is None else f"N{n.text}")


def program_title(program: GcodeProgram) -> str | None:
    """The program's name: its O line's comment, else its first comment, else its O word."""
    o_word = None
    for src in program.lines:
        o = src.word("O")
        if o is not None:
            o_word = f"O{o.text}"
            if src.comments:
                return src.comments[0].text.strip() or o_word
    for src in program.lines:
        if src.comments and all(w.letter in "NO" for w in src.words):
            text = src.comments[0].text.strip()
            if text:
                return text
    return o_word


def _segments(program: GcodeProgram, run) -> list[ContourSegment]:
    out = []
    for m in run[1:-1]:
        if m.kind == "rapid":
            raise _err(
                program,
                f"a rapid (G0) inside the compensated contour (between its lead-in at line "
                f"{run[0].line} and its exit at line {run[-1].line}): a rapid cuts no "
                "feature; program it as G1, or end the contour (G40) before it",
                m.line,
            )
        if m.is_arc and m.start == m.end:
            raise _err(program, "a full-circle arc is not a feature of a turned profile", m.line)
        if m.start == m.end:
            continue  # a zero-length move: no feature
        text, block = block_source(program, m.line)
        if m.is_arc:
            seg = ContourSegment(
                "arc", m.start, m.end, m.line, text, block, m.exact_center(), m.ccw
            )
        else:
            seg = ContourSegment("line", m.start, m.end, m.line, text, block)
        out.append(seg)
    return out


def finish_contour(program: GcodeProgram, *, run: int | None = None) -> FinishContour:
    """The finish contour of `program`: one feature per move of a G41/G42 run
    between its lead-in and its exit (see the module doc for the rules).

    **Arguments:**

    - `program`: a read [`GcodeProgram`][] (`read_gcode`).
    - `run`: which compensation run (1-based) when the program has several.

    **Returns:** a [`FinishContour`][] (mm, radius X, program coordinates).

    **Raises:** [`InputError`][piecs_bayes.errors.InputError] naming the program,
    the line and why, for every contour it cannot represent.
    """
    runs = compensation_runs(program)
    if not runs:
        first = next((m.line for m in program.moves if m.kind != "rapid"), None)
        raise _err(
            program,
            "no nose compensation (G41/G42) in the program: the path is the tool's, not the "
            "part's; program the finish contour with G41/G42 ... G40, or give the path's nose "
            "radius and the point it is written for (init --nose-radius R --tip T)"
            + ("" if first is None else " (this is its first cutting move)"),
            first,
        )
    if run is None and len(runs) > 1:
        each = [
            f"run {i}: lines {r[0].comp.line}-{r[-1].line} ({r[0].comp.code})"
            for i, r in enumerate(runs, 1)
        ]
        lines = "; ".join(each if len(each) <= 4 else [*each[:3], "...", each[-1]])
        raise _err(
            program,
            f"{len(runs)} compensated runs ({lines}): choose the finish contour with --run N",
        )
    k = 1 if run is None else int(run)
    if not 1 <= k <= len(runs):
        raise _err(program, f"--run {run}: the program has {len(runs)} compensated run(s)")
    moves = runs[k - 1]
    comp = moves[0].comp
    if len(moves) < 3:
        raise _err(
            program,
            f"the compensated run of {comp.code} (line {comp.line}) has no feature between "
            f"its lead-in (line {moves[0].line}) and its exit (line {moves[-1].line}): the "
            "first compensated move brings the nose onto the contour and the last leaves it",
            comp.line,
        )
    segments = _segments(program, moves)
    if not segments:
        raise _err(
            program,
            f"the compensated run of {comp.code} (line {comp.line}) has no feature between "
            f"its lead-in (line {moves[0].line}) and its exit (line {moves[-1].line}): "
            "only zero-length moves",
            comp.line,
        )
    side = 1 if _nose_side(comp) == "left" else -1
    try:
        outer = profile_side([s.spec for s in segments], internal=False)
    except ProfileError:
        raise _err(
            program,
            f"the contour (lines {segments[0].line}-{segments[-1].line}) encloses no area with "
            "the spindle axis (a lone face): its material side cannot be told",
            segments[0].line,
        ) from None
    units = {program.state(s.line).units for s in segments}
    return FinishContour(
        segments=tuple(segments),
        comp=comp,
        side=side,
        kind="external" if side == outer else "internal",
        lead_in=moves[0].line,
        exit=moves[-1].line,
        off=_off_line(program, comp),
        units=units.pop() if len(units) == 1 else None,
        run=k,
        runs=len(runs),
        title=program_title(program),
        program=program.name,
    )

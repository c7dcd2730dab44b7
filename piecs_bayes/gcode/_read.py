"""Reading a part program: [`read_gcode`][] (a file) and [`parse_gcode`][] (a text).

The text is lexed losslessly, its dialect taken as given or detected (with the
reason), and the program run as its control runs it (``_interp``: control flow and
parameters; ``_modal``: the modal state) into a :class:`~piecs_bayes.gcode.GcodeProgram`
whose moves are in mm, radius X. Nothing is dropped silently: what is not understood is
an :class:`~piecs_bayes.errors.InputError` naming the file, the line, the word and why.

What is read in each dialect: docs/models/part_programs.md and docs/formats.md.
"""

from __future__ import annotations

import gc
from dataclasses import replace
from pathlib import Path

from ..errors import InputError
from ._dialect import DIALECTS, Dialect, detect_dialect, dialect_table
from ._interp import Interpreter
from ._lexer import GcodeText, lex_gcode, read_text_lossless
from ._modal import ModalMachine
from ._options import ReadOptions
from ._program import GcodeProgram, LineState


def _dialect(dialect, options: ReadOptions, src: GcodeText) -> Dialect:
    given = dialect if dialect is not None else options.dialect
    if given is None:
        return detect_dialect(src)
    if isinstance(given, Dialect):
        given = given.name
    if given not in DIALECTS:
        raise InputError(
            f"dialect: got {given!r}, expected one of {', '.join(DIALECTS)}", file=src.name
        )
    return Dialect(given, "given")


def _check_lexed(src: GcodeText, interp: Interpreter) -> None:
    """A line that could not be lexed is refused even where the program never runs it
    (up to the tape's closing %: what follows it is not the program)."""
    lines = src.lines
    first = next((i for i, ln in enumerate(lines) if not ln.is_blank), None)
    tape = first is not None and lines[first].percent and not lines[first].words
    for i, line in enumerate(lines):
        if tape and i > first and line.percent and not line.words:
            return
        if line.error is not None:
            interp.lex_error(line)


def _states(src: GcodeText, interp: Interpreter, initial: LineState) -> tuple[LineState, ...]:
    """The state of each line after it first ran; a line that never ran gets the state
    of the line before it in the text."""
    out = []
    last = initial
    for line in src.lines:
        last = interp.states.get(line.number, last)
        out.append(last)
    return tuple(out)


def parse_gcode(
    text: str,
    dialect: str | Dialect | None = None,
    *,
    name: str | None = None,
    options: ReadOptions | None = None,
    units: str | None = None,
    diameter_mode: bool | None = None,
    start: tuple[float, float] | None = None,
) -> GcodeProgram:
    """Read a lathe part program from its text.

    **Arguments:**

    - `text`: the program text.
    - `dialect`: ``"linuxcnc" | "fanuc" | "haas" | "okuma"``; None: ``options.dialect``,
      else detected from the program (``GcodeProgram.dialect`` says which and why).
    - `name`: the name used in error messages.
    - `options`: a :class:`~piecs_bayes.gcode.ReadOptions` (units, diameter mode, start
      position, step limit, block delete, machine zero); `units`, `diameter_mode` and
      `start` given here override its fields.

    **Returns:** a :class:`~piecs_bayes.gcode.GcodeProgram` (``.moves`` in mm, radius X;
    ``.text`` is ``text`` unchanged).
    """
    options = options or ReadOptions()
    changes = {
        k: v
        for k, v in (("units", units), ("diameter_mode", diameter_mode), ("start", start))
        if v is not None
    }
    try:
        options = replace(options, **changes) if changes else options
    except InputError as exc:
        raise InputError(str(exc), file=name) from None
    collecting = gc.isenabled()
    gc.disable()  # a long program makes many small objects: the collector would rescan them
    try:
        return _parse(text, dialect, name, options)
    finally:
        if collecting:
            gc.enable()


def _parse(text: str, dialect, name: str | None, options: ReadOptions) -> GcodeProgram:
    src = lex_gcode(text, name=name, strict=False)
    chosen = _dialect(dialect, options, src)
    opts = options.resolved(chosen.name)
    table = dialect_table(chosen.name)
    turret = table.turret or not any(
        w.letter == "M" and w.expr is None and w.code == "M6" for ln in src.lines for w in ln.words
    )
    machine = ModalMachine(name, table, opts, turret)
    initial = machine.state()
    interp = Interpreter(src, table, opts, machine)
    _check_lexed(src, interp)
    interp.run()
    return GcodeProgram(
        src,
        tuple(machine.moves),
        tuple(machine.events),
        _states(src, interp, initial),
        opts,
        chosen,
        tuple(machine.notes),
        tuple(interp.runs),
        frozenset(interp.computed),
        tuple(interp.cycles),
    )


def read_gcode(
    path,
    dialect: str | Dialect | None = None,
    *,
    options: ReadOptions | None = None,
    units: str | None = None,
    diameter_mode: bool | None = None,
    start: tuple[float, float] | None = None,
) -> GcodeProgram:
    """Read a lathe part program file (see :func:`parse_gcode` for the arguments).

    The bytes are kept exactly (line endings, undecodable bytes), so
    ``program.source.to_bytes()`` equals the file's bytes.
    """
    path = Path(path)
    return parse_gcode(
        read_text_lossless(path),
        dialect,
        name=str(path),
        options=options,
        units=units,
        diameter_mode=diameter_mode,
        start=start,
    )

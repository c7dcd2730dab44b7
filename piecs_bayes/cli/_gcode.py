"""``piecs-bayes gcode ...``: part-program commands (nose compensation, reading check).

- ``gcode nose-comp IN -o OUT [--corner arc|extend] [--tool-table FILE]``
  writes an equivalent program with G41/G42/G40 resolved into the controlled
  point's path (lines outside compensation byte-identical).
- ``gcode check IN [--tool-table FILE] [--rs274]`` reads a program and prints
  what was understood: modes, moves, compensation runs and the side of the material
  each run's moves in air say (a warning where they do not tell it, or put the nose
  on the material side); with ``--rs274`` it also compares the compensated path with
  LinuxCNC's ``rs274``.

Errors: bad input exits 2, a gouge (analysis) exits 1 (mapped by ``cli.main``).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from . import _types as T


def register(subparsers) -> None:
    """Add the ``gcode`` command group to the CLI's subparsers."""
    p = subparsers.add_parser(
        "gcode",
        help="Part programs: resolve nose-radius compensation, check what is read.",
        description="Part-program commands (RS274 / ISO 6983 lathe dialect).",
        epilog="example:\n  piecs-bayes gcode nose-comp finish.ngc -o finish_nc.ngc "
        "--tool-table tool.tbl",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="gcode_command", metavar="ACTION")
    sub.required = True

    n = sub.add_parser(
        "nose-comp",
        help="Write the program with G41/G42/G40 resolved (no compensation words).",
        description="Resolve tool-nose radius compensation into the controlled point's path "
        "(LinuxCNC conventions for side and tool orientation) and write an equivalent program.",
        epilog="example:\n  piecs-bayes gcode nose-comp data/demo/finish.ngc "
        "-o reports/finish_nc.ngc "
        "--nose-radius 0.4 --corner extend",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    n.add_argument("program", type=Path, help="input part program (.ngc/.nc)")
    n.add_argument("-o", "--output", type=Path, required=True, help="output program")
    n.add_argument(
        "--corner",
        choices=("arc", "extend"),
        default="arc",
        help="convex corners: 'arc' inserts an arc like LinuxCNC (default); 'extend' uses the "
        "1969 bisector / offset-intersection rule",
    )
    n.add_argument(
        "--kind",
        choices=("auto", "external", "internal", "unchecked"),
        default="auto",
        help="where the material is, to refuse G41/G42 on the side that cuts into the part: "
        "'external' (OD), 'internal' (bore), 'auto' (default: the moves in air around each "
        "compensated run say it, its entry, exit and rapids; a run they do not tell is "
        "refused) or 'unchecked'",
    )
    _common(n)
    n.set_defaults(func=cmd_nose_comp)

    c = sub.add_parser(
        "check",
        help="Read a program and print what was understood.",
        description="Read a program and print what was understood: modes, moves, "
        "compensation runs.",
        epilog="example:\n  piecs-bayes gcode check data/demo/finish.ngc --nose-radius 0.4",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    c.add_argument("program", type=Path, help="part program (.ngc/.nc)")
    c.add_argument(
        "--rs274",
        action="store_true",
        help="also run LinuxCNC's rs274 on the program and on the resolved one and compare",
    )
    _common(c)
    c.set_defaults(func=cmd_check)


def _common(p) -> None:
    p.add_argument("--tool-table", type=Path, default=None, help="LinuxCNC tool table (.tbl)")
    p.add_argument(
        "--tool-units",
        choices=("mm", "in"),
        default="mm",
        help="units of the tool table's lengths (LinuxCNC: the machine units; the standalone "
        "rs274 reads inches). Default mm",
    )
    p.add_argument(
        "--nose-radius",
        type=T.positive_mm,
        default=None,
        help="nose radius (mm, > 0) for G41/G42 tools",
    )
    p.add_argument(
        "--units",
        choices=("mm", "in"),
        default="mm",
        help="units before the program's first G20/G21 (default mm)",
    )
    p.add_argument(
        "--diameter-mode",
        action="store_const",
        const=True,
        default=None,
        help="X words are diameters before the first G7/G8 (default: the dialect's: LinuxCNC "
        "radius, Fanuc/Haas/Okuma diameter)",
    )
    p.add_argument(
        "--dialect",
        choices=("linuxcnc", "fanuc", "haas", "okuma"),
        default=None,
        help="the program's dialect (default: detected from what it contains, and said)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="print only errors")


def _load(args):
    from ..gcode import read_gcode, read_tool_table

    program = read_gcode(
        args.program, args.dialect, units=args.units, diameter_mode=args.diameter_mode
    )
    tools = None
    if args.tool_table is not None:
        tools = read_tool_table(args.tool_table, units=args.tool_units)
    return program, tools


def cmd_nose_comp(args, console) -> int:
    from ..gcode import nose_compensate
    from ..io import write_bytes_atomic

    program, tools = _load(args)
    kind = None if args.kind == "unchecked" else args.kind
    result = nose_compensate(
        program, corner=args.corner, tool_table=tools, nose_radius=args.nose_radius, kind=kind
    )
    data = result.text.encode("utf-8", errors="surrogateescape")
    protect = [args.program] + ([args.tool_table] if args.tool_table else [])
    write_bytes_atomic(args.output, data, protect=protect)
    console.say(
        f"{args.program}: {len(result.path)} moves, {len(result.changed_lines)} lines rewritten "
        f"(corner rule {args.corner!r})"
    )
    console.say(f"wrote {args.output}")
    return 0


def cmd_check(args, console) -> int:
    from ..gcode import compensated_path, nose_compensate

    program, tools = _load(args)
    console.say(repr(program))
    d = program.dialect
    console.say(f"dialect: {d.name} ({d.reason})")
    repeated = [k + 1 for k, n in enumerate(program.runs) if n > 1 and program.lines[k].words]
    if repeated or program.computed:
        console.say(
            f"  {sum(program.runs)} blocks ran; lines that ran more than once: "
            f"{_line_list(repeated)}; lines computed from parameters: "
            f"{_line_list(sorted(program.computed))}"
        )
    for note in program.notes:
        console.say(f"  line {note.line}: {note.word}: {note.text}")
    runs = [ev for ev in program.events if not hasattr(ev, "kind")]
    for ev in runs:
        if ev.setting is None:
            console.say(f"  line {ev.line}: G40 compensation off")
        else:
            s = ev.setting
            what = (
                f"D {s.diameter_mm:g} mm, orientation {s.orientation}"
                if s.diameter_mm is not None
                else f"tool {s.tool}"
            )
            console.say(f"  line {ev.line}: {s.code} nose on the {s.side} of travel, {what}")
    for m in program.moves:
        st = program.state(m.line)
        x, z = m.end
        centre = "" if m.center is None else f" centre (x={m.center[0]:.4f}, z={m.center[1]:.4f})"
        comp = f" [{m.comp.code}{' entry' if m.entry else ''}]" if m.comp else ""
        console.say(
            f"  {m.line:5d} {m.kind:5s} to (x={x:.4f}, z={z:.4f}) mm radius{centre}{comp}"
            f"  ({st.units}, {'diameter' if st.diameter else 'radius'} mode)"
        )
    _say_sides(program, console)
    if any(m.comp is not None for m in program.moves):
        path = compensated_path(program, tool_table=tools, nose_radius=args.nose_radius)
        console.say(f"compensated path: {len(path)} moves of the controlled point")
    if args.rs274:
        return _compare_rs274(args, program, tools, console, nose_compensate)
    return 0


def _say_sides(program, console) -> None:
    """The material side of each compensation run, as the moves in air say it; a
    warning for a run that `nose-comp --kind auto` refuses."""
    import warnings

    from ..gcode import MaterialSideWarning, comp_sides, side_error

    for run in comp_sides(program):
        console.say(f"  material side: {run.summary(program)}")
        err = side_error(run, program)
        if err is not None:
            warnings.warn(
                f"gcode nose-comp --kind auto refuses this run: {err}",
                MaterialSideWarning,
                stacklevel=1,
            )


def _line_list(lines, most: int = 12) -> str:
    if not lines:
        return "none"
    text = ", ".join(map(str, lines[:most]))
    return text + (f" and {len(lines) - most} more" if len(lines) > most else "")


def _compare_rs274(args, program, tools, console, nose_compensate) -> int:
    from ..errors import InputError
    from ..gcode import compensated_path, rs274_path, run_rs274

    if rs274_path() is None:
        raise InputError("rs274 is not installed (Debian package linuxcnc-uspace)")
    if program.dialect.name != "linuxcnc":
        raise InputError(
            f"--rs274 compares with LinuxCNC's interpreter: this program is read as "
            f"{program.dialect.name}",
            file=program.name,
        )
    if args.tool_table is None and any(
        m.comp is not None and m.comp.diameter_mm is None for m in program.moves
    ):
        raise InputError("--rs274 with G41/G42 needs --tool-table (in inches for rs274)")
    ref = run_rs274(args.program, tool_table=args.tool_table)
    if ref.error:
        console.say(f"rs274 stops: {ref.error}")
        return 1
    if not any(m.comp is not None for m in program.moves):
        return _agree(console, "the reader's own moves", ref.moves, program.moves, 1e-4)
    skip = _g70_entry_moves(program)
    try:  # the geometry is compared, as rs274 sees it: no view of where the material is
        resolved = nose_compensate(
            program, tool_table=tools, nose_radius=args.nose_radius, kind=None
        )
    except InputError as exc:
        if "cannot be rewritten in place" not in str(exc):
            raise
        # compensated lines that run several times (a loop): our path itself is compared
        path = compensated_path(program, tool_table=tools, nose_radius=args.nose_radius)
        console.say(f"  ({exc.reason}: the compensated path is compared, not a program)")
        return _agree(console, "the compensated path", ref.moves, path, 1e-4, skip)
    out = run_rs274(resolved.text, tool_table=args.tool_table)
    if out.error:
        console.say(f"rs274 disagrees: {out.error}")
        return 1
    if skip:
        console.say(
            f"  {len(skip)} moves not compared: the first two of each G70 under G41/G42, "
            "which LinuxCNC makes uncompensated since July 2024 (as read here) and older "
            "rs274 builds compensate"
        )
    return _agree(console, "the resolved program's moves", ref.moves, out.moves, None, skip)


def _g70_entry_moves(program) -> set[int]:
    """Indices of the first two moves of every G70 made under compensation."""
    out: set[int] = set()
    moves = program.moves
    for k, m in enumerate(moves):
        if m.via == "G70" and (k == 0 or moves[k - 1].line != m.line):
            if any(n.comp is not None for n in moves[k:] if n.line == m.line):
                out |= {k, k + 1}
    return out


def _agree(console, what, ref, ours, tol, skip=frozenset()) -> int:
    """``ours`` against rs274's canonical moves ``ref``: same count, kinds and points
    (the moves of index in ``skip`` by kind only)."""
    if len(ours) != len(ref):
        console.say(f"rs274 disagrees: {len(ref)} canonical moves, {what} {len(ours)}")
        return 1
    dev = 0.0
    for k, (a, b) in enumerate(zip(ref, ours, strict=True)):
        if k in skip:
            continue
        if (a.kind == "arc") != (b.kind in ("arc", "cw", "ccw")):
            console.say(f"rs274 disagrees: an arc where {what} has a straight move or back")
            return 1
        dev = max(dev, *(abs(u - v) for u, v in zip(a.end, b.end, strict=True)))
        y = getattr(b, "y", None)  # ours: (start, end) off the XZ plane, else None
        dev = max(dev, abs(a.y - (y if isinstance(y, float) else y[1] if y else 0.0)))
        if a.center is not None and b.center is not None:
            dev = max(dev, math.dist(a.center, b.center))
    # rs274 prints 4 decimals in the program's units: 1e-4 in is 2.54e-3 mm
    if tol is not None and dev > tol * 25.4:
        console.say(f"rs274 disagrees: {what} are {dev:.2e} mm off its canonical moves")
        return 1
    console.say(
        f"rs274 agrees: {len(ref)} canonical moves, largest difference {dev:.2e} mm ({what})"
    )
    return 0

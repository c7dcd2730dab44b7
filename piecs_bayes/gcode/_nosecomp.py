"""Tool-nose (cutter) radius compensation for lathe programs: G41/G42/G40 resolved.

The programmed contour is the part's edge; the nose centre runs one nose radius away
from it, left (G41) or right (G42) of travel in the drawing frame, and the machine
positions the controlled point, the imaginary tip (`tip_offset` by LinuxCNC's lathe
orientations). [`compensated_path`][] gives the controlled point's moves
([`PathMove`][], mm, radius X) of a [`GcodeProgram`][], with `corner="arc"` (default:
what LinuxCNC does, `_nosecomp_arc`) or `corner="extend"` (the 1969 bisector rule,
`_nosecomp_extend`); a gouge or a LinuxCNC quirk the rule cannot follow raises
`AnalysisError` naming the block. [`nose_compensate`][] rewrites the program without
compensation (lines outside it byte-identical) and refuses G41/G42 on the material side
(`infer_kind`, `check_comp_sides`); [`correct_radius_error`][] corrects an already
compensated path for a nose radius that differs from plan.

The corner rules, tip offsets and gouges: docs/models/nose_compensation.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass

from ..errors import AnalysisError, InputError
from ._nosecomp_arc import ArcCornerComp
from ._nosecomp_base import UniformNose, _left, tip_offset
from ._nosecomp_extend import _extend, _offset_chain, _Seg


@dataclass(frozen=True)
class PathMove:
    """A move of the controlled point: ``kind`` in ``rapid | feed | cw | ccw``;
    ``(x, z)`` points in mm (x a radius); ``line`` is the source block."""

    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    line: int
    center: tuple[float, float] | None = None

    @property
    def is_arc(self) -> bool:
        return self.kind in ("cw", "ccw")


def _as_path(raw, start) -> tuple[PathMove, ...]:
    moves, pos = [], start
    for kind, end, line, center in raw:
        moves.append(PathMove(kind, pos, end, line, center))
        pos = end
    return tuple(moves)


def axial_air(kind: str):
    """The air side of a turned contour by its kind, for `check_comp_sides`: above an
    external (OD) contour, below an internal (bore) one, judged on moves that run
    mostly along Z (a face's air side depends on the step it belongs to)."""
    if kind not in ("external", "internal"):
        raise InputError(f"kind: got {kind!r}, expected 'external' or 'internal'", value=kind)
    up = (1.0, 0.0) if kind == "external" else (-1.0, 0.0)

    def air(m):
        dx, dz = m.end[0] - m.start[0], m.end[1] - m.start[1]
        return up if abs(dz) > 2.0 * abs(dx) else None

    return air


def _axial_move(m) -> bool:
    return not m.is_arc and abs(m.end[1] - m.start[1]) > 2.0 * abs(m.end[0] - m.start[0])


def _beside(p, run) -> str | None:
    """Where an air point `p` lies against the run's contour at its own Z: "external"
    above it, "internal" below, None outside the contour's Z span (in front of or
    behind the part, where the air surrounds both an OD and a bore) or within it."""
    z_lo = min(min(n.start[1], n.end[1]) for n in run)
    z_hi = max(max(n.start[1], n.end[1]) for n in run)
    eps = 1e-6 * max(1.0, abs(z_lo), abs(z_hi))
    if not z_lo + eps < p[1] < z_hi - eps:
        return None
    xs = []
    for n in run:  # the contour's X at p's Z (chords of arcs)
        (x0, z0), (x1, z1) = n.start, n.end
        if min(z0, z1) - eps <= p[1] <= max(z0, z1) + eps:
            xs += [x0, x1] if abs(z1 - z0) <= eps else [x0 + (x1 - x0) * (p[1] - z0) / (z1 - z0)]
    if xs and p[0] > max(xs) + eps:
        return "external"
    if xs and p[0] < min(xs) - eps:
        return "internal"
    return None


def _nose_side(run) -> str | None:
    """The kind the run's G41/G42 side says: the nose is in the air, above an OD contour
    and below a bore; each axial move votes by its length (None on a tie)."""
    length = {"external": 0.0, "internal": 0.0}
    for n in run:
        if not _axial_move(n):
            continue
        side = n.comp.side
        if n.comp.diameter_mm is not None and n.comp.diameter_mm < 0:
            side = "left" if side == "right" else "right"
        dz = n.end[1] - n.start[1]
        nose_up = (dz > 0) == (side == "left")  # left of +Z travel is +X (z right, x up)
        length["external" if nose_up else "internal"] += abs(dz)
    if length["external"] == length["internal"]:
        return None
    return max(length, key=length.get)


def infer_kind(program) -> str | None:
    """``"external"``/``"internal"`` for a program's compensation runs, or None.

    The tool is in the air, the material beyond the contour. First, where the tool
    comes from and goes to: the start of a run's entry move and the end of its
    departure move, where such a point lies beside the contour (within its Z span)
    above it (an OD) or below it (a bore). A point in front of the part or behind it
    says nothing: air surrounds both there, so a bore entered from above the face and
    left behind the part reads like an OD. A run with no such point is read from its
    G41/G42 side and the travel direction of its axial moves (nose above the contour
    on the air side of an OD, below it in a bore; the majority of their length), so
    that `check_comp_sides` still refuses a move whose side contradicts the rest. None
    unless every run agrees.
    """
    moves = list(program.moves)
    votes = set()
    for i, m in enumerate(moves):
        if not (m.entry and m.comp is not None):
            continue
        run = []
        for n in moves[i + 1 :]:
            if n.comp is None:
                break
            run.append(n)
        if not any(_axial_move(n) for n in run):
            continue
        j = i + 1 + len(run)
        points = [m.start] + ([moves[j].end] if j < len(moves) else [])
        seen = {k for k in (_beside(p, run) for p in points) if k is not None}
        if not seen:
            seen = {k for k in (_nose_side(run),) if k is not None}
        votes |= seen
    return votes.pop() if len(votes) == 1 else None


def check_comp_sides(program, air) -> None:
    """Refuse G41/G42 on the side that cuts into the material.

    G41 puts the nose left of travel, G42 right (drawing frame: z right, x up; a
    negative G41.1/G42.1 diameter swaps them). `air(move)` gives the unit direction
    of the air side of a programmed straight move (e.g. the outward normal of the
    profile feature it cuts, or `axial_air(kind)`), or None where it cannot say.
    A compensated move whose nose side points into the material is an `InputError`
    naming its line. (LinuxCNC's rs274 runs such a program: it judges gouges, not
    sides.)
    """
    for m in program.moves:
        if m.comp is None or m.entry or m.is_arc or m.start == m.end:
            continue
        n_air = air(m)
        if n_air is None:
            continue
        side = m.comp.side
        if m.comp.diameter_mm is not None and m.comp.diameter_mm < 0:
            side = "left" if side == "right" else "right"
        left = _left((m.end[0] - m.start[0], m.end[1] - m.start[1]))
        nose = left if side == "left" else (-left[0], -left[1])
        if nose[0] * n_air[0] + nose[1] * n_air[1] < -0.5:
            other = "G42" if side == "left" else "G41"
            raise InputError(
                f"{m.comp.code} (line {m.comp.line}) puts the tool nose {side} of travel, on "
                f"the material side of the contour at line {m.line}: it would cut into the "
                f"part; use {other}",
                file=getattr(program, "name", None),
                line=m.line,
                value=m.comp.code,
            )


def compensated_path(
    program,
    *,
    corner: str = "arc",
    tool_table: Mapping | None = None,
    nose_radius: float | None = None,
    start: tuple[float, float] | None = None,
) -> tuple[PathMove, ...]:
    """The controlled point's path for a program with G41/G42/G40 (mm, radius X).

    **Arguments:**

    - `program`: a :class:`~piecs_bayes.gcode.GcodeProgram`.
    - `corner`: ``"arc"`` (LinuxCNC's corners) or ``"extend"`` (1969 bisector rule).
    - `tool_table`: ``{tool: ToolEntry}`` for G41/G42 (see
      :func:`~piecs_bayes.gcode.read_tool_table`).
    - `nose_radius`: instead of a tool table, the nose radius (mm) of every
      G41/G42 tool, orientation 0 (G41.1/G42.1 keep their own D and L).
    - `start`: the tool position before the first move (default: the one the
      program was read with).

    **Returns:** one :class:`PathMove` per motion of the controlled point, each
    with the line of the block that produced it. Raises
    :class:`~piecs_bayes.errors.AnalysisError` (with ``.line``) on a gouge.
    """
    if nose_radius is not None:
        if isinstance(nose_radius, bool) or not (
            isinstance(nose_radius, int | float) and math.isfinite(nose_radius) and nose_radius > 0
        ):
            raise InputError(
                f"nose radius must be a finite number > 0 (mm), got {nose_radius!r}",
                value=nose_radius,
            )
        tool_table = UniformNose(float(nose_radius))
    if start is None:
        start = tuple(program.options.get("start", (0.0, 0.0)))
    comp = ArcCornerComp(program, tool_table, start)
    if corner == "arc":
        raw = comp.run()
    elif corner == "extend":
        raw = _extend(program, tool_table, comp.gouge)
    else:
        raise InputError(f"unknown corner rule {corner!r}; expected 'arc' or 'extend'")
    path = _as_path(raw, start)
    programmed = {m.line: m for m in program.moves}
    for m in path:
        if m.is_arc and math.dist(m.start, m.end) < 1e-7:
            src = programmed.get(m.line)
            if src is None or math.dist(src.start, src.end) >= 1e-7:
                raise comp.gouge(
                    m.line, "compensation would turn this arc into a full circle (gouge)"
                )
    return path


@dataclass(frozen=True)
class NoseCompResult:
    """A program with compensation resolved: ``text`` has no G41/G42/G40 words."""

    text: str
    path: tuple[PathMove, ...]
    corner: str
    changed_lines: tuple[int, ...]

    def __repr__(self) -> str:
        return (
            f"NoseCompResult(corner={self.corner!r}, {len(self.path)} moves, "
            f"{len(self.changed_lines)} source lines rewritten)"
        )


def nose_compensate(
    program,
    *,
    corner: str = "arc",
    tool_table: Mapping | None = None,
    nose_radius: float | None = None,
    start: tuple[float, float] | None = None,
    kind: str | None = "auto",
) -> NoseCompResult:
    """Resolve nose-radius compensation into an equivalent program without it.

    Lines outside compensation stay byte-identical; compensated blocks are
    rewritten (their other words and comments kept) with the controlled
    point's moves, extra corner arcs on lines of their own. Arguments as for
    :func:`compensated_path`; `kind` (``"external"``, ``"internal"``, ``"auto"``:
    `infer_kind`, or None: not checked) says where the material is, and a G41/G42
    on the material side is refused (`check_comp_sides`).
    """
    from ._writer import write_path_program

    if kind == "auto":
        kind = infer_kind(program)
    if kind is not None:
        check_comp_sides(program, axial_air(kind))
    path = compensated_path(
        program, corner=corner, tool_table=tool_table, nose_radius=nose_radius, start=start
    )
    text, changed = write_path_program(program, path)
    return NoseCompResult(text, path, corner, changed)


def correct_radius_error(
    path: Sequence,
    *,
    planned: float,
    actual: float,
    side: str,
    orientation: int = 0,
    compensated: Callable[[object], bool] | Collection[int] | None = None,
) -> tuple[PathMove, ...]:
    """Correct an already compensated path for a nose radius that differs from plan.

    Every compensated move is offset by ``dr = actual - planned`` to the
    compensation ``side`` (``"left"``/``"right"`` of travel; a negative ``dr``
    offsets the other way): lines move parallel, arcs change radius by ``dr``
    (convex corner arcs of radius ``planned`` become ``actual``), and the
    junctions follow the 1969 rule (bisector ``dr / cos(alpha / 2)`` between
    compensated moves, ``dr`` normal where an uncompensated move meets one,
    zero at the far end of an uncompensated move). The imaginary tip moves with
    the radius too: ``tip_offset(orientation, dr)`` is added to compensated
    points.

    **Arguments:**

    - `path`: moves with ``kind, start, end, line, center`` (``PathMove`` or
      ``Motion``), mm, radius X.
    - `planned`, `actual`: nose radii (mm).
    - `side`: ``"left"`` or ``"right"`` (G41 / G42).
    - `orientation`: the tool orientation 0-9.
    - `compensated`: which moves were compensated: a predicate on a move or
      the source line numbers (default: every feed move and arc, no rapid).

    **Returns:** the corrected moves. Raises AnalysisError on a gouge.
    """
    if side not in ("left", "right"):
        raise InputError(f"side must be 'left' or 'right', got {side!r}")
    if planned < 0 or actual < 0:
        raise InputError(f"radii must be >= 0, got planned={planned} actual={actual}")
    dr = actual - planned
    if compensated is None:
        is_comp = lambda m: m.kind != "rapid"  # noqa: E731
    elif callable(compensated):
        is_comp = compensated
    else:
        lines = {int(n) for n in compensated}
        is_comp = lambda m: m.line in lines  # noqa: E731
    segs = [
        _Seg(m.kind, tuple(m.start), tuple(m.end), m.line, m.center, bool(is_comp(m)))
        for m in path
        if tuple(m.start) != tuple(m.end)
    ]
    if not segs:
        return ()

    def err(line, msg):
        e = AnalysisError(f"line {line}: {msg}")
        e.line = line
        return e

    s = 1.0 if side == "left" else -1.0
    raw = _offset_chain(segs, s, dr, tip_offset(orientation, dr), err)
    return _as_path(raw, segs[0].start)

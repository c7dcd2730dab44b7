"""A read part program: its moves, modal states, events and what was recorded.

[`GcodeProgram`][] is what :func:`~piecs_bayes.gcode.read_gcode` returns: the lossless
text, every move as a [`Motion`][] (mm, radius X, ``(x, z)``, with its source line),
the nose-compensation events ([`CompEvent`][], [`CompSetting`][]), the modal state of
each line ([`LineState`][], with the cutting tool's [`ToolWord`][]), the [`Note`][] s of
what was recorded and not applied, the dialect, and which lines ran several times or
computed their words (so that an edit in place can be refused with the reason).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InputError
from ._dialect import Dialect
from ._lexer import GcodeText, SourceLine


@dataclass(frozen=True)
class CompSetting:
    """A G41/G42/G41.1/G42.1 request, as programmed.

    ``side`` is ``"left"`` or ``"right"`` of travel in the drawing frame.
    G41/G42 take the radius and orientation from the tool table: ``tool`` is
    the D word or else the tool in the spindle (None when none was loaded).
    G41.1/G42.1 carry them: ``diameter_mm`` (the D word) and ``orientation``
    (the L word, 0 when absent).
    """

    side: str
    code: str
    line: int
    tool: int | None = None
    diameter_mm: float | None = None
    orientation: int | None = None


@dataclass(frozen=True)
class ToolWord:
    """The T word that put the cutting tool in place, as written.

    ``text`` is the word (``"T0202"``), ``value`` its number, ``line`` its line.
    ``by`` says what made it the cutting tool: ``"M6"`` (a tool change, LinuxCNC
    style: the T word only selects) or ``"T"`` (a program without any M6, turret
    style: the T word itself indexes the turret and applies its offsets, as on
    Fanuc-style lathes). What the number means is read by
    :func:`~piecs_bayes.gcode.tool_call`.
    """

    text: str
    value: int
    line: int
    by: str


@dataclass(frozen=True)
class CompEvent:
    """Compensation switched on (``setting``) or off (``setting is None``: G40) at ``line``."""

    line: int
    setting: CompSetting | None


@dataclass(frozen=True)
class Motion:
    """One programmed move: ``kind`` in ``"rapid" | "feed" | "cw" | "ccw"``.

    Points are ``(x, z)`` in mm with x a radius; ``center`` is set for arcs
    (as programmed: for I/K arcs the end may sit up to LinuxCNC's tolerance
    off the circle). ``comp`` is the compensation in force, ``entry`` marks
    the first move after it was switched on.
    """

    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    line: int
    center: tuple[float, float] | None = None
    comp: CompSetting | None = None
    entry: bool = False
    via: str = ""
    """What made the move besides a motion word: ``"G28"`` / ``"G30"`` (reference return:
    the intermediate point and the reference), ``"G53"`` (machine coordinates), ``",C"``
    / ``",R"`` (a chamfer or corner the control inserts), ``"G81"`` .. ``"G89"`` / ``"G73"``
    (a LinuxCNC drilling cycle), ``"G38.2"`` .. ``"G38.5"`` (a probing move)."""
    y: tuple[float, float] | None = None
    """Start and end Y in mm where the move is off the XZ plane (LinuxCNC's Y axis: a
    drilling or probing macro); None on the plane. Such a move is never a contour's."""

    @property
    def is_arc(self) -> bool:
        return self.kind in ("cw", "ccw")

    @property
    def ccw(self) -> bool:
        return self.kind == "ccw"

    @property
    def length(self) -> float:
        return math.dist(self.start, self.end)

    def exact_center(self) -> tuple[float, float]:
        """The centre moved onto the chord's perpendicular bisector (nearest point), so
        that start and end are exactly equidistant from it."""
        (x0, z0), (x1, z1), (cx, cz) = self.start, self.end, self.center
        mx, mz = (x0 + x1) / 2, (z0 + z1) / 2
        dx, dz = x1 - x0, z1 - z0
        d2 = dx * dx + dz * dz
        if d2 == 0.0:
            return self.center
        t = ((cx - mx) * dx + (cz - mz) * dz) / d2
        return (cx - t * dx, cz - t * dz)

    def to_feature(self, id: str, *, side: int = -1, tolerance=(-0.01, 0.01)):
        """This move as a :class:`~piecs_bayes.geometry.Line` or
        :class:`~piecs_bayes.geometry.Arc` (G3 -> ``ccw=True``)."""
        from ..geometry import Arc, Line

        if self.is_arc:
            return Arc(id, self.start, self.end, self.exact_center(), self.ccw, side, tolerance)
        if self.length == 0.0:
            raise InputError("a zero-length move is not a feature", line=self.line, feature=id)
        return Line(id, self.start, self.end, side, tolerance)


@dataclass(frozen=True)
class LineState:
    """Modal state in force for the motion of a line (after its own G codes)."""

    units: str
    diameter: bool
    absolute: bool
    arc_absolute: bool
    motion: str | None
    comp: CompSetting | None
    tool: ToolWord | None = None
    """The T word of the cutting tool (None before any)."""
    feed_per_rev: bool = False
    """Feed per revolution (G95, Fanuc G99) rather than per minute."""


@dataclass(frozen=True)
class Note:
    """Something the reader recorded rather than applied to the moves: ``word`` (``"G10"``,
    ``"M8"``, ``"G50 S3500"``, ``"/"``) at ``line`` and what was done with it."""

    line: int
    word: str
    text: str


@dataclass(frozen=True)
class CycleContour:
    """The contour of a canned cycle (G70-G73) as the reader ran it.

    ``code`` and ``line`` are the cycle block's; ``contour`` the contour's blocks as
    :class:`Motion`s in program order, read from the cycle's start point with the
    compensation the control applies to them (Fanuc: the G41/G42 of its ``P``..``Q``
    blocks; LinuxCNC: the G41/G42 in force at the cycle), each with its own source line
    (LinuxCNC's ``A``/``C`` corners are arcs and lines of the block that carries them);
    ``events`` the compensation switched within it; ``finish`` says that this is a
    finish pass (G70) or a roughing cycle whose contour no G70 cuts, so that it is the
    part's profile; ``move_index`` is where the cycle's moves begin in
    ``GcodeProgram.moves``; ``blocks`` its contour's lines (Fanuc ``P``..``Q``, LinuxCNC
    the O-sub's lines)."""

    code: str
    line: int
    contour: tuple[Motion, ...]
    events: tuple[CompEvent, ...] = ()
    finish: bool = False
    move_index: int = 0
    blocks: tuple[int, ...] = ()


@dataclass(frozen=True)
class GcodeProgram:
    """A read program: its lossless text, its moves, events and per-line modal states.

    A line that ran several times (a loop, a subroutine called twice) gives several
    moves with the same ``line``; ``runs`` counts how often each line ran and
    ``computed`` holds the lines whose words came from parameters or expressions:
    :meth:`edit_refusal` says why such a line cannot be edited in place.
    """

    source: GcodeText
    moves: tuple[Motion, ...]
    events: tuple[Motion | CompEvent, ...]
    states: tuple[LineState, ...]
    options: object = None
    """The :class:`~piecs_bayes.gcode.ReadOptions` it was read with (dialect and its
    defaults filled in), to read an edit alike."""
    dialect: Dialect | None = None
    notes: tuple[Note, ...] = ()
    runs: tuple[int, ...] = ()
    computed: frozenset[int] = frozenset()
    cycles: tuple[CycleContour, ...] = ()
    """The canned cycles' contours (G70-G73), in the order they ran."""

    @property
    def name(self) -> str | None:
        return self.source.name

    @property
    def text(self) -> str:
        return self.source.text

    @property
    def lines(self) -> tuple[SourceLine, ...]:
        return self.source.lines

    def state(self, line: int) -> LineState:
        return self.states[line - 1]

    def moves_at(self, line: int) -> tuple[Motion, ...]:
        return tuple(m for m in self.moves if m.line == line)

    def runs_of(self, line: int) -> int:
        """How many times ``line`` ran (0: never, e.g. a branch not taken)."""
        return self.runs[line - 1] if self.runs else 1

    def edit_refusal(self, line: int) -> str | None:
        """Why ``line`` cannot be edited where it stands, or None when it can."""
        n = self.runs_of(line)
        if n > 1:
            return (
                f"line {line} ran {n} times (a loop or a subroutine called more than once): "
                "editing it would change every pass"
            )
        if line in self.computed:
            return f"line {line} computes its words from parameters or expressions"
        if n == 0:
            return f"line {line} never ran"
        return None

    def __repr__(self) -> str:
        comp = sum(1 for m in self.moves if m.comp is not None)
        dialect = f", {self.dialect.name}" if self.dialect is not None else ""
        return (
            f"GcodeProgram({self.name or '<text>'}{dialect}: {len(self.lines)} lines, "
            f"{len(self.moves)} moves, {comp} compensated)"
        )

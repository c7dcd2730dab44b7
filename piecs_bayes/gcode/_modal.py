"""Modal interpretation of a lathe part program: words -> moves in the XZ half-plane.

[`read_gcode`][] (a file, bytes kept exactly) and [`parse_gcode`][] (a text) keep the
full modal state the way LinuxCNC's interpreter does and return a [`GcodeProgram`][]
whose every motion block is a [`Motion`][] in **millimetres, radius X** (``(x, z)``
points), with its source line, the nose-compensation settings and the tool words in
force. Anything not understood (threads, other planes, Y/J words, an unknown code) is
an :class:`~piecs_bayes.errors.InputError` with the file, line number and text: nothing
is dropped silently. Modal defaults are LinuxCNC's (G8 radius mode, G90, G91.1,
no motion mode until G0-G3) with G18 assumed; `units`, `diameter_mode` and `start`
set the state before the program says otherwise. G2 is clockwise and G3
counter-clockwise in the drawing frame (z right, x up), as LinuxCNC's ``ARC_FEED``
shows.

The words understood: docs/models/part_programs.md, "The modal interpreter".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ._lexer import GcodeText, SourceLine, lex_gcode, read_text_lossless

MM_PER_INCH = 25.4
_G_GROUPS = {
    "motion": {"G0", "G1", "G2", "G3", "G80"},
    "plane": {"G18"},
    "units": {"G20", "G21"},
    "diameter": {"G7", "G8"},
    "comp": {"G40", "G41", "G42", "G41.1", "G42.1"},
    "length": {"G43", "G49"},
    "coord": {"G54", "G55", "G56", "G57", "G58", "G59"},
    "path": {"G61", "G61.1", "G64"},
    "distance": {"G90", "G91"},
    "arc_distance": {"G90.1", "G91.1"},
    "feed_mode": {"G94", "G95"},
    "spindle_mode": {"G96", "G97"},
    "dwell": {"G4"},
}
_G_GROUP_OF = {code: group for group, codes in _G_GROUPS.items() for code in codes}
_M_GROUPS = {
    "stop": {"M0", "M1", "M2", "M30"},
    "toolchange": {"M6"},
    "spindle": {"M3", "M4", "M5"},
    "coolant": {"M7", "M8", "M9"},
}
_M_GROUP_OF = {code: group for group, codes in _M_GROUPS.items() for code in codes}
_LETTERS = set("GMNOXZIKRFSTDLPQH")
_REFUSED = {
    "G17": "only the XZ plane (G18) is supported for a lathe",
    "G19": "only the XZ plane (G18) is supported for a lathe",
    "G93": "inverse-time feed (G93) is not supported",
}
_THREAD = (
    "threading is not understood: a thread is a helix synchronised with the spindle, "
    "not a contour of lines and arcs"
)
_REFUSED.update({code: _THREAD for code in ("G32", "G33", "G33.1", "G76")})
# Arc tolerances (mm): how far an R arc may fall short of its chord, and how much an
# I/K arc's start and end radii may differ; chosen to accept what rs274 accepts
# on the test corpus (0.00005 in; 0.01 mm or 0.001 in times sqrt(2), twice).
_RADIUS_TOL_MM = 0.00005 * MM_PER_INCH
_SPIRAL_ABS_MM = {"mm": 2 * 0.01 * math.sqrt(2), "in": 2 * 0.001 * math.sqrt(2) * MM_PER_INCH}
_SPIRAL_REL = 0.001


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


@dataclass(frozen=True)
class GcodeProgram:
    """A read program: its lossless text, its moves, events and per-line modal states."""

    source: GcodeText
    moves: tuple[Motion, ...]
    events: tuple[Motion | CompEvent, ...]
    states: tuple[LineState, ...]
    options: dict = field(default_factory=dict, compare=False)
    """The reading options (``units``, ``diameter_mode``, ``start``), to read an edit alike."""

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

    def __repr__(self) -> str:
        comp = sum(1 for m in self.moves if m.comp is not None)
        return (
            f"GcodeProgram({self.name or '<text>'}: {len(self.lines)} lines, "
            f"{len(self.moves)} moves, {comp} compensated)"
        )


class _Reader:
    def __init__(self, src: GcodeText, units: str, diameter: bool, start):
        self.src = src
        self.units0, self.diameter0, self.start0 = units, diameter, tuple(start)
        self.units = units
        self.diameter = diameter
        self.absolute = True
        self.arc_absolute = False
        self.motion: str | None = None
        self.pos = (float(start[0]), float(start[1]))
        self.comp: CompSetting | None = None
        self.first_after_on = False
        self.just_off = False
        self.selected: int | None = None
        self.tool: int | None = None
        self.t_selected: ToolWord | None = None
        self.t_cutting: ToolWord | None = None
        # a program without M6 changes tools with the T word alone (turret lathes)
        self.turret = not any(
            w.letter == "M" and w.code == "M6" for ln in src.lines for w in ln.words
        )
        self.moves: list[Motion] = []
        self.events: list[Motion | CompEvent] = []
        self.states: list[LineState] = []

    def err(self, line: SourceLine, msg: str) -> InputError:
        return InputError(
            f"{msg}: {line.text.strip()!r}", file=self.src.name or "<program>", line=line.number
        )

    def length(self, value: float) -> float:
        return value * (MM_PER_INCH if self.units == "in" else 1.0)

    def run(self) -> GcodeProgram:
        for line in self.src.lines:
            self.block(line)
            self.states.append(
                LineState(
                    self.units,
                    self.diameter,
                    self.absolute,
                    self.arc_absolute,
                    self.motion,
                    self.comp,
                    self.t_cutting,
                )
            )
        options = {"units": self.units0, "diameter_mode": self.diameter0, "start": self.start0}
        return GcodeProgram(
            self.src, tuple(self.moves), tuple(self.events), tuple(self.states), options
        )

    def block(self, line: SourceLine) -> None:
        if line.percent or not line.words:
            return
        seen: dict[str, object] = {}
        gcodes: dict[str, str] = {}
        mcodes: dict[str, str] = {}
        for w in line.words:  # refused codes first: a thread cycle's J word says less
            if w.letter == "G" and w.code in _REFUSED:
                raise self.err(line, f"{w.code}: {_REFUSED[w.code]}")
        for k, w in enumerate(line.words):
            if w.letter not in _LETTERS:
                hint = " (a lathe program lives in the XZ plane)" if w.letter in "YJ" else ""
                raise self.err(line, f"word {w} is not understood{hint}")
            if w.letter == "G":
                code = w.code
                group = _G_GROUP_OF.get(code)
                if group is None:
                    raise self.err(line, f"{code} is not understood")
                if group in gcodes:
                    raise self.err(
                        line, f"{gcodes[group]} and {code} in one block (same modal group)"
                    )
                gcodes[group] = code
            elif w.letter == "M":
                code = w.code
                group = _M_GROUP_OF.get(code)
                if group is None:
                    raise self.err(line, f"{code} is not understood")
                if group in mcodes:
                    raise self.err(
                        line, f"{mcodes[group]} and {code} in one block (same modal group)"
                    )
                mcodes[group] = code
            else:
                if w.letter in seen:
                    raise self.err(line, f"word {w.letter} appears twice")
                if w.letter == "O" and k != 0:
                    raise self.err(line, "an O number must be the first word of its line")
                seen[w.letter] = w.value
        self.execute(line, gcodes, mcodes, seen)

    def execute(self, line, gcodes, mcodes, w) -> None:
        if "T" in w:
            if w["T"] < 0 or w["T"] != int(w["T"]):
                raise self.err(line, "T must be a whole number >= 0")
            self.selected = int(w["T"])
            by = "T" if self.turret else "M6"
            self.t_selected = ToolWord(f"T{line.word('T').text}", self.selected, line.number, by)
            if self.turret:
                self.t_cutting = self.t_selected
        if "toolchange" in mcodes:
            if self.comp is not None:
                raise self.err(line, "cannot change tools with compensation on (G40 first)")
            if self.selected is None:
                raise self.err(line, "M6 with no tool selected (T word)")
            self.tool = self.selected
            self.t_cutting = self.t_selected
        if "dwell" in gcodes and "P" not in w:
            raise self.err(line, "G4 needs a P word (seconds)")
        if "P" in w and "dwell" not in gcodes and gcodes.get("path") != "G64":
            raise self.err(line, "a P word is only understood with G4 or G64")
        if "Q" in w and gcodes.get("path") != "G64":
            raise self.err(line, "a Q word is only understood with G64")
        if "H" in w and gcodes.get("length") != "G43":
            raise self.err(line, "an H word is only understood with G43")
        units = gcodes.get("units")
        if units:
            self.units = "in" if units == "G20" else "mm"
        dia = gcodes.get("diameter")
        if dia:
            self.diameter = dia == "G7"
        comp = gcodes.get("comp")
        if "D" in w and comp not in ("G41", "G42", "G41.1", "G42.1"):
            raise self.err(line, "a D word is only understood with G41/G42/G41.1/G42.1")
        if "L" in w and comp not in ("G41.1", "G42.1"):
            raise self.err(line, "an L word is only understood with G41.1/G42.1")
        if comp == "G40":
            self.just_off = self.comp is not None
            self.comp = None
            self.events.append(CompEvent(line.number, None))
        elif comp:
            self.comp_on(line, comp, w)
        if gcodes.get("distance"):
            self.absolute = gcodes["distance"] == "G90"
        if gcodes.get("arc_distance"):
            self.arc_absolute = gcodes["arc_distance"] == "G90.1"
        if gcodes.get("motion"):
            self.motion = None if gcodes["motion"] == "G80" else gcodes["motion"]
        has_axis = "X" in w or "Z" in w
        arc_words = [k for k in ("I", "K", "R") if k in w]
        if has_axis:
            if self.motion is None:
                raise self.err(line, "axis words with no motion mode (G0/G1/G2/G3) in force")
            self.move(line, w)
        elif arc_words:
            raise self.err(line, f"{'/'.join(arc_words)} without an arc end point (X/Z)")
        if arc_words and self.motion not in ("G2", "G3"):
            raise self.err(line, f"{'/'.join(arc_words)} words are only understood with G2/G3")

    def comp_on(self, line, code, w) -> None:
        if self.comp is not None:
            raise self.err(line, f"{code} while compensation is already on (G40 first)")
        side = "left" if code.startswith("G41") else "right"
        if code.endswith(".1"):
            if "D" not in w:
                raise self.err(line, f"{code} needs a D word (tool diameter)")
            orient = int(w["L"]) if "L" in w else 0
            if "L" in w and (w["L"] != orient or not 0 <= orient <= 9):
                raise self.err(line, f"L must be a tool orientation 0-9, got {w['L']:g}")
            setting = CompSetting(side, code, line.number, None, self.length(w["D"]), orient)
        else:
            tool = self.tool
            if "D" in w:
                if w["D"] < 0 or abs(w["D"] - round(w["D"])) >= 1e-4:
                    raise self.err(line, f"{code} needs D to be a tool number (whole, >= 0)")
                tool = int(round(w["D"]))
            setting = CompSetting(side, code, line.number, tool)
        self.comp = setting
        self.first_after_on = True
        self.events.append(CompEvent(line.number, setting))

    def move(self, line, w) -> None:
        x0, z0 = self.pos
        x, z = x0, z0
        if "X" in w:
            vx = self.length(w["X"]) / (2.0 if self.diameter else 1.0)
            x = vx if self.absolute else x0 + vx
        if "Z" in w:
            vz = self.length(w["Z"])
            z = vz if self.absolute else z0 + vz
        kind = {"G0": "rapid", "G1": "feed", "G2": "cw", "G3": "ccw"}[self.motion]
        center = None
        if kind in ("cw", "ccw"):
            if self.just_off:
                raise self.err(line, "the move just after G40 must be straight")
            center = self.arc_center(line, w, (x0, z0), (x, z), kind)
        m = Motion(
            kind,
            (x0, z0),
            (x, z),
            line.number,
            center,
            self.comp,
            self.comp is not None and self.first_after_on,
        )
        if self.comp is not None:
            self.first_after_on = False
        self.just_off = False
        self.moves.append(m)
        self.events.append(m)
        self.pos = (x, z)

    def arc_center(self, line, w, p0, p1, kind):
        has_ik = "I" in w or "K" in w
        if has_ik and "R" in w:
            raise self.err(line, "an arc takes R or I/K, not both")
        if not has_ik and "R" not in w:
            raise self.err(line, "an arc needs R or I/K")
        if "R" in w:
            return _center_from_r(self, line, p0, p1, self.length(w["R"]), kind)
        i = self.length(w.get("I", 0.0))
        k = self.length(w.get("K", 0.0))
        c = (i, k) if self.arc_absolute else (p0[0] + i, p0[1] + k)
        r0, r1 = math.dist(c, p0), math.dist(c, p1)
        if r0 < _RADIUS_TOL_MM or r1 < _RADIUS_TOL_MM:
            raise self.err(line, "zero-radius arc")
        err = abs(r0 - r1)
        if err > _SPIRAL_ABS_MM[self.units] or err / max(r0, r1) > _SPIRAL_REL:
            raise self.err(
                line,
                f"radius to the arc's end differs from radius to its start "
                f"({r0:.4f} vs {r1:.4f} mm)",
            )
        return c


def _center_from_r(reader, line, p0, p1, r, kind):
    """Centre of an R-format arc from ``p0`` to ``p1`` (drawing frame: z right, x up).

    The centre lies on the perpendicular bisector of the chord, $h =
    \\sqrt{R^2 - (c/2)^2}$ from its mid-point: to the left of the chord for a
    counter-clockwise arc of at most 180 degrees, to the right for a clockwise
    one; a negative R asks for the arc over 180 degrees (the other side).
    """
    (x0, z0), (x1, z1) = p0, p1
    dx, dz = x1 - x0, z1 - z0
    chord = math.hypot(dx, dz)
    if chord == 0.0:
        raise reader.err(line, "an R arc cannot start and end at the same point")
    ar = abs(r)
    if chord / 2 - ar > _RADIUS_TOL_MM:
        raise reader.err(line, f"arc radius {ar:.4f} mm is too small to reach the end point")
    h = math.sqrt(max(ar * ar - chord * chord / 4, 0.0))
    left_x, left_z = dz / chord, -dx / chord  # unit normal, left of travel (drawing frame)
    side = (1.0 if kind == "ccw" else -1.0) * (1.0 if r > 0 else -1.0)
    return ((x0 + x1) / 2 + side * h * left_x, (z0 + z1) / 2 + side * h * left_z)


def parse_gcode(
    text: str,
    *,
    name: str | None = None,
    units: str = "mm",
    diameter_mode: bool = False,
    start: tuple[float, float] = (0.0, 0.0),
) -> GcodeProgram:
    """Read a lathe part program from its text.

    **Arguments:**

    - `text`: the program text.
    - `name`: the name used in error messages.
    - `units`: ``"mm"`` or ``"in"`` before the first G20/G21.
    - `diameter_mode`: X words are diameters before the first G7/G8
      (LinuxCNC's default is radius, Fanuc's diameter).
    - `start`: the tool position ``(x, z)`` (mm, radius) before the first move.

    **Returns:** a :class:`GcodeProgram` (``.moves`` in mm, radius X;
    ``.text`` is ``text`` unchanged).
    """
    if units not in ("mm", "in"):
        raise InputError(f"units must be 'mm' or 'in', got {units!r}", file=name)
    return _Reader(lex_gcode(text, name=name), units, diameter_mode, start).run()


def read_gcode(
    path,
    *,
    units: str = "mm",
    diameter_mode: bool = False,
    start: tuple[float, float] = (0.0, 0.0),
) -> GcodeProgram:
    """Read a lathe part program file (see :func:`parse_gcode` for the arguments).

    The bytes are kept exactly (line endings, undecodable bytes), so
    ``program.source.to_bytes()`` equals the file's bytes.
    """
    path = Path(path)
    return parse_gcode(
        read_text_lossless(path),
        name=str(path),
        units=units,
        diameter_mode=diameter_mode,
        start=start,
    )

"""The modal state of a lathe control: blocks in, moves in the XZ half-plane out.

[`ModalMachine`][] executes one [`Block`][] at a time (a source line whose values are
known) under a dialect's table, in LinuxCNC's order of execution, and collects every
move as a :class:`~piecs_bayes.gcode.Motion` in **millimetres, radius X**, with its
source line. It keeps units, diameter or radius X, absolute or incremental axes, arc
centres, work offsets and shifts (G10, G54-G59, G92, Fanuc's G50), G28/G30, G53, nose
compensation and tools, and notes what it does not apply (M codes, G10 tool data,
spindle clamps). Anything not understood is an InputError naming file, line, word and
why. LinuxCNC's Y moves, drilling cycles (`drill_moves`) and probing moves (G38.x) are
read as the moves it makes, with their Y (``Motion.y``): never a contour. G2 is
clockwise in the drawing frame (z right, x up), as LinuxCNC's ``ARC_FEED`` shows.

The words of each dialect: docs/models/part_programs.md, "The modal machine".
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import NamedTuple

from ..errors import InputError
from ._dialect import LINUXCNC_DRILLING, LINUXCNC_PROBING, DialectTable
from ._drill_cycle import DrillCall, drill_moves
from ._lexer import SourceLine, code_of
from ._options import ReadOptions
from ._params import ParameterError
from ._program import CompEvent, CompSetting, LineState, Motion, Note, ToolWord

MM_PER_INCH = 25.4
_new = object.__new__
# Arc tolerances (mm): how far an R arc may fall short of its chord, and how much an
# I/K arc's start and end radii may differ; chosen to accept what rs274 accepts
# on the test corpus (0.00005 in; 0.01 mm or 0.001 in times sqrt(2), twice).
_RADIUS_TOL_MM = 0.00005 * MM_PER_INCH
_SPIRAL_ABS_MM = {"mm": 2 * 0.01 * math.sqrt(2), "in": 2 * 0.001 * math.sqrt(2) * MM_PER_INCH}
_SPIRAL_REL = 0.001
# after a probing move LinuxCNC's standalone interpreter puts the tool 0.01 in back
# towards where the move began (saicanon.cc, STRAIGHT_PROBE)
_PROBE_BACKOFF_MM = 0.254
_KIND = {"G0": "rapid", "G1": "feed", "G2": "cw", "G3": "ccw"}
_LINUXCNC_LETTERS = set("GMNOXYZIKRFSTDLPQHE")
_FANUC_LETTERS = set("GMNOXZUWIKRFSTPQLHE") | {",C", ",R"}
_M_GROUPS_LINUXCNC = {
    **dict.fromkeys(("M0", "M1", "M2", "M30", "M60"), "stop"),
    **dict.fromkeys(("M6", "M61"), "toolchange"),
    **dict.fromkeys(("M3", "M4", "M5", "M19"), "spindle"),
    **dict.fromkeys(("M7", "M8", "M9"), "coolant"),
    **dict.fromkeys(("M48", "M49", "M50", "M51", "M52", "M53"), "override"),
    **dict.fromkeys(("M62", "M63", "M64", "M65", "M66", "M67", "M68"), "io"),
    **dict.fromkeys(("M70", "M71", "M72", "M73"), "state"),
}
_M_GROUPS_FANUC = {
    **dict.fromkeys(("M0", "M1", "M2", "M30", "M98", "M99", "M97"), "stop"),
    **dict.fromkeys(("M3", "M4", "M5"), "spindle"),
    **dict.fromkeys(("M8", "M9"), "coolant"),
}
_WORK_SYSTEMS = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
_FANUC_SYSTEMS = ("G54", "G55", "G56", "G57", "G58", "G59")


class BlockWord(NamedTuple):
    """A word of an executed block: its letter, its value now, its text (as written, or
    the value computed), its index among the source line's words and, for G and M
    words, its code (``"G1"``)."""

    letter: str
    value: float
    text: str
    index: int
    code: str = ""

    @classmethod
    def of(cls, letter: str, value: float, text: str, index: int) -> BlockWord:
        return cls(letter, value, text, index, code_of(letter, value) if letter in "GM" else "")


@dataclass(frozen=True)
class Block:
    """A source line as it runs this time: its words with their values known."""

    line: SourceLine
    words: tuple[BlockWord, ...]

    @classmethod
    def of(cls, line: SourceLine, words: tuple) -> Block:
        """``Block(line, words)``, fast (a block is made for every computed line run)."""
        block = _new(cls)
        block.__dict__["line"] = line
        block.__dict__["words"] = words
        return block

    @classmethod
    def plain(cls, line: SourceLine) -> Block:
        """The block of a line whose words are all plain numbers: its words as lexed
        (they have the letter, value, text and code a block word has)."""
        return cls(line, line.words)


@dataclass
class _Modes:
    """The modal state that M70-M73 save and restore."""

    units: str
    diameter: bool
    absolute: bool
    arc_absolute: bool
    feed_per_rev: bool


class ModalMachine:
    """Executes blocks (module docstring); ``err`` builds the errors the reader raises.

    **Arguments:**

    - `name`: the program's name for messages.
    - `table`: the dialect's :class:`~piecs_bayes.gcode.DialectTable`.
    - `options`: the resolved :class:`~piecs_bayes.gcode.ReadOptions`.
    - `turret`: T words change tools without M6 (Fanuc-style; a LinuxCNC program
      without any M6).
    """

    def __init__(self, name: str | None, table: DialectTable, options: ReadOptions, turret: bool):
        self.name = name or "<program>"
        self.table = table
        self.dialect = table.name
        self.fanuc = table.name in ("fanuc", "haas")
        self.letters = _LINUXCNC_LETTERS if table.name == "linuxcnc" else _FANUC_LETTERS
        if table.name == "okuma":
            self.letters = (_FANUC_LETTERS - {"U", "W", ",C", ",R"}) | {"D"}
        self.m_groups = _M_GROUPS_LINUXCNC if table.name == "linuxcnc" else _M_GROUPS_FANUC
        self.units = options.units
        self.diameter = bool(options.diameter_mode)
        self.absolute = True
        self.arc_absolute = False
        self.feed_per_rev = table.feed_per_rev
        self.motion: str | None = None
        self.pos = tuple(options.start)
        self.y = 0.0  # LinuxCNC's Y axis (mm): off the XZ plane only in drilling and probing
        self.plane = "G18"
        self.probe_sink = None  # the reader's: the probe's results into #5061-#5070
        self.drill: dict[str, float] = {}  # a drilling cycle's sticky R, Z, Q, P, L
        self.drill_initial: float | None = None  # its initial level (LinuxCNC's cycle_il)
        zero = options.machine_zero
        # machine coordinates of each work system's zero (NaN: not known)
        self.base = (-zero[0], -zero[1]) if zero is not None else (math.nan, math.nan)
        self.system = "G54"
        self.offsets: dict[str, tuple[float, float]] = {}
        self.ext = (0.0, 0.0)
        self.shift = (0.0, 0.0)
        self.saved_shift = (0.0, 0.0)
        # reference positions in machine coordinates: LinuxCNC's #5161.. / #5181.. (0 in
        # rs274 without a parameter file); Fanuc's first reference is the machine zero
        nan = (math.nan, math.nan)
        self.homes = {"G28": (0.0, 0.0), "G30": (0.0, 0.0) if table.name == "linuxcnc" else nan}
        self.feed = 0.0
        self.speed = 0.0
        self.spindle = "M5"
        self.coolant: set[str] = set()
        self.length_on = False
        self.css = False
        self.return_mode = "G99"  # LinuxCNC starts retracting canned cycles to R
        self.comp: CompSetting | None = None
        self.first_after_on = False
        self.just_off = False
        self.selected: int | None = None
        self.tool: int | None = None
        self.t_selected: ToolWord | None = None
        self.t_cutting: ToolWord | None = None
        self.turret = turret
        self.saved: _Modes | None = None
        self.corner: tuple[Motion, BlockWord] | None = None
        self.contour_mode = False  # reading a LinuxCNC G7x contour: A/C words are corners
        self.corners: dict[int, tuple[float, float]] = {}  # move index -> (fillet, chamfer)
        self._last_state: tuple | None = None
        self.moves: list[Motion] = []
        self.events: list[Motion | CompEvent] = []
        self.notes: list[Note] = []

    # -- helpers --------------------------------------------------------------------------

    def err(self, line: SourceLine, msg: str) -> InputError:
        return InputError(f"{msg}: {line.text.strip()!r}", file=self.name, line=line.number)

    def note(self, line: int, word: str, text: str) -> None:
        self.notes.append(Note(line, word, text))

    def length(self, value: float) -> float:
        return value * (MM_PER_INCH if self.units == "in" else 1.0)

    def x_length(self, value: float) -> float:
        return self.length(value) / (2.0 if self.diameter else 1.0)

    def work(self, system: str | None = None) -> tuple[float, float]:
        """Machine coordinates of the program's zero in ``system`` (NaN: not known)."""
        ox, oz = self.offsets.get(system or self.system, self.base)
        return (ox + self.ext[0] + self.shift[0], oz + self.ext[1] + self.shift[1])

    def to_program(self, machine: tuple[float, float]) -> tuple[float, float]:
        wx, wz = self.work()
        return (machine[0] - wx, machine[1] - wz)

    def _reframe(self, line, old: tuple[float, float], what: str) -> None:
        """The program's zero moved from ``old`` to ``work()`` (machine coordinates): the
        tool stays where it is, its program coordinates change."""
        new = self.work()
        if old == new:
            return
        self.pos = (self.pos[0] + old[0] - new[0], self.pos[1] + old[1] - new[1])
        if any(math.isnan(v) for v in self.pos):
            self.note(line.number, what, "the work offsets are not known: the position is "
                      "unknown until X and Z are programmed absolutely")  # fmt: skip

    def state(self) -> LineState:
        key = (
            self.units,
            self.diameter,
            self.absolute,
            self.arc_absolute,
            self.motion,
            self.comp,
            self.t_cutting,
            self.feed_per_rev,
        )
        last = self._last_state
        if last is not None and last[0] == key:
            return last[1]  # modes unchanged: the same (immutable) state
        state = LineState(*key)
        self._last_state = (key, state)
        return state

    def save_modes(self) -> _Modes:
        return _Modes(
            self.units, self.diameter, self.absolute, self.arc_absolute, self.feed_per_rev
        )

    def restore_modes(self, modes: _Modes) -> None:
        self.units, self.diameter = modes.units, modes.diameter
        self.absolute, self.arc_absolute = modes.absolute, modes.arc_absolute
        self.feed_per_rev = modes.feed_per_rev

    def finish(self) -> None:
        """The program ended: a ,C/,R corner still waiting for its next move is an error."""
        if self.corner is not None:
            m, w = self.corner
            raise InputError(
                f"{w.letter}{w.text} on line {m.line} has no next move to make its corner with",
                file=self.name,
                line=m.line,
            )

    # -- canned cycles ----------------------------------------------------------------------

    def snapshot(self):
        """The whole state, to run a cycle's contour blocks and then undo them."""
        keep = ("moves", "events", "notes")
        state = {k: copy.copy(v) for k, v in vars(self).items() if k not in keep}
        return state, len(self.moves), len(self.events), len(self.notes)

    def restore(self, snap) -> tuple[list[Motion], list[CompEvent], dict]:
        """Back to ``snap``; returns the moves, compensation events and corners (index
        into those moves -> (fillet, chamfer)) made since."""
        state, n_moves, n_events, n_notes = snap
        moves = self.moves[n_moves:]
        events = [e for e in self.events[n_events:] if isinstance(e, CompEvent)]
        corners = {k - n_moves: v for k, v in self.corners.items() if k >= n_moves}
        del self.moves[n_moves:], self.events[n_events:], self.notes[n_notes:]
        vars(self).update(state)
        return moves, events, corners

    def emit_cycle_move(self, line: SourceLine, move, via: str) -> None:
        """A move a canned cycle makes (a ``CycleMove``), with the compensation in force."""
        m = self._motion(line, move.kind, move.start, move.end, move.center, via)
        self.moves.append(m)
        self.events.append(m)
        self.pos = move.end

    # -- predefined parameters --------------------------------------------------------------

    def predefined(self, ref) -> float | None:
        """The value of a parameter the control computes (None: not one of them)."""
        scale = 1.0 / MM_PER_INCH if self.units == "in" else 1.0
        if isinstance(ref, str):
            return self._named(ref, scale)
        if self.dialect == "linuxcnc":
            return self._linuxcnc_numbered(ref, scale)
        return self._fanuc_numbered(ref, scale)

    def _program_pos(self, scale: float) -> tuple[float, float]:
        return (self.pos[0] * scale, self.pos[1] * scale)

    def _named(self, name: str, scale: float) -> float | None:
        if name.startswith(("_ini[", "_hal[")):
            raise ParameterError(f"#<{name}> (the machine's INI or HAL) has no value here")
        x, z = self._program_pos(scale)
        motion = 800.0 if self.motion is None else float(round(float(self.motion[1:]) * 10))
        comp = 400.0
        if self.comp is not None:
            comp = {"G41": 410.0, "G41.1": 411.0, "G42": 420.0, "G42.1": 421.0}[self.comp.code]
        values = {
            "_x": x,
            "_z": z,
            "_abs_x": self.pos[0] * scale,
            "_abs_z": self.pos[1] * scale,
            "_y": self.y * scale,
            "_abs_y": self.y * scale,
            **dict.fromkeys(("_a", "_b", "_c", "_u", "_v", "_w"), 0.0),
            **dict.fromkeys(("_abs_a", "_abs_b", "_abs_c"), 0.0),
            "_imperial": float(self.units == "in"),
            "_metric": float(self.units == "mm"),
            "_absolute": float(self.absolute),
            "_incremental": float(not self.absolute),
            "_lathe_diameter_mode": float(self.diameter),
            "_lathe_radius_mode": float(not self.diameter),
            "_ijk_absolute_mode": float(self.arc_absolute),
            "_ijk_incremental_mode": float(not self.arc_absolute),
            "_motion_mode": motion,
            "_plane": float(self.plane[1:]) * 10,
            "_ccomp": comp,
            "_feed": self.feed,
            "_rpm": self.speed,
            "_current_tool": float(self.tool or 0),
            "_current_pocket": float(self.tool or 0),
            "_selected_tool": float(self.selected if self.selected is not None else -1),
            "_selected_pocket": float(self.selected if self.selected is not None else -1),
            "_spindle_on": float(self.spindle in ("M3", "M4")),
            "_spindle_cw": float(self.spindle == "M3"),
            "_spindle_css_mode": float(self.css),
            "_spindle_rpm_mode": float(not self.css),
            "_mist": float("M7" in self.coolant),
            "_flood": float("M8" in self.coolant),
            "_coord_system": 10.0 * float(self.system[1:]),
            "_tool_offset": float(self.length_on),
            "_units_per_minute": float(not self.feed_per_rev),
            "_units_per_rev": float(self.feed_per_rev),
            "_inverse_time": 0.0,
            "_retract_r_clear": float(self.return_mode == "G99"),
            "_retract_old_z": float(self.return_mode == "G98"),
            **dict.fromkeys(
                ("_speed_override", "_feed_override", "_adaptive_feed", "_feed_hold"), 1.0
            ),
            "_task": 0.0,
            "_vmajor": 2.9,  # the LinuxCNC version whose rules the reader follows
            "_vminor": 0.0,
            "_remap_level": 0.0,
        }
        return values.get(name)

    def _linuxcnc_numbered(self, n: int, scale: float) -> float | None:
        axis = {0: 0, 2: 1}  # X and Z among X Y Z A B C U V W
        if 5161 <= n <= 5169 or 5181 <= n <= 5189:
            home = self.homes["G28" if n < 5170 else "G30"]
            k = (n - 5161) % 20
            return home[axis[k]] * scale if k in axis else 0.0
        if 5211 <= n <= 5219:
            k = n - 5211
            return self.shift[axis[k]] * scale if k in axis else 0.0
        if n == 5210:
            return float(self.shift != (0.0, 0.0))
        if n == 5220:
            return float(_WORK_SYSTEMS.index(self.system) + 1)
        if 5221 <= n <= 5390:
            system, k = divmod(n - 5221, 20)
            off = self.offsets.get(_WORK_SYSTEMS[system], self.base)
            if k in axis and math.isnan(off[axis[k]]):
                raise ParameterError(f"#{n}: the work offset is not known")
            return off[axis[k]] * scale if k in axis else 0.0
        if n == 5400:
            return float(self.tool or 0)
        if 5401 <= n <= 5413:
            return 0.0  # tool-table data: the standalone interpreter's empty table
        if 5420 <= n <= 5428:
            k = n - 5420
            x, z = self._program_pos(scale)
            return {0: x, 1: self.y * scale, 2: z}.get(k, 0.0)
        if 5061 <= n <= 5070 or n == 5399:
            raise ParameterError(
                f"#{n} (a probe or input result) has no value when only reading"
                + (" (no probing move before it)" if n != 5399 else "")
            )
        return None

    def _fanuc_numbered(self, n: int, scale: float) -> float | None:
        if 4001 <= n <= 4130:
            modal = {
                4001: float((self.motion or "G0")[1:]),
                4005: 99.0 if self.feed_per_rev else 98.0,
                4006: 20.0 if self.units == "in" else 21.0,
                4007: float((self.comp.code if self.comp else "G40")[1:3]),
                4014: float(self.system[1:]),
                4109: self.feed,
                4119: self.speed,
                4120: float(self.t_cutting.value if self.t_cutting else 0),
            }
            if n in modal:
                return modal[n]
        if n in (5001, 5002, 5041, 5042):
            x, z = self._program_pos(scale)
            return (x * (2.0 if self.diameter else 1.0)) if n % 2 else z
        if n >= 1000:
            raise ParameterError(f"system variable #{n} has no value when a program is only read")
        return None

    # -- a block -----------------------------------------------------------------------------

    def execute(self, block: Block) -> None:
        line = block.line
        corner = None
        if self.contour_mode:  # LinuxCNC G7x contour: A (fillet) and C (chamfer) corners
            found = {w.letter: w.value for w in block.words if w.letter in ("A", "C")}
            if found:
                if len(found) == 2:
                    raise self.err(line, "a G7x corner takes A (fillet) or C (chamfer), not both")
                corner = (found.get("A", 0.0), found.get("C", 0.0))
                words = tuple(w for w in block.words if w.letter not in ("A", "C"))
                block = Block(line, words)
        n_moves = len(self.moves)
        if corner is None and self.straight(block):
            return
        self._execute(block)
        if corner is not None:
            if len(self.moves) == n_moves:
                raise self.err(line, "a G7x corner (A/C) needs a move in its block")
            self.corners[len(self.moves) - 1] = (self.length(corner[0]), self.length(corner[1]))

    def straight(self, block: Block) -> bool:
        """The common block, fast: G0/G1, X, Z, F, N words only, each at most once, from
        and to a known position, no corner waiting. True when done; False (nothing
        changed) for every other block, which `_execute` runs."""
        if self.corner is not None:
            return False
        code = x = z = f = None
        for w in block.words:
            letter = w.letter
            if letter == "X" and x is None:
                x = w.value
            elif letter == "Z" and z is None:
                z = w.value
            elif letter == "F" and f is None:
                f = w.value
            elif letter == "G" and code is None and w.code in ("G0", "G1"):
                code = w.code
            elif letter != "N":
                return False
        motion = code or self.motion
        if x is None and z is None:
            if code is None and f is None:
                return False
        elif motion not in ("G0", "G1"):
            return False
        x0, z0 = self.pos
        x1, z1 = x0, z0
        if x is not None:
            v = self.x_length(x)
            x1 = v if self.absolute else x0 + v
        if z is not None:
            v = self.length(z)
            z1 = v if self.absolute else z0 + v
        if x0 != x0 or z0 != z0 or x1 != x1 or z1 != z1:  # NaN: a position not known
            return False
        if f is not None:
            self.feed = f
        self.motion = motion
        if x is not None or z is not None:
            m = self._motion(block.line, _KIND[motion], (x0, z0), (x1, z1), None)
            self.moves.append(m)
            self.events.append(m)
            self.pos = (x1, z1)
        return True

    def _execute(self, block: Block) -> None:
        line = block.line
        gcodes, mcodes, w = self._sort(block)
        if self.corner is not None and "comp" in gcodes:
            raise self.err(line, "a ,C/,R corner cannot end where compensation changes")
        self._settings(line, gcodes, mcodes, w)
        nonmodal = gcodes.get("nonmodal")
        before = self.motion
        if gcodes.get("motion"):
            self.motion = None if gcodes["motion"] == "G80" else gcodes["motion"]
        axes = [k for k in ("X", "Y", "Z", "U", "W") if k in w]  # a setting took its own
        if self.motion in LINUXCNC_DRILLING and nonmodal not in ("G28", "G30", "G53"):
            if axes or "motion" in gcodes:
                self._drill(line, before, w)
            self._stops(line, mcodes)
            return
        if (axes and nonmodal not in ("G28", "G30")) or "motion" in gcodes:
            self.drill_initial = None  # another motion: a new run of cycles starts afresh
        if nonmodal in ("G28", "G30"):
            self._reference(line, nonmodal, w, axes)
            axes = []
        arc_words = [k for k in ("I", "K", "R") if k in w]
        if axes:
            if self.motion is None and not (nonmodal == "G53" and self.fanuc):
                raise self.err(line, "axis words with no motion mode (G0/G1/G2/G3) in force")
            self._move(line, w, machine=nonmodal == "G53")
        elif nonmodal == "G53":
            raise self.err(line, "G53 needs the axes to move (X/Z)")
        elif arc_words:
            raise self.err(line, f"{'/'.join(arc_words)} without an arc end point (X/Z)")
        if arc_words and self.motion not in ("G2", "G3"):
            raise self.err(line, f"{'/'.join(arc_words)} words are only understood with G2/G3")
        if (",C" in w or ",R" in w) and not axes:
            raise self.err(line, ",C/,R needs a G1 move in its block")
        self._stops(line, mcodes)

    def _sort(self, block: Block):
        """G codes by group, M codes by group and the other words by letter (checked)."""
        line = block.line
        table = self.table
        gcodes: dict[str, str] = {}
        mcodes: dict[str, str] = {}
        w: dict[str, BlockWord] = {}
        for word in block.words:  # refused codes first: a thread cycle's J word says less
            if word.letter == "G" and word.code in table.refused:
                raise self.err(line, f"{word.code}: {table.refused[word.code]}")
        for k, word in enumerate(block.words):
            letter = word.letter
            if letter not in self.letters:
                raise self.err(
                    line, f"word {letter}{word.text} is not understood{_hint(self, letter)}"
                )
            if letter == "G":
                code = word.code
                group = table.groups.get(code)
                if group is None:
                    raise self.err(line, f"{code} is not understood")
                if group in gcodes and gcodes[group] != code:
                    if table.same_group == "refuse" or group == "nonmodal":
                        raise self.err(
                            line, f"{gcodes[group]} and {code} in one block (same modal group)"
                        )
                    self.note(
                        line.number,
                        f"{gcodes[group]} {code}",
                        f"two codes of one group in a block: {code} (the last) is valid",
                    )
                gcodes[group] = code
            elif letter == "M":
                code = word.code
                group = self.m_groups.get(code)
                if group is None:
                    if self.table.m_codes is not None and code not in self.table.m_codes:
                        raise self.err(line, f"{code} is not understood")
                    group = code  # recorded, machine-specific
                if group in mcodes:
                    if group == "coolant" and {mcodes[group], code} == {"M7", "M8"}:
                        group = "coolant2"
                    else:
                        raise self.err(
                            line, f"{mcodes[group]} and {code} in one block (same modal group)"
                        )
                mcodes[group] = code
            else:
                if letter in w:
                    raise self.err(line, f"word {letter} appears twice")
                if letter == "O" and k != 0:
                    raise self.err(line, "an O number must be the first word of its line")
                w[letter] = word
        if "X" in w and "U" in w or "Z" in w and "W" in w:
            raise self.err(line, "X and U (or Z and W) in one block: one axis, two targets")
        return gcodes, mcodes, w

    def _settings(self, line: SourceLine, gcodes, mcodes, w) -> None:
        """Everything of a block but its motion and its stops, in LinuxCNC's order."""
        n = line.number
        nonmodal = gcodes.get("nonmodal")
        self._check_letters(line, gcodes, mcodes, w)
        if "feed_mode" in gcodes:
            code = gcodes["feed_mode"]
            self.feed_per_rev = code in ("G95", "G99")
        if "F" in w:
            self.feed = w["F"].value
        if "S" in w and nonmodal != "G50":
            self.speed = w["S"].value
        if "T" in w:
            self._t_word(line, w["T"])
        if "toolchange" in mcodes:
            self._tool_change(line, mcodes["toolchange"], w)
        if "spindle" in mcodes:
            self.spindle = mcodes["spindle"]
        for key in ("coolant", "coolant2"):
            if key in mcodes:
                code = mcodes[key]
                self.coolant = set() if code == "M9" else self.coolant | {code}
        if "state" in mcodes:
            self._state_codes(line, mcodes["state"])
        for group, code in mcodes.items():
            if group not in ("stop", "toolchange", "spindle", "coolant", "coolant2", "state"):
                self.note(n, code, "recorded (no motion)")
        if "spindle_mode" in gcodes:
            self.css = gcodes["spindle_mode"] == "G96"
        if nonmodal == "G50" and "S" in w:
            self.note(n, f"G50 S{w['S'].text}", "spindle speed clamp recorded")
        if nonmodal == "G4":
            self._dwell(line, w)
        if "units" in gcodes:
            self.units = "in" if gcodes["units"] == "G20" else "mm"
        if "diameter" in gcodes:
            self.diameter = gcodes["diameter"] == "G7"
        if "plane" in gcodes:
            plane = gcodes["plane"]
            if plane != "G18" and self.comp is not None and gcodes.get("comp") != "G40":
                raise self.err(line, f"{plane} with nose compensation on (G40 first)")
            self.plane = plane
        comp = gcodes.get("comp")
        if comp == "G40":
            self.just_off = self.comp is not None
            self.comp = None
            self.events.append(CompEvent(n, None))
        elif comp:
            self._comp_on(line, comp, w)
        if "length" in gcodes:
            self.length_on = gcodes["length"] != "G49"
            if gcodes["length"] in ("G43.1", "G43.2"):
                for k in ("X", "Z"):
                    w.pop(k, None)
                self.note(n, gcodes["length"], "tool length offset recorded, not applied")
        if "coord" in gcodes and gcodes["coord"] != self.system:
            old = self.work()
            self.system = gcodes["coord"]
            self._reframe(line, old, self.system)
        if "distance" in gcodes:  # (path control G61/G64, G103, G187: not the path's shape)
            self.absolute = gcodes["distance"] == "G90"
        if "arc_distance" in gcodes:
            self.arc_absolute = gcodes["arc_distance"] == "G90.1"
        if "return_mode" in gcodes:
            self.return_mode = gcodes["return_mode"]
        if nonmodal == "G10":
            self._g10(line, w)
        elif nonmodal in ("G92", "G50") and any(k in w for k in "XZUW"):
            self._set_coordinates(line, nonmodal, w)
        elif nonmodal in ("G92.1", "G92.2", "G92.3"):
            old = self.work()
            if nonmodal == "G92.1":
                self.saved_shift = (0.0, 0.0)
            self.shift = self.saved_shift if nonmodal == "G92.3" else (0.0, 0.0)
            self._reframe(line, old, nonmodal)
        elif nonmodal in ("G28.1", "G30.1"):
            wx, wz = self.work()
            self.homes[nonmodal[:3]] = (self.pos[0] + wx, self.pos[1] + wz)

    def _check_letters(self, line, gcodes, mcodes, w) -> None:
        nonmodal = gcodes.get("nonmodal")
        comp = gcodes.get("comp")
        m = set(mcodes.values())
        linuxcnc = self.table.name == "linuxcnc"
        motion = gcodes.get("motion") or self.motion
        drilling = motion in LINUXCNC_DRILLING
        p_ok = nonmodal in ("G4", "G10") or gcodes.get("path") == "G64"
        p_ok = p_ok or motion in ("G82", "G89")
        p_ok = p_ok or bool(
            m & {"M98", "M99", "M97", "M62", "M63", "M64", "M65", "M66", "M67", "M68"}
        )
        if "P" in w and not p_ok:
            what = "G4, G10 or G64" if linuxcnc else "G4, G10, M98, M99 or M97"
            raise self.err(line, f"a P word is only understood with {what}")
        q_ok = gcodes.get("path") == "G64" or nonmodal == "G10" or "M61" in m or "M66" in m
        q_ok = q_ok or motion in ("G73", "G83")
        if "Q" in w and not q_ok:
            raise self.err(
                line, "a Q word is only understood with G64" + ("" if linuxcnc else " or G10")
            )
        if "H" in w and gcodes.get("length") != "G43":
            raise self.err(line, "an H word is only understood with G43")
        if "E" in w and not m & {"M67", "M68"}:
            raise self.err(line, "an E word (thread lead, analog output) is not understood here")
        if "L" in w and not (
            comp in ("G41.1", "G42.1") or nonmodal == "G10" or m & {"M98", "M66"} or drilling
        ):
            raise self.err(line, "an L word is only understood with G41.1/G42.1, G10 or M98")
        if "D" in w and not (
            comp in ("G41", "G42", "G41.1", "G42.1") or gcodes.get("spindle_mode") == "G96"
        ):
            raise self.err(line, "a D word is only understood with G41/G42/G41.1/G42.1 or G96")

    def _dwell(self, line, w) -> None:
        if self.table.name == "linuxcnc":
            if "P" not in w:
                raise self.err(line, "G4 needs a P word (seconds)")
            return
        if not ({"P", "X", "U"} & set(w)):
            raise self.err(line, "G04 needs the dwell time (P, X or U)")
        for k in ("X", "U"):
            w.pop(k, None)  # Fanuc G04 X1.5 / U1.5: seconds, not an axis

    def _t_word(self, line: SourceLine, t: BlockWord) -> None:
        if t.value < 0 or t.value != int(t.value):
            raise self.err(line, "T must be a whole number >= 0")
        self.selected = int(t.value)
        by = "T" if self.turret else "M6"
        self.t_selected = ToolWord(f"T{t.text}", self.selected, line.number, by)
        if self.turret:
            self.t_cutting = self.t_selected
            self.tool = self.selected

    def _tool_change(self, line, code, w) -> None:
        if code == "M61":
            if "Q" not in w:
                raise self.err(line, "M61 needs a Q word (the tool)")
            self.tool = int(w["Q"].value)
            self.note(line.number, "M61", f"tool {self.tool} set as loaded")
            return
        if self.comp is not None:
            raise self.err(line, "cannot change tools with compensation on (G40 first)")
        if self.selected is None:
            raise self.err(line, "M6 with no tool selected (T word)")
        self.tool = self.selected
        self.t_cutting = self.t_selected

    def _state_codes(self, line, code) -> None:
        if code in ("M70", "M73"):
            self.saved = self.save_modes()
            if code == "M73":
                self.note(line.number, code, "modal state saved, restored when the call returns")
        elif code == "M71":
            self.saved = None
        elif code == "M72":
            if self.saved is None:
                raise self.err(line, "M72 with no state saved (M70 first)")
            self.restore_modes(self.saved)

    def _comp_on(self, line, code, w) -> None:
        if self.comp is not None:
            raise self.err(line, f"{code} while compensation is already on (G40 first)")
        if self.plane != "G18":
            raise self.err(line, f"{code} in the {_PLANES[self.plane]} plane ({self.plane}): "
                           "nose compensation is read in the XZ plane (G18) only")  # fmt: skip
        side = "left" if code.startswith("G41") else "right"
        if code.endswith(".1"):
            if "D" not in w:
                raise self.err(line, f"{code} needs a D word (tool diameter)")
            orient = int(w["L"].value) if "L" in w else 0
            if "L" in w and (w["L"].value != orient or not 0 <= orient <= 9):
                raise self.err(line, f"L must be a tool orientation 0-9, got {w['L'].value:g}")
            setting = CompSetting(side, code, line.number, None, self.length(w["D"].value), orient)
        else:
            # the tool an M6 loaded; a turret-style T word leaves it to the program's reader
            # (`finish_cut_tools`: Tttoo is a tool and an offset, not a tool-table entry)
            tool = None if self.turret else self.tool
            if "D" in w:
                d = w["D"].value
                if d < 0 or abs(d - round(d)) >= 1e-4:
                    raise self.err(line, f"{code} needs D to be a tool number (whole, >= 0)")
                tool = int(round(d))
            setting = CompSetting(side, code, line.number, tool)
        self.comp = setting
        self.first_after_on = True
        self.events.append(CompEvent(line.number, setting))

    # -- coordinates ---------------------------------------------------------------------

    def _g10(self, line, w) -> None:
        n = line.number
        if "Y" in w:
            raise self.err(line, "G10 Y: offsets of the Y axis are not read")
        lw = w.get("L")
        level = int(lw.value) if lw is not None else None
        if level in (2, 20):
            if "P" not in w:
                raise self.err(line, f"G10 L{level} needs P (the coordinate system)")
            p = int(w["P"].value)
            systems = _WORK_SYSTEMS if self.table.name == "linuxcnc" else _FANUC_SYSTEMS
            if p == 0 and self.table.name == "linuxcnc":
                system = self.system
            elif p == 0:
                system = "EXT"
            elif 1 <= p <= len(systems):
                system = systems[p - 1]
            else:
                raise self.err(line, f"G10 L{level} P{p}: no such coordinate system")
            if "R" in w and w["R"].value != 0:
                raise self.err(line, "G10 with a rotation (R) is not read")
            before = self.work()
            ox, oz = self.ext if system == "EXT" else self.offsets.get(system, self.base)
            if level == 2:
                x = self.x_length(w["X"].value) if "X" in w else ox
                z = self.length(w["Z"].value) if "Z" in w else oz
            else:  # L20: the current position gets the coordinates given, in that system
                wx, wz = self.work()
                mx, mz = self.pos[0] + wx, self.pos[1] + wz
                ex, ez = (0.0, 0.0) if system == "EXT" else self.ext
                x = mx - ex - self.shift[0] - self.x_length(w["X"].value) if "X" in w else ox
                z = mz - ez - self.shift[1] - self.length(w["Z"].value) if "Z" in w else oz
            if system == "EXT":
                self.ext = (x, z)
            else:
                self.offsets[system] = (x, z)
            used = system in (self.system, "EXT")
            if used and level == 20:
                gx = self.x_length(w["X"].value) if "X" in w else self.pos[0]
                gz = self.length(w["Z"].value) if "Z" in w else self.pos[1]
                self.pos = (gx, gz)  # known even where the machine position is not
            elif used:
                self._reframe(line, before, f"G10 L{level}")
            self.note(
                n,
                f"G10 L{level} P{p}",
                f"work offset {system} set to (x={x:.4f}, z={z:.4f}) mm"
                + (" (the system in use: applied)" if used else " (not the system in use)"),
            )
            for k in ("X", "Z"):
                w.pop(k, None)
            return
        for k in ("X", "Z", "U", "W", "R"):
            w.pop(k, None)
        self.note(
            n,
            "G10" + (f" L{level}" if level is not None else ""),
            "tool data recorded, not applied",
        )

    def _set_coordinates(self, line, code, w) -> None:
        """G92 / Fanuc's G50 X Z: the current position gets the coordinates given."""
        if "Y" in w:
            raise self.err(line, f"{code} Y: offsets of the Y axis are not read")
        if code == "G50" and self.table.name == "okuma":
            raise self.err(line, "Okuma's G50 X/Z (zero shift) is not read")
        if "U" in w or "W" in w:
            raise self.err(line, f"{code} takes X/Z (the position's new coordinates), not U/W")
        x, z = self.pos
        if "X" in w:
            x = self.x_length(w["X"].value)
        if "Z" in w:
            z = self.length(w["Z"].value)
        self.shift = (self.shift[0] + self.pos[0] - x, self.shift[1] + self.pos[1] - z)
        self.saved_shift = self.shift
        self.pos = (x, z)
        self.note(
            line.number, code, f"coordinate system set: the tool is at (x={x:.4f}, z={z:.4f}) mm"
        )
        for k in ("X", "Z"):
            w.pop(k, None)

    def _axis_targets(self, w, start) -> tuple[float, float]:
        """The end point of the axis words in program coordinates (NaN where unknown)."""
        x, z = start
        if "X" in w:
            v = self.x_length(w["X"].value)
            x = v if self.absolute else x + v
        if "Z" in w:
            v = self.length(w["Z"].value)
            z = v if self.absolute else z + v
        if "U" in w:
            x = x + self.x_length(w["U"].value)
        if "W" in w:
            z = z + self.length(w["W"].value)
        return (x, z)

    def _reference(self, line, code, w, axes) -> None:
        """G28/G30: a rapid to the intermediate point (the axis words), then to the
        reference position on the axes named (all of them without axis words: LinuxCNC)."""
        if not axes and self.table.name != "linuxcnc":
            raise self.err(line, f"{code} needs the axes to return (U0 W0, or X/Z)")
        mid = self._axis_targets(w, self.pos)
        y_mid = self._y_target(line, w)
        # LinuxCNC: also without axis words
        self._emit(line, "rapid", mid, None, via=code, y_end=y_mid)
        xs = not axes or any(k in w for k in ("X", "U"))
        zs = not axes or any(k in w for k in ("Z", "W"))
        ref = self.to_program(self.homes[code])
        end = (ref[0] if xs else mid[0], ref[1] if zs else mid[1])
        y_end = 0.0 if not axes or "Y" in w else y_mid  # Y's reference: 0 (no Y offsets)
        if not any(math.isnan(v) for v in end):
            self._emit(line, "rapid", end, None, via=code, y_end=y_end)
        else:
            self.pos, self.y = end, y_end
            self.note(
                line.number,
                code,
                "the reference position is the machine's, not known here (ReadOptions."
                "machine_zero): the position is unknown until X and Z are programmed absolutely",
            )

    # -- moves -----------------------------------------------------------------------------

    def _y_target(self, line, w) -> float:
        """The Y the block moves to (mm); Y words are refused under nose compensation."""
        if "Y" not in w:
            return self.y
        if self.comp is not None:
            raise self.err(line, "a Y move with nose compensation on: a profile is in the XZ plane")
        v = self.length(w["Y"].value)
        return v if self.absolute else self.y + v

    def _move(self, line, w, *, machine: bool = False) -> None:
        if self.motion in LINUXCNC_PROBING and not machine:
            self._probe(line, w)
            return
        x0, z0 = self.pos
        y1 = self._y_target(line, w)
        # Fanuc G53 is a one-shot rapid whatever the motion mode (none in force included)
        kind = "rapid" if machine and self.fanuc else _KIND[self.motion]
        if machine:
            if kind not in ("rapid", "feed"):
                raise self.err(line, "G53 works with G0 or G1 only")
            if self.table.name == "linuxcnc" and not self.absolute:
                raise self.err(line, "G53 in incremental mode (G91) is not allowed")
            if self.fanuc:
                kind = "rapid"  # Fanuc G53: a rapid in machine coordinates
            if "Y" in w:
                raise self.err(line, "G53 Y: the Y axis's machine coordinates are not read")
            wx, wz = self.work()
            x = self.x_length(w["X"].value) - wx if "X" in w else x0
            z = self.length(w["Z"].value) - wz if "Z" in w else z0
            self._emit(line, kind, (x, z), None, via="G53")
            return
        end = self._axis_targets(w, (x0, z0))
        if any(math.isnan(v) for v in end):
            if kind != "rapid":
                raise self.err(
                    line,
                    "a cutting move from or to a position that is not known (after a "
                    "reference return or a machine-coordinate move: program X and Z "
                    "absolutely with G0 first, or give the machine zero)",
                )
        center = None
        if kind in ("cw", "ccw"):
            if self.plane != "G18":
                plane = f"{_PLANES[self.plane]} plane ({self.plane})"
                raise self.err(line, f"an arc in the {plane} is not read: a profile is in XZ")
            if "Y" in w:
                raise self.err(line, "a helix (an arc with a Y word) is not read")
            if self.just_off:
                raise self.err(line, "the move just after G40 must be straight")
            if any(math.isnan(v) for v in (x0, z0)):
                raise self.err(line, "an arc from a position that is not known")
            center = self._arc_center(line, w, (x0, z0), end, kind)
        corner = w.get(",C") or w.get(",R")
        if self.corner is not None:
            self._make_corner(line, kind, end)
            x0, z0 = self.pos
        if corner is not None:
            if kind != "feed":
                raise self.err(line, f"{corner.letter} is only read on a G1 move")
            m = self._motion(line, kind, (x0, z0), end, None)
            self.corner = (m, corner)
            self.pos = end
            return
        if any(math.isnan(v) for v in (x0, z0)) or any(math.isnan(v) for v in end):
            self.note(line.number, "G0", "a rapid from or to a position that is not known")
            self.pos, self.y = end, y1
            return
        self._emit(line, kind, end, center, y_end=y1)

    def _probe(self, line, w) -> None:
        """G38.2-G38.5 (LinuxCNC): a straight feed towards the end point. Where the probe
        touches is not known when only reading: the move is read to its end, where
        LinuxCNC's standalone interpreter puts the contact (#5061-#5063 = that point)."""
        code = self.motion
        if self.comp is not None:
            raise self.err(line, f"{code}: probing with nose compensation on")
        if self.feed == 0.0:
            raise self.err(line, f"{code}: probing with a zero feed rate")
        if self.feed_per_rev:
            raise self.err(line, f"{code}: probing in feed per revolution (G95)")
        end = self._axis_targets(w, self.pos)
        y1 = self._y_target(line, w)
        if any(math.isnan(v) for v in (*self.pos, *end)):
            raise self.err(line, f"{code}: probing from or to a position that is not known")
        if code in ("G38.2", "G38.4") and end == self.pos and y1 == self.y:
            raise self.err(line, f"{code}: the start point is the probe's end point")
        self.note(line.number, code, "probing move: read to its end point, taken as the "
                  "contact (#5061-#5063; #5070 = 0), and backed off 0.254 mm towards its start, as "
                  "LinuxCNC's standalone interpreter does")  # fmt: skip
        start = (self.pos[0], self.y, self.pos[1])
        self._emit(line, "feed", end, None, via=code, y_end=y1)
        probed = (end[0], y1, end[1])
        if self.probe_sink is not None:  # in program units; "not tripped", as rs274 says
            scale = 1.0 / MM_PER_INCH if self.units == "in" else 1.0
            self.probe_sink((*(v * scale for v in probed), *(0.0,) * 7))
        d = [a - b for a, b in zip(start, probed, strict=True)]
        dist = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if dist != 0.0:  # the next move starts there (no move is made)
            x, y, z = (p + _PROBE_BACKOFF_MM * v / dist for p, v in zip(probed, d, strict=True))
            self.pos, self.y = (x, z), y

    def _drill(self, line, before: str | None, w) -> None:
        """A LinuxCNC drilling cycle block (G73, G81-G83, G85, G89) in the XY plane:
        `drill_moves`, with the sticky R, Z, Q and P of the cycle already in force."""
        code = self.motion
        if self.plane != "G17":
            plane = f"{_PLANES[self.plane]} plane ({self.plane})"
            raise self.err(
                line, f"{code} in the {plane} drills across the axis: read in G17 (along Z)"
            )
        if self.comp is not None:
            raise self.err(line, f"{code}: canned cycles with nose compensation on")
        if self.feed == 0.0:
            raise self.err(line, f"{code}: a drilling cycle with a zero feed rate")
        if any(math.isnan(v) for v in self.pos):
            raise self.err(line, f"{code}: a drilling cycle from a position that is not known")
        same = before == code
        sticky = self.drill if same else {}
        needed = {"R": "the clearance plane R", "Z": "the depth Z"}
        if code in ("G73", "G83"):
            needed["Q"] = "the peck Q"
        if code in ("G82", "G89"):
            needed["P"] = "the dwell P"
        values = {}
        for letter, what in needed.items():
            if letter in w:
                values[letter] = w[letter].value
            elif letter in sticky:
                values[letter] = sticky[letter]
            else:
                raise self.err(
                    line, f"{code} needs {what}" + ("" if same else " on its first block")
                )
        lw = w.get("L")
        repeats = 1 if lw is None else lw.value
        if repeats != int(repeats) or repeats < 1:
            raise self.err(line, f"{code}: L (repeats) must be a whole number >= 1")
        unit = MM_PER_INCH if self.units == "in" else 1.0
        halve = 2.0 if self.diameter else 1.0
        here = (self.pos[0] / unit, self.y / unit, self.pos[1] / unit)
        if self.absolute:
            tx = w["X"].value / halve if "X" in w else here[0]
            ty = w["Y"].value if "Y" in w else here[1]
        else:
            tx = w["X"].value / halve if "X" in w else 0.0
            ty = w["Y"].value if "Y" in w else 0.0
        call = DrillCall(code, (tx, ty), values["R"], values["Z"], self.absolute,
                         q=values.get("Q", 0.0), repeats=int(repeats),
                         retract_r=self.return_mode == "G99")  # fmt: skip
        if self.drill_initial is None:
            self.drill_initial = here[2]
        try:
            moves, _ = drill_moves(call, here, self.drill_initial, metric=self.units == "mm")
        except ValueError as exc:
            raise self.err(line, f"{code}: {exc}") from None
        for mv in moves:
            x, y, z = mv.end
            self._emit(line, mv.kind, (x * unit, z * unit), None, via=code, y_end=y * unit)
        self.drill = {**sticky, **values}

    def _motion(self, line, kind, start, end, center, via="", y_end=None) -> Motion:
        m = _new(Motion)  # Motion(...) without the frozen dataclass's per-field setattr
        m.__dict__.update(
            kind=kind,
            start=start,
            end=end,
            line=line.number,
            center=center,
            comp=self.comp,
            entry=self.comp is not None and self.first_after_on,
            via=via,
        )
        y1 = self.y if y_end is None else y_end
        if self.y or y1:
            m.__dict__["y"] = (self.y, y1)
        if self.comp is not None:
            self.first_after_on = False
        self.just_off = False
        return m

    def _emit(self, line, kind, end, center, via="", y_end=None) -> None:
        y1 = self.y if y_end is None else y_end
        if any(math.isnan(v) for v in (*self.pos, *end)):
            self.note(line.number, via or kind, "a rapid from or to a position that is not known")
            self.pos, self.y = end, y1
            return
        m = self._motion(line, kind, self.pos, end, center, via, y1)
        self.moves.append(m)
        self.events.append(m)
        self.pos, self.y = end, y1

    def _make_corner(self, line, kind, end) -> None:
        """The waiting ,C/,R move ends short of its corner; the corner is inserted."""
        prev, word = self.corner
        self.corner = None
        if kind != "feed":
            raise self.err(
                line,
                f"{word.letter}{word.text} on line {prev.line}: a corner "
                "between a line and an arc is not read yet (G1 after it)",
            )
        p0, p1, p2 = prev.start, prev.end, end
        ua, la = _unit(p0, p1)
        ub, lb = _unit(p1, p2)
        if la == 0.0 or lb == 0.0:
            raise self.err(line, f"{word.letter} on line {prev.line}: a corner needs two moves")
        cross = ua[0] * ub[1] - ua[1] * ub[0]
        dot = ua[0] * ub[0] + ua[1] * ub[1]
        if abs(cross) < 1e-12:
            raise self.err(line, f"{word.letter} on line {prev.line}: the moves are in line")
        size = self.length(word.value)
        if word.letter == ",C":
            t = size
        else:
            phi = math.atan2(abs(cross), dot)  # the turn between the two moves
            t = size * math.tan(phi / 2)
        if t >= la - 1e-9 or t >= lb - 1e-9:
            raise self.err(
                line,
                f"{word.letter}{word.text} on line {prev.line} is larger than the moves it joins",
            )
        q1 = (p1[0] - t * ua[0], p1[1] - t * ua[1])
        q2 = (p1[0] + t * ub[0], p1[1] + t * ub[1])
        first = Motion(prev.kind, p0, q1, prev.line, None, prev.comp, prev.entry, prev.via)
        self.moves.append(first)
        self.events.append(first)
        if word.letter == ",C":
            corner = Motion("feed", q1, q2, prev.line, None, prev.comp, False, ",C")
        else:
            # the centre lies on the inner side of the turn (left for a left turn)
            s = 1.0 if cross > 0 else -1.0
            n = (-ua[1] * s, ua[0] * s)
            c = (q1[0] + size * n[0], q1[1] + size * n[1])
            corner = Motion(
                "ccw" if cross < 0 else "cw", q1, q2, prev.line, c, prev.comp, False, ",R"
            )
        self.moves.append(corner)
        self.events.append(corner)
        self.pos = q2

    def _arc_center(self, line, w, p0, p1, kind):
        has_ik = "I" in w or "K" in w
        if has_ik and "R" in w:
            raise self.err(line, "an arc takes R or I/K, not both")
        if not has_ik and "R" not in w:
            raise self.err(line, "an arc needs R or I/K")
        if "R" in w:
            return _center_from_r(self, line, p0, p1, self.length(w["R"].value), kind)
        i = self.length(w["I"].value) if "I" in w else 0.0
        k = self.length(w["K"].value) if "K" in w else 0.0
        if self.arc_absolute:
            c = (i, k)
        else:
            c = (p0[0] + i, p0[1] + k)
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

    def _stops(self, line, mcodes) -> None:
        code = mcodes.get("stop")
        if code in ("M0", "M1", "M60"):
            self.note(line.number, code, "program stop: reading goes on")


_PLANES = {"G17": "XY", "G18": "XZ", "G19": "YZ"}


def _unit(p, q):
    dx, dz = q[0] - p[0], q[1] - p[1]
    length = math.hypot(dx, dz)
    if length == 0.0:
        return (0.0, 0.0), 0.0
    return (dx / length, dz / length), length


def _hint(machine: ModalMachine, letter: str) -> str:
    if letter in ("Y", "J"):
        return " (a lathe program lives in the XZ plane)"
    if letter in ("U", "W") and machine.table.name == "linuxcnc":
        return " (U/W are axes in LinuxCNC; incremental X/Z words are Fanuc's: --dialect fanuc)"
    if letter in ("A", "B", "C"):
        return " (rotary axes are not read)"
    return ""


def _center_from_r(machine, line, p0, p1, r, kind):
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
        raise machine.err(line, "an R arc cannot start and end at the same point")
    ar = abs(r)
    if chord / 2 - ar > _RADIUS_TOL_MM:
        raise machine.err(line, f"arc radius {ar:.4f} mm is too small to reach the end point")
    h = math.sqrt(max(ar * ar - chord * chord / 4, 0.0))
    left_x, left_z = dz / chord, -dx / chord  # unit normal, left of travel (drawing frame)
    side = (1.0 if kind == "ccw" else -1.0) * (1.0 if r > 0 else -1.0)
    return ((x0 + x1) / 2 + side * h * left_x, (z0 + z1) / 2 + side * h * left_z)

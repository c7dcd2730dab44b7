"""The moves of a gauging program, read the way the control reads them.

:func:`read_gauge_program` (and :func:`gauge_moves`, its moves) interprets a LinuxCNC or
a Fanuc-style gauging program (the ones `gauging_program` writes, and hand-edited ones)
into a [`GaugeProgram`][] of :class:`GaugeMove` s: every rapid, feed move and probe move,
in **mm, X a radius, work coordinates**, with the modal state in effect on its line.
``controller=None`` reads a program as Fanuc when it has ``G31``, ``POPEN``, ``PCLOS``
or ``DPRNT``, else as LinuxCNC. LinuxCNC: ``G38.2`` / ``G38.3`` (modal), G7/G8,
``(PROBEOPEN name)``; Fanuc: ``G31`` (one shot), ``POPEN`` / ``DPRNT[...]`` / ``PCLOS``,
X as `x_mode` says, every coordinate with a decimal point. Refused, with the control's
words and the line (:class:`~piecs_bayes.errors.InputError`): a probe move in feed per
revolution, with compensation on, with zero feed or length, an unknown code or letter,
two codes of one modal group, axis words without a motion mode.

The dialects, word by word: docs/models/gauging.md, "Reading a gauging program".
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import InputError
from ._dprnt import DprntFormat, parse_dprnt
from ._lexer import SourceLine, lex_line, read_text_lossless

MM_PER_INCH = 25.4
PROBE_CODES = {"linuxcnc": ("G38.2", "G38.3"), "fanuc": ("G31",)}
_COMMON_G = {
    "motion": {"G0", "G1", "G2", "G3", "G80"},
    "plane": {"G18"},
    "units": {"G20", "G21"},
    "comp": {"G40", "G41", "G42"},
    "length": {"G43", "G49"},
    "coord": {"G54", "G55", "G56", "G57", "G58", "G59"},
    "path": {"G61", "G64"},
    "distance": {"G90", "G91"},
    "spindle_mode": {"G96", "G97"},
    "dwell": {"G4"},
}
_G_GROUPS = {
    "linuxcnc": {
        **_COMMON_G,
        "motion": _COMMON_G["motion"] | {"G38.2", "G38.3"},
        "comp": _COMMON_G["comp"] | {"G41.1", "G42.1"},
        "diameter": {"G7", "G8"},
        "feed_mode": {"G94", "G95"},
    },
    "fanuc": {**_COMMON_G, "skip": {"G31"}, "feed_mode": {"G98", "G99"}},
}
_PER_REV = {"linuxcnc": "G95", "fanuc": "G99"}
_M_LINUXCNC = {f"M{k}" for k in (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 30)}
_M_LINUXCNC |= {f"M{k}" for k in range(60, 69)} | {f"M{k}" for k in range(100, 200)}
_LETTERS = set("GMNXZIKRFSTDHPQL")
_COORD_LETTERS = set("XZIKR")
_OTHER = {
    "Y": "a gauging program moves in the XZ plane only (a lathe has no Y here)",
    "U": "incremental addresses U/W are not read; use G91",
    "W": "incremental addresses U/W are not read; use G91",
}
_FANUC_STATEMENT = re.compile(r"^\s*(?:N\d+\s*)?(POPEN|PCLOS|DPRNT\s*\[(.*)\])\s*(?:\(.*\))?\s*$",
                              re.IGNORECASE)  # fmt: skip
_POINT_LABEL = re.compile(r"^\s*(point\s*\d+|P\d+)\b", re.IGNORECASE)


@dataclass(frozen=True)
class GaugeMove:
    """One move of a gauging program (mm, X a radius, work frame).

    - `kind`: ``"rapid"`` (G0), ``"feed"`` (G1), ``"arc"`` (G2/G3: only its end
      point is kept) or ``"probe"``; `code` the G code (``"G38.2"``, ``"G31"``...).
    - `start`: the position before the move; `target`: its programmed end point.
    - `line`, `text`: the source line (1-based) and its text.
    - `units` (``"mm"``/``"in"``), `x_mode` (``"diameter"``/``"radius"``),
      `distance` (``"absolute"``/``"incremental"``), `feed` (mm/min, None when none
      was set), the modal state on the line.
    - `label`: the last comment before the move naming a planned point
      (``"point 3 dia_24 t=0.955 ..."``), or None.
    - `recording`: LinuxCNC: between PROBEOPEN and PROBECLOSE (its trip is written);
      Fanuc: between POPEN and PCLOS (its DPRNTs print).
    - `dprnt`: Fanuc: the DPRNT statements after this probe move (before the next).
    - `log`: LinuxCNC: the texts of the ``(LOG,...)`` comments after this probe move
      (before the next), between ``(LOGOPEN,name)`` and ``(LOGCLOSE)``.
    - `axes`: the axis letters the line programs (``"X"``, ``"Z"``, ``"XZ"``).
    """

    kind: str
    code: str
    start: tuple[float, float]
    target: tuple[float, float]
    line: int
    text: str
    units: str
    x_mode: str
    distance: str
    feed: float | None
    label: str | None = None
    recording: bool = False
    dprnt: tuple[DprntFormat, ...] = ()
    axes: str = ""
    log: tuple[str, ...] = ()

    @property
    def length(self) -> float:
        return math.dist(self.start, self.target)


@dataclass(frozen=True)
class GaugeProgram:
    """A gauging program read: its moves, dialect, X mode setting (Fanuc), the
    PROBEOPEN file name (LinuxCNC, None when none) and the file name (or None)."""

    moves: tuple[GaugeMove, ...]
    controller: str
    x_mode: str
    probe_file: str | None
    name: str | None
    log_file: str | None = None

    @property
    def probe_moves(self) -> tuple[GaugeMove, ...]:
        return tuple(m for m in self.moves if m.kind == "probe")


def _source(text_or_path) -> tuple[str, str | None]:
    if isinstance(text_or_path, Path) or (
        isinstance(text_or_path, str) and "\n" not in text_or_path and "\r" not in text_or_path
    ):
        path = Path(text_or_path)
        if path.is_dir():
            raise InputError("is a folder, not a gauging program", file=str(path))
        if not path.exists():
            raise InputError("gauging program not found", file=str(path))
        return read_text_lossless(path), str(path)
    return str(text_or_path), None


def _detect(text: str) -> str:
    up = text.upper()
    if re.search(r"\bG0*31(?![.\d])", up) or re.search(r"\b(POPEN|PCLOS|DPRNT)\b", up):
        return "fanuc"
    return "linuxcnc"


class _State:
    def __init__(self, controller, x_mode, start):
        self.controller = controller
        self.x_mode = x_mode
        self.units = "mm"
        self.distance = "absolute"
        self.per_rev = False
        self.comp: str | None = None
        self.motion: str | None = None
        self.feed: float | None = None
        self.pos = (float(start[0]), float(start[1]))
        self.label: str | None = None
        self.recording = False
        self.probe_file: str | None = None
        self.log_file: str | None = None
        self.logging = False


def read_gauge_program(
    text_or_path, *, controller: str | None = None, x_mode: str | None = None, start=(0.0, 0.0)
) -> GaugeProgram:
    """The program's moves (module docstring).

    **Arguments:**

    - `text_or_path`: the program text (a string with a line break) or its path.
    - `controller`: ``"linuxcnc"`` or ``"fanuc"``; None: detected.
    - `x_mode`: Fanuc: ``"diameter"`` (default) or ``"radius"``, the control's
      setting; LinuxCNC: the mode before any G7/G8 (default ``"radius"``, G8).
    - `start`: the position before the first move (mm, radius X; rs274 starts at 0).
    """
    text, name = _source(text_or_path)
    ctrl = controller or _detect(text)
    if ctrl not in PROBE_CODES:
        raise InputError(f"controller: got {ctrl!r}, expected 'linuxcnc' or 'fanuc'")
    mode = x_mode or ("diameter" if ctrl == "fanuc" else "radius")
    if mode not in ("diameter", "radius"):
        raise InputError(f"x_mode: got {mode!r}, expected 'diameter' or 'radius'")
    st = _State(ctrl, mode, start)
    moves: list[GaugeMove] = []
    number = 0
    for raw in re.split(r"\r\n|\n|\r", text):
        number += 1
        if ctrl == "fanuc" and _fanuc_statement(raw, number, name, st, moves):
            continue
        src = lex_line(raw, "", number, name)
        if src.percent or src.is_blank:
            continue
        if ctrl == "linuxcnc":
            _log_comments(src, st, moves, name)
        move = _block(src, st, name)
        if move is not None:
            moves.append(move)
    return GaugeProgram(tuple(moves), ctrl, mode, st.probe_file, name, st.log_file)


def gauge_moves(text_or_path, **kwargs) -> tuple[GaugeMove, ...]:
    """The moves of a gauging program (`read_gauge_program`'s `moves`)."""
    return read_gauge_program(text_or_path, **kwargs).moves


def _err(msg: str, name, line: int, text: str) -> InputError:
    return InputError(f"{msg}: {text.strip()!r}", file=name or "<program>", line=line)


def _fanuc_statement(raw: str, number: int, name, st: _State, moves: list) -> bool:
    m = _FANUC_STATEMENT.match(raw)
    if m is None:
        if re.search(r"\b(POPEN|PCLOS|DPRNT)", raw, re.IGNORECASE):
            raise _err("a POPEN, PCLOS or DPRNT statement must stand alone on its line",
                       name, number, raw)  # fmt: skip
        return False
    word = m.group(1).upper()
    if word == "POPEN":
        st.recording = True
    elif word == "PCLOS":
        st.recording = False
    else:
        fmt = parse_dprnt(m.group(2), line=number, text=raw, name=name)
        if not st.recording:
            raise _err("DPRNT outside POPEN ... PCLOS: nothing would be printed", name,
                       number, raw)  # fmt: skip
        last = next((k for k in range(len(moves) - 1, -1, -1) if moves[k].kind == "probe"), None)
        if last is None:
            raise _err("DPRNT before any G31: #5061/#5062 hold no skip position", name,
                       number, raw)  # fmt: skip
        old = moves[last]
        moves[last] = replace(old, dprnt=(*old.dprnt, fmt))
    return True


def _log_comments(src: SourceLine, st: _State, moves: list, name) -> None:
    """LinuxCNC's ``(LOGOPEN,name)``, ``(LOG,text)`` and ``(LOGCLOSE)``: a LOG text
    belongs to the last probe move before it (its parameters are that trip's)."""
    for c in src.comments:
        if c.kind != "paren":
            continue
        body = c.text.strip()
        up = body.upper()
        if up.startswith("LOGOPEN,"):
            if st.log_file is not None:
                raise _err("a second LOGOPEN: the simulated machine writes one log file", name,
                           src.number, src.text)  # fmt: skip
            st.log_file, st.logging = body[len("LOGOPEN,") :].strip(), True
        elif up.startswith("LOGCLOSE"):
            st.logging = False
        elif up.startswith("LOG,"):
            if not st.logging:
                raise _err("LOG outside LOGOPEN ... LOGCLOSE: nothing would be written", name,
                           src.number, src.text)  # fmt: skip
            last = next((k for k in range(len(moves) - 1, -1, -1) if moves[k].kind == "probe"),
                        None)  # fmt: skip
            if last is None:
                raise _err("LOG before any probe move: #5061-#5070 hold no trip", name,
                           src.number, src.text)  # fmt: skip
            moves[last] = replace(moves[last], log=(*moves[last].log, body[len("LOG,") :]))


def _comments(src: SourceLine, st: _State, name) -> None:
    for c in src.comments:
        body = c.text.strip()
        if _POINT_LABEL.match(body):
            st.label = body
        if c.kind != "paren" or st.controller != "linuxcnc":
            continue
        up = body.upper()
        if up.startswith("PROBEOPEN"):
            fname = body[len("PROBEOPEN") :].strip()
            if not fname:
                raise _err("PROBEOPEN needs a file name", name, src.number, src.text)
            if st.probe_file is not None and fname != st.probe_file:
                raise _err(f"a second PROBEOPEN ({st.probe_file!r} is already named): the "
                           "simulated machine writes one probe file", name, src.number,
                           src.text)  # fmt: skip
            st.probe_file, st.recording = fname, True
        elif up.startswith("PROBECLOSE"):
            st.recording = False


def _codes(src: SourceLine, st: _State, name) -> tuple[dict, set]:
    groups = _G_GROUPS[st.controller]
    of = {code: g for g, codes in groups.items() for code in codes}
    g_by_group: dict[str, str] = {}
    ms: set[str] = set()
    fanuc = st.controller == "fanuc"
    for k, w in enumerate(src.words):
        if w.letter == "G":
            code = w.code
            if code not in of:
                msg = ("PS0010 IMPROPER G-CODE" if fanuc else "Unknown g code used") + (
                    f": {code} is not a code of a {st.controller} gauging program"
                )
                raise _err(msg, name, src.number, src.text)
            grp = of[code]
            if grp in g_by_group:
                raise _err(f"Two g codes used from same modal group ({g_by_group[grp]} and "
                           f"{code})", name, src.number, src.text)  # fmt: skip
            g_by_group[grp] = code
        elif w.letter == "M":
            if not fanuc and w.code not in _M_LINUXCNC:
                raise _err(f"Unknown m code used: {w.code}", name, src.number, src.text)
            ms.add(w.code)
        elif w.letter == "O":
            if not fanuc or k != 0:
                what = (
                    "O-words (subroutines, loops) are not read"
                    if not fanuc
                    else ("the program number O must be the first word of its line")
                )
                raise _err(what, name, src.number, src.text)
        elif w.letter not in _LETTERS:
            why = _OTHER.get(w.letter, "not a word of a gauging program")
            raise _err(f"Unknown word starting with {w.letter}: {why}", name, src.number,
                       src.text)  # fmt: skip
        if fanuc and w.letter in _COORD_LETTERS and "." not in w.text:
            raise _err(f"{w}: an address without a decimal point is read by Fanuc controls "
                       f"in least input increments (0.001 mm) unless parameter DPI is set; "
                       f"write {w.letter}{w.text}.", name, src.number, src.text)  # fmt: skip
    for letter in "XZFRIK":
        if len(src.find(letter)) > 1:
            raise _err(f"Multiple {letter} words on one line", name, src.number, src.text)
    return g_by_group, ms


def _modal(g: dict, src: SourceLine, st: _State) -> None:
    if "diameter" in g:
        st.x_mode = "diameter" if g["diameter"] == "G7" else "radius"
    if "units" in g:
        st.units = "in" if g["units"] == "G20" else "mm"
    if "distance" in g:
        st.distance = "incremental" if g["distance"] == "G91" else "absolute"
    if "feed_mode" in g:
        st.per_rev = g["feed_mode"] == _PER_REV[st.controller]
    f = src.word("F")
    if f is not None:
        st.feed = f.value * (MM_PER_INCH if st.units == "in" else 1.0)
    if "comp" in g:
        st.comp = None if g["comp"] == "G40" else g["comp"]
    if "motion" in g:
        st.motion = None if g["motion"] == "G80" else g["motion"]


def _target(src: SourceLine, st: _State) -> tuple[float, float]:
    k = MM_PER_INCH if st.units == "in" else 1.0
    x, z = st.pos
    wx, wz = src.word("X"), src.word("Z")
    if wx is not None:
        v = wx.value * k / (2.0 if st.x_mode == "diameter" else 1.0)
        x = x + v if st.distance == "incremental" else v
    if wz is not None:
        v = wz.value * k
        z = z + v if st.distance == "incremental" else v
    return (x, z)


def _block(src: SourceLine, st: _State, name) -> GaugeMove | None:
    if src.computed or src.assignments or src.oword or src.macro or src.block_delete:
        raise _err("a gauging program is read block by block: parameters, expressions, "
                   "O-words, macro statements and block delete are not read here", name,
                   src.number, src.text)  # fmt: skip
    _comments(src, st, name)
    g, _ms = _codes(src, st, name)
    _modal(g, src, st)
    axes = src.word("X") is not None or src.word("Z") is not None
    if "dwell" in g:
        return None
    code = g.get("skip") or st.motion
    explicit = "skip" in g or "motion" in g
    if code is None:
        if axes:
            raise _err("Cannot use axis values without a g code that uses them", name,
                       src.number, src.text)  # fmt: skip
        return None
    if not axes and not explicit:
        return None
    probes = PROBE_CODES[st.controller]
    target = _target(src, st)
    if code in probes:
        _check_probe(code, target, src, st, name)
    elif not axes:
        return None
    kind = "probe" if code in probes else {"G0": "rapid", "G1": "feed"}.get(code, "arc")
    move = GaugeMove(
        kind=kind, code=code, start=st.pos, target=target, line=src.number, text=src.text,
        units=st.units, x_mode=st.x_mode, distance=st.distance, feed=st.feed,
        label=st.label if kind == "probe" else None, recording=st.recording,
        axes="".join(a for a in "XZ" if src.word(a) is not None),
    )  # fmt: skip
    st.pos = target
    if kind == "probe":
        st.label = None
    return move


def _check_probe(code, target, src: SourceLine, st: _State, name) -> None:
    fanuc = st.controller == "fanuc"
    if st.comp is not None:
        msg = (
            (
                f"PS0035 CAN NOT COMMANDED G31 (tool nose radius compensation {st.comp} is "
                "on; cancel it with G40)"
            )
            if fanuc
            else (
                f"Cannot probe with cutter radius compensation on ({st.comp}; cancel it with G40)"
            )
        )
        raise _err(msg, name, src.number, src.text)
    if st.per_rev:
        msg = (
            (
                "G31 in feed per revolution (G99): with the spindle stopped the skip would "
                "never move; probe in G98"
            )
            if fanuc
            else ("Cannot probe with feed per rev mode (G95; probe in G94)")
        )
        raise _err(msg, name, src.number, src.text)
    if not st.feed:
        msg = (
            "PS0011 FEED ZERO (COMMAND): G31 needs an F word"
            if fanuc
            else ("Cannot probe with zero feed rate")
        )
        raise _err(msg, name, src.number, src.text)
    dist = math.dist(st.pos, target)
    least = 0.0 if fanuc else (0.254 if st.units == "mm" else 0.01 * MM_PER_INCH)
    if dist <= least:
        msg = (
            (
                f"G31 block without motion: the target is the start "
                f"(X {target[0]:g}, Z {target[1]:g} mm, radius)"
            )
            if fanuc
            else (
                f"Start point too close to probe point ({dist:.4g} mm; at least "
                f"{'0.254 mm' if st.units == 'mm' else '0.01 in'})"
            )
        )
        raise _err(msg, name, src.number, src.text)

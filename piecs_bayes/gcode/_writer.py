"""Write a program whose motion is replaced by a given path (nose compensation resolved).

Every line whose moves are unchanged stays byte-identical. A rewritten block
loses its compensation words (G40/G41/G42/G41.1/G42.1 and their D/L words)
and its motion words (G0-G3, X, Z, I, K, R); the first new move takes their
place in the line, so the block keeps its N number, F/S/T/M words and
comments; further moves of the same block follow on lines of their own.
Coordinates are written in the block's own modes: units (G20/G21), X as
diameter (G7) or radius (G8), absolute or incremental (G90/G91) and arc
centres absolute or incremental (G90.1/G91.1), with 6 decimals in mm and 7 in
inches (well below the 1e-4 mm that rs274 prints).
"""

from __future__ import annotations

import math
from collections import defaultdict

from ..errors import InputError
from ._contour import CYCLE_CODES
from ._lexer import edit_line

_COMP_CODES = {"G40", "G41", "G42", "G41.1", "G42.1"}
_MOTION_CODES = {"G0", "G1", "G2", "G3"}
_AXIS_WORDS = {"X", "Z", "I", "K", "R", "U", "W", ",C", ",R"}
_GCODE = {"rapid": "G0", "feed": "G1", "cw": "G2", "ccw": "G3"}
_KEPT = {"N", "F", "S", "T", "M", "G"}  # what a cycle block keeps written out as moves


def _fmt(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}".rstrip("0")
    if text.endswith("."):
        text += "0"
    if float(text) == 0.0:
        text = "0.0"
    return text


def move_words(move, prev_end, state) -> list[str]:
    """Word texts (``["G1", "X20.0", "Z-5.0"]``) for ``move`` in the modes of ``state``.

    ``prev_end`` is the controlled point before the move (for incremental
    coordinates and incremental arc centres).
    """
    scale = 1 / 25.4 if state.units == "in" else 1.0
    dec = 7 if state.units == "in" else 6
    xs = (2.0 if state.diameter else 1.0) * scale
    (x, z), (px, pz) = move.end, prev_end
    if state.absolute:
        wx, wz = x * xs, z * scale
    else:
        wx, wz = (x - px) * xs, (z - pz) * scale
    words = [_GCODE[move.kind], f"X{_fmt(wx, dec)}", f"Z{_fmt(wz, dec)}"]
    if move.kind in ("cw", "ccw"):
        cx, cz = move.center
        if not state.arc_absolute:
            cx, cz = cx - px, cz - pz
        words += [f"I{_fmt(cx * scale, dec)}", f"K{_fmt(cz * scale, dec)}"]
    return words


def _same(a, b, check_start: bool, omitted=()) -> bool:
    """Do the emitted moves ``a`` equal the programmed ``b``, as the unchanged line
    would run from where the emitted path really is?"""
    if len(a) != len(b):
        return False
    for m, n in zip(a, b, strict=True):
        # an omitted axis word repeats the current position: the emitted one
        for axis in omitted:
            if abs(m.start[axis] - n.start[axis]) > 1e-9:
                return False
        if m.kind != n.kind or math.dist(m.end, n.end) > 1e-9:
            return False
        if (m.center is None) != (n.center is None):
            return False
        if m.center is not None and math.dist(m.center, n.center) > 1e-9:
            return False
        if check_start and math.dist(m.start, n.start) > 1e-9:
            return False
    return True


def _cycle_line(line) -> bool:
    return any(w.letter == "G" and w.code in CYCLE_CODES for w in line.words)


def write_path_program(program, path) -> tuple[str, tuple[int, ...]]:
    """Text of ``program`` with its motion replaced by ``path`` (moves tagged with lines).

    **Returns:** ``(text, changed line numbers)``.
    """
    emitted = defaultdict(list)
    for m in path:
        emitted[m.line].append(m)
    programmed = defaultdict(list)
    for m in program.moves:
        programmed[m.line].append(m)
    out: list[str] = []
    changed: list[int] = []
    for line in program.lines:
        st = program.state(line.number)
        new, old = emitted.get(line.number, []), programmed.get(line.number, [])
        comp_codes = {
            k for k, w in enumerate(line.words) if w.letter == "G" and w.code in _COMP_CODES
        }
        comp_words = comp_codes | {
            k
            for k, w in enumerate(line.words)
            if comp_codes and w.letter in ("D", "L") and not _cycle_line(line)
        }
        arcs = any(m.kind in ("cw", "ccw") for m in old)
        omitted = [k for k, letter in enumerate("XZ") if line.word(letter) is None]
        same = _same(new, old, not st.absolute or (arcs and not st.arc_absolute), omitted)
        if same and not comp_words:
            out.append(line.text + line.eol)
            continue
        why = program.edit_refusal(line.number) if hasattr(program, "edit_refusal") else None
        if why is not None:
            raise InputError(
                f"this line cannot be rewritten in place: {why}",
                file=program.name or "<program>",
                line=line.number,
            )
        changed.append(line.number)
        remove = set(comp_words)
        inserted: list[list[str]] = []
        if not same:
            motion = {
                k
                for k, w in enumerate(line.words)
                if (w.letter == "G" and w.code in _MOTION_CODES) or w.letter in _AXIS_WORDS
            }
            if _cycle_line(line):
                # a canned cycle written out as its moves: the cycle and its words go
                motion |= {
                    k
                    for k, w in enumerate(line.words)
                    if (w.letter == "G" and w.code in CYCLE_CODES) or w.letter not in _KEPT
                }
            if not new:  # keep the motion mode, drop the axes
                motion = {k for k in motion if line.words[k].letter != "G"}
            remove |= motion
            inserted = [move_words(m, m.start, st) for m in new]
            restore = st.motion is not None and not _cycle_line(line)
            if new and _GCODE[new[-1].kind] != st.motion and restore:
                inserted.append([st.motion])
        anchor = -1
        if inserted:
            first = min(k for k in remove if k not in comp_words) if remove - comp_words else None
            anchor = (first if first is not None else len(line.words)) - 1
            while anchor in remove:
                anchor -= 1
        if line.words and all(
            c.islower() for w in line.words for c in line.text[w.start : w.num_start] if c.isalpha()
        ):
            inserted = [[w.lower() for w in words] for words in inserted]
        text = edit_line(line, remove=remove, insert={anchor: inserted[0]} if inserted else None)
        rows = [text] + [" ".join(words) for words in inserted[1:]]
        if not text.strip() and not inserted:
            continue  # a line that only switched compensation: nothing is left of it
        eol = line.eol or "\n"
        out.append(eol.join(rows) + line.eol)
    return "".join(out), tuple(changed)

"""The words of a canned-cycle block, per dialect, as the cycle's parameters.

[`linuxcnc_cycle`][] reads LinuxCNC's ``G70``/``G71``/``G72`` (and ``.1``/``.2``) words,
[`fanuc_cycle`][] Fanuc's and Haas's ``G70``/``G71``/``G72``/``G73`` (the one-block and
the two-block forms), into a [`FinishCycle`][], [`RoughCycle`][] or [`PatternRepeat`][]
in mm, radius X, with each dialect's defaults. [`non_contour_cycle`][] names the codes
that are cycles or threads but never a contour (G32, G33, G74, G75, G76, ...), for a
reader to refuse them as one. The mapping, word by word: docs/models/part_programs.md,
"Canned cycles".
"""

from __future__ import annotations

from collections.abc import Mapping

from ..errors import InputError
from ._cycles import FinishCycle, RoughCycle
from ._pattern_repeat import PatternRepeat

_PASS_THROUGH = set("GNFSTMO")
_LINUXCNC_WORDS = {"G70": set("QXZDEP"), "G71": set("QXZDIR"), "G72": set("QXZDIR")}
_THREAD = "a thread: a helix synchronised with the spindle, not a contour of lines and arcs"
_NOT_CONTOURS = {
    "fanuc": {
        "G32": f"thread cutting, {_THREAD}",
        "G33": f"thread cutting (G-code systems B/C), {_THREAD}",
        "G34": f"variable-lead thread cutting, {_THREAD}",
        "G74": "the face grooving / peck drilling cycle (along Z), not a contour",
        "G75": "the grooving cycle (along X), not a contour",
        "G76": f"the multiple threading cycle, {_THREAD}",
        "G92": f"the thread cutting cycle, {_THREAD}",
    },
    "linuxcnc": {
        "G33": f"spindle-synchronised motion, {_THREAD}",
        "G33.1": "rigid tapping, not a contour",
        "G76": f"the threading cycle, {_THREAD}",
        "G73": "the chip-breaking drilling cycle (LinuxCNC's G73), not a contour",
        "G74": "the left-hand tapping cycle, not a contour",
        **{f"G{n}": "a drilling cycle, not a contour" for n in range(81, 90)},
    },
}
_NOT_CONTOURS["haas"] = _NOT_CONTOURS["fanuc"]


def non_contour_cycle(code: str, dialect: str = "fanuc") -> str | None:
    """Why `code` (``"G76"``) is never a contour in `dialect` (``"fanuc"``, ``"haas"``
    or ``"linuxcnc"``): a sentence naming it, or None when it is not such a code."""
    table = _NOT_CONTOURS.get(dialect)
    if table is None:
        raise InputError(f"unknown dialect {dialect!r}, expected one of {sorted(_NOT_CONTOURS)}")
    reason = table.get(code.upper())
    return None if reason is None else f"{code.upper()}: {reason}"


def _check_letters(code: str, words: Mapping[str, float], allowed: set, line: int):
    for letter in words:
        if letter.upper() not in allowed | _PASS_THROUGH:
            raise InputError(
                f"{code}: word {letter.upper()} is not understood here "
                f"(expected {' '.join(sorted(allowed))})",
                line=line,
            )


def _upper(words: Mapping[str, float]) -> dict[str, float]:
    return {k.upper(): float(v) for k, v in words.items()}


def linuxcnc_cycle(
    code: str,
    words: Mapping[str, float],
    *,
    line: int,
    diameter: bool = False,
    unit_mm: float = 1.0,
) -> FinishCycle | RoughCycle:
    """A LinuxCNC ``G70``/``G71``/``G72`` block as the cycle's parameters.

    **Arguments:**

    - `code`: ``"G70"``, ``"G71"``, ``"G71.1"``, ``"G71.2"``, ``"G72"``, ``"G72.1"``
      or ``"G72.2"``.
    - `words`: the block's words as written (letter -> number, absolute X/Z), in the
      program's units; ``Q`` (the subroutine) and G/N/F/S/T/M/O are the reader's and
      are passed over.
    - `line`: the block's source line.
    - `diameter`: G7 in force (X is a diameter; D, E, I, R are distances, as written).
    - `unit_mm`: the program's length unit in mm (25.4 under G20).

    LinuxCNC's defaults apply, in program units: D 0, E 0, P 1, I 1, R 0.5. U and W
    are refused: rs274 (2.9) has no U/W axes and refuses them on the cycle block.
    """
    base = code.upper().split(".")[0]
    if base not in _LINUXCNC_WORDS or code.upper() == "G70.1":
        raise InputError(f"{code} is not a LinuxCNC G70/G71/G72 cycle", line=line)
    w = _upper(words)
    _check_letters(code, w, _LINUXCNC_WORDS[base], line)
    if "Q" not in w:
        raise InputError(f"{code} needs a Q word (the contour's O-sub)", line=line)
    x = None if "X" not in w else w["X"] * unit_mm / (2.0 if diameter else 1.0)
    z = None if "Z" not in w else w["Z"] * unit_mm
    d = w.get("D", 0.0) * unit_mm
    if base == "G70":
        return FinishCycle(line, x, z, d, w.get("E", 0.0) * unit_mm, w.get("P", 1.0))
    return RoughCycle(
        code.upper(), line, x, z, d, w.get("I", 1.0) * unit_mm, w.get("R", 0.5) * unit_mm
    )


def fanuc_cycle(
    code: str,
    words: Mapping[str, float],
    *,
    line: int,
    setup: Mapping[str, float] | None = None,
    p_block: Mapping[str, float] | None = None,
    diameter: bool = True,
    unit_mm: float = 1.0,
    retract: float | None = None,
) -> FinishCycle | RoughCycle | PatternRepeat:
    """A Fanuc (G-code system A) or Haas cycle block, the one with ``P``/``Q``, as the
    cycle's parameters. The cycle starts at the tool position and returns there.

    **Arguments:**

    - `code`: ``"G70"``, ``"G71"``, ``"G72"`` or ``"G73"``.
    - `words`: the block's words as written (letter -> number; ``D`` with its decimal
      point, the control's rule for numbers without one is the reader's), program units.
    - `line`: the block's source line.
    - `setup`: the words of the first block of the two-block form (``G71 U R``,
      ``G72 W R``, ``G73 U W R``) in force; None for the one-block form (``D``: the
      depth of cut, Haas ``I K D`` for G73).
    - `p_block`: the words of the contour's first block: G71/G72 are type II (pockets
      cut: ``G71``/``G72``) when it moves both X (X/U) and Z (Z/W), or when the cycle
      block has Haas's ``R1``; else type I (``G71.1``/``G72.1``).
    - `diameter`: X and U are diameters (Fanuc's default).
    - `unit_mm`: the program's length unit in mm.
    - `retract`: the retract of the one-block G71/G72 form, which the control keeps
      in a setting (Fanuc parameter 5133, Haas setting 73), in program units.

    Haas's G71/G72 rough-pass allowances ``I``/``K`` are refused (not expanded yet).
    """
    c = code.upper()
    w = _upper(words)
    s = _upper(setup) if setup is not None else None
    xs = 0.5 if diameter else 1.0
    if c == "G70":
        _check_letters(c, w, set("PQ"), line)
        return FinishCycle(line, return_to_start=True)
    if c not in ("G71", "G72", "G73"):
        raise InputError(f"{code} is not a Fanuc G70/G71/G72/G73 cycle", line=line)
    if "P" not in w or "Q" not in w:
        raise InputError(f"{c} needs P and Q (the contour's first and last blocks)", line=line)
    shift = (w.get("U", 0.0) * xs * unit_mm, w.get("W", 0.0) * unit_mm)
    if c == "G73":
        return _pattern_repeat(w, s, line, xs, unit_mm, shift)
    if "I" in w or "K" in w:
        raise InputError(
            f"{c}: Haas's rough-pass allowances I/K are not expanded (leave them out, "
            "or give the finishing allowances U/W)",
            line=line,
        )
    _check_letters(c, w, set("PQUWDR"), line)
    if "D" in w and s is not None:
        raise InputError(
            f"{c}: D (one-block form) and a {c} setup block both give the depth", line=line
        )
    if "D" in w:
        depth = w["D"]
        if retract is None:
            raise InputError(
                f"{c}: the one-block form takes its retract from a control setting "
                "(Fanuc parameter 5133, Haas setting 73): give it",
                line=line,
            )
        lift = retract
    elif s is not None:
        key = "U" if c == "G71" else "W"
        _check_letters(f"{c} setup", s, {key, "R"}, line)
        if key not in s or "R" not in s:
            raise InputError(f"{c}: the setup block needs {key} (depth) and R (retract)", line=line)
        depth, lift = s[key], s["R"]
    else:
        raise InputError(
            f"{c} P.. Q.. without its depth of cut: no D and no "
            f"{c} {'U' if c == 'G71' else 'W'}.. R.. block before it",
            line=line,
        )
    r = w.get("R")
    if r is not None and r not in (0.0, 1.0):
        raise InputError(f"{c}: R on the P/Q block selects Haas's type (R1), got R{r:g}", line=line)
    pb = _upper(p_block or {})
    type2 = r == 1.0 or (("X" in pb or "U" in pb) and ("Z" in pb or "W" in pb))
    return RoughCycle(
        c if type2 else f"{c}.1",
        line,
        depth=depth * unit_mm,
        retract=lift * unit_mm,
        shift=shift,
        return_to_start=True,
    )


def _pattern_repeat(w, s, line, xs, unit_mm, shift) -> PatternRepeat:
    if s is not None:
        if any(k in w for k in "IKD"):
            raise InputError(
                "G73: I/K/D (Haas one-block form) and a G73 U W R block both give the relief",
                line=line,
            )
        _check_letters("G73 setup", s, set("UWR"), line)
        _check_letters("G73", w, set("PQUW"), line)
        relief = (s.get("U", 0.0) * unit_mm, s.get("W", 0.0) * unit_mm)  # U: a radius
        passes = s.get("R")
    else:
        _check_letters("G73", w, set("PQUWIKD"), line)
        relief = (w.get("I", 0.0) * unit_mm, w.get("K", 0.0) * unit_mm)  # I: a radius
        passes = w.get("D")
    if passes is None:
        raise InputError("G73 needs the number of passes (R on its first block, Haas D)", line=line)
    return PatternRepeat(line, relief, int(passes) if passes == int(passes) else passes, shift)

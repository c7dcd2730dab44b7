"""Running the lathe canned cycles G70-G73 where a program calls them.

[`run_cycle`][] is the interpreter's step for a cycle block. Fanuc and Haas: the
two-block form's first block is remembered; ``G71``/``G72``/``G73 P Q`` run their
``P``..``Q`` blocks on a copy of the machine to read the contour, make the roughing
moves (``expand_cycle``, ``expand_pattern_repeat``) and go on after the ``Q`` block
when the contour follows the cycle block; ``G70 P Q`` runs the blocks themselves (their
G41/G42, feeds and corners, as the control does) and returns to the start point.
LinuxCNC: ``G70``/``G71``/``G72 Q`` read the O-sub's blocks from the cycle's start
point (``A``/``C`` corners included, with the G41/G42 in force at the cycle) and make
LinuxCNC's moves. Each cycle's contour is kept as a :class:`CycleContour`;
[`finish_cycles`][] marks the ones that are the part's profile (a G70, or a roughing
cycle whose blocks no G70 cuts). The words of each dialect: ``_cycle_words``.
"""

from __future__ import annotations

import math
from dataclasses import replace

from ..errors import InputError
from ._cycle_words import fanuc_cycle, linuxcnc_cycle
from ._cycles import ContourMove, FinishCycle, expand_cycle
from ._modal import Block
from ._pattern_repeat import PatternRepeat, expand_pattern_repeat
from ._program import CycleContour, Motion
from ._thread_cycle import expand_g76

_PASS = set("NFSTMO")
#: the retract of the one-block G71/G72 (a control setting, not in the program), mm
DEFAULT_RETRACT_MM = 0.5


def run_cycle(interp, pc: int, line, block) -> int:
    """Run the cycle block ``line`` (index ``pc``); the index of the next line."""
    cycles = interp.table.cycles
    found = [w for w in block.words if w.letter == "G" and w.code in cycles]
    code = found[0].code
    if len(found) > 1:
        raise interp.err(line, f"{found[0].code} and {found[1].code}: two cycles in one block")
    if interp.in_cycle is not None:
        raise interp.err(line, f"{code} inside the contour of the cycle on line {interp.in_cycle}")
    words: dict[str, float] = {}
    rest = []
    for w in block.words:
        if w is found[0]:
            continue
        if w.letter == "G" or w.letter in _PASS:
            rest.append(w)
            continue
        if w.letter in words:
            raise interp.err(line, f"{code}: word {w.letter} appears twice")
        words[w.letter] = w.value
    machine = interp.machine
    if any(w.letter != "N" for w in rest):
        machine.execute(Block(line, tuple(rest)))  # its F, S, T, M and modal G codes
    try:
        if interp.linuxcnc:
            return _linuxcnc(interp, pc, line, code, words)
        return _fanuc(interp, pc, line, code, words)
    except InputError as exc:
        if exc.file is not None:
            raise
        raise interp.err(line, exc.reason) from None


def _unit(machine) -> float:
    return 25.4 if machine.units == "in" else 1.0


def _check_position(interp, line, code) -> None:
    if any(math.isnan(v) for v in interp.machine.pos):
        raise interp.err(
            line,
            f"{code} starts where the tool is, and that is not known here (after a reference "
            "return or a machine-coordinate move: program X and Z absolutely before it)",
        )


def _emit(interp, line, moves, via: str) -> None:
    for m in moves:
        interp.machine.emit_cycle_move(line, m, via)


# -- Fanuc and Haas ---------------------------------------------------------------------


def _fanuc(interp, pc, line, code, words) -> int:
    n = f"{code} P{_num(words['P'])}" if "P" in words else code
    if "P" not in words:
        if code == "G70" or "Q" in words:
            raise interp.err(line, f"{code} needs P and Q (the contour's first and last blocks)")
        interp.cycle_setup[code] = words  # the two-block form's first block
        interp.machine.note(line.number, code, "depth of cut and retract for the next "
                            f"{code} P.. Q.. block")  # fmt: skip
        return pc + 1
    if "Q" not in words:
        raise interp.err(line, f"{n} has no Q (the contour's last block)")
    depth = {"G71": "U", "G72": "W"}.get(code)
    if depth and "D" not in words and code not in interp.cycle_setup:
        raise interp.err(line, f"{code} P.. Q.. without its depth of cut: no D and no "
                         f"{code} {depth}.. R.. block before it")  # fmt: skip
    _check_position(interp, line, code)
    p, q = _label(interp, line, words["P"], "P"), _label(interp, line, words["Q"], "Q")
    ip = interp.find_label(line, p, pc, n)
    iq = interp.find_label(line, q, ip, f"{n} Q{q}")
    if iq < ip:
        raise interp.err(
            line,
            f"{n} Q{q}: the Q block N{q} (line {interp.lines[iq].number}) comes before the "
            f"P block N{p} (line {interp.lines[ip].number})",
        )
    _check_blocks(interp, line, ip, iq, f"{n} Q{q}")
    machine = interp.machine
    start = machine.pos
    blocks = tuple(interp.lines[i].number for i in range(ip, iq + 1))
    if code == "G70":
        first = len(machine.moves)
        interp.in_cycle = line.number
        try:
            interp.run_lines(ip, iq, count=True, what=n)
        finally:
            interp.in_cycle = None
        if machine.moves[first:] == []:
            raise interp.err(line, f"{n}: the blocks P..Q make no move")
        interp.finished.update(range(ip, iq + 1))
        machine.emit_cycle_move(line, _Rapid(machine.pos, start), "G70")
        return pc + 1
    contour, events, _ = _dry_run(interp, line, ip, iq, n)
    setup = interp.cycle_setup.pop(code, None)
    p_block = {w.letter: w.value for w in interp.block(interp.lines[ip]).words}
    retract = None
    if "D" in words and setup is None:
        retract = DEFAULT_RETRACT_MM / _unit(machine)
        why = f"the one-block form's retract is a control setting: {DEFAULT_RETRACT_MM} mm"
        machine.note(line.number, f"{code} D", f"{why} taken (it moves only the roughing)")
    cycle = fanuc_cycle(
        code,
        words,
        line=line.number,
        setup=setup,
        p_block=p_block,
        diameter=machine.diameter,
        unit_mm=_unit(machine),
        retract=retract,
    )
    if isinstance(cycle, PatternRepeat):
        moves = expand_pattern_repeat(cycle, contour, start)
    else:
        moves = expand_cycle(cycle, contour, start, unit_mm=_unit(machine))
    index = len(machine.moves)
    saved = machine.comp
    machine.comp = None  # the roughing passes are not compensated
    _emit(interp, line, moves, code)
    machine.comp = saved
    interp.cycles.append(
        CycleContour(code, line.number, tuple(contour), tuple(events), False, index, blocks)
    )
    between = interp.lines[pc + 1 : ip]
    if all(ln.is_blank or not (ln.words or ln.oword or ln.macro) for ln in between):
        return iq + 1  # the contour follows the cycle: the control goes on after Q
    return pc + 1


def _check_blocks(interp, line, first: int, last: int, what: str) -> None:
    """Refuse, on the cycle's line, contour blocks that run past the program's end or
    hold a call or another cycle (the end named first: the likelier mistake)."""
    found: dict[str, tuple[str, int]] = {}
    for i in range(first, last + 1):
        src = interp.lines[i]
        for w in src.words:
            if w.expr is not None or w.letter not in "GM":
                continue
            if w.code in ("M30", "M2"):
                found.setdefault("end", (w.code, src.number))
            elif w.code in interp.table.cycles or w.code in ("M99", "M98", "M97"):
                found.setdefault("other", (w.code, src.number))
    if "end" in found:
        code, number = found["end"]
        raise interp.err(
            line,
            f"{what}: the contour's blocks run past the program's end ({code} on line "
            f"{number}): is the Q block where it should be?",
        )
    if "other" in found:
        code, number = found["other"]
        raise interp.err(line, f"{what}: the contour's blocks hold {code} (line {number}): "
                         "is the Q block where it should be?")  # fmt: skip


def _label(interp, line, value: float, letter: str) -> int:
    if value != int(value) or value < 0:
        raise interp.err(line, f"{letter}{_num(value)} is not a sequence number")
    return int(value)


def _num(v: float) -> str:
    return f"{v:g}"


class _Rapid:
    """A rapid a cycle makes (the return to the start point)."""

    kind = "rapid"
    center = None

    def __init__(self, start, end):
        self.start, self.end = start, end


def _dry_run(interp, line, first: int, last: int, what: str):
    """The moves of lines ``first``..``last`` run on a copy of the machine (undone)."""
    machine = interp.machine
    snap = machine.snapshot()
    runs = list(interp.runs)
    interp.in_cycle = line.number
    try:
        interp.run_lines(first, last, count=False, what=what)
    finally:
        interp.in_cycle = None
        moves, events, corners = machine.restore(snap)
        interp.runs[:] = runs
    if not moves:
        raise interp.err(line, f"{what}: the contour's blocks make no move")
    return moves, events, corners


# -- LinuxCNC ---------------------------------------------------------------------------


def _linuxcnc(interp, pc, line, code, words) -> int:
    machine = interp.machine
    if code == "G76":
        if machine.comp is not None:
            raise interp.err(line, "Cannot use G76 threading cycle with cutter radius "
                             "compensation on")  # fmt: skip
        _check_position(interp, line, code)
        moves = expand_g76(words, machine.pos, line=line.number, diameter=machine.diameter,
                           unit_mm=_unit(machine), absolute=machine.absolute)  # fmt: skip
        _emit(interp, line, moves, code)  # a thread: via "G76", never a contour
        return pc + 1
    cycle = linuxcnc_cycle(
        code, words, line=line.number, diameter=machine.diameter, unit_mm=_unit(machine)
    )
    _check_position(interp, line, code)
    q = words["Q"]
    label = f"{int(q)}" if q == int(q) and q >= 0 else None
    subs = interp.structure.subs
    if label not in subs:
        raise interp.err(line, f"{code} Q{_num(q)}: no o{label or _num(q)} sub in this program "
                         "(the contour's subroutine)")  # fmt: skip
    start_index, end_index = subs[label]
    position = machine.pos
    start = (
        position[0] if cycle.x is None else cycle.x,
        position[1] if cycle.z is None else cycle.z,
    )
    machine_snap = machine.snapshot()
    runs = list(interp.runs)
    comp = machine.comp
    machine.pos, machine.comp, machine.contour_mode = start, None, True
    interp.in_cycle = line.number
    try:
        interp.run_call(start_index, pc, f"o{label}")
    finally:
        interp.in_cycle = None
        moves, _, corners = machine.restore(machine_snap)
    if code != "G70":
        interp.runs[:] = runs  # roughing: the contour's blocks do not count as cut
    if not moves:
        raise interp.err(line, f"{code} Q{label}: the contour's subroutine makes no move")
    contour = [
        ContourMove.from_motion(m, fillet=corners.get(k, (0.0, 0.0))[0],
                                chamfer=corners.get(k, (0.0, 0.0))[1])
        for k, m in enumerate(moves)
    ]  # fmt: skip
    unit = _unit(machine)
    index = len(machine.moves)
    moves = expand_cycle(cycle, contour, position, unit_mm=unit)
    lead = next((k for k, m in enumerate(moves) if m.contour_line is not None), len(moves))
    machine.comp = None  # LinuxCNC (since July 2024): the moves to the start point are not
    _emit(interp, line, moves[:lead], code)  # compensated; the contour's lead-in enters it
    machine.comp = comp
    _emit(interp, line, moves[lead:], code)
    profile = expand_cycle(FinishCycle(line.number, *start), contour, start, unit_mm=unit)
    along: list[Motion] = []
    for m in profile:
        if m.contour_line is None:
            continue
        corner = bool(along) and along[-1].line == m.contour_line  # an A/C corner's move
        via = "" if not corner else ",R" if m.is_arc else ",C"
        along.append(replace(machine_motion(line, m, comp), line=m.contour_line, via=via))
    if along:
        along[0] = replace(along[0], entry=comp is not None)
    blocks = tuple(interp.lines[i].number for i in range(start_index + 1, end_index))
    interp.cycles.append(CycleContour(code, line.number, tuple(along), (), False, index, blocks))
    if code == "G70":
        interp.finished.update(range(start_index + 1, end_index))
    return pc + 1


def machine_motion(line, move, comp) -> Motion:
    """A cycle's move as a Motion of line ``line`` with the compensation ``comp``."""
    return Motion(move.kind, move.start, move.end, line.number, move.center, comp, False)


# -- the end of the program ---------------------------------------------------------------


def finish_cycles(interp) -> None:
    """Mark the cycles whose contour is the part's profile: every G70 (LinuxCNC: its
    record; Fanuc: its blocks ran as they are) and each roughing cycle whose blocks no
    G70 cut, whose blocks then count as run once (the cycle's last pass cut them)."""
    index = {ln.number: i for i, ln in enumerate(interp.lines)}
    out = []
    for c in interp.cycles:
        rows = [index[n] for n in c.blocks]
        finish = c.code == "G70" or not any(i in interp.finished for i in rows)
        if finish and c.code != "G70":
            for i in rows:
                interp.runs[i] = max(interp.runs[i], 1)
        out.append(replace(c, finish=finish))
    interp.cycles = out

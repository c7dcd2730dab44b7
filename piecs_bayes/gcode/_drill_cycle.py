"""LinuxCNC's drilling cycles in the XY plane (G17), expanded into the moves it makes.

A lathe drills on its axis: ``G17`` then ``G81``/``G82``/``G83``/``G73``/``G85``/``G89``
with ``X0 Y0``, the depth Z and the clearance plane R, as LinuxCNC's own lathe macro
``drill.ngc`` does. These moves are never a contour (they carry ``via`` = the cycle's
code); they are read so that a program that drills can be read whole and checked against
``rs274``. [`drill_moves`][] follows LinuxCNC 2.9's ``convert_cycle_xy`` and its
``CYCLE_MACRO`` word for word: the rapid up to R when the tool starts below it, the
move over each hole at the clearance height, the repeats L (incremental X/Y steps in
G91), the retract to the old Z (G98) or to R (G99), the pecks of G83 (back to R, then
down to 0.010 in above the last depth) and G73 (back 0.010 in), the feed out of G85 and
G89. The arithmetic runs in the program's units, as the control's does, so that the
number of pecks is decided as the control decides it.
"""

from __future__ import annotations

from dataclasses import dataclass

#: LinuxCNC 2.9's G83_RAPID_DELTA: the peck clearance, 0.010 in (the INI setting
#: G83_PECK_CLEARANCE of later versions replaces it)
PECK_CLEARANCE_IN = 0.010


@dataclass(frozen=True)
class DrillMove:
    """One move of a drilling cycle: ``kind`` ``"rapid"`` or ``"feed"``; ``end`` (x, y,
    z) in program units, x a radius."""

    kind: str
    end: tuple[float, float, float]


@dataclass(frozen=True)
class DrillCall:
    """One block of a drilling cycle, its values resolved (program units, x a radius).

    ``target``: the hole's (x, y) in absolute mode, or the (x, y) increments of each
    repeat in incremental mode; ``r`` and ``z`` as the block gives them (absolute, or R
    from the initial level and Z from R in incremental mode); ``q`` the peck (G73/G83);
    ``repeats`` L; ``retract_r``: G99 (back to R) rather than G98 (the old Z)."""

    code: str
    target: tuple[float, float]
    r: float
    z: float
    absolute: bool
    q: float = 0.0
    repeats: int = 1
    retract_r: bool = False


def drill_moves(
    call: DrillCall, position: tuple[float, float, float], initial: float, *, metric: bool
) -> tuple[tuple[DrillMove, ...], float]:
    """The moves of one drilling block from ``position`` (x, y, z, program units).

    ``initial`` is the initial level (the Z where this run of cycles began: LinuxCNC's
    ``cycle_il``). Returns the moves and the retract height the tool ends at. Raises
    ValueError with the control's reason (R below Z, a peck Q <= 0).
    """
    x0, y0, z0 = position
    old_cc = initial
    if call.absolute:
        r, cc = call.r, call.z
        aa, bb = call.target
        da = db = 0.0
    else:
        r = call.r + old_cc
        cc = r + call.z
        aa, bb = x0, y0
        da, db = call.target
    if r < cc:
        raise ValueError(f"the R plane ({r:g}) is below the bottom Z ({cc:g})")
    if call.code in ("G73", "G83") and call.q <= 0.0:
        raise ValueError(f"{call.code} needs a peck Q greater than 0")
    moves: list[DrillMove] = []
    current = z0
    if old_cc < r:  # below the R plane: straight up to it first
        moves.append(DrillMove("rapid", (x0, y0, r)))
        old_cc = r
        current = old_cc
    clear = r if call.retract_r else old_cc
    delta = PECK_CLEARANCE_IN * (25.4 if metric else 1.0)

    def go(kind: str, z: float) -> None:
        moves.append(DrillMove(kind, (aa, bb, z)))

    for repeat in range(call.repeats, 0, -1):
        aa, bb = aa + da, bb + db
        if repeat == call.repeats and current > r:
            go("rapid", current)
            go("rapid", r)
        else:
            go("rapid", clear)
            if clear > r:
                go("rapid", r)
        if call.code in ("G83", "G73"):
            depth = r - call.q
            while depth > cc:
                go("feed", depth)
                if call.code == "G83":
                    go("rapid", r)
                go("rapid", depth + delta)
                depth = depth - call.q
        go("feed", cc)
        if call.code in ("G85", "G89"):
            go("feed", r if call.code == "G85" else clear)
        if call.code != "G89":
            go("rapid", clear)
    return tuple(moves), clear

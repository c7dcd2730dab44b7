"""LinuxCNC's G76 threading cycle expanded into the moves the control makes.

A thread is a helix synchronised with the spindle, never a contour: these moves are read
so that a program that threads can be read and checked against ``rs274`` whole, and they
carry ``via="G76"`` so that no finish contour, no compensation run and no adjusted block
is ever taken from them. [`expand_g76`][] follows LinuxCNC's rules (the drive line, the
depth of each pass from J, R and the pass count, the compound angle Q, the spring passes
H, the taper E with its entry/exit flags L), word by word as LinuxCNC documents them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from ..errors import InputError
from ._cycles import CycleMove

_LETTERS = set("PZXIJKRQHELNFSTMG")


def expand_g76(
    words: Mapping[str, float],
    position: tuple[float, float],
    *,
    line: int,
    diameter: bool,
    unit_mm: float,
    absolute: bool = True,
) -> tuple[CycleMove, ...]:
    """The moves of a LinuxCNC ``G76 P Z I J K [R Q H E L]`` block.

    **Arguments:**

    - `words`: the block's words (letter -> value, program units; X/Z the end point).
    - `position`: the tool position (mm, radius x): the drive line's start.
    - `line`: the block's line; `diameter`: G7 in force (I, J, K are then halved, as
      LinuxCNC halves them); `unit_mm`: the program's length unit in mm; `absolute`: G90.

    **Returns:** rapids and feeds in mm, radius x, ending with the rapid to the end point.
    Refused (the control's own errors): I = 0, J <= 0, K <= J, a pitch P missing or <= 0.
    """
    w = {k.upper(): float(v) for k, v in words.items()}
    for letter in w:
        if letter not in _LETTERS:
            raise InputError(f"G76: word {letter} is not understood here", line=line)
    for letter in "PIJK":
        if letter not in w:
            raise InputError(f"G76 needs {letter}", line=line)
    if w["I"] == 0:
        raise InputError("In G76, I must not be 0", line=line)
    if w["J"] <= 0:
        raise InputError("In G76, J must be greater than 0", line=line)
    if w["K"] <= w["J"]:
        raise InputError("In G76, K must be greater than J", line=line)
    if w["P"] <= 0:
        raise InputError("In G76, the pitch P must be greater than 0", line=line)
    u = unit_mm
    x0, z0 = position[0] / u, position[1] / u  # program units, radius
    end_x = x0 if "X" not in w else (w["X"] / (2 if diameter else 1)) + (0 if absolute else x0)
    end_z = z0 if "Z" not in w else w["Z"] + (0 if absolute else z0)
    half = 2.0 if diameter else 1.0
    i, j, k = w["I"] / half, w["J"] / half, w["K"] / half
    boring = i > 0
    full_dia = abs(i)
    start_depth = abs(i) + abs(j)
    increment = abs(j)
    height = abs(k)
    end_depth = abs(k) + abs(i)
    pitch = w["P"]
    angle = w.get("Q", 0.0)
    angle = 0.0 if angle == -1 else angle
    angle = math.radians(angle)
    if end_z > z0:
        angle = -angle
    spring = int(w.get("H", 0.0))
    degression = w.get("R", 1.0)
    degression = 1.0 if degression < 1.0 else degression
    taper = max(w.get("E", 0.0), 0.0)
    del pitch  # the pitch synchronises the spindle; it moves nothing here
    if end_z > z0:
        taper = -taper
    flags = max(int(w.get("L", 0.0)), 0)
    entry, leave = flags & 1, flags & 2
    target_z = end_z + abs(k) * math.tan(angle)

    moves: list[CycleMove] = []
    pos = (x0, z0)

    def add(kind, x, z):
        nonlocal pos
        moves.append(CycleMove(kind, (pos[0] * u, pos[1] * u), (x * u, z * u), line))
        pos = (x, z)

    def xs(depth):
        return x0 + depth if boring else x0 - depth

    def one_pass(depth):
        zoff = (depth - full_dia) * math.tan(angle)
        back = xs(depth) + (-end_depth if boring else end_depth)
        add("rapid", back, z0 - zoff)
        if taper and entry:
            add("feed", xs(depth) + (-height if boring else height), z0 - zoff)
            add("feed", xs(depth), z0 - zoff - taper)
        else:
            add("rapid", xs(depth), z0 - zoff)
        if taper and leave:
            add("feed", xs(depth), target_z - zoff + taper)
            add("feed", xs(depth) + (-height if boring else height), target_z - zoff)
        else:
            add("feed", xs(depth), target_z - zoff)
        add("rapid", back, target_z - zoff)

    depth, count = start_depth, 1
    while depth < end_depth:
        one_pass(depth)
        count += 1
        depth = full_dia + increment * count ** (1.0 / degression)
    for _ in range(spring + 1):
        one_pass(end_depth)
    add("rapid", end_x, end_z)
    return tuple(moves)

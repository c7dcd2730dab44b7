"""Blocks that carry a corner in the adjusted program: Fanuc ``,C``/``,R`` and LinuxCNC's
``C``/``A`` in a G7x contour.

Such a block programs the **vertex** where its line meets the next block's; the control
cuts its line short there and inserts the corner: a fillet (``,R`` / ``A``: an arc of
that radius tangent to both lines) or a chamfer (Fanuc ``,C``: legs of that length along
both lines; LinuxCNC ``C``: a chamfer ending where a fillet of that radius would, legs of
``C tan(t/2)`` for a deflection ``t``). Its two moves cut two features of the profile.
[`corner_blocks`][] finds them among a program's moves; [`corner_vertex`][] gives where two
line features meet; [`corner_size`][] the corner word's value (mm) that makes the adjusted
corner feature. Corners next to an arc are not rewritten (the machine reads none).
"""

from __future__ import annotations

import math

#: ``Motion.via`` of the move a corner word inserts (the fillet ``,R``, the chamfer ``,C``)
CORNER_VIA = (",C", ",R")
#: the words that give a corner's size, by dialect: Fanuc's, then LinuxCNC's G7x ones
CORNER_WORDS = (",R", ",C", "A", "C")


def corner_blocks(moves) -> dict[int, tuple]:
    """``{line: (its move, its corner move)}`` for the blocks among `moves` that carry a
    corner (two moves of one line, the second a corner's)."""
    by_line: dict[int, list] = {}
    for m in moves:
        by_line.setdefault(m.line, []).append(m)
    return {
        ln: (ms[0], ms[1]) for ln, ms in by_line.items() if len(ms) == 2 and ms[1].via in CORNER_VIA
    }


def corner_vertex(f, g) -> tuple[float, float] | None:
    """Where the lines through line features `f` and `g` meet (None: parallel, or
    either is not a line)."""
    if f.kind != "line" or g.kind != "line":
        return None
    (x0, z0), (x1, z1) = f.p0, f.p1
    (x2, z2), (x3, z3) = g.p0, g.p1
    dx1, dz1, dx2, dz2 = x1 - x0, z1 - z0, x3 - x2, z3 - z2
    den = dx1 * dz2 - dz1 * dx2
    if abs(den) <= 1e-12 * math.hypot(dx1, dz1) * math.hypot(dx2, dz2):
        return None
    t = ((x2 - x0) * dz2 - (z2 - z0) * dx2) / den
    return (x0 + t * dx1, z0 + t * dz1)


def corner_size(letter: str, corner, vertex, f, g) -> float:
    """The value (mm) of corner word `letter` (``",R"``, ``",C"``, ``"A"``, ``"C"``) that
    makes the corner feature `corner` between line features `f` and `g` meeting at
    `vertex`: a fillet's radius, a Fanuc chamfer's leg from the vertex to its start, a
    LinuxCNC chamfer's leg over ``tan(t/2)``."""
    if letter in (",R", "A"):
        return float(corner.radius)
    leg = math.dist(vertex, corner.p0)
    if letter == ",C":
        return leg
    u = _unit(f.p0, f.p1)
    v = _unit(g.p0, g.p1)
    t = math.acos(max(-1.0, min(1.0, u[0] * v[0] + u[1] * v[1])))
    return leg / math.tan(t / 2)


def _unit(p, q):
    d = math.dist(p, q)
    return ((q[0] - p[0]) / d, (q[1] - p[1]) / d)

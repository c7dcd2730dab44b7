"""Fanuc's G73 pattern repeat: the contour run again and again, moved closer each pass.

[`expand_pattern_repeat`][] takes the ``P``..``Q`` contour (read from the tool position
at the cycle, the start point A), the tool position and a [`PatternRepeat`][] and
returns the [`CycleMove`][]s: pass k of d is the whole contour (its lead-in from A
included) translated by the finishing allowance plus $(d-k)/(d-1)$ of the relief, so
the first pass runs relief + allowance off the contour and the last the allowance
alone; a rapid brings the tool to A moved by the pass's translation before each pass,
and back to A at the end. There is no rs274 peer (LinuxCNC's G73 is a drilling
cycle): the rule is the Fanuc and Haas description, see docs/models/part_programs.md,
"Canned cycles".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import InputError
from ._cycles import CycleMove


@dataclass(frozen=True)
class PatternRepeat:
    """G73 (Fanuc ``G73 U W R`` / ``G73 P Q U W F``; Haas ``G73 P Q I K U W D F``).

    - `line`: the cycle block's source line.
    - `relief`: ``(x, z)`` (mm, x a radius): how much farther from the contour the
      first pass runs than the last (Fanuc's first-block ``U``/``W``, Haas ``I``/``K``),
      with its sign.
    - `passes`: the number of passes d (Fanuc's first-block ``R``, Haas ``D``), >= 1.
    - `allowance`: ``(x, z)`` (mm, x a radius): where the last pass runs from the
      contour (Fanuc's second-block ``U``/2 and ``W``).
    """

    line: int
    relief: tuple[float, float]
    passes: int
    allowance: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        if int(self.passes) != self.passes or self.passes < 1:
            raise InputError(
                f"G73: the number of passes must be a whole number >= 1, got {self.passes}",
                line=self.line,
            )

    def translation(self, k: int) -> tuple[float, float]:
        """The translation ``(x, z)`` (mm) of pass `k` (1 to `passes`)."""
        d = int(self.passes)
        f = (d - k) / (d - 1) if d > 1 else 0.0
        return (
            self.allowance[0] + f * self.relief[0],
            self.allowance[1] + f * self.relief[1],
        )


def expand_pattern_repeat(
    cycle: PatternRepeat, contour: Sequence, position: tuple[float, float]
) -> tuple[CycleMove, ...]:
    """The moves of a G73 cycle.

    **Arguments:**

    - `cycle`: the [`PatternRepeat`][].
    - `contour`: the ``P``..``Q`` blocks in order ([`ContourMove`][]s or
      :class:`~piecs_bayes.gcode.Motion`s), read from `position`: the first block
      leads in from it.
    - `position`: the tool position at the cycle (the start point A; mm, radius).

    **Returns:** per pass a rapid to A translated, then every contour block translated,
    as programmed (a rapid stays a rapid, arcs keep their sense) and carrying its line;
    a rapid back to A at the end.
    """
    if not contour:
        raise InputError("G73: the contour has no blocks", line=cycle.line)
    a = (float(position[0]), float(position[1]))
    first = contour[0].start
    if abs(first[0] - a[0]) > 1e-6 or abs(first[1] - a[1]) > 1e-6:
        raise InputError(
            f"G73: the contour must start at the tool position (x {first[0]:g}, z {first[1]:g}"
            f" vs x {a[0]:g}, z {a[1]:g})",
            line=cycle.line,
        )
    moves: list[CycleMove] = []
    pos = a
    for k in range(1, int(cycle.passes) + 1):
        dx, dz = cycle.translation(k)

        def moved(p, dx=dx, dz=dz):
            return None if p is None else (p[0] + dx, p[1] + dz)

        moves.append(CycleMove("rapid", pos, moved(a), cycle.line))
        pos = moved(a)
        for m in contour:
            end = moved(m.end)
            moves.append(CycleMove(m.kind, pos, end, cycle.line, moved(m.center), m.line))
            pos = end
    moves.append(CycleMove("rapid", pos, a, cycle.line))
    return tuple(moves)

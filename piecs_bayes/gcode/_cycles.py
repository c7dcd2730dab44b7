"""Lathe canned cycles G70/G71/G72 expanded into the moves the control makes.

[`expand_cycle`][] takes a contour (a LinuxCNC O-sub's blocks or Fanuc's ``P``..``Q``
blocks, as [`ContourMove`][]s or [`Motion`][]s read from the cycle's start point), the
tool position before the cycle block and a [`FinishCycle`][] (G70) or [`RoughCycle`][]
(G71/G72 and their ``.1``/``.2`` forms), and returns the [`CycleMove`][]s LinuxCNC
2.9's interpreter makes: rapids, feeds and arcs in mm, radius X, each with the cycle
block's line and, where it follows the contour, the contour block it comes from. It
follows LinuxCNC's rules (``rs274``) to its tolerances, quirks included; a contour the
control refuses is an :class:`~piecs_bayes.errors.InputError` naming the cycle's line.
Nose compensation is the caller's: a G70 pass is the contour itself and composes with
G41/G42 as the program's own blocks would.

The rules, each dialect's words, where rs274 departs from LinuxCNC's documentation:
docs/models/part_programs.md, "Canned cycles".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import InputError

#: LinuxCNC's tolerances (interp_g7x.cc), in the program's length unit
_TOL = 1e-6
_MONOTONIC_TOL = 1e-3
_GAP_TOL = 1e-2
_EQUAL = 1e-4  # TOLERANCE_EQUAL: an arc to where the tool already is is not made
_MAX_STEPS = 1_000_000
_ROUGH = {"G71": 0, "G71.1": 1, "G71.2": 2, "G72": 0, "G72.1": 1, "G72.2": 2}


@dataclass(frozen=True)
class ContourMove:
    """One block of a cycle's contour: ``kind`` is ``"rapid"``, ``"feed"``, ``"cw"``
    or ``"ccw"`` (a rapid is cut as a feed, as the control does).

    Points ``(x, z)`` in mm with x a radius; ``center`` for arcs. ``fillet`` and
    ``chamfer`` are a corner at the block's end: LinuxCNC's ``A`` and ``C`` words in
    a G7x subroutine (a chamfer ends where a fillet of that radius would; Fanuc's
    ``,R`` is the fillet, Fanuc's ``,C`` a leg length: see the docs). ``line`` is the
    block's source line. :meth:`from_motion` makes one from a reader's Motion.
    """

    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    line: int
    center: tuple[float, float] | None = None
    fillet: float = 0.0
    chamfer: float = 0.0

    def __post_init__(self):
        if self.kind not in ("rapid", "feed", "cw", "ccw"):
            raise InputError(f"a contour move is rapid, feed, cw or ccw, got {self.kind!r}")
        if (self.kind in ("cw", "ccw")) != (self.center is not None):
            raise InputError("an arc needs its centre, a line has none", line=self.line)
        if self.fillet and self.chamfer:
            raise InputError(
                "a corner takes a fillet (A) or a chamfer (C), not both", line=self.line
            )

    @classmethod
    def from_motion(cls, motion, *, fillet: float = 0.0, chamfer: float = 0.0) -> ContourMove:
        """The block of a :class:`~piecs_bayes.gcode.Motion` (with its corner, if any)."""
        return cls(
            motion.kind, motion.start, motion.end, motion.line, motion.center, fillet, chamfer
        )


@dataclass(frozen=True)
class FinishCycle:
    """G70: the finish pass along the contour (LinuxCNC ``G70 Q X Z D E P``).

    - `line`: the cycle block's source line.
    - `x`, `z`: the start point (mm, radius; LinuxCNC's ``X``/``Z``, absolute);
      None: the tool position. The cycle first rapids there, and returns there
      between passes.
    - `start_distance`, `end_distance`: ``D`` and ``E`` (mm), the distance from the
      contour of the first and of the last pass, towards the start point.
    - `passes`: ``P``; pass k of P (counted down from P to 1) runs at
      $(k-1)(D-E)/P + E$ (P is truncated to a whole number of passes, as rs274 does).
    - `return_to_start`: a rapid back to the start point at the end (Fanuc's G70
      ends there; LinuxCNC's leaves the tool at the contour's end).
    """

    line: int
    x: float | None = None
    z: float | None = None
    start_distance: float = 0.0
    end_distance: float = 0.0
    passes: float = 1.0
    return_to_start: bool = False


@dataclass(frozen=True)
class RoughCycle:
    """G71/G72 roughing (LinuxCNC ``G71 Q X Z D I R``, also ``G71.1``/``G71.2`` and
    the same for G72).

    - `code`: ``"G71"`` (turning: layers along Z) or ``"G72"`` (facing: layers along
      X), with ``.1`` (no pockets: Fanuc's type I) or ``.2`` (the pockets only, after
      a ``.1``); plain G71/G72 cut pockets too (Fanuc's type II).
    - `line`: the cycle block's source line; `x`, `z`: the start point as for G70.
    - `allowance`: ``D`` (mm), the material left normal to the contour.
    - `depth`: ``I`` (mm), the depth of each layer (> 0); `retract`: ``R`` (mm), the
      lift off each layer, along both axes.
    - `shift`: ``(u, w)`` (mm, u a radius): the contour moved by this before roughing
      (Fanuc's finishing allowances ``U``/2 and ``W``; the start point stays).
    - `return_to_start`: a rapid back to the start point at the end (Fanuc).
    """

    code: str
    line: int
    x: float | None = None
    z: float | None = None
    allowance: float = 0.0
    depth: float = 1.0
    retract: float = 0.5
    shift: tuple[float, float] = (0.0, 0.0)
    return_to_start: bool = False

    def __post_init__(self):
        if self.code not in _ROUGH:
            raise InputError(
                f"a roughing cycle is one of {sorted(_ROUGH)}, got {self.code!r}", line=self.line
            )
        if not self.depth > 0:
            raise InputError(
                f"{self.code}: the depth of cut (I) must be > 0, got {self.depth}", line=self.line
            )


@dataclass(frozen=True)
class CycleMove:
    """A move the control makes for a cycle: ``kind`` ``"rapid" | "feed" | "cw" | "ccw"``,
    points ``(x, z)`` in mm (x a radius), ``center`` for arcs.

    ``line`` is the cycle block's line; ``contour_line`` the contour block the move
    follows (every move of a finish pass; in roughing the moves along the contour),
    None for the approach, the roughing layers and their retracts.
    """

    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    line: int
    center: tuple[float, float] | None = None
    contour_line: int | None = None

    @property
    def is_arc(self) -> bool:
        return self.kind in ("cw", "ccw")


def cycle_start(cycle, position: tuple[float, float]) -> tuple[float, float]:
    """The start point of a cycle: its ``X``/``Z`` where given, else the tool position."""
    x = position[0] if cycle.x is None else cycle.x
    z = position[1] if cycle.z is None else cycle.z
    return (float(x), float(z))


def expand_cycle(
    cycle: FinishCycle | RoughCycle,
    contour: Sequence,
    position: tuple[float, float],
    *,
    unit_mm: float = 1.0,
) -> tuple[CycleMove, ...]:
    """The moves a lathe control makes for a G70, G71 or G72 cycle.

    **Arguments:**

    - `cycle`: a [`FinishCycle`][] or a [`RoughCycle`][].
    - `contour`: the contour's blocks in order, [`ContourMove`][]s or
      :class:`~piecs_bayes.gcode.Motion`s, read from the cycle's start point
      ([`cycle_start`][]): the first block leads in from there.
    - `position`: the tool position before the cycle block (mm, radius).
    - `unit_mm`: the length of the program's unit in mm (25.4 for G20): LinuxCNC's
      tolerances are in program units, and so are they here.

    **Returns:** the moves, starting with the rapid to the start point (of zero length
    when the block has no X/Z, as rs274 makes it). A G70 pass is the contour offset by
    its distance (none on the last pass). Nose compensation in force at G70 (LinuxCNC's
    G41/G42 before it, Fanuc's in the P block) is not applied here: compensate the
    moves after the first as the same blocks written out would be (the rapid to X/Z is
    made uncompensated, as LinuxCNC does since July 2024), not the contour.

    Raises :class:`~piecs_bayes.errors.InputError` (with the cycle's line) where the
    control refuses the contour: not monotonic, a corner that does not fit, a roughing
    pass that does not end.
    """
    if not unit_mm > 0:
        raise InputError(f"unit_mm must be > 0, got {unit_mm}", line=cycle.line)
    start = cycle_start(cycle, position)
    out = _Out(cycle.line, unit_mm, _pt(position, unit_mm))
    out.rapid_to(_pt(start, unit_mm))  # the cycle block's own move to X/Z
    segs = _segments(contour, _pt(start, unit_mm), cycle.line, unit_mm)
    shift = getattr(cycle, "shift", (0.0, 0.0))
    if shift != (0.0, 0.0):
        d = complex(shift[1], shift[0]) / unit_mm
        for s in segs:
            s.translate(d)
        segs[0].start -= d  # the start point stays; the lead-in reaches the moved contour
    if len(segs) > 1:
        try:
            if isinstance(cycle, FinishCycle):
                _finish(segs, cycle, out)
            elif isinstance(cycle, RoughCycle):
                _rough(segs, cycle, out)
            else:
                raise InputError(f"not a G70/G71/G72 cycle: {cycle!r}")
        except _CycleFailure as e:
            raise InputError(f"{_code(cycle)}: {e}", line=cycle.line) from None
    if cycle.return_to_start:
        out.rapid_to(_pt(start, unit_mm))
    return tuple(out.moves)


def _code(cycle) -> str:
    return cycle.code if isinstance(cycle, RoughCycle) else "G70"


def _pt(p, unit_mm) -> complex:
    """A point ``(x, z)`` in mm as LinuxCNC's complex ``z + i x`` in program units."""
    return complex(p[1], p[0]) / unit_mm


class _CycleFailure(Exception):
    """The control refuses the cycle (LinuxCNC's 'G7X error: ...')."""


# ------------------------------------------------------------------------------------
# The contour's segments, as LinuxCNC works on them: complex points z + i x, mutable.


def _cross(a: complex, b: complex) -> float:
    return (a.conjugate() * b).imag


class _Line:
    __slots__ = ("start", "end", "line", "corner")

    def __init__(self, start, end, line, corner=0.0):
        self.start, self.end, self.line = start, end, line
        self.corner = corner  # a pending chamfer's size (LinuxCNC's `finish`)

    def copy(self):
        return _Line(self.start, self.end, self.line, self.corner)

    def mirror_x(self):
        self.start, self.end = self.start.conjugate(), self.end.conjugate()

    def mirror_z(self):
        self.start, self.end = -self.start.conjugate(), -self.end.conjugate()

    def rotate(self):
        self.start, self.end = -1j * self.start, -1j * self.end

    def translate(self, d):
        self.start += d
        self.end += d

    def offset(self, distance):
        """Move the line `distance` to the right of its travel."""
        d = 1j * distance * (self.start - self.end) / abs(self.start - self.end)
        self.start += d
        self.end += d

    def extent(self) -> float:
        return abs(self.start - self.end)

    def monotonic(self) -> bool:
        return (self.end - self.start).real <= _MONOTONIC_TOL

    def crossings(self, x: float) -> list[float]:
        """The z where the line is at height x (both ends for a level line)."""
        s, e = self.start, self.end
        if min(s.imag, e.imag) > x + _TOL or max(s.imag, e.imag) < x - _TOL:
            return []
        if abs(s.imag - e.imag) < _TOL:
            return [s.real, e.real]
        return [(x - s.imag) / (e.imag - s.imag) * (e.real - s.real) + s.real]

    def draw(self, out):
        out.feed(self.end, self.line)

    def climb(self, loc, out):
        """Follow the line up; (True, loc) when it goes down (not a climb)."""
        if self.end.imag + _TOL < self.start.imag:
            return True, loc
        if abs(loc - self.start) > _TOL:
            raise _CycleFailure("How did we get here?")
        out.feed(self.end, self.line)
        return False, self.end

    def climb_only(self, loc, out):
        if self.end.imag < self.start.imag:
            return loc
        zs = self.crossings(loc.imag)
        if not zs:
            return loc
        loc = complex(zs[0], loc.imag)
        out.feed(loc, None)
        out.feed(self.end, self.line)
        return self.end

    def dive(self, loc, x, out, fast):
        """Follow the line down to height x; (True, loc) when it does not go down."""
        if self.start.imag <= self.end.imag + _TOL:
            return True, loc
        move = out.rapid if fast else out.feed
        if x < self.end.imag:
            move(self.end, self.line)
            return False, self.end
        zs = self.crossings(x)
        if not zs:
            raise _CycleFailure("x too large in straight dive")
        ep = complex(zs[0], x)
        move(ep, self.line)
        return False, ep


class _Arc:
    __slots__ = ("start", "end", "center", "ccw", "line", "corner")

    def __init__(self, start, center, end, ccw, line, corner=0.0):
        self.start, self.center, self.end = start, center, end
        self.ccw, self.line = bool(ccw), line
        self.corner = corner  # a pending fillet's radius

    def copy(self):
        return _Arc(self.start, self.center, self.end, self.ccw, self.line, self.corner)

    def mirror_x(self):
        self.ccw = not self.ccw
        self.start, self.end = self.start.conjugate(), self.end.conjugate()
        self.center = self.center.conjugate()

    def mirror_z(self):
        self.ccw = not self.ccw
        self.start, self.end = -self.start.conjugate(), -self.end.conjugate()
        self.center = -self.center.conjugate()

    def rotate(self):
        self.start, self.end, self.center = -1j * self.start, -1j * self.end, -1j * self.center

    def translate(self, d):
        self.start += d
        self.end += d
        self.center += d

    def offset(self, distance):
        """Move the arc `distance` to the right of its travel (outwards for G3)."""
        r = abs(self.start - self.center)
        f = (r + (distance if self.ccw else -distance)) / r
        self.start = f * (self.start - self.center) + self.center
        self.end = f * (self.end - self.center) + self.center

    def extent(self) -> float:
        return min(abs(self.start - self.end), abs(self.start - self.center))

    def monotonic(self) -> bool:
        if self.corner != 0:
            return True
        entry = (self.start - self.center).imag
        leave = (self.end - self.center).imag
        dz = (self.end - self.start).real
        if self.ccw:
            return entry >= -_MONOTONIC_TOL and leave >= -_MONOTONIC_TOL and dz <= -_MONOTONIC_TOL
        return entry <= _MONOTONIC_TOL and leave <= _MONOTONIC_TOL and dz <= -_MONOTONIC_TOL

    def _on(self, p) -> bool:
        a = _cross(self.start - self.center, p - self.center)
        b = _cross(self.end - self.center, p - self.center)
        if self.ccw:
            return a >= -_TOL and b <= _TOL
        return a <= _TOL and b >= -_TOL

    def crossings(self, x: float) -> list[float]:
        c = self.center
        r = abs(self.start - c)
        s = -(x - r - c.imag) * (x + r - c.imag)
        if s < -_TOL:
            return []
        s = math.sqrt(max(s, 0.0))
        return [z for z in (c.real + s, c.real - s) if self._on(complex(z, x))]

    def draw(self, out):
        out.arc(self.ccw, self.center, self.end, self.line)

    def _top(self):
        """The end, or the circle's top when a G3 would pass it."""
        if self.end.real < self.center.real:
            return complex(self.center.real, self.center.imag + abs(self.start - self.center))
        return self.end

    def climb(self, loc, out):
        if not self.ccw:
            if loc.real > self.center.real:
                return True, loc
            if abs(loc - self.end) > _MONOTONIC_TOL:
                out.arc(False, self.center, self.end, self.line)
            return False, self.end
        if loc.real < self.center.real:
            return True, loc
        ep = self._top()
        if abs(loc - ep) > _MONOTONIC_TOL:
            out.arc(True, self.center, ep, self.line)
        return True, ep

    def climb_only(self, loc, out):
        zs = self.crossings(loc.imag)
        if not zs:
            return loc
        if not self.ccw:
            if zs[-1] > self.center.real:
                return loc
            loc = complex(zs[-1], loc.imag)
            out.feed(loc, None)
            if abs(loc - self.end) > _MONOTONIC_TOL:
                out.arc(False, self.center, self.end, self.line)
            return self.end
        if zs[0] < self.center.real:
            return loc
        loc = complex(zs[0], loc.imag)
        out.feed(loc, None)
        ep = self._top()
        if abs(loc - ep) > _MONOTONIC_TOL:
            out.arc(True, self.center, ep, self.line)
        return ep

    def dive(self, loc, x, out, fast):
        if abs(loc - self.end) < _TOL or (loc - self.end).real <= _TOL:
            return False, self.end
        zs = self.crossings(x) or self.crossings(x - _TOL)
        c = self.center
        if self.ccw:
            if loc.real - _TOL > c.real:
                return True, loc
            if not zs or zs[-1] > c.real:
                out.arc(True, c, self.end, self.line)
                return False, self.end
            ep = complex(zs[-1], x)
            out.arc(True, c, ep, self.line)
            return False, ep
        if loc.real <= c.real:
            return True, loc  # already climbing
        if not zs:
            out.arc(False, c, self.end, self.line)
            return False, self.end
        if zs[0] < c.real:
            return False, loc  # met on the back side only: the next layer
        ep = complex(zs[0], x)
        out.arc(False, c, ep, self.line)
        return False, ep


def _meet(prev, nxt):
    """Move ``prev``'s end and ``nxt``'s start to where the two curves meet."""
    if isinstance(prev, _Line) and isinstance(nxt, _Line):
        rot = (nxt.start - nxt.end).conjugate() / abs(nxt.start - nxt.end)
        ps, pe = (prev.start - nxt.end) * rot, (prev.end - nxt.end) * rot
        if (ps - pe).imag == 0:
            raise _CycleFailure("Cannot intersect parallel lines")
        f = ps.imag / (ps - pe).imag
        p = (ps + f * (pe - ps)) / rot + nxt.end
    elif isinstance(prev, _Arc) and isinstance(nxt, _Arc):
        a = abs(nxt.start - nxt.center)
        b = abs(prev.start - prev.center)
        c = abs(nxt.center - prev.center)
        if c == 0 or a == 0:
            raise _CycleFailure("two concentric arcs cannot be joined (rs274 makes NaN here)")
        cos_b = (c * c + a * a - b * b) / 2.0 / a / c
        rot = complex(cos_b, math.sqrt(1 - min(cos_b * cos_b, 1.0)))
        p = rot * (prev.center - nxt.center) / c * a + nxt.center
    else:
        if abs(nxt.start - prev.end) < _TOL:
            return
        line, arc = (nxt, prev) if isinstance(nxt, _Line) else (prev, nxt)
        rot = (line.start - line.end).conjugate() / abs(line.start - line.end)
        pe = (arc.end - line.end) * rot
        pc = (arc.center - line.end) * rot
        b = abs(pc - pe) ** 2 - pc.imag * pc.imag
        b = math.sqrt(b) if b >= 0 else 0.0
        s1 = (pc.real + b) / rot + line.end
        s2 = (pc.real - b) / rot + line.end
        p = s1 if abs(nxt.start - s1) < abs(nxt.start - s2) else s2
    nxt.start = prev.end = p


def _segments(contour, start: complex, line: int, unit_mm: float) -> list:
    """The contour as segments from the start point, corners as pending segments."""
    segs: list = []
    pos = start
    for k, m in enumerate(contour):
        a, b = _pt(m.start, unit_mm), _pt(m.end, unit_mm)
        if k == 0 and abs(a - start) > 1e-6 / unit_mm:
            raise InputError(
                f"the contour must start at the cycle's start point (x {m.start[0]:g}, "
                f"z {m.start[1]:g} vs x {start.imag * unit_mm:g}, z {start.real * unit_mm:g})",
                line=line,
            )
        a = pos  # each block starts where the previous one ended
        if a == b:
            continue
        if m.kind in ("cw", "ccw"):
            segs.append(_Arc(a, _pt(m.center, unit_mm), b, m.kind == "ccw", m.line))
        else:
            segs.append(_Line(a, b, m.line))
        fillet, chamfer = getattr(m, "fillet", 0.0), getattr(m, "chamfer", 0.0)
        if fillet:
            segs.append(_Arc(b, b, b, False, m.line, fillet / unit_mm))
        if chamfer:
            segs.append(_Line(b, b, m.line, chamfer / unit_mm))
        pos = b
    return segs


# ------------------------------------------------------------------------------------
# The profile in LinuxCNC's working frame: turned (G72) and mirrored so that it runs
# with Z and X as the roughing expects; the moves are mapped back on the way out.


class _Out:
    """Collects the moves in the part frame (mm), as the interpreter receives them."""

    def __init__(self, line, unit_mm, position):
        self.cycle_line, self.unit = line, unit_mm
        self.rotated = self.flip_x = self.flip_z = False
        self.pos = position
        self.moves: list[CycleMove] = []

    def to_part(self, p: complex) -> complex:
        if self.flip_x:
            p = p.conjugate()
        if self.flip_z:
            p = -p.conjugate()
        return 1j * p if self.rotated else p

    def _add(self, kind, p, line, center=None):
        u = self.unit
        self.moves.append(
            CycleMove(
                kind,
                (self.pos.imag * u, self.pos.real * u),
                (p.imag * u, p.real * u),
                self.cycle_line,
                None if center is None else (center.imag * u, center.real * u),
                line,
            )
        )
        self.pos = p

    def rapid_to(self, p):
        """A rapid to a point of the part frame, following no contour block."""
        self._add("rapid", p, None)

    def rapid(self, p, line):
        self._add("rapid", self.to_part(p), line)

    def feed(self, p, line):
        self._add("feed", self.to_part(p), line)

    def arc(self, ccw, center, p, line):
        p = self.to_part(p)
        if abs(p.real - self.pos.real) < _EQUAL and abs(p.imag - self.pos.imag) < _EQUAL:
            return
        ccw = ccw != (self.flip_x != self.flip_z)
        self._add("ccw" if ccw else "cw", p, line, self.to_part(center))


def _turn(segs):
    for s in segs:
        s.rotate()


def _orient(segs, frame=None):
    """Mirror the profile so that it runs from high X to low X and from high Z
    to low Z, taken from the first segment's end to the last's (LinuxCNC's swap)."""
    d = segs[0].end - segs[-1].end
    flip_x, flip_z = d.imag > 0, d.real < 0
    for s in segs:
        if flip_x:
            s.mirror_x()
        if flip_z:
            s.mirror_z()
    if frame is not None:
        frame.flip_x ^= flip_x
        frame.flip_z ^= flip_z


def _corners(segs):
    """Turn the pending fillets and chamfers into their segments (LinuxCNC's
    do_finish), then drop what is shorter than 1e-3."""
    for k in range(1, len(segs) - 1):
        s = segs[k]
        if s.corner != 0:
            _corner(s, segs[k - 1], segs[k + 1])
    segs[:] = [s for s in segs if s.extent() >= _MONOTONIC_TOL]


def _corner(seg, prev, nxt):
    size = seg.corner
    for _ in range(2):
        p, n = prev.copy(), nxt.copy()
        p.offset(size)
        n.offset(size)
        if (p.end - n.start).real <= _GAP_TOL:
            break
        size = -size
    else:
        z, x = prev.end.real, prev.end.imag
        raise _CycleFailure(f"Corner finish failed at ({z:g},{x:g})")
    _meet(p, n)
    center = (p.end + n.start) / 2.0
    p.offset(-size)
    n.offset(-size)
    seg.start = prev.end = p.end
    seg.end = nxt.start = n.start
    if isinstance(seg, _Arc):
        seg.center = center
        seg.ccw = (seg.start - center).imag > 0 or (seg.end - center).imag > 0
        seg.corner = 0.0


def _check_monotonic(segs):
    if (segs[0].end - segs[0].start).real > 0:
        segs[0].start = complex(segs[0].end.real, segs[0].start.imag)
    if not all(s.monotonic() for s in segs):
        raise _CycleFailure("Not monotonic")


def _offset(segs, distance):
    """Offset the profile (lead-in excluded) by `distance` towards the start point,
    in steps of at most half the shortest segment, rounding the opened corners
    (LinuxCNC's add_distance)."""
    v1 = segs[0].end - segs[0].start
    v2 = segs[-1].start - segs[0].start
    if v2 != 0 and (v1 / v2).imag < 0:
        distance = -distance
    lead = segs.pop(0)
    done = 0.0
    steps = 0
    while done != distance:
        steps += 1
        if steps > _MAX_STEPS or not segs:
            raise _CycleFailure("the contour cannot be offset by this distance")
        step = min(min((s.extent() / 2 for s in segs), default=1e9), abs(distance - done))
        step = -step if distance < 0 else step
        kept = []
        for s in segs:
            s.offset(step)
            if s.extent() >= _MONOTONIC_TOL:
                kept.append(s)
        segs[:] = kept
        k = 0
        while k < len(segs) - 1:
            a, b = segs[k], segs[k + 1]
            if (a.end - b.start).real > _GAP_TOL:
                s, e = a.copy(), b.copy()
                s.offset(-step)
                e.offset(-step)
                center = (s.end + e.start) / 2.0
                segs.insert(k + 1, _Arc(a.end, center, b.start, distance > 0, a.line))
                k += 1
            k += 1
        k = 0
        while k < len(segs) - 1:
            if not segs[k].monotonic():
                if k == 0:
                    raise _CycleFailure("Not monotonic after the offset")
                drop = k if segs[k].extent() < segs[k - 1].extent() else k - 1
                del segs[drop]
                k = 0
            if segs[k].extent() < _MONOTONIC_TOL:
                del segs[k]
                k = 0
            else:
                _meet(segs[k], segs[k + 1])
            k += 1
        done += step
    for a, b in zip(segs, segs[1:], strict=False):
        a.end = b.start = (a.end + b.start) / 2.0
    lead.end = segs[0].start
    segs.insert(0, lead)


def _copy(segs):
    return [s.copy() for s in segs]


def _finish(segs, cycle: FinishCycle, out: _Out):
    """G70: the contour, offset by each pass's distance, after a rapid to its start."""
    probe = _copy(segs[1:])
    _orient(probe)
    rotated = False
    if not all(s.monotonic() for s in probe):
        _turn(probe)
        _orient(probe)
        rotated = True
    _check_monotonic(probe)
    if rotated:
        _turn(segs)
        out.rotated = True
    _orient(segs, out)
    _corners(segs)
    _check_monotonic(segs)
    unit = out.unit
    d, e, p = cycle.start_distance / unit, cycle.end_distance / unit, cycle.passes
    for k in range(int(p), 0, -1):
        path = _copy(segs)
        _offset(path, (k - 1) * (d - e) / p + e)
        out.rapid(path[0].start, None)
        out.rapid(path[0].end, path[0].line)
        for s in path[1:]:
            s.draw(out)


def _rough(segs, cycle: RoughCycle, out: _Out):
    """G71/G72: layers `depth` apart down to the contour offset by `allowance`."""
    unit = out.unit
    if cycle.code.startswith("G72"):
        _turn(segs)
        out.rotated = True
    _orient(segs, out)
    _corners(segs)
    _check_monotonic(segs)
    _offset(segs, cycle.allowance / unit)
    delta = max(cycle.depth / unit, 2 * _TOL)
    escape = cycle.retract / unit * (1 + 1j)
    out.rapid(segs[0].start, None)
    last, first = segs[-1], segs[0]
    if last.end.imag < first.start.imag:  # close the profile up to the start's level
        segs.append(_Line(last.end, complex(last.end.real, first.start.imag), None))
    _layers(segs, _ROUGH[cycle.code], delta, escape, out)


def _layers(segs, mode, delta, escape, out):
    """The roughing layers (LinuxCNC's pocket, its recursion unrolled). `mode`: 0 all,
    1 no pockets, 2 the pockets only (3 once the first roughing pass is skipped)."""
    starts = [segs[0].start]
    loc = segs[0].start
    p = 0
    steps = 0
    while True:
        x = starts[-1].imag
        if mode == 2:
            while p < len(segs):
                not_diving, loc = segs[p].dive(loc, -1e9, out, p == 0)
                if not_diving:
                    break
                p += 1
            mode = 3
        pocket = False
        while p < len(segs) and not pocket:
            steps += 1
            if steps > _MAX_STEPS:
                raise _CycleFailure("the roughing does not end (LinuxCNC loops here)")
            while x - _TOL > loc.imag:
                x -= delta
            not_diving, loc = segs[p].dive(loc, x, out, p == 0)
            if not_diving:
                if mode == 1:
                    for s in segs[p:]:
                        loc = s.climb_only(loc, out)
                    return
                while p < len(segs):
                    stop, loc = segs[p].climb(loc, out)
                    if stop:
                        if mode == 3:
                            if loc.imag > starts[-1].imag and len(starts) > 1:
                                starts.pop()
                            if len(starts) == 1:
                                starts.append(loc)
                        pocket = True
                        break
                    p += 1
                if not pocket:
                    return
                continue
            if abs(loc.imag - x) > _TOL:
                p += 1
                continue
            p, x = _layer(segs, p, loc, x, delta, escape, out)
        if not pocket:
            return


def _layer(segs, p, loc, x, delta, escape, out):
    """One layer at height ``loc.imag``: cut along Z to the next contour crossing,
    retract, return over it. Returns the segment and the height to go on with."""
    for ip in range(p, len(segs)):
        zs = segs[ip].crossings(loc.imag)
        if not zs:
            continue
        z = zs[0] if ip != p else zs[-1]
        dist = abs(z - loc.real)
        if z - _TOL > loc.real:
            continue  # meets the diving curve at its start only
        if dist < _TOL:
            if ip == p:
                continue
            if abs(loc - segs[ip].start) < _TOL:
                return ip, x  # another curve starts here: follow it
            return p, x - delta  # a zero-length cut
        dest = complex(z, loc.imag)
        out.feed(dest, None)
        scale = 1.0 if escape.real == 0 else min(1.0, dist / 2 / escape.real)
        out.rapid(dest + scale * escape, None)
        out.rapid(loc - (scale * escape).conjugate(), None)
        (out.rapid if p == 0 else out.feed)(loc, None)
        return p, x - delta
    return p, x

"""Nose-radius compensation by the arc-corner rule (``corner="arc"``): what LinuxCNC does.

Written for piecs_bayes from the documented behaviour of G40/G41/G42 (RS274/NGC and
LinuxCNC user manuals) and from running LinuxCNC's ``rs274`` interpreter as a black box
on probe programs. No interpreter source code was consulted.

[`ArcCornerComp`][] runs one program on the **nose centre** (``(x, z)`` in mm, x a
radius; the controlled point adds :func:`tip_offset`): compensated lines move ``r`` to
the tool side and arcs change radius by ``r``; smooth corners (``|turn| <
TANGENT_TURN``) join, convex ones get an arc of radius ``r`` about the programmed corner,
concave ones are trimmed; the entry move ends ``r`` off its end. A gouge raises
:class:`~piecs_bayes.errors.AnalysisError` naming the block. The output agrees with
``rs274`` move for move, except where ``rs274`` misbehaves (refused here).

The rule, gouges, tolerances, differences: docs/models/nose_compensation.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import AnalysisError
from ._nosecomp_base import (
    _EPS,
    _add,
    _cross,
    _dot,
    _left,
    _meet_circles,
    _meet_line_circle,
    _meet_lines,
    _sub,
    _sweep,
    _unit,
    _wrap,
    resolve_setting,
    tip_offset,
)

TANGENT_TURN = 0.05
_SLACK = 1e-9


def _direction(m, at_end: bool):
    """Travel direction of a programmed move at its start or end (not unit)."""
    if not m.is_arc:
        return _sub(m.end, m.start)
    rad = _sub(m.end if at_end else m.start, m.center)
    t = (rad[1], -rad[0])  # counter-clockwise tangent
    return t if m.kind == "ccw" else (-t[0], -t[1])


@dataclass
class _Open:
    """A compensated move whose end waits for the next move (nose-centre coordinates)."""

    kind: str
    line: int
    start: tuple  # where it starts (fixed)
    corner: tuple  # programmed end point
    out_dir: tuple  # programmed travel direction at the end
    end: tuple  # its own offset end
    centre: tuple | None = None  # arcs: centre and offset radius at the end
    rho: float = 0.0
    ref_start: tuple | None = None  # its own offset start (None: the entry line)
    sweep: float = 0.0  # arcs: sweep from ref_start to end
    base: tuple | None = None  # lines: a point of the offset line, and its direction
    dir: tuple | None = None
    entry: bool = False
    trimmed: bool = False  # its start was set by a concave corner
    zeros: list = field(default_factory=list)

    @property
    def arc(self) -> bool:
        return self.centre is not None


class ArcCornerComp:
    """Arc-corner compensation of one program; :meth:`run` gives the controlled
    point's moves as ``(kind, end, line, centre)`` tuples (centre None for lines)."""

    def __init__(self, program, tools, start):
        self.program = program
        self.tools = tools
        self.pos = (float(start[0]), float(start[1]))
        self.out: list[tuple] = []
        self.state = None  # (s, r, tip) while compensating with r > 0
        self.open: _Open | None = None
        self.tip_arc_entry = False

    def gouge(self, line: int, msg: str) -> AnalysisError:
        err = AnalysisError(f"{self.program.name or '<program>'}:{line}: {msg}")
        err.line = line
        return err

    def run(self) -> list[tuple]:
        for ev in self.program.events:
            if not hasattr(ev, "kind"):  # G40 / G41 / G42
                self._close(ev.line)
                self.state = None
                if ev.setting is not None:
                    side, r, orientation = resolve_setting(
                        ev.setting, self.tools, self.program.name
                    )
                    if r > 0:
                        s = 1.0 if side == "left" else -1.0
                        self.state = (s, r, tip_offset(orientation, r))
            elif self.state is None or ev.comp is None:
                self._emit(ev.kind, ev.end, ev.line, ev.center)
            elif ev.entry:
                self._enter(ev)
            elif ev.start == ev.end:
                self.open.zeros.append((ev.kind, ev.line))
            else:
                self._turn_onto(ev)
        self._close()
        return self.out

    # -- output ---------------------------------------------------------------

    def _emit(self, kind, end, line, centre=None, tip=(0.0, 0.0)):
        end = _add(end, tip)
        self.out.append((kind, end, line, None if centre is None else _add(centre, tip)))
        self.pos = end

    def _finish(self, piece: _Open, end, blame: int, concave: bool = False) -> None:
        """Fix the end of the open move (``concave``: at a concave corner), check
        that its corners trim it without reversing it, emit it."""
        tip = self.state[2]
        if piece.arc:
            ccw = piece.kind == "ccw"
            cut = _wrap(_sweep(piece.ref_start, piece.centre, piece.start, ccw))
            grow = _wrap(_sweep(piece.end, piece.centre, end, ccw))
            left = piece.sweep - cut + grow > _EPS * (1 + piece.sweep)
        else:
            u = _unit(piece.dir)
            cut = 0.0 if piece.ref_start is None else _dot(_sub(piece.start, piece.ref_start), u)
            grow = _dot(_sub(end, piece.end), u)
            left = piece.entry or _dot(_sub(end, piece.start), u) > 0
        what = "arc" if piece.arc else "move"
        if (piece.trimmed and cut < -_SLACK) or (concave and grow > _SLACK):
            raise self.gouge(
                blame,
                f"the nose cannot reach into the concave corner at the "
                f"{'end' if concave and grow > _SLACK else 'start'} of line {piece.line}: "
                f"the offset paths meet beyond the compensated {what}",
            )
        if not left:
            raise self.gouge(
                blame,
                f"the nose does not fit the concave corner: the compensated {what} of line "
                f"{piece.line} would run backwards (gouge)",
            )
        self._emit(piece.kind, end, piece.line, piece.centre, tip)
        for kind, line in piece.zeros:
            self._emit(kind, end, line, None, tip)

    def _tip_arc_entry(self, a: _Open) -> AnalysisError:
        return self.gouge(
            a.line,
            "an arc that switches compensation on with a tip offset (orientation 1-8) must be "
            "followed by a compensated move that leaves it tangentially: otherwise LinuxCNC "
            "turns it into a full circle or stops; program a straight entry move",
        )

    def _close(self, blame: int | None = None) -> None:
        """End the open move at its own offset end (G40 on line ``blame``, or the end)."""
        if self.open is not None and self.open.entry and self.tip_arc_entry:
            raise self._tip_arc_entry(self.open)
        if self.open is not None:
            self._finish(self.open, self.open.end, blame or self.open.line)
            self.open = None

    # -- moves ----------------------------------------------------------------

    def _check_radius(self, m) -> None:
        """An arc with the nose on its inside must be larger than the nose."""
        s, r, _ = self.state
        if m.is_arc and (m.kind == "ccw") == (s > 0) and math.dist(m.end, m.center) <= r:
            raise self.gouge(
                m.line,
                f"the arc radius ({math.dist(m.end, m.center):.4g} mm) is not larger than the "
                f"nose radius ({r:.4g} mm) on its inside (gouge)",
            )

    def _enter(self, m) -> None:
        s, r, tip = self.state
        self.tip_arc_entry = False
        self._check_radius(m)
        chord = math.dist(m.start, m.end)
        if chord <= r:
            raise self.gouge(
                m.line,
                f"the move that switches compensation on must end farther than the nose radius "
                f"({r:.4g} mm) from where it starts ({chord:.4g} mm)",
            )
        out_dir = _direction(m, True)
        end = _add(m.end, _left(out_dir), s * r)
        if not m.is_arc:
            here = _sub(self.pos, tip)
            self.open = _Open(m.kind, m.line, here, m.end, out_dir, end, base=end, dir=out_dir)
            self.open.entry = True
            return
        # re-planned arc: through the start, tangent to the offset circle at ``end``
        u = _unit(_sub(m.center, m.end))
        w = _sub(end, m.start)
        den = 2.0 * _dot(u, w)
        if abs(den) <= _EPS * _dot(w, w):
            raise self.gouge(m.line, "the arc that switches compensation on cannot be re-planned")
        t = -_dot(w, w) / den
        centre = _add(end, u, t)
        if tip != (0.0, 0.0):
            self._emit("feed", m.start, m.line, None, tip)
            self.tip_arc_entry = True
        sweep = _sweep(m.start, centre, end, m.kind == "ccw")
        self.open = _Open(
            m.kind, m.line, m.start, m.end, out_dir, end, centre, abs(t), m.start, sweep
        )
        self.open.entry = True

    def _offset_start(self, m):
        s, r, _ = self.state
        return _add(m.start, _left(_direction(m, False)), s * r)

    def _piece(self, m, start) -> _Open:
        s, r, _ = self.state
        out_dir = _direction(m, True)
        end = _add(m.end, _left(out_dir), s * r)
        if not m.is_arc:
            ref = self._offset_start(m)
            return _Open(
                m.kind, m.line, start, m.end, out_dir, end, ref_start=ref, base=end, dir=out_dir
            )
        rho = math.dist(m.end, m.center) + (-s * r if m.kind == "ccw" else s * r)
        sweep = _sweep(m.start, m.center, m.end, m.kind == "ccw")
        ref = self._offset_start(m)
        return _Open(m.kind, m.line, start, m.end, out_dir, end, m.center, rho, ref, sweep)

    def _turn_onto(self, m) -> None:
        s, r, tip = self.state
        a = self.open
        self._check_radius(m)
        d_in = _direction(m, False)
        turn = math.atan2(_cross(a.out_dir, d_in), _dot(a.out_dir, d_in))
        if abs(turn) < TANGENT_TURN:
            self._finish(a, a.end, m.line)
            self.open = self._piece(m, a.end)
            return
        if self.tip_arc_entry and a.entry:
            raise self._tip_arc_entry(a)
        start_b = self._offset_start(m)
        if s * turn < 0 or abs(turn) > math.pi - _EPS:  # convex: round the corner
            self._finish(a, a.end, m.line)
            if m.kind == "rapid":  # a rapid cannot be an arc: cross the corner straight
                self._emit("rapid", start_b, m.line, None, tip)
            else:
                self._emit("cw" if s > 0 else "ccw", start_b, m.line, a.corner, tip)
            self.open = self._piece(m, start_b)
            return
        meet = self._meet(a, m, start_b)
        if meet is None:
            raise self.gouge(
                m.line, "the nose does not fit the concave corner: the offset paths do not meet"
            )
        self._finish(a, meet, m.line, concave=True)
        self.open = self._piece(m, meet)
        self.open.trimmed = True

    def _meet(self, a: _Open, m, start_b):
        s, r, _ = self.state
        ref = a.corner
        if m.is_arc:
            grow = -s * r if m.kind == "ccw" else s * r
            rho_b = math.dist(m.end, m.center) + grow
            if a.arc:
                return _meet_circles(a.centre, a.rho, m.center, rho_b, ref)
            # found on the circle through the arc's start, then put on its offset circle
            q = _meet_line_circle(a.base, a.dir, m.center, math.dist(m.start, m.center) + grow, ref)
            return None if q is None else _add(m.center, _unit(_sub(q, m.center)), rho_b)
        d = _direction(m, False)
        if a.arc:
            return _meet_line_circle(start_b, d, a.centre, a.rho, ref)
        return _meet_lines(a.base, a.dir, start_b, d)

"""The 1969 bisector / offset-intersection rule (``corner="extend"``) and its use
for radius-error correction of an already compensated path."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ._nosecomp_base import (
    _add,
    _left,
    _meet_circles,
    _meet_line_circle,
    _sub,
    _sweep,
    _wrap,
    resolve_setting,
    tip_offset,
)

_TANGENT_RAD = 0.01  # junctions turning less than this are tangent


@dataclass(frozen=True)
class _Seg:
    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    line: int
    center: tuple[float, float] | None
    comp: bool

    @property
    def arc(self) -> bool:
        return self.kind in ("cw", "ccw")


def _tangent(seg: _Seg, at_end: bool):
    """Travel direction at an end of ``seg`` (not normalised)."""
    if not seg.arc:
        return _sub(seg.end, seg.start)
    rad = _sub(seg.end if at_end else seg.start, seg.center)
    t = (rad[1], -rad[0])  # radial turned +90 deg in the drawing frame: CCW travel
    return t if seg.kind == "ccw" else (-t[0], -t[1])


def _normal(seg: _Seg, at_end: bool, s: float):
    """Unit offset direction (side ``s``: +1 left, -1 right) at an end of ``seg``."""
    n = _left(_tangent(seg, at_end))
    return (s * n[0], s * n[1])


def _offset_radius(seg: _Seg, s: float, off: float) -> float:
    radius = math.dist(seg.start, seg.center)
    return radius - s * off if seg.kind == "ccw" else radius + s * off


def _junction(a: _Seg, b: _Seg, s: float, off: float, err) -> tuple[float, float]:
    """Offset point at the junction of compensated ``a`` -> ``b`` (the extend rule)."""
    p = a.end
    n1, n2 = _normal(a, True, s), _normal(b, False, s)
    cos_a = max(-1.0, min(1.0, n1[0] * n2[0] + n1[1] * n2[1]))
    if 1.0 + cos_a < 2e-4:  # cos(alpha/2) < 0.01: the path reverses
        raise err(b.line, "the path reverses here; the offset corner would run off to infinity")
    guess = _add(p, ((n1[0] + n2[0]) / (1 + cos_a), (n1[1] + n2[1]) / (1 + cos_a)), off)
    turn = math.acos(cos_a)
    if not a.arc and not b.arc:
        return guess
    if turn < _TANGENT_RAD:
        arc = a if a.arc else b
        return _add(p, _normal(arc, arc is a, s), off)
    if a.arc and b.arc:
        q = _meet_circles(
            a.center, _offset_radius(a, s, off), b.center, _offset_radius(b, s, off), guess
        )
    else:
        line, arc = (b, a) if a.arc else (a, b)
        n = _normal(line, False, s)
        q = _meet_line_circle(
            _add(line.start, n, off),
            _sub(line.end, line.start),
            arc.center,
            _offset_radius(arc, s, off),
            guess,
        )
    if q is None:
        raise err(b.line, "the offset curves do not meet at this corner (use corner='arc')")
    return q


def _offset_chain(segs: Sequence[_Seg], s: float, off: float, shift, err) -> list[tuple]:
    """Offset the compensated members of a chain by ``off`` (side ``s``), extend rule."""
    n = len(segs)
    pts = [segs[0].start] + [seg.end for seg in segs]
    new = list(pts)
    for k in range(n + 1):
        before = segs[k - 1] if k > 0 else None
        after = segs[k] if k < n else None
        cb = before is not None and before.comp
        ca = after is not None and after.comp
        if cb and ca:
            q = _junction(before, after, s, off, err)
        elif cb:
            q = _add(pts[k], _normal(before, True, s), off)
        elif ca:
            q = _add(pts[k], _normal(after, False, s), off)
        else:
            continue
        new[k] = _add(q, shift)
    raw = []
    for k, seg in enumerate(segs):
        a, b = new[k], new[k + 1]
        center = None
        if seg.arc:
            center = _add(seg.center, shift) if seg.comp else seg.center
            if not seg.comp and (a != pts[k] or b != pts[k + 1]):
                raise err(seg.line, "an uncompensated arc cannot meet a compensated move")
            if seg.comp:
                rad = _offset_radius(seg, s, off)
                if rad <= 0:
                    raise err(seg.line, "arc radius not larger than the tool radius on its inside")
                ccw = seg.kind == "ccw"
                sweep = _sweep(seg.start, seg.center, seg.end, ccw)
                da = _wrap(_sweep(seg.start, seg.center, _sub(a, shift), ccw))
                db = _wrap(_sweep(seg.end, seg.center, _sub(b, shift), ccw))
                if sweep + db - da < 1e-12:
                    raise err(seg.line, "arc in a concave corner the tool cannot reach (gouge)")
        elif seg.comp and seg.start != seg.end:
            d0, d1 = _sub(seg.end, seg.start), _sub(b, a)
            if d0[0] * d1[0] + d0[1] * d1[1] <= 0:
                raise err(
                    seg.line,
                    "concave corner the tool cannot reach (gouge): the "
                    "offset move would run backwards",
                )
        raw.append((seg.kind, b, seg.line, center))
    return raw


def _extend(program, tools, gouge) -> list[tuple]:
    """Nose compensation by the extend rule, one chain per G41/G42 ... G40 run."""
    raw: list[tuple] = []
    run: list[_Seg] = []
    state = None  # (side sign, radius, tip shift) while compensating

    def flush():
        if run:
            raw.extend(_offset_chain(run, *state, gouge))
            run.clear()

    for ev in program.events:
        if not hasattr(ev, "kind"):
            flush()
            state = None
            if ev.setting is not None:
                side, r, orient = resolve_setting(ev.setting, tools, program.name)
                if r > 0:
                    state = (1.0 if side == "left" else -1.0, r, tip_offset(orient, r))
            continue
        if state is None or ev.comp is None:
            raw.append((ev.kind, ev.end, ev.line, ev.center))
        elif ev.entry:
            if ev.is_arc:
                raise gouge(ev.line, "the extend rule needs a straight entry move")
            if math.dist(ev.start, ev.end) <= state[1]:
                raise gouge(
                    ev.line,
                    "the move that switches compensation on must end farther than the nose "
                    "radius from where it starts",
                )
            run.append(_Seg(ev.kind, ev.start, ev.end, ev.line, ev.center, False))
        elif ev.start != ev.end:
            run.append(_Seg(ev.kind, ev.start, ev.end, ev.line, ev.center, True))
    flush()
    return raw

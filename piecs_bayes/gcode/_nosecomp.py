"""Tool-nose (cutter) radius compensation for lathe programs: G41/G42/G40 resolved.

The programmed contour is the part's edge; the nose centre runs one nose radius away
from it, left (G41) or right (G42) of travel in the drawing frame, and the machine
positions the controlled point, the imaginary tip (`tip_offset` by LinuxCNC's lathe
orientations). [`compensated_path`][] gives the controlled point's moves
([`PathMove`][], mm, radius X) of a [`GcodeProgram`][], with `corner="arc"` (default:
what LinuxCNC does) or `corner="extend"` (the 1969 bisector rule); a gouge or a
LinuxCNC quirk the rule cannot follow raises `AnalysisError` naming the block.
[`nose_compensate`][] rewrites the program without compensation (lines outside it
byte-identical) and refuses G41/G42 on the material side (`check_auto_sides`,
`check_comp_sides`); [`correct_radius_error`][] corrects an already
compensated path for a nose radius that differs from plan.

The corner rules, tip offsets and gouges: docs/models/nose_compensation.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field

from ..errors import AnalysisError, InputError

# --- Plane geometry, tip offsets and the tool behind a request -----------------------
# Drawing frame: z right, x up, angles counter-clockwise from +z. `tip_offset` is the
# offset (dx, dz) from the nose centre to the controlled point (the imaginary tip) by
# LinuxCNC's lathe orientations 0-9; `resolve_setting` the side, radius and
# orientation of a G41/G42 (tool table) or G41.1/G42.1 request. `_EPS = 1e-12` is the
# relative size under which a determinant, a distance between centres or a sweep
# counts as zero: far below any length a program can state, far above float64
# round-off of millimetre coordinates.

_EPS = 1e-12
_TIP = {
    0: (0, 0),
    1: (-1, 1),
    2: (-1, -1),
    3: (1, -1),
    4: (1, 1),
    5: (0, 1),
    6: (-1, 0),
    7: (0, -1),
    8: (1, 0),
    9: (0, 0),
}


def tip_offset(orientation: int, radius: float) -> tuple[float, float]:
    """``(dx, dz)`` from the nose centre to the imaginary tip for a lathe
    orientation 0-9 (0 and 9: the nose centre itself)."""
    if orientation not in _TIP:
        raise InputError(f"tool orientation must be 0-9, got {orientation!r}")
    dx, dz = _TIP[orientation]
    return (dx * radius, dz * radius)


class UniformNose:
    """Stands in for a tool table: every G41/G42 tool has ``radius`` (mm), orientation 0."""

    def __init__(self, radius: float):
        self.radius = float(radius)


def resolve_setting(setting, tools, name: str | None) -> tuple[str, float, int]:
    """``(side, radius, orientation)`` of a G41/G42/G41.1/G42.1 request.

    A negative diameter puts the tool on the other side; the radius returned
    is never negative. Raises InputError when the tool cannot be found.
    """
    where = {"file": name, "line": setting.line}
    if setting.diameter_mm is not None:
        diameter, orientation = setting.diameter_mm, setting.orientation or 0
    elif isinstance(tools, UniformNose):
        diameter, orientation = 2.0 * tools.radius, 0
    elif tools is None:
        raise InputError(
            f"{setting.code} reads the nose radius from a tool table: pass a tool table "
            "or a nose radius",
            **where,
        )
    elif setting.tool is None:
        raise InputError(f"{setting.code} with no tool loaded (T.. M6) and no D word", **where)
    else:
        entry = tools.get(setting.tool)
        if entry is None:
            raise InputError(f"T{setting.tool} is not in the tool table", **where)
        diameter, orientation = entry.diameter_mm, entry.orientation
    side = setting.side
    if diameter < 0:
        side = "left" if side == "right" else "right"
    return side, abs(diameter) / 2.0, int(orientation)


# -- plane vectors, (x, z) -----------------------------------------------------


def _add(p, v, k: float = 1.0):
    return (p[0] + k * v[0], p[1] + k * v[1])


def _sub(p, q):
    return (p[0] - q[0], p[1] - q[1])


def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1]


def _cross(a, b) -> float:
    """z-up cross product in the drawing frame: > 0 when ``b`` is left of ``a``."""
    return a[1] * b[0] - a[0] * b[1]


def _unit(v):
    n = math.hypot(*v)
    return (v[0] / n, v[1] / n)


def _left(d):
    """Unit normal to the left of travel direction ``d`` (drawing frame)."""
    u = _unit(d)
    return (u[1], -u[0])


def _wrap(a: float) -> float:
    """``a`` brought into (-pi, pi]."""
    a = math.fmod(a, 2 * math.pi)
    if a > math.pi:
        a -= 2 * math.pi
    elif a <= -math.pi:
        a += 2 * math.pi
    return a


def _sweep(start, centre, end, ccw: bool) -> float:
    """Angle swept from ``start`` to ``end`` about ``centre`` in the travel
    direction, in (0, 2 pi] (a full turn when the points coincide in angle)."""
    a0 = math.atan2(start[0] - centre[0], start[1] - centre[1])
    a1 = math.atan2(end[0] - centre[0], end[1] - centre[1])
    d = math.fmod((a1 - a0) if ccw else (a0 - a1), 2 * math.pi)
    return d + 2 * math.pi if d <= 0 else d


# -- intersections: the one nearest ``ref`` ------------------------------------


def _meet_lines(p, d, q, e):
    det = _cross(d, e)
    if abs(det) <= _EPS * math.hypot(*d) * math.hypot(*e):
        return None
    k = _cross(_sub(q, p), e) / det
    return _add(p, d, k)


def _meet_line_circle(p, d, c, rho, ref):
    u = _unit(d)
    w = _sub(p, c)
    b = _dot(w, u)
    disc = b * b - (_dot(w, w) - rho * rho)
    if disc < 0:
        return None
    h = math.sqrt(disc)
    return min((_add(p, u, -b - h), _add(p, u, -b + h)), key=lambda q: math.dist(q, ref))


def _meet_circles(c1, r1, c2, r2, ref):
    dist = math.dist(c1, c2)
    if dist <= _EPS * max(r1, r2):
        return None
    a = (dist * dist + r1 * r1 - r2 * r2) / (2 * dist)
    h2 = r1 * r1 - a * a
    if h2 < 0:
        return None
    e = _unit(_sub(c2, c1))
    base = _add(c1, e, a)
    n = (-e[1], e[0])
    h = math.sqrt(h2)
    return min((_add(base, n, h), _add(base, n, -h)), key=lambda q: math.dist(q, ref))


# --- The arc-corner rule (corner="arc"): what LinuxCNC does ------------------------
# Written for piecs_bayes from the documented behaviour of G40/G41/G42 (RS274/NGC and
# LinuxCNC user manuals) and from running LinuxCNC's rs274 interpreter as a black box
# on probe programs; no interpreter source code was consulted. `ArcCornerComp` runs a
# program on the nose centre: compensated lines move r to the tool side, arcs change
# radius by r; smooth corners join, convex ones get an arc of radius r about the
# programmed corner, concave ones are trimmed; the entry move ends r off its end.

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
        dialect = getattr(program, "dialect", None)
        self.fanuc_startup = dialect is not None and dialect.name in ("fanuc", "haas", "okuma")

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
        if a.entry and not a.arc and self.fanuc_startup:
            # Fanuc's start-up (type A): the entry block ends with the nose square to
            # the next block's start, whatever the angle between the two
            start_b = self._offset_start(m)
            self._finish(a, start_b, m.line)
            self.open = self._piece(m, start_b)
            return
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


# --- The 1969 bisector / offset-intersection rule (corner="extend") ---------------
# and its use for the radius-error correction of an already compensated path.

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


# --- The program: G41/G42/G40 resolved, sides checked, programs rewritten ----------


@dataclass(frozen=True)
class PathMove:
    """A move of the controlled point: ``kind`` in ``rapid | feed | cw | ccw``;
    ``(x, z)`` points in mm (x a radius); ``line`` is the source block."""

    kind: str
    start: tuple[float, float]
    end: tuple[float, float]
    line: int
    center: tuple[float, float] | None = None

    @property
    def is_arc(self) -> bool:
        return self.kind in ("cw", "ccw")


def _as_path(raw, start) -> tuple[PathMove, ...]:
    moves, pos = [], start
    for kind, end, line, center in raw:
        moves.append(PathMove(kind, pos, end, line, center))
        pos = end
    return tuple(moves)


def axial_air(kind: str):
    """The air side of a turned contour by its kind, for `check_comp_sides`: above an
    external (OD) contour, below an internal (bore) one, judged on moves that run
    mostly along Z (a face's air side depends on the step it belongs to)."""
    if kind not in ("external", "internal"):
        raise InputError(f"kind: got {kind!r}, expected 'external' or 'internal'", value=kind)
    up = (1.0, 0.0) if kind == "external" else (-1.0, 0.0)

    def air(m):
        dx, dz = m.end[0] - m.start[0], m.end[1] - m.start[1]
        return up if abs(dz) > 2.0 * abs(dx) else None

    return air


def check_comp_sides(program, air) -> None:
    """Refuse G41/G42 on the side that cuts into the material.

    G41 puts the nose left of travel, G42 right (drawing frame: z right, x up; a
    negative G41.1/G42.1 diameter swaps them). `air(move)` gives the unit direction
    of the air side of a programmed straight move (e.g. the outward normal of the
    profile feature it cuts, or `axial_air(kind)`), or None where it cannot say.
    A compensated move whose nose side points into the material is an `InputError`
    naming its line; a rapid cuts nothing and is not judged. (LinuxCNC's rs274 runs
    such a program: it judges gouges, not sides.)
    """
    for m in program.moves:
        if m.comp is None or m.entry or m.is_arc or m.kind == "rapid" or m.start == m.end:
            continue
        n_air = air(m)
        if n_air is None:
            continue
        side = m.comp.side
        if m.comp.diameter_mm is not None and m.comp.diameter_mm < 0:
            side = "left" if side == "right" else "right"
        left = _left((m.end[0] - m.start[0], m.end[1] - m.start[1]))
        nose = left if side == "left" else (-left[0], -left[1])
        if nose[0] * n_air[0] + nose[1] * n_air[1] < -0.5:
            other = "G42" if side == "left" else "G41"
            raise InputError(
                f"{m.comp.code} (line {m.comp.line}) puts the tool nose {side} of travel, on "
                f"the material side of the contour at line {m.line}: it would cut into the "
                f"part; use {other}",
                file=getattr(program, "name", None),
                line=m.line,
                value=m.comp.code,
            )


def check_auto_sides(program) -> None:
    """Refuse a run whose G41/G42 the moves in air contradict or do not confirm
    (`comp_sides`, `side_error`), then judge each compensated move of a run by the
    side they say is air (`check_comp_sides`), as with a `kind` given. `program` is
    the program as read (its canned cycles' own moves are part of the evidence)."""
    from ._contour import contour_view
    from ._material_side import comp_sides, run_air, side_error

    airs = {}
    for run in comp_sides(program):
        err = side_error(run, program)
        if err is not None:
            raise err
        airs[run.comp] = run_air(run)
    blocks = contour_view(program)
    check_comp_sides(blocks, lambda m: airs[m.comp](m) if m.comp in airs else None)


def compensated_path(
    program,
    *,
    corner: str = "arc",
    tool_table: Mapping | None = None,
    nose_radius: float | None = None,
    start: tuple[float, float] | None = None,
) -> tuple[PathMove, ...]:
    """The controlled point's path for a program with G41/G42/G40 (mm, radius X).

    **Arguments:**

    - `program`: a :class:`~piecs_bayes.gcode.GcodeProgram`.
    - `corner`: ``"arc"`` (LinuxCNC's corners) or ``"extend"`` (1969 bisector rule).
    - `tool_table`: ``{tool: ToolEntry}`` for G41/G42 (see
      :func:`~piecs_bayes.gcode.read_tool_table`).
    - `nose_radius`: instead of a tool table, the nose radius (mm) of every
      G41/G42 tool, orientation 0 (G41.1/G42.1 keep their own D and L).
    - `start`: the tool position before the first move (default: the one the
      program was read with).

    **Returns:** one :class:`PathMove` per motion of the controlled point, each
    with the line of the block that produced it. Raises
    :class:`~piecs_bayes.errors.AnalysisError` (with ``.line``) on a gouge.
    """
    if nose_radius is not None:
        if isinstance(nose_radius, bool) or not (
            isinstance(nose_radius, int | float) and math.isfinite(nose_radius) and nose_radius > 0
        ):
            raise InputError(
                f"nose radius must be a finite number > 0 (mm), got {nose_radius!r}",
                value=nose_radius,
            )
        tool_table = UniformNose(float(nose_radius))
    if start is None:
        start = tuple(program.options.start) if program.options is not None else (0.0, 0.0)
    comp = ArcCornerComp(program, tool_table, start)
    if corner == "arc":
        raw = comp.run()
    elif corner == "extend":
        raw = _extend(program, tool_table, comp.gouge)
    else:
        raise InputError(f"unknown corner rule {corner!r}; expected 'arc' or 'extend'")
    path = _as_path(raw, start)
    programmed = {m.line: m for m in program.moves}
    for m in path:
        if m.is_arc and math.dist(m.start, m.end) < 1e-7:
            src = programmed.get(m.line)
            if src is None or math.dist(src.start, src.end) >= 1e-7:
                raise comp.gouge(
                    m.line, "compensation would turn this arc into a full circle (gouge)"
                )
    return path


@dataclass(frozen=True)
class NoseCompResult:
    """A program with compensation resolved: ``text`` has no G41/G42/G40 words."""

    text: str
    path: tuple[PathMove, ...]
    corner: str
    changed_lines: tuple[int, ...]

    def __repr__(self) -> str:
        return (
            f"NoseCompResult(corner={self.corner!r}, {len(self.path)} moves, "
            f"{len(self.changed_lines)} source lines rewritten)"
        )


def nose_compensate(
    program,
    *,
    corner: str = "arc",
    tool_table: Mapping | None = None,
    nose_radius: float | None = None,
    start: tuple[float, float] | None = None,
    kind: str | None = "auto",
) -> NoseCompResult:
    """Resolve nose-radius compensation into an equivalent program without it.

    Lines outside compensation stay byte-identical; compensated blocks are
    rewritten (their other words and comments kept) with the controlled
    point's moves, extra corner arcs on lines of their own. Arguments as for
    :func:`compensated_path`; `kind` says where the material is: ``"external"``,
    ``"internal"``, ``"auto"`` (each run's moves in air say it, `comp_sides`: a run
    they do not tell is refused, naming ``--kind``) or None (not checked); a G41/G42
    on the material side is refused (`check_comp_sides`).
    """
    from ._contour import contour_view
    from ._writer import write_path_program

    if kind == "auto":
        check_auto_sides(program)
    elif kind is not None:  # a cycle's sides are its contour's, not its passes'
        check_comp_sides(contour_view(program), axial_air(kind))
    path = compensated_path(
        program, corner=corner, tool_table=tool_table, nose_radius=nose_radius, start=start
    )
    text, changed = write_path_program(program, path)
    return NoseCompResult(text, path, corner, changed)


def correct_radius_error(
    path: Sequence,
    *,
    planned: float,
    actual: float,
    side: str,
    orientation: int = 0,
    compensated: Callable[[object], bool] | Collection[int] | None = None,
) -> tuple[PathMove, ...]:
    """Correct an already compensated path for a nose radius that differs from plan.

    Every compensated move is offset by ``dr = actual - planned`` to the
    compensation ``side`` (``"left"``/``"right"`` of travel; a negative ``dr``
    offsets the other way): lines move parallel, arcs change radius by ``dr``
    (convex corner arcs of radius ``planned`` become ``actual``), and the
    junctions follow the 1969 rule (bisector ``dr / cos(alpha / 2)`` between
    compensated moves, ``dr`` normal where an uncompensated move meets one,
    zero at the far end of an uncompensated move). The imaginary tip moves with
    the radius too: ``tip_offset(orientation, dr)`` is added to compensated
    points.

    **Arguments:**

    - `path`: moves with ``kind, start, end, line, center`` (``PathMove`` or
      ``Motion``), mm, radius X.
    - `planned`, `actual`: nose radii (mm).
    - `side`: ``"left"`` or ``"right"`` (G41 / G42).
    - `orientation`: the tool orientation 0-9.
    - `compensated`: which moves were compensated: a predicate on a move or
      the source line numbers (default: every feed move and arc, no rapid).

    **Returns:** the corrected moves. Raises AnalysisError on a gouge.
    """
    if side not in ("left", "right"):
        raise InputError(f"side must be 'left' or 'right', got {side!r}")
    if planned < 0 or actual < 0:
        raise InputError(f"radii must be >= 0, got planned={planned} actual={actual}")
    dr = actual - planned
    if compensated is None:
        is_comp = lambda m: m.kind != "rapid"  # noqa: E731
    elif callable(compensated):
        is_comp = compensated
    else:
        lines = {int(n) for n in compensated}
        is_comp = lambda m: m.line in lines  # noqa: E731
    segs = [
        _Seg(m.kind, tuple(m.start), tuple(m.end), m.line, m.center, bool(is_comp(m)))
        for m in path
        if tuple(m.start) != tuple(m.end)
    ]
    if not segs:
        return ()

    def err(line, msg):
        e = AnalysisError(f"line {line}: {msg}")
        e.line = line
        return e

    s = 1.0 if side == "left" else -1.0
    raw = _offset_chain(segs, s, dr, tip_offset(orientation, dr), err)
    return _as_path(raw, segs[0].start)

"""Where the material is around each nose-compensation run, read from the moves in air.

A rapid, the move that switches compensation on (the entry) and the one that switches
it off (the exit) pass through air. A turned contour runs along Z (a shaft, a bore) or
along X (a face); a point of such a move within the contour's span along that axis
(its ends included) and beyond every point of the contour there across it (above or
below it, in front of or behind it) says that side is air: the material is on the
other, out to the axis or to wherever the part ends, which the program does not say.
[`comp_sides`][] gathers this evidence for every run ([`RunSide`][], one
[`AirWitness`][] per move and side): the rapids just before the entry, the entry, the
rapids under compensation, the exit and the rapids after it, until the tool cuts, is
changed or leaves the work frame. [`side_error`][] refuses a run's G41/G42 that puts
the nose on the material side, or that the moves do not confirm (none beside the
contour, or some on each side), naming ``--kind``. The rules and what they assume:
docs/models/nose_compensation.md, "The material side".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ._contour import CYCLE_CODES, contour_view
from ._program import CompSetting

#: moves that leave the work frame (reference returns, machine coordinates): where
#: they pass in the part's frame is not known
_OFF_FRAME = frozenset(("G28", "G30", "G53"))
#: mm: a point closer than this to the contour, across it, is on it; a span end
#: closer than this is the end (a program's resolution)
ON_CONTOUR_MM = 0.01
_CELLS = 1_000_000  # points x segments compared at once (memory, not accuracy)
_ROLES = {
    "approach": "the rapid before it",
    "entry": "the entry move",
    "rapid": "the rapid under compensation",
    "exit": "the exit move",
    "retract": "the rapid after it",
    "cycle": "a rapid of its canned cycle",
}
#: side names by the axis the contour runs along and the sign across it
_SIDE = {("z", 1): "above", ("z", -1): "below", ("x", 1): "in front of", ("x", -1): "behind"}
_WHAT = {
    ("z", 1): "an OD (material between the contour and the axis)",
    ("z", -1): "a bore (material outside the contour)",
    ("x", 1): "a face seen from the front (material behind it)",
    ("x", -1): "a back face (material in front of it)",
}


@dataclass(frozen=True)
class AirWitness:
    """A move through air that passes beside a run's contour.

    ``role``: ``"approach"`` (a rapid just before the entry), ``"entry"``, ``"rapid"``
    (under compensation), ``"exit"``, ``"retract"`` (a rapid after the exit) or
    ``"cycle"`` (a rapid of the canned cycle whose finish contour the run is);
    ``line`` its line; ``point`` ``(x, z)`` (mm, x a radius) where it passes;
    ``feature`` the line of the contour's move it passes nearest across the axis;
    ``sign`` the side it is on across the contour's axis (+1: +X of a contour along
    Z, +Z of one along X; -1 the other): that side is air."""

    role: str
    line: int
    point: tuple[float, float]
    feature: int
    sign: int


@dataclass(frozen=True)
class RunSide:
    """One compensation run and what the moves in air say of its material side.

    ``comp`` is its G41/G42 (`CompSetting`); ``nose`` the side of travel that word
    puts the nose on (a negative G41.1/G42.1 diameter swaps it); ``lines`` the first
    and last line of its contour; ``axis`` ``"z"`` (a shaft or a bore) or ``"x"`` (a
    face): the one it runs along; ``word`` the side across that axis the nose is on
    (+1/-1, most of the contour's length along the axis; 0 on a tie); ``witnesses``
    the moves in air beside it.
    """

    comp: CompSetting
    nose: str
    lines: tuple[int, int]
    axis: str
    word: int
    witnesses: tuple[AirWitness, ...]

    @property
    def air(self) -> int:
        """The side across the axis the moves say is air (+1/-1), 0 when none say or
        they differ."""
        signs = {w.sign for w in self.witnesses}
        return signs.pop() if len(signs) == 1 else 0

    @property
    def kind(self) -> str | None:
        """``"external"``/``"internal"`` for a contour along Z whose air side is known."""
        if self.axis != "z" or not self.air:
            return None
        return "external" if self.air > 0 else "internal"

    @property
    def verdict(self) -> str:
        """``"agrees"``, ``"contradicts"`` (the nose on the material side),
        ``"undecided"`` (no move in air beside the contour) or ``"conflicting"``
        (air on both sides)."""
        if not self.witnesses:
            return "undecided"
        if not self.air:
            return "conflicting"
        return "contradicts" if self.word == -self.air else "agrees"

    def side_name(self, sign: int) -> str:
        """``"above"``, ``"below"``, ``"in front of"`` or ``"behind"``."""
        return _SIDE[(self.axis, sign)]

    def what(self, air: int) -> str:
        """What the contour is with air on side `air`: an OD, a bore, a face."""
        return _WHAT[(self.axis, air)]

    def summary(self, program) -> str:
        """One line for `gcode check`: the air side, the move that says it, and whether
        the G41/G42 agrees (`program` gives the coordinates as written)."""
        c, (first, last) = self.comp, self.lines
        head = f"{c.code} (line {c.line}), contour lines {first}-{last}"
        if self.verdict == "undecided":
            return f"{head}: no move in air passes beside it: the side is not told"
        if self.verdict == "conflicting":
            return f"{head}: moves in air pass on both sides of it: the side is not told"
        w = next(w for w in self.witnesses if w.sign == self.air)
        seen = f"{_witness_text(w, self, program)}: {self.what(self.air)}"
        if self.verdict == "contradicts":
            return f"{head}: {seen}; {c.code} puts the nose on the material side"
        return f"{head}: {seen}; {c.code} agrees"


class MaterialSideWarning(UserWarning):
    """`gcode check`: a compensation run whose material side the moves do not tell,
    or whose G41/G42 puts the nose on the side they say is the material."""


def comp_sides(program) -> tuple[RunSide, ...]:
    """What the moves in air say of each compensation run of `program` that cuts
    something. A canned cycle's run is its finish contour (`contour_view`), judged by
    the rapids the cycle makes."""
    view = list(contour_view(program).moves)
    raw = list(program.moves)
    where = {id(m): k for k, m in enumerate(raw)}
    raw_runs = dict(_runs(raw))
    out = []
    for i0, i1 in _runs(view):
        features = [m for m in view[i0 + 1 : i1] if _is_feature(m)]
        if not features:
            continue  # nothing cut: nothing to put on a side
        geo = _Contour(features)
        k0 = where.get(id(view[i0]))
        if k0 is not None and k0 in raw_runs:
            air = _air_moves(program, raw, k0, raw_runs[k0])
        else:
            air = _cycle_air(program, raw, view[i0:i1])
        nose = _nose(view[i0].comp)
        out.append(
            RunSide(
                comp=view[i0].comp,
                nose=nose,
                lines=(features[0].line, features[-1].line),
                axis="z" if geo.along == 1 else "x",
                word=_word(features, nose, geo.along),
                witnesses=tuple(_witnesses(air, geo)),
            )
        )
    return tuple(out)


def run_air(run: RunSide):
    """``air(move)`` for `check_comp_sides`: the unit air direction ``(x, z)`` for a
    straight move along the run's axis, None for the others or when ``run.air`` is 0."""
    if not run.air:
        return lambda m: None
    along = 1 if run.axis == "z" else 0
    up = (float(run.air), 0.0) if along == 1 else (0.0, float(run.air))

    def air(m):
        d = (m.end[0] - m.start[0], m.end[1] - m.start[1])
        return up if abs(d[along]) > 2.0 * abs(d[1 - along]) else None

    return air


# --- what is wrong, in words --------------------------------------------------------------


def side_error(run: RunSide, program) -> InputError | None:
    """The error that refuses `run`'s G41/G42 in `program`, None when the moves in
    air agree with it."""
    verdict = run.verdict
    if verdict == "agrees":
        return None
    c, name = run.comp, getattr(program, "name", None)
    if verdict == "contradicts":
        w = next(w for w in run.witnesses if w.sign == run.air)
        other = "G42" if c.side == "left" else "G41"
        msg = (
            f"{c.code} (line {c.line}) puts the tool nose {run.nose} of travel, "
            f"{run.side_name(run.word)} the contour (lines {run.lines[0]}-{run.lines[1]}), "
            f"but {_witness_text(w, run, program)}: the air is {run.side_name(run.air)} it, "
            f"so it is {run.what(run.air)} and the nose would cut into the part; use "
            f"{other}. (If that move passes over a ring's wall or through a tube's bore, "
            f"say where the material is: {_KIND_WORDS})"
        )
        return InputError(msg, file=name, line=c.line, value=c.code)
    if verdict == "conflicting":
        a, b = (next(w for w in run.witnesses if w.sign == s) for s in (1, -1))
        why = (
            f"moves in air pass on both sides of it ({_witness_text(a, run, program)}; "
            f"{_witness_text(b, run, program)})"
        )
    else:
        why = (
            "no move in air passes beside it (the entry, the exit and the rapids around "
            "them lie beyond its ends, or there are none)"
        )
    msg = (
        f"{c.code} (line {c.line}), contour lines {run.lines[0]}-{run.lines[1]}: {why}, so "
        f"the program does not say which side the material is on, and {c.code} alone is "
        f"not trusted with it; say where it is: {_KIND_WORDS}"
    )
    return InputError(msg, file=name, line=c.line, value=c.code)


_KIND_WORDS = (
    "--kind external (an OD: the material towards the axis) or --kind internal (a bore), "
    "as a study's [profile] kind says it"
)


def _witness_text(w: AirWitness, run: RunSide, program) -> str:
    """``"the exit move (line 10) passes above the contour at X40.0000 Z-35.0000 (mm,
    X a diameter), across from line 9"``."""
    return (
        f"{_ROLES[w.role]} (line {w.line}) passes {run.side_name(w.sign)} the contour at "
        f"{_as_programmed(program, w.line, w.point)}, across from line {w.feature}"
    )


def _as_programmed(program, line: int, point) -> str:
    """A point as the program writes it at `line`: X a diameter in diameter mode,
    in the program's units."""
    try:
        state = program.state(line)
        units, diameter = state.units, state.diameter
    except (AttributeError, IndexError, KeyError):
        units, diameter = "mm", False
    k = 25.4 if units == "in" else 1.0
    x, z = point[0] * (2.0 if diameter else 1.0) / k, point[1] / k
    mode = "a diameter" if diameter else "a radius"
    return f"X{x:.4f} Z{z:.4f} ({units}, X {mode})"


# --- the runs and their moves in air ------------------------------------------------------


def _runs(moves) -> list[tuple[int, int]]:
    """``(i0, i1)``: a run's first move (its entry) and the index after its last."""
    out, i = [], 0
    while i < len(moves):
        m = moves[i]
        if m.comp is None:
            i += 1
            continue
        j = i + 1
        while j < len(moves) and moves[j].comp is m.comp and not moves[j].entry:
            j += 1
        out.append((i, j))
        i = j
    return out


def _is_feature(m) -> bool:
    return m.kind != "rapid" and m.y is None and m.start != m.end


def _in_frame(m) -> bool:
    return m.via not in _OFF_FRAME and m.y is None


def _plain_rapid(program, m, beside) -> bool:
    """A rapid without compensation, in the work frame, with the tool of the move
    `beside` it (a tool change ends the moves that say something of a contour)."""
    if m.kind != "rapid" or m.comp is not None or not _in_frame(m):
        return False
    if m.via in CYCLE_CODES or beside.via in CYCLE_CODES:
        return True  # a cycle changes no tool (and runs lines another tool ran too)
    return program.state(m.line).tool == program.state(beside.line).tool


def _before(program, moves, k: int) -> list[tuple[str, int]]:
    """The rapids that end at move `k`, back to a cut, another tool or another run
    (the exit of a run before says nothing of this one)."""
    out: list[tuple[str, int]] = []
    k -= 1
    while k >= 0 and _plain_rapid(program, moves[k], moves[k + 1]) and _joined(moves, k + 1):
        if k > 0 and moves[k - 1].comp is not None:
            break
        out.insert(0, ("approach", k))
        k -= 1
    return out


def _after(program, moves, k: int) -> list[tuple[str, int]]:
    """The rapids that follow move `k`, up to a cut, another tool or another run."""
    out: list[tuple[str, int]] = []
    k += 1
    while k < len(moves) and _plain_rapid(program, moves[k], moves[k - 1]) and _joined(moves, k):
        out.append(("retract", k))
        k += 1
    return out


def _joined(moves, k: int) -> bool:
    """Move `k` starts where move ``k - 1`` ended, in the work frame: not the program's
    first move (from where the reader assumes), nor one after a reference return, a
    machine-coordinate move or a shift of the frame (G92, G10, another G5x)."""
    if k <= 0 or not _in_frame(moves[k - 1]):
        return False
    return math.dist(moves[k].start, moves[k - 1].end) <= 1e-6


def _paths(moves, picked):
    """``(role, move, path)``: ``path`` False where only the end point is known
    (`_joined`)."""
    return [(role, moves[k], _joined(moves, k)) for role, k in picked if _in_frame(moves[k])]


def _air_moves(program, moves, i0, i1):
    """The moves in air around run ``[i0, i1)`` of `moves`: the rapids before its
    entry, the entry, the rapids under compensation, the exit and the rapids after."""
    picked = _before(program, moves, i0)
    if moves[i0].entry:
        picked.append(("entry", i0))
    picked += [("rapid", k) for k in range(i0 + 1, i1) if moves[k].kind == "rapid"]
    if i1 < len(moves) and moves[i1].comp is None:
        picked += [("exit", i1), *_after(program, moves, i1)]
    return _paths(moves, picked)


def _cycle_air(program, moves, run):
    """The moves in air around the canned cycle whose finish contour is `run`: the
    rapids before it, every rapid it makes (its passes' retracts, its return to the
    start point) and the rapids after it."""
    ids = {id(m) for m in run}
    cycle = next((c for c in program.cycles if any(id(m) in ids for m in c.contour)), None)
    if cycle is None or cycle.move_index >= len(moves):
        return []
    i0 = i1 = cycle.move_index
    while i1 < len(moves) and moves[i1].via == moves[i0].via:
        i1 += 1
    picked = _before(program, moves, i0)
    picked += [("cycle", k) for k in range(i0, i1) if moves[k].kind == "rapid"]
    return _paths(moves, picked + _after(program, moves, i1 - 1))


def _witnesses(air, geo) -> list[AirWitness]:
    """One witness per move in air and side it passes on (its point farthest from
    the contour across the axis)."""
    out = []
    for role, m, path in air:
        pts = _samples(m, geo.step) if path else np.array([m.end], dtype=float)
        best: dict[int, tuple] = {}
        for p, sign, line, gap in geo.beside(pts):
            if sign not in best or gap > best[sign][2]:
                best[sign] = (p, line, gap)
        out += [AirWitness(role, m.line, p, line, s) for s, (p, line, _) in best.items()]
    return out


def _samples(m, step: float) -> np.ndarray:
    """Points along move `m` (its ends included) about `step` apart (at most 401)."""
    ratio = m.length / step
    n = int(min(400, max(8, math.ceil(ratio)))) if math.isfinite(ratio) else 400
    if m.is_arc:
        return _arc_points(m, n)
    t = np.linspace(0.0, 1.0, n + 1)
    a, b = np.asarray(m.start, float), np.asarray(m.end, float)
    return a + t[:, None] * (b - a)


def _arc_points(m, n: int) -> np.ndarray:
    """``n + 1`` points along arc move `m`, from its start to its end."""
    c = np.asarray(m.center, float)
    r0 = np.asarray(m.start, float) - c
    a0 = math.atan2(r0[0], r0[1])  # from +z towards +x: counter-clockwise (z right, x up)
    sweep = _turn(m)
    ang = a0 + (sweep if m.ccw else -sweep) * np.linspace(0.0, 1.0, n + 1)
    rad = math.hypot(*r0)
    return np.stack([c[0] + rad * np.sin(ang), c[1] + rad * np.cos(ang)], 1)


class _Contour:
    """The run's features as segments (arcs as chords of 2 degrees at most), the axis
    they run along (``along``: 1 for Z, 0 for X) and their span on it."""

    def __init__(self, features):
        pieces, lines = [], []
        for m in features:
            pts = (
                _arc_points(m, max(2, math.ceil(math.degrees(_turn(m)) / 2)))
                if m.is_arc
                else np.array([m.start, m.end], float)
            )
            pieces.append(np.stack([pts[:-1], pts[1:]], 1))
            lines += [m.line] * (len(pts) - 1)
        self.segs = np.concatenate(pieces)  # (S, 2 ends, (x, z))
        self.lines = np.asarray(lines)
        pts = self.segs.reshape(-1, 2)
        extent = np.ptp(pts, axis=0)
        self.along = 1 if extent[1] >= extent[0] else 0
        self.span = (float(pts[:, self.along].min()), float(pts[:, self.along].max()))
        self.step = max(float(extent.max()), 1.0) / 200.0

    def beside(self, pts: np.ndarray):
        """``(point, sign, feature line, gap)`` for each point within the span and
        beyond every point of the contour there across the axis, by ``gap`` (mm)."""
        chunk = max(1, _CELLS // len(self.segs))  # points x segments held at once
        for k in range(0, len(pts), chunk):
            with np.errstate(all="ignore"):  # a huge coordinate compares as none
                found = list(self._beside(pts[k : k + chunk]))
            yield from found

    def _beside(self, pts: np.ndarray):
        a, c, tol = self.along, 1 - self.along, ON_CONTOUR_MM
        u, v = pts[:, a][:, None], pts[:, c]
        u0, u1 = self.segs[None, :, 0, a], self.segs[None, :, 1, a]
        v0, v1 = self.segs[None, :, 0, c], self.segs[None, :, 1, c]
        hit = (np.minimum(u0, u1) - tol <= u) & (u <= np.maximum(u0, u1) + tol)
        du = u1 - u0
        flat = np.abs(du) <= tol  # across the axis: both its ends are there
        at = v0 + np.clip((u - u0) / np.where(flat, 1.0, du), 0.0, 1.0) * (v1 - v0)
        low = np.where(hit, np.where(flat, np.minimum(v0, v1), at), np.inf)
        high = np.where(hit, np.where(flat, np.maximum(v0, v1), at), -np.inf)
        inside = (self.span[0] - tol <= u[:, 0]) & (u[:, 0] <= self.span[1] + tol)
        up = inside & (v > high.max(axis=1) + tol)
        down = inside & (v < low.min(axis=1) - tol)
        for k in np.flatnonzero(up | down):
            sign = 1 if up[k] else -1
            j = int(np.argmax(high[k]) if up[k] else np.argmin(low[k]))
            gap = v[k] - high[k, j] if up[k] else low[k, j] - v[k]
            yield (float(pts[k, 0]), float(pts[k, 1])), sign, int(self.lines[j]), float(gap)


def _turn(m) -> float:
    """The angle an arc move turns through, in (0, 2 pi]."""
    c = m.center
    a0 = math.atan2(m.start[0] - c[0], m.start[1] - c[1])
    a1 = math.atan2(m.end[0] - c[0], m.end[1] - c[1])
    d = math.fmod((a1 - a0) if m.ccw else (a0 - a1), 2 * math.pi)
    return d + 2 * math.pi if d <= 1e-12 else d


# --- the word's side ----------------------------------------------------------------------


def _nose(comp) -> str:
    side = comp.side
    if comp.diameter_mm is not None and comp.diameter_mm < 0:
        side = "left" if side == "right" else "right"
    return side


def _word(features, nose: str, along: int) -> int:
    """The side across the axis the nose is on (+1/-1) over most of the contour's
    length along it (arcs by their chords), 0 on a tie."""
    c = 1 - along
    total = 0.0
    for m in features:
        d = (m.end[0] - m.start[0], m.end[1] - m.start[1])
        left = (d[1], -d[0])  # left of travel, (x, z): left of +Z travel is +X
        n = left if nose == "left" else (-left[0], -left[1])
        total += math.copysign(abs(d[along]), n[c]) if n[c] else 0.0
    return 0 if total == 0.0 else (1 if total > 0 else -1)

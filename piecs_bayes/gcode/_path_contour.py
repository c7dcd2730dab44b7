"""The part contour of a tool path written without nose compensation (CAM output).

A CAM system often writes the path of the tool's controlled point itself: the imaginary
tip of a LinuxCNC orientation ``tip`` (1-8) or the nose centre (0, 9), one nose radius
``R`` away from the part, with arcs of radius R about each convex vertex of the part.
[`path_contour`][] takes such a run of cutting moves (between rapids; the first and the
last are the lead-in and the exit) back to the part's edge: the centre path offset by R
towards the material, its corner arcs shrunk to their vertices, the lines of a sharp
corner met (a concave corner; a path cannot tell it from a fillet of radius R). The
result is a [`FinishContour`][] whose ``comp`` is the compensation that would make this
path (G41.1/G42.1, D = 2R, L = ``tip``). [`path_targets`][] goes the other way for the
adjusted program: where each block of the path ends for an adjusted profile. The
material side is ``kind``, else the tip's (below the nose centre: an outside diameter).
The rules: docs/formats.md, "Study from the part program".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import AnalysisError, InputError
from ..geometry import ProfileError, profile_side
from ._contour import (
    CYCLE_CODES,
    ContourSegment,
    FinishContour,
    block_source,
    contour_view,
    program_title,
)
from ._dialect import LINUXCNC_DRILLING, LINUXCNC_PROBING
from ._nosecomp import tip_offset
from ._program import CompSetting

_EPS = 1e-9  # mm: a radius, a gap or a length below this is none
_VERTEX = 5e-3  # mm: an offset arc smaller than this is a vertex (the path's numbers round)


@dataclass(frozen=True)
class PathRole:
    """What a move of the path becomes in the part contour: ``"feature"`` (segment
    ``index``) or ``"corner"`` (an arc about the vertex that ends segment ``index``)."""

    line: int
    role: str
    index: int


#: moves that are never a part's contour: reference returns, machine moves, threads,
#: drilling and probing (and any move off the XZ plane, ``Motion.y``)
_NOT_CUTTING = frozenset(("G28", "G30", "G53", "G76")) | LINUXCNC_DRILLING | LINUXCNC_PROBING


def path_runs(program) -> list[list]:
    """The runs of cutting moves (feeds and arcs between rapids) of `program`."""
    runs: list[list] = []
    current: list = []
    for m in contour_view(program).moves:
        if m.kind == "rapid" or m.via in _NOT_CUTTING or m.via in CYCLE_CODES or m.y:
            if current:
                runs.append(current)
            current = []
        elif m.start != m.end:
            current.append(m)
    if current:
        runs.append(current)
    return [r for r in runs if len(r) >= 3]


def _kind(kind, tip, radius, name) -> str:
    if kind is not None:
        if kind not in ("external", "internal"):
            raise InputError(f"kind: got {kind!r}, expected 'external' or 'internal'", file=name)
        return kind
    dx = tip_offset(tip, radius)[0]
    if dx == 0:
        raise InputError(
            f"the tip orientation {tip} does not say where the material is: give the "
            "contour's kind (--kind external or internal)",
            file=name,
        )
    return "external" if dx < 0 else "internal"


def _left(d):
    """The unit normal left of direction `d` = (dx, dz) in the drawing frame."""
    n = math.hypot(d[0], d[1])
    return (d[1] / n, -d[0] / n)


def _dir(m, at_end: bool):
    if m.kind in ("cw", "ccw"):
        c = m.center
        p = m.end if at_end else m.start
        r = (p[0] - c[0], p[1] - c[1])
        # the tangent of travel (drawing frame: z right, x up; ccw turns left)
        return (r[1], -r[0]) if m.kind == "ccw" else (-r[1], r[0])
    return (m.end[0] - m.start[0], m.end[1] - m.start[1])


def _cross(u, v) -> float:
    """Counter-clockwise positive in the drawing frame (z right, x up)."""
    return u[1] * v[0] - u[0] * v[1]


@dataclass
class _Piece:
    kind: str  # "line" | "arc"
    start: tuple
    end: tuple
    line: int
    center: tuple | None = None
    ccw: bool = False


def _offset(m, d: float, side: int):
    """Move `m` offset by `d` to `side` (+1 left of travel, -1 right); None when an arc
    shrinks to its centre."""
    if m.kind in ("cw", "ccw"):
        c, ccw = m.center, m.kind == "ccw"
        rho = math.dist(c, m.start)
        new = rho - d if (side == 1) == ccw else rho + d
        if new < _EPS:
            return None
        k = new / rho
        s = (c[0] + (m.start[0] - c[0]) * k, c[1] + (m.start[1] - c[1]) * k)
        e = (c[0] + (m.end[0] - c[0]) * k, c[1] + (m.end[1] - c[1]) * k)
        return _Piece("arc", s, e, m.line, c, ccw)
    n = _left(_dir(m, False))
    v = (side * d * n[0], side * d * n[1])
    return _Piece(
        "line", (m.start[0] + v[0], m.start[1] + v[1]), (m.end[0] + v[0], m.end[1] + v[1]), m.line
    )


def _meet_lines(a: _Piece, b: _Piece):
    (x0, z0), (x1, z1) = a.start, a.end
    (x2, z2), (x3, z3) = b.start, b.end
    d1, d2 = (x1 - x0, z1 - z0), (x3 - x2, z3 - z2)
    den = d1[0] * d2[1] - d1[1] * d2[0]
    if abs(den) < 1e-15:
        return None
    t = ((x2 - x0) * d2[1] - (z2 - z0) * d2[0]) / den
    return (x0 + t * d1[0], z0 + t * d1[1])


def _centre_path(run, radius, tip):
    dx, dz = tip_offset(tip, radius)
    out = []
    for m in run:

        def back(p, dx=dx, dz=dz):
            return None if p is None else (p[0] - dx, p[1] - dz)

        out.append(_Move(m.kind, back(m.start), back(m.end), m.line, back(m.center)))
    return out


@dataclass
class _Move:
    kind: str
    start: tuple
    end: tuple
    line: int
    center: tuple | None = None


def path_contour(
    program, *, nose_radius: float, tip: int, kind: str | None = None, run: int | None = None
) -> FinishContour:
    """The part contour of a tool path without G41/G42 (module doc).

    **Arguments:**

    - `program`: a read :class:`~piecs_bayes.gcode.GcodeProgram`.
    - `nose_radius`: R (mm, > 0).
    - `tip`: the controlled point: LinuxCNC orientation 1-8 (the imaginary tip), 0 or
      9 (the nose centre).
    - `kind`: ``"external"`` / ``"internal"``; None: from the tip.
    - `run`: which run of cutting moves (1-based) when the program has several.

    **Returns:** a [`FinishContour`][] (mm, radius X) whose segments carry the lines of
    the path's blocks, and the role of each path move (``path_roles``).
    """
    contour, _ = path_contour_roles(program, nose_radius=nose_radius, tip=tip, kind=kind, run=run)
    return contour


def path_contour_roles(program, *, nose_radius, tip, kind=None, run=None):
    """`path_contour` and the [`PathRole`][] of each move between lead-in and exit."""
    name = program.name or "<program>"
    if not (isinstance(nose_radius, int | float) and nose_radius > 0):
        raise InputError(f"nose radius: got {nose_radius!r}, expected a number > 0 (mm)")
    if tip not in range(10):
        raise InputError(f"tip: got {tip!r}, expected a LinuxCNC orientation 0-9", file=name)
    if any(m.comp is not None for m in program.moves):
        raise InputError(
            "the program has nose compensation (G41/G42): its contour is the programmed one, "
            "not a tool path (leave out --nose-radius/--tip)",
            file=name,
        )
    runs = path_runs(program)
    if not runs:
        raise InputError("no run of cutting moves (feeds and arcs between rapids)", file=name)
    if run is None and len(runs) > 1:
        each = [f"run {i}: lines {r[0].line}-{r[-1].line}" for i, r in enumerate(runs, 1)]
        text = "; ".join(each if len(each) <= 4 else [*each[:3], "...", each[-1]])
        raise InputError(f"{len(runs)} runs of cutting moves ({text}): choose one with --run N",
                         file=name)  # fmt: skip
    k = 1 if run is None else int(run)
    if not 1 <= k <= len(runs):
        raise InputError(f"--run {run}: the program has {len(runs)} run(s)", file=name)
    moves = _centre_path(runs[k - 1], nose_radius, tip)
    kind = _kind(kind, tip, nose_radius, name)
    body = moves[1:-1]
    specs = [
        {"p0": m.start, "p1": m.end, **({"center": m.center, "ccw": m.kind == "ccw"}
                                        if m.center is not None else {})}
        for m in body
    ]  # fmt: skip
    try:
        air = profile_side(specs, internal=kind == "internal")
    except ProfileError:
        raise InputError(
            f"the path (lines {body[0].line}-{body[-1].line}) encloses no area with the "
            "spindle axis: its material side cannot be told",
            file=name,
            line=body[0].line,
        ) from None
    pieces, roles = _to_part(body, nose_radius, -air, name)
    segs = [_segment(program, p) for p in pieces]
    side = "left" if air == 1 else "right"
    code = "G41.1" if air == 1 else "G42.1"
    comp = CompSetting(side, code, runs[k - 1][0].line, None, 2 * nose_radius, tip)
    units = {program.state(s.line).units for s in segs}
    contour = FinishContour(
        segments=tuple(segs),
        comp=comp,
        side=air,
        kind=kind,
        lead_in=moves[0].line,
        exit=moves[-1].line,
        off=None,
        units=units.pop() if len(units) == 1 else None,
        run=k,
        runs=len(runs),
        title=program_title(program),
        program=program.name,
    )
    return contour, roles


def _to_part(body, radius, material, name):
    """The centre path's moves offset to the part, with their roles."""
    pieces: list[_Piece] = []
    roles: list[PathRole] = []
    for m in body:
        p = _offset(m, radius, material)
        if p is None or (p.kind == "arc" and math.dist(p.center, p.start) < _VERTEX):
            # an arc about a convex vertex of the part
            if not pieces:
                raise AnalysisError(f"{name}:{m.line}: the path starts with a corner arc")
            roles.append(PathRole(m.line, "corner", len(pieces) - 1))
            continue
        if pieces:
            _join(pieces, p, m, name)
        roles.append(PathRole(m.line, "feature", len(pieces)))
        pieces.append(p)
    return pieces, roles


def _join(pieces, p, m, name) -> None:
    """Join piece `p` (of move `m`) to the last piece: where they meet already (tangent
    moves, a corner arc taken out), where two lines meet when extended or trimmed (a sharp
    corner of the path: a concave corner of the part, or a convex one the path cuts by
    the extend rule), or within the written numbers' rounding."""
    a = pieces[-1]
    gap = math.dist(a.end, p.start)
    if gap < 1e-7:
        p.start = a.end
        return
    if a.kind == "line" and p.kind == "line":
        q = _meet_lines(a, p)
        if q is None:
            raise AnalysisError(f"{name}:{m.line}: the tool path reverses here")
        a.end = p.start = q
        return
    if gap < _VERTEX:
        mid = ((a.end[0] + p.start[0]) / 2, (a.end[1] + p.start[1]) / 2)
        a.end = p.start = mid
        return
    raise AnalysisError(
        f"{name}:{m.line}: a sharp corner of the tool path next to an arc is not read "
        f"(the offsets are {gap:.4f} mm apart): program the contour with G41/G42"
    )


def _segment(program, p: _Piece) -> ContourSegment:
    text, block = block_source(program, p.line)
    if p.kind == "arc":
        return ContourSegment("arc", p.start, p.end, p.line, text, block, p.center, p.ccw)
    return ContourSegment("line", p.start, p.end, p.line, text, block)


def _air_point(f, p, radius: float, air: int):
    """Point `p` of feature `f` moved `radius` to the air side (`air`: +1 left of travel)."""
    if f.kind == "arc":
        c = f.center
        rho = math.dist(c, p)
        new = rho - radius if (air == 1) == f.ccw else rho + radius
        return (c[0] + (p[0] - c[0]) * new / rho, c[1] + (p[1] - c[1]) * new / rho)
    n = _left((f.p1[0] - f.p0[0], f.p1[1] - f.p0[1]))
    return (p[0] + air * radius * n[0], p[1] + air * radius * n[1])


def _air_line(f, radius, air) -> _Piece:
    return _Piece("line", _air_point(f, f.p0, radius, air), _air_point(f, f.p1, radius, air), 0)


def path_targets(program, nominal_profile, adjusted_profile, *, nose_radius, tip, kind=None,
                 run=None) -> tuple[dict, dict]:  # fmt: skip
    """Where each block of a tool path ends (and its arc centre) to cut `adjusted_profile`:
    ``({line: (end, centre or None)}, {feature id: lines})``, mm. The path, computed
    the same way from `nominal_profile`, must be the program's (else AnalysisError)."""
    name = program.name or "<program>"
    contour, roles = path_contour_roles(
        program, nose_radius=nose_radius, tip=tip, kind=kind, run=run
    )
    if len(contour.segments) != len(nominal_profile.features):
        raise AnalysisError(
            f"{name}: the tool path cuts {len(contour.segments)} features, the study has "
            f"{len(nominal_profile.features)}"
        )
    run_moves = path_runs(program)[contour.run - 1]
    targets = _targets_for(adjusted_profile, roles, run_moves, nose_radius, tip, contour.side)
    check = _targets_for(nominal_profile, roles, run_moves, nose_radius, tip, contour.side)
    by_line = {m.line: m for m in run_moves}
    for line, (end, centre) in check.items():
        m = by_line[line]
        off = math.dist(end, m.end)
        if centre is not None and m.center is not None:
            off = max(off, math.dist(centre, m.center))
        if off > 2e-3:
            raise AnalysisError(
                f"{name}:{line}: the tool path is not the study's profile offset by the nose "
                f"(radius {nose_radius:g} mm, tip {tip}): {off:.4f} mm off here"
            )
    ids = [f.id for f in adjusted_profile.features]
    features: dict[str, list[int]] = {fid: [] for fid in ids}
    for r in roles:
        if r.role == "feature":
            features[ids[r.index]].append(r.line)
    return targets, {k: tuple(v) for k, v in features.items()}


def _targets_for(profile, roles, run_moves, radius, tip, air) -> dict:
    feats = profile.features
    dx, dz = tip_offset(tip, radius)

    def tip_point(p):
        return None if p is None else (p[0] + dx, p[1] + dz)

    out: dict[int, tuple] = {}
    first = feats[0]
    out[run_moves[0].line] = (tip_point(_air_point(first, first.p0, radius, air)), None)
    for k, r in enumerate(roles):
        f = feats[r.index]
        if r.role == "corner":
            g = feats[r.index + 1]
            end = _air_point(g, g.p0, radius, air)
            out[r.line] = (tip_point(end), tip_point(f.p1))
            continue
        end = _air_point(f, f.p1, radius, air)
        nxt = roles[k + 1] if k + 1 < len(roles) else None
        if nxt is not None and nxt.role == "feature" and f.kind == "line":
            g = feats[nxt.index]
            if g.kind == "line":
                q = _meet_lines(_air_line(f, radius, air), _air_line(g, radius, air))
                if q is not None:
                    end = q  # a sharp corner of the path (tangent lines meet where they end)
        centre = tip_point(f.center) if f.kind == "arc" else None
        out[r.line] = (tip_point(end), centre)
    return out

"""The adjusted finish-cut program: the part program rewritten to the compensated contour.

Assumes the program is written in *part coordinates* and that its finish cut programs
the *part contour* with G41/G42 (or G41.1/G42.1) taking care of the nose radius.
:func:`map_blocks_to_profile` pairs the finish-cut blocks with the profile's features
by geometry (within ``tol_mm``; an explicit ``mapping`` overrides) -> [`BlockMap`][];
:func:`adjust_program` moves each mapped block's end point to the corresponding point of
the adjusted feature and rewrites arcs' ``R`` or ``I``/``K`` -> [`ProgramAdjustment`][].
Only coordinate words change, each in its own number format (rounded to its decimal
places), X in the block's diameter / radius mode and units; every other line stays
byte-identical. Refused (:class:`~piecs_bayes.errors.AnalysisError`): a change larger
than ``max_correction_mm``, a block or feature that cannot be mapped, a result that
gouges (a reversed move, an invalid arc, a gouge of the nose compensation).

The assumptions and the mapping: docs/models/part_programs.md, "The adjusted program".
"""

from __future__ import annotations

import difflib
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import AnalysisError, InputError
from ..geometry import Arc, Line, Profile
from ._adjust_corners import CORNER_WORDS, corner_blocks, corner_size, corner_vertex
from ._header import diff_labels, header_checked


@dataclass(frozen=True)
class BlockMap:
    """Which finish-cut block cuts which feature.

    ``features``: feature id -> line numbers (program order); ``lines``: line
    -> feature id; ``connecting``: approach / departure lines that map to no
    feature; ``reversed``: feature ids the program cuts against the profile's
    direction.
    """

    features: dict
    lines: dict
    connecting: tuple[int, ...]
    reversed: frozenset
    corners: dict = field(default_factory=dict)
    """line -> the feature its corner word (``,C``/``,R``, G7x ``C``/``A``) inserts."""

    def __repr__(self) -> str:
        parts = ", ".join(f"{k}: {list(v)}" for k, v in self.features.items())
        return f"BlockMap({parts}; connecting {list(self.connecting)})"


@dataclass(frozen=True)
class BlockChange:
    """One rewritten block: its line, feature, old and new text and how far its end moved (mm)."""

    line: int
    feature: str | None
    old: str
    new: str
    shift_mm: float


@dataclass(frozen=True)
class ProgramAdjustment:
    """The adjusted program ``text``, its unified ``diff`` against the original,
    the block ``changes`` and the ``mapping`` used (line numbers of the input
    program); ``header_lines`` comment lines were inserted at the top of ``text``."""

    text: str
    diff: str
    changes: tuple[BlockChange, ...]
    mapping: BlockMap
    header_lines: int = 0

    @property
    def max_shift_mm(self) -> float:
        return max((c.shift_mm for c in self.changes), default=0.0)

    def __repr__(self) -> str:
        return (
            f"ProgramAdjustment({len(self.changes)} blocks rewritten, "
            f"largest end-point move {self.max_shift_mm * 1000:.1f} um)"
        )


def read_program(program):
    """The program (a path or a read one) as its blocks: `contour_view`."""
    from ._contour import contour_view
    from ._program import GcodeProgram
    from ._read import read_gcode

    program = program if isinstance(program, GcodeProgram) else read_gcode(program)
    return contour_view(program)


def candidates(program):
    moves = [m for m in program.moves if m.comp is not None]
    if not moves:
        moves = [m for m in program.moves if m.kind != "rapid"]
    return [m for m in moves if m.start != m.end]


def _on_line(p, f: Line, tol):
    (x0, z0), (x1, z1) = f.p0, f.p1
    L = math.dist(f.p0, f.p1)
    ux, uz = (x1 - x0) / L, (z1 - z0) / L
    t = (p[0] - x0) * ux + (p[1] - z0) * uz
    d = abs(-(p[0] - x0) * uz + (p[1] - z0) * ux)
    return d <= tol and -tol <= t <= L + tol, t / L


def _arc_fraction(p, f: Arc):
    a0 = math.atan2(f.p0[0] - f.center[0], f.p0[1] - f.center[1])
    a = math.atan2(p[0] - f.center[0], p[1] - f.center[1])
    d = a - a0
    if f.ccw:
        d %= 2 * math.pi
    else:
        d = -((-d) % (2 * math.pi))
    sweep = f.sweep
    if abs(d - sweep) > math.pi and abs(d) > math.pi:  # wrapped past the start
        d = d - math.copysign(2 * math.pi, d)
    return d / sweep


def _matches(m, f, tol):
    """``(matched, reversed)`` for move ``m`` against feature ``f``."""
    if m.is_arc != (f.kind == "arc"):
        return False, False
    if f.kind == "line":
        ok0, t0 = _on_line(m.start, f, tol)
        ok1, t1 = _on_line(m.end, f, tol)
        return ok0 and ok1, t1 < t0
    c = m.exact_center()
    if math.dist(c, f.center) > tol or abs(math.dist(c, m.start) - f.radius) > tol:
        return False, False
    rev = m.ccw != f.ccw
    fr = [_arc_fraction(p, f) for p in (m.start, m.end)]
    slack = tol / max(f.length, tol)
    inside = all(-slack <= v <= 1 + slack for v in fr)
    return inside and ((fr[1] < fr[0]) == rev), rev


def map_blocks_to_profile(program, profile: Profile, *, tol_mm: float = 0.01, mapping=None):
    """Map the finish-cut blocks of ``program`` to the features of ``profile``.

    **Arguments:**

    - `program`: a :class:`~piecs_bayes.gcode.GcodeProgram` or a path.
    - `profile`: the nominal profile (mm, radius X, part coordinates).
    - `tol_mm`: how far a block's geometry may sit from its feature's.
    - `mapping`: ``{feature id: line number or list of line numbers}``
      overriding the geometric match.

    **Returns:** a :class:`BlockMap`. Raises AnalysisError naming the block or
    feature that cannot be mapped.
    """
    program = read_program(program)
    name = program.name or "<program>"
    moves = candidates(program)
    if not moves:
        raise AnalysisError(f"{name}: no finish-cut block (no compensated or feed move) found")
    corner_moves = {id(c) for _, c in corner_blocks(moves).values()}
    by_line = {m.line: m for m in moves if id(m) not in corner_moves}
    lines, rev, forced = _forced_lines(program, profile, mapping, by_line)
    corners: dict[int, str] = {}
    for m in moves:
        if m.line in forced:
            continue
        hits = [(f, r) for f in profile.features for ok, r in [_matches(m, f, tol_mm)] if ok]
        if len(hits) >= 1:
            f, r = hits[0]
            (corners if id(m) in corner_moves else lines)[m.line] = f.id
            if r:
                rev.add(f.id)
    ordered = [m for m in moves if m.line in by_line and id(m) not in corner_moves]
    connecting = _connecting_blocks(program, ordered, lines, name, tol_mm)
    cut = {(ln, 0): fid for ln, fid in lines.items()}
    cut.update({(ln, 1): fid for ln, fid in corners.items()})  # a block's corner after it
    features = {f.id: tuple(k[0] for k in sorted(cut) if cut[k] == f.id) for f in profile}
    missing = [fid for fid, lns in features.items() if not lns]
    if missing:
        raise AnalysisError(
            f"{name}: no finish-cut block cuts feature(s) {', '.join(map(repr, missing))} "
            f"(tolerance {tol_mm:g} mm); give an explicit mapping"
        )
    return BlockMap(
        features,
        dict(sorted(lines.items())),
        tuple(connecting),
        frozenset(rev),
        dict(sorted(corners.items())),
    )


def _forced_lines(program, profile: Profile, mapping, by_line):
    """The explicit ``mapping``: ``(lines, reversed, forced)``; adds its moves to ``by_line``."""
    lines: dict[int, str] = {}
    rev: set[str] = set()
    forced = set()
    for fid, lns in (mapping or {}).items():
        f = profile[fid] if fid in profile.ids else None
        if f is None:
            raise InputError(
                f"mapping names feature {fid!r}, which is not in the profile "
                f"({', '.join(profile.ids)})",
                feature=fid,
            )
        for ln in [lns] if isinstance(lns, int) else list(lns):
            m = by_line.get(ln) or next((x for x in program.moves if x.line == ln), None)
            if m is None:
                raise InputError(
                    f"mapping for feature {fid!r} names line {ln}, which has no move",
                    file=program.name,
                    line=ln,
                    feature=fid,
                )
            if m.is_arc != (f.kind == "arc"):
                raise InputError(
                    f"mapping pairs a {'G2/G3' if m.is_arc else 'straight'} block with "
                    f"{f.kind} feature {fid!r}",
                    file=program.name,
                    line=ln,
                    feature=fid,
                )
            by_line.setdefault(ln, m)
            lines[ln] = fid
            forced.add(ln)
            if m.is_arc and m.ccw != f.ccw:
                rev.add(fid)
    return lines, rev, forced


def _connecting_blocks(program, ordered, lines, name, tol_mm):
    """Unmapped blocks allowed around the contour (first, last, entry moves); any other
    unmapped block is an AnalysisError."""
    connecting = []
    for k, m in enumerate(ordered):
        if m.line in lines:
            continue
        if k in (0, len(ordered) - 1) or m.entry:
            connecting.append(m.line)
            continue
        text = program.source.line(m.line).text.strip()
        raise AnalysisError(
            f"{name}:{m.line}: this finish-cut block lies on no profile feature "
            f"(tolerance {tol_mm:g} mm); map it explicitly or check that the program is in "
            f"part coordinates: {text!r}"
        )
    return connecting


def _transfer(p, nominal, adjusted, reverse):
    """The point of ``adjusted`` that corresponds to point ``p`` of ``nominal``."""
    if nominal.kind == "line":
        _, t = _on_line(p, nominal, math.inf)
        (a0, a1) = adjusted.p0, adjusted.p1
        return (a0[0] + t * (a1[0] - a0[0]), a0[1] + t * (a1[1] - a0[1]))
    fr = _arc_fraction(p, nominal)
    a0 = math.atan2(adjusted.p0[0] - adjusted.center[0], adjusted.p0[1] - adjusted.center[1])
    ang = a0 + fr * adjusted.sweep
    r = adjusted.radius
    return (adjusted.center[0] + r * math.sin(ang), adjusted.center[1] + r * math.cos(ang))


def _snap(p, nominal_profile, adjusted_profile, tol):
    """Adjusted vertex for a point at a nominal vertex, else None."""
    for f, g in zip(nominal_profile.features, adjusted_profile.features, strict=True):
        for a, b in ((f.p0, g.p0), (f.p1, g.p1)):
            if math.dist(p, a) <= tol:
                return b
    return None


def _default_decimals(program, units):
    counts = Counter(
        w.decimals for ln in program.lines for w in ln.words if w.letter in "XZ" and "." in w.text
    )
    best = counts.most_common(1)[0][0] if counts else 0
    return max(best, 3 if units == "mm" else 4)


def _check_sides(program, profile: Profile, bmap) -> None:
    """G41/G42 must put the nose on the air side of the features its blocks cut:
    the mapped feature's outward normal is the air side (`check_comp_sides`)."""
    from ._nosecomp import check_comp_sides

    def air(m):
        fid = bmap.lines.get(m.line)
        if fid is None:
            return None
        mid = (np.asarray(m.start) + np.asarray(m.end)) / 2.0
        n = np.asarray(profile[fid].outward_normal(mid))
        return (float(n[0]), float(n[1]))

    check_comp_sides(program, air)


def adjust_program(
    program,
    nominal_profile: Profile,
    adjusted_profile: Profile,
    *,
    max_correction_mm: float,
    mapping=None,
    tol_mm: float = 0.01,
    tool_table=None,
    nose_radius_mm: float | None = None,
    header: Sequence[str] = (),
    output_name: str | None = None,
) -> ProgramAdjustment:
    """Rewrite the finish-cut blocks of ``program`` to ``adjusted_profile``.

    **Arguments:**

    - `program`: a :class:`~piecs_bayes.gcode.GcodeProgram` or a path (part
      coordinates, the contour programmed with G41/G42).
    - `nominal_profile`, `adjusted_profile`: the drawing's profile and the
      compensated one (same feature ids; e.g. ``AdjustedPath.profile``).
    - `max_correction_mm`: the largest allowed move of any end point, arc
      centre or radius.
    - `mapping`: explicit ``{feature id: line numbers}`` (see
      :func:`map_blocks_to_profile`).
    - `tol_mm`: geometric matching tolerance.
    - `tool_table`, `nose_radius_mm`: to check the result for gouges with the
      nose radius (``nose_radius_mm`` stands in for G41/G42 tools).
    - `header`: comment texts, one line each, put at the top of the result in the
      program's comment syntax, after a ``%`` line and the O-number line (see
      `gcode._header`); only comment lines are added, the motion stays the same.
    - `output_name`: the adjusted program's path as the diff names it
      (``+++ b/<output_name>``; default ``<stem>_adjusted<suffix>``); the input is
      ``--- a/<program's path>``.

    **Returns:** a :class:`ProgramAdjustment`; write ``.text`` with
    :func:`~piecs_bayes.io.write_text_atomic` (``protect=[input]``).
    """

    program = read_program(program)
    name = program.name or "<program>"
    if nominal_profile.ids != adjusted_profile.ids:
        raise InputError(
            f"the adjusted profile's features {adjusted_profile.ids} differ from the nominal "
            f"ones {nominal_profile.ids}"
        )
    for ln in sorted({m.line for m in candidates(program)}):
        why = program.edit_refusal(ln)
        if why is not None:  # before the mapping: a block that runs twice maps twice
            raise AnalysisError(
                f"{name}:{ln}: the adjusted program cannot edit this finish-cut block in "
                f"place: {why}"
            )
    bmap = map_blocks_to_profile(program, nominal_profile, tol_mm=tol_mm, mapping=mapping)
    _check_sides(program, nominal_profile, bmap)
    blocks = _as_blocks(program)  # a corner block: one move, to its vertex
    moves = {m.line: m for m in blocks.moves}
    target = _targets(blocks, moves, nominal_profile, adjusted_profile, bmap, tol_mm)
    sizes = _corner_targets(blocks, nominal_profile, adjusted_profile, bmap, target, name)
    _check_shifts(moves, target, bmap, name, max_correction_mm)
    _check_editable(blocks, target, sizes, name)
    texts = _rewrite_blocks(blocks, target, sizes)
    checks = (tool_table, nose_radius_mm)
    return _adjustment(program, texts, target, sizes, bmap, moves, checks, header, output_name)


@dataclass(frozen=True)
class ToolPath:
    """A program without G41/G42 that is the tool's path (CAM output): the nose radius
    (mm), the point the path is written for (`tip`: LinuxCNC orientation 1-8, the
    imaginary tip; 0 or 9 the nose centre), the material side (`kind`; None: from the
    tip) and which run of cutting moves (`run`; None: the only one)."""

    nose_radius: float
    tip: int
    kind: str | None = None
    run: int | None = None


def adjust_path_program(
    program,
    nominal_profile: Profile,
    adjusted_profile: Profile,
    *,
    tool_path: ToolPath,
    max_correction_mm: float,
    header: Sequence[str] = (),
    output_name: str | None = None,
) -> ProgramAdjustment:
    """Rewrite a tool path (no G41/G42) to cut ``adjusted_profile``: each block of the
    path moves to where the nose's `tool_path.tip` runs for the adjusted contour
    (`gcode.path_targets`: lines offset by the nose radius, corner arcs about the
    adjusted vertices, arcs' radii). Only coordinate words change; refused as
    `adjust_program` refuses (a change above the limit, a block that ran twice or
    computes its words, a move that would run backwards). Arguments as there."""
    from ._path_contour import path_targets

    program = read_program(program)
    name = program.name or "<program>"
    target, features = path_targets(
        program, nominal_profile, adjusted_profile, nose_radius=tool_path.nose_radius,
        tip=tool_path.tip, kind=tool_path.kind, run=tool_path.run,
    )  # fmt: skip
    lines = {ln: fid for fid, lns in features.items() for ln in lns}
    connecting = tuple(sorted(set(target) - set(lines)))
    bmap = BlockMap(features, dict(sorted(lines.items())), connecting, frozenset())
    moves = {m.line: m for m in program.moves}
    _check_shifts(moves, target, bmap, name, max_correction_mm)
    _check_editable(program, target, {}, name)
    texts = _rewrite_blocks(program, target, {})
    return _adjustment(program, texts, target, {}, bmap, moves, (None, None), header, output_name)


def _adjustment(program, texts, target, sizes, bmap, moves, checks, header, output_name):
    """The adjusted program from the new texts of its blocks: read again and checked
    (`_check`), its header put on, the changes and the diff."""
    from ._read import parse_gcode

    name = program.name or "<program>"
    new_source = program.source.with_line_texts(texts)
    try:
        raw = parse_gcode(new_source.text, name=program.name, options=program.options)
        new_program = read_program(raw)
    except InputError as exc:
        raise AnalysisError(f"the adjusted program is not valid: {exc}") from None
    _check(program, new_program, target, set(sizes), name, *checks)
    text, n_header = header_checked(raw, header)
    changes: list[BlockChange] = []
    for ln in sorted(texts):
        new_end = target[ln][0] if ln in sizes else new_program.moves_at(ln)[-1].end
        changes.append(
            BlockChange(
                ln,
                bmap.lines.get(ln),
                program.source.line(ln).text,
                texts[ln],
                math.dist(moves[ln].end, new_end),
            )
        )
    old_label, new_label = diff_labels(program.name, output_name)
    diff = "".join(
        difflib.unified_diff(
            program.text.splitlines(keepends=True),
            text.splitlines(keepends=True),
            fromfile=old_label,
            tofile=new_label,
        )
    )
    return ProgramAdjustment(text, diff, tuple(changes), bmap, n_header)


def _as_blocks(program):
    """`program` with each corner block as one move to its vertex (the point its words
    program; the corner's own move dropped): what is rewritten is the block's words."""
    corners = corner_blocks(program.moves)
    if not corners:
        return program
    out, moves = [], list(program.moves)
    for k, m in enumerate(moves):
        pair = corners.get(m.line)
        if pair is None:
            out.append(m)
            continue
        if m is pair[1]:
            continue
        nxt = moves[k + 2] if k + 2 < len(moves) else None
        vertex = None if nxt is None else _vertex_of(m, nxt)
        out.append(m if vertex is None else replace(m, end=vertex))
    return replace(program, moves=tuple(out))


def _vertex_of(m, nxt):
    """Where the lines of move `m` and the move after its corner meet."""
    if m.is_arc or nxt.is_arc:
        return None
    return corner_vertex(Line("a", m.start, m.end), Line("b", nxt.start, nxt.end))


def _corner_targets(blocks, nominal_profile, adjusted_profile, bmap, target, name):
    """``{line: (corner word letter, new value mm)}`` for the corner blocks; their
    targets become the adjusted vertex (where the adjusted lines meet)."""
    sizes: dict[int, tuple[str, float]] = {}
    order = [m.line for m in blocks.moves]
    for ln, cid in bmap.corners.items():
        k = order.index(ln)
        nxt = bmap.lines.get(order[k + 1]) if k + 1 < len(order) else None
        fid = bmap.lines.get(ln)
        src = blocks.source.line(ln)
        letter = next((w.letter for w in src.words if w.letter in CORNER_WORDS), None)
        f, g = (adjusted_profile[x] if x else None for x in (fid, nxt))
        vertex = None if f is None or g is None else corner_vertex(f, g)
        if vertex is None or letter is None:
            raise AnalysisError(
                f"{name}:{ln}: the corner of this block is not between two line features "
                "(a corner next to an arc is not rewritten); map it explicitly or program "
                "the corner as a block of its own"
            )
        target[ln] = (vertex, None)
        sizes[ln] = (letter, corner_size(letter, adjusted_profile[cid], vertex, f, g))
    return sizes


def _targets(program, moves, nominal_profile, adjusted_profile, bmap, tol_mm):
    """``{line: (new end, new centre or None)}`` for the blocks to rewrite."""
    target: dict[int, tuple] = {}  # line -> (new end, new centre or None)
    for ln, fid in bmap.lines.items():
        m = moves[ln]
        nom, adj = nominal_profile[fid], adjusted_profile[fid]
        end = _snap(m.end, nominal_profile, adjusted_profile, tol_mm)
        end = end if end is not None else _transfer(m.end, nom, adj, fid in bmap.reversed)
        target[ln] = (end, adj.center if m.is_arc else None)
    for ln in bmap.connecting:
        end = _snap(moves[ln].end, nominal_profile, adjusted_profile, tol_mm)
        if end is not None:
            target[ln] = (end, None)
    for prev, nxt in zip(program.moves[:-1], program.moves[1:], strict=True):
        # the approach to the first mapped block follows the contour's new start
        if nxt.line in bmap.lines and prev.line not in target and prev.line != nxt.line:
            end = _snap(prev.end, nominal_profile, adjusted_profile, tol_mm)
            if end is not None:
                target[prev.line] = (end, None)
    return target


def _check_shifts(moves, target, bmap, name, max_correction_mm) -> None:
    """No end point or arc centre may move by more than ``max_correction_mm``."""
    for ln, (end, centre) in target.items():
        m = moves[ln]
        shift = math.dist(end, m.end)
        if centre is not None:
            shift = max(shift, math.dist(centre, m.exact_center()))
        if shift > max_correction_mm:
            fid = bmap.lines.get(ln)
            raise AnalysisError(
                f"{name}:{ln}: the block{f' of feature {fid!r}' if fid else ''} would move by "
                f"{shift:.4f} mm, more than the maximum correction {max_correction_mm:g} mm"
            )


def _check_editable(program, lines, sizes, name) -> None:
    """Each block to rewrite must be editable where it stands: it ran once, its words
    are numbers, it makes one move with X/Z words (not U/W) or carries a corner between
    two lines (`_adjust_corners`)."""
    for ln in sorted(lines):
        why = program.edit_refusal(ln)
        if why is None:
            letters = {w.letter for w in program.source.line(ln).words}
            if {"U", "W"} & letters:
                why = f"line {ln} moves by U/W (incremental words), which are not rewritten yet"
            elif ln not in sizes and ({",C", ",R"} & letters or len(program.moves_at(ln)) > 1):
                why = (
                    f"line {ln} makes more than one move (a corner next to an arc, or a "
                    "block the contour does not cut as its features)"
                )
        if why is not None:
            raise AnalysisError(
                f"{name}:{ln}: the adjusted program cannot edit this block in place: {why}"
            )


def _rewrite_blocks(program, target, sizes) -> dict[int, str]:
    """New texts of the target blocks, block by block, tracking where the new program
    really is (a block that omits an axis follows the new position); ``sizes`` the new
    corner words of corner blocks."""
    texts: dict[int, str] = {}
    pos_new = None
    for m in program.moves:
        start = m.start if pos_new is None else pos_new
        if m.line not in target:
            pos_new = _realised_end(m, start, program)
            continue
        end, centre = target[m.line]
        new_text = _block_text(program, m, start, end, centre, sizes.get(m.line))
        if new_text is not None:
            texts[m.line] = new_text
        pos_new = end
    return texts


def _block_text(program, m, start, end, centre, corner=None):
    """The text of block ``m`` moved to ``end`` (and ``centre``; ``corner``: its corner
    word's letter and new value in mm), or None if unchanged."""
    from ._lexer import edit_line, format_number

    line = program.source.line(m.line)
    st = program.state(m.line)
    decimals = _default_decimals(program, st.units)
    scale = 1 / 25.4 if st.units == "in" else 1.0
    xs = scale * (2.0 if st.diameter else 1.0)
    want = {
        "X": (end[0] if st.absolute else end[0] - start[0]) * xs,
        "Z": (end[1] if st.absolute else end[1] - start[1]) * scale,
    }
    if m.is_arc:
        r_word = line.word("R")
        if r_word is not None:
            want["R"] = math.copysign(math.dist(centre, end), r_word.value) * scale
        else:
            c = centre if st.arc_absolute else (centre[0] - start[0], centre[1] - start[1])
            want["I"], want["K"] = c[0] * scale, c[1] * scale
    if corner is not None:
        want[corner[0]] = corner[1] * scale
    values, insert = {}, []
    for letter, v in want.items():
        idx = next((k for k, w in enumerate(line.words) if w.letter == letter), None)
        if idx is not None:
            word = line.words[idx]
            new = format_number(v, word, decimals=decimals)
            if abs(float(new) - v) > 0.5 * 10.0**-decimals:
                # the word's own decimal places cannot carry the correction
                new = format_number(v, _widened(word, decimals), decimals=decimals)
            if new != word.text:
                values[idx] = new
        else:
            modal = _modal_value(letter, start, st, xs, scale)
            new = format_number(v, decimals=decimals)
            if modal is None or new != format_number(modal, decimals=decimals):
                insert.append(f"{letter}{new}")
    if not (values or insert):
        return None
    anchor = max(
        (k for k, w in enumerate(line.words) if w.letter in "XZIKR"),
        default=len(line.words) - 1,
    )
    return edit_line(line, values=values, insert={anchor: insert})


def _widened(word, decimals):
    """``word`` as if written with ``decimals`` places (sign and leading-zero style kept)."""
    from dataclasses import replace

    body = word.text.split(".")[0] + "." + "0" * decimals
    return replace(word, text=body)


def _modal_value(letter, start, st, xs, scale):
    """The value a block means when it omits ``letter`` (I/K omitted are 0)."""
    if letter in "IK":
        return 0.0
    if letter == "R":
        return None
    if not st.absolute:
        return 0.0
    return start[0] * xs if letter == "X" else start[1] * scale


def _realised_end(m, start, program):
    """Where an unchanged block ends when it starts at ``start`` (absent axes follow)."""
    line = program.source.line(m.line)
    st = program.state(m.line)
    if not st.absolute:
        return (m.end[0] - m.start[0] + start[0], m.end[1] - m.start[1] + start[1])
    return (m.end[0] if line.word("X") else start[0], m.end[1] if line.word("Z") else start[1])


def _check(old, new, target, corner_lines, name, tool_table, nose_radius_mm):
    from ._nosecomp import compensated_path

    if len(old.moves) != len(new.moves):
        raise AnalysisError(f"{name}: the adjusted program has a different number of moves")
    for a, b in zip(old.moves, new.moves, strict=True):
        if b.line in target and b.line not in corner_lines:  # a corner's end: its vertex
            end, centre = target[b.line]
            st = new.state(b.line)
            tol = 2 * 10.0 ** -_default_decimals(new, st.units) * (25.4 if st.units == "in" else 1)
            if math.dist(b.end, end) > tol:
                raise AnalysisError(f"{name}:{b.line}: the rewritten block misses its target")
        if a.start == a.end or b.start == b.end:
            continue
        if a.is_arc:
            da = _turn(a)
            db = _turn(b)
            if db * da <= 0 or abs(db - da) > math.pi / 2:
                raise AnalysisError(
                    f"{name}:{b.line}: the adjusted arc no longer runs as programmed (gouge)"
                )
        else:
            d0 = (a.end[0] - a.start[0], a.end[1] - a.start[1])
            d1 = (b.end[0] - b.start[0], b.end[1] - b.start[1])
            if d0[0] * d1[0] + d0[1] * d1[1] <= 0:
                raise AnalysisError(
                    f"{name}:{b.line}: the adjusted block runs backwards (the correction is "
                    "larger than the block: gouge)"
                )
    if not any(m.comp is not None for m in new.moves):
        return
    needs_table = any(m.comp is not None and m.comp.diameter_mm is None for m in new.moves)
    if needs_table and tool_table is None and nose_radius_mm is None:
        return
    try:
        compensated_path(new, tool_table=tool_table, nose_radius=nose_radius_mm)
    except AnalysisError as exc:
        raise AnalysisError(f"the adjusted program gouges with the nose radius: {exc}") from None


def _turn(m):
    c = m.exact_center()
    a0 = math.atan2(m.start[0] - c[0], m.start[1] - c[1])
    a1 = math.atan2(m.end[0] - c[0], m.end[1] - c[1])
    d = a1 - a0
    if m.ccw:
        return d % (2 * math.pi) or 2 * math.pi
    return -((-d) % (2 * math.pi) or 2 * math.pi)

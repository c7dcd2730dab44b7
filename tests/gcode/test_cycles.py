"""Canned cycles: G70/G71/G72 against LinuxCNC's rs274 and by hand, G73 by hand, the
dialects' words.

The rs274 tests run every program of tests/data/gcode/cycles and the lathe cycle
programs LinuxCNC installs (read in place, never copied: GPL) through ``rs274 -g`` and
through `expand_cycle` (contours read by the small reader in _g7x_reader.py), and
compare every canonical move: kind, arc sense, end and centre, to rs274's printed
precision (1e-4 of the program's unit).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from _g7x_reader import Cycle, read_g7x_program

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import (
    ContourMove,
    FinishCycle,
    PatternRepeat,
    RoughCycle,
    cycle_start,
    expand_cycle,
    expand_pattern_repeat,
    fanuc_cycle,
    linuxcnc_cycle,
    non_contour_cycle,
    parse_gcode,
    rs274_path,
    run_rs274,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode" / "cycles"
OWN = sorted(DATA.glob("*.ngc"))
REFUSED = sorted((DATA / "refused").glob("*.ngc"))
NCFILES = Path("/usr/share/linuxcnc/ncfiles")
SHIPPED = ["lathe_g70_71_demo.ngc", "lathe_g7x_face_boring.ngc", "lathe_g7x_quadrants.ngc"]

needs_rs274 = pytest.mark.skipif(
    rs274_path() is None,
    reason="LinuxCNC's rs274 is not installed (make conformance installs linuxcnc-uspace)",
)


def _shipped(name: str) -> str:
    """The installed program, its tool changes (``T2M6G43``) taken out: they move
    nothing, and rs274's tool table is shared between processes (a run beside another
    one may not find the tool)."""
    path = NCFILES / name
    if not path.is_file():
        pytest.skip(f"{path} is not installed (linuxcnc-uspace)")
    return re.sub(r"T\d+\s*M6\s*G43", "", path.read_text())


def _ours(events) -> list:
    """The program's moves as canonical moves: (kind, end, centre, rotation)."""
    out = []
    for e in events:
        if isinstance(e, Cycle):
            for m in e.moves:
                if m.is_arc:
                    out.append(("arc", m.end, m.center, 1 if m.kind == "ccw" else -1))
                else:
                    out.append((m.kind, m.end, None, 0))
        else:
            out.append((e[0], e[1], None, 0))
    return out


def _compare(ref, ours, unit_mm: float) -> float:
    """Every move equal to rs274's to its 4 printed decimals; the largest difference
    (mm)."""
    tol = 1e-4 * unit_mm + 1e-9
    assert len(ref) == len(ours), f"{len(ref)} canonical moves vs {len(ours)}"
    worst = 0.0
    for k, (a, (kind, end, center, rot)) in enumerate(zip(ref, ours, strict=True)):
        assert (a.kind, a.rotation) == (kind, rot), (k, a, kind, rot)
        dev = float(np.max(np.abs(np.subtract(a.end, end))))
        if a.center is not None:
            dev = max(dev, float(np.max(np.abs(np.subtract(a.center, center)))))
        assert dev <= tol, (k, a, end, center, dev)
        worst = max(worst, dev)
    return worst


def _unit_mm(text: str) -> float:
    return 25.4 if "G20" in text.upper() else 1.0


# --- rs274: the programs LinuxCNC ships and ours -------------------------------------


@pytest.mark.rs274
@needs_rs274
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_cycle_programs_match_rs274(name, record_property):
    text = _shipped(name)
    # the demo runs its G70 under G42.1: the same program without it is compared here,
    # the compensated one in test_g70_under_nose_compensation_composes
    text = text.replace("G42.1 D0.3 L2", "")
    ref = run_rs274(text)
    assert ref.error is None, ref.error
    events = read_g7x_program(text)
    assert any(isinstance(e, Cycle) for e in events)
    worst = _compare(ref.moves, _ours(events), 1.0)
    record_property("moves", len(ref.moves))
    record_property("worst_mm", worst)


@pytest.mark.rs274
@needs_rs274
@pytest.mark.parametrize("path", OWN, ids=lambda p: p.name)
def test_own_cycle_programs_match_rs274(path, record_property):
    text = path.read_text()
    ref = run_rs274(path)
    assert ref.error is None, ref.error
    events = read_g7x_program(text)
    worst = _compare(ref.moves, _ours(events), _unit_mm(text))
    record_property("moves", len(ref.moves))
    record_property("worst_mm", worst)


def _reader_moves(program) -> list:
    return [
        ("arc", m.end, m.center, 1 if m.kind == "ccw" else -1)
        if m.is_arc
        else (m.kind, m.end, None, 0)
        for m in program.moves
    ]


@pytest.mark.rs274
@needs_rs274
@pytest.mark.parametrize("path", OWN, ids=lambda p: p.name)
def test_the_reader_runs_own_cycle_programs_as_rs274(path):
    """The package's reader (not the small one above) makes rs274's moves, cycle by
    cycle, with their contours from the O-subs."""
    text = path.read_text()
    ref = run_rs274(path)
    assert ref.error is None, ref.error
    program = parse_gcode(text, name=path.name)
    assert program.cycles and all(c.contour for c in program.cycles)
    _compare(ref.moves, _reader_moves(program), _unit_mm(text))


@pytest.mark.rs274
@needs_rs274
@pytest.mark.parametrize("path", REFUSED, ids=lambda p: p.name)
def test_the_reader_refuses_what_rs274_refuses(path):
    with pytest.raises(InputError, match=r":12: G71: Not monotonic"):
        parse_gcode(path.read_text(), name=path.name)


@pytest.mark.rs274
@needs_rs274
@pytest.mark.parametrize("path", REFUSED, ids=lambda p: p.name)
def test_refused_cycles_are_refused_by_both(path):
    ref = run_rs274(path)
    assert ref.error is not None and "Not monotonic" in ref.error
    with pytest.raises(InputError, match=r"line 12: G71: Not monotonic"):
        read_g7x_program(path.read_text())


@pytest.mark.rs274
@needs_rs274
def test_lathe_pawn_has_no_cycle():
    """lathe_pawn.ngc is the demo's part roughed and finished in plain blocks: no cycle."""
    events = read_g7x_program(_shipped("lathe_pawn.ngc"))
    assert events and not any(isinstance(e, Cycle) for e in events)


def _written_out(moves, comp: str) -> list[str]:
    """Moves as blocks (absolute arc centres), `comp` switched on before the first one
    that leaves the approach point."""
    lines, on = [], False
    for m in moves:
        if not on and m.start != m.end:
            lines.append(comp)
            on = True
        x, z = m.end
        if m.is_arc:
            cx, cz = m.center
            g = "G3" if m.kind == "ccw" else "G2"
            lines.append(f"{g} X{x:.12f} Z{z:.12f} I{cx:.12f} K{cz:.12f}")
        elif on:
            lines.append(f"{'G0' if m.kind == 'rapid' else 'G1'} X{x:.12f} Z{z:.12f}")
    return lines


@pytest.mark.rs274
@needs_rs274
def test_g70_under_nose_compensation_composes():
    """The demo's G70 under ``G42.1 D0.3 L2``: our moves written out after the same
    G42.1 make the canonical moves rs274 makes for the G70 itself, once past the
    approach (this rs274 build makes an unintended move there, fixed in LinuxCNC in
    July 2024: docs/models/part_programs.md)."""
    text = _shipped("lathe_g70_71_demo.ngc")
    ref = run_rs274(text)
    assert ref.error is None, ref.error
    cycles = [e for e in read_g7x_program(text) if isinstance(e, Cycle)]
    g70 = cycles[-1]
    assert g70.code == "G70"
    before = sum(len(c.moves) for c in cycles[:-1])
    approach = g70.moves[0].end
    program = [
        "G18 G21 G8 G90.1",
        "F400",
        f"G0 X{g70.position[0]:.12f} Z{g70.position[1]:.12f}",
        f"G0 X{approach[0]:.12f} Z{approach[1]:.12f}",
        *_written_out(g70.moves[1:], "G42.1 D0.3 L2"),
        "M2",
    ]
    ours = run_rs274("\n".join(program) + "\n")
    assert ours.error is None, ours.error
    reference = ref.moves[before + 2 :]  # past the cycle's approach and its start point
    composed = ours.moves[2:]  # past the two positioning rapids
    _compare(
        reference,
        [(m.kind, m.end, m.center, m.rotation) for m in composed],
        1.0,
    )


@pytest.mark.rs274
@needs_rs274
def test_fanuc_g71_g72_g70_equal_rs274_on_the_linuxcnc_rewrite():
    """A Fanuc two-block G71 (U/W allowances), G72 and G70: the same as rs274 on the
    program rewritten into LinuxCNC's form (the contour moved by U/2, W into an O-sub,
    G71.1/G72.1 for type I), but for the return to the start point that Fanuc adds."""
    # N10 G00 X6. ; N20 G01 Z-8. ; N30 X12. Z-10. ; N40 Z-18. ; N50 X20. (diameters)
    a = (11.0, 2.0)  # the tool at the cycle: x radius 11 (X22.), z 2
    fanuc_contour = "G0 X6.\nG1 Z-8.\nX12. Z-10.\nZ-18.\nX20.\n"
    contour = parse_gcode(fanuc_contour, diameter_mode=True, start=a).moves
    cases = [
        ("G71", {"P": 10, "Q": 50, "U": 0.4, "W": 0.1}, {"U": 1.2, "R": 0.4}),
        ("G72", {"P": 10, "Q": 50, "U": 0.2, "W": 0.2}, {"W": 0.8, "R": 0.3}),
        ("G70", {"P": 10, "Q": 50}, None),
    ]
    for code, words, setup in cases:
        cycle = fanuc_cycle(code, words, line=7, setup=setup, p_block={"X": 6.0})
        moves = expand_cycle(cycle, contour, a)
        assert moves[-1].kind == "rapid" and moves[-1].end == a  # Fanuc returns to A
        u, w = words.get("U", 0.0) / 2, words.get("W", 0.0)
        sub = "\n".join(f"G1 X{m.end[0] + u:.10f} Z{m.end[1] + w:.10f}" for m in contour)
        if code == "G70":
            block = "G70 Q100"
        else:
            depth = setup["U" if code == "G71" else "W"]
            block = f"{code}.1 Q100 D0 I{depth} R{setup['R']}"
        text = (
            f"G18 G21 G8 G90\nF100\no100 sub\n{sub}\no100 endsub\nG0 X{a[0]} Z{a[1]}\n{block}\nM2\n"
        )
        ref = run_rs274(text)
        assert ref.error is None, (code, ref.error)
        ours = [("rapid", a, None, 0)] + _ours_moves(moves[:-1])
        _compare(ref.moves, ours, 1.0)


def _ours_moves(moves):
    return [
        ("arc", m.end, m.center, 1 if m.kind == "ccw" else -1)
        if m.is_arc
        else (m.kind, m.end, None, 0)
        for m in moves
    ]


# --- by hand ---------------------------------------------------------------------------


def _lines(points, start, first_line=10):
    """ContourMoves along `points` (x radius, z) from `start`, lines 10, 11, ..."""
    moves, pos = [], start
    for k, p in enumerate(points):
        moves.append(ContourMove("feed", pos, p, first_line + k))
        pos = p
    return moves


STEP = [(4.0, 2.0), (4.0, -5.0), (8.0, -5.0), (8.0, -10.0), (10.0, -10.0)]


def test_g71_layers_by_hand():
    """A stepped shaft from X10 Z2 (radius), I1.5 R0.5 D0: the layers at X 10, 8.5,
    7 and 5.5 cut to the contour and lift 0.5 in X and Z; the last climbs the
    contour from X4."""
    start = (10.0, 2.0)
    cycle = RoughCycle("G71", 3, 10.0, 2.0, allowance=0.0, depth=1.5, retract=0.5)
    moves = expand_cycle(cycle, _lines(STEP, start), (12.0, 5.0))
    got = [(m.kind, m.end) for m in moves]
    expected = [("rapid", (10.0, 2.0))] * 3
    for x, z_end in ((10.0, -10.0), (8.5, -10.0), (7.0, -5.0), (5.5, -5.0)):
        if x != 10.0:
            expected.append(("rapid", (x, 2.0)))
        expected += [
            ("feed", (x, z_end)),
            ("rapid", (x + 0.5, z_end + 0.5)),
            ("rapid", (x + 0.5, 1.5)),
            ("rapid", (x, 2.0)),
        ]
    expected += [("rapid", (4.0, 2.0))] + [("feed", p) for p in STEP[1:]]
    assert len(got) == len(expected)
    for (k1, p1), (k2, p2) in zip(got, expected, strict=True):
        assert k1 == k2
        np.testing.assert_allclose(p1, p2, atol=1e-12)
    assert all(m.line == 3 for m in moves)
    # the moves along the contour carry its blocks; layers and lifts carry none
    assert [m.contour_line for m in moves[-4:]] == [11, 12, 13, 14]
    assert moves[3].contour_line is None


def test_g70_is_the_contour_itself():
    start = (10.0, 3.0)
    contour = _lines(STEP, start)
    moves = expand_cycle(FinishCycle(20, 10.0, 3.0), contour, (10.0, -10.0))
    assert [m.kind for m in moves] == ["rapid", "rapid", "rapid"] + ["feed"] * 4
    assert moves[2].end == STEP[0] and moves[2].contour_line == 10
    for m, c in zip(moves[3:], contour[1:], strict=True):
        assert (m.start, m.end, m.contour_line, m.line) == (c.start, c.end, c.line, 20)


def test_g70_passes_by_hand():
    """D1 E0 P2: the first pass 0.5 off the contour, towards the start point (the
    offset lines meet at the inside corners, an arc about the outside corner joins
    them there), the second on it."""
    start = (10.0, 3.0)
    moves = expand_cycle(FinishCycle(20, 10.0, 3.0, 1.0, 0.0, 2), _lines(STEP, start), start)
    first = [(4.5, 2.0), (4.5, -4.5), (8.0, -4.5), (8.5, -5.0), (8.5, -9.5), (10.0, -9.5)]
    expected = [start, start, *first, start, *STEP]
    np.testing.assert_allclose([m.end for m in moves], expected, atol=1e-12)
    kinds = [m.kind for m in moves]
    assert (
        kinds
        == ["rapid"] * 3 + ["feed"] * 2 + ["ccw"] + ["feed"] * 2 + ["rapid"] * 2 + ["feed"] * 4
    )
    assert moves[5].center == pytest.approx((8.0, -5.0))


def test_arc_contour_and_inch_units_scale():
    """The same contour in mm and in inches (the cycle working in inch units) gives the
    same moves when no tolerance decides."""
    contour_mm = [
        ContourMove("feed", (10.0, 2.0), (4.0, 2.0), 1),
        ContourMove("feed", (4.0, 2.0), (4.0, -6.0), 2),
        ContourMove("cw", (4.0, -6.0), (7.0, -9.0), 3, center=(7.0, -6.0)),
        ContourMove("feed", (7.0, -9.0), (10.0, -9.0), 4),
    ]
    cycle = RoughCycle("G71", 5, allowance=0.254, depth=1.27, retract=0.508)
    mm = expand_cycle(cycle, contour_mm, (10.0, 2.0))
    assert any(m.kind == "cw" for m in mm)
    inch = expand_cycle(cycle, contour_mm, (10.0, 2.0), unit_mm=25.4)
    assert len(mm) == len(inch)
    for a, b in zip(mm, inch, strict=True):
        assert a.kind == b.kind
        np.testing.assert_allclose(a.end, b.end, atol=1e-9)


def test_refusals_name_the_cycle_line():
    start = (10.0, 2.0)
    undercut = _lines([(3.0, 1.0), (3.0, -6.0), (5.0, -4.0), (5.0, -12.0), (9.0, -12.0)], start)
    with pytest.raises(InputError, match=r"line 12: G71: Not monotonic"):
        expand_cycle(RoughCycle("G71", 12), undercut, start)
    with pytest.raises(InputError, match="must start at the cycle's start point"):
        expand_cycle(RoughCycle("G71", 12, x=9.0), undercut, start)
    with pytest.raises(InputError, match="depth of cut"):
        RoughCycle("G71", 12, depth=0.0)
    with pytest.raises(InputError, match="G73"):
        RoughCycle("G73", 12)


def test_cycle_start_and_contour_from_motion():
    assert cycle_start(RoughCycle("G72", 1, x=None, z=4.0), (7.0, 9.0)) == (7.0, 4.0)
    motions = parse_gcode("G1 X4 Z2\nG1 Z-5\nG1 X8\n", start=(8.0, 3.0)).moves
    a = expand_cycle(FinishCycle(9), motions, (8.0, 3.0))
    b = expand_cycle(FinishCycle(9), [ContourMove.from_motion(m) for m in motions], (8.0, 3.0))
    assert a == b


def test_g73_passes_by_hand():
    """Three passes, relief 3 (radius) and 1 in Z, allowance 0.2/0.1: the translations
    are allowance + relief * (3 - k) / 2, each pass the contour moved, lead-in included;
    a rapid to A moved before each pass and back to A at the end."""
    a = (12.0, 2.0)
    contour = [
        ContourMove("rapid", a, (4.0, 1.0), 10),
        ContourMove("feed", (4.0, 1.0), (4.0, -6.0), 11),
        ContourMove("ccw", (4.0, -6.0), (7.0, -9.0), 12, center=(4.0, -9.0)),
        ContourMove("feed", (7.0, -9.0), (12.0, -9.0), 13),
    ]
    cycle = PatternRepeat(4, relief=(3.0, 1.0), passes=3, allowance=(0.2, 0.1))
    assert cycle.translation(1) == pytest.approx((3.2, 1.1))
    assert cycle.translation(2) == pytest.approx((1.7, 0.6))
    assert cycle.translation(3) == pytest.approx((0.2, 0.1))
    moves = expand_pattern_repeat(cycle, contour, a)
    assert len(moves) == 3 * 5 + 1
    for k, (dx, dz) in enumerate([(3.2, 1.1), (1.7, 0.6), (0.2, 0.1)]):
        block = moves[5 * k : 5 * k + 5]
        assert block[0].kind == "rapid" and block[0].contour_line is None
        np.testing.assert_allclose(block[0].end, (12.0 + dx, 2.0 + dz))
        for m, c in zip(block[1:], contour, strict=True):
            assert (m.kind, m.contour_line, m.line) == (c.kind, c.line, 4)
            np.testing.assert_allclose(m.end, (c.end[0] + dx, c.end[1] + dz))
        np.testing.assert_allclose(block[3].center, (4.0 + dx, -9.0 + dz))
    assert moves[-1].kind == "rapid" and moves[-1].end == a
    one = expand_pattern_repeat(PatternRepeat(4, (3.0, 1.0), 1, (0.2, 0.1)), contour, a)
    np.testing.assert_allclose(one[1].end, (4.2, 1.1))  # one pass: the allowance alone
    with pytest.raises(InputError, match="whole number"):
        PatternRepeat(4, (3.0, 1.0), 2.5)


# --- the dialects' words -----------------------------------------------------------------


def test_linuxcnc_words():
    c = linuxcnc_cycle("G71.1", {"Q": 100, "X": 15, "Z": 3.041, "D": 1, "I": 1, "R": 0.3}, line=24)
    assert c == RoughCycle("G71.1", 24, 15.0, 3.041, 1.0, 1.0, 0.3)
    c = linuxcnc_cycle(
        "G70", {"Q": 100, "X": 30, "D": 0.5, "E": 0.1, "P": 2}, line=3, diameter=True, unit_mm=25.4
    )
    assert c == FinishCycle(3, 15 * 25.4, None, 0.5 * 25.4, 0.1 * 25.4, 2.0)
    # LinuxCNC's defaults are in program units: I1 R0.5 of an inch program
    c = linuxcnc_cycle("G72", {"Q": 1}, line=1, unit_mm=25.4)
    assert (c.depth, c.retract, c.allowance) == (25.4, 12.7, 0.0)
    for words, match in (
        ({"Q": 1, "U": 0.2}, "word U is not understood"),
        ({"X": 1}, "needs a Q word"),
    ):
        with pytest.raises(InputError, match=match):
            linuxcnc_cycle("G71", words, line=5)


def test_fanuc_words():
    # two-block G71: U depth (radius) R retract; U/W finishing allowances (U diameter)
    c = fanuc_cycle(
        "G71",
        {"P": 10, "Q": 20, "U": 0.5, "W": 0.1, "F": 0.2},
        line=8,
        setup={"U": 2.0, "R": 0.5},
        p_block={"X": 6.0},
    )
    assert c == RoughCycle(
        "G71.1", 8, depth=2.0, retract=0.5, shift=(0.25, 0.1), return_to_start=True
    )
    # type II: the P block moves both axes (Fanuc), or R1 (Haas)
    assert (
        fanuc_cycle(
            "G71", {"P": 1, "Q": 2}, line=1, setup={"U": 1, "R": 1}, p_block={"X": 6, "W": 0}
        ).code
        == "G71"
    )
    haas = fanuc_cycle(
        "G71", {"P": 1, "Q": 2, "D": 0.1, "R": 1, "U": 0.02}, line=1, retract=0.05, unit_mm=25.4
    )
    assert haas.code == "G71" and haas.depth == pytest.approx(2.54)
    assert haas.shift == pytest.approx((0.254, 0.0))
    g72 = fanuc_cycle("G72", {"P": 1, "Q": 2}, line=1, setup={"W": 0.8, "R": 0.2})
    assert (g72.code, g72.depth, g72.retract) == ("G72.1", 0.8, 0.2)
    assert fanuc_cycle("G70", {"P": 1, "Q": 2}, line=4) == FinishCycle(4, return_to_start=True)
    g73 = fanuc_cycle(
        "G73", {"P": 1, "Q": 2, "U": 0.4, "W": 0.1}, line=6, setup={"U": 3.0, "W": 1.0, "R": 3}
    )
    assert g73 == PatternRepeat(6, (3.0, 1.0), 3, (0.2, 0.1))
    haas73 = fanuc_cycle("G73", {"P": 1, "Q": 2, "I": 3, "K": 1, "D": 3, "U": 0.4}, line=6)
    assert haas73 == PatternRepeat(6, (3.0, 1.0), 3, (0.2, 0.0))
    for code, words, kw, match in (
        ("G71", {"P": 1, "Q": 2}, {}, "without its depth of cut"),
        ("G71", {"P": 1, "Q": 2, "D": 1}, {}, "retract from a control setting"),
        ("G71", {"P": 1}, {"setup": {"U": 1, "R": 1}}, "needs P and Q"),
        ("G71", {"P": 1, "Q": 2, "I": 0.1, "D": 1}, {"retract": 1}, "rough-pass allowances"),
        ("G72", {"P": 1, "Q": 2}, {"setup": {"U": 1, "R": 1}}, "word U is not understood"),
        ("G70", {"P": 1, "Q": 2, "U": 1}, {}, "word U is not understood"),
        ("G73", {"P": 1, "Q": 2}, {}, "number of passes"),
        ("G75", {"P": 1, "Q": 2}, {}, "not a Fanuc"),
    ):
        with pytest.raises(InputError, match=match):
            fanuc_cycle(code, words, line=3, **kw)


def test_non_contour_cycles_are_named():
    for code in ("G74", "G75", "G76", "G32", "G33"):
        assert non_contour_cycle(code).startswith(f"{code}: ")
    assert "thread" in non_contour_cycle("g76")
    assert non_contour_cycle("G33.1", "linuxcnc").startswith("G33.1: rigid tapping")
    assert non_contour_cycle("G73", "linuxcnc") is not None  # drilling there
    assert non_contour_cycle("G73") is None  # pattern repeat: a contour on Fanuc
    assert non_contour_cycle("G71") is None and non_contour_cycle("G1", "haas") is None
    with pytest.raises(InputError, match="unknown dialect"):
        non_contour_cycle("G76", "okuma")


def test_a_g76_thread_is_read_but_never_a_contour():
    """LinuxCNC's G76 is read as rs274 makes it (tests/gcode/test_linuxcnc_corpus.py);
    its moves carry via="G76" and the finish contour is the G42 run after it."""
    from piecs_bayes.gcode import compensation_runs, finish_contour

    text = (
        "G18 G21 G7 G90\nG0 X20 Z2\nG76 P1.5 Z-20 I-1 J0.2 K1 R1.5 Q29.5 H2\n"
        "G0 X10 Z2\nG42.1 D0.8 L2 G1 X8 Z0\nG1 X24\nG1 Z-30\nG1 X30\nG40 G0 X40\nM2\n"
    )
    program = parse_gcode(text, name="thread.ngc")
    thread = [m for m in program.moves if m.via == "G76"]
    assert len(thread) > 10 and {m.kind for m in thread} == {"rapid", "feed"}
    assert thread[-1].end == pytest.approx((10.0, -20.0))  # the drive line's end: X20 Z-20
    assert len(compensation_runs(program)) == 1
    assert [s.line for s in finish_contour(program).segments] == [6, 7]

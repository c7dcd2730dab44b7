"""The Fanuc -> LinuxCNC rewriting helper (tests/gcode/fanuc_rewrite.py) against rs274.

Issue 38's acceptance compares our expansion of a Fanuc program's canned cycles with the moves
rs274 makes from the same program rewritten into LinuxCNC's G7x form. The rewrite is that
reference, so it is tested here: every cycle program of tests/data/gcode/dialects runs through
`rs274 -g` without error, and its G70 finish pass goes through the contour's points, computed
by hand below from the programs (mm, radius X). The tool table gives every tool a zero radius,
so that the compensated path is the programmed one (rs274's G70 under G41/G42 with a real
radius offsets the profile and drops the rapid to the cycle's start point).

rs274 (LinuxCNC 2.9) keeps its tool table in a memory-mapped file, ``$HOME/.tool.mmap``: two
rs274 runs at once under one HOME read each other's tables ("Requested tool 2 not found in
the tool table", a cutter-compensation error, or SIGBUS). Every test here runs it with a HOME
of its own.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from fanuc_rewrite import RewriteError, cycle_parts, rewrite_fanuc

from piecs_bayes.gcode import rs274_path, run_rs274
from piecs_bayes.gcode._rs274 import parse_canon

DIALECTS = Path(__file__).resolve().parents[1] / "data" / "gcode" / "dialects"
ZERO_RADIUS = "T1 P1 Z0 D0 ;\nT2 P2 Z0 D0 ;\nT3 P3 Z0 D0 ;\n"
MM = 1e-4 + 1e-9  # rs274 prints 4 decimals
INCH = 25.4e-4 + 1e-9

pytestmark = [
    pytest.mark.rs274,
    pytest.mark.skipif(
        rs274_path() is None,
        reason="LinuxCNC's rs274 is not installed (make conformance installs linuxcnc-uspace)",
    ),
]

#: the demo shaft's finish pass after the lead-in (data/demo/finish.ngc, radius mm): the seven
#: features, the lead-out up the back of the dia 44 and the Q block's exit to X60. Z-92.
DEMO_PASS = [
    ("feed", (12.0, 0.0)),
    ("feed", (12.0, -30.0)),
    ("feed", (15.0, -45.0)),
    ("feed", (15.0, -57.0)),
    ("arc", (18.0, -60.0), (18.0, -57.0), -1),  # G02 X36. Z-60. R3.: centre X36 Z-57
    ("feed", (22.0, -60.0)),
    ("feed", (22.0, -90.0)),
    ("feed", (24.0, -90.0)),
    ("feed", (30.0, -92.0)),
]
#: ,C1. at X24. Z0. (a square corner: 1 mm along each leg) and ,R3. at X30. Z-60. (the
#: demo's fillet: tangent 3 mm from the corner on both legs, centre X36 Z-57)
CHAMFER_PASS = [("feed", (11.0, 0.0)), ("feed", (12.0, -1.0))] + DEMO_PASS[1:]
#: the inch shaft (haas_g71_one_block_inch.nc), inches x 12.7 for a radius in mm
INCH_PASS = [
    ("feed", (0.75 * 12.7, 0.0)),
    ("feed", (0.75 * 12.7, -1.0 * 25.4)),
    ("feed", (1.0 * 12.7, -1.5 * 25.4)),
    ("feed", (1.0 * 12.7, -2.0 * 25.4)),
    ("arc", (1.25 * 12.7, -2.125 * 25.4), (1.25 * 12.7, -2.0 * 25.4), -1),
    ("feed", (1.5 * 12.7, -2.125 * 25.4)),
    ("feed", (1.5 * 12.7, -3.0 * 25.4)),
    ("feed", (1.6 * 12.7, -3.0 * 25.4)),
    ("feed", (2.0 * 12.7, -3.05 * 25.4)),
]
#: the flange face and boss of fanuc_g72_facing.nc: lead-in onto the OD, 2x45 chamfer, face
#: at Z-10., R2 fillet (G03: centre X34 Z-8), boss dia 30, 1x45 chamfer, front face, exit
FACING_PASS = [
    ("feed", (42.0, -12.0)),
    ("feed", (40.0, -10.0)),
    ("feed", (17.0, -10.0)),
    ("arc", (15.0, -8.0), (17.0, -8.0), 1),
    ("feed", (15.0, -1.0)),
    ("feed", (14.0, 0.0)),
    ("feed", (0.0, 0.0)),
    ("feed", (-0.5, 1.0)),
    ("feed", (-0.5, 3.0)),
]

#: program -> (units, cycles rs274 runs, cycle start point (radius mm), profile start, G70 pass)
CYCLES = {
    "haas_demo_shaft.nc": ("mm", ["ROUGH G71 P10 Q20", "FINISH G70 P10 Q20"], (30.0, 2.0), (4.0, 0.0), DEMO_PASS),
    "haas_g71_one_block_inch.nc": ("in", ["ROUGH G71 P10 Q20", "FINISH G70 P10 Q20"], (25.4, 2.54), (3.175, 0.0), INCH_PASS),
    "fanuc_g71_two_block.nc": ("mm", ["ROUGH G71 P10 Q20", "FINISH G70 P10 Q20"], (30.0, 2.0), (4.0, 0.0), DEMO_PASS),
    "fanuc_g70_finish_tool.nc": ("mm", ["ROUGH G71 P10 Q20", "FINISH G70 P10 Q20"], (30.0, 2.0), (4.0, 0.0), DEMO_PASS),
    "fanuc_g73_pattern_repeat.nc": ("mm", ["ROUGH G73 P10 Q20", "FINISH G70 P10 Q20"], (30.0, 2.0), (4.0, 0.0), DEMO_PASS),
    "fanuc_chamfer_corner_words.nc": ("mm", ["ROUGH G71 P10 Q20", "FINISH G70 P10 Q20"], (30.0, 2.0), (4.0, 0.0), CHAMFER_PASS),
    "fanuc_g72_facing.nc": ("mm", ["ROUGH G72 P10 Q20", "FINISH G70 P10 Q20"], (43.0, 2.0), (43.0, -12.0), FACING_PASS),
    "fanuc_g71_without_g70.nc": ("mm", ["ROUGH G71 P10 Q20"], (30.0, 2.0), (4.0, 0.0), None),
}  # fmt: skip


@pytest.fixture(autouse=True)
def _own_home(tmp_path, monkeypatch):
    """rs274's tool table lives in $HOME/.tool.mmap: a HOME per test, no run shares it."""
    monkeypatch.setenv("HOME", str(tmp_path))


def _rs274(name: str):
    units = CYCLES[name][0] if name in CYCLES else ("in" if "inch" in name else "mm")
    rewrite = rewrite_fanuc((DIALECTS / name).read_text(), units=units)
    result = run_rs274(rewrite.text, tool_table=ZERO_RADIUS)
    return rewrite, result


def _close(a, b, tol) -> bool:
    return all(abs(u - v) <= tol for u, v in zip(a, b, strict=True))


def _assert_pass(moves, expected, tol):
    got = [m for m in moves if m.kind != "rapid"]
    assert len(got) == len(expected), (got, expected)
    for m, e in zip(got, expected, strict=True):
        assert m.kind == e[0] and _close(m.end, e[1], tol), (m, e)
        if m.kind == "arc":
            assert _close(m.center, e[2], tol) and m.rotation == e[3], (m, e)


@pytest.mark.parametrize("name", sorted(CYCLES), ids=str)
def test_rewritten_cycle_program_runs_and_finishes_on_the_contour(name):
    units, cycles, start, first, finish = CYCLES[name]
    rewrite, result = _rs274(name)
    assert result.returncode == 0 and result.error is None, (result.error, rewrite.text)
    parts = cycle_parts(result.output)
    assert list(parts) == cycles
    rough = parse_canon("\n".join(parts[cycles[0]]))[0]
    assert len(rough) > 10  # the roughing passes ran
    if finish is None:
        return
    tol = INCH if units == "in" else MM
    moves = parse_canon("\n".join(parts["FINISH G70 P10 Q20"]))[0]
    assert moves[0].kind == "rapid" and _close(moves[0].end, start, tol)  # to the G70's X Z
    lead = [m for m in moves if m.kind != "rapid"][0]
    before = moves[: moves.index(lead)]
    assert before[-1].kind == "rapid" and _close(before[-1].end, first, tol)  # profile start
    _assert_pass(moves, finish, tol)
    assert moves[-1].kind == "rapid" and _close(moves[-1].end, start, tol)  # back, as Fanuc


def test_g71_depth_and_allowance_reach_rs274():
    """G71 U1.5 R0.5 / G71 P10 Q20 U0.4: rs274 cuts at the start X, then 1.5 mm deeper each
    pass (radius), and its last pass follows the profile 0.2 mm (U/2) off it."""
    rewrite, result = _rs274("fanuc_g71_two_block.nc")
    assert "G71 Q100 X60 Z2 D0.2 I1.5 R0.5" in rewrite.text
    assert rewrite.notes and "U0.4 W0.1" in rewrite.notes[0]
    rough = parse_canon("\n".join(cycle_parts(result.output)["ROUGH G71 P10 Q20"]))[0]
    levels = sorted(
        {m.end[0] for m in rough if m.kind == "feed"} & {30.0 - 1.5 * k for k in range(18)}
    )
    assert levels == [30.0 - 1.5 * k for k in range(17, -1, -1)]  # X60. down to X9.
    ends = [m.end for m in rough if m.kind == "feed"]
    assert any(_close(p, (12.0, 0.2), MM) for p in ends)  # the face, 0.2 in front of it
    assert any(_close(p, (22.2, -89.8), MM) for p in ends)  # the dia 44, 0.2 above it


def test_g73_passes_are_the_contour_shifted_toward_the_finish():
    """G73 U3. W0.5 R3 / G73 P10 Q20 U0.4 W0.1: pass k of 3 starts at the P point (X8. Z0.)
    shifted by 3 (3-k)/2 + 0.2 in X (radius) and 0.5 (3-k)/2 + 0.1 in Z."""
    _, result = _rs274("fanuc_g73_pattern_repeat.nc")
    rough = parse_canon("\n".join(cycle_parts(result.output)["ROUGH G73 P10 Q20"]))[0]
    back = [
        k for k, m in enumerate(rough[:-1]) if m.kind == "rapid" and _close(m.end, (30.0, 2.0), MM)
    ]
    starts = [rough[0].end] + [rough[k + 1].end for k in back]
    assert [tuple(round(v, 4) for v in p) for p in starts] == [
        (4.0 + 3.2, 0.6),
        (4.0 + 1.7, 0.35),
        (4.0 + 0.2, 0.1),
    ]
    assert _close(rough[-1].end, (30.0, 2.0), MM)  # the last pass returns to the start point
    assert sum(1 for m in rough if m.kind == "arc") == 3


@pytest.mark.parametrize(
    "name",
    sorted(
        p.name
        for p in DIALECTS.glob("*.nc")
        if p.name not in CYCLES
        and p.name not in ("fanuc_macro_b.nc", "fanuc_duplicate_n_in_cycle.nc")
    ),
    ids=str,
)
def test_rewritten_plain_program_runs_and_cuts_the_contour(name):
    """The programs without cycles: rs274 runs the rewrite and cuts the demo shaft (or the
    inch shaft) through the same points as the G70 passes above."""
    rewrite, result = _rs274(name)
    assert result.returncode == 0 and result.error is None, (result.error, rewrite.text)
    inch = "inch" in name
    expected = INCH_PASS[:-1] if inch else DEMO_PASS[:-1]
    tol = INCH if inch else MM
    ends = [m.end for m in result.moves if m.kind != "rapid"]
    k = next(i for i, p in enumerate(ends) if _close(p, expected[0][1], tol))
    for m, e in zip([m for m in result.moves if m.kind != "rapid"][k:], expected, strict=False):
        assert m.kind == e[0] and _close(m.end, e[1], tol), (m, e)


def test_g50_coordinate_setting_is_g92():
    rewrite, result = _rs274("fanuc_g50_coordinate_setting.nc")
    assert "N10 G92 X200 Z150" in rewrite.text
    assert _close(result.moves[-1].end, (100.0, 150.0), MM)  # N160 X200. Z150.


def test_incremental_words_become_absolute():
    rewrite, _ = _rs274("fanuc_incremental_uw.nc")
    assert "N50 G42 G1 X8 Z0 F0.08" in rewrite.text and "N150 Z50 M9" in rewrite.text


def test_what_the_helper_does_not_rewrite_is_named():
    with pytest.raises(RewriteError, match="line 4: macro B"):
        rewrite_fanuc((DIALECTS / "fanuc_macro_b.nc").read_text())
    text = (DIALECTS / "haas_demo_shaft.nc").read_text().replace("N18 X48.", "N18 Z-95.")
    with pytest.raises(RewriteError, match="line 19: two collinear moves"):
        rewrite_fanuc(text)
    text = (DIALECTS / "fanuc_g71_two_block.nc").read_text().replace("N20 G00", "N21 G00")
    with pytest.raises(RewriteError, match="line 9: N20 does not come after"):
        rewrite_fanuc(text)

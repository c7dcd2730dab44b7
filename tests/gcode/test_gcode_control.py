"""LinuxCNC control flow and parameters: subroutines, loops, branches, their timing and
refusals. Each program's moves are worked out by hand (in the comments) and, where
``rs274`` is installed, compared with its canonical moves too."""

from __future__ import annotations

import pytest

from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.gcode import (
    STEP_LIMIT,
    ReadOptions,
    adjust_program,
    parse_gcode,
    rs274_path,
    run_rs274,
)
from piecs_bayes.geometry import Line, Profile

HEAD = "G18 G21 G8 F100\n"


def _ends(text: str, **kw) -> list[tuple[float, float]]:
    return [tuple(round(v, 9) for v in m.end) for m in parse_gcode(text, **kw).moves]


def _peer(text: str, ends) -> None:
    """rs274 makes the same moves (when it is installed)."""
    if rs274_path() is None:
        return
    ref = run_rs274(text)
    assert ref.error is None, ref.error
    got = [v for m in ref.moves for v in m.end]
    assert got == pytest.approx([float(v) for e in ends for v in e], abs=1e-4)


SUB = HEAD + (
    "o<step> sub\n"  # 2
    "  G1 X#1 Z#2\n"  # 3: runs twice, with the call's arguments
    "  o<step> return [#1 + #2]\n"
    "o<step> endsub\n"
    "o<step> call [1] [2]\n"  # 6: X1 Z2, returns 3
    "G1 X#<_value> Z#<_value_returned>\n"  # 7: X3 Z1
    "o<step> call [3] [-1]\n"  # 8: X3 Z-1, returns 2
    "G1 X[#<_value> * 10] Z0\n"  # 9: X20 Z0
    "M2\n"
)


def test_a_subroutine_with_arguments_and_its_return_value():
    ends = [(1, 2), (3, 1), (3, -1), (20, 0)]
    assert _ends(SUB) == ends
    _peer(SUB, ends)


def test_a_line_run_twice_or_computed_says_why_it_cannot_be_edited():
    p = parse_gcode(SUB, name="sub.ngc")
    assert [m.line for m in p.moves] == [3, 7, 3, 9]
    assert p.runs_of(3) == 2 and p.runs_of(7) == 1 and p.runs_of(2) == 1
    assert p.computed == frozenset({3, 7, 9})
    assert "ran 2 times" in p.edit_refusal(3)
    assert "computes its words" in p.edit_refusal(7)
    assert p.edit_refusal(1) is None


def test_the_adjusted_program_refuses_a_contour_line_that_runs_twice():
    text = HEAD + (
        "G0 X20 Z5\no<cut> sub\n  G42.1 D0.8 L3 G1 X10 Z0\n  G1 Z-10\n  G1 X12\n  G40 G0 X20\n"
        "o<cut> endsub\no<cut> call\no<cut> call\nM2\n"
    )
    nominal = Profile((Line("d", (10.0, 0.0), (10.0, -10.0), -1),))
    with pytest.raises(AnalysisError, match="ran 2 times"):
        adjust_program(parse_gcode(text, name="twice.ngc"), nominal, nominal, max_correction_mm=0.1)


def test_parameters_take_effect_after_their_line():
    text = HEAD + (
        "#1 = 5 #2 = [#1 + 1]\n"  # #2 = 0 + 1: #1 is set after the line is read
        "G1 X#1 Z#2\n"  # X5 Z1
        "#1 = [#1 + 1] G1 X#1 Z0\n"  # X5 (the old #1), then #1 = 6
        "G1 X#1 Z0\n"  # X6
        "M2\n"
    )
    ends = [(5, 1), (5, 0), (6, 0)]
    assert _ends(text) == ends
    _peer(text, ends)


def test_local_and_global_parameters():
    text = HEAD + (
        "o<s> sub\n  #1 = 7\n  #<loc> = 1\n  #<_glob> = [#2 + 1]\n  G1 X#1 Z#<loc>\no<s> endsub\n"
        "#1 = 2 #<loc> = 9\n"
        "o<s> call [0] [4]\n"  # inside: X7 Z1; #<_glob> = 5
        "G1 X#1 Z#<loc>\n"  # back: #1 = 2 and #<loc> = 9 again: X2 Z9
        "G1 X#<_glob> Z#31\n"  # X5 Z0 (#31 is global, unset: 0)
        "M2\n"
    )
    ends = [(7, 1), (2, 9), (5, 0)]
    assert _ends(text) == ends
    _peer(text, ends)
    with pytest.raises(InputError, match=r"#<loc> is not set") as exc:
        parse_gcode(HEAD + "#<loc> = 1\no<s> sub\nG1 X#<loc>\no<s> endsub\no<s> call\n")
    assert exc.value.line == 4


NESTED = HEAD + (
    "#<i> = 0\n"
    "o1 while [#<i> LT 3]\n"
    "  o2 if [#<i> EQ 0]\n    G1 X10 Z[-#<i>]\n"
    "  o2 elseif [#<i> EQ 1]\n    G1 X11 Z[-#<i>]\n"
    "  o2 else\n    G1 X12 Z[-#<i>]\n"
    "  o2 endif\n"
    "  #<i> = [#<i> + 1]\n"
    "o1 endwhile\n"
    "M2\n"
)


def test_nested_while_and_if_elseif_else():
    ends = [(10, 0), (11, -1), (12, -2)]
    assert _ends(NESTED) == ends
    _peer(NESTED, ends)
    p = parse_gcode(NESTED)
    assert [p.runs_of(n) for n in (3, 5, 7, 9, 11)] == [4, 1, 1, 1, 3]


def test_repeat_do_while_break_and_continue():
    # (a do loop holding both a break and a continue is left out: LinuxCNC 2.9's rs274
    # leaves such a loop at the continue, which its documentation does not say)
    text = HEAD + (
        "G0 X0 Z0\n"
        "o3 repeat [3]\n  G1 Z[#<_z> - 1]\no3 endrepeat\n"  # Z-1, Z-2, Z-3
        "o4 repeat [0]\n  G1 X99\no4 endrepeat\n"  # never
        "#1 = 0\n"
        "o5 do\n"
        "  #1 = [#1 + 1]\n"
        "  o6 if [#1 EQ 2]\n    o5 continue\n  o6 endif\n"  # skips X2
        "  G1 X#1\n"
        "o5 while [#1 LT 4]\n"  # X1, X3, X4
        "o7 do\n"
        "  #1 = [#1 + 1]\n"
        "  G1 Z[-#1]\n"
        "  o8 if [#1 GE 6]\n    o7 break\n  o8 endif\n"  # Z-5, Z-6
        "o7 while [1]\n"
        "#2 = 0\n"
        "o9 while [#2 LT 3]\n"
        "  #2 = [#2 + 1]\n"
        "  o10 if [#2 EQ 2]\n    o9 continue\n  o10 endif\n"
        "  G1 X[10 + #2]\n"  # X11, X13
        "o9 endwhile\n"
        "M2\n"
    )
    ends = [(0, 0), (0, -1), (0, -2), (0, -3), (1, -3), (3, -3), (4, -3), (4, -5), (4, -6)]
    ends += [(11, -6), (13, -6)]
    assert _ends(text) == ends
    _peer(text, ends)


def test_predefined_parameters_and_modes():
    text = (
        "G18 G21 G7 F100\nG0 X10 Z-3\n"  # radius 5
        "G1 X[#<_x> * 2 + 2] Z[#<_z>]\n"  # #<_x> is the radius: X12 -> 6
        "G1 X[#5420 * 2] Z[#5422 - #<_metric> - #<_imperial>]\n"  # X12, Z-4
        "G1 X[#<_lathe_diameter_mode> * 20] Z[#<_motion_mode>]\n"  # X20, Z10 (G1)
        "M2\n"
    )
    ends = [(5, -3), (6, -3), (6, -4), (10, 10)]
    assert _ends(text) == ends
    _peer(text, ends)


def test_m73_restores_the_modes_when_the_call_returns():
    text = (
        "G18 G21 G7 F100\nG0 X10 Z0\n"
        "o<m> sub\n  M73\n  G8 G91\n  G1 X1 Z-1\no<m> endsub\n"  # radius, incremental
        "o<m> call\n"
        "G1 X20 Z-5\n"  # diameter and absolute again: (10, -5)
        "M2\n"
    )
    ends = [(5, 0), (6, -1), (10, -5)]
    assert _ends(text) == ends
    _peer(text, ends)


COORDS = (
    "G18 G21 G7 F100\n"
    "G0 X10 Z10\n"  # (5, 10)
    "G10 L2 P1 X4 Z1\n"  # the G54 offset moves: the program coordinates stay
    "G0 X10 Z10\n"  # (5, 10)
    "G10 L20 P1 X2 Z2\n"  # here is now X2 Z2
    "G0 X2 Z2\n"  # (1, 2): no move of the machine
    "G92 X0 Z0\n"  # here is now 0 0
    "G0 X2 Z-1\n"  # (1, -1)
    "G92.1\n"  # the shift is gone: here is (1 + 1, -1 + 2)
    "G0 X2 Z-1\n"  # (1, -1)
    "G10 L2 P0 X0 Z0\n"  # the offsets of the system in use, (6, 9) since L20, back to 0
    "G30\n"  # the intermediate point (here: (1 + 6, -1 + 9)), the second reference (0, 0)
    "G28.1\n"  # the first reference here
    "G0 X8 Z8\n"  # (4, 8)
    "G28 Z3\n"  # via Z3, Z back to the reference: (4, 3), (4, 0)
    "G53 G0 X2 Z5\n"  # machine coordinates: (1, 5)
    "M2\n"
)


def test_offsets_shifts_references_and_machine_coordinates():
    ends = [(5, 10), (5, 10), (1, 2), (1, -1), (1, -1), (7, 8), (0, 0), (4, 8), (4, 3), (4, 0)]
    ends.append((1, 5))
    p = parse_gcode(COORDS, name="coords.ngc")
    assert [tuple(round(v, 9) for v in m.end) for m in p.moves] == ends
    assert [m.via for m in p.moves][5:] == ["G30", "G30", "", "G28", "G28", "G53"]
    assert [n.word for n in p.notes][:3] == ["G10 L2 P1", "G10 L20 P1", "G92"]
    _peer(COORDS, ends)


def test_block_delete_runs_unless_the_switch_is_on():
    text = HEAD + "G1 X1 Z0\n/G1 X2\nG1 X3\nM2\n"
    assert _ends(text) == [(1, 0), (2, 0), (3, 0)]
    p = parse_gcode(text)
    assert [(n.line, n.word) for n in p.notes] == [(3, "/")]
    assert _ends(text, options=ReadOptions(block_delete=True)) == [(1, 0), (3, 0)]


@pytest.mark.parametrize(
    "body, line, message",
    [
        ("o100 sub\nG1 X1\nM2\n", 2, "o100 sub has no o100 endsub"),
        ("o200 call [1]\nM2\n", 2, "no o200 sub in this program"),
        ("o<x> endsub\n", 2, "endsub without o<x> sub"),
        ("o1 if [1]\nG1 X1\no2 endif\n", 4, "endif without o2 if (o1 if is still open)"),
        ("o1 endwhile\n", 2, "endwhile without o1 while"),
        ("o1 while [1]\no2 break\no1 endwhile\n", 3, "o2 break outside an o2 while or do loop"),
        ("o1 repeat [2]\no1 break\no1 endrepeat\n", 3, "not repeat"),
        ("o1 return\n", 2, "return outside a subroutine"),
        ("G1 X[1/0]\n", 2, "word X[1/0]: division by zero"),
        ("G1 X#<nope>\n", 2, "#<nope> is not set"),
        ("G1 X#5061\n", 2, "probe"),
        ("M98 P10\n", 2, "M98 is not understood"),
        ("IF [1 GT 0] GOTO 10\n", 2, "macro B statements (IF) are Fanuc's"),
        ("G1 X1\x00\n", 2, "NUL byte"),
        ("(abort, tool broken)\n", 2, "the program aborts: tool broken"),
        ("o1 sub\no1 endsub\no1 sub\no1 endsub\n", 4, "defined twice"),
    ],
)
def test_refusals_name_the_line_and_why(body, line, message):
    with pytest.raises(InputError) as exc:
        parse_gcode(HEAD + body, name="bad.ngc")
    assert exc.value.line == line and exc.value.file == "bad.ngc", str(exc.value)
    assert message in str(exc.value)


def test_an_endless_loop_stops_at_the_step_limit_naming_it():
    assert ReadOptions().step_limit == STEP_LIMIT == 1_000_000
    text = HEAD + "G0 X0 Z0\no1 while [1]\n  G1 X1\n  G1 X0\no1 endwhile\nM2\n"
    with pytest.raises(InputError) as exc:
        parse_gcode(text, name="loop.ngc", options=ReadOptions(step_limit=1000))
    assert "ran 1,000 blocks without ending (inside the loop of line 3)" in str(exc.value)
    assert exc.value.line in (3, 4, 5, 6)
    with pytest.raises(InputError, match="step_limit must be"):
        ReadOptions(step_limit=0)


def test_a_call_that_never_returns_is_refused():
    text = HEAD + "o<r> sub\no<r> call\no<r> endsub\no<r> call\nM2\n"
    with pytest.raises(InputError, match="nested deeper than 50"):
        parse_gcode(text)

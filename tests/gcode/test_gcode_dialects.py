"""Dialects: detection with its reason, Fanuc / Haas / Okuma words, macro B, subprograms,
headers and tape marks. Programs in the style of the controls' programming manuals; the
moves (mm, radius X) are worked out by hand in the comments."""

from __future__ import annotations

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import (
    Dialect,
    ReadOptions,
    detect_dialect,
    lex_gcode,
    parse_gcode,
    tool_call,
)


def _moves(program):
    return [(m.kind, tuple(round(v, 9) for v in m.end), m.line, m.via) for m in program.moves]


FANUC = (
    "%\n"  # 1
    "O1234 (SHAFT)\n"  # 2
    "N10 G21 G18 G40 G99\n"  # 3
    "N20 G28 U0 W0\n"  # 4: via here (0, 0) to the reference: unknown
    "N30 T0101\n"  # 5
    "N40 G50 S2500\n"  # 6: the spindle clamp (recorded)
    "N50 G96 S180 M03\n"  # 7
    "N60 G00 X50. Z5. M08\n"  # 8: from an unknown position to (25, 5): recorded
    "N70 G01 X40. Z0. F0.2\n"  # 9: (20, 0)
    "N80 U10. W-10.\n"  # 10: U is an incremental diameter: (25, -10)
    "N90 G97 S1000\n"  # 11
    "N100 G98 G01 W-5. F100.\n"  # 12: feed per minute; (25, -15)
    "N110 G04 X1.5\n"  # 13: a dwell of 1.5 s, not an axis
    "N120 G00 G01 X60.\n"  # 14: two codes of group 01: the last (G01) is valid; (30, -15)
    "N130 G28 U0. W0.\n"  # 15: via (30, -15) to the reference
    "N140 M30\n"  # 16
    "%\n"  # 17
)


def test_fanuc_words():
    p = parse_gcode(FANUC, name="f.nc")
    assert p.dialect.name == "fanuc"
    assert "U/W words" in p.dialect.reason and "G50" in p.dialect.reason
    assert _moves(p) == [
        ("rapid", (0, 0), 4, "G28"),
        ("feed", (20, 0), 9, ""),
        ("feed", (25, -10), 10, ""),
        ("feed", (25, -15), 12, ""),
        ("feed", (30, -15), 14, ""),
        ("rapid", (30, -15), 15, "G28"),
    ]
    assert p.state(9).feed_per_rev and not p.state(12).feed_per_rev
    assert p.state(9).diameter and p.state(9).units == "mm"
    words = [(n.line, n.word) for n in p.notes]
    assert (6, "G50 S2500") in words and (14, "G0 G1") in words and (4, "G28") in words
    tool = p.state(9).tool
    assert (tool.text, tool.by) == ("T0101", "T")
    assert (tool_call(tool).tool, tool_call(tool).offset) == (1, 1)


def test_a_known_machine_zero_makes_the_reference_return_a_move():
    p = parse_gcode(FANUC, options=ReadOptions(machine_zero=(100.0, 200.0)))
    assert _moves(p)[:3] == [
        ("rapid", (0, 0), 4, "G28"),
        ("rapid", (100, 200), 4, "G28"),
        ("rapid", (25, 5), 8, ""),
    ]


def test_a_cut_from_an_unknown_position_is_refused():
    text = "G21 G18 G99\nG28 U0. W0.\nG01 U-2. F0.1\nM30\n"
    with pytest.raises(InputError, match="not known") as exc:
        parse_gcode(text, name="u.nc")
    assert exc.value.line == 3


def test_g50_x_z_sets_the_coordinates_of_where_the_tool_is():
    text = (
        "G21 G18 G99\nT0101\n"
        "G00 X40. Z10.\n"  # (20, 10)
        "G50 X100. Z50.\n"  # here is now X100 Z50: (50, 50)
        "G00 X80. Z40.\n"  # (40, 40): 10 mm down and left of where G50 was given
        "U-20. W-10.\n"  # (30, 30)
        "M30\n"
    )
    p = parse_gcode(text)
    assert p.dialect.name == "fanuc"
    assert [m.end for m in p.moves] == [(20.0, 10.0), (40.0, 40.0), (30.0, 30.0)]
    assert any(n.word == "G50" and "(x=50.0000, z=50.0000)" in n.text for n in p.notes)


def test_haas_safe_start_block():
    text = (
        "%\nO01000\n(T2 FINISH)\nN1 G00 G18 G20 G40 G80 G99\nN2 T0202\nG50 S3000\n"
        "G96 S600 M03\nG00 X1.2 Z0.1\nG01 X1. F0.004\nM30\n%\n"
    )
    p = parse_gcode(text)
    assert p.dialect.name == "haas" and "safe-start block G00 G18 G20 G40 G80 G99" in (
        p.dialect.reason
    )
    assert p.moves[-1].end == pytest.approx((12.7, 2.54))
    assert p.state(9).units == "in" and p.state(9).feed_per_rev
    with pytest.raises(InputError, match="G0 and G80 in one block") as exc:
        parse_gcode(text, "linuxcnc")
    assert exc.value.line == 4


def test_chamfer_and_corner_words_make_their_moves():
    text = (
        "G21 G18 G99\nT0101\n"
        "G00 X20. Z2.\n"  # 3: (10, 2)
        "G01 Z0. F0.1\n"  # 4: (10, 0)
        "X30. ,C1.\n"  # 5: up to the corner at (15, 0) less 1 mm, the chamfer to (15, -1)
        "Z-10. ,R2.\n"  # 6: down to (15, -8), a 2 mm corner round to (17, -10)
        "X40.\n"  # 7: (20, -10)
        "M30\n"
    )
    p = parse_gcode(text)
    got = [(m.kind, m.start, m.end, m.line, m.via) for m in p.moves]
    assert got[2:] == [
        ("feed", (10.0, 0.0), (14.0, 0.0), 5, ""),
        ("feed", (14.0, 0.0), (15.0, -1.0), 5, ",C"),
        ("feed", (15.0, -1.0), (15.0, -8.0), 6, ""),
        ("cw", (15.0, -8.0), (17.0, -10.0), 6, ",R"),
        ("feed", (17.0, -10.0), (20.0, -10.0), 7, ""),
    ]
    assert p.moves[5].center == pytest.approx((17.0, -8.0))
    with pytest.raises(InputError, match="has no next move"):
        parse_gcode("G21 G18 G99\nG00 X20. Z2.\nG01 X30. ,C1. F0.1\nM30\n")


MACRO = (
    "%\nO0100 (MACRO B)\nG21 G18 G40 G99\n"  # 1-3
    "#100 = 20.\n#101 = 0\n"  # 4-5
    "N10 T0101\nG00 X50. Z2.\n"  # 6-7: (25, 2)
    "WHILE [#101 LT 3] DO1\n"  # 8
    "  #102 = #100 + #101 * 2\n"  # 9: 20, 22, 24 (no brackets: Fanuc)
    "  G01 X#102 Z-10. F0.2\n"  # 10: (10, -10), (11, -10), (12, -10)
    "  G00 U2. W12.\n"  # 11: (11, 2), (12, 2), (13, 2)
    "  #101 = #101 + 1\n"  # 12
    "END1\n"  # 13
    "IF [#100 EQ 20] GOTO 30\n"  # 14: taken
    "G01 X99.\n"  # 15: skipped
    "N30 IF [#101 GT 2] THEN #103 = 5\n"  # 16
    "G01 X[#103 * 2] Z#104\n"  # 17: #104 is vacant: no Z word; (5, 2)
    "M98 P200 L2\n"  # 18: O200 twice: (5, 1), (5, 0)
    "G65 P300 A1. B2.\n"  # 19: #1 = 1, #2 = 2: X21 Z-2 -> (10.5, -2)
    "M98 P30010\n"  # 20: O0010 three times: W-1 each
    "M30\n"  # 21
    "O200\nG01 W-1.\nM99\n"  # 22-24
    "O300\nG01 X[#1 + #2 * 10] Z-#2\nM99\n"  # 25-27
    "O0010\nG01 W-1.\nM99\n"  # 28-30
    "%\n"
)


def test_macro_b_loops_branches_subprograms_and_macro_calls():
    p = parse_gcode(MACRO, name="m.nc")
    assert p.dialect.name == "fanuc" and "macro B WHILE" in p.dialect.reason
    ends = [tuple(round(v, 9) for v in m.end) for m in p.moves]
    assert ends == [(25, 2), (10, -10), (11, 2), (11, -10), (12, 2), (12, -10), (13, 2)] + [
        (5, 2),
        (5, 1),
        (5, 0),
        (10.5, -2),
        (10.5, -3),
        (10.5, -4),
        (10.5, -5),
    ]
    assert p.runs_of(15) == 0 and p.runs_of(10) == 3 and p.runs_of(23) == 2 and p.runs_of(29) == 3
    assert {10, 17, 26} <= p.computed
    assert "ran 3 times" in p.edit_refusal(10)


@pytest.mark.parametrize(
    "body, line, message",
    [
        ("GOTO 99\n", 2, "there is no block N99"),
        ("N5 G00 X1.\nN5 G00 X2.\nGOTO 5\n", 4, "N5 is on several lines (2, 3)"),
        ("END1\n", 2, "END1 without WHILE [...] DO1"),
        ("WHILE [1] DO2\nG00 X1.\n", 2, "has no END2"),
        ("M98 P1234\n", 2, "program O1234 is not in this file"),
        ("#3000 = 12 (SPINDLE FAULT)\n", 2, "alarm 12 (#3000) SPINDLE FAULT"),
        ("G90 X10. Z-5. F0.2\n", 2, "turning box cycle"),
        ("G91 G00 X1.\n", 2, "does not exist in Fanuc lathe G-code system A"),
        ("G71 P10 Q20 U0.4 W0.1 F0.25\n", 2, "without its depth of cut"),
        ("G71 U2. R0.5\nG71 P10 Q20\nN10 G01 X10.\n", 3, "there is no block N20"),
        ("G70 U2.\n", 2, "G70 needs P and Q"),
        ("G74 X10. Z-5. P1000 Q2000 R0.5 F0.1\n", 2, "G74 (face grooving"),
        ("G01 X10. U2. F0.1\n", 2, "X and U"),
        ("G50 U10.\n", 2, "G50 takes X/Z"),
        ("o100 sub\n", 2, "O-word statements (o100 sub) are LinuxCNC's"),
        ("G00 Y5.\n", 2, "word Y5. is not understood"),
    ],
)
def test_fanuc_refusals_name_the_line_and_why(body, line, message):
    with pytest.raises(InputError) as exc:
        parse_gcode("G21 G18 G99\n" + body + "M30\n", "fanuc", name="bad.nc")
    assert exc.value.line == line and message in str(exc.value), str(exc.value)


def test_m99_in_the_main_program_ends_it_with_a_note():
    p = parse_gcode("G21 G18 G99\nG00 X10. Z1.\nM99\nG00 X20.\n", "fanuc")
    assert len(p.moves) == 1 and p.notes[-1].word == "M99"


def test_program_headers_and_tape_marks():
    text = "%\n:0100 (COLON NUMBER)\nG21 G18 G99\nG00 X10. Z1.\nM30\n\n%\n))) not the program\n"
    p = parse_gcode(text, name="t.nc")
    assert p.dialect.name == "fanuc" and ":program number" in p.dialect.reason
    assert p.lines[1].words[0].letter == "O" and p.lines[1].words[0].value == 100
    assert [m.end for m in p.moves] == [(5.0, 1.0)] and p.text == text
    one_line = parse_gcode("%\nO1\nG21 G18 G99\nG00 X10. Z1.\nM30 %\n", "fanuc")
    assert len(one_line.moves) == 1 and one_line.lines[-1].percent
    crlf = parse_gcode(FANUC.replace("\n", "\r\n"), name="crlf.nc")
    assert _moves(crlf) == _moves(parse_gcode(FANUC)) and crlf.text.count("\r\n") == 17


OKUMA = (
    "$FLANGE.MIN%\n"  # 1
    "N001 G50 S2000\n"  # 2
    "N002 G00 X200 Z200\n"  # 3: (100, 200)
    "N003 T010101\n"
    "N004 G96 S150 M03\n"
    "N005 G00 X50 Z5 M08\n"  # 6: (25, 5)
    "N006 G42 G01 X20 Z0 F0.2\n"  # 7: (10, 0)
    "N007 G01 X30 Z0\n"  # 8: (15, 0)
    "N008 G03 X40 Z-5 K-5\n"  # 9: K only: centre (15, -5)
    "N009 G01 Z-20\n"  # 10: (20, -20)
    "N010 G02 X50 Z-25 I5\n"  # 11: I only: centre (25, -20)
    "N011 G40 G00 X60\n"  # 12: (30, -25)
    "N012 M02\n"
)


def test_okuma_header_and_arcs_with_one_centre_word():
    p = parse_gcode(OKUMA, name="flange.min")
    assert p.dialect == Dialect("okuma", "$FLANGE.MIN% header")
    assert [m.end for m in p.moves] == [
        (100.0, 200.0),
        (25.0, 5.0),
        (10.0, 0.0),
        (15.0, 0.0),
        (20.0, -5.0),
        (20.0, -20.0),
        (25.0, -25.0),
        (30.0, -25.0),
    ]
    assert p.moves[4].center == (15.0, -5.0) and p.moves[4].kind == "ccw"
    assert p.moves[6].center == (25.0, -20.0) and p.moves[6].kind == "cw"


def test_okuma_lap_cycles_are_refused_by_name():
    text = OKUMA.replace("N012 M02\n", "N012 G85 NLAP1 D2 U0.5 W0.1 F0.3\nN013 M02\n")
    with pytest.raises(InputError, match="G85: Okuma LAP cycles") as exc:
        parse_gcode(text, name="lap.min")
    assert exc.value.line == 13


@pytest.mark.parametrize(
    "text, name, reason",
    [
        ("G18 G7 G21\nG0 X10 Z0\n", "linuxcnc", "G7/G8"),
        ("o<a> sub\no<a> endsub\no<a> call\n", "linuxcnc", "O-word"),
        ("#<depth> = 2\nG0 X#<depth>\n", "linuxcnc", "named parameters"),
        ("G0 X10 Z0\n", "linuxcnc", "nothing dialect-specific found"),
        ("G0 X10 Z0\nG1 U-2 W-1\n", "fanuc", "U/W words"),
        ("G50 S2000\nG0 X10 Z0\n", "fanuc", "G50"),
        ("#1 = 1\nIF [#1 GT 0] GOTO 10\nN10 G0 X1\n", "fanuc", "macro B IF"),
        ("G0 X10 Z0\nM98 P100\n", "fanuc", "M98/M99"),
        ("G0 X10 Z0\nG1 X20 ,C1\nZ-5\n", "fanuc", ",C/,R"),
        ("G0 X10 Z0\nM97 P100\n", "haas", "M97"),
        ("$A.MIN%\nG0 X10 Z0\n", "okuma", "$A.MIN% header"),
    ],
)
def test_detection_names_the_dialect_and_why(text, name, reason):
    d = detect_dialect(lex_gcode(text))
    assert d.name == name and reason in d.reason, d


def test_a_given_dialect_and_its_defaults():
    text = "G18 G21\nG0 X20 Z0\n"
    assert parse_gcode(text).moves[0].end == (20.0, 0.0)  # LinuxCNC: radius
    p = parse_gcode(text, "fanuc")
    assert p.dialect == Dialect("fanuc", "given") and p.moves[0].end == (10.0, 0.0)
    assert p.options.dialect == "fanuc" and p.options.diameter_mode is True
    assert parse_gcode(text, options=ReadOptions(dialect="okuma")).dialect.name == "okuma"
    assert parse_gcode(text, "fanuc", diameter_mode=False).moves[0].end == (20.0, 0.0)
    with pytest.raises(InputError, match="expected one of linuxcnc, fanuc, haas, okuma"):
        parse_gcode(text, "siemens")

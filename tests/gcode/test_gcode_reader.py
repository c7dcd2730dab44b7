"""Part-program reader and lossless writer: modal state, conventions, errors, round trips."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import (
    edit_line,
    format_number,
    lex_gcode,
    parse_gcode,
    parse_tool_table,
    read_gcode,
    read_tool_table,
)
from piecs_bayes.gcode._rs274 import parse_canon
from piecs_bayes.geometry import Arc, Line

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
CORPUS = sorted(DATA.glob("*.ngc")) + sorted(DATA.glob("*/*.ngc"))


def test_corpus_is_big_enough():
    assert len(sorted(DATA.glob("*.ngc"))) >= 20
    assert len(sorted((DATA / "gouge").glob("*.ngc"))) >= 5


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: p.name)
def test_round_trip_is_byte_identical(path):
    """Lossless text: every program read in full (its canned cycles run)."""
    program = read_gcode(path)
    assert program.source.to_bytes() == path.read_bytes()
    assert program.text.encode() == path.read_bytes()


_number = st.builds(
    lambda sign, a, point, b: f"{sign}{a}{point}{b}" if (a or b) else "0",
    st.sampled_from(["", "-", "+"]),
    st.sampled_from(["", "0", "12", "007"]),
    st.sampled_from(["", "."]),
    st.sampled_from(["", "5", "250", "0001"]),
)
_word = st.builds(lambda c, n: c + n, st.sampled_from(list("GMXZIKRFSTNgxz")), _number)
_piece = st.one_of(
    _word,
    st.builds(lambda t: f"({t})", st.text(alphabet="abc 1.;%#", max_size=8)),
    st.sampled_from([" ", "\t", "  "]),
)
_line = st.one_of(
    st.lists(_piece, max_size=6).map("".join),
    st.builds(
        lambda a, t: a + ";" + t,
        st.lists(_piece, max_size=3).map("".join),
        st.text(alphabet="xyz ();#%\t\xe9", max_size=8),
    ),
    st.just("%"),
)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(_line, st.sampled_from(["\n", "\r\n", "\r"])), max_size=8), st.booleans())
def test_round_trip_property(lines, last_eol):
    text = "".join(a + b for a, b in lines)
    if lines and not last_eol:
        text = text[: -len(lines[-1][1])]
    assert lex_gcode(text).text == text


@settings(max_examples=300, deadline=None)
@given(_line)
def test_the_fast_paths_lex_as_the_full_lexer(text):
    # most lines are lexed by one regular expression; the full lexer is the reference
    from piecs_bayes.gcode._lexer import _LexError, _LineLexer, lex_line

    full = _LineLexer(text)
    try:
        full.run()
    except _LexError:
        return
    line = lex_line(text, "\n", 1, None)
    assert line.words == tuple(full.words) and line.comments == tuple(full.comments)
    assert line.percent == full.percent


def test_round_trip_keeps_odd_bytes_endings_and_blanks():
    raw = b"%\r\nG18 G21\t(tab) \r\n\r\n  g1 x1.50 z-2 f100 ; caf\xe9\rG0 X2\n%"
    text = raw.decode("utf-8", errors="surrogateescape")
    src = lex_gcode(text, name="odd.ngc")
    assert src.to_bytes() == raw
    assert [ln.eol for ln in src.lines] == ["\r\n", "\r\n", "\r\n", "\r", "\n", ""]
    assert src.lines[0].percent and src.lines[-1].percent


def test_parameters_expressions_and_block_delete_are_lexed():
    # (these were refused before the reader ran control flow and parameters)
    line = lex_gcode("/G1 X#1 Z[1+2] #3=[#1*2] (c)\n").lines[0]
    assert line.block_delete and [str(w) for w in line.words] == ["G1", "X#1", "Z[1+2]"]
    assert line.words[1].expr is not None and math.isnan(line.words[1].value)
    assert [a.text for a in line.assignments] == ["#3=[#1*2]"] and line.computed


def test_words_keep_their_text():
    line = lex_gcode("N10 g01 X 20.500 Z-.25 F+0.1 (c) ; rest\n").lines[0]
    assert [str(w) for w in line.words] == ["N10", "G01", "X20.500", "Z-.25", "F+0.1"]
    assert [w.code for w in line.words[:2]] == ["N10", "G1"]
    assert line.word("X").decimals == 3 and line.word("X").value == 20.5
    assert [c.text for c in line.comments] == ["c", " rest"]


@pytest.mark.parametrize(
    "text, message",
    [
        ("G1 X1 (open\n", "not closed"),
        ("G1 X Z1\n", "has no number"),
        ("G1 X1 % Z2\n", "must end its line"),
        ("G1 X[1+2\n", "not closed"),
        ("G1 X1 /Z2\n", "must begin the line"),
        ("#1 2\n", "not assigned"),
        ("G1 X10\x00\n", "NUL byte"),
    ],
)
def test_lexer_errors_name_line_and_text(text, message):
    with pytest.raises(InputError) as exc:
        lex_gcode("G18\n" + text, name="bad.ngc")
    assert exc.value.line == 2 and exc.value.file == "bad.ngc"
    assert message in str(exc.value) and text.strip()[:6] in str(exc.value)


@pytest.mark.parametrize(
    "block, message",
    [
        ("G17 G2 X1 Y1 R5", "an arc in the XY plane (G17) is not read"),
        ("G19 G3 Y1 Z1 R5", "an arc in the YZ plane (G19) is not read"),
        ("G2 X1 Y1 Z1 R5", "helix"),
        ("G41.1 D1 G1 X1 Y1", "a Y move with nose compensation on"),
        ("G17 G41.1 D1 G1 X1", "read in the XZ plane (G18) only"),
        ("G17.1 G1 X1", "XZ plane"),
        ("G81 X0 Z-1 R1", "drills across the axis"),
        ("G17 G83 X0 Z-1 R1", "G83 needs the peck Q on its first block"),
        ("G17 G81 X0 Z-1", "G81 needs the clearance plane R"),
        ("G17 G81 X0 Z1 R0", "is below the bottom Z"),
        ("G17 G81 X0 Z-1 R1 L0", "L (repeats)"),
        ("G17 G84 X0 Z-1 R1", "tapping cycles"),
        ("G38.2 X0", "the start point is the probe's end point"),
        ("G95 G38.2 X1", "feed per revolution"),
        ("G10 L2 P1 Y1", "offsets of the Y axis"),
        ("G53 G0 Y1", "machine coordinates are not read"),
        ("G2 X1 Z1 J1", "XZ plane"),
        ("G33 X1", "not understood"),
        ("G33 X1 K1.5", "G33: threading"),
        ("G76 P1.5 Z-20 I-1 J0.1 K0.05", "K must be greater than J"),
        ("G76 P1.5 Z-20 I0 J0.1 K1", "I must not be 0"),
        ("G1 X1 G32 Z-5", "G32: threading"),
        ("M98 P10", "not understood"),
        ("G0 G1 X1", "same modal group"),
        ("G1 X1 X2", "appears twice"),
        ("G1 X1 D1", "only understood with G41"),
        ("G41 L2 G1 X1", "only understood with G41.1"),
        ("G41.1 G1 X5", "needs a D word"),
        ("G41.1 D1 L12 G1 X5", "orientation 0-9"),
        ("G2 X1 Z1", "needs R or I/K"),
        ("G2 X1 Z1 R5 I1", "not both"),
        ("G2 X1 Z1 I9 K9", "differs from radius"),
        ("G2 X10 Z0 R1", "too small to reach"),
        ("G1 I1", "without an arc end point"),
        ("G1 X1 O5", "first word"),
        ("Q1", "only understood with G64"),
    ],
)
def test_reader_refuses_what_it_does_not_understand(block, message):
    text = f"G18 G21 G8 F100\nG0 X0 Z0\n{block}\nM30\n"
    with pytest.raises(InputError) as exc:
        parse_gcode(text, name="p.ngc")
    assert exc.value.line == 3, str(exc.value)
    assert message in str(exc.value)
    assert block in str(exc.value)


def test_axis_words_need_a_motion_mode_and_arcs_after_g40_must_wait():
    with pytest.raises(InputError, match="no motion mode"):
        parse_gcode("G18\nX1 Z1\n", name="p")
    text = "G18 G8 F1\nG0 X5 Z5\nG41.1 D1 G1 X3 Z1\nG1 Z0\nG40\nG2 X4 Z-1 R1\n"
    with pytest.raises(InputError, match="must be straight") as exc:
        parse_gcode(text, name="p")
    assert exc.value.line == 6


def test_modal_state_units_diameter_incremental():
    text = "\n".join(
        [
            "G18 G21 G7 G90",
            "G0 X20 Z5",  # diameter 20 -> radius 10
            "G8 G1 X12 Z0",  # radius mode
            "G20 G91 G1 X0.1 Z-1",  # inch, incremental radius
            "G7 X0.2",  # incremental diameter: radius + 0.1 in
            "G90 G21 G1 Z-30",
        ]
    )
    p = parse_gcode(text, name="m")
    ends = [m.end for m in p.moves]
    assert ends[0] == (10.0, 5.0)
    assert ends[1] == (12.0, 0.0)
    assert ends[2] == pytest.approx((12.0 + 2.54, -25.4))
    assert ends[3] == pytest.approx((12.0 + 2.54 + 2.54, -25.4))
    assert ends[4] == pytest.approx((12.0 + 5.08, -30.0))
    st = p.state(4)
    assert (st.units, st.diameter, st.absolute, st.motion) == ("in", False, False, "G1")


def test_arc_centres_i_is_a_radius_in_both_modes_and_both_ijk_modes():
    for header, words in [
        ("G7 G91.1", "I5 K0"),
        ("G8 G91.1", "I5 K0"),
        ("G7 G90.1", "I15 K0"),
        ("G8 G90.1", "I15 K0"),
    ]:
        x0, x1 = ("X20", "X30") if "G7" in header else ("X10", "X15")
        text = f"G18 G21 {header} F1\nG0 {x0} Z0\nG3 {x1} Z-5 {words}\n"
        arc = parse_gcode(text, name="a").moves[1]
        assert arc.center == pytest.approx((15.0, 0.0)), header


def test_g2_g3_in_the_drawing_frame():
    """G2 is clockwise and G3 counter-clockwise with z to the right and x up
    (checked against rs274's ARC_FEED rotation): a G2 from the diameter into a
    shoulder is the concave fillet of an OD profile cut toward the chuck."""
    text = "G18 G21 G8 F1\nG0 X10 Z-10\nG2 X11 Z-11 R1\nG3 X12 Z-12 R1\n"
    cw, ccw = parse_gcode(text, name="a").moves[1:]
    assert cw.center == pytest.approx((11.0, -10.0))
    assert ccw.center == pytest.approx((11.0, -12.0))
    f_cw, f_ccw = cw.to_feature("a"), ccw.to_feature("b")
    assert isinstance(f_cw, Arc) and not f_cw.ccw and f_ccw.ccw
    assert f_cw.sweep == pytest.approx(-math.pi / 2) and f_ccw.sweep == pytest.approx(math.pi / 2)


def test_r_arcs_small_and_large():
    text = "G18 G21 G8 F1\nG0 X0 Z0\nG2 X0 Z-10 R10\nG2 X0 Z-20 R-10\n"
    small, large = parse_gcode(text, name="r").moves[1:]
    # chord along -z (right to left): clockwise passes below, so the arc under
    # 180 deg has its centre above (+x); R < 0 asks for the one over 180 deg
    assert small.center == pytest.approx((math.sqrt(75), -5.0))
    assert large.center == pytest.approx((-math.sqrt(75), -15.0))


def test_to_feature_makes_exact_arcs_from_rounded_centres():
    text = "G18 G21 G8 F1\nG0 X10 Z0\nG3 X10.707 Z-0.293 I-0.001 K-1.0\n"
    arc = parse_gcode(text, name="f").moves[1]
    feat = arc.to_feature("fillet")
    assert math.dist(feat.p0, feat.center) == pytest.approx(math.dist(feat.p1, feat.center))
    assert math.dist(feat.center, arc.center) < 1e-3
    line = parse_gcode("G18 G8 F1\nG1 X1 Z2\n", name="l").moves[0].to_feature("d", side=1)
    assert isinstance(line, Line) and line.p1 == (1.0, 2.0) and line.side == 1


def test_compensation_settings_and_tools():
    text = (
        "G18 G21 G8 F1\nT3 M6\nG0 X20 Z5\nG42 G1 X10 Z1\nG1 Z-5\nG40 G0 X20 Z5\n"
        "G41.1 D0.8 L6 G1 X10 Z1\nG1 Z-2\nG40\nG41 D7 G1 X12 Z1\nG40 G1 X20\n"
    )
    p = parse_gcode(text, name="c")
    comps = [m.comp for m in p.moves]
    assert comps[0] is None
    assert (comps[1].code, comps[1].side, comps[1].tool, comps[1].line) == ("G42", "right", 3, 4)
    assert p.moves[1].entry and not p.moves[2].entry
    assert comps[4].diameter_mm == 0.8 and comps[4].orientation == 6 and comps[4].side == "left"
    assert comps[6].tool == 7
    assert comps[-1] is None
    with pytest.raises(InputError, match="already on"):
        parse_gcode("G18 F1\nG41.1 D1\nG42.1 D1\n", name="c")
    with pytest.raises(InputError, match="cannot change tools"):
        parse_gcode("G18 F1\nG41.1 D1\nT2 M6\n", name="c")


def test_o_numbers_percent_lines_and_comments_are_kept():
    text = "%\nO1001 (PART)\nN10 G18 G21 G7 G90 G40 ; header\nN20 T0202\nN30 G0 X10 Z2\n%\n"
    p = parse_gcode(text, name="o")
    assert p.text == text
    assert len(p.moves) == 1 and p.moves[0].end == (5.0, 2.0)


def test_read_gcode_path_and_errors(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        read_gcode(tmp_path / "missing.ngc")
    prog = read_gcode(DATA / "17_crlf_lower_n_comments.ngc")
    assert prog.name.endswith("17_crlf_lower_n_comments.ngc")
    assert "13 moves, 11 compensated" in repr(prog)


def test_format_number_keeps_the_format():
    w = lex_gcode("X20.000 Z-.250 X+1.5 K0 R2.\n").lines[0].words
    assert format_number(20.0041, w[0]) == "20.004"
    assert format_number(-0.2496, w[1]) == "-.250"
    assert format_number(1.44, w[2]) == "+1.4"
    assert format_number(0.0004, w[3], decimals=3) == "0.000" or format_number(0.0004, w[3]) == "0"
    assert format_number(0.5, w[3], decimals=3) == "0.500"
    assert format_number(3.0, w[4]) == "3."
    assert format_number(-0.00001, w[0]) == "0.000"


def test_edit_line_changes_only_the_words_asked():
    line = lex_gcode("N60 G1 X24.000 Z0.000 (face) F0.08\n").lines[0]
    assert edit_line(line, values={2: "23.992"}) == "N60 G1 X23.992 Z0.000 (face) F0.08"
    assert edit_line(line, remove={1}) == "N60 X24.000 Z0.000 (face) F0.08"
    assert edit_line(line, remove={0}) == "G1 X24.000 Z0.000 (face) F0.08"
    assert edit_line(line, remove={4}) == "N60 G1 X24.000 Z0.000 (face)"
    assert edit_line(line, insert={3: ["I1.0"]}) == "N60 G1 X24.000 Z0.000 I1.0 (face) F0.08"
    assert edit_line(line, insert={-1: ["G90"]}) == "G90 N60 G1 X24.000 Z0.000 (face) F0.08"
    packed = lex_gcode("G1X1Z2F3").lines[0]
    assert edit_line(packed, remove={1}, insert={0: ["X5"]}) == "G1X5Z2F3"
    indented = lex_gcode("  G41 G1 X1").lines[0]
    assert edit_line(indented, remove={0}) == "  G1 X1"


def test_tool_table(tmp_path):
    text = "T1 P1 D0.8 Z+0.1 I95 J155 Q3 ; finish\n\n; comment only\nT2 P2 D0.031 Q9\n"
    tools = parse_tool_table(text, units="mm")
    assert tools[1].radius_mm == 0.4 and tools[1].orientation == 3 and tools[1].comment == "finish"
    assert tools[1].offsets_mm["Z"] == 0.1
    inch = parse_tool_table(text, units="in")
    assert inch[2].diameter_mm == pytest.approx(0.7874)
    for bad, msg in [("T1 D1 Q10", "0-9"), ("P1 D1", "tool number"), ("T1 D1 ZZ", "cannot read")]:
        with pytest.raises(InputError, match=msg):
            parse_tool_table(bad, name="t.tbl")
    with pytest.raises(InputError, match="listed twice"):
        parse_tool_table("T1 D1\nT1 D2\n")
    path = tmp_path / "t.tbl"
    path.write_text(text)
    assert read_tool_table(path)[2].orientation == 9


def test_parse_canon_units_and_arcs():
    text = (
        "    1 N..... USE_LENGTH_UNITS(CANON_UNITS_INCHES)\n"
        "    2 N..... STRAIGHT_FEED(1.0000, 0.0000, -2.0000, 0.0000, 0.0000, 0.0000)\n"
        "    3 N..... ARC_FEED(-3.0000, 1.5000, -2.0000, 1.5000, -1, 0.0000, 0.0000, 0.0000)\n"
        "Some error\n"
    )
    moves, other = parse_canon(text)
    assert moves[0].end == pytest.approx((25.4, -50.8))
    assert moves[1].end == pytest.approx((38.1, -76.2)) and moves[1].rotation == -1
    assert moves[1].center == pytest.approx((38.1, -50.8))
    assert other == ["Some error"]

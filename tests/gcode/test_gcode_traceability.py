"""The tool that cuts the finish pass (its T word) and the adjusted program's comment
block and diff labels (issue 15)."""

from __future__ import annotations

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import (
    ToolWord,
    adjust_program,
    comment_text,
    diff_labels,
    finish_cut_tools,
    lex_gcode,
    parse_gcode,
    tool_call,
)
from piecs_bayes.geometry import Arc, Line, Profile


def _shaft(v, c):
    """The demo shaft (radius mm) from its 8 vertices and the fillet's centre."""
    return Profile(
        (
            Line("face_end", v[0], v[1], -1),
            Line("dia_24", v[1], v[2], -1),
            Line("taper", v[2], v[3], -1),
            Line("dia_30", v[3], v[4], -1),
            Arc("fillet", v[4], v[5], c, False, -1),
            Line("shoulder", v[5], v[6], -1),
            Line("dia_44", v[6], v[7], -1),
        )
    )


NOMINAL = _shaft(
    [(4, 0), (12, 0), (12, -30), (15, -45), (15, -57), (18, -60), (22, -60), (22, -90)],
    (18, -57),
)
D = 0.004  # every surface 4 um out of the material
ADJUSTED = _shaft(
    [
        (4, D),
        (12 + D, D),
        (12 + D, -30),
        (15 + D, -45),
        (15 + D, -57),
        (18, -60 + D),
        (22 + D, -60 + D),
        (22 + D, -90),
    ],
    (18, -57),
)
FINISH = """\
N50 G42 G1 X8.000 Z0.000 F0.08
N60 G1 X24.000 Z0.000
N70 G1 X24.000 Z-30.000
N80 G1 X30.000 Z-45.000
N90 G1 X30.000 Z-57.000
N100 G2 X36.000 Z-60.000 I3.000 K0.000
N110 G1 X44.000 Z-60.000
N120 G1 X44.000 Z-90.000
N130 G1 X48.000
N140 G40 G0 X60.000
"""
FANUC = (
    "%\nO1001 (DEMO SHAFT FINISH CUT)\nN10 G18 G7 G21 G90 G40\nN20 T0202 (FINISH TOOL R0.4)\n"
    "N30 G96 S180 M3\nN40 G0 X10.000 Z2.000\n" + FINISH + "N150 G0 Z50.000\nN160 M30\n%\n"
)


def _word(text, by="T", line=4):
    return ToolWord(text, int(text[1:]), line, by)


@pytest.mark.parametrize(
    "word, by, tool, offset",
    [
        ("T0202", "T", 2, 2),  # Fanuc Tttoo: tool 02, wear offset 02
        ("T202", "T", 2, 2),  # leading zero left out
        ("T0211", "T", 2, 11),  # another wear offset of tool 2
        ("T1212", "T", 12, 12),
        ("T2", "T", 2, 2),  # one or two digits: the tool with its own offset
        ("T12", "T", 12, 12),
        ("T0200", "T", 2, 0),  # offsets cancelled
        ("T2", "M6", 2, 2),  # LinuxCNC T2 M6: tool 2, its tool-table entry
        ("T0202", "M6", 202, 202),  # LinuxCNC reads the number as written
        ("T030201", "T", 2, 1),  # Okuma OSP: nose-radius number 03, tool 02, offset 01
    ],
)
def test_what_a_t_word_calls(word, by, tool, offset):
    call = tool_call(_word(word, by))
    assert (call.tool, call.offset, call.word, call.line) == (tool, offset, word, 4)
    assert call.style == ("turret" if by == "T" else "M6")


def test_a_t_word_of_five_or_more_than_six_digits_is_refused():
    with pytest.raises(
        InputError, match=r"p.ngc:4: T10202: a T word of five or more than six digits"
    ):
        tool_call(_word("T10202"), file="p.ngc")
    with pytest.raises(InputError, match=r"T1020304: a T word of five or more than six"):
        tool_call(_word("T1020304"), file="p.ngc")


def test_the_reader_tracks_the_cutting_tool_turret_and_m6_style():
    prog = parse_gcode(FANUC, name="demo.ngc")
    assert prog.state(3).tool is None
    assert prog.state(4).tool == ToolWord("T0202", 202, 4, "T")  # T alone changes tools
    assert prog.state(12).tool == prog.state(4).tool
    # with M6 anywhere in the program, a T word only selects: M6 loads
    m6 = parse_gcode("G18 G7 G21\nT3 M6\nG0 X10 Z2\nT5\nG1 X20 Z0\nM6\nG0 X30\n")
    assert [m6.state(k).tool and m6.state(k).tool.text for k in range(1, 8)] == [
        None,
        "T3",
        "T3",
        "T3",  # T5 prepares the next tool, T3 still cuts
        "T3",
        "T5",
        "T5",
    ]
    assert m6.state(2).tool.by == "M6"
    lower = parse_gcode("g18 g7 g21\nt0303\ng0 x10 z2\n")
    assert lower.state(3).tool == ToolWord("T0303", 303, 2, "T")


def test_finish_cut_tools_of_the_demo_program():
    found = finish_cut_tools(parse_gcode(FANUC, name="demo.ngc"), NOMINAL)
    assert found.mapped and not found.untooled and not found.why
    (call,) = found.calls
    assert (call.tool, call.offset, call.word, call.line) == (2, 2, "T0202", 4)
    assert call.blocks == tuple(range(8, 15))  # N60..N120, mapped to the 7 features
    assert "T0202 line 4: tool 2, offset 2" in repr(call)


def test_finish_cut_tools_with_two_tools_and_an_unmapped_program():
    # the face cut with T0101, the rest with T0303: two calls, in program order
    text = FANUC.replace("N60 G1 X24.000 Z0.000\n", "N60 G1 X24.000 Z0.000\nN65 T0303\n")
    found = finish_cut_tools(parse_gcode(text, name="two.ngc"), NOMINAL)
    assert [(c.word, c.tool, c.offset) for c in found.calls] == [
        ("T0202", 2, 2),
        ("T0303", 3, 3),
    ]
    assert found.calls[0].blocks == (8,) and found.calls[1].blocks[0] == 10
    # a program that does not map to the profile: its compensated moves stand in
    shifted = FANUC.replace("X24.000", "X25.000")
    found = finish_cut_tools(parse_gcode(shifted, name="off.ngc"), NOMINAL)
    assert not found.mapped and "lies on no profile feature" in found.why
    assert [c.word for c in found.calls] == ["T0202"] and found.calls[0].blocks[0] == 7
    # finish blocks cut before any T word
    bare = FANUC.replace("N20 T0202 (FINISH TOOL R0.4)\n", "N20 (NO TOOL)\n")
    found = finish_cut_tools(parse_gcode(bare, name="bare.ngc"), NOMINAL)
    assert not found.calls and found.untooled == tuple(range(8, 15))


HEADER = ("piecs_bayes 0.1.0 adjusted finish cut", "study study.toml sha256 " + "ab" * 32)


def test_comment_block_after_percent_and_o_number_only_comments_added():
    prog = parse_gcode(FANUC, name="data/demo/finish.ngc")
    res = adjust_program(prog, NOMINAL, ADJUSTED, max_correction_mm=0.05, header=HEADER)
    old, new = FANUC.splitlines(keepends=True), res.text.splitlines(keepends=True)
    assert new[:2] == old[:2]  # "%" and the O-number line stay first
    assert new[2:4] == [f"({HEADER[0]})\n", f"({HEADER[1]})\n"]
    assert res.header_lines == 2 and len(new) == len(old) + 2
    body = new[:2] + new[4:]
    changed = {c.line for c in res.changes}
    for k, (a, b) in enumerate(zip(old, body, strict=True), start=1):
        assert (a == b) == (k not in changed), (k, a, b)  # every other line byte-identical
    # the new program moves as the old one, apart from the changed coordinates
    again = parse_gcode(res.text)
    before = prog.moves
    assert [m.line - 2 for m in again.moves] == [m.line for m in before]
    assert [m.kind for m in again.moves] == [m.kind for m in before]
    for a, b in zip(before, again.moves, strict=True):
        if a.line not in changed:
            assert a.end == b.end
    # the diff names the input and the output
    lines = res.diff.splitlines()
    assert lines[:2] == ["--- a/data/demo/finish.ngc", "+++ b/finish_adjusted.ngc"]
    assert f"+({HEADER[0]})" in lines
    out = adjust_program(
        prog, NOMINAL, ADJUSTED, max_correction_mm=0.05, output_name="/tmp/out/new.ngc"
    )
    assert out.diff.splitlines()[1] == "+++ b/tmp/out/new.ngc" and out.header_lines == 0


def test_comment_block_in_the_programs_own_syntax_and_line_endings():
    # no "%" nor O number: the block goes first; ";" comments only: ";" comments
    text = "G18 G7 G21 G90 G40 ; setup\r\nT0202\r\nG0 X10.000 Z2.000\r\n" + FINISH.replace(
        "\n", "\r\n"
    )
    res = adjust_program(
        parse_gcode(text), NOMINAL, ADJUSTED, max_correction_mm=0.05, header=HEADER
    )
    assert res.text.startswith(f"; {HEADER[0]}\r\n; {HEADER[1]}\r\nG18 G7 G21 G90 G40 ; setup\r\n")
    # an unchanged program still gets its block; nothing else changes
    same = adjust_program(
        parse_gcode(FANUC), NOMINAL, NOMINAL, max_correction_mm=0.05, header=HEADER
    )
    assert not same.changes and same.text.replace(f"({HEADER[0]})\n({HEADER[1]})\n", "") == FANUC


def test_comment_texts_are_made_safe_for_controllers():
    assert comment_text("study (copy).toml 100% µm") == "study [copy].toml 100? ?m"
    assert comment_text("a (b)", "semicolon") == "a (b)"
    assert comment_text("MSG, hello") == "- MSG, hello"  # not a LinuxCNC active comment
    assert comment_text("debug, x") == "- debug, x"
    assert comment_text("probe probe.csv") == "probe probe.csv"
    text = lex_gcode(f"({comment_text('x (y) ; z')})\n").lines[0]
    assert [c.text for c in text.comments] == ["x [y] ; z"] and not text.words


def test_diff_labels():
    assert diff_labels("data/demo/finish.ngc") == (
        "a/data/demo/finish.ngc",
        "b/finish_adjusted.ngc",
    )
    assert diff_labels("/abs/p.nc", "/o/q.nc") == ("a/abs/p.nc", "b/o/q.nc")
    assert diff_labels(None) == ("a/program.ngc", "b/program_adjusted.ngc")

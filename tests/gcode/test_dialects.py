"""What the reader of issue 38 must give on the Fanuc, Haas and Okuma programs.

One case per program of tests/data/gcode/dialects (its README says what each exercises):
the dialect `read_gcode` detects and its reason, the finish contour (`finish_contour`) in mm
radius with the program lines its features, lead-in and exit come from, the tool that cuts
it, and the refusals with their line and word. The expected values are computed by hand from
the programs (the README gives the demo shaft's seven features; the G70 passes are also
checked against rs274 on the program rewritten by tests/gcode/fanuc_rewrite.py).

The canned cycles (G70-G73 with P/Q) are run by the reader: a G70's finish pass is the
contour, a G71 that no G70 follows gives its own. The reader's API is used in one place
each: `_read` (`read_gcode(path, dialect=...)`) and `_dialect` (`.dialect.name/.reason`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest
from fanuc_rewrite import cycle_parts, rewrite_fanuc

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import (
    detect_dialect,
    finish_contour,
    parse_gcode,
    read_gcode,
    rs274_path,
    run_rs274,
    tool_call,
)
from piecs_bayes.gcode._lexer import lex_gcode, read_text_lossless
from piecs_bayes.gcode._rs274 import parse_canon

DIALECTS = Path(__file__).resolve().parents[1] / "data" / "gcode" / "dialects"
TOL = 1e-9

# ----------------------------------------------------------------------- the contours (by hand)
#: the demo shaft (data/demo/finish.ngc, data/demo/study.toml halved): radius mm
DEMO = [
    ("line", (4.0, 0.0), (12.0, 0.0)),
    ("line", (12.0, 0.0), (12.0, -30.0)),
    ("line", (12.0, -30.0), (15.0, -45.0)),
    ("line", (15.0, -45.0), (15.0, -57.0)),
    ("arc", (15.0, -57.0), (18.0, -60.0), (18.0, -57.0), False),
    ("line", (18.0, -60.0), (22.0, -60.0)),
    ("line", (22.0, -60.0), (22.0, -90.0)),
]
#: ,C1. at X24. Z0. cuts the face short at X22. and adds the chamfer to (X24., Z-1.)
CHAMFERED = [
    ("line", (4.0, 0.0), (11.0, 0.0)),
    ("line", (11.0, 0.0), (12.0, -1.0)),
    ("line", (12.0, -1.0), (12.0, -30.0)),
    *DEMO[2:],
]
#: okuma_shaft.min: the face to X22., G03 X24. Z-1. K-1. (centre X22. Z-1.), then the demo
ROUNDED = [
    ("line", (4.0, 0.0), (11.0, 0.0)),
    ("arc", (11.0, 0.0), (12.0, -1.0), (11.0, -1.0), True),
    ("line", (12.0, -1.0), (12.0, -30.0)),
    *DEMO[2:],
]
#: the inch shaft: X in inches x 12.7 = radius mm, Z x 25.4
INCH = [
    ("line", (3.175, 0.0), (9.525, 0.0)),
    ("line", (9.525, 0.0), (9.525, -25.4)),
    ("line", (9.525, -25.4), (12.7, -38.1)),
    ("line", (12.7, -38.1), (12.7, -50.8)),
    ("arc", (12.7, -50.8), (15.875, -53.975), (15.875, -50.8), False),
    ("line", (15.875, -53.975), (19.05, -53.975)),
    ("line", (19.05, -53.975), (19.05, -76.2)),
]
#: fanuc_g72_facing.nc: chamfer at the flange OD, face, R2 fillet (G03), boss, chamfer, face
FACING = [
    ("line", (42.0, -12.0), (40.0, -10.0)),
    ("line", (40.0, -10.0), (17.0, -10.0)),
    ("arc", (17.0, -10.0), (15.0, -8.0), (17.0, -8.0), True),
    ("line", (15.0, -8.0), (15.0, -1.0)),
    ("line", (15.0, -1.0), (14.0, 0.0)),
    ("line", (14.0, 0.0), (0.0, 0.0)),
]


@dataclass(frozen=True)
class Case:
    """One program: its dialect, what the reason may name, its contour, the N labels (or
    (label, nth)) of the lead-in, the features and the exit, and the finish tool: the T word
    in force on the block `tool_at`, as (word, tool, offset)."""

    file: str
    dialect: str
    construct: str
    clues: tuple[str, ...]
    features: list
    lead_in: object
    labels: tuple
    exit: object
    tool_at: object
    tool: tuple[str, int, int]
    units: str = "mm"


def _n(first: int, step: int, count: int) -> tuple[str, ...]:
    return tuple(f"N{first + step * k}" for k in range(count))


FANUC_CLUES = (
    "G99",
    "G98",
    "U/W",
    "G28",
    "G50",
    "G71",
    "G72",
    "G73",
    "G70",
    "P/Q",
    "T0",
    "M98",
    "#",
)
HAAS_CLUES = ("G80", "safe-start", "safe start")
BODY = ("N50", _n(60, 10, 7), "N130", "N60", ("T0202", 2, 2))  # the demo body of the plain programs
CYCLE = ("N10", _n(11, 1, 7), "N18")

CASES = [
    Case("haas_demo_shaft.nc", "haas", "a Haas G71 one-block cycle and its G70 finish pass", HAAS_CLUES, DEMO, *CYCLE, "N26", ("T202", 2, 2)),
    Case("haas_safe_start_inch.nc", "haas", "the Haas safe-start line G00 G18 G20 G40 G80 G99", HAAS_CLUES, INCH, "N8", _n(9, 1, 7), "N16", "N9", ("T101", 1, 1), "in"),
    Case("haas_g71_one_block_inch.nc", "haas", "G71 P Q U W D F (one block, inch) and G70 F", HAAS_CLUES, INCH, *CYCLE, "N21", ("T101", 1, 1), "in"),
    Case("haas_m31_chip_conveyor.nc", "haas", "Haas M31/M33", HAAS_CLUES, DEMO, "N7", _n(8, 1, 7), "N15", "N8", ("T202", 2, 2)),
    Case("fanuc_g71_two_block.nc", "fanuc", "the two-block G71 and G70", FANUC_CLUES, DEMO, *CYCLE, "N30", ("T0101", 1, 1)),
    Case("fanuc_g70_finish_tool.nc", "fanuc", "G70 with another tool than the G71", FANUC_CLUES, DEMO, *CYCLE, "N70", ("T0212", 2, 12)),
    Case("fanuc_g71_without_g70.nc", "fanuc", "a G71 without G70 (its contour is the finish contour)", FANUC_CLUES, DEMO, *CYCLE, "N7", ("T0101", 1, 1)),
    Case("fanuc_g72_facing.nc", "fanuc", "the G72 facing cycle", FANUC_CLUES, FACING, "N11", _n(12, 1, 6), "N18", "N30", ("T0303", 3, 3)),
    Case("fanuc_g73_pattern_repeat.nc", "fanuc", "the G73 pattern repeat", FANUC_CLUES, DEMO, *CYCLE, "N30", ("T0101", 1, 1)),
    Case("fanuc_chamfer_corner_words.nc", "fanuc", ",C and ,R corner words", FANUC_CLUES, CHAMFERED, "N10", ("N11", "N11", "N12", "N13", "N14", "N14", "N15", "N16"), "N17", "N30", ("T0101", 1, 1)),
    Case("fanuc_g28_reference_return.nc", "fanuc", "G28 U0 W0", FANUC_CLUES, DEMO, "N60", _n(70, 10, 7), "N140", "N70", ("T0202", 2, 2)),
    Case("fanuc_g50_spindle_clamp.nc", "fanuc", "G50 S (spindle clamp)", FANUC_CLUES, DEMO, "N60", _n(70, 10, 7), "N140", "N70", ("T0202", 2, 2)),
    Case("fanuc_g50_coordinate_setting.nc", "fanuc", "G50 X Z (coordinate setting)", FANUC_CLUES, DEMO, "N60", _n(70, 10, 7), "N140", "N70", ("T0202", 2, 2)),
    Case("fanuc_g96_g97.nc", "fanuc", "G96/G97 with G50 S", FANUC_CLUES, DEMO, "N70", _n(80, 10, 7), "N150", "N80", ("T0202", 2, 2)),
    Case("fanuc_g98_g99_feed.nc", "fanuc", "G98/G99 as Fanuc's feed modes", FANUC_CLUES, DEMO, "N60", _n(70, 10, 7), "N140", "N70", ("T0202", 2, 2)),
    Case("fanuc_incremental_uw.nc", "fanuc", "incremental U/W in a diameter program", FANUC_CLUES, DEMO, "N50", _n(60, 10, 7), "N130", "N60", ("T0202", 2, 2)),
    Case("fanuc_t_word_offset.nc", "fanuc", "T0101 with its offset (T0100, T0212)", FANUC_CLUES, DEMO, "N110", _n(120, 10, 7), "N190", "N120", ("T0212", 2, 12)),
    Case("fanuc_g53_machine_moves.nc", "fanuc", "G53 moves", FANUC_CLUES, DEMO, "N70", _n(80, 10, 7), "N150", "N80", ("T0202", 2, 2)),
    Case("fanuc_percent_lines.nc", "fanuc", "% lines", FANUC_CLUES, DEMO, *BODY),
    Case("fanuc_blank_line_before_percent.nc", "fanuc", "blank lines before %", FANUC_CLUES, DEMO, *BODY),
    Case("fanuc_m30_percent_one_line.nc", "fanuc", "M30 and % on one line", FANUC_CLUES, DEMO, *BODY),
    Case("fanuc_program_number_o.nc", "fanuc", "O1234 program numbers", FANUC_CLUES, DEMO, *BODY),
    Case("fanuc_program_number_colon.nc", "fanuc", ":0100 program numbers", FANUC_CLUES, DEMO, *BODY),
    Case("fanuc_crlf.nc", "fanuc", "CRLF Fanuc programs", FANUC_CLUES, DEMO, *BODY),
    Case("fanuc_duplicate_n.nc", "fanuc", "duplicate N labels", FANUC_CLUES, DEMO, ("N50", 2), (("N60", 2), *_n(70, 10, 6)), "N130", ("N60", 2), ("T0202", 2, 2)),
    Case("fanuc_macro_b.nc", "fanuc", "Fanuc macro B (#, IF GOTO, WHILE DO END)", FANUC_CLUES, DEMO, "N9", _n(10, 1, 7), "N17", "N10", ("T0202", 2, 2)),
    Case("fanuc_m98_m99_subprogram.nc", "fanuc", "M98/M99 subprograms", FANUC_CLUES, DEMO, "N10", _n(20, 10, 7), "N90", "N20", ("T0202", 2, 2)),
    Case("demo_shaft_fanuc.nc", "fanuc", "the demo shaft as a Fanuc 0i program", FANUC_CLUES, DEMO, "N60", _n(70, 10, 7), "N140", "N70", ("T0202", 2, 2)),
    Case("okuma_shaft.min", "okuma", "Okuma $NAME.MIN% headers and I-only/K-only arcs", ("$SHAFT.MIN%", "header"), ROUNDED, "N5", _n(6, 1, 8), "N14", "N6", ("T020202", 2, 2)),
]  # fmt: skip

#: programs that must be refused: (file, dialect, construct, N labels the message may name
#: the line of, the words it must name)
REFUSED = [
    ("fanuc_duplicate_n_in_cycle.nc", "fanuc", "duplicate N labels in a cycle's P/Q", (("N6", 1), ("N10", 2)), ("N10",)),
    ("okuma_lap_g85.min", "okuma", "Okuma LAP cycles (to refuse them by name)", (("N5", 1),), ("G85", "LAP")),
]  # fmt: skip


def _params(cases):
    return [pytest.param(c, id=c.file) for c in cases]


# ----------------------------------------------------------------------- the reader's API, guessed
def _read(path: Path, dialect: str | None):
    return read_gcode(path) if dialect is None else read_gcode(path, dialect=dialect)


def _dialect(program) -> tuple[str, str]:
    return program.dialect.name, program.dialect.reason


# ----------------------------------------------------------------------- helpers
def _line(path: Path, label) -> int:
    """The 1-based line of the `nth` block whose first word is `label` ("N60" or ("N60", 2))."""
    label, nth = (label, 1) if isinstance(label, str) else label
    seen = 0
    for k, raw in enumerate(path.read_bytes().split(b"\n"), 1):
        words = raw.decode("ascii").split()
        if words and words[0].upper() == label:
            seen += 1
            if seen == nth:
                return k
    raise AssertionError(f"{path.name}: no block {label} (#{nth})")


def _close(a, b) -> bool:
    return all(abs(u - v) <= TOL for u, v in zip(a, b, strict=True))


def _assert_features(contour, expected):
    got = contour.segments
    assert len(got) == len(expected), [(s.kind, s.start, s.end) for s in got]
    for s, e in zip(got, expected, strict=True):
        assert s.kind == e[0] and _close(s.start, e[1]) and _close(s.end, e[2]), (s, e)
        if s.kind == "arc":
            assert _close(s.center, e[3]) and s.ccw == e[4], (s, e)


# ----------------------------------------------------------------------- the corpus itself
def test_every_program_has_its_case_and_its_readme_line():
    files = sorted(p.name for p in DIALECTS.iterdir() if p.suffix in (".nc", ".min"))
    assert files == sorted([c.file for c in CASES] + [r[0] for r in REFUSED])
    readme = (DIALECTS / "README.md").read_text()
    assert [f for f in files if f"`{f}`" not in readme] == []
    assert len(files) >= 30


def test_demo_contour_is_finish_ngcs():
    """DEMO, the contour most programs here carry, is data/demo/finish.ngc's as read today."""
    demo = Path(__file__).resolve().parents[2] / "data" / "demo" / "finish.ngc"
    _assert_features(finish_contour(read_gcode(demo)), DEMO)


def test_crlf_program_is_crlf_throughout():
    data = (DIALECTS / "fanuc_crlf.nc").read_bytes()
    assert data.count(b"\r\n") == data.count(b"\n") == 19 and b"\r\r" not in data


def test_the_labels_of_every_case_are_in_its_program():
    for c in CASES:
        path = DIALECTS / c.file
        lines = [_line(path, x) for x in (c.lead_in, *c.labels, c.exit, c.tool_at)]
        assert lines[0] < lines[1] <= lines[-3] < lines[-2], (c.file, lines)
        text = path.read_text()
        assert c.tool[0] in text and len(c.labels) == len(c.features), c.file


G70_PROGRAMS = [c for c in CASES if c.file in (
    "haas_demo_shaft.nc", "haas_g71_one_block_inch.nc", "fanuc_g71_two_block.nc",
    "fanuc_g70_finish_tool.nc", "fanuc_g72_facing.nc", "fanuc_g73_pattern_repeat.nc",
    "fanuc_chamfer_corner_words.nc",
)]  # fmt: skip


@pytest.fixture
def _own_home(tmp_path, monkeypatch):
    """rs274 keeps its tool table in $HOME/.tool.mmap: a HOME of its own per test."""
    monkeypatch.setenv("HOME", str(tmp_path))


def _rs274_g70(case):
    """rs274's G70 pass on the rewritten program: the chain of points from the profile's
    start and the kinds of its moves ("line" / "arc")."""
    rewrite = rewrite_fanuc((DIALECTS / case.file).read_text(), units=case.units)
    result = run_rs274(rewrite.text, tool_table="T1 P1 D0 ;\nT2 P2 D0 ;\nT3 P3 D0 ;\n")
    assert result.error is None, result.error
    moves = parse_canon("\n".join(cycle_parts(result.output)["FINISH G70 P10 Q20"]))[0]
    cut = [m for m in moves if m.kind != "rapid"]
    chain = [moves[moves.index(cut[0]) - 1].end] + [m.end for m in cut]
    return chain, ["arc" if m.kind == "arc" else "line" for m in cut]


def _assert_chain(chain, kinds, ours, our_kinds, units):
    """`ours` (a contour's points) is a run of rs274's `chain`, move kinds alike."""
    tol = (25.4e-4 if units == "in" else 1e-4) + 1e-9

    def near(a, b):
        return all(abs(u - v) <= tol for u, v in zip(a, b, strict=True))

    k = next(i for i, p in enumerate(chain) if near(p, ours[0]))  # after the lead-in
    assert all(near(a, b) for a, b in zip(chain[k : k + len(ours)], ours, strict=True))
    assert kinds[k : k + len(our_kinds)] == our_kinds


PLAIN = [c for c in CASES if c.file not in {g.file for g in G70_PROGRAMS} | {
    "fanuc_g71_without_g70.nc", "fanuc_macro_b.nc", "fanuc_m98_m99_subprogram.nc"}]  # fmt: skip


@pytest.mark.parametrize("case", PLAIN, ids=lambda c: c.file)
def test_hand_contour_is_todays_reading_of_the_program_in_linuxcnc_words(case):
    """The expected contours are not only hand-computed: today's reader, on the plain
    programs rewritten into LinuxCNC's words (the words it does not read dropped: G28, G53,
    G92, G96's D, G94/G95), finds the same features."""
    path = DIALECTS / case.file
    if case.dialect == "okuma":  # its header, G50 S and six-digit T word dropped
        lines = [ln for ln in path.read_text().splitlines()[1:] if "G50" not in ln]
        text = "G18 G7 G21\n" + "\n".join(ln.replace("T020202", "T2") for ln in lines)
    else:
        text = rewrite_fanuc(path.read_text(), units=case.units).text
    keep = []
    for line in text.splitlines():
        if re.search(r"G28|G92|G53|^G90$|^G1$", line):
            continue
        keep.append(re.sub(r"\bG9[45]\b|(?<=G96) D\d+", "", line))
    contour = finish_contour(parse_gcode("\n".join(keep) + "\n", name=case.file))
    _assert_features(contour, case.features)
    assert contour.units == case.units and contour.kind == "external"


@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("case", G70_PROGRAMS, ids=lambda c: c.file)
def test_hand_contour_is_rs274s_g70_pass(case, _own_home):
    """The expected contours of the G70 programs are the passes rs274 makes from them
    rewritten (to its 4 decimals)."""
    chain, kinds = _rs274_g70(case)
    ours = [case.features[0][1]] + [f[2] for f in case.features]
    _assert_chain(chain, kinds, ours, [f[0] for f in case.features], case.units)


# ----------------------------------------------------------------------- what the reader gives
@pytest.mark.parametrize("case", CASES, ids=lambda c: c.file)
def test_dialect_is_detected_with_its_reason(case):
    """Detection reads the words only (a cycle's program is detected before it is refused);
    the reader keeps the name apart from the reason and prints them "fanuc (reason)"."""
    path = DIALECTS / case.file
    detected = detect_dialect(lex_gcode(read_text_lossless(path), name=str(path)))
    name, reason = detected.name, detected.reason
    assert name == case.dialect, reason
    assert _dialect(_read(path, None)) == (name, reason)  # what read_gcode detects is that
    text = path.read_text()
    assert any(c in reason and c in text for c in case.clues), reason


@pytest.mark.parametrize("case", _params(CASES))
def test_finish_contour_in_mm_radius_from_its_lines(case):
    path = DIALECTS / case.file
    program = _read(path, case.dialect)
    contour = finish_contour(program)
    _assert_features(contour, case.features)
    assert [s.line for s in contour.segments] == [_line(path, x) for x in case.labels]
    assert contour.lead_in == _line(path, case.lead_in)
    assert contour.exit == _line(path, case.exit)
    assert contour.units == case.units and contour.kind == "external"
    assert program.source.to_bytes() == path.read_bytes()  # byte for byte, CRLF included


@pytest.mark.parametrize("case", _params(CASES))
def test_finish_tool_and_its_offset(case):
    path = DIALECTS / case.file
    program = _read(path, case.dialect)
    word = program.state(_line(path, case.tool_at)).tool
    call = tool_call(word, file=str(path))
    assert (word.text, call.tool, call.offset) == case.tool


@pytest.mark.parametrize("case", [pytest.param(r, id=r[0]) for r in REFUSED])
def test_refusal_names_the_line_and_the_word(case):
    file, dialect, _, labels, words = case
    path = DIALECTS / file
    with pytest.raises(InputError) as info:
        _read(path, dialect)
    exc = info.value
    assert exc.line in [_line(path, x) for x in labels], str(exc)
    assert all(w in str(exc) for w in words) and file in str(exc), str(exc)


# ----------------------------------------------------------------------- program by program
def test_g50_coordinate_setting_sets_where_the_tool_stands():
    program = _read(DIALECTS / "fanuc_g50_coordinate_setting.nc", "fanuc")
    first, last = program.moves[0], program.moves[-1]
    assert _close(first.start, (100.0, 150.0)) and _close(first.end, (5.0, 2.0))
    assert _close(last.end, (100.0, 150.0))  # N160 X200. Z150.


def test_g50_spindle_clamp_moves_nothing():
    program = _read(DIALECTS / "fanuc_g50_spindle_clamp.nc", "fanuc")
    assert _close(program.moves[0].start, (0.0, 0.0)) and _close(program.moves[0].end, (5.0, 2.0))
    assert not program.moves_at(_line(DIALECTS / "fanuc_g50_spindle_clamp.nc", "N30"))


@pytest.mark.parametrize(
    "file, labels",
    [
        pytest.param("fanuc_g28_reference_return.nc", ("N20", "N160", "N170"), id="G28"),
        pytest.param("fanuc_g53_machine_moves.nc", ("N20", "N30", "N170", "N180"), id="G53"),
    ],
)  # fmt: skip
def test_reference_and_machine_moves_are_rapids_off_the_contour(file, labels):
    path = DIALECTS / file
    program = _read(path, "fanuc")
    for label in labels:
        line = _line(path, label)
        moves = program.moves_at(line)
        assert all(m.kind == "rapid" and m.comp is None for m in moves), label
        # a move to or from a position the reader does not know (the machine's reference
        # and machine zero are not known here: ReadOptions.machine_zero) is a note on its
        # line naming the code, not a move
        code = "G28" if "g28" in file else "G53"
        assert moves or any(n.line == line and n.word == code for n in program.notes), label


def test_macro_b_loop_makes_three_rough_passes():
    path = DIALECTS / "fanuc_macro_b.nc"
    program = _read(path, "fanuc")
    body = _line(path, "G01")  # the WHILE body's cut: G01 Z-90. F0.25
    cuts = program.moves_at(body)
    assert [m.start[0] for m in cuts] == pytest.approx([24.2, 23.2, 22.2], abs=TOL)
    assert all(m.kind == "feed" and _close(m.end, (m.start[0], -90.0)) for m in cuts)


@pytest.mark.parametrize(
    "file, title",
    [
        pytest.param("fanuc_program_number_o.nc", "DEMO SHAFT FINISH - PROGRAM NUMBER O1234", id="O1234"),
        pytest.param("fanuc_program_number_colon.nc", "DEMO SHAFT FINISH - PROGRAM NUMBER WITH A COLON", id="colon"),
        pytest.param("okuma_shaft.min", "DEMO SHAFT WITH A ROUNDED FACE EDGE - OKUMA OSP", id="okuma"),
    ],
)  # fmt: skip
def test_program_title(file, title):
    path = DIALECTS / file
    dialect = "okuma" if file.endswith(".min") else "fanuc"
    assert finish_contour(_read(path, dialect)).title == title


# ----------------------------------------------------------------------- against rs274
@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("case", _params(G70_PROGRAMS))
def test_g70_contour_is_rs274s_pass_on_the_rewritten_program(case, _own_home):
    """Issue 38's acceptance for the finish pass: the contour we read from the Fanuc program
    is the pass rs274 makes from it rewritten into LinuxCNC's G70 (to its 4 decimals)."""
    chain, kinds = _rs274_g70(case)
    segments = finish_contour(_read(DIALECTS / case.file, case.dialect)).segments
    ours = [segments[0].start] + [s.end for s in segments]
    _assert_chain(chain, kinds, ours, [s.kind for s in segments], case.units)

"""The adjusted finish-cut program: block-to-feature mapping and the rewrite."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.gcode import (
    adjust_program,
    lex_gcode,
    map_blocks_to_profile,
    parse_gcode,
    read_gcode,
)
from piecs_bayes.geometry import Arc, Line, Profile
from piecs_bayes.io import write_text_atomic

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode" / "adjust"
DEMO = Path(__file__).resolve().parents[2] / "data" / "demo"


def _profile(v, fillet_c, round_c, ids=None):
    """The stepped shaft from its 9 vertices and two arc centres (radius mm); the
    material is right of travel (side -1: an external profile cut toward the chuck)."""
    return Profile(
        (
            Line("face_end", v[0], v[1], -1),
            Line("dia_24", v[1], v[2], -1),
            Line("taper", v[2], v[3], -1),
            Line("dia_30", v[3], v[4], -1),
            Arc("fillet", v[4], v[5], fillet_c, False, -1),
            Line("shoulder", v[5], v[6], -1),
            Arc("round", v[6], v[7], round_c, True, -1),
            Line("dia_44", v[7], v[8], -1),
        )
    )


NOMINAL = _profile(
    [(4, 0), (12, 0), (12, -30), (15, -45), (15, -57), (18, -60), (20, -60), (22, -62), (22, -90)],
    (18, -57),
    (20, -62),
)
NEW_V = [
    (4, -0.003),
    (11.996, -0.003),
    (11.996, -30.002),
    (15.003, -45.001),
    (15.003, -57.002),
    (18.003, -60.002),
    (19.998, -60.002),
    (21.998, -62.002),
    (21.998, -90.0),
]
ADJUSTED = _profile(NEW_V, (18.003, -57.002), (19.998, -62.002))
COORDS = set("XZIKR")


def _only_coordinates_changed(old: str, new: str) -> None:
    a, b = lex_gcode(old).lines[0], lex_gcode(new).lines[0]
    assert [c.text for c in a.comments] == [c.text for c in b.comments]
    keep_a = [str(w) for w in a.words if w.letter not in COORDS]
    keep_b = [str(w) for w in b.words if w.letter not in COORDS]
    assert keep_a == keep_b
    letters_a = [w.letter for w in a.words]
    letters_b = [w.letter for w in b.words]
    it = iter(letters_b)
    assert all(letter in it for letter in letters_a), (old, new)  # order kept
    # outside the words, the text is the same
    strip = lambda ln: "".join(ch for k, ch in enumerate(ln.text) if not _in_word(ln, k))  # noqa: E731
    assert strip(a).split() == strip(b).split()


def _in_word(line, k):
    return any(w.start <= k < w.end for w in line.words)


def test_mapping_by_geometry():
    bmap = map_blocks_to_profile(DATA / "stepped_shaft.ngc", NOMINAL)
    assert bmap.features == {
        "face_end": (8,),
        "dia_24": (9, 10),
        "taper": (11,),
        "dia_30": (12,),
        "fillet": (13,),
        "shoulder": (14,),
        "round": (15,),
        "dia_44": (16,),
    }
    assert bmap.connecting == (7, 17)  # the G42 entry and the departure
    assert not bmap.reversed
    assert "connecting [7, 17]" in repr(bmap)


def test_adjusted_program_changes_only_finish_coordinates():
    program = read_gcode(DATA / "stepped_shaft.ngc")
    result = adjust_program(program, NOMINAL, ADJUSTED, max_correction_mm=0.05, nose_radius_mm=0.4)
    old, new = program.text.splitlines(), result.text.splitlines()
    assert len(old) == len(new)
    changed = {k + 1 for k, (a, b) in enumerate(zip(old, new, strict=True)) if a != b}
    assert changed == {c.line for c in result.changes}
    assert changed <= set(range(7, 17))  # the entry and the finish-cut blocks
    for ln in changed:
        _only_coordinates_changed(old[ln - 1], new[ln - 1])
    text = dict(zip(range(1, len(new) + 1), new, strict=True))
    assert text[7] == "N50 G42 G1 X8.000 Z-0.003 F0.08"
    assert text[8] == "N60 G1 X23.992 Z-0.003"
    assert text[10] == "N80 Z-30.002"  # X unchanged (modal), not added
    assert text[13] == "N110 G2 X36.006 Z-60.002 I3.000 K0.000"
    assert text[14] == "N120 G1 X39.996 Z-60.002"  # X40.0 cannot carry 2 um: usual places
    assert text[15] == "N130 G3 X43.996 Z-62.002 R2.0"
    # the new program runs through the adjusted vertices (to the written precision)
    again = parse_gcode(result.text, name="new")
    ends = {m.line: m.end for m in again.moves}
    for ln, v in zip([7, 8, 10, 11, 12, 13, 14, 15, 16], NEW_V, strict=True):
        assert math.dist(ends[ln], v) < 6e-4, ln
    assert result.diff.startswith("--- ") and "+N60 G1 X23.992 Z-0.003" in result.diff
    assert result.max_shift_mm == pytest.approx(0.005, abs=1e-6)
    assert "blocks rewritten" in repr(result)


def test_unchanged_profile_leaves_the_program_byte_identical():
    program = read_gcode(DATA / "stepped_shaft.ngc")
    result = adjust_program(program, NOMINAL, NOMINAL, max_correction_mm=0.05)
    assert result.text == program.text and result.diff == "" and not result.changes


@pytest.mark.parametrize("name", ["stepped_shaft_g91.ngc", "stepped_shaft_inch.ngc"])
def test_incremental_and_inch_programs(name):
    program = read_gcode(DATA / name)
    result = adjust_program(program, NOMINAL, ADJUSTED, max_correction_mm=0.05)
    again = parse_gcode(result.text, name="new")
    finish = [m for m in again.moves if m.comp is not None]
    ends = [m.end for m in finish]
    tol = 2e-3 if "inch" in name else 6e-4  # 5 decimals in inches: 0.25 um
    for v in NEW_V:
        assert min(math.dist(e, v) for e in ends) < tol
    old_departure = [m for m in program.moves if m.comp is not None][-1]
    if "g91" in name:  # an unchanged incremental departure moves with its start
        assert math.dist(finish[-1].end, (24 - 0.002, -90.0)) < 1e-9
    else:  # an absolute one still ends where it did
        assert math.dist(finish[-1].end, old_departure.end) < 1e-12
    for c in result.changes:
        _only_coordinates_changed(c.old, c.new)
    if "g91" in name:
        assert "G91 G1 X7.996 Z0\n" in result.text  # increments from the new start


def test_refusals():
    program = read_gcode(DATA / "stepped_shaft.ngc")
    with pytest.raises(AnalysisError, match="more than the maximum correction 0.001 mm"):
        adjust_program(program, NOMINAL, ADJUSTED, max_correction_mm=0.001)
    with pytest.raises(InputError, match="differ from the nominal"):
        other = Profile(NOMINAL.features[:-1])
        adjust_program(program, NOMINAL, other, max_correction_mm=0.1)
    # a block on no feature in the middle of the contour
    text = program.text.replace("N90 G1 X30.000 Z-45.000", "N90 G1 X30.500 Z-45.000")
    with pytest.raises(AnalysisError, match=r"p.ngc:11: this finish-cut block lies on no profile"):
        map_blocks_to_profile(parse_gcode(text, name="p.ngc"), NOMINAL)
    # ... unless the mapping names it (and the taper, which no longer fits by geometry)
    bmap = map_blocks_to_profile(
        parse_gcode(text, name="p.ngc"), NOMINAL, mapping={"taper": [11], "dia_30": 12}
    )
    assert bmap.lines[11] == "taper" and bmap.lines[12] == "dia_30"
    # a feature no block cuts
    extra = Profile(NOMINAL.features + (Line("dia_48", (22, -90), (24, -95), 1),))
    with pytest.raises(AnalysisError, match="no finish-cut block cuts feature.*dia_48"):
        map_blocks_to_profile(program, extra)
    with pytest.raises(InputError, match="not in the profile"):
        map_blocks_to_profile(program, NOMINAL, mapping={"nope": [9]})
    with pytest.raises(InputError, match="has no move"):
        map_blocks_to_profile(program, NOMINAL, mapping={"taper": [1]})
    with pytest.raises(InputError, match="pairs a straight block with arc"):
        map_blocks_to_profile(program, NOMINAL, mapping={"fillet": [8]})


def _groove(walls):
    z1, z2 = walls
    return Profile(
        (
            Line("dia_a", (10, 0), (10, z1), -1),
            Line("wall_a", (10, z1), (8, z1), -1),
            Line("bottom", (8, z1), (8, z2), -1),
            Line("wall_b", (8, z2), (10, z2), -1),
            Line("dia_b", (10, z2), (10, -20), -1),
        )
    )


def test_a_result_that_gouges_is_refused():
    program = read_gcode(DATA / "groove.ngc")
    nominal = _groove((-10, -11))
    ok = adjust_program(program, nominal, _groove((-10.05, -10.95)), max_correction_mm=0.2)
    # the walls' blocks (G1 X16, G1 X20) need no change: their Z follows modally
    assert [c.line for c in ok.changes] == [6, 8]
    assert [c.new for c in ok.changes] == ["G1 Z-10.050", "G1 Z-10.950"]
    with pytest.raises(AnalysisError, match="gouges with the nose radius"):
        adjust_program(program, nominal, _groove((-10.15, -10.85)), max_correction_mm=0.2)
    with pytest.raises(AnalysisError, match="runs backwards"):
        adjust_program(program, nominal, _groove((-10.6, -10.4)), max_correction_mm=1.0)


def test_writing_never_overwrites_the_input(tmp_path):
    src = tmp_path / "finish.ngc"
    src.write_bytes((DATA / "stepped_shaft.ngc").read_bytes())
    result = adjust_program(read_gcode(src), NOMINAL, ADJUSTED, max_correction_mm=0.05)
    with pytest.raises(InputError, match="refusing to overwrite"):
        write_text_atomic(src, result.text, protect=[src])
    out = write_text_atomic(tmp_path / "finish_adjusted.ngc", result.text, protect=[src])
    assert out.read_text() == result.text


def test_demo_program_changes_only_in_finish_coordinate_words():
    if not (DEMO / "study.toml").exists():
        pytest.skip(f"demo study not found in {DEMO}")
    from piecs_bayes.io import load_study

    study = load_study(DEMO / "study.toml")
    program = read_gcode(study.program)
    nominal = study.profile
    shifted = []
    for f in nominal.features:  # move every feature by a few micrometres, keep it connected

        def mv(p):
            return (p[0] + 0.004 * (p[0] > 12.5) - 0.002, p[1] - 0.003 * (p[1] < -40))

        if isinstance(f, Arc):
            shifted.append(Arc(f.id, mv(f.p0), mv(f.p1), mv(f.center), f.ccw, f.side))
        else:
            shifted.append(Line(f.id, mv(f.p0), mv(f.p1), f.side))
    result = adjust_program(program, nominal, Profile(tuple(shifted)), max_correction_mm=0.02)
    bmap = result.mapping
    finish = set(bmap.lines) | set(bmap.connecting)
    for c in result.changes:
        assert c.line in finish
        _only_coordinates_changed(c.old, c.new)
    old, new = program.text.splitlines(), result.text.splitlines()
    for k, (a, b) in enumerate(zip(old, new, strict=True), start=1):
        if k not in {c.line for c in result.changes}:
            assert a == b

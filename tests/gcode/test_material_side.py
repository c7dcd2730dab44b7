"""The material side of a compensated run, read from the moves in air (issue 42).

An OD contour (chamfer, diameter, taper, diameter, shoulder) entered from in front of
the face and left by a rapid outward at its last shoulder, then back over the part:
with G41 the nose is below the contour, where the moves say the material is, and
`nose_compensate` (``kind="auto"``) refuses it naming the file, the word's line and the
move that contradicts it; with G42 it is resolved. The same for a bore left by a rapid
towards the axis (G42 refused, G41 resolved). A run whose moves do not pass beside
its contour is refused naming ``--kind``; every corpus program either agrees or is
listed, with its reason, in ``_corpus_sides.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _corpus_sides import SAID_BY_KIND

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import comp_sides, nose_compensate, parse_gcode, read_gcode

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"

# radius X in the reader: X16 = 8 mm; the contour runs from (8, 1) to (16, -35)
OD = """(OD: chamfer, diameter, taper, diameter, shoulder)
G18 G21 G7 G90 G40
G0 X30 Z5
{word} G1 X16 Z1 F0.2
G1 X20 Z-1
G1 Z-15
G1 X26 Z-25
G1 Z-35
G1 X32
G40 G0 X40
G0 Z5
M30
"""
# its mirror in a bore: the contour runs from (17, 1) to (9, -35), the exit towards the axis
BORE = """(bore: chamfer, diameter, taper, diameter, shoulder)
G18 G21 G7 G90 G40
G0 X20 Z5
{word} G1 X34 Z1 F0.1
G1 X30 Z-1
G1 Z-15
G1 X24 Z-25
G1 Z-35
G1 X18
G40 G0 X10
G0 Z5
M30
"""


def _read(text: str, name: str):
    return parse_gcode(text, name=name)


def test_od_with_g41_on_the_material_side_is_refused():
    program = _read(OD.format(word="G41"), "od_g41.ngc")
    with pytest.raises(InputError) as exc:
        nose_compensate(program, nose_radius=0.4)
    msg = str(exc.value)
    assert exc.value.line == 4 and exc.value.file == "od_g41.ngc"
    assert msg.startswith(
        "od_g41.ngc:4: G41 (line 4) puts the tool nose left of travel, below the contour "
        "(lines 5-9), but the exit move (line 10) passes above the contour at X40.0000 "
        "Z-35.0000 (mm, X a diameter), across from line 9: the air is above it, so it is "
        "an OD (material between the contour and the axis)"
    )
    assert "use G42" in msg and "--kind external" in msg
    (run,) = comp_sides(program)
    assert (run.verdict, run.nose, run.word, run.air, run.kind) == (
        "contradicts", "left", -1, 1, "external",
    )  # fmt: skip
    # the exit at the shoulder and the rapid back over the part both say it
    roles = [(w.role, w.line, w.sign) for w in run.witnesses]
    assert roles == [("exit", 10, 1), ("retract", 11, 1)]
    assert run.witnesses[0].point == (20.0, -35.0)
    back = run.witnesses[1]  # its point farthest above the contour: over the chamfer
    assert back.point[0] == 20.0 and 0.5 < back.point[1] <= 1.0 and back.feature == 5


def test_the_same_od_with_g42_is_resolved():
    program = _read(OD.format(word="G42"), "od_g42.ngc")
    (run,) = comp_sides(program)
    assert (run.verdict, run.nose, run.word, run.air, run.kind) == (
        "agrees", "right", 1, 1, "external",
    )  # fmt: skip
    result = nose_compensate(program, nose_radius=0.4)
    again = parse_gcode(result.text, name="out")
    assert all(m.comp is None for m in again.moves)
    # the nose centre runs 0.4 mm above the X20 diameter (radius 10) from Z-1 to Z-15
    (along,) = [m for m in result.path if m.line == 6 and m.kind == "feed"]
    np.testing.assert_allclose(along.start, (10.4, -1.0), atol=1e-12)
    assert along.end[0] == along.start[0] and -15.0 < along.end[1] < -14.0
    # and the same contour said to be an OD gives the same program
    assert nose_compensate(program, nose_radius=0.4, kind="external").text == result.text


@pytest.mark.parametrize("word, verdict", [("G42", "contradicts"), ("G41", "agrees")])
def test_the_bore_mirror(word, verdict):
    program = _read(BORE.format(word=word), f"bore_{word.lower()}.ngc")
    (run,) = comp_sides(program)
    assert (run.verdict, run.air, run.kind) == (verdict, -1, "internal")
    assert [(w.role, w.line, w.sign) for w in run.witnesses] == [
        ("exit", 10, -1), ("retract", 11, -1),
    ]  # fmt: skip
    assert run.witnesses[0].point == (5.0, -35.0)
    if verdict == "agrees":
        result = nose_compensate(program, nose_radius=0.4)
        (along,) = [m for m in result.path if m.line == 6 and m.kind == "feed"]
        np.testing.assert_allclose(along.start[0], 14.6, atol=1e-12)  # the X30 bore
        return
    with pytest.raises(InputError) as exc:
        nose_compensate(program, nose_radius=0.4)
    msg = str(exc.value)
    assert msg.startswith("bore_g42.ngc:4: G42 (line 4) puts the tool nose right of travel, above")
    assert (
        "the exit move (line 10) passes below the contour at X10.0000 Z-35.0000 (mm, X a "
        "diameter), across from line 9: the air is below it, so it is a bore" in msg
    )
    assert "use G41" in msg


# the OD contour entered in front of it and left behind it: no move passes beside it
UNTOLD = OD.replace("G40 G0 X40\nG0 Z5\n", "G40 G0 X40 Z-40\n")


@pytest.mark.parametrize("word", ["G41", "G42"])
def test_a_run_the_moves_do_not_tell_is_refused_naming_kind(word):
    program = _read(UNTOLD.format(word=word), "untold.ngc")
    (run,) = comp_sides(program)
    assert run.verdict == "undecided" and run.witnesses == () and run.air == 0
    with pytest.raises(InputError) as exc:
        nose_compensate(program, nose_radius=0.4)
    assert str(exc.value) == (
        f"untold.ngc:4: {word} (line 4), contour lines 5-9: no move in air passes beside "
        "it (the entry, the exit and the rapids around them lie beyond its ends, or there "
        "are none), so the program does not say which side the material is on, and "
        f"{word} alone is not trusted with it; say where it is: --kind external (an OD: "
        "the material towards the axis) or --kind internal (a bore), as a study's "
        "[profile] kind says it"
    )
    if word == "G42":  # said, it is resolved; G41 said external is refused by its moves
        nose_compensate(program, nose_radius=0.4, kind="external")
    else:
        with pytest.raises(InputError, match=r"G41 \(line 4\) .*use G42"):
            nose_compensate(program, nose_radius=0.4, kind="external")


def test_moves_on_both_sides_do_not_tell_either():
    """A rapid inside a tube's bore under an OD contour and the exit above it."""
    text = OD.format(word="G42").replace("G0 X30 Z5\n", "G0 X4 Z-20\nG0 Z5\nG0 X30\n")
    program = _read(text, "tube.ngc")
    (run,) = comp_sides(program)
    assert run.verdict == "conflicting" and run.air == 0
    signs = {(w.role, w.line): w.sign for w in run.witnesses}
    assert signs == {("approach", 3): -1, ("approach", 4): -1, ("exit", 12): 1, ("retract", 13): 1}
    with pytest.raises(InputError) as exc:
        nose_compensate(program, nose_radius=0.4)
    msg = str(exc.value)
    assert "moves in air pass on both sides of it (the exit move (line 12) passes above" in msg
    assert "the rapid before it (line 3) passes below the contour at X4.0000 Z-20.0000" in msg
    assert "--kind external" in msg


def test_the_moves_after_the_exit_stop_at_the_next_cut():
    """A groove cut after G40 makes air below the contour: the rapids after it are not
    evidence (nor are moves after a tool change or a reference return)."""
    text = OD.format(word="G42").replace(
        "G0 Z5\nM30\n", "G0 X40 Z-20\nG1 X22\nG0 X40\nG0 Z5\nG28\nG0 X4 Z-20\nM30\n"
    )
    (run,) = comp_sides(_read(text, "groove.ngc"))
    assert [(w.role, w.line) for w in run.witnesses] == [("exit", 10), ("retract", 11)]
    assert run.verdict == "agrees"


def test_a_shift_of_the_frame_ends_the_evidence():
    """A G92 between a rapid and the run: the rapid's coordinates are in the old frame."""
    text = OD.format(word="G41").replace("G0 X30 Z5\n", "G0 X30 Z-60\nG0 Z-20\nG92 Z40\n")
    program = _read(text, "g92.ngc")
    (run,) = comp_sides(program)
    # the rapids at Z-20 and Z-60 (old frame) would pass above the contour: not counted
    assert all(w.role != "approach" for w in run.witnesses)


def test_a_rapid_under_compensation_back_over_the_part():
    """LinuxCNC's ngcgui taper-od: G42 on, a taper, and a rapid back over it still under
    compensation (issue 29's vote by travel read it as a bore and refused the right
    G42); the rapid is air above the taper, and a rapid cuts nothing to judge."""
    text = """G18 G20 G7 G90
G0 X1.2 Z0.2
G42
G0 X1 Z0.1
G1 X1 Z0 F2
X1.7053 Z-2
X1.9053
G0 Z0
G40
M2
"""
    program = _read(text, "taper.ngc")
    (run,) = comp_sides(program)
    assert run.verdict == "agrees" and run.kind == "external"
    assert [(w.role, w.line, w.sign) for w in run.witnesses] == [("rapid", 8, 1)]
    nose_compensate(program, nose_radius=0.4)


def test_a_canned_cycle_is_judged_by_its_own_rapids():
    """Fanuc G71 with no G70: the finish contour is the cycle's; its passes' retracts
    and its return to the start point pass above it."""
    program = read_gcode(DATA / "dialects" / "fanuc_g71_without_g70.nc")
    (run,) = comp_sides(program)
    assert run.verdict == "agrees" and run.kind == "external"
    assert {w.role for w in run.witnesses} == {"cycle"}
    assert all(w.line == 9 and w.sign == 1 for w in run.witnesses)


def test_a_face_is_judged_in_front_and_behind():
    program = read_gcode(DATA / "05_face_mm_t5_g41.ngc")
    (run,) = comp_sides(program)
    assert (run.axis, run.verdict, run.air, run.kind) == ("x", "agrees", 1, None)
    assert run.side_name(run.air) == "in front of"
    text = (DATA / "05_face_mm_t5_g41.ngc").read_text().replace("G41 G1", "G42 G1")
    with pytest.raises(InputError, match=r"G42 \(line 6\) .*behind the contour .*use G41"):
        nose_compensate(parse_gcode(text, name="face_g42.ngc"), nose_radius=0.4)


def test_every_corpus_program_agrees_or_is_listed_with_its_kind():
    """Named for an OD or a bore, a corpus program's moves say so, or it is listed in
    `_corpus_sides.SAID_BY_KIND` with the reason its moves do not (and it is refused
    by `--kind auto`, resolved with its kind)."""
    seen = set()
    for path in sorted(DATA.glob("*.ngc")):
        program = read_gcode(path)
        runs = comp_sides(program)
        verdicts = {r.verdict for r in runs}
        if path.name in SAID_BY_KIND:
            seen.add(path.name)
            assert verdicts != {"agrees"}, path.name
            with pytest.raises(InputError, match="--kind external"):
                nose_compensate(program, nose_radius=0.1)
            nose_compensate(program, nose_radius=0.1, kind=SAID_BY_KIND[path.name][0])
            continue
        assert verdicts == {"agrees"}, (path.name, [r.verdict for r in runs])
        words = path.stem.split("_")
        want = "internal" if "bore" in words else "external" if "od" in words else None
        if want is not None:
            assert {r.kind for r in runs} == {want}, path.name
    assert seen == set(SAID_BY_KIND)

"""Nose-radius compensation against hand-computed paths: LinuxCNC's corner arcs,
the 1969 bisector rule (r / cos(alpha/2)), tip offsets, radius-error correction, gouges."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from _corpus_sides import corpus_kind

from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.gcode import (
    compensated_path,
    correct_radius_error,
    nose_compensate,
    parse_gcode,
    parse_tool_table,
    read_gcode,
    read_tool_table,
    tip_offset,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
R = 0.5  # nose radius of the hand-computed programs (G42.1 D1)

# OD step, tool right of travel (G42): entry, -Z, up a shoulder (concave), -Z (convex).
STEP = """G18 G21 G8 G90 F1
G0 X20 Z5
G42.1 D1 L{o} G1 X10 Z1
G1 Z-10
G1 X15
G1 Z-20
G40 G0 X20 Z5
M30
"""


def _line_offset_intersection(p, u, q, v):
    """Intersection of the lines p + s u and q + t v (x, z)."""
    a = np.array([[u[0], -v[0]], [u[1], -v[1]]])
    s, _ = np.linalg.solve(a, np.subtract(q, p))
    return np.add(p, s * np.asarray(u))


def _ends(path):
    return np.array([m.end for m in path])


def test_tip_offsets_follow_linuxcnc():
    table = {
        0: (0, 0),
        1: (-1, 1),
        2: (-1, -1),
        3: (1, -1),
        4: (1, 1),
        5: (0, 1),
        6: (-1, 0),
        7: (0, -1),
        8: (1, 0),
        9: (0, 0),
    }
    for o, (dx, dz) in table.items():
        assert tip_offset(o, 0.4) == (dx * 0.4, dz * 0.4)
    with pytest.raises(InputError):
        tip_offset(10, 0.4)


def test_linuxcnc_corners_by_hand():
    path = compensated_path(parse_gcode(STEP.format(o=0), name="step"))
    kinds = [m.kind for m in path]
    assert kinds == ["rapid", "feed", "feed", "feed", "ccw", "feed", "rapid"]
    # entry: ends one radius right of the entry move at its end, then trimmed
    # back to the offset of the first contour move (x = 10 + r): concave corner
    d = np.array([10 - 20, 1 - 5.0])
    u = d / np.linalg.norm(d)
    right = -np.array([u[1], -u[0]])
    end = np.array([10.0, 1.0]) + R * right
    mid = _line_offset_intersection(end, u, (10 + R, 0.0), (0.0, 1.0))
    assert path[1].end == pytest.approx(tuple(mid), abs=1e-12)
    # concave 90 deg corner: offsets meet one radius off both walls
    assert path[2].end == pytest.approx((10 + R, -10 + R))
    # convex 90 deg corner: line ends one radius right of its end, an arc about
    # the programmed corner (CCW for a tool right of travel) joins the next offset
    assert path[3].end == pytest.approx((15.0, -10 + R))
    assert path[4].center == pytest.approx((15.0, -10.0))
    assert path[4].end == pytest.approx((15 + R, -10.0))
    assert path[5].end == pytest.approx((15 + R, -20.0))
    assert path[6].end == (20.0, 5.0)


@pytest.mark.parametrize("orientation", range(10))
def test_orientation_shifts_every_compensated_point(orientation):
    base = compensated_path(parse_gcode(STEP.format(o=0), name="s"))
    moved = compensated_path(parse_gcode(STEP.format(o=orientation), name="s"))
    dx, dz = tip_offset(orientation, R)
    for a, b in zip(base[1:6], moved[1:6], strict=True):
        assert b.end == pytest.approx((a.end[0] + dx, a.end[1] + dz), abs=1e-12)
        if a.center is not None:
            assert b.center == pytest.approx((a.center[0] + dx, a.center[1] + dz))
    assert moved[0].end == base[0].end and moved[-1].end == base[-1].end


def test_left_and_right_mirror():
    right = compensated_path(parse_gcode(STEP.format(o=0), name="s"))
    left_text = STEP.format(o=0).replace("G42.1", "G41.1")
    # the same contour with the tool on the other side: the shoulder corner
    # turns convex (an arc is inserted) and the offsets change sign
    left = compensated_path(parse_gcode(left_text, name="s"))
    # entry corner and shoulder corner are convex now: two CW arcs (tool left)
    assert [m.kind for m in left] == ["rapid", "feed", "cw", "feed", "cw", "feed", "feed", "rapid"]
    assert left[4].center == pytest.approx((10.0, -10.0))
    assert left[5].end == pytest.approx((15 - R, -10 - R))
    assert right[3].end == pytest.approx((15.0, -10 + R))
    ext = compensated_path(parse_gcode(left_text, name="s"), corner="extend")
    assert ext[2].end == pytest.approx((10 - R, -10 - R))


def test_extend_rule_by_hand():
    path = compensated_path(parse_gcode(STEP.format(o=0), name="s"), corner="extend")
    assert [m.kind for m in path] == ["rapid", "feed", "feed", "feed", "feed", "rapid"]
    # uncompensated entry meets the first compensated move: r along its normal
    assert path[1].end == pytest.approx((10 + R, 1.0))
    # compensated-compensated junctions: on the bisector, r / cos(alpha / 2) away
    for k, corner in ((2, (10.0, -10.0)), (3, (15.0, -10.0))):
        v = np.subtract(path[k].end, corner)
        assert np.linalg.norm(v) == pytest.approx(R / math.cos(math.radians(45)))
        assert abs(v[0]) == pytest.approx(abs(v[1]))
    assert path[2].end == pytest.approx((10 + R, -10 + R))
    assert path[3].end == pytest.approx((15 + R, -10 + R))
    # compensated move meets the uncompensated exit move: r along its normal
    assert path[4].end == pytest.approx((15 + R, -20.0))
    assert path[5].end == (20.0, 5.0)  # zero at the end of the uncompensated move


@pytest.mark.parametrize("taper_deg", [10.0, 30.0, 60.0, -25.0])
def test_extend_bisector_length_on_tapers(taper_deg):
    """A diameter followed by a taper turning by alpha: the offset corner lies on
    the bisector of the normals at r / cos(alpha / 2) from the programmed corner."""
    a = math.radians(taper_deg)
    x2, z2 = 10 + 8 * math.sin(a), -10 - 8 * math.cos(a)
    text = (
        f"G18 G21 G8 F1\nG0 X20 Z5\nG42.1 D1 G1 X10 Z1\nG1 Z-10\n"
        f"G1 X{x2:.9f} Z{z2:.9f}\nG1 Z{z2 - 5:.9f}\nG40 G0 X30 Z5\n"
    )
    path = compensated_path(parse_gcode(text, name="t"), corner="extend")
    corner = np.array([10.0, -10.0])
    v = np.asarray(path[2].end) - corner
    alpha = abs(a)
    assert np.linalg.norm(v) == pytest.approx(R / math.cos(alpha / 2), rel=1e-9)
    n1 = np.array([1.0, 0.0])  # right of -Z travel: +x
    d2 = np.array([math.sin(a), -math.cos(a)])
    n2 = -np.array([d2[1], -d2[0]])
    bis = (n1 + n2) / np.linalg.norm(n1 + n2)
    assert v / np.linalg.norm(v) == pytest.approx(bis, abs=1e-9)


def test_extend_line_arc_junction_is_on_both_offsets():
    text = (
        "G18 G21 G8 F1\nG0 X20 Z5\nG42.1 D1 G1 X10 Z1\nG1 Z-10\n"
        "G3 X13 Z-13 R3\nG1 X13 Z-20\nG40 G0 X30 Z5\n"
    )
    prog = parse_gcode(text, name="a")
    arc = prog.moves[3]
    path = compensated_path(prog, corner="extend")
    # the G3 arc is convex seen from a tool on its right: offset radius 3 + r
    out = path[3]
    assert out.kind == "ccw" and out.center == pytest.approx(arc.center)
    for p in (out.start, out.end):
        assert math.dist(p, arc.center) == pytest.approx(3 + R)
    assert out.start[0] == pytest.approx(10 + R)  # on the offset of the diameter
    assert out.end == pytest.approx((13 + R, -13.0))  # tangent exit: r along the normal


def test_radius_error_correction_matches_recompensation():
    """An arc-cornered path made with r0 and corrected to r1 is the path made
    with r1 on every compensated move (corner arcs grow from r0 to r1)."""
    r0, r1 = 0.5, 0.53
    made = compensated_path(parse_gcode(STEP.format(o=0), name="s"))
    want = compensated_path(parse_gcode(STEP.format(o=0).replace("D1", f"D{2 * r1}"), name="s"))
    # lines 2 (approach), 3 (entry) and 7 (exit) are not compensated moves
    fixed = correct_radius_error(
        made, planned=r0, actual=r1, side="right", compensated=lambda m: m.line in (4, 5, 6)
    )
    for a, b in zip(fixed[2:6], want[2:6], strict=True):
        assert a.end == pytest.approx(b.end, abs=1e-12)
        assert a.kind == b.kind
        if a.center is not None:
            assert a.center == pytest.approx(b.center)
            assert math.dist(a.end, a.center) == pytest.approx(r1)


def test_radius_error_correction_rules_and_tip():
    made = compensated_path(parse_gcode(STEP.format(o=0), name="s"), corner="extend")
    fixed = correct_radius_error(made, planned=R, actual=R - 0.02, side="right", orientation=3)
    dr = -0.02
    tip = np.array(tip_offset(3, dr))
    # interior concave corner: on the bisector at dr / cos(45 deg), plus the tip change
    v = np.asarray(fixed[2].end) - np.asarray(made[2].end) - tip
    assert np.linalg.norm(v) == pytest.approx(abs(dr) * math.sqrt(2))
    # the rapid approach (uncompensated) meets the entry feed (compensated by
    # default): dr along the entry's normal, plus the tip change
    shift = np.asarray(fixed[0].end) - np.asarray(made[0].end) - tip
    entry = np.subtract(made[1].end, made[1].start)
    assert np.linalg.norm(shift) == pytest.approx(abs(dr))
    assert abs(np.dot(shift, entry)) < 1e-12
    with pytest.raises(InputError):
        correct_radius_error(made, planned=R, actual=R, side="up")


def test_radius_error_correction_of_a_resolved_program():
    """Read a program without compensation words, correct it, write it back."""
    from piecs_bayes.gcode import write_path_program

    resolved = parse_gcode(nose_compensate(parse_gcode(STEP.format(o=0), name="s")).text, name="r")
    fixed = correct_radius_error(
        resolved.moves, planned=R, actual=R + 0.02, side="right", compensated=[4, 5, 6, 7]
    )
    text, changed = write_path_program(resolved, fixed)
    again = parse_gcode(text, name="fixed")
    want = compensated_path(parse_gcode(STEP.format(o=0).replace("D1 ", "D1.04 "), name="s"))
    for a, b in zip(again.moves[2:6], want[2:6], strict=True):
        assert a.end == pytest.approx(b.end, abs=1e-6)
    assert changed == (3, 4, 5, 6, 7)


@pytest.mark.parametrize(
    "name, line",
    [
        ("g01_entry_too_short.ngc", 6),
        ("g02_groove_too_narrow.ngc", 10),
        ("g03_fillet_smaller_than_nose.ngc", 8),
        ("g04_step_shorter_than_nose.ngc", 9),
        ("g05_entry_arc_too_short.ngc", 6),
        ("g06_arc_in_concave_corner.ngc", 9),
        ("g07_arc_to_line_corner.ngc", 11),
    ],
)
def test_gouges_raise_with_their_line(name, line, tools):
    with pytest.raises(AnalysisError) as exc:
        compensated_path(read_gcode(DATA / "gouge" / name), tool_table=tools)
    assert exc.value.line == line
    assert f"{name}:{line}:" in str(exc.value)


def test_extend_rule_gouges():
    narrow = read_gcode(DATA / "gouge" / "g02_groove_too_narrow.ngc")
    with pytest.raises(AnalysisError, match="runs backwards|cannot reach"):
        compensated_path(narrow, corner="extend", nose_radius=0.4)
    small = read_gcode(DATA / "gouge" / "g03_fillet_smaller_than_nose.ngc")
    with pytest.raises(AnalysisError, match="arc radius"):
        compensated_path(small, corner="extend", nose_radius=0.4)
    with pytest.raises(InputError, match="unknown corner rule"):
        compensated_path(narrow, corner="round", nose_radius=0.4)


def test_arc_entry_quirk_is_refused():
    """LinuxCNC turns the arc after an arc entry into a full circle when a tip
    offset is active and the next corner is concave; we refuse that program."""
    text = (
        "G18 G21 G7 G90 F1\nG0 X18 Z6\nG42.1 D0.8 L3 G2 X12 Z0 R5\nG3 X20 Z-4 R4\n"
        "G1 Z-10\nG40 G0 X40 Z6\n"
    )
    with pytest.raises(AnalysisError, match="full circle") as exc:
        compensated_path(parse_gcode(text, name="q"))
    assert exc.value.line == 3


def test_tool_table_resolution(tools):
    g42 = "G18 G21 G8 F1\nT{t} M6\nG0 X20 Z5\nG42 G1 X10 Z1\nG1 Z-10\nG40 G0 X20 Z5\n"
    with pytest.raises(InputError, match="tool table") as exc:
        compensated_path(parse_gcode(g42.format(t=3), name="p.ngc"))
    assert exc.value.line == 4 and exc.value.file == "p.ngc"
    with pytest.raises(InputError, match="T42 is not in the tool table"):
        compensated_path(parse_gcode(g42.format(t=42), name="p.ngc"), tool_table=tools)
    no_m6 = "G18 G21 G8 F1\nT3\nG0 X20 Z5\nG42 G1 X10 Z1\nG40 G0 X20 Z5\n"
    with pytest.raises(InputError, match="no tool loaded"):
        compensated_path(parse_gcode(no_m6, name="p"), tool_table=tools)
    # a tool with no radius: compensation changes nothing
    plain = compensated_path(parse_gcode(g42.format(t=12), name="p"), tool_table=tools)
    np.testing.assert_array_equal(_ends(plain), [(20, 5), (10, 1), (10, -10), (20, 5)])
    # a negative diameter swaps the side
    neg = parse_tool_table("T1 D-1 Q0\n")
    pos = parse_tool_table("T1 D1 Q0\n")
    swapped = compensated_path(parse_gcode(g42.format(t=1), name="p"), tool_table=neg)
    left = g42.format(t=1).replace("G42", "G41")
    np.testing.assert_allclose(
        _ends(swapped), _ends(compensated_path(parse_gcode(left, name="p"), tool_table=pos))
    )
    # nose_radius stands in for the table (orientation 0)
    by_radius = compensated_path(parse_gcode(g42.format(t=3), name="p"), nose_radius=0.5)
    inline = g42.format(t=3).replace("G42 G1", "G42.1 D1 G1")
    np.testing.assert_allclose(
        _ends(by_radius), _ends(compensated_path(parse_gcode(inline, name="p")))
    )


def test_output_program_has_no_compensation_and_keeps_other_lines(tools):
    for path in sorted(DATA.glob("*.ngc")):
        program = read_gcode(path)
        result = nose_compensate(program, tool_table=tools, kind=corpus_kind(path))
        again = parse_gcode(result.text, name="out")
        assert all(m.comp is None for m in again.moves), path.name
        codes = {w.code for ln in again.lines for w in ln.words if w.letter == "G"}
        assert not codes & {"G40", "G41", "G42", "G41.1", "G42.1"}, path.name
        changed = set(result.changed_lines)
        kept = [ln.text + ln.eol for ln in program.lines if ln.number not in changed]
        out = result.text
        for text in kept:
            assert text in out, (path.name, text)
        # the new program's moves are the compensated path, end for end
        np.testing.assert_allclose(
            _ends(again.moves), _ends(result.path), atol=1e-5, err_msg=path.name
        )


def test_writer_keeps_case_words_and_incremental_mode(tools):
    crlf = nose_compensate(read_gcode(DATA / "17_crlf_lower_n_comments.ngc"), tool_table=tools)
    assert "\r\nn50 g1 x" in crlf.text and "f.1 (entry move)\r\n" in crlf.text
    assert "\n" not in crlf.text.replace("\r\n", "") and crlf.text.endswith("%\r\n")
    inc = nose_compensate(read_gcode(DATA / "23_g40_alone_then_incremental.ngc"), tool_table=tools)
    assert "\nG40\n" not in inc.text
    assert "G91 G1 X4.0 Z0.3937" in inc.text  # relative to where the tool really is
    assert "NoseCompResult(corner='arc'" in repr(inc)


@pytest.fixture
def tools():
    return read_tool_table(DATA / "tools.tbl", units="in")


def test_a_ring_bore_left_over_the_ring_needs_its_kind_said(tools):
    """A ring's bore entered from above the face, left behind the ring and back over
    it (issue 29 accepted its G41 from the word alone): the rapid back over the ring
    passes where a bore's wall would be, as far as the program says, so `--kind auto`
    refuses it naming that move and `--kind`; said to be internal it is resolved, and a
    move whose side contradicts the rest of its run is still refused."""
    ring = read_gcode(DATA / "29_bore_ring_in_front_and_behind_t2.ngc")
    with pytest.raises(InputError) as exc:
        nose_compensate(ring, tool_table=tools)
    msg = str(exc.value)
    assert msg.startswith(f"{ring.name}:6: G41 (line 6) puts the tool nose left of travel")
    assert "the exit move (line 10) passes above the contour at X40.0000 Z-12.0000" in msg
    assert "use G42" in msg and "--kind internal" in msg
    result = nose_compensate(ring, tool_table=tools, kind="internal")
    assert result.changed_lines == (6, 7, 8, 9, 10)
    text = (DATA / "29_bore_ring_in_front_and_behind_t2.ngc").read_text()
    back = text.replace("G1 X20.000 Z-12.000\n", "G1 X20.000 Z-12.000\nG1 X20.000 Z-11.000\n")
    with pytest.raises(InputError, match=r"G41 \(line 6\) .* contour at line 10: .*use G42"):
        nose_compensate(parse_gcode(back, name="back.ngc"), tool_table=tools, kind="internal")

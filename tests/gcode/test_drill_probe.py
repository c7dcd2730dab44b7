"""LinuxCNC's drilling cycles (G17: G73, G81-G83, G85, G89), its Y axis and its probing
moves (G38.x), read as the moves the control makes: by hand on a small case, and beside
``rs274 -g`` on every form (repeats, incremental steps, retract modes, inch, sticky words).
None of them is ever a contour."""

from __future__ import annotations

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import parse_gcode, rs274_path, run_rs274
from piecs_bayes.gcode._path_contour import path_runs


def _moves(text):
    return [(m.kind, m.end[0], m.y[1] if m.y else 0.0, m.end[1]) for m in parse_gcode(text).moves]


def test_peck_drilling_by_hand():
    """G83 from Z5 with R2, Z-7, Q3 (mm, G98): over the hole at the old Z, down to R,
    pecks to -1 and -4 with a rapid back to R and down to 0.254 mm above the last depth,
    the last feed to -7, the retract to the old Z (5)."""
    text = "G18 G21 G8 F100\nG0 X0 Z5\nG17 G98 G83 X1 Y2 Z-7 R2 Q3\nG80\nM2\n"
    got = _moves(text)[1:]
    d = 0.254
    want = [
        ("rapid", 1, 2, 5), ("rapid", 1, 2, 2),
        ("feed", 1, 2, -1), ("rapid", 1, 2, 2), ("rapid", 1, 2, -1 + d),
        ("feed", 1, 2, -4), ("rapid", 1, 2, 2), ("rapid", 1, 2, -4 + d),
        ("feed", 1, 2, -7), ("rapid", 1, 2, 5),
    ]  # fmt: skip
    assert [m[0] for m in got] == [m[0] for m in want]
    for a, b in zip(got, want, strict=True):
        assert a[1:] == pytest.approx(b[1:], abs=1e-12)


def test_drilling_and_probing_moves_are_never_a_path_contour():
    text = (
        "G18 G21 G8 F100\nG0 X10 Z5\nG1 X8 Z0\nG1 Z-10\nG1 X10 Z-12\nG0 X20\n"
        "G17 G0 X0 Y0 Z5\nG81 Z-5 R1\nG81 Y3\nG80\nG38.3 X5 Y1\nG18\nM2\n"
    )
    program = parse_gcode(text)
    runs = path_runs(program)
    assert [[m.line for m in r] for r in runs] == [[3, 4, 5]]
    assert {m.via for m in program.moves if m.y} >= {"G81", "G38.3"}


def test_the_probe_result_is_the_moves_end_and_the_tool_backs_off():
    text = "G18 G21 G8 F50\nG0 X0 Z0\nG38.2 Z-4\n#1=#5063\nG0 X[#1]\nM2\n"
    program = parse_gcode(text)
    probe, after = program.moves[1], program.moves[2]
    assert probe.via == "G38.2" and probe.end == (0.0, -4.0)
    assert after.start == pytest.approx((0.0, -4.0 + 0.254)) and after.end[0] == -4.0
    assert any("contact" in n.text for n in program.notes)


def test_a_probe_result_before_any_probe_has_no_value():
    with pytest.raises(InputError, match="5061"):
        parse_gcode("G18 G21 F50\nG0 X[#5061] Z0\nM2\n")


#: drilling programs beside rs274: preamble and blocks
CASES = {
    "g81-g98-above": "G21 G8 F100\nG0 X0 Y0 Z10\nG17 G98 G81 X2 Y1 Z-3 R2\nX4\nY-1 Z-5\nG80\nG0 Z10",
    "g81-g99-repeats-incremental": "G21 G8 F100\nG0 X0 Y0 Z10\nG17 G91 G99 G81 X3 Y1 Z-4 R-6 L3\nG90 G80\nG0 Z10",
    "g82-g85-g89": "G21 G8 F100\nG0 X0 Y0 Z6\nG17 G82 X1 Z-2 R1 P0.5\nG85 X2 Z-3 R1\nG89 X3 Z-4 R1 P1\nG80",
    "g73-chip-break": "G21 G8 F100\nG0 X0 Y0 Z3\nG17 G73 X0 Y0 Z-10 R1 Q2.5\nG80",
    "g83-below-r": "G21 G8 F100\nG0 X0 Y0 Z-2\nG17 G83 X0 Y0 Z-9 R1 Q2\nG80",
    "g83-exact-pecks": "G21 G8 F100\nG0 X0 Y0 Z5\nG17 G83 Z-6 R0 Q2\nG80",
    "g83-inch-diameter": "G20 G7 F4\nG0 X0 Y0 Z0.5\nG17 G83 X0.5 Y0.2 Z-0.7 R0.1 Q0.25\nX1\nG80",
    "g81-incremental-from-below": "G21 G8 F100\nG0 X1 Y1 Z-1\nG17 G91 G81 X1 Z-3 R2 L2\nG90 G80",
    "y-moves-g19-g17": "G21 G8 F100\nG0 X1 Y2 Z3\nG19 G1 Y-1 Z0\nG17 G1 X4 Y0\nG18 G0 X10 Z10\nG28\n",
    "probes-x-y-z": "G21 G8 F40\nG0 X5 Z2\nG91 G38.2 X3\nG38.3 Y-2\nG90 G0 X[#5061-1]\nG38.5 Z[#5063-5]\nG38.4 X0\n",
}  # fmt: skip


@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("case", sorted(CASES))
def test_drilling_probing_and_y_moves_as_rs274(case):
    text = f"G18 {CASES[case]}\nM2\n"
    program = parse_gcode(text, name=case)
    ref = run_rs274(text)
    assert ref.error is None, ref.error
    ours = program.moves
    assert len(ours) == len(ref.moves), (len(ours), len(ref.moves))
    unit = 25.4 if "G20" in text else 1.0
    for k, (a, b) in enumerate(zip(ours, ref.moves, strict=True)):
        where = f"move {k + 1} (line {a.line})"
        kind = "probe" if a.via.startswith("G38") else a.kind
        assert kind == b.kind, where
        ay = a.y[1] if a.y else 0.0
        for u, v in ((a.end[0], b.end[0]), (ay, b.y), (a.end[1], b.end[1])):
            assert abs(u - v) / unit <= 1e-4 + 1e-9, (where, u, v)


#: LinuxCNC's own probing programs (mill programs it ships): a grid of G38.2 probes, and
#: a loop that runs until the probe's result #5070 clears (read as rs274 reports it)
SHIPPED = ("gridprobe.ngc", "smartprobe.ngc")


@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("name", SHIPPED)
def test_linuxcncs_probing_programs_as_rs274(name):
    from pathlib import Path

    path = Path("/usr/share/linuxcnc/ncfiles") / name
    if not path.is_file():
        pytest.skip(f"{path} is not installed")
    program = parse_gcode(path.read_text(), name=name)
    ref = run_rs274(path)
    assert ref.error is None, ref.error
    assert len(program.moves) == len(ref.moves) > 100
    for a, b in zip(program.moves, ref.moves, strict=True):
        ay = a.y[1] if a.y else 0.0
        assert max(abs(a.end[0] - b.end[0]), abs(ay - b.y), abs(a.end[1] - b.end[1])) <= 2.6e-3

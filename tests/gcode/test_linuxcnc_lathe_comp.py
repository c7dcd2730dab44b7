"""LinuxCNC's own lathe compensation test (tests/ccomp/lathe-comp in the LinuxCNC
repository), reproduced: our ``gcode nose-comp`` resolves the program's G41/G42 with the
test's tool table, LinuxCNC's ``rs274`` runs the resolved program, and its canonical moves
are the test's expected output to 2e-4 in.

The program is the test's geometry written here again (inch, lower case as there): the
same contour cut three times, without compensation, with G41 by tool 2 (orientation 2)
and backwards with G42 by tool 7 (orientation 7), each tool 0.1 in across. ``EXPECTED``
holds the ends and centres of the moves of the test's ``expected`` file (inches; arcs as
``(x, z, centre x, centre z, +1 ccw / -1 cw)``).
"""

from __future__ import annotations

import pytest

from piecs_bayes.cli import main
from piecs_bayes.gcode import rs274_path, run_rs274

PROGRAM = """g20 g64 g18 f30
g49
t0 m6
g0 x.3 z0
g40
g1 x.1
g3 x0 z.1 r.1
g1 z1
g2 r.25 x-.25 z1.25
g3 r.25 x-.5 z1.5
g1 z1.75
g0 x.3
t2 m6
g43 h2
g0 z0
g41
g1 x.1
g3 x0 z.1 r.1
g1 z1
g2 r.25 x-.25 z1.25
g3 r.25 x-.5 z1.5
g1 z1.75
g40
g0 x.3
t7 m6
g43 h9
g0 z1.85
g0 x-.3
g42
g1 x-.4
g2 x-.5 z1.75 r.1
g1 z1.5
g2 r.25 x-.25 z1.25
g3 r.25 x0 z1
g1 z.1
g2 r.1 x.1 z0
g40
g0 x.3
g49
t0 m6
m2
"""
#: (the test's table: a second P word on two lines, as LinuxCNC writes it; I/J angles)
TOOLS = """T2 P2 Z0.0 X0.0 D0.1 I85.0 J25.0 Q2;
T7 P7 Z0.0 P0.0 D0.1 I-30.0 J30.0 Q7;
T9 P9 Z0.0 P0.0 D0.1 I0 J0 Q9;
"""
#: the expected canonical moves: ("rapid"|"feed", x, z) or ("arc", x, z, cx, cz, rotation)
EXPECTED = [
    ("rapid", 0.3, 0.0), ("feed", 0.1, 0.0), ("arc", 0.0, 0.1, 0.1, 0.1, 1),
    ("feed", 0.0, 1.0), ("arc", -0.25, 1.25, -0.25, 1.0, -1), ("arc", -0.5, 1.5, -0.25, 1.5, 1),
    ("feed", -0.5, 1.75), ("rapid", 0.3, 1.75),
    # tool 2, G41
    ("rapid", 0.3, 0.0), ("feed", 0.05, 0.0), ("arc", 0.0, 0.05, 0.05, 0.05, 1),
    ("feed", 0.0, 0.95), ("arc", -0.3, 1.25, -0.3, 0.95, -1), ("arc", -0.5, 1.45, -0.3, 1.45, 1),
    ("feed", -0.5, 1.70), ("rapid", 0.3, 1.75),
    # tool 7, G42
    ("rapid", 0.3, 1.85), ("rapid", -0.3, 1.85), ("feed", -0.4, 1.75),
    ("arc", -0.45, 1.70, -0.40, 1.70, -1), ("feed", -0.45, 1.45),
    ("arc", -0.25, 1.25, -0.25, 1.45, -1), ("arc", 0.05, 0.95, -0.25, 0.95, 1),
    ("feed", 0.05, 0.05), ("arc", 0.1, 0.0, 0.1, 0.05, -1), ("rapid", 0.3, 0.0),
]  # fmt: skip


@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
def test_lathe_comp_through_nose_comp_then_rs274(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))  # rs274's tool table lives under $HOME
    (tmp_path / "test.ngc").write_text(PROGRAM)
    (tmp_path / "test.tbl").write_text(TOOLS)
    out = tmp_path / "resolved.ngc"
    argv = ["gcode", "nose-comp", str(tmp_path / "test.ngc"), "-o", str(out),
            "--tool-table", str(tmp_path / "test.tbl"), "--tool-units", "in", "-q"]  # fmt: skip
    assert main(argv) == 0
    resolved = out.read_text()
    assert "g41" not in resolved and "g42" not in resolved
    res = run_rs274(resolved, tool_table=TOOLS)
    assert res.error is None, res.error
    assert len(res.moves) == len(EXPECTED)
    mm = 25.4
    for k, (got, want) in enumerate(zip(res.moves, EXPECTED, strict=True)):
        kind = "arc" if want[0] == "arc" else want[0]
        assert got.kind == kind, (k, got, want)
        assert abs(got.end[0] / mm - want[1]) <= 2e-4 and abs(got.end[1] / mm - want[2]) <= 2e-4
        if kind == "arc":
            assert abs(got.center[0] / mm - want[3]) <= 2e-4, (k, got, want)
            assert abs(got.center[1] / mm - want[4]) <= 2e-4, (k, got, want)
            assert got.rotation == want[5], (k, got, want)

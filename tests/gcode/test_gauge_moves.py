"""Reading a gauging program's moves (issue 26): the targets are plan.json's and
rs274's, the modal state is the control's, and what the controls refuse is refused
with their words and the line."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.export.machine import plan_json, plan_program
from piecs_bayes.gcode import (
    GaugingOptions,
    dprnt_value,
    gauge_moves,
    gauging_program,
    read_gauge_program,
    rs274_path,
    run_rs274,
)
from piecs_bayes.io import load_study
from piecs_bayes.jobs import plan_study

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo" / "study.toml"
_PROBE = re.compile(r"STRAIGHT_PROBE\(([^)]*)\)")


@pytest.fixture(scope="module")
def study():
    return load_study(DEMO)


def _fine_program(plan, **kw) -> str:
    """The plan's program with 10 decimals (the shipped one has 4)."""
    s, st = plan.settings, plan.study
    args = dict(
        controller=s.controller, units=st.units, x_mode=s.x_mode, tool=st.probe.tool,
        feed_mm_min=st.probe.feed, decimals=10,
    )  # fmt: skip
    args.update(kw)
    return gauging_program(
        plan.home, plan.path, plan.points, options=GaugingOptions(**args), header=["test"]
    )


@pytest.mark.parametrize("controller", ["linuxcnc", "fanuc"])
@pytest.mark.parametrize("x_mode", ["diameter", "radius"])
def test_probe_targets_and_starts_are_plan_json_s(study, controller, x_mode):
    from dataclasses import replace

    plan = plan_study(replace(study, plan={"x_mode": x_mode}), points=4, controller=controller)
    prog = read_gauge_program(_fine_program(plan), x_mode=x_mode)
    assert prog.controller == controller
    probes = prog.probe_moves
    want = json.loads(plan_json(plan))["points"]
    assert len(probes) == len(want) == plan.n_points
    got_t = np.array([m.target for m in probes])
    got_s = np.array([m.start for m in probes])
    np.testing.assert_allclose(got_t, [p["target"] for p in want], rtol=0, atol=1e-9)
    np.testing.assert_allclose(got_s, [p["start"] for p in want], rtol=0, atol=1e-9)
    code = "G31" if controller == "fanuc" else "G38.2"
    assert {m.code for m in probes} == {code} and all(m.recording for m in probes)
    assert all(m.feed == 200.0 and m.units == "mm" for m in probes)
    assert probes[0].label.split()[:2] in (["point", "1"], ["P1", want[0]["feature"]])
    if controller == "fanuc":
        assert all(len(m.dprnt) == 1 for m in probes)
        assert probes[0].dprnt[0].items[1] == ("var", 5061, 4, 4)
    else:
        assert prog.probe_file == "probe_points.txt"


def test_the_shipped_program_s_words_are_read_exactly(study):
    plan = plan_study(study, points=4)
    text = plan_program(plan)
    moves = gauge_moves(text)
    words = [
        (float(m.group(1)) / 2, float(m.group(2)))
        for m in re.finditer(r"G38\.2 X(\S+) Z(\S+)", text)
    ]
    np.testing.assert_allclose([m.target for m in moves if m.kind == "probe"], words, atol=1e-12)
    # the rounding of the 4-decimal diameters: plan.json's targets to half a digit
    want = [p["target"] for p in json.loads(plan_json(plan))["points"]]
    np.testing.assert_allclose(words, want, rtol=0, atol=0.5e-4 + 1e-9)


@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("x_mode", ["diameter", "radius"])
def test_targets_are_rs274_s_straight_probe_targets(study, x_mode):
    from dataclasses import replace

    plan = plan_study(replace(study, plan={"x_mode": x_mode}), points=4)
    text = plan_program(plan)
    res = run_rs274(text, tool_table="T9 P9 Z0 D0 ;touch probe\n")
    assert res.error is None, res.error
    got = np.array([[float(v) for v in m.group(1).split(",")] for m in _PROBE.finditer(res.output)])
    mine = np.array([m.target for m in gauge_moves(text) if m.kind == "probe"])
    assert got.shape == (len(mine), 6)
    # rs274 prints 4 decimals, X a radius (a halved 4-decimal diameter has 5)
    np.testing.assert_allclose(got[:, [0, 2]], mine, rtol=0, atol=0.5e-4 + 1e-9)


def test_the_modal_state_is_the_control_s():
    text = "\n".join([
        "G18 G8 G21 G90 G94",
        "G0 X10 Z5",
        "G7 (diameters from here)",
        "G0 X30",
        "G20 G91 G0 Z-1 (an inch, incremental)",
        "G90 G21 G38.2 X20 Z0 F100",
        "X18 (G38.2 is modal: probes again)",
        "G20 G38.3 X1 F4",
        "G8 G1 X0.5 Z0.1",
        "M30",
    ]) + "\n"  # fmt: skip
    moves = gauge_moves(text)
    assert [m.kind for m in moves] == ["rapid", "rapid", "rapid", "probe", "probe", "probe", "feed"]
    assert [m.target for m in moves[:3]] == [(10.0, 5.0), (15.0, 5.0), (15.0, 5.0 - 25.4)]
    p1, p2, p3 = moves[3:6]
    assert p1.start == (15.0, 5.0 - 25.4) and p1.target == (10.0, 0.0) and p1.feed == 100.0
    assert p2.code == "G38.2" and p2.target == (9.0, 0.0) and p2.line == 7
    assert p3.code == "G38.3" and p3.target == pytest.approx((12.7, 0.0), abs=1e-12)
    assert p3.units == "in" and p3.x_mode == "diameter" and p3.feed == pytest.approx(101.6)
    assert moves[-1].target == pytest.approx((12.7, 2.54)) and moves[-1].x_mode == "radius"
    assert moves[1].distance == "absolute" and moves[2].distance == "incremental"


LINUXCNC_REFUSALS = [
    ("g95", "G95 G38.2 X20 F0.1", "Cannot probe with feed per rev mode"),
    ("comp", "G41 G38.2 X20 F100", "Cannot probe with cutter radius compensation on"),
    ("comp_1", "G42.1 D0.8 L3 G38.2 X20 F100", "Cannot probe with cutter radius compensation on"),
    ("zero_feed", "G38.2 X20", "Cannot probe with zero feed rate"),
    ("zero_length", "G38.2 X30 Z2 F100", "Start point too close to probe point"),
    ("short", "G38.2 X30.2 Z2 F100", "Start point too close to probe point"),
    ("word", "G38.2 X20 E3 F100", "Unknown word starting with E"),
    ("y", "G38.2 X20 Y3 F100", "Unknown word starting with Y"),
    ("gcode", "G28 X20", "Unknown g code used: G28"),
    ("g31", "G31 X20 F100", "Unknown g code used: G31"),
    ("mcode", "M98 P1000", "Unknown m code used: M98"),
    ("group", "G0 G38.2 X20 F100", "Two g codes used from same modal group"),
    ("no_motion", "G80 X20", "Cannot use axis values without a g code that uses them"),
]  # fmt: skip


@pytest.mark.parametrize("case", LINUXCNC_REFUSALS, ids=[c[0] for c in LINUXCNC_REFUSALS])
def test_linuxcnc_refusals_name_the_line(tmp_path, case):
    name, block, expect = case
    prog = tmp_path / "g.ngc"
    prog.write_text(f"G18 G7 G21 G90 G94\nG0 X30 Z2\n{block}\nM30\n")
    with pytest.raises(InputError) as err:
        gauge_moves(prog, controller="linuxcnc")
    msg = str(err.value)
    assert msg.startswith(f"{prog}:3: ") and expect in msg, msg


@pytest.mark.parametrize(
    "block, expect",
    [
        ("G99 G31 X20. F0.1", "G31 in feed per revolution (G99)"),
        ("G41 G31 X20. F100.", "PS0035 CAN NOT COMMANDED G31"),
        ("G31 X30. Z2. F100.", "G31 block without motion"),
        ("G31 X20. ", "PS0011 FEED ZERO"),
        ("G31 X20 F100.", "an address without a decimal point"),
        ("G7 G31 X20. F100.", "PS0010 IMPROPER G-CODE"),
    ],
)
def test_fanuc_refusals_name_the_line(tmp_path, block, expect):
    prog = tmp_path / "g.nc"
    prog.write_text(f"O9001\nG18 G21 G90 G98\nG0 X30. Z2.\n{block}\nM30\n")
    with pytest.raises(InputError) as err:
        gauge_moves(prog)
    assert str(err.value).startswith(f"{prog}:4: ") and expect in str(err.value), str(err.value)


def test_fanuc_x_mode_and_dprnt_placement():
    text = "O9001\nG18 G21 G90 G98\nG0 X30. Z2.\nPOPEN\nG31 X20. F100.\nDPRNT[X#5061[44]*Z#5062[44]]\nPCLOS\nM30\n"  # fmt: skip
    assert gauge_moves(text)[1].target == (10.0, 2.0)  # default: diameter
    assert gauge_moves(text, x_mode="radius")[1].target == (20.0, 2.0)
    with pytest.raises(InputError, match="DPRNT outside POPEN"):
        gauge_moves(text.replace("POPEN\n", ""))
    with pytest.raises(InputError, match="DPRNT before any G31"):
        gauge_moves(text.replace("G31 X20. F100.\n", ""))
    with pytest.raises(InputError, match="only the skip positions"):
        gauge_moves(text.replace("#5062", "#100"))


def test_dprnt_values():
    assert dprnt_value(12.5, 4, 4) == "   12.5000"
    assert dprnt_value(-31.07, 4, 4) == "  -31.0700"
    assert dprnt_value(0.25, 4, 4) == "    0.2500"
    assert dprnt_value(-0.00001, 4, 4) == "    0.0000"  # rounds to zero: no sign
    assert dprnt_value(1.234567, 3, 5) == "   1.23457"
    assert dprnt_value(-9999.99994, 4, 4) == "-9999.9999"
    with pytest.raises(InputError, match="more than 4 integer digits"):
        dprnt_value(10000.0, 4, 4)


def test_gauging_options_defaults_and_refusal():
    """`GaugingOptions` holds what `gauging_program` took as keywords, with the same
    defaults; an unknown controller is refused."""
    o = GaugingOptions(controller="fanuc", units="mm", x_mode="radius", tool=9, feed_mm_min=200.0)
    assert (o.probe_file, o.log_file, o.probe_on, o.probe_off, o.program_number, o.decimals) == (
        "probe_points.txt", "probe_log.txt", None, None, 9001, None
    )  # fmt: skip
    with pytest.raises(InputError, match=r"controller: got 'haas', expected one of \('linuxcnc'"):
        GaugingOptions(controller="haas", units="mm", x_mode="radius", tool=9, feed_mm_min=200.0)

"""The type-1 study run by the machine (issue 40): `gauge-study program` writes the
program that touches the reference `repeats` times and its plan; the control's probe
file, read back against the plan, gives the readings (the contact c + r a: twice its X
on a bore or shaft, its Z on a face), and `gauge-study type1` studies them. The
program's probe targets are checked against LinuxCNC's rs274 where it is installed."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import rs274_path, run_rs274
from piecs_bayes.jobs import gauge_type1_program, gauge_type1_study

HEAD = """[gauge]
name = "T9 on ring 40"
tolerance = 0.025
resolution = 0.0001

[type1]
reference = 40.0012
expanded_uncertainty = 0.0006
coverage_factor = 2
{readings}

[type1.program]
surface = "{surface}"
at = {at}
repeats = 30
ball_diameter = 2.0
tool = 9
{extra}
"""


def _file(tmp_path, surface="bore", at=-5.0, readings="", extra=""):
    p = tmp_path / "gauge.toml"
    p.write_text(HEAD.format(surface=surface, at=at, readings=readings, extra=extra))
    return p


def _linuxcnc_file(path, centres):
    """A PROBEOPEN file: X Y Z A B C U V W per touch (X a radius)."""
    path.write_text("".join(f"{x:.6f} 0.000000 {z:.6f} 0 0 0 0 0 0\n" for x, z in centres))


@pytest.mark.parametrize(
    "surface, at, axis, want",
    [("bore", -5.0, 0, lambda c: 2 * (c + 1.0)), ("shaft", -5.0, 0, lambda c: 2 * (c - 1.0)),
     ("face", 15.0, 1, lambda c: c - 1.0)],
)  # fmt: skip
def test_the_program_touches_the_reference_and_its_file_reads_back(tmp_path, surface, at, axis,
                                                                    want):  # fmt: skip
    """30 touches, each a probe move towards the surface from 1 mm before it; the
    plan's ball centres at contact by hand (ring Ø40.0012, ball Ø2: bore X 19.0006, shaft
    X 21.0006; face at Z 40.0012 touched from +Z: Z 41.0012). A simulated control file
    (centres shifted by a known bias and noise) reads back as the readings by hand:
    2 (x + 1) on a bore, 2 (x - 1) on a shaft, z - 1 on a face."""
    study, files = gauge_type1_program(_file(tmp_path, surface, at))
    plan = json.loads(files["type1_plan.json"])
    prog = files["type1_gauging.ngc"]
    assert len(plan["points"]) == 30 and prog.count("G38.2") == 30
    assert prog.count("(LOG,") == 30 and "(PROBEOPEN probe_points.txt)" in prog
    c0 = {"bore": [19.0006, -5.0], "shaft": [21.0006, -5.0], "face": [15.0, 41.0012]}[surface]
    for p in plan["points"]:
        np.testing.assert_allclose(p["centre"], c0, atol=1e-9)
    a = np.array(plan["points"][0]["approach"])
    np.testing.assert_allclose(np.array(plan["points"][0]["target"]) - c0, 0.5 * a, atol=1e-9)
    rng = np.random.default_rng(4)
    centres = np.tile(c0, (30, 1))
    centres[:, axis] += 0.0002 * a[axis] + 0.0003 * rng.standard_normal(30)
    (tmp_path / "type1_plan.json").write_text(files["type1_plan.json"])
    _linuxcnc_file(tmp_path / "probe_points.txt", centres)
    path = _file(tmp_path, surface, at, readings='probe_file = "probe_points.txt"')
    res = gauge_type1_study(path)
    np.testing.assert_allclose(res.type1.readings, want(centres[:, axis]), atol=2e-6)
    assert res.type1.n == 30 and res.study.type1.file.endswith("probe_points.txt")


def test_bad_program_tables_and_files_are_refused(tmp_path):
    """Fewer than 25 touches, an unknown surface, a missing key, readings and a probe
    file both, a probe file with a touch missing: each names the file and the value."""
    with pytest.raises(InputError, match="surface: expected one of bore, shaft, face"):
        gauge_type1_program(_file(tmp_path, surface="sphere"))
    p = tmp_path / "gauge.toml"
    p.write_text(HEAD.format(surface="bore", at=-5, readings="", extra="").replace(
        "repeats = 30", "repeats = 10"))  # fmt: skip
    with pytest.raises(InputError, match="repeats: expected at least 25") as e:
        gauge_type1_program(p)
    assert e.value.file == str(p)
    p.write_text(HEAD.format(surface="bore", at=-5, readings="", extra="").replace(
        "ball_diameter = 2.0\n", ""))  # fmt: skip
    with pytest.raises(InputError, match="ball_diameter is missing"):
        gauge_type1_program(p)
    _, files = gauge_type1_program(_file(tmp_path))
    (tmp_path / "type1_plan.json").write_text(files["type1_plan.json"])
    _linuxcnc_file(tmp_path / "probe_points.txt", [(19.0006, -5.0)] * 29)
    both = 'probe_file = "probe_points.txt"\nreadings = "ring.csv"'
    with pytest.raises(InputError, match="both readings and probe_file"):
        gauge_type1_study(_file(tmp_path, readings=both))
    with pytest.raises(InputError, match="29 probe points in the file") as e:
        gauge_type1_study(_file(tmp_path, readings='probe_file = "probe_points.txt"'))
    assert e.value.file.endswith("probe_points.txt")


def test_the_cli_writes_the_program_and_never_an_input(tmp_path, capsys):
    from piecs_bayes.cli import main

    path = _file(tmp_path, extra='controller = "fanuc"')
    rc = main(["gauge-study", "program", str(path), "--out", str(tmp_path / "out")])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "30 touches of the bore" in text
    prog = (tmp_path / "out" / "type1_gauging_fanuc.nc").read_text()
    assert prog.count("G31 ") == 30 and prog.count("DPRNT[") == 30
    assert json.loads((tmp_path / "out" / "type1_plan.json").read_text())["controller"] == "fanuc"
    rc = main(["gauge-study", "program", str(tmp_path / "nothing.toml")])
    assert rc == 2


@pytest.mark.rs274
@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("surface, at", [("bore", -5.0), ("face", 15.0)])
def test_the_program_runs_in_rs274_to_the_planned_targets(tmp_path, surface, at):
    """rs274 interprets the program to its end; its STRAIGHT_PROBE targets are the
    plan's, in order, to its printed 4 decimals (X a radius)."""
    _, files = gauge_type1_program(_file(tmp_path, surface, at))
    res = run_rs274(files["type1_gauging.ngc"], tool_table="T9 P9 Z0 D0 ;probe\n")
    assert res.error is None, res.error
    got = np.array(
        [[float(v) for v in m.group(1).split(",")]
         for m in re.finditer(r"STRAIGHT_PROBE\(([^)]*)\)", res.output)]
    )  # fmt: skip
    want = np.array([p["target"] for p in json.loads(files["type1_plan.json"])["points"]])
    assert got.shape == (30, 6)
    np.testing.assert_allclose(got[:, 0], want[:, 0], atol=1e-4 + 1e-9)
    np.testing.assert_allclose(got[:, 2], want[:, 1], atol=1e-4 + 1e-9)

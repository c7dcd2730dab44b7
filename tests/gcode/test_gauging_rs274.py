"""The gauging programs run through LinuxCNC's ``rs274`` (issue 25).

For the demo and for every corpus program whose finish contour makes a study
(``init``), the plan's LinuxCNC program runs to its end without an error and its
``STRAIGHT_PROBE`` targets are plan.json's, in order, to 1e-4 (rs274 prints 4
decimals in the program's units, X a radius). A corpus part the ball (0.25 mm here)
cannot gauge must be refused naming a feature.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import gauge_ready

from piecs_bayes.errors import InputError
from piecs_bayes.export.machine import plan_json, plan_program
from piecs_bayes.gcode import rs274_path, run_rs274
from piecs_bayes.io import load_study
from piecs_bayes.jobs import plan_study, study_from_program

ROOT = Path(__file__).resolve().parents[2]
CORPUS = sorted((ROOT / "tests" / "data" / "gcode").glob("*.ngc")) + sorted(
    (ROOT / "tests" / "data" / "gcode" / "adjust").glob("*.ngc")
)
TOOLS = "T9 P9 Z0 D0 ;touch probe\n"
_PROBE = re.compile(r"STRAIGHT_PROBE\(([^)]*)\)")

pytestmark = [
    pytest.mark.rs274,
    pytest.mark.skipif(
        rs274_path() is None,
        reason="LinuxCNC's rs274 is not installed (make conformance installs linuxcnc-uspace)",
    ),
]


def _check(plan):
    res = run_rs274(plan_program(plan), tool_table=TOOLS)
    assert res.error is None, res.error
    got = np.array([[float(v) for v in m.group(1).split(",")] for m in _PROBE.finditer(res.output)])
    want = np.array([p["target"] for p in json.loads(plan_json(plan))["points"]])
    assert got.shape == (len(want), 6)
    np.testing.assert_allclose(got[:, 0], want[:, 0], rtol=0, atol=1e-4 + 1e-9)  # X radius
    np.testing.assert_allclose(got[:, 2], want[:, 1], rtol=0, atol=1e-4 + 1e-9)  # Z
    return len(want)


@pytest.mark.parametrize("kw", [{}, {"points": 5}], ids=["ratio", "points5"])
def test_the_demo_gauging_program_runs_in_rs274(kw):
    study = load_study(ROOT / "data" / "demo" / "study.toml")
    assert _check(plan_study(study, **kw)) > 0


def test_radius_mode_gives_the_same_probe_targets():
    study = load_study(ROOT / "data" / "demo" / "study.toml")
    from dataclasses import replace

    plan = plan_study(replace(study, plan={"x_mode": "radius"}), points=4)
    assert "G8" in plan_program(plan).splitlines()[4]
    _check(plan)


def _corpus_study(program: Path, tmp_path: Path):
    try:
        res = study_from_program(program, study_path=tmp_path / "study.toml", ball_radius_mm=0.25)
    except InputError:
        return None  # not a single finish contour (tested with init)
    text = gauge_ready(res.text, small=True)
    (tmp_path / "study.toml").write_text(text)
    return load_study(tmp_path / "study.toml")


@pytest.mark.parametrize("program", CORPUS, ids=[p.name for p in CORPUS])
def test_corpus_gauging_programs_run_in_rs274(program, tmp_path):
    study = _corpus_study(program, tmp_path)
    if study is None:
        pytest.skip("init refuses this program (several runs, rapids in the contour...)")
    try:
        plan = plan_study(study, points=3)
    except InputError as exc:  # the ball cannot gauge this part: the refusal names it
        assert exc.feature in study.profile.ids, str(exc)
        return
    assert _check(plan) == plan.n_points

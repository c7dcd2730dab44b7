"""The loop on the machine, end to end (issue 26): the study from the finish program
(`init`), the probe plan and gauging program (`plan`), the simulated machine running
it on the truth part (`simulate gauge`), the control's probe file read against the
plan, then fit, decide and compensate.

Asserted on the demo shaft (LinuxCNC and Fanuc dialects) and on a bore: every
characteristic within 3 u of the truth's; the adjusted path's vertices within 3 u
(their linearised standard uncertainty, with 1 um of slack for the 4-decimal program
words) of the path that would remove the truth's deviations exactly; the adjusted
program runs through rs274 where it is installed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import gauge_ready, lobing_probe

from piecs_bayes.export.machine import plan_json, plan_program
from piecs_bayes.gcode import rs274_path, run_rs274
from piecs_bayes.io import load_study
from piecs_bayes.jobs import (
    adjust_study_program,
    characteristics,
    compensate_study,
    fit_study,
    plan_study,
    study_from_program,
    toolpath_uncertainty,
)
from piecs_bayes.simulate import simulate_gauge
from piecs_bayes.uncertainty import normal_deviation

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo"
GCODE = ROOT / "tests" / "data" / "gcode"


def _study_text(program: Path, tmp: Path, *, ball: float, nose=None) -> str:
    res = study_from_program(program, study_path=tmp / "study.toml", ball_radius_mm=ball,
                             nose=nose)  # fmt: skip
    return gauge_ready(res.text, small=ball < 1.0)


def _loop(tmp: Path, program: Path, truth_by_order, *, controller="linuxcnc", ball=1.0,
          points=None, pretravel=None, probe_keys="", nose=None):  # fmt: skip
    """init -> plan -> simulate gauge -> read -> fit: the study, the fit and the truth
    (`pretravel`: the simulated probe's; `probe_keys`: more `[probe]` lines to read
    the probe file with)."""
    text = _study_text(program, tmp, ball=ball, nose=nose)
    (tmp / "study.toml").write_text(text)
    study = load_study(tmp / "study.toml")
    truth = dict(zip(study.profile.ids, truth_by_order(study), strict=True))
    plan = plan_study(study, points=points, controller="fanuc" if controller == "fanuc" else None)
    (tmp / "plan").mkdir()
    (tmp / "plan" / "plan.json").write_text(plan_json(plan))
    prog = tmp / "plan" / ("gauging_fanuc.nc" if controller == "fanuc" else "gauging.ngc")
    prog.write_text(plan_program(plan))
    run = simulate_gauge(
        prog, study, truth, repeatability=study.probe.repeatability, seed=11,
        x_mode_fanuc=study.probe.x_mode if controller == "fanuc" else None, pretravel=pretravel,
    )  # fmt: skip
    run.write(tmp / "probe_points.txt")
    fmt, name = ("fanuc-dprnt", "probe_points.txt") if controller == "fanuc" else (
        ("linuxcnc", "probe_points.txt") if controller == "linuxcnc" else
        ("linuxcnc-log", "probe_log.txt"))  # fmt: skip
    if controller == "linuxcnc-log":
        run.write_log(tmp / "probe_log.txt")
    text = text.replace(
        "probe_files = []",
        f'probe_files = ["{name}"]\nprobe_format = "{fmt}"\nprobe_plan = "plan/plan.json"',
    ).replace("[probe]\n", f"[probe]\n{probe_keys}", 1)
    (tmp / "study.toml").write_text(text)
    study = load_study(tmp / "study.toml")
    return study, fit_study(study), truth


def _demo_truth(study):
    """data/demo/truth.json's deviations, feature by feature in profile order (init's
    ids are face_z0, dia_24, taper_1, ...; the demo study's face_end, dia_24, taper)."""
    demo = load_study(DEMO / "study.toml")
    body = json.loads((DEMO / "truth.json").read_text())["deviations"]
    return [np.array([body[f.id][p] for p in f.param_names]) for f in demo.profile.features]


def _check(study, fit, truth, tmp):
    chars = characteristics(study, fit, at="worst")
    for f in study.profile.features:
        if f.id in fit.unmeasured:  # the plan could not reach it: corrected by nothing
            continue
        c = chars[f.id]
        true = float(normal_deviation(f, truth[f.id], c.t))
        assert abs(c.mean - true) <= 3 * c.sd, (f.id, c.mean, true, c.sd)
    path = compensate_study(study, fit)
    ideal = compensate_study(study, _with_deviations(fit, truth))
    u = toolpath_uncertainty(study, fit)["linearised"]
    sd = np.sqrt(np.einsum("vii->vi", u.vertex_cov))
    assert np.all(np.abs(path.vertices - ideal.vertices) <= 3 * sd + 1e-9), (
        path.vertices - ideal.vertices,
        sd,
    )
    adj = adjust_study_program(study, path)
    (tmp / "finish_adjusted.ngc").write_text(adj.text)
    if rs274_path() is not None and _dialect(study) == "linuxcnc":
        _rs274_runs(adj.text)
    return chars


def _rs274_runs(text: str) -> None:
    """rs274 runs the adjusted program. A G70 under G41.1/G42.1 is run with its
    compensation resolved (`nose_compensate`): the rs274 Debian ships (2.9.0~pre1)
    compensates a G70's first moves wrongly (tests/gcode/test_linuxcnc_corpus.py); its
    moves must then be our compensated path's, cycles included, to 1e-4 mm."""
    from piecs_bayes.gcode import nose_compensate, parse_gcode

    tools = GCODE / "tools.tbl"
    tools = tools.read_text() + "T202 P202 D0.0315 ;R0.4 finish tool (inches)\n"
    program = parse_gcode(text)
    if not any(m.via == "G70" and m.comp is not None for m in program.moves):
        res = run_rs274(text, tool_table=tools)
        assert res.error is None, res.error
        return
    resolved = nose_compensate(program)
    res = run_rs274(resolved.text, tool_table=tools)
    assert res.error is None, res.error
    assert len(res.moves) == len(resolved.path)
    for a, b in zip(res.moves, resolved.path, strict=True):
        assert max(abs(u - v) for u, v in zip(a.end, b.end, strict=True)) <= 1e-4 + 1e-9


def _dialect(study) -> str:
    from piecs_bayes.gcode import read_gcode

    return read_gcode(study.program).dialect.name


def _with_deviations(fit, truth):
    """The fit with its deviations replaced by the truth's (the perfect correction)."""
    from dataclasses import replace

    fits = {fid: replace(f, values=np.asarray(truth[fid], float)) for fid, f in fit.fits.items()}
    return replace(fit, fits=fits)


@pytest.mark.parametrize("controller", ["linuxcnc", "linuxcnc-log", "fanuc"])
def test_the_demo_loop(tmp_path, controller):
    study, fit, truth = _loop(tmp_path, DEMO / "finish.ngc", _demo_truth, controller=controller)
    chars = _check(study, fit, truth, tmp_path)
    assert set(chars) == set(study.profile.ids)


@pytest.mark.parametrize("calibrated", [False, True], ids=["one_radius", "calibrated"])
def test_the_loop_with_a_lobing_probe(tmp_path, calibrated):
    """The simulated machine's probe lobes (tests/jobs/test_probe_calibration_use.py:
    r0 4 um above the 1 mm ball, 0.6 um and 1.5 um lobes of orders 2 and 3; `simulate
    gauge --pretravel PROBE_CAL`). Read with one radius, some characteristic is off by
    more than 3 u; with `[probe] calibration` every one is within 3 u and the adjusted
    path's vertices within 3 u of the perfect correction's."""
    from piecs_bayes.jobs import lobing_pretravel

    lobing = lobing_probe()
    (tmp_path / "probe_cal.json").write_text(lobing.to_json_text())
    keys = 'calibration = "probe_cal.json"\n' if calibrated else ""
    study, fit, truth = _loop(tmp_path, DEMO / "finish.ngc", _demo_truth,
                              pretravel=lobing_pretravel(lobing, 1.0), probe_keys=keys)  # fmt: skip
    if calibrated:
        assert study.probe.calibration is not None
        _check(study, fit, truth, tmp_path)
        return
    chars = characteristics(study, fit, at="worst")
    off = {f.id: abs(chars[f.id].mean - float(normal_deviation(f, truth[f.id], chars[f.id].t)))
           / chars[f.id].sd for f in study.profile.features}  # fmt: skip
    assert max(off.values()) > 3.0, off


def test_the_loop_on_a_bore(tmp_path):
    """Corpus program 04 (a bore with fillets), a 0.25 mm ball; a truth of a few um per
    feature: every line shifted outward by 6 um and turned by 50 urad, every arc's
    radius grown by 4 um."""

    def truth(study):
        return [np.array([0.006, 5e-5]) if f.kind == "line" else np.array([0.0, 0.0, 0.004])
                for f in study.profile.features]  # fmt: skip

    study, fit, tr = _loop(tmp_path, GCODE / "04_bore_mm_t4_g41.ngc", truth, ball=0.25,
                           points=6)  # fmt: skip
    assert any(f.id.startswith("bore_") for f in study.profile.features)
    _check(study, fit, tr, tmp_path)


def test_the_shipped_gauge_data(tmp_path):
    """data/demo/gauge: the demo study reading the PROBEOPEN file that the simulated
    machine wrote for the shipped plan's LinuxCNC program on the truth part. Its
    characteristics lie within 3 u of the truth's; the main job runs on it unchanged and
    lists the plan and the gauging program among its inputs."""
    from piecs_bayes.gcode import gauge_moves
    from piecs_bayes.io import read_plan_points
    from piecs_bayes.jobs import JobOptions, run_job

    gauge = DEMO / "gauge"
    study = load_study(gauge / "study.toml")
    assert study.probe_format == "linuxcnc" and study.probe_plan == gauge / "plan.json"
    body = json.loads((DEMO / "truth.json").read_text())["deviations"]
    truth = {f.id: np.array([body[f.id][p] for p in f.param_names]) for f in study.profile}
    fit = fit_study(study)
    chars = characteristics(study, fit, at="worst")
    for f in study.profile.features:
        true = float(normal_deviation(f, truth[f.id], chars[f.id].t))
        assert abs(chars[f.id].mean - true) <= 3 * chars[f.id].sd, f.id
    # the program's probe targets are the plan's (to its 4 printed decimals)
    plan = read_plan_points(study.probe_plan)
    moves = [m for m in gauge_moves(gauge / "gauging.ngc") if m.kind == "probe"]
    np.testing.assert_allclose([m.target for m in moves], plan.target, rtol=0, atol=1e-4)
    res = run_job(study, JobOptions(bayes=False))
    roles = {i.role: i.path.name for i in res.inputs}
    assert roles["probe plan"] == "plan.json" and roles["gauging program"] == "gauging.ngc"


# --------------------------------------------------------------------------- issue 38
DIALECTS = GCODE / "dialects"
NC = Path("/usr/share/linuxcnc/ncfiles")


def _small_truth(study):
    """A few um per feature: lines shifted 5 um outward and turned 40 urad, arcs grown 3 um."""
    return [np.array([0.005, 4e-5]) if f.kind == "line" else np.array([0.0, 0.0, 0.003])
            for f in study.profile.features]  # fmt: skip


@pytest.mark.parametrize(
    "program, truth, controller",
    [
        pytest.param(DIALECTS / "haas_demo_shaft.nc", _demo_truth, "fanuc", id="haas-g71-g70"),
        pytest.param(GCODE / "g70" / "demo_shaft_g70.ngc", _demo_truth, "linuxcnc", id="linuxcnc-g70"),
        pytest.param(NC / "lathe_g70_71_demo.ngc", _small_truth, "linuxcnc", id="linuxcnc-shipped-g70"),
    ],
)  # fmt: skip
def test_the_loop_on_canned_cycle_programs(tmp_path, program, truth, controller):
    if not program.is_file():
        pytest.skip(f"{program} is not installed (linuxcnc-uspace)")
    small = program.name == "lathe_g70_71_demo.ngc"  # a pawn: features of a few mm
    study, fit, tr = _loop(tmp_path, program, truth, controller=controller,
                           ball=0.25 if small else 1.0, points=6 if small else None)  # fmt: skip
    # the pawn's shortest features (a 0.46 mm diameter, a 0.5 mm face, a 0.42 mm arc)
    # cannot hold a fit's points at the plan's 0.1 mm spacing: planned without them, not
    # measured, the loop closes on the rest
    assert set(fit.unmeasured) == ({"dia_4", "face_z8p732", "arc_6"} if small else set())
    _check(study, fit, tr, tmp_path)


def test_the_loop_on_a_tool_path_without_compensation(tmp_path):
    """A CAM-style program: the demo's path of the imaginary tip (orientation 2, nose
    0.4 mm) written out without G41/G42 (our nose_compensate on data/demo/finish.ngc);
    `init --nose-radius 0.4 --tip 2` takes the contour back and the adjusted program moves
    the path, which rs274 runs."""
    from piecs_bayes.gcode import nose_compensate, parse_gcode
    from piecs_bayes.jobs import ToolNose

    text = (DEMO / "finish.ngc").read_text().replace("G42 G1", "G42.1 D0.8 L2 G1")
    cam = tmp_path / "cam.ngc"
    cam.write_text(nose_compensate(parse_gcode(text, name="finish.ngc")).text)
    (tmp_path / "loop").mkdir()
    study, fit, tr = _loop(tmp_path / "loop", cam, _demo_truth, nose=ToolNose(radius=0.4, tip=2))
    assert study.program_settings.path_tip == 2
    _check(study, fit, tr, tmp_path / "loop")

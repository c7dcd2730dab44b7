"""The simulated machine (issue 26): the ball's first contact with the truth part
agrees with an independent closed form to 1e-9 mm on lines and arcs (convex and
concave), outside (the demo shaft, a part with convex and concave arcs) and inside
(a bore); the files are what the controls write."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.export.machine import plan_program
from piecs_bayes.gcode import GaugingOptions, gauging_program
from piecs_bayes.io import load_study
from piecs_bayes.jobs import plan_study, study_from_program
from piecs_bayes.simulate import read_truth, simulate_gauge
from piecs_bayes.simulate._contact import contact_direction, truth_pieces

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo" / "study.toml"
TRUTH = ROOT / "data" / "demo" / "truth.json"
GCODE = ROOT / "tests" / "data" / "gcode"


def _corpus_study(text: str, tmp: Path):
    (tmp / "part.ngc").write_text(text)
    res = study_from_program(tmp / "part.ngc", study_path=tmp / "study.toml", ball_radius_mm=0.25)
    study = res.text.replace("# tool = 9 ", "tool = 9   ").replace("# feed = ", "feed = ")
    study += "\n[plan]\nclearance = 0.3\nend_clearance = 0.05\n"
    (tmp / "study.toml").write_text(study.replace("[program]\n", "[program]\nstock = 0.1\n"))
    return load_study(tmp / "study.toml")


def _bore_text() -> str:
    """Corpus bore 04 with a face and a convex round at its mouth (and its concave R1)."""
    t = (GCODE / "04_bore_mm_t4_g41.ngc").read_text()
    old = "G1 X24.000 Z0.000\nG1 X20.000 Z-2.000\n"
    assert old in t
    return t.replace(old, "G1 X28.000 Z0.000\nG1 X24.000 Z0.000\nG2 X20.000 Z-2.000 R2.000\n")


def _truth(profile) -> dict:
    """Deviations of every feature, of both signs, well inside the overtravel."""
    out = {}
    for k, f in enumerate(profile.features):
        sign = 1.0 if k % 2 == 0 else -1.0
        if f.kind == "line":
            out[f.id] = {"offset": 0.021 * sign, "rotation": 3e-4 * sign}
        else:
            out[f.id] = {"center_x": 0.011 * sign, "center_z": -0.007, "radius": 0.006 * sign}
    return out


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    demo = load_study(DEMO)
    arcs = _corpus_study((GCODE / "06_od_arcs_mm_t6_g42.ngc").read_text(),
                         tmp_path_factory.mktemp("arcs"))  # fmt: skip
    bore = _corpus_study(_bore_text(), tmp_path_factory.mktemp("bore"))
    return {"demo": (demo, TRUTH), "od_arcs": (arcs, _truth(arcs.profile)),
            "bore": (bore, _truth(bore.profile))}  # fmt: skip


def _rot(v, th):
    """Rotate (x, z) by th CCW in the drawing frame (z right, x up)."""
    z, x = v[1], v[0]
    return np.array([z * math.sin(th) + x * math.cos(th), z * math.cos(th) - x * math.sin(th)])


def _independent(f, dev, a, b, r) -> np.ndarray:
    """The ball centre on a -> b at distance r from the deviated feature (closed form)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    u = b - a
    if f.kind == "line":
        p0, p1 = np.asarray(f.p0, float), np.asarray(f.p1, float)
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        n0 = f.side * np.array([d[1], -d[0]])  # outward: left of travel is (dz, -dx)
        m = 0.5 * (p0 + p1) + dev[0] * n0
        n = _rot(n0, dev[1])
        s = (r - (a - m) @ n) / (u @ n)
        return a + s * u
    c = np.asarray(f.center, float) + dev[:2]
    big = f.radius + dev[2]
    rho = big + r if f.convex else big - r
    qa, qb, qc = u @ u, 2 * u @ (a - c), (a - c) @ (a - c) - rho * rho
    roots = sorted([(-qb - math.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa),
                    (-qb + math.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)])  # fmt: skip
    s = roots[0] if f.convex else roots[1]  # from outside the circle / from inside it
    return a + s * u


def _probe_lines(text: str) -> np.ndarray:
    rows = [[float(v) for v in line.split()] for line in text.splitlines()]
    return np.array(rows).reshape(-1, 9)


@pytest.mark.parametrize("name", ["demo", "od_arcs", "bore"])
def test_contact_agrees_with_the_closed_form(cases, name):
    study, truth = cases[name]
    plan = plan_study(study, points=3)
    run = simulate_gauge(plan_program(plan), study, truth, repeatability=0.0, seed=0)
    devs = read_truth(truth, study.profile)
    r = study.probe.ball_radius
    kinds = set()
    assert len(run.trips) == plan.n_points
    for trip, pt in zip(run.trips, plan.points, strict=True):
        f = study.profile[pt.feature]
        assert trip.touched and trip.feature == pt.feature, (trip, pt)
        want = _independent(f, devs[f.id], trip.move.start, trip.move.target, r)
        np.testing.assert_allclose(trip.contact, want, rtol=0, atol=1e-9)
        assert trip.centre == trip.contact  # no repeatability, no pretravel
        kinds.add("line" if f.kind == "line" else ("convex" if f.convex else "concave"))
    expected = {"demo": {"line", "concave"}}.get(name, {"line", "convex", "concave"})
    assert kinds == expected
    # the file: LinuxCNC's %f, 6 decimals, X a radius, Y A B C U V W zero
    rows = _probe_lines(run.text)
    assert rows.shape == (plan.n_points, 9)
    np.testing.assert_allclose(rows[:, [0, 2]], run.centres, rtol=0, atol=5e-7 + 1e-12)
    assert not rows[:, [1, 3, 4, 5, 6, 7, 8]].any()
    assert re.fullmatch(r"(-?\d+\.\d{6} ){8}-?\d+\.\d{6}\n", run.text.splitlines(True)[0])


def test_the_demo_truth_shifts_the_centres_by_the_deviation(cases):
    study, truth = cases["demo"]
    plan = plan_study(study, points=4)
    run = simulate_gauge(plan_program(plan), study, truth, repeatability=0.0, seed=0)
    dia24 = [t for t in run.trips if t.feature == "dia_24"]
    devs = read_truth(truth, study.profile)["dia_24"]
    for t in dia24:  # a diameter: x = 12 + 1 + offset + rotation about the mid-point
        want = 13.0 + devs[0] + (t.centre[1] + 15.0) * math.tan(devs[1]) / 1.0
        assert t.centre[0] == pytest.approx(want, abs=1e-8)


def test_repeatability_along_the_move_and_pretravel_at_the_contact_normal(cases):
    """The trip: the contact plus the repeatability's draw and the pretravel along the
    move; a lobing pretravel is a function of the contact normal's angle (the touched
    surface's, here up to a few mrad from the move's on the deviated part)."""
    study, truth = cases["demo"]
    text = plan_program(plan_study(study, points=3))
    exact = simulate_gauge(text, study, truth, repeatability=0.0, seed=0)
    run = simulate_gauge(text, study, truth, repeatability=0.002, seed=11)
    again = simulate_gauge(text, study, truth, repeatability=0.002, seed=11)
    assert run.text == again.text and run.text != exact.text
    draws = np.random.default_rng(11).normal(0.0, 1.0, len(run.trips)) * 0.002
    lobes = lambda ang: 0.003 * math.cos(3 * ang)  # noqa: E731
    pre = simulate_gauge(text, study, truth, repeatability=0.002, seed=11, pretravel=lobes)
    pieces = {p.feature: p for p in truth_pieces(study.profile, read_truth(truth, study.profile))}
    turns = []
    for t0, t1, t2, k in zip(exact.trips, run.trips, pre.trips, draws, strict=True):
        u = np.subtract(t0.move.target, t0.move.start)
        u /= np.linalg.norm(u)
        np.testing.assert_allclose(t1.centre, np.add(t0.contact, k * u), atol=1e-12)
        d = contact_direction(pieces[t0.feature], t0.contact)
        turns.append(math.acos(min(1.0, float(d @ u))))
        extra = k + lobes(math.atan2(d[0], d[1]))
        np.testing.assert_allclose(t2.centre, np.add(t0.contact, extra * u), atol=1e-12)
    assert 1e-5 < max(turns) < 0.02
    const = simulate_gauge(text, study, truth, repeatability=0.0, seed=0, pretravel=0.004)
    assert all(t.pretravel == 0.004 for t in const.trips)


def test_a_probe_that_misses_stops_with_the_control_s_message(cases):
    """dia_24 moved 0.6 mm inward (the overtravel is 0.5): its probe moves end in air.
    The control's message names the program line of the first one that misses (a point
    near the face may touch the face's corner instead, which the truth keeps at its
    nominal length); G38.3 records the end point; Fanuc's G31 writes it, in diameter."""
    study, _ = cases["demo"]
    text = plan_program(plan_study(study, points=4))
    miss = {"dia_24": {"offset": -0.6, "rotation": 0.0}}  # overtravel is 0.5
    with pytest.raises(AnalysisError) as err:
        simulate_gauge(text, study, miss, repeatability=0.0, seed=0)
    msg = str(err.value)
    line = int(re.search(r"<program>:(\d+): G38\.2 \(point \d+ dia_24 t=", msg).group(1))
    assert text.splitlines()[line - 1].startswith("G38.2 X25.0000 Z")  # dia_24's diameter
    assert "G38.2 move finished without making contact" in msg, msg
    # G38.3: no error, the end point is recorded (and written: it differs from the last)
    run = simulate_gauge(text.replace("G38.2", "G38.3"), study, miss, repeatability=0.0, seed=0)
    missed = [t for t in run.trips if not t.touched]
    assert missed and all(t.feature is None and t.centre == t.move.target for t in missed)
    first = missed[0]
    assert first.move.target[0] == 12.5
    row = f"12.500000 0.000000 {first.move.target[1]:.6f} "
    assert any(x.startswith(row) for x in run.text.splitlines())
    # Fanuc G31: the block's end point, in diameter
    fan = plan_program(plan_study(study, points=4, controller="fanuc"))
    run = simulate_gauge(fan, study, miss, repeatability=0.0, seed=0)
    assert f"X   25.0000 Z{first.move.target[1]:10.4f}" in run.text.splitlines()


def test_the_fanuc_output_parses_back_to_its_precision(cases):
    study, truth = cases["demo"]
    for mode in ("diameter", "radius"):
        plan = plan_study(replace(study, plan={"x_mode": mode}), points=3, controller="fanuc")
        run = simulate_gauge(plan_program(plan), study, truth, repeatability=0.0015, seed=5,
                             x_mode_fanuc=mode)  # fmt: skip
        pat = re.compile(r"X( {0,4}-?\d{1,4}\.\d{4}) Z( {0,4}-?\d{1,4}\.\d{4})")
        rows = []
        for line in run.text.splitlines():
            m = pat.fullmatch(line)
            assert m is not None and len(line) == 23, line
            rows.append([float(m.group(1)), float(m.group(2))])
        rows = np.array(rows)
        k = 2.0 if mode == "diameter" else 1.0
        np.testing.assert_allclose(rows[:, 0] / k, run.centres[:, 0], atol=0.5e-4 / k + 1e-12)
        np.testing.assert_allclose(rows[:, 1], run.centres[:, 1], atol=0.5e-4 + 1e-12)


def test_an_inch_program_writes_inches(cases):
    study, truth = cases["demo"]
    plan = plan_study(study, points=3)
    texts = {
        units: gauging_program(plan.home, plan.path, plan.points, header=[units],
                               options=GaugingOptions(controller="linuxcnc", units=units,
                                                      x_mode="diameter", tool=9,
                                                      feed_mm_min=200.0, decimals=10))
        for units in ("in", "mm")
    }  # fmt: skip
    assert "G20" in texts["in"]
    run = simulate_gauge(texts["in"], study, truth, repeatability=0.0, seed=0)
    mm = simulate_gauge(texts["mm"], study, truth, repeatability=0.0, seed=0)
    np.testing.assert_allclose(run.centres, mm.centres, atol=1e-7)  # the programs' rounding
    rows = _probe_lines(run.text)
    np.testing.assert_allclose(rows[:, [0, 2]], run.centres / 25.4, atol=5e-7 + 1e-12)


def test_probeopen_writes_no_exact_repeat(cases):
    study, truth = cases["demo"]
    text = plan_program(plan_study(study, points=3))
    lines = text.splitlines(keepends=True)
    k = next(i for i, x in enumerate(lines) if x.startswith("G38.2"))
    # probe point 1 again: its label, G38.2, LOG and the way back
    twice = "".join(lines[: k + 3] + lines[k - 1 : k + 3] + lines[k + 3 :])
    run = simulate_gauge(twice, study, truth, repeatability=0.0, seed=0)
    assert run.trips[0].centre == run.trips[1].centre
    assert [t.written for t in run.trips[:3]] == [1, 0, 1]
    assert len(run.text.splitlines()) == len(run.trips) - 1
    noisy = simulate_gauge(twice, study, truth, repeatability=0.001, seed=0)
    assert len(noisy.text.splitlines()) == len(noisy.trips)
    # outside PROBEOPEN ... PROBECLOSE nothing is written
    closed = text.replace("(PROBEOPEN probe_points.txt)", "")
    assert simulate_gauge(closed, study, truth, repeatability=0.0, seed=0).text == ""


def test_travel_into_the_part_and_g91_after_a_probe_are_refused(cases):
    study, truth = cases["demo"]
    text = plan_program(plan_study(study, points=3))
    first = next(x for x in text.splitlines() if x.startswith("G0 X29.0000 Z"))
    crash = text.replace(first + "\n", first + "\nG0 X20.0000\n", 1)
    with pytest.raises(AnalysisError, match="Probe tripped during non-probe move"):
        simulate_gauge(crash, study, truth, repeatability=0.0, seed=0)
    lines = text.splitlines(keepends=True)
    k = next(i for i, x in enumerate(lines) if x.startswith("G38.2"))
    inc = "".join(lines[: k + 1] + ["G91 G0 X2.0\nG90\n"] + lines[k + 1 :])
    with pytest.raises(InputError, match="in G91 after a probe move"):
        simulate_gauge(inc, study, truth, repeatability=0.0, seed=0)


def test_truth_refusals_name_file_line_and_value(cases, tmp_path):
    study, _ = cases["demo"]
    bad = tmp_path / "truth.json"
    text = TRUTH.read_text().replace('"radius": 0.004', '"radius": "big"')
    bad.write_text(text)
    line = text.splitlines().index('      "radius": "big"') + 1
    with pytest.raises(InputError) as err:
        read_truth(bad, study.profile)
    assert str(err.value).startswith(f"{bad}:{line}, feature 'fillet': radius: expected a finite")
    bad.write_text(TRUTH.read_text().replace('"taper"', '"tapper"'))
    with pytest.raises(InputError, match="unknown feature id 'tapper'"):
        read_truth(bad, study.profile)
    bad.write_text('{\n  "deviations": {\n')
    with pytest.raises(InputError, match=r"truth.json:3: not JSON"):
        read_truth(bad, study.profile)

"""`piecs-bayes simulate batch`: the shipped run is reproduced to the precision it prints, and
`--points` / `--parts` make dense and long runs anyone can regenerate."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from golden import Deterministic, compare_text_file

from piecs_bayes.cli import main
from piecs_bayes.io import load_study
from piecs_bayes.jobs import load_probe_data
from piecs_bayes.simulate import (
    BATCH_WEAR_PER_PART,
    DEMO_POINTS,
    SimulatedProbing,
    batch_part_errors,
    write_batch,
)

BATCH = Path(__file__).resolve().parents[2] / "data" / "batch"


def test_the_default_run_is_the_shipped_data(tmp_path):
    write_batch(tmp_path)
    shipped = sorted(p.name for p in BATCH.iterdir() if p.is_file())
    assert sorted(p.name for p in tmp_path.iterdir()) == shipped
    # at the precision the files print (the CSVs' 5 decimals: one unit of the last
    # digit), truth.json within 1e-12 relative: XLA's last bits differ between CPUs
    for name in shipped:
        want, got = (BATCH / name).read_text(), (tmp_path / name).read_text()
        base = Deterministic(rtol=1e-12 if name.endswith(".json") else 0.0, atol=0.0)
        assert compare_text_file(name, want, got, base=base) == [], name


class _MeanRng:
    """A generator whose every normal draw is its mean: the law's systematic part."""

    def normal(self, loc=0.0, scale=1.0):
        return loc


def test_the_batch_law_is_the_shipped_runs_law():
    # `batch_part_errors` is the law the shipped run was drawn from (a simulation of
    # the study's process, benchmarks/bench_batch_process.py, draws from it): its
    # systematic part and tool change equal truth.json's, and the shipped offsets
    # scatter about it with the law's 0.8 µm sd
    truth = json.loads((BATCH / "truth.json").read_text())
    resid = []
    for k, part in enumerate(truth["parts"], start=1):
        err, change = batch_part_errors(k, _MeanRng(), tool_change_at=truth["tool_change_at"])
        assert change == part["tool_change"], part["part"]
        shipped = part["process_errors"]
        for name, value in shipped.items():
            if name in ("tool_offset_x", "tool_offset_z"):
                resid.append(value - getattr(err, name))
            else:
                assert getattr(err, name) == pytest.approx(value, rel=1e-12, abs=1e-15), name
    assert truth["wear_per_part_mm"] == BATCH_WEAR_PER_PART
    # 72 draws of N(0, 0.8 µm): their sd within its 99.9 % range (0.8 µm x [0.73, 1.27])
    assert 0.73 * 0.0008 < np.std(resid, ddof=1) < 1.27 * 0.0008
    assert abs(np.mean(resid)) < 3.3 * 0.0008 / np.sqrt(len(resid))


def test_dense_long_run_points_names_and_tool_changes(tmp_path):
    truths = write_batch(tmp_path, n_parts=45, points=16)
    study = load_study(tmp_path / "study.toml")
    probe = load_probe_data(study)
    assert probe.parts[0] == "part01" and probe.parts[-1] == "part45"
    assert len(probe.feature) == 45 * 7 * 16
    per_part = {p: int(np.sum(probe.part == p)) for p in probe.parts}
    assert set(per_part.values()) == {7 * 16}
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["points_per_feature"] == 16
    # every insert lasts tool_change_at - 1 = 20 parts
    assert truth["tool_change_parts"] == ["part21", "part41"]
    assert [t["part"] for t in truths if t["tool_change"]] == ["part21", "part41"]
    wear = [t["process_errors"]["wear_start"] for t in truths]
    assert wear[20] == wear[40] == 0.0 and wear[19] > 0 and wear[44] == wear[24]


def test_names_sort_in_production_order_beyond_99_parts(tmp_path):
    write_batch(tmp_path, n_parts=101, points=3)
    names = sorted(p.stem for p in tmp_path.glob("part*.csv"))
    assert names[0] == "part001" and names[-1] == "part101" and len(names) == 101


def test_default_points_are_the_demo_parts(tmp_path):
    write_batch(tmp_path, n_parts=1)
    rows = (tmp_path / "part01.csv").read_text().splitlines()[2:]
    assert len(rows) == sum(DEMO_POINTS.values())


@pytest.mark.parametrize("points", ["2", "0", "x"])
def test_cli_refuses_too_few_points(tmp_path, capsys, points):
    argv = ["simulate", "batch", "--parts", "2", "--points", points, "--out", str(tmp_path)]
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse's own check (not an integer >= 1)
        rc = exc.code
    assert rc == 2
    assert "points" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_simulated_probing_defaults_and_refusal():
    """`SimulatedProbing` holds what `simulate_parts` took as keywords, with the same
    defaults; a negative noise is refused."""
    from piecs_bayes.geometry import MachineTransform

    p = SimulatedProbing(ball_radius=1.0)
    assert (p.transform, p.points, p.noise_sd, p.margin) == (MachineTransform(), 8, 0.001, 0.1)
    with pytest.raises(ValueError, match="noise_sd must be a number >= 0, got -0.001"):
        SimulatedProbing(ball_radius=1.0, noise_sd=-0.001)


def test_simulated_contacts_are_on_the_deviated_feature_in_closed_form():
    """Simulated probing puts its contacts where `drawn_at(t, dev)` says (NumPy, one
    part or many at once): on the deviated feature (closed form) with its outward
    normals; the batch of parts is each part's own."""
    from piecs_bayes.geometry import Arc, Line

    t = np.linspace(0.1, 0.9, 7)
    line = Line(id="first_probe_line", p0=(11.25, -3.5), p1=(13.75, -27.0))
    dev = np.array([0.004, 2e-4])  # offset (mm), rotation (rad)
    s, n = line.drawn_at(t, dev)
    point, _, normal = (np.asarray(a) for a in line.actual(dev))
    np.testing.assert_allclose((s - point) @ normal, 0.0, atol=1e-13)
    np.testing.assert_allclose(n, np.broadcast_to(normal, n.shape), atol=1e-15)
    arc = Arc(id="first_probe_arc", p0=(20.0, -40.0), p1=(17.0, -43.0), center=(17.0, -40.0),
              ccw=False)  # fmt: skip
    dev = np.array([0.003, -0.002, 0.005])  # centre x, z, radius (mm)
    s, n = arc.drawn_at(t, dev)
    centre, radius = np.array(arc.center) + dev[:2], arc.radius + dev[2]
    v = s - centre
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 1]), radius, rtol=0, atol=1e-13)
    np.testing.assert_allclose(n, arc.sense * v / radius, atol=1e-12)
    devs = np.array([[0.003, -0.002, 0.005], [-0.01, 0.0, 0.02], [0.0, 0.0, 0.0]])
    many = arc.drawn_at(t, devs)
    assert many[0].shape == many[1].shape == (3, 7, 2)
    for j, d in enumerate(devs):
        for a, b in zip(many, arc.drawn_at(t, d), strict=True):
            np.testing.assert_array_equal(a[j], b)

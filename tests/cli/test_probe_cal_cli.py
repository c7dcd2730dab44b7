"""``piecs-bayes simulate calibration`` -> ``calibrate-probe`` -> ``read_probe_calibration``:
the round trip, the summary, never over an input, the exit codes."""

from __future__ import annotations

import json

import numpy as np
from helpers import run_cli as _run

from piecs_bayes.io import read_probe_calibration
from piecs_bayes.jobs import calibrate_probe


def test_round_trip(capsys, tmp_path):
    rc, text = _run(capsys, ["simulate", "calibration", "--out", tmp_path, "--seed", "3"])
    assert rc == 0, text
    toml = tmp_path / "calibration.toml"
    out = tmp_path / "probe_cal.json"
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", out])
    assert rc == 0, text
    assert "r0" in text and "a3" in text and "probing error" in text and "dof 17" in text
    back = read_probe_calibration(out)
    direct = calibrate_probe(toml)
    assert back.orders == direct.orders == (2, 3)
    np.testing.assert_array_equal(back.coefficients, direct.coefficients)
    np.testing.assert_allclose(back.cov, direct.cov, rtol=1e-15, atol=0)
    assert back.probe == "T9 simulated probe" and back.feed == 200.0 and back.dof == 17
    assert [i["file"] for i in back.inputs] == [str(toml), str(tmp_path / "cal_points.csv")]
    truth = json.loads((tmp_path / "truth.json").read_text())
    z = (back.coefficients - np.array(list(truth["coefficients"].values()))) / np.sqrt(
        np.diag(back.cov)
    )
    assert np.all(np.abs(z) < 3.0)
    # K = 0 on request: one radius
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", out, "--orders", "0", "-q"])
    assert rc == 0 and read_probe_calibration(out).orders == ()


def test_never_over_an_input_and_the_exit_codes(capsys, tmp_path):
    _run(capsys, ["simulate", "calibration", "--out", tmp_path])
    toml = tmp_path / "calibration.toml"
    csv = tmp_path / "cal_points.csv"
    before = csv.read_bytes()
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", csv])
    assert rc == 2 and "refusing to write over it" in text and csv.read_bytes() == before
    rc, text = _run(capsys, ["calibrate-probe", tmp_path / "none.toml", "--out", "x.json"])
    assert rc == 2 and "not found" in text
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", tmp_path / "c.json",
                             "--orders", "1"])  # fmt: skip
    assert rc == 2 and "order 1 is the probe's offset" in text
    rc, _ = _run(capsys, ["calibrate-probe", toml])
    assert rc == 2  # --out is required (argparse)


def test_a_ring_csv_without_directions_takes_them_from_the_nominal(capsys, tmp_path):
    """K = 0 on a ring probed at +X and -X from a CSV (X as a diameter): the closed form
    r0 = (D - (x_plus - x_minus)) / 2 with X a radius, to 1e-9."""
    (tmp_path / "ring.csv").write_text("feature,x,z\nring,44.0012,-5\nring,-43.9968,-5\n"
                                       "ring,44.0016,-6\nring,-43.9972,-6\n")  # fmt: skip
    (tmp_path / "cal.toml").write_text(
        '[calibration]\nprobe = "T9"\norders = "auto"\nrepeatability = 0.0015\n'
        'sigma = "known"\n[artefact]\nkind = "ring"\ndiameter = 50.0012\n'
        "expanded_uncertainty = 0.0008\ncoverage_factor = 2.0\n"
        '[[probe_files]]\nfile = "ring.csv"\nx_mode = "diameter"\n'
    )
    rc, text = _run(
        capsys, ["calibrate-probe", tmp_path / "cal.toml", "--out", tmp_path / "o.json"]
    )
    assert rc == 0, text
    cal = read_probe_calibration(tmp_path / "o.json")
    x_plus, x_minus = (44.0012 + 44.0016) / 4, (-43.9968 - 43.9972) / 4
    assert cal.orders == () and abs(cal.r0 - (50.0012 - (x_plus - x_minus)) / 2) < 1e-9


def test_auto_prints_why_and_the_half_sphere_warning(capsys, tmp_path):
    """The lathe's half sphere (the simulator's default): the candidates with their u at
    the lathe's four directions, the chosen marked, and a warning naming the file, the
    missing +X approach and the ring that adds it. --directions judges elsewhere."""
    _run(capsys, ["simulate", "calibration", "--out", tmp_path, "--seed", "3"])
    toml, out = tmp_path / "calibration.toml", tmp_path / "probe_cal.json"
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", out])
    assert rc == 0, text
    assert "orders auto: the u of r(theta) at -90, 0, 90, 180 degrees (the lathe's axis" in text
    cal = read_probe_calibration(out)
    rows = cal.orders_choice["candidates"]
    for row in rows:
        line = f"{row['model']:<44} {row['u_mm'] * 1e3:8.2f} {row['u_model_mm'] * 1e3:8.2f}"
        assert line in text
    assert "orders 2,3" + " " * 34 in text and "<- chosen" in text
    flat = " ".join(text.split())
    assert (f"warning: {toml}: the calibration's approach directions span 180 degrees (90 to "
            "270): none along +X (0 degrees") in flat  # fmt: skip
    assert "A ring gauge, probed from inside along +X and -X, adds the X approaches" in flat
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", out, "--directions", "176.09,90"])
    assert rc == 0, text
    assert read_probe_calibration(out).orders_choice["targets_deg"] == [176.09, 90.0]
    assert "at 90, 176.09 degrees (given)" in text
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", out, "--directions", "x,90"])
    assert rc == 2 and "--directions: expected angles in degrees separated by commas" in text
    rc, text = _run(capsys, ["calibrate-probe", toml, "--out", out, "--directions", "90",
                             "--plan", tmp_path / "plan.json"])  # fmt: skip
    assert rc == 2 and "--directions and --plan both give the target directions" in text


def test_a_plans_approaches_are_the_targets(capsys, tmp_path):
    _run(capsys, ["simulate", "calibration", "--out", tmp_path, "--full-circle"])
    pts = [{"feature": "dia", "centre": [15.0, -5.0], "approach": [-1.0, 0.0],
            "target": [14.0, -5.0]},
           {"feature": "face", "centre": [10.0, 3.0], "approach": [0.0, -1.0],
            "target": [10.0, 2.0]}]  # fmt: skip
    plan = {"format": "piecs_bayes probe plan 1", "units": "mm", "x": "radius", "points": pts}
    (tmp_path / "plan.json").write_text(json.dumps(plan))
    out = tmp_path / "probe_cal.json"
    rc, text = _run(capsys, ["calibrate-probe", tmp_path / "calibration.toml", "--out", out,
                             "--plan", tmp_path / "plan.json"])  # fmt: skip
    assert rc == 0, text
    assert read_probe_calibration(out).orders_choice["targets_deg"] == [180.0, -90.0]
    assert "warning" not in text  # the full circle covers every direction


def test_one_radius_per_axis_from_a_ring_and_its_faces(capsys, tmp_path):
    """A ring at +-X (X as a diameter) and its face pair at -+Z (feature "face"), two
    points a direction, `orders = "a2"` in the file: r along X and along Z printed, the
    closed forms of the means to 1e-9 mm."""
    (tmp_path / "pts.csv").write_text(
        "feature,x,z\nring,44.0012,-5\nring,-43.9968,-5\nring,44.0016,-6\nring,-43.9972,-6\n"
        "face,30,-1.9985\nface,30,-18.0017\nface,31,-1.9983\nface,31,-18.0019\n"
    )
    (tmp_path / "cal.toml").write_text(
        '[calibration]\nprobe = "T9"\norders = "a2"\nrepeatability = 0.0015\n'
        'sigma = "known"\n[artefact]\nkind = "ring"\ndiameter = 50.0012\n'
        "expanded_uncertainty = 0.0008\ncoverage_factor = 2.0\ncentre = [0.0, -10.0]\n"
        "[artefact.face]\nwidth = 10.0004\nexpanded_uncertainty = 0.0006\n"
        "coverage_factor = 2.0\n"
        '[[probe_files]]\nfile = "pts.csv"\nx_mode = "diameter"\n'
    )
    out = tmp_path / "o.json"
    rc, text = _run(capsys, ["calibrate-probe", tmp_path / "cal.toml", "--out", out])
    assert rc == 0, text
    cal = read_probe_calibration(out)
    r_x = (50.0012 - ((44.0012 + 44.0016) / 4 - (-43.9968 - 43.9972) / 4)) / 2
    r_z = ((-1.9984 - -18.0018) - 10.0004) / 2
    assert cal.fixed == ("b2",) and cal.orders_choice is None
    got = cal.radius(np.radians([0.0, 90.0]))
    assert abs(got[0] - r_x) < 1e-9 and abs(got[1] - r_z) < 1e-9
    assert "r0 + a2 cos 2 theta (one radius per axis)" in text
    assert f"r along X    {r_x:10.5f}" in text and f"r along Z    {r_z:10.5f}" in text
    assert "b2" in text and "(held at 0)" in text

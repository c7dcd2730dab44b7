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

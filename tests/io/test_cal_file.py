"""The calibration file: read and checked key by key; the refusals name file and key."""

from __future__ import annotations

import json

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.io import ProbeCalibration, read_calibration_file, read_probe_calibration

GOOD = """\
[calibration]
probe = "T9 Renishaw OMP40"
units = "mm"
feed = 200.0
date = "2026-11-30"
orders = [2, 3]
repeatability = 0.0015
[artefact]
kind = "sphere"
diameter = 25.0004
expanded_uncertainty = 0.0005
coverage_factor = 2.0
centre = [0.0, -40.0]
[[probe_files]]
file = "cal_points.csv"
format = "csv"
x_mode = "radius"
"""


def _write(tmp_path, text):
    p = tmp_path / "calibration.toml"
    p.write_text(text)
    return p


def test_a_good_file_reads(tmp_path):
    cal = read_calibration_file(_write(tmp_path, GOOD))
    assert cal.probe == "T9 Renishaw OMP40" and cal.orders == (2, 3) and cal.feed == 200.0
    assert cal.artefact.kind == "sphere" and cal.artefact.radius_u == 0.0005 / 4
    assert cal.artefact.centre == (0.0, -40.0) and cal.repeatability == 0.0015
    assert cal.probe_files[0].file == tmp_path / "cal_points.csv"
    assert cal.probe_files[0].x_mode == "radius" and cal.sigma == "estimated"
    assert cal.inputs == (tmp_path / "cal_points.csv",)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (("feed = 200.0", "feed = 200.0\nspeed = 3"), r"calibration.speed: unknown key 'speed'"),
        (('kind = "sphere"', 'kind = "sphere"\nradius = 3'), r"artefact.radius: unknown key"),
        (('x_mode = "radius"', 'x_mode = "radius"\nunits = "mm"'), r"probe_files\[0\].units"),
        (("expanded_uncertainty = 0.0005\n", ""), r"an artefact with no certificate uncertainty"),
        (("expanded_uncertainty = 0.0005", "expanded_uncertainty = 0"), r"no certificate unc"),
        (('units = "mm"', 'units = "in"'), r"calibration.units: a calibration is made in 'mm'"),
        (("orders = [2, 3]", "orders = [1, 2]"), r"order 1 is the probe's offset"),
        (('kind = "sphere"', 'kind = "cube"'), r"artefact.kind: unknown value 'cube'"),
        (('format = "csv"', 'format = "linuxcnc"'), r"probe_files\[0\].plan: missing"),
    ],
)
def test_refusals_name_the_file_and_the_key(tmp_path, edit, match):
    path = _write(tmp_path, GOOD.replace(*edit))
    with pytest.raises(InputError, match=match) as err:
        read_calibration_file(path)
    assert err.value.file == str(path)


def test_a_probe_cal_json_of_another_unit_is_refused(tmp_path):
    cal = ProbeCalibration(orders=(), coefficients=np.array([3.004]), cov=np.eye(1) * 1e-8)
    body = cal.to_json()
    p = tmp_path / "probe_cal.json"
    p.write_text(json.dumps(body))
    assert read_probe_calibration(p).r0 == 3.004
    with pytest.raises(InputError, match=r"the calibration is in 'mm', the study in 'in'"):
        read_probe_calibration(p, units="in")
    body["units"] = "in"
    p.write_text(json.dumps(body))
    with pytest.raises(InputError, match=r"the calibration is in 'in'"):
        read_probe_calibration(p)

"""The CSV tables: long, with their units in a `unit` column or in the column names,
and X stated as a radius (the results' `to_dataframe()` against these CSVs: the
tests of fit, uncertainty and jobs).

One demo fit, its adjusted path, the linearised tool-path uncertainty and a short
(not converged, on purpose: fast) Bayesian run are shared by the module.
"""

from __future__ import annotations

import csv
import io
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from piecs_bayes.export.tables import (
    band_csv,
    bounds_csv,
    budget_csv,
    fit_csv,
    path_csv,
    posterior_csv,
    residuals_csv,
    to_csv,
)
from piecs_bayes.fit import SOURCE_UNITS
from piecs_bayes.io import load_study
from piecs_bayes.jobs import bayes_study, compensate_study, fit_study, toolpath_uncertainty

DEMO = Path(__file__).resolve().parents[3] / "data" / "demo" / "study.toml"

FIT = [
    "part", "feature", "type", "parameter", "unit", "value", "std_error", "n_points",
    "residual_sd_mm", "residual_dof", "sigma_mm", "sigma_source", "sigma_dof",
    "n_outliers", "method",
]  # fmt: skip
RESIDUALS = [
    "part", "feature", "line", "ball_x_radius_mm", "ball_z_mm", "residual_mm", "weight",
    "outlier", "nominal_x_radius_mm", "nominal_z_mm", "error_x_radius_mm", "error_z_mm",
]  # fmt: skip
PATH = [
    "vertex", "between", "junction", "nominal_x_radius_mm", "nominal_z_mm", "x_radius_mm",
    "z_mm", "dx_radius_mm", "dz_mm",
]  # fmt: skip
BOUNDS = ["vertex", "x_radius_mm", "z_mm", "u_x_radius_mm", "u_z_mm", "corr_xz", "method"]
BAND = [
    "feature", "t", "nominal_x_radius_mm", "nominal_z_mm", "normal_x", "normal_z",
    "offset_mm", "u_offset_mm", "pointwise_lower_mm", "pointwise_upper_mm",
    "simultaneous_lower_mm", "simultaneous_upper_mm",
]  # fmt: skip
BUDGET = ["output", "unit", "source", "u", "variance_share"]
POSTERIOR = ["part", "parameter", "unit", "mean", "sd", "q2.5", "q97.5"]


@pytest.fixture(scope="module")
def demo():
    study = load_study(DEMO)
    fit = fit_study(study)
    tpu = toolpath_uncertainty(study, fit)["linearised"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a short chain does not converge: expected
        bayes = bayes_study(study, fit, nsteps=200, n_ensembles=1, progress=False, seed=1)
    return study, fit, compensate_study(study, fit), tpu, bayes


def _rows(text: str) -> tuple[list[str], list[dict]]:
    reader = csv.DictReader(io.StringIO(text))
    rows = list(reader)
    return list(reader.fieldnames or []), rows


def _read(text: str) -> pd.DataFrame:
    return pd.read_csv(io.StringIO(text))


def test_fit_csv_has_a_unit_per_parameter(demo):
    study, fit = demo[:2]
    head, rows = _rows(fit_csv(fit))
    assert head == FIT
    units = {(r["type"], r["parameter"]): r["unit"] for r in rows}
    assert units[("line", "offset")] == "mm" and units[("line", "rotation")] == "rad"
    assert all(units[("arc", p)] == "mm" for p in ("center_x", "center_z", "radius"))
    assert len(rows) == sum(f.nparams for f in study.profile.features if f.id in fit.fits)


def test_residuals_and_path_csv_state_x_as_a_radius(demo):
    study, fit, path = demo[:3]
    head, rows = _rows(residuals_csv(fit))
    assert head == RESIDUALS and len(rows) == sum(f.n for f in fit)
    head, rows = _rows(path_csv(path))
    assert head == PATH and len(rows) == len(study.profile) + 1
    first = rows[1]  # face_end|dia_24: the corner at the nominal radius 12 (diameter 24)
    assert float(first["nominal_x_radius_mm"]) == pytest.approx(12.0)


def test_toolpath_csvs_have_units_in_their_headers(demo):
    study, tpu = demo[0], demo[3]
    head, rows = _rows(bounds_csv(tpu))
    assert head == BOUNDS and len(rows) == len(tpu.vertices)
    head, rows = _rows(band_csv(tpu, study.profile))
    assert head == BAND and len(rows) == len(tpu.grid)
    head, rows = _rows(budget_csv(tpu, study.profile))
    assert head == BUDGET
    by_output: dict[str, list[dict]] = {}
    for r in rows:
        by_output.setdefault(r["output"], []).append(r)
    assert by_output["dia_24.rotation"][0]["unit"] == "rad"
    assert {r["unit"] for r in by_output["vertex1.x_radius"]} == {"mm"}
    for output, group in by_output.items():  # the shares of the sources sum to 1
        total = [r for r in group if r["source"] == "total"]
        assert len(total) == 1, output
        if float(total[0]["u"]) == 0.0:  # a vertex held by the path's ends
            continue
        shares = sum(float(r["variance_share"]) for r in group if r["source"] != "total")
        assert float(total[0]["variance_share"]) == 1.0, output
        assert shares == pytest.approx(1.0, abs=1e-6), output
        u2 = sum(float(r["u"]) ** 2 for r in group if r["source"] != "total")
        assert np.sqrt(u2) == pytest.approx(float(total[0]["u"]), rel=1e-6), output


def test_posterior_csv_has_a_unit_per_parameter(demo):
    bayes = demo[4]
    head, rows = _rows(posterior_csv(bayes))
    assert head == POSTERIOR and [r["parameter"] for r in rows] == list(bayes.names)
    units = {r["parameter"]: r["unit"] for r in rows}
    assert units["dia_24.offset"] == "mm" and units["dia_24.rotation"] == "rad"
    for name, unit in units.items():
        if "." not in name:  # nuisance sources and the probe sigma
            assert unit == SOURCE_UNITS.get(name, "mm"), name


def test_floats_keep_their_decimal_point():
    text = to_csv([{"a": 46.0, "b": 3, "c": -0.0, "d": 1e-12, "e": None, "f": float("nan")}])
    assert text.splitlines()[1] == "46.0,3,-0.0,1e-12,,nan"
    df = _read(text)
    assert str(df["a"].dtype) == "float64" and str(df["b"].dtype) == "int64"

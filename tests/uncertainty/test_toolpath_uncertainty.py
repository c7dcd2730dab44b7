"""Uncertainty of the adjusted tool path: GUM vs Monte Carlo, budgets, calibration."""

from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.fit import FitOptions, fit_profile
from piecs_bayes.io import load_study
from piecs_bayes.jobs import bayes_study, fit_study, toolpath_uncertainty
from piecs_bayes.simulate import (
    DEMO_ERRORS,
    DEMO_POINTS,
    demo_profile,
    process_deviations,
    simulate_probe,
)
from piecs_bayes.uncertainty import (
    LinearisedOptions,
    linearised_toolpath,
)

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"
FULL = demo_profile()
TRUTH_ALL = process_deviations(FULL, DEMO_ERRORS)


@pytest.fixture(scope="module")
def demo_uncertainty():
    study = load_study(DEMO)
    fit = fit_study(study)
    bayes = bayes_study(study, fit, nsteps=8000, n_ensembles=2, progress=False, seed=1)
    return study, fit, bayes, toolpath_uncertainty(study, fit, bayes=bayes)


def test_dataframes_are_the_bounds_band_and_budget_csvs():
    import io

    import pandas as pd

    from piecs_bayes.export.tables import band_csv, bounds_csv, budget_csv

    study = load_study(DEMO)
    tpu = toolpath_uncertainty(study, fit_study(study))["linearised"]
    profile = study.profile

    def read(text):
        return pd.read_csv(io.StringIO(text))

    pd.testing.assert_frame_equal(tpu.to_dataframe(), read(bounds_csv(tpu)))
    band = tpu.to_dataframe("band", profile=profile)
    pd.testing.assert_frame_equal(band, read(band_csv(tpu, profile)))
    budget = tpu.to_dataframe("budget", profile=profile)
    pd.testing.assert_frame_equal(budget, read(budget_csv(tpu, profile)))
    vertices = tpu.to_dataframe()
    assert vertices["u_x_radius_mm"].to_numpy() == pytest.approx(tpu.vertex_sd[:, 0])
    total = budget[budget["source"] == "total"].set_index("output")["u"]
    assert total["vertex1.x_radius"] == pytest.approx(tpu.vertex_sd[1, 0])
    with pytest.raises(ValueError, match="give profile=study.profile"):
        tpu.to_dataframe("band")
    with pytest.raises(ValueError, match="unknown table 'vertex'"):
        tpu.to_dataframe("vertex")


def test_linearised_and_monte_carlo_agree_within_10_percent_on_the_demo(demo_uncertainty):
    study, _, bayes, unc = demo_uncertainty
    lin, mc = unc["linearised"], unc["monte_carlo"]
    assert bayes.posterior.converged, bayes.posterior.problems
    for fid in study.profile.ids:
        r = np.sqrt(np.diag(mc.deviation_cov[fid]) / np.diag(lin.deviation_cov[fid]))
        assert np.all(np.abs(r - 1) < 0.10), (fid, r)
    big = lin.vertex_sd > 1e-4  # 0.1 um: below that a ratio means nothing
    r = mc.vertex_sd[big] / lin.vertex_sd[big]
    assert np.all(np.abs(r - 1) < 0.10), r
    r = mc.offset_sd / lin.offset_sd
    assert np.all(np.abs(r - 1) < 0.10)
    # simultaneous band wider than pointwise, both ways
    for u in (lin, mc):
        assert (
            u.bands.crit_simultaneous > 2.3 > 1.96 >= float(np.max(u.bands.crit_pointwise)) - 0.05
        )


def test_budget_sums_to_the_total_variance(demo_uncertainty):
    _, _, _, unc = demo_uncertainty
    lin = unc["linearised"]
    for budget in (lin.deviation_budget, lin.vertex_budget, lin.offset_budget):
        parts = sum(v for k, v in budget.items() if k != "total")
        assert np.allclose(parts, budget["total"], rtol=1e-12, atol=0)
    diag = np.concatenate([np.diag(lin.deviation_cov[f]) for f in lin.deviation_cov])
    assert np.allclose(lin.deviation_budget["total"], diag, rtol=1e-10)
    assert set(lin.deviation_budget) == {
        "repeatability",
        "ball_radius",
        "scale_x",
        "scale_z",
        "x_centre",
        "total",
    }
    # the centre-line offset moves diameters, not faces
    i_face = 0  # face_end.offset
    assert lin.deviation_budget["x_centre"][i_face] < 1e-6 * lin.deviation_budget["total"][i_face]
    i_dia = 2  # dia_24.offset
    assert lin.deviation_budget["x_centre"][i_dia] > 0.3 * lin.deviation_budget["total"][i_dia]


def test_a_scale_dominated_study_has_wider_bounds_in_the_expected_ratio():
    sim = simulate_probe(
        FULL, TRUTH_ALL, ball_radius=1.0, points=DEMO_POINTS, noise_sd=0.0015, rng=5
    )
    fit = fit_profile(FULL, sim["feature"], sim["points"], ball_radius=1.0,
                      options=FitOptions(sigma=0.0015, solver="lm"))  # fmt: skip
    noise = linearised_toolpath(
        FULL, sim["feature"], sim["points"], fit.deviations, sigma=0.0015,
        options=LinearisedOptions(ball_radius=1.0),
    )  # fmt: skip
    scale = linearised_toolpath(
        FULL, sim["feature"], sim["points"], fit.deviations, sigma=0.0015,
        options=LinearisedOptions(ball_radius=1.0, source_sd={"scale_z": 50e-6}),
    )  # fmt: skip
    # a face: its ball centres (at z ~ -60 + rb) are scaled, so its offset moves by z_c * s
    z_c = sim["points"][sim["feature"] == "shoulder", 1].mean()
    u0 = np.sqrt(noise.deviation_cov["shoulder"][0, 0])
    expected = np.sqrt(u0**2 + (z_c * 50e-6) ** 2) / u0
    got = np.sqrt(scale.deviation_cov["shoulder"][0, 0]) / u0
    assert got == pytest.approx(expected, rel=1e-5)
    assert expected > 3.0  # the scale error dominates: 2.95 um against ~0.9 um of noise
    # diameters do not feel a Z scale error (to second order: their fitted rotation
    # couples it in at ~3e-8 relative); the band is wider where faces are
    assert np.sqrt(scale.deviation_cov["dia_24"][0, 0]) == pytest.approx(
        np.sqrt(noise.deviation_cov["dia_24"][0, 0]), rel=1e-6
    )
    # the band on the shoulder widens by the same ratio (at its mid-point the
    # path offset is the mirrored offset parameter)
    k = FULL.ids.index("shoulder")
    mid = np.flatnonzero((scale.grid.feature == k) & np.isclose(scale.grid.t, 0.5))[0]
    assert scale.offset_sd[mid] / noise.offset_sd[mid] == pytest.approx(expected, rel=1e-5)


def test_all_points_with_an_inlier_mask_equal_the_inliers_alone():
    """`inlier=`: every trigger given and the fit's outliers masked gives the inliers'
    result (to rounding), so that parts with other outliers share one compiled
    Jacobian (the coverage check)."""
    sim = simulate_probe(
        FULL, TRUTH_ALL, ball_radius=1.0, points=DEMO_POINTS, noise_sd=0.0015, rng=7,
        outliers=(("dia_30", 3, 0.05), ("fillet", 2, -0.04)),
    )  # fmt: skip
    keep = np.ones(len(sim["feature"]), dtype=bool)
    keep[[int(np.flatnonzero(sim["feature"] == "dia_30")[3]),
          int(np.flatnonzero(sim["feature"] == "fillet")[2])]] = False  # fmt: skip
    fit = fit_profile(FULL, sim["feature"][keep], sim["points"][keep], ball_radius=1.0,
                      options=FitOptions(sigma=0.0015, solver="lm"))  # fmt: skip
    opts = LinearisedOptions(ball_radius=1.0, source_sd={"x_centre": 0.001}, band_sims=2**12)
    kw = dict(sigma=0.0015, dof=30.0, options=opts)
    a = linearised_toolpath(FULL, sim["feature"][keep], sim["points"][keep], fit.deviations, **kw)
    b = linearised_toolpath(FULL, sim["feature"], sim["points"], fit.deviations, inlier=keep, **kw)
    np.testing.assert_allclose(b.vertex_cov, a.vertex_cov, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(b.offset_sd, a.offset_sd, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(b.bands.simultaneous_upper, a.bands.simultaneous_upper, rtol=1e-9)
    assert b.bands.crit_simultaneous == pytest.approx(a.bands.crit_simultaneous, rel=1e-9)
    for fid in a.deviation_cov:
        np.testing.assert_allclose(b.deviation_cov[fid], a.deviation_cov[fid], rtol=1e-9,
                                   atol=1e-18)  # fmt: skip


def test_linearised_options_defaults_and_refusal():
    """`LinearisedOptions` holds what `linearised_toolpath` took as keywords, with the
    same defaults; an unknown source is refused with the message it had."""
    from piecs_bayes.errors import InputError
    from piecs_bayes.geometry import MachineTransform

    o = LinearisedOptions(ball_radius=1.0)
    assert (o.transform, o.source_sd, o.radius, o.loss, o.gain, o.grid, o.p, o.band_sims) == (
        MachineTransform(), None, None, "linear", 1.0, None, 0.95, 100_000
    )  # fmt: skip
    with pytest.raises(InputError, match="unknown uncertainty source 'spindle'; expected one of"):
        LinearisedOptions(ball_radius=1.0, source_sd={"spindle": 0.001})

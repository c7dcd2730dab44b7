"""Feature models through the fitting engine: joint fits, fixed parameters, robustness."""

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.fit import FitOptions, fit_feature, fit_profile, fit_profile_joint
from piecs_bayes.fit.lsq import TUNING
from piecs_bayes.geometry import Arc, Line, MachineTransform
from piecs_bayes.simulate import (
    DEMO_ERRORS,
    DEMO_POINTS,
    DEMO_TRANSFORM,
    demo_profile,
    process_deviations,
    simulate_probe,
)

PROFILE = demo_profile()
TRUTH = process_deviations(PROFILE, DEMO_ERRORS)
SIGMA = 0.0015


def test_joint_fit_recovers_axis_scale_errors_and_deviations():
    truth = dict(TRUTH, dia_24=np.zeros(2), face_end=np.zeros(2))  # reference features as drawn
    real = MachineTransform(x_centre=0.0021, z_offset=-312.4873, scale_x=40e-6, scale_z=-25e-6)
    sim = simulate_probe(
        PROFILE, truth, ball_radius=1.0, transform=real, points=DEMO_POINTS, noise_sd=0.0
    )
    fit = fit_profile_joint(
        PROFILE,
        sim["feature"],
        sim["points"],
        ball_radius=1.0,
        transform=DEMO_TRANSFORM,  # the study's transform does not know the scale errors
        free_transform=("scale_x", "scale_z"),
        options=FitOptions(fix=("dia_24.offset", "face_end.offset")),
    )
    assert fit.transform["scale_x"]["value"] == pytest.approx(40e-6, abs=1e-12)
    assert fit.transform["scale_z"]["value"] == pytest.approx(-25e-6, abs=1e-12)
    for fid, dev in truth.items():
        assert np.max(np.abs(fit[fid].values - dev)) < 1e-9, fid
    assert fit["dia_24"].fixed == ("offset",) and fit["dia_24"].std_errors[0] == 0.0


def test_joint_fit_with_an_unidentifiable_transform_says_why():
    sim = simulate_probe(
        PROFILE, TRUTH, ball_radius=1.0, transform=DEMO_TRANSFORM, points=DEMO_POINTS, noise_sd=0.0
    )
    fit = fit_profile_joint(
        PROFILE,
        sim["feature"],
        sim["points"],
        ball_radius=1.0,
        transform=DEMO_TRANSFORM,
        free_transform=("x_centre",),
    )
    assert fit["dia_24"].covariance is None
    assert "singular" in fit.result.covariance_reason
    with pytest.raises(InputError, match="unknown transform parameter 'spin'"):
        fit_profile_joint(
            PROFILE, sim["feature"], sim["points"], ball_radius=1.0, free_transform=("spin",)
        )


def test_fixed_radius_arc():
    arc = PROFILE["fillet"]
    truth = np.array([0.004, -0.003, 0.0])
    sim = simulate_probe(
        PROFILE, {"fillet": truth}, ball_radius=1.0, points={"fillet": 9}, noise_sd=0.0
    )
    fit = fit_feature(
        arc, sim["points"], ball_radius=1.0, options=FitOptions(fix={arc.id: ("radius",)})
    )
    assert np.max(np.abs(fit.values - truth)) < 1e-10
    assert fit.std_errors[2] == 0.0 and fit.fixed == ("radius",)
    with pytest.raises(InputError, match="cannot fix 'diameter'"):
        fit_feature(
            arc, sim["points"], ball_radius=1.0, options=FitOptions(fix={arc.id: ("diameter",)})
        )


def _chipped_part(frac, seed, n=20):
    rng = np.random.default_rng(seed)
    outliers = []
    for fid in PROFILE.ids:
        k = int(round(frac * n))
        for i in rng.choice(n, k, replace=False):
            outliers.append(
                (fid, int(i), float(rng.uniform(0.050, 0.500)))
            )  # chips: 50-500 um, one-sided
    return simulate_probe(
        PROFILE,
        TRUTH,
        ball_radius=1.0,
        points=dict.fromkeys(PROFILE.ids, n),
        noise_sd=SIGMA,
        rng=seed,
        outliers=tuple(outliers),
    ), len(outliers)


@pytest.mark.parametrize(
    "frac, loss", [(0.10, "huber"), (0.10, "tukey"), (0.25, "cauchy"), (0.25, "tukey")]
)
def test_robust_fits_survive_chips_where_plain_least_squares_does_not(frac, loss):
    sim, n_out = _chipped_part(frac, seed=3)
    plain = fit_profile(
        PROFILE, sim["feature"], sim["points"], ball_radius=1.0,
        options=FitOptions(sigma=SIGMA, solver="lm"),
    )  # fmt: skip
    robust = fit_profile(
        PROFILE,
        sim["feature"],
        sim["points"],
        ball_radius=1.0,
        options=FitOptions(
            method="robust", loss=loss, scale=TUNING[loss] * SIGMA, sigma=SIGMA, solver="lm"
        ),
    )
    z_plain = np.concatenate([(plain[k].values - TRUTH[k]) / plain[k].std_errors for k in TRUTH])
    z_rob = np.concatenate([(robust[k].values - TRUTH[k]) / robust[k].std_errors for k in TRUTH])
    assert np.max(np.abs(z_rob)) < 3.0
    assert np.max(np.abs(z_plain)) > 10.0
    flagged = sum(len(f.outliers) for f in robust)
    assert flagged >= 0.9 * n_out  # nearly every chip is reported


def test_profile_fit_dataframes_are_its_csvs():
    """`ProfileFit.to_dataframe()` is fit.csv (and residuals.csv) as pandas reads it:
    one row per parameter with its unit."""
    import io

    import pandas as pd

    from piecs_bayes.export.tables import fit_csv, residuals_csv

    sim = simulate_probe(PROFILE, TRUTH, ball_radius=1.0, points=DEMO_POINTS, noise_sd=SIGMA, rng=4)
    fit = fit_profile(
        PROFILE, sim["feature"], sim["points"], ball_radius=1.0,
        options=FitOptions(sigma=SIGMA, solver="lm"), part="p1",
    )  # fmt: skip
    df = fit.to_dataframe()
    pd.testing.assert_frame_equal(df, pd.read_csv(io.StringIO(fit_csv(fit))))
    assert len(df) == sum(f.nparams for f in PROFILE.features)
    units = df.groupby("parameter")["unit"].unique().to_dict()
    assert {k: list(v) for k, v in units.items()} == {
        "offset": ["mm"], "rotation": ["rad"], "center_x": ["mm"], "center_z": ["mm"],
        "radius": ["mm"],
    }  # fmt: skip
    assert df.loc[df["parameter"] == "offset", "value"].to_numpy() == pytest.approx(
        [fit[k].values[0] for k in PROFILE.ids if PROFILE[k].kind == "line"]
    )
    res = fit.to_dataframe("residuals")
    pd.testing.assert_frame_equal(res, pd.read_csv(io.StringIO(residuals_csv(fit))))
    assert len(res) == len(sim["points"]) and set(res["part"]) == {"p1"}
    with pytest.raises(ValueError, match="unknown table 'points'"):
        fit.to_dataframe("points")


@pytest.mark.parametrize(
    "feature",
    [
        Line("taper", (10.0, -2.0), (12.0, -30.0), side=-1),
        Line("face", (0.0, 0.0), (-3.0, 4.0), side=1),
        Arc("round", (20.0, -40.0), (17.0, -43.0), (17.0, -40.0), ccw=False),
        Arc("fillet", (10.0, 5.0), (10.0, -5.0), (10.0, 0.0), ccw=False, side=-1),
    ],
    ids=lambda f: f.id,
)
def test_surface_and_nominal_points_are_the_models(feature):
    """A fit's surface points (ball centres moved back along the fitted feature's
    outward normal) and their nearest nominal points, in NumPy, are what the feature's
    JAX methods give."""
    import jax.numpy as jnp

    from piecs_bayes.fit._features import surface_and_nominal

    q, n = feature.drawn_at(np.linspace(0.1, 0.9, 9))
    centres = q + 1.5 * n + np.random.default_rng(0).normal(0.0, 0.01, q.shape)
    values = np.array([0.01, -0.002, 0.004][: feature.nparams])
    surface, nominal = surface_and_nominal(feature, centres, values, 1.5)
    want = centres - 1.5 * np.asarray(feature.outward_normal(jnp.asarray(centres), values))
    np.testing.assert_allclose(surface, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        nominal, feature.closest_point(jnp.asarray(want)), rtol=0, atol=1e-12
    )

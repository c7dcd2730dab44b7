"""Uncertainty of the adjusted tool path: GUM vs Monte Carlo, budgets, calibration."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.fit import fit_profile, fit_profiles_bayes
from piecs_bayes.fit._features import to_part_frame
from piecs_bayes.geometry import MachineTransform, Profile
from piecs_bayes.pipeline import bayes_study, fit_study, load_study, toolpath_uncertainty
from piecs_bayes.simulate import (
    DEMO_ERRORS,
    DEMO_POINTS,
    demo_profile,
    process_deviations,
    simulate_probe,
)
from piecs_bayes.uncertainty import (
    linearised_toolpath,
    monte_carlo_toolpath,
    path_function,
    path_grid,
)

DEMO = Path(__file__).resolve().parents[1] / "data" / "demo" / "study.toml"
FULL = demo_profile()
TRUTH_ALL = process_deviations(FULL, DEMO_ERRORS)


@pytest.fixture(scope="module")
def demo_uncertainty():
    study = load_study(DEMO)
    fit = fit_study(study)
    bayes = bayes_study(study, fit, nsteps=8000, n_ensembles=2, progress=False, seed=1)
    return study, fit, bayes, toolpath_uncertainty(study, fit, bayes=bayes)


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
    fit = fit_profile(FULL, sim["feature"], sim["points"], ball_radius=1.0, sigma=0.0015)
    kw = dict(ball_radius=1.0, sigma=0.0015)
    noise = linearised_toolpath(FULL, sim["feature"], sim["points"], fit.deviations, **kw)
    scale = linearised_toolpath(
        FULL, sim["feature"], sim["points"], fit.deviations, source_sd={"scale_z": 50e-6}, **kw
    )
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


def test_calibration_over_200_simulated_parts():
    """95 % intervals of deviations and vertices, and the simultaneous band of the
    whole path, cover the truth at their nominal rate for both propagation routes.
    Each part has its own ball-radius, centre-line and Z-scale errors drawn from
    the priors; the fits use the nominal values."""
    profile = Profile(FULL.features[:3])
    truth = {k: TRUTH_ALL[k] for k in profile.ids}
    t0 = MachineTransform(x_centre=0.0021, z_offset=-312.4873)
    src = {"ball_radius": 0.0005, "x_centre": 0.001, "scale_z": 20e-6}
    priors = {k: {"dist": "normal", "mean": 0.0, "sd": v} for k, v in src.items()}
    sigma = 0.0015
    grid = path_grid(profile)
    true_v, true_o = map(
        np.asarray, path_function(profile, grid)(tuple(truth[f.id] for f in profile))
    )
    rng = np.random.default_rng(123)
    n_parts = 200
    sims, fits, lins = [], [], []
    for _ in range(n_parts):
        d = {n: rng.normal(0.0, s) for n, s in src.items()}
        real = MachineTransform(
            x_centre=t0.x_centre + d["x_centre"], z_offset=t0.z_offset, scale_z=d["scale_z"]
        )
        sim = simulate_probe(
            profile,
            truth,
            ball_radius=1.0 + d["ball_radius"],
            transform=real,
            points=8,
            noise_sd=sigma,
            rng=rng,
        )
        fit = fit_profile(
            profile, sim["feature"], to_part_frame(t0, sim["points"]), ball_radius=1.0, sigma=sigma
        )
        lin = linearised_toolpath(
            profile,
            sim["feature"],
            sim["points"],
            fit.deviations,
            ball_radius=1.0,
            sigma=sigma,
            transform=t0,
            source_sd=src,
            grid=grid,
        )
        sims.append(sim)
        fits.append(fit)
        lins.append(lin)
    # all parts sampled together: independent emcee ensembles stepped in lockstep
    # (issue 8), so this also checks the batch sampler's calibration
    parts = np.repeat([f"p{k:03d}" for k in range(n_parts)], [len(s["feature"]) for s in sims])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # short chains on purpose: the coverage is the check
        bayes = fit_profiles_bayes(
            profile,
            parts,
            np.concatenate([s["feature"] for s in sims]),
            np.concatenate([s["points"] for s in sims]),
            starts={f"p{k:03d}": fit.deviations for k, fit in enumerate(fits)},
            sources=priors,
            ball_radius=1.0,
            transform=t0,
            sigma=sigma,
            nsteps=500,
            n_ensembles=1,
            nwalkers=32,
            progress=False,
            on_fail="ignore",
            seed=7,
        )
    hits = {"lin": ([], [], []), "mc": ([], [], [])}
    for lin, post in zip(lins, bayes.values(), strict=True):
        mc = monte_carlo_toolpath(profile, post.deviation_samples, grid=grid)
        for key, u in (("lin", lin), ("mc", mc)):
            dev_z = np.concatenate(
                [
                    (u.deviations[f.id] - truth[f.id]) / np.sqrt(np.diag(u.deviation_cov[f.id]))
                    for f in profile
                ]
            )
            sd = u.vertex_sd
            ok = sd > 1e-7
            vert_z = ((u.vertices - true_v)[ok]) / sd[ok]
            b = u.bands
            whole = np.all((true_o >= b.simultaneous_lower) & (true_o <= b.simultaneous_upper))
            hits[key][0].append(np.abs(dev_z) < 1.959964)
            hits[key][1].append(np.abs(vert_z) < 1.959964)
            hits[key][2].append(whole)
    for key, (dev, vert, band) in hits.items():
        dev_cov = np.mean(np.concatenate(dev))
        vert_cov = np.mean(np.concatenate(vert))
        band_cov = np.mean(band)
        assert 0.92 <= dev_cov <= 0.98, (key, dev_cov)
        assert 0.92 <= vert_cov <= 0.98, (key, vert_cov)
        assert 0.92 <= band_cov <= 0.98, (key, band_cov)

"""A probe calibration used by every fit (issue 27): points corrected to r(theta),
its covariance one systematic source correlated over the points.

The lobing probe of the tests: r0 4 um above the nominal 1 mm ball, a 2-lobe term of
0.58 um and a 3-lobe term of 1.5 um; its covariance that of a 24-direction sphere
calibration with 1.5 um repeatability and a certificate u(R) of 0.25 um.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import lobing_probe

from piecs_bayes.errors import InputError
from piecs_bayes.fit import (
    CALIBRATION_SOURCE,
    FitOptions,
    RadiusComponents,
    fit_profiles,
    to_part_frame,
)
from piecs_bayes.io import approach_angle, load_study
from piecs_bayes.jobs import (
    CoverageOptions,
    approach_directions,
    calibrated_points,
    contact_directions,
    coverage_check,
    fit_study,
    load_probe_data,
    toolpath_uncertainty,
)
from piecs_bayes.simulate import (
    DEMO_ERRORS,
    DEMO_TRANSFORM,
    SimulatedProbing,
    demo_profile,
    process_deviations,
    simulate_parts,
)

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo"
PROFILE = demo_profile()
TRUTH = process_deviations(PROFILE, DEMO_ERRORS)
SIGMA = 0.0015
LOBING = lobing_probe()
FEW = {"face_end": 3, "dia_24": 8, "taper": 4, "dia_30": 5, "fillet": 5, "shoulder": 6, "dia_44": 7}


def _fit(points, sim, ball_radius):
    bf = fit_profiles(
        PROFILE, sim["part"], sim["feature"], to_part_frame(DEMO_TRANSFORM, points),
        ball_radius=ball_radius, options=FitOptions(method="lsq", sigma=SIGMA),
    )  # fmt: skip
    return {f.id: bf.values(f.id)[0] for f in PROFILE.features}


def test_noise_free_points_of_a_lobing_probe_give_the_truth_once_calibrated():
    """No noise. With one radius (the nominal ball) every feature is off by 3-4 um.
    With the calibration, each line is the truth to 1e-9 mm and the fillet to 2 nm: the
    simulated probe lobes at the deviated surface's normal, and the correction's second
    pass is along each feature's fitted normal (the first pass, along the nominal
    normal, left the fillet, whose centre moved 20 um, 0.3 um off: 7 mrad times
    r'(theta), up to 5 um/rad, amplified by the arc's fit)."""
    sim = simulate_parts(
        PROFILE, TRUTH, 1, probing=SimulatedProbing(
            ball_radius=1.0, transform=DEMO_TRANSFORM, points=8, noise_sd=0.0),
        probe=LOBING,
    )  # fmt: skip
    good = _fit(calibrated_points(PROFILE, sim["feature"], sim["points"], DEMO_TRANSFORM, LOBING),
                sim, LOBING.r0)  # fmt: skip
    plain = _fit(sim["points"], sim, 1.0)
    for f in PROFILE.features:
        err = np.abs(good[f.id] - TRUTH[f.id]).max()
        assert err < (2e-6 if f.kind == "arc" else 1e-9), f.id
        assert np.abs(plain[f.id] - TRUTH[f.id]).max() > max(10 * err, 0.0025), f.id
    # a line's offset absorbs r(theta) - 1 at its approach: the surface seems that far out
    a = approach_directions(PROFILE, sim["feature"], sim["points"], DEMO_TRANSFORM)
    rows = sim["feature"] == "dia_24"
    off = float(LOBING.radius(approach_angle(a[rows][:1]))[0]) - 1.0
    assert plain["dia_24"][0] - TRUTH["dia_24"][0] == pytest.approx(off, abs=1e-6)
    assert abs(off) > 0.003


@pytest.mark.parametrize("noise", [0.0, SIGMA])
def test_the_second_pass_corrects_at_the_contact_normal_of_a_part_50_um_off(noise):
    """The demo's fillet (a 90-degree arc, R 3 mm) with its centre 50 um off nominal:
    the probe lobes at the contact normal, up to 17 mrad from the nominal one. The
    correction along the nominal normal is off by r'(theta) times that angle (0.083 um
    at most, measured); along each part's fitted normals (the second pass) the lobing
    error left is under 0.05 um on every point (0.0006 um measured without noise; with
    1.5 um noise the fitted normal is ~0.1 mrad off: a few thousandths of a um)."""
    truth = {"fillet": np.array([0.0354, -0.0354, 0.0])}
    sim = simulate_parts(
        PROFILE, truth, 3, probing=SimulatedProbing(
            ball_radius=1.0, transform=DEMO_TRANSFORM, points=12, noise_sd=noise),
        probe=LOBING, rng=11,
    )  # fmt: skip
    raw, feat = sim["points"], sim["feature"]
    part = to_part_frame(DEMO_TRANSFORM, raw)
    out = np.zeros_like(part)
    for f in PROFILE.features:
        rows = feat == f.id
        dev = truth.get(f.id, np.zeros(f.nparams))
        out[rows] = np.asarray(f.outward_normal(part[rows], dev))
    # what a probe of radius r0 would have recorded at the same contact
    ideal = raw - (LOBING.radius(approach_angle(-out)) - LOBING.r0)[:, None] * out
    a = approach_directions(PROFILE, feat, raw, DEMO_TRANSFORM)
    first = raw + (LOBING.radius(approach_angle(a)) - LOBING.r0)[:, None] * a
    both = calibrated_points(PROFILE, feat, raw, DEMO_TRANSFORM, LOBING, parts=sim["part"])
    fillet = feat == "fillet"
    left_first = np.abs(np.sum((first - ideal) * out, axis=1))[fillet].max()
    left = np.abs(np.sum((both - ideal) * out, axis=1)).max()
    assert left_first > 0.07e-3  # the angle off nominal, times r'(theta)
    assert left < (0.002e-3 if noise == 0.0 else 0.02e-3) < 0.05e-3


def test_the_budget_line_is_the_calibrations_radius_uncertainty_at_the_approach():
    """All points of dia_24 are approached along -X (180 degrees): the calibration's
    share of its offset's variance is u(r(180 deg))^2 exactly (the radius moves every
    residual alike: the offset follows one for one, the rotation not at all)."""
    from piecs_bayes.uncertainty import LinearisedOptions, linearised_toolpath

    sim = simulate_parts(
        PROFILE, TRUTH, 1, probing=SimulatedProbing(
            ball_radius=1.0, transform=DEMO_TRANSFORM, points=FEW, noise_sd=SIGMA),
        probe=LOBING, rng=4,
    )  # fmt: skip
    pts = calibrated_points(PROFILE, sim["feature"], sim["points"], DEMO_TRANSFORM, LOBING)
    radius = RadiusComponents.from_calibration(LOBING)
    assert radius.names == tuple(f"probe_cal_{j}" for j in range(1, 6))
    u = linearised_toolpath(
        PROFILE, sim["feature"], pts, _fit(pts, sim, LOBING.r0), sigma=SIGMA,
        options=LinearisedOptions(
            ball_radius=LOBING.r0, transform=DEMO_TRANSFORM,
            source_sd={"x_centre": 0.001, **radius.source_sd}, radius=radius),
    )  # fmt: skip
    assert set(u.deviation_budget) == {"repeatability", "x_centre", CALIBRATION_SOURCE, "total"}
    i = [f.id for f in PROFILE.features].index("dia_24") * 2  # lines before it: 2 params each
    share = u.deviation_budget[CALIBRATION_SOURCE][i : i + 2]
    assert share[0] == pytest.approx(float(LOBING.radius_u([math.pi])[0]) ** 2, rel=1e-9)
    assert share[1] == pytest.approx(0.0, abs=1e-18)


def test_coverage_with_and_without_the_calibration():
    """The demo part probed sparsely by the lobing probe, 1.5 um noise. Fitted with one
    radius (declared 1 mm +- 0.5 um): the 4 um of r0 and the lobes push the parameter
    coverage far below 90 % (67 % measured at 300 parts; 100 parts here, where 90 % is
    5 binomial sds above it). Fitted with the calibration, each part's probe off it
    by a draw of its covariance: 95 %. 300 parts here, a window of 3 binomial sds
    (3.8 %); benchmarks/bench_calibration.py --probe counts 1,000."""
    kw = dict(points=FEW, margin=0.12, transform=DEMO_TRANSFORM, band_sims=2**13,
              probe=LOBING, seed=5)  # fmt: skip
    plain = coverage_check(PROFILE, TRUTH, CoverageOptions(calibrated=False, n_parts=100,
                           source_sd={"x_centre": 0.001, "ball_radius": 0.0005}, **kw))  # fmt: skip
    assert plain.rates["linearised"]["parameters"] < 0.90, plain.table()
    cal = coverage_check(PROFILE, TRUTH, CoverageOptions(calibrated=True, n_parts=300,
                         source_sd={"x_centre": 0.001}, **kw))  # fmt: skip
    half = 3.0 * math.sqrt(0.95 * 0.05 / 300)
    for kind, rate in cal.rates["linearised"].items():
        assert abs(rate - 0.95) <= half, (kind, cal.table())


@pytest.fixture
def calibrated_study(tmp_path):
    """The demo study with `[probe] calibration` (the lobing probe's file) and without
    the declared ball radius uncertainty."""
    for f in ("study.toml", "probe_part01.csv", "finish.ngc"):
        shutil.copy(DEMO / f, tmp_path / f)
    (tmp_path / "probe_cal.json").write_text(LOBING.to_json_text())
    text = (tmp_path / "study.toml").read_text()
    text = text.replace("ball_radius_u = 0.0005\n", 'calibration = "probe_cal.json"\n')
    text = text.replace('ball_radius = { dist = "normal", mean = 0.0, sd = 0.0005 }\n', "")
    (tmp_path / "study.toml").write_text(text)
    return tmp_path


def test_a_study_with_a_calibration_corrects_its_points_and_carries_the_source(
    calibrated_study,
):
    study = load_study(calibrated_study / "study.toml")
    assert study.probe.ball_radius == LOBING.r0 and study.probe.calibration is not None
    plain = load_study(DEMO / "study.toml")
    raw, corrected = load_probe_data(plain), load_probe_data(study)
    a = approach_directions(plain.profile, raw.feature, raw.points, plain.transform, raw.approach)
    first = raw.points + (LOBING.radius(approach_angle(a)) - LOBING.r0)[:, None] * a
    c = contact_directions(
        plain.profile, raw.feature, to_part_frame(plain.transform, first), a, raw.part
    )
    # the second pass: along the fitted normals, within a few mrad of the nominal ones
    turn = np.arccos(np.clip(np.sum(a * c, axis=1), -1, 1))
    assert 0.0 < turn.max() < 0.01
    shift = LOBING.radius(approach_angle(c)) - LOBING.r0
    np.testing.assert_allclose(corrected.points - raw.points, shift[:, None] * c, atol=1e-12)
    fit = fit_study(study, corrected)
    lin = toolpath_uncertainty(study, fit, corrected)["linearised"]
    assert CALIBRATION_SOURCE in lin.vertex_budget and "ball_radius" not in lin.vertex_budget


def test_the_bayesian_fit_samples_the_calibrations_components(calibrated_study):
    """The components are nuisance parameters with the calibration's normal priors; a
    part does not inform them, so their posterior sds stay near the prior's."""
    from piecs_bayes.jobs import bayes_study

    study = load_study(calibrated_study / "study.toml")
    post = bayes_study(study, nsteps=600, n_ensembles=1, progress=False, on_fail="ignore")
    radius = RadiusComponents.from_calibration(LOBING)
    assert set(radius.names) <= set(post.names)
    units = dict(zip(post.names, post.units, strict=True))
    assert all(units[n] == "mm" for n in radius.names)
    draws = {n: post.posterior.samples[:, post.names.index(n)] for n in radius.names}
    for n, sd in radius.source_sd.items():
        assert 0.6 * sd < float(np.std(draws[n])) < 1.4 * sd, n


def _edit(folder: Path, old: str, new: str) -> Path:
    p = folder / "study.toml"
    p.write_text(p.read_text().replace(old, new, 1))
    return p


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('calibration = "probe_cal.json"', 'calibration = "probe_cal.json"\nball_radius_u = 0.0005',
         r"probe\.ball_radius_u: 0\.0005 mm beside a calibration"),
        ("ball_radius = 1.0", "ball_radius = 1.5", r"r0 = 1\.0040 mm for a declared ball_radius of 1\.5"),
        ("tool = 9", "tool = 7", r"calibrates probe 'T9', the study's probe is tool 7"),
        ('calibration = "probe_cal.json"', 'calibration = "missing.json"',
         "missing.json: probe calibration file not found"),
        ("[uncertainty]", '[uncertainty]\nball_radius = { dist = "normal", mean = 0.0, sd = 0.0005 }',
         r"uncertainty\.ball_radius: a source beside \[probe\] calibration"),
        ('calibration = "probe_cal.json"', "calibration = 3", r"probe\.calibration: expected a file name"),
        ('calibration = "probe_cal.json"', 'calibration = "probe_cal.json"\ncalibration_max_age = 3',
         "calibration_max_age"),
    ],
)  # fmt: skip
def test_a_calibration_that_does_not_fit_the_study_is_refused(calibrated_study, old, new, message):
    path = _edit(calibrated_study, old, new)
    with pytest.raises(InputError, match=message):
        load_study(path)


def test_a_calibration_file_of_other_units_or_format_is_refused(calibrated_study):
    obj = LOBING.to_json()
    (calibrated_study / "probe_cal.json").write_text(json.dumps({**obj, "units": "in"}))
    with pytest.raises(InputError, match="the calibration is in 'in', the study in 'mm'"):
        load_study(calibrated_study / "study.toml")
    (calibrated_study / "probe_cal.json").write_text(json.dumps({**obj, "format": "other 2"}))
    with pytest.raises(InputError, match="not a probe calibration: format 'other 2'"):
        load_study(calibrated_study / "study.toml")
    bad = {**obj, "covariance": (-np.asarray(obj["covariance"])).tolist()}
    (calibrated_study / "probe_cal.json").write_text(json.dumps(bad))
    with pytest.raises(InputError, match="not symmetric positive semi-definite"):
        load_study(calibrated_study / "study.toml")


def test_a_calibration_at_another_feed_or_too_old_is_a_warning_in_the_report(calibrated_study):
    """Made at 200 mm/min: probing at 400 is a warning; made 2026-11-30: older than a
    `calibration_max_age_days` of 1 on 2026-12-02 is one. The main job issues them,
    lists the calibration among its inputs, and the report shows it (r(theta) figure)."""
    import datetime as dt
    from dataclasses import replace

    from piecs_bayes.export.report import report_html
    from piecs_bayes.jobs import JobOptions, calibration_warnings, run_job

    study = load_study(_edit(calibrated_study, "feed = 200.0", "feed = 400.0"))
    day = dt.date(2026, 12, 2)
    (msg,) = calibration_warnings(study.probe, today=day)
    assert "feed of 200 mm/min, the study probes at 400 mm/min" in msg
    old = replace(study.probe, feed=200.0, calibration_max_age_days=1.0)
    (msg,) = calibration_warnings(old, today=day)
    assert "is 2 days old (made 2026-11-30)" in msg
    assert calibration_warnings(replace(old, calibration_max_age_days=30.0), today=day) == []
    with pytest.warns(UserWarning, match="probing feed of 200 mm/min"):
        res = run_job(study, JobOptions(bayes=False))
    assert any("probing feed" in w for w in res.warnings)
    assert {i.role: i.path.name for i in res.inputs}["probe calibration"] == "probe_cal.json"
    html = report_html(res)
    assert "Probe calibration: r(θ)" in html and "probe_calibration" in html

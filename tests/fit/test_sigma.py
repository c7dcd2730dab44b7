"""The probe sigma rule (pooled over features, declared prior, Student-t) by known answers."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from piecs_bayes.decide import conformance, decide
from piecs_bayes.errors import InputError
from piecs_bayes.export.tables import fit_csv, fit_json
from piecs_bayes.fit import (
    FitOptions,
    coverage_factor,
    effective_dof,
    fit_feature,
    fit_profile,
    fit_profiles,
    probe_sigma,
    to_part_frame,
)
from piecs_bayes.fit.mcmc import ScaledInvChi2
from piecs_bayes.io import load_study
from piecs_bayes.jobs import bayes_sources, fit_study
from piecs_bayes.simulate import (
    DEMO_ERRORS,
    DEMO_TRANSFORM,
    SimulatedProbing,
    demo_profile,
    process_deviations,
    simulate_parts,
)

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"
PROFILE = demo_profile()
TRUTH = process_deviations(PROFILE, DEMO_ERRORS)
FEW = {"face_end": 3, "dia_24": 8, "taper": 4, "dia_30": 5, "fillet": 5, "shoulder": 6, "dia_44": 7}


def test_rule_is_the_conjugate_update():
    s = probe_sigma(2.3e-5, 12, declared=0.0015, declared_dof=8.0)
    assert s.value == pytest.approx(math.sqrt((8 * 0.0015**2 + 2.3e-5) / 20), rel=1e-14)
    assert (s.dof, s.source, s.pooled_dof) == (20.0, "pooled+declared", 12)
    assert s.pooled_sd == pytest.approx(math.sqrt(2.3e-5 / 12))
    alone = probe_sigma(2.3e-5, 12, declared=0.0015, declared_dof=0.0)
    assert (alone.value, alone.dof, alone.source) == (
        pytest.approx(math.sqrt(2.3e-5 / 12)),
        12,
        "pooled",
    )
    known = probe_sigma(2.3e-5, 12, declared=0.0015, known=True)
    assert (known.value, known.dof, known.source) == (0.0015, math.inf, "declared")
    prior = probe_sigma(0.0, 0, declared=0.0015)
    assert (prior.value, prior.dof, prior.source) == (0.0015, 8.0, "prior")
    with pytest.raises(InputError, match="no degrees of freedom"):
        probe_sigma(0.0, 0)
    with pytest.raises(InputError, match="all zero"):
        probe_sigma(0.0, 5)
    assert "46 dof" not in repr(s) and "20 dof" in repr(s)
    assert json.dumps(known.as_dict())  # inf is written as null
    assert known.as_dict()["dof"] is None


def test_scaled_inverse_chi2_prior_is_scipys_invgamma_of_the_variance():
    p = ScaledInvChi2(8.0, 0.0015)
    x = np.array([0.0008, 0.0012, 0.0015, 0.002, 0.004])
    ref = stats.invgamma(a=4.0, scale=8.0 * 0.0015**2 / 2.0)
    want = ref.logpdf(x**2) + np.log(2.0 * x)  # density of sigma from that of sigma^2
    np.testing.assert_allclose(np.asarray(p.log_pdf(x)), want, rtol=1e-12)
    assert float(p.log_pdf(-1e-3)) == -np.inf
    draws = p.sample(np.random.default_rng(0), 400_000)
    assert draws.mean() == pytest.approx(p.mean, rel=3e-3)
    assert draws.std() == pytest.approx(p.sd, rel=1e-2)


def test_welch_satterthwaite_and_coverage_factors():
    assert effective_dof(math.sqrt(2.0), 1.0, 10.0) == pytest.approx(40.0)
    assert effective_dof(1.0, 1.0, math.inf) == math.inf
    assert effective_dof(1.0, 0.0, 5.0) == math.inf  # no Type A share
    assert coverage_factor(math.inf) == pytest.approx(1.959963985, rel=1e-9)
    assert coverage_factor(10.0) == pytest.approx(2.228138852, rel=1e-9)
    np.testing.assert_allclose(
        coverage_factor(np.array([10.0, np.inf])), [2.228138852, 1.959964], rtol=1e-6
    )


def _sparse_part(seed=1, noise=0.0015):
    sim = simulate_parts(
        PROFILE, TRUTH, 1, rng=seed, probing=SimulatedProbing(
            ball_radius=1.0, transform=DEMO_TRANSFORM, points=FEW, noise_sd=noise, margin=0.12),
    )  # fmt: skip
    return sim["feature"], to_part_frame(DEMO_TRANSFORM, sim["points"]), sim


def test_a_five_point_arc_gets_the_parts_pooled_sigma_not_its_own():
    ids, centres, _ = _sparse_part()
    fit = fit_profile(PROFILE, ids, centres, ball_radius=1.0, options=FitOptions(
        method="robust", scale=1.345 * 0.0015, declared=0.0015, solver="lm"))  # fmt: skip
    s = fit.sigma
    flagged = sum(len(f.outliers) for f in fit)  # robust fits pool their inliers
    assert s.source == "pooled+declared" and s.pooled_dof == 38 - 15 - flagged
    assert s.dof == 8 + s.pooled_dof
    arc = fit["fillet"]
    assert arc.n == 5 and arc.residual_dof == 2
    unit = fit_feature(arc.feature, centres[ids == "fillet"], ball_radius=1.0,
                       options=FitOptions(method="robust", scale=1.345 * 0.0015, sigma=1.0))  # fmt: skip
    np.testing.assert_allclose(arc.covariance, s.value**2 * unit.covariance, rtol=1e-9)
    # the arc's own residual sd is far from sigma with 2 dof; the pooled one is not
    assert abs(s.value / 0.0015 - 1) < 0.35


def test_a_perfect_fit_reports_no_placeholder():
    ids, centres, _ = _sparse_part(noise=0.0)
    fit = fit_profile(PROFILE, ids, centres, ball_radius=1.0, options=FitOptions(
        method="robust", scale=0.002, declared=0.0015, solver="lm"))  # fmt: skip
    for f in fit:
        assert f.residual_sd < 1e-9  # was 1.0 (mm!) from the MAD's fallback
        assert f.result.residual_sd < 1e-9
    # no residual scatter: the declared prior alone (8 dof) against 23 dof of zeros
    assert fit.sigma.value == pytest.approx(0.0015 * math.sqrt(8 / 31), rel=1e-6)
    doc = json.loads(fit_json(fit))
    assert doc["probe_sigma"]["source"] == "pooled+declared" and doc["probe_sigma"]["dof"] == 31
    assert all(f["residual_sd"] < 1e-9 and f["sigma"]["dof"] == 31 for f in doc["features"])
    # without a declared value the data alone speak: (numerically) zero scatter
    bare = fit_profile(PROFILE, ids, centres, ball_radius=1.0, options=FitOptions(declared=None))
    assert bare.sigma.source == "pooled" and bare.sigma.value < 1e-9


def test_batch_fits_apply_the_rule_part_by_part():
    sim = simulate_parts(
        PROFILE, TRUTH, 6, rng=4, probing=SimulatedProbing(
            ball_radius=1.0, transform=DEMO_TRANSFORM, points=FEW, noise_sd=0.0015, margin=0.12),
    )  # fmt: skip
    centres = to_part_frame(DEMO_TRANSFORM, sim["points"])
    opts = FitOptions(method="robust", scale=1.345 * 0.0015, declared=0.0015)
    bf = fit_profiles(PROFILE, sim["part"], sim["feature"], centres, ball_radius=1.0, options=opts)
    for i, part in enumerate(bf.parts):
        rows = sim["part"] == part
        one = fit_profile(PROFILE, sim["feature"][rows], centres[rows], ball_radius=1.0,
                          options=dataclasses.replace(opts, solver="lm"))  # fmt: skip
        assert bf.sigma[i] == pytest.approx(one.sigma.value, rel=1e-6)  # solvers agree to ~1e-10 mm
        assert bf.sigma_dof[i] == one.sigma.dof
        np.testing.assert_allclose(bf.covariance("fillet")[i], one["fillet"].covariance, rtol=1e-6)
        np.testing.assert_allclose(bf.residual_sd("taper")[i], one["taper"].residual_sd, rtol=1e-6)
        ps = bf.probe_sigma(part)
        assert (ps.source, ps.dof, ps.pooled_dof) == (
            one.sigma.source,
            one.sigma.dof,
            one.sigma.pooled_dof,
        )


def test_study_outputs_name_the_sigma_and_known_sigma_is_declared():
    study = load_study(DEMO)
    fit = fit_study(study)
    assert fit.sigma.source == "pooled+declared" and fit.sigma.dof == 46
    rows = fit_csv(fit).splitlines()
    head = rows[0].split(",")
    assert {"sigma_mm", "sigma_source", "sigma_dof", "residual_dof"} <= set(head)
    assert all(",pooled+declared," in r for r in rows[1:])
    known = dataclasses.replace(study, fit=dataclasses.replace(study.fit, known_sigma=True))
    kfit = fit_study(known)
    assert kfit.sigma.value == study.probe.repeatability and kfit.sigma.dof == math.inf
    assert ",declared,inf" in fit_csv(kfit)
    doc = json.loads(fit_json(kfit), parse_constant=lambda c: pytest.fail(f"non-JSON {c}"))
    assert doc["probe_sigma"]["dof"] is None and doc["probe_sigma"]["declared_dof"] is None
    # the Bayesian fit: sigma estimated with the declared prior unless known
    assert bayes_sources(study)["repeatability"] == dict(study.sources["repeatability"])
    plain = dataclasses.replace(
        study, sources={k: v for k, v in study.sources.items() if k != "repeatability"}
    )
    assert bayes_sources(plain)["repeatability"] == {
        "dist": "scaled_inv_chi2",
        "nu": 8.0,
        "scale": 0.0015,
    }
    assert "repeatability" not in bayes_sources(known)


def test_conformance_and_decisions_use_student_t():
    c = conformance(0.004, 0.002, (-0.01, 0.01), dof=5.0)
    k = stats.t.ppf(0.5 + 0.9544997361036416 / 2, 5.0)
    assert c.expanded == pytest.approx(k * 0.002, rel=1e-12)
    assert c.p_conform == pytest.approx(stats.t.cdf(3.0, 5) - stats.t.cdf(-7.0, 5), rel=1e-12)
    normal = conformance(0.004, 0.002, (-0.01, 0.01))
    assert normal.expanded == pytest.approx(0.004) and normal.p_conform > c.p_conform
    a = decide(tolerance=(-0.01, 0.01), mean=0.004, sd=0.0015)
    b = decide(tolerance=(-0.01, 0.01), mean=0.004, sd=0.0015, dof=math.inf)
    assert a == b  # inf is the normal model exactly
    t3 = decide(tolerance=(-0.01, 0.01), mean=0.004, sd=0.0015, dof=3.0)
    assert t3.dof == 3.0 and "3 effective degrees of freedom" in t3.reasons[0]
    # heavier tails: less sure the deviation exceeds the null band
    assert t3.p_exceed < a.p_exceed
    with pytest.raises(InputError, match="dof"):
        decide(tolerance=(-0.01, 0.01), mean=0.004, sd=0.0015, dof=0.0)

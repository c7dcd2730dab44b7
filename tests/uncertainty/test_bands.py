"""Pointwise and simultaneous bands: exact critical values and coverage by simulation.

Known answers: one parameter moving every point alike has max-|z| equal to
|z| (critical value 1.959964); independent points have the Sidak value
$\\Phi^{-1}((1 + p^{1/n})/2)$; Scheffe's bound for rank 3 is $\\sqrt{\\chi^2_{3,0.95}}$.
Coverage: a quadratic profile in z (3 parameters, the size of a feature model)
fitted by least squares to noisy points from a known truth, 400 times; the
simultaneous band must hold the whole true curve in 95 % of the fits (within
a 99.99 % binomial range) and the pointwise band clearly less often.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from piecs_bayes.errors import InputError
from piecs_bayes.uncertainty import Bands, bands_from_samples, bands_linear

N_SIM = 400
P = 0.95


def _binomial_range(n=N_SIM, p=P, level=0.9999):
    lo, hi = stats.binom.interval(level, n, p)
    return lo / n, hi / n


def test_critical_value_one_parameter_is_the_normal_quantile():
    g = np.ones(25)  # a pure offset: every point moves together
    b = bands_linear(np.zeros(25), 0.3**2 * np.outer(g, g), n_sim=2**14)
    assert b.crit_simultaneous == pytest.approx(
        stats.norm.ppf(0.975), abs=4 * b.crit_simultaneous_se
    )
    assert np.allclose(b.crit_pointwise, stats.norm.ppf(0.975))


@pytest.mark.parametrize("method", ["qmc", "mc"])
def test_critical_value_independent_points_is_sidak(method):
    n = 10
    exact = stats.norm.ppf((1.0 + P ** (1.0 / n)) / 2.0)
    b = bands_linear(np.zeros(n), np.diag(np.linspace(1.0, 4.0, n)), method=method, seed=1)
    assert b.crit_simultaneous_se < 0.01
    assert abs(b.crit_simultaneous - exact) <= 4 * b.crit_simultaneous_se
    # the same from Monte Carlo draws of the curve
    draws = np.random.default_rng(2).normal(size=(50_000, n)) * np.sqrt(np.linspace(1, 4, n))
    bs = bands_from_samples(draws, center=np.zeros(n))
    assert abs(bs.crit_simultaneous - exact) <= 4 * bs.crit_simultaneous_se
    assert np.all(np.abs(bs.crit_pointwise - stats.norm.ppf(0.975)) < 0.05)


def _design(z):
    return np.vander(z, 3, increasing=True)  # 1, z, z^2


Z_FIT = np.linspace(-1.0, 1.0, 30)
Z_GRID = np.linspace(-1.0, 1.0, 101)
BETA = np.array([0.010, -0.004, 0.006])  # mm: a tapered, slightly barrelled diameter
SIGMA = 0.002  # probe repeatability, mm


def test_scheffe_bound_and_ordering():
    x, g = _design(Z_FIT), _design(Z_GRID)
    cov = g @ (SIGMA**2 * np.linalg.inv(x.T @ x)) @ g.T
    sch = bands_linear(g @ BETA, cov, method="scheffe")
    assert sch.crit_simultaneous == pytest.approx(math.sqrt(stats.chi2.ppf(P, 3)), rel=1e-12)
    sch_t = bands_linear(g @ BETA, cov, method="scheffe", dof=27)
    assert sch_t.crit_simultaneous == pytest.approx(math.sqrt(3 * stats.f.ppf(P, 3, 27)))
    sim = bands_linear(g @ BETA, cov)
    # pointwise < simultaneous on a grid < Scheffe (the sup over all linear combinations)
    assert 1.96 < sim.crit_simultaneous < sch.crit_simultaneous
    assert 2.5 < sim.crit_simultaneous < 2.75  # DESIGN 8: ~2.7 for a 3-parameter profile
    assert sim.n_draws == 2**17 and sim.method == "linear-qmc"
    assert np.all(sim.simultaneous_upper - sim.simultaneous_lower > 0)
    assert np.all(sim.pointwise_upper < sim.simultaneous_upper)


def test_factor_and_covariance_give_the_same_band():
    x, g = _design(Z_FIT), _design(Z_GRID)
    cov_b = SIGMA**2 * np.linalg.inv(x.T @ x)
    factor = g @ np.linalg.cholesky(cov_b)
    a = bands_linear(g @ BETA, g @ cov_b @ g.T, dof=27)
    b = bands_linear(g @ BETA, factor=factor, dof=27)
    assert np.allclose(a.sd, b.sd, rtol=1e-12) and np.allclose(a.crit_pointwise, b.crit_pointwise)
    se = math.hypot(a.crit_simultaneous_se, b.crit_simultaneous_se)
    assert abs(a.crit_simultaneous - b.crit_simultaneous) <= 4 * se
    sch = bands_linear(g @ BETA, factor=np.hstack([factor, factor[:, :1]]), method="scheffe")
    assert sch.crit_simultaneous == pytest.approx(math.sqrt(stats.chi2.ppf(P, 3)))  # rank 3
    with pytest.raises(InputError, match="exactly one"):
        bands_linear(g @ BETA, g @ cov_b @ g.T, factor=factor)
    with pytest.raises(InputError, match="factor"):
        bands_linear(g @ BETA, factor=factor[:5])


def _simulate(estimated_sigma: bool):
    """N_SIM least-squares fits; -> (sim-cover, pw-cover, max|t| per fit, one Bands)."""
    rng = np.random.default_rng(11 if estimated_sigma else 10)
    x, g = _design(Z_FIT), _design(Z_GRID)
    xtx_inv = np.linalg.inv(x.T @ x)
    truth = g @ BETA
    dof = Z_FIT.size - 3
    base = None
    cover_s, cover_p, maxt = [], [], []
    for _ in range(N_SIM):
        y = x @ BETA + rng.normal(0.0, SIGMA, Z_FIT.size)
        bhat = xtx_inv @ x.T @ y
        s2 = np.sum((y - x @ bhat) ** 2) / dof if estimated_sigma else SIGMA**2
        factor = g @ np.linalg.cholesky(s2 * xtx_inv)  # U = L L^T, rank 3
        b = bands_linear(g @ bhat, factor=factor, dof=dof if estimated_sigma else None, n_sim=2**12)
        base = base or b
        cover_s.append(b.covers(truth))
        cover_p.append(b.covers(truth, "pointwise"))
        maxt.append(np.max(np.abs(g @ bhat - truth) / b.sd))
    return np.mean(cover_s), np.mean(cover_p), np.array(maxt), base


@pytest.mark.parametrize("estimated_sigma", [False, True], ids=["known-sigma", "estimated-sigma"])
def test_linear_bands_cover_the_true_curve_at_the_nominal_rate(estimated_sigma):
    sim_cov, pw_cov, maxt, b = _simulate(estimated_sigma)
    lo, hi = _binomial_range()
    assert lo <= sim_cov <= hi, sim_cov
    assert pw_cov < 0.88, pw_cov  # pointwise bands miss part of the curve far more often
    # the critical value agrees with the empirical 95 % quantile of max|t| over the fits
    q_lo, q_hi = np.quantile(maxt, _binomial_range(level=0.999))
    assert q_lo <= b.crit_simultaneous <= q_hi
    want_pw = stats.t.ppf(0.975, 27) if estimated_sigma else stats.norm.ppf(0.975)
    assert np.allclose(b.crit_pointwise, want_pw)  # 2.05 or 1.96
    assert b.crit_simultaneous > want_pw + 0.55  # ~2.6 / ~2.77


def test_sample_bands_cover_the_true_curve_at_the_nominal_rate():
    # Monte Carlo route: posterior draws of the 3 parameters (flat prior, known sigma:
    # N(bhat, sigma^2 (X'X)^-1)) pushed to the grid, bands from the draws
    rng = np.random.default_rng(12)
    x, g = _design(Z_FIT), _design(Z_GRID)
    cov_b = SIGMA**2 * np.linalg.inv(x.T @ x)
    chol = np.linalg.cholesky(cov_b)
    truth = g @ BETA
    cover_s = cover_p = 0
    crits = []
    for _ in range(N_SIM):
        y = x @ BETA + rng.normal(0.0, SIGMA, Z_FIT.size)
        bhat = np.linalg.solve(x.T @ x, x.T @ y)
        draws = (bhat + rng.standard_normal((2000, 3)) @ chol.T) @ g.T
        b = bands_from_samples(draws, center=g @ bhat)
        cover_s += b.covers(truth)
        cover_p += b.covers(truth, "pointwise")
        crits.append(b.crit_simultaneous)
    lo, hi = _binomial_range()
    assert lo <= cover_s / N_SIM <= hi
    assert cover_p / N_SIM < 0.88
    lin = bands_linear(truth, factor=g @ chol, n_sim=2**16)
    assert abs(np.mean(crits) - lin.crit_simultaneous) < 0.02


def test_band_object_and_inputs():
    b = bands_from_samples(np.random.default_rng(0).normal(size=(500, 4)))
    assert isinstance(b, Bands) and b.method == "samples" and b.n_draws == 500
    assert "simultaneous" in repr(b)
    inside = b.center.copy()
    outside = b.center + 10 * b.sd
    assert b.covers(inside) and not b.covers(outside, "pointwise")
    assert b.contains(outside).sum() == 0
    with pytest.raises(ValueError):
        b.center[0] = 1.0
    with pytest.raises(InputError, match="kind"):
        b.contains(inside, "both")
    # a point with no spread (a fixed vertex) is held exactly and ignored by the max
    draws = np.random.default_rng(1).normal(size=(1000, 3))
    draws[:, 1] = 0.5
    bz = bands_from_samples(draws)
    assert bz.sd[1] == 0.0 and bz.pointwise_lower[1] == bz.pointwise_upper[1] == 0.5
    with pytest.raises(InputError, match="expected"):
        bands_from_samples(np.zeros((5, 3)))
    with pytest.raises(InputError, match="center"):
        bands_from_samples(draws, center=np.zeros(2))
    with pytest.raises(InputError, match="shapes"):
        bands_linear(np.zeros(3), np.eye(2))
    with pytest.raises(InputError, match="method"):
        bands_linear(np.zeros(3), np.eye(3), method="exact")
    with pytest.raises(InputError, match="p:"):
        bands_linear(np.zeros(3), np.eye(3), p=95)
    zero = bands_linear(np.ones(3), np.zeros((3, 3)))
    assert zero.crit_simultaneous == 0.0 and np.all(zero.simultaneous_lower == 1.0)

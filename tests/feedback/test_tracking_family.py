"""The tracker's family spans the anchors (issue 41): every EWMA is a local level of the
grid, the grid follows a process where full feedback is best, and sampled inspection's
predictive intervals keep their coverage."""

import math
from dataclasses import replace

import numpy as np
import pytest

from piecs_bayes.feedback._policies import replay_runs
from piecs_bayes.feedback._tracking import (
    GRID_DYNAMICS,
    HYPER_GRID,
    U_REF,
    TrackModel,
    ewma_ratio,
    track,
)
from tests.helpers import three_sds, window_pass_rate

UM = 1e-3
TOL = (-10 * UM, 10 * UM)


def _steady_gain(q, r):
    """The steady-state Kalman gain of a local level (walk q, observation variance r)
    by iterating the Riccati recursion."""
    p = q
    for _ in range(10_000):
        p_new = p * r / (p + r) + q
        if abs(p_new - p) <= 1e-18 * p:
            break
        p = p_new
    return p / (p + r)


@pytest.mark.parametrize("lam", [0.02, 0.1, 0.25, 0.4, 0.5, 0.75, 0.9, 0.95, 0.999])
def test_ewma_is_the_local_level_with_ratio_lam2_over_1_minus_lam(lam):
    """sigma_l^2 / (sigma_e^2 + u^2) = lambda^2 / (1 - lambda): the steady-state gain
    is lambda (the Riccati recursion, and the closed form P = (q + sqrt(q^2 + 4qr)) / 2)."""
    r = (1.5 * UM) ** 2 + U_REF**2
    q = ewma_ratio(lam) ** 2 * r
    assert _steady_gain(q, r) == pytest.approx(lam, abs=1e-9)
    p = (q + math.sqrt(q * q + 4 * q * r)) / 2
    assert p / (p + r) == pytest.approx(lam, abs=1e-12)


def test_the_grid_holds_every_ewma_weight_of_its_family():
    """Each local level of the grid (no drift) on parts measured with u = U_REF filters
    as the EWMA of its weight: after convergence, level = prediction + lambda x
    innovation (the filter itself, to 1e-9 in the gain)."""
    lams = sorted({lam for lam, drift, walk in GRID_DYNAMICS if drift == "none" and lam > 0})
    assert lams[0] <= 0.1 and lams[-1] >= 0.95  # from slow to full feedback's limit
    rng = np.random.default_rng(5)
    y = np.cumsum(rng.normal(0, 1.0, 300)) * UM + rng.normal(0, 1.5, 300) * UM
    for lam in lams:
        m = next(g for g in HYPER_GRID if g.scatter_sd == pytest.approx(2.0 * UM)
                 and g.drift0_sd == 0 and g.drift_sd == 0
                 and g.level_sd == pytest.approx(ewma_ratio(lam) * math.hypot(2.0 * UM, U_REF)))  # fmt: skip
        tr = track(y, U_REF, model=replace(m, step_prob=0.0, outlier_prob=0.0))
        k = np.arange(250, 300)
        gain = (tr.level[k] - tr.pred_mean[k]) / (y[k] - tr.pred_mean[k])
        np.testing.assert_allclose(gain, lam, atol=1e-9)


def _level_walk(rng, runs, parts, walk=3.0, scatter=0.3):
    level = rng.normal(0, 4, (runs, 1)) + np.cumsum(
        np.hstack([np.zeros((runs, 1)), rng.normal(0, walk, (runs, parts - 1))]), axis=1
    )
    u = rng.uniform(0.8, 1.2, (runs, parts))
    dev = level + rng.normal(0, scatter, (runs, parts)) + u * rng.standard_normal((runs, parts))
    return dev * UM, u * UM


def test_bayes_follows_a_process_where_full_feedback_is_best():
    """A level random walk of 3 µm/part with 0.3 µm scatter (u ~ 1 µm; the known
    process's Kalman gain is 0.9): EWMA lambda = 1 beats the shop's lambda = 0.4 by
    14 %; bayes, which must learn that the process walks, is within 8 % of lambda = 1
    (1.060 on these runs) and 5 % below lambda = 0.4 (0.915). Over 60 runs x 30 parts
    the pooled RMS ratio has a bootstrap sd of about 0.01."""
    rng = np.random.default_rng(41)
    dev, u = _level_walk(rng, 60, 30)

    def rms(policy, st):
        c, _, _ = replay_runs(dev, u, policy=policy, settings=st, tolerance=TOL)
        return float(np.sqrt(np.mean((dev + c)[:, 1:] ** 2)))

    full, shop = rms("ewma", {"lam": 1.0}), rms("ewma", {"lam": 0.4})
    bayes = rms("bayes", {})
    assert full < 0.9 * shop
    assert bayes <= 1.08 * full, (bayes / full, bayes, full)
    assert bayes <= 0.95 * shop, (bayes / shop, bayes, shop)


def _sampled_pit(model, runs=120, parts=46, seed=7):
    rng = np.random.default_rng(seed)
    k = np.arange(parts)[None, :]
    level = rng.normal(0, 4, (runs, 1)) + 0.15 * k
    u = rng.uniform(0.8, 1.2, (runs, parts))
    dev = level + rng.normal(0, 1.5, (runs, parts)) + u * rng.standard_normal((runs, parts))
    st = {} if model is None else {"model": model}
    _, _, pit = replay_runs(dev * UM, u * UM, policy="bayes", settings=st, tolerance=TOL,
                            inspect_every=5)  # fmt: skip
    p = pit[:, 1:]
    p = p[np.isfinite(p)]
    assert p.size == runs * 9
    return p


def _within_three_sds(p):
    n = p.size
    window = three_sds(n)
    assert window_pass_rate(window, n, 0.95) > 0.99  # a calibrated predictive passes
    cover = float(np.mean((p >= 0.025) & (p <= 0.975)))
    assert window[0] <= cover <= window[1], (cover, window)


def test_sampled_inspection_with_a_step_hazard_covers_95_percent():
    """Every 5th part measured (wear 0.15 µm/part, scatter 1.5 µm, no steps) and a
    model with a 2 % undeclared-step hazard: the 95 % one-step-ahead intervals of the
    measured parts cover within 3 binomial sds of 0.95 (1,080 predictions: 0.930-0.970).
    With the hazard per part (five parts' worth over a gap of five, issue 28) the same
    intervals covered 100 %."""
    m = TrackModel(level_sd=0.0, drift_sd=0.0, scatter_sd=1.5 * UM, step_prob=0.02,
                   outlier_prob=0.0, drift0_mean=0.15 * UM, drift0_sd=0.05 * UM)  # fmt: skip
    _within_three_sds(_sampled_pit(m))


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="the grid's 95 % intervals over-cover on sampled inspection (about 0.98 on "
    "these runs, 0.98-0.99 in benchmarks/bench_feedback.py's inspect 1/5): with 9 "
    "measurements a run, the first four predictives still mix the prior's scatters, "
    "drifts and odd-part rate and cover 100 %; the same tracker given the process "
    "covers 0.95 (the test above, docs/feedback.md)",
)
def test_predictive_coverage_of_sampled_inspection_is_95_percent():
    """The grid-averaged tracker on the runs above: within 3 binomial sds of 0.95."""
    _within_three_sds(_sampled_pit(None))


def test_a_step_hazard_is_carried_by_the_measured_part_that_ends_a_gap():
    """The undeclared-step probability is per measurement: a run measured every 5th
    part has the prior step weight p_step at each measured part, not 5 p_step."""
    m = TrackModel(level_sd=0.0, drift_sd=0.0, scatter_sd=1.0 * UM, step_prob=0.02,
                   outlier_prob=0.0, drift0_sd=0.0)  # fmt: skip
    y = np.full(11, np.nan)
    y[::5] = [0.0, 0.5, -0.3]
    tr = track(y * UM, UM, model=m)
    # the predictive of part 5: the regular component and the step one, 0.98 : 0.02
    w = tr.pred_weights[5]
    step_share = float(np.sum(w[tr.pred_sds[5] > 5 * UM]))
    assert step_share == pytest.approx(0.02, abs=1e-9)

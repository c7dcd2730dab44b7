"""Sampled inspection, late results and a transient drift: known answers.

A part without a measurement is a prediction step of the filter (checked against the
joint normal of the run written out without that part, and against the closed-form
prediction), the level several parts ahead is the closed-form prediction, a decaying
drift is the joint normal's, and the closed loop with every part measured at once and
unit gain is the replay of `_feedback`.
"""

import math

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.feedback._filter import mixture_filter
from piecs_bayes.feedback._policies import POLICIES, TUNING_GRIDS, replay, replay_runs
from piecs_bayes.feedback._replay import schedule
from piecs_bayes.feedback._tracking import TrackModel, model_params, track

UM = 1e-3
TOL = (-10 * UM, 10 * UM)


def _gauss(**kw):
    base = dict(level_sd=0.3 * UM, drift_sd=0.1 * UM, scatter_sd=1.0 * UM, step_sd=8 * UM,
                step_prob=0.0, outlier_prob=0.0, drift0_sd=0.5 * UM, level0_sd=5 * UM,
                drift0_mean=0.2 * UM)  # fmt: skip
    base.update(kw)
    return TrackModel(**base)


def _dense(m, u, n_lev):
    """Loadings of levels 0..n_lev-1 and of y_0..y_{n-1} on independent normals, and
    the levels' prior means, for the model with `drift_decay` (no steps, no changes)."""
    n = len(u)
    n_src = 2 + 2 * n_lev + n
    lev = np.zeros((n_lev, n_src))
    dri = np.zeros((n_lev, n_src))
    mean = np.zeros(n_lev)
    dmean = np.zeros(n_lev)
    lev[0, 0], dri[0, 1], dmean[0] = m.level0_sd, m.drift0_sd, m.drift0_mean
    for k in range(1, n_lev):
        lev[k] = lev[k - 1] + dri[k - 1]
        lev[k, 2 + 2 * k] = m.level_sd
        mean[k] = mean[k - 1] + dmean[k - 1]
        dri[k] = m.drift_decay * dri[k - 1]
        dri[k, 3 + 2 * k] = m.drift_sd
        dmean[k] = m.drift_decay * dmean[k - 1]
    ys = lev[:n].copy()
    for k in range(n):
        ys[k, 2 + 2 * n_lev + k] = math.sqrt(m.scatter_sd**2 + u[k] ** 2)
    return lev, ys, mean


def _cond(row, ys, y, idx, m_row, mean):
    yy = ys[idx]
    say = row @ yy.T
    gain = np.linalg.solve(yy @ yy.T, say.T).T
    return float((m_row + gain @ (y[idx] - mean[idx]))[0]), float(
        np.sum(row**2) - np.sum(gain * say)
    )


@pytest.mark.parametrize("decay", [1.0, 0.7])
def test_a_part_not_measured_is_a_prediction_step(decay):
    """Parts 2 and 3 not measured: every predictive, filtered level and the evidence
    equal the joint normal conditioned on the measured parts only."""
    m = _gauss(drift_decay=decay)
    u = np.array([1.0, 1.5, 0.8, 1.2, 0.9, 1.1]) * UM
    y = np.array([3.0, 4.5, np.nan, np.nan, 6.0, 7.5]) * UM
    seen = [0, 1, 4, 5]
    lev, ys, mean = _dense(m, u, 8)
    tr = track(y, u, model=m)
    loglik = 0.0
    for k in range(6):
        before = [i for i in seen if i < k]
        pm, pv = _cond(ys[k : k + 1], ys, y, before, mean[k], mean)
        assert tr.pred_mean[k] == pytest.approx(pm, abs=1e-12)
        assert tr.pred_sd[k] == pytest.approx(math.sqrt(pv), rel=1e-9)
        if k in seen:
            loglik += -0.5 * (math.log(2 * math.pi * pv) + (y[k] - pm) ** 2 / pv)
        fm, fv = _cond(lev[k : k + 1], ys, y, [i for i in seen if i <= k], mean[k], mean)
        assert tr.level[k] == pytest.approx(fm, abs=1e-12)
        assert tr.level_sd[k] == pytest.approx(math.sqrt(fv), rel=1e-9)
        sm, sv = _cond(lev[k : k + 1], ys, y, seen, mean[k], mean)
        assert tr.smooth_level[k] == pytest.approx(sm, abs=1e-12)
        assert tr.smooth_level_sd[k] == pytest.approx(math.sqrt(sv), rel=1e-7)
    assert tr.loglik == pytest.approx(loglik, rel=1e-9)
    assert np.isnan(tr.pit(y)[2]) and np.isnan(tr.pit(y)[3])


def test_levels_ahead_are_the_closed_form_prediction():
    """From the filtered (level, drift) after part k, the level h parts on is
    $\\ell + d (1 + \\phi + \\dots + \\phi^{h-1})$ with the variance of $F^h P F^{hT}$
    plus the walks; and column 1 is the next part's predictive."""
    phi = 0.8
    m = _gauss(drift_decay=phi, drift_sd=0.2 * UM)
    u = np.array([1.0, 1.2, 0.9, 1.1, 1.0]) * UM
    y = np.array([1.0, 2.5, 3.0, 4.2, 4.0]) * UM
    out = mixture_filter(y[None], (u**2)[None], model_params((m,)), np.zeros(5, bool), ahead=4)
    lev, ys, mean = _dense(m, u, 10)
    for k in range(5):
        for h in range(1, 5):
            em, ev = _cond(lev[k + h : k + h + 1], ys, y, list(range(k + 1)), mean[k + h], mean)
            assert out["am"][0, k, h - 1] == pytest.approx(em, abs=1e-12)
            assert out["av"][0, k, h - 1] == pytest.approx(ev, rel=1e-9)
        if k < 4:
            assert out["am"][0, k, 0] == pytest.approx(out["lm"][0, k + 1], abs=1e-15)
    assert out["am"][0, 4, 0] == pytest.approx(out["next_m"][0], abs=1e-15)


def test_the_mixture_with_a_missing_part_keeps_its_weights_and_predicts():
    """With odd parts and steps in the model, an unmeasured part adds no evidence, is
    never odd, and the next measured part's predictive is the two-step prediction."""
    m = TrackModel(level_sd=0.2 * UM, drift_sd=0.0, scatter_sd=1.0 * UM, step_prob=0.02,
                   outlier_prob=0.05, drift0_sd=0.3 * UM)  # fmt: skip
    y = np.array([0.0, 1.0, np.nan, 2.0, 1.5]) * UM
    out = mixture_filter(y[None], np.full((1, 5), UM**2), model_params((m,)), np.zeros(5, bool),
                         ahead=2)  # fmt: skip
    assert out["loglik"][0, 2] == 0.0
    assert out["p_filt"][0, 2, 1] < 1e-12
    assert out["lm"][0, 3] == pytest.approx(out["am"][0, 1, 1], abs=1e-15)
    assert out["lv"][0, 3] == pytest.approx(out["av"][0, 1, 1], rel=1e-12)


def test_the_schedule():
    inspected, source = schedule(12, 5, 1)
    assert np.flatnonzero(inspected).tolist() == [0, 5, 10]
    assert source.tolist() == [-1, -1, 0, -1, -1, -1, -1, 5, -1, -1, -1, -1]
    with pytest.raises(InputError):
        schedule(5, 0, 0)
    with pytest.raises(InputError):
        schedule(5, 1, -1)


def _runs(seed=5, r=6, n=25):
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    dev = rng.normal(0, 4, (r, 1)) + 0.4 * k + rng.normal(0, 1.5, (r, n))
    return dev * UM, rng.uniform(0.8, 1.2, (r, n)) * UM


@pytest.mark.parametrize("policy", POLICIES)
def test_every_part_measured_at_once_is_the_plain_replay(policy):
    """`inspect_every = 1`, `delay = 0`, `gain = 1` are the defaults: the same loop."""
    dev, u = _runs()
    st = TUNING_GRIDS[policy][min(3, len(TUNING_GRIDS[policy]) - 1)]
    a = replay_runs(dev, u, policy=policy, settings=st, tolerance=TOL)
    b = replay_runs(dev, u, policy=policy, settings=st, tolerance=TOL, inspect_every=1,
                    delay=0, gain=np.ones(dev.shape[0]))  # fmt: skip
    np.testing.assert_array_equal(a[0], b[0])


@pytest.mark.parametrize("policy", ["ewma", "fixed_gain", "bayes"])
def test_sampled_and_late_corrections_change_only_when_a_result_arrives(policy):
    dev, u = _runs(n=30)
    st = TUNING_GRIDS[policy][min(2, len(TUNING_GRIDS[policy]) - 1)]
    c, _, pit = replay_runs(dev, u, policy=policy, settings=st, tolerance=TOL,
                            inspect_every=5, delay=1)  # fmt: skip
    _, source = schedule(30, 5, 1)
    changes = np.flatnonzero(np.any(np.diff(c, axis=1) != 0, axis=0)) + 1
    assert set(changes) <= set(np.flatnonzero(source >= 0).tolist())
    assert np.all(c[:, :2] == 0)  # part 0's result arrives after part 1 is cut
    if pit is not None:
        assert np.all(np.isnan(pit[:, [1, 2, 3, 4, 6]])) and np.all(np.isfinite(pit[:, 5]))


def test_the_result_that_arrives_late_is_the_one_the_policy_uses():
    """ewma with lambda = 1 and a delay of 2: c_k = -(part k - 3's uncompensated value)."""
    dev, u = _runs(r=3, n=12)
    c, _, _ = replay_runs(dev, u, policy="ewma", settings={"lam": 1.0}, tolerance=TOL, delay=2)
    np.testing.assert_allclose(c[:, 3:], -dev[:, :-3], atol=1e-15)
    assert np.all(c[:, :3] == 0)


def test_the_gain_of_a_correction_moves_the_realised_part():
    dev, u = _runs(r=1, n=15)
    res = replay(dev[0], u[0], policy="ewma", settings={"lam": 0.5}, tolerance=TOL, gain=0.7)
    np.testing.assert_allclose(res.realised, dev[0] + 0.7 * res.corrections, atol=1e-15)
    # the policy sees r - c = dev - 0.3 c: its correction is not the unit-gain one
    one = replay(dev[0], u[0], policy="ewma", settings={"lam": 0.5}, tolerance=TOL)
    assert not np.allclose(res.corrections, one.corrections)


@pytest.mark.parametrize(("every", "delay"), [(5, 0), (5, 1), (1, 2), (3, 1)])
def test_next_part_is_the_replays_correction_when_the_result_arrives(every, delay):
    """The measured parts so far (every `every`-th, realised with the replay's
    corrections) and `applied`: `next_part` gives the correction the replay decides
    when the last result arrives, for the parts it holds it for."""
    from piecs_bayes.feedback._policies import next_part

    dev, u = _runs(seed=8, r=1, n=40)
    res = replay(dev[0], u[0], policy="bayes", settings={}, tolerance=TOL,
                 inspect_every=every, delay=delay)  # fmt: skip
    _, source = schedule(40, every, delay)
    k = int(np.flatnonzero(source >= 0)[-2])  # a decision with a result before it
    j = int(source[k])
    idx = np.arange(0, j + 1, every)
    nxt = next_part(res.realised[idx], u[0, idx], tolerance=TOL, applied=res.corrections[idx],
                    inspect_every=every, delay=delay)  # fmt: skip
    assert nxt["correction"] == pytest.approx(res.corrections[k], abs=1e-7 * UM)

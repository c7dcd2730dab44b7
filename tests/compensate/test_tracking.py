"""Part-to-part tracking: known answers for the Kalman filter, the smoother and the mixture."""

import math

import numpy as np
import pytest

from piecs_bayes.compensate._tracking import (
    HYPER_GRID,
    TrackModel,
    fit_track_model,
    fit_transfer,
    track,
)
from piecs_bayes.errors import InputError

UM = 1e-3


def _gaussian(**kw):
    base = dict(level_sd=0.3 * UM, drift_sd=0.1 * UM, scatter_sd=1.0 * UM, step_sd=8 * UM,
                step_prob=0.0, outlier_prob=0.0, drift0_sd=0.5 * UM, level0_sd=5 * UM)  # fmt: skip
    base.update(kw)
    return TrackModel(**base)


def _joint(model, u, declared):
    """The 4-part run as one multivariate normal: the loadings of (levels 0..n, y 0..n-1)
    on independent standard normals, written out from the model's equations."""
    n = len(u)
    # independent sources: level0, drift0, (w_k, v_k, step_k) for k=1..n, e_k for k<n
    n_src = 2 + 3 * n + n
    lev = np.zeros((n + 1, n_src))
    dri = np.zeros((n + 1, n_src))
    lev[0, 0] = model.level0_sd
    dri[0, 1] = model.drift0_sd
    for k in range(1, n + 1):
        j = 2 + 3 * (k - 1)
        lev[k] = lev[k - 1] + dri[k - 1]
        lev[k, j] = model.level_sd
        if k < n and declared[k]:
            lev[k, j + 2] = model.step_sd
        dri[k] = dri[k - 1]
        dri[k, j + 1] = model.drift_sd
    ys = lev[:n].copy()
    for k in range(n):
        ys[k, 2 + 3 * n + k] = math.sqrt(model.scatter_sd**2 + u[k] ** 2)
    return lev, ys


def _condition(a_rows, y_rows, y, idx):
    """Mean and variance of each `a_rows` given y[idx] (zero prior mean)."""
    if len(idx) == 0:
        return np.zeros(len(a_rows)), np.sum(a_rows**2, 1)
    yy = y_rows[idx]
    syy = yy @ yy.T
    say = a_rows @ yy.T
    gain = np.linalg.solve(syy, say.T).T
    mean = gain @ y[idx]
    var = np.sum(a_rows**2, 1) - np.sum(gain * say, 1)
    return mean, var


def test_gaussian_filter_and_smoother_equal_the_joint_normal():
    u = np.array([1.0, 1.5, 0.8, 1.2]) * UM
    y = np.array([3.0, 4.5, 14.0, 15.5]) * UM
    declared = np.array([False, False, True, False])
    m = _gaussian()
    lev, ys = _joint(m, u, declared)
    tr = track(y, u, model=m, tool_changes=(2,))
    loglik = 0.0
    for k in range(4):
        pm, pv = _condition(ys[k : k + 1], ys, y, list(range(k)))
        assert tr.pred_mean[k] == pytest.approx(pm[0], abs=1e-12)
        assert tr.pred_sd[k] == pytest.approx(math.sqrt(pv[0]), rel=1e-9)
        loglik += -0.5 * (math.log(2 * math.pi * pv[0]) + (y[k] - pm[0]) ** 2 / pv[0])
        fm, fv = _condition(lev[k : k + 1], ys, y, list(range(k + 1)))
        assert tr.level[k] == pytest.approx(fm[0], abs=1e-12)
        assert tr.level_sd[k] == pytest.approx(math.sqrt(fv[0]), rel=1e-9)
        sm, sv = _condition(lev[k : k + 1], ys, y, [0, 1, 2, 3])
        assert tr.smooth_level[k] == pytest.approx(sm[0], abs=1e-12)
        assert tr.smooth_level_sd[k] == pytest.approx(math.sqrt(sv[0]), rel=1e-7)
    nm, nv = _condition(lev[4:5], ys, y, [0, 1, 2, 3])
    assert tr.next_mean == pytest.approx(nm[0], abs=1e-12)
    assert tr.next_sd == pytest.approx(math.sqrt(nv[0]), rel=1e-9)
    assert tr.loglik == pytest.approx(loglik, rel=1e-9)
    assert tr.steps == (2,) and tr.tool_changes == (2,)
    # the 95 % predictive interval of a Gaussian model is mean ± 1.96 sd
    assert tr.pred_hi[1] == pytest.approx(tr.pred_mean[1] + 1.959964 * tr.pred_sd[1], rel=1e-5)


def test_diffuse_start_is_the_limit_of_a_wide_prior():
    u = np.array([1.0, 1.5, 0.8, 1.2, 1.0]) * UM
    y = np.array([3.0, 4.5, 4.0, 5.5, 6.0]) * UM
    diffuse = track(y, u, model=_gaussian(level0_sd=None))
    wide = track(y, u, model=_gaussian(level0_sd=10.0))
    assert np.isnan(diffuse.pred_mean[0])
    np.testing.assert_allclose(diffuse.level, wide.level, atol=1e-9)
    np.testing.assert_allclose(diffuse.level_sd, wide.level_sd, rtol=1e-4)
    np.testing.assert_allclose(diffuse.pred_mean[1:], wide.pred_mean[1:], atol=1e-9)
    np.testing.assert_allclose(diffuse.smooth_level, wide.smooth_level, atol=1e-9)
    assert diffuse.next_sd == pytest.approx(wide.next_sd, rel=1e-4)


def test_local_level_steady_state_is_an_ewma():
    """Local level (no drift): the steady-state Kalman gain K = P/(P + R) with
    P^2 - qP - qR = 0 turns the filter into an EWMA with lambda = K."""
    q, r = (0.5 * UM) ** 2, (2.0 * UM) ** 2
    m = TrackModel(level_sd=math.sqrt(q), drift_sd=0.0, scatter_sd=math.sqrt(r - UM**2),
                   step_prob=0.0, outlier_prob=0.0, drift0_sd=0.0)  # fmt: skip
    p = (q + math.sqrt(q * q + 4 * q * r)) / 2
    lam = p / (p + r)
    rng = np.random.default_rng(3)
    y = np.cumsum(rng.normal(0, 0.5, 200)) * UM + rng.normal(0, 2.0, 200) * UM
    tr = track(y, UM, model=m)
    # after convergence: next prediction = lam * y_k + (1 - lam) * previous prediction
    pred = tr.pred_mean
    ewma = lam * y[100:199] + (1 - lam) * pred[100:199]
    np.testing.assert_allclose(pred[101:200], ewma, atol=1e-12)
    assert tr.level[150] - pred[150] == pytest.approx(lam * (y[150] - pred[150]), abs=1e-12)


def test_an_odd_part_is_flagged_and_not_followed():
    rng = np.random.default_rng(4)
    y = 2 * UM + rng.normal(0, 1.2, 30) * UM
    y[15] += 40 * UM
    tr = track(y, np.full(30, UM))
    assert tr.p_outlier[15] > 0.95 and tr.p_step[15] < 0.05
    assert np.all(np.delete(tr.p_outlier, 15) < 0.5)
    assert abs(tr.pred_mean[16] - tr.pred_mean[15]) < 1 * UM
    assert abs(tr.level[15] - tr.level[14]) < 1 * UM
    assert 15 not in tr.steps and abs(tr.next_mean - 2 * UM) < 1.5 * UM


def test_a_declared_step_is_followed_in_one_part_and_an_undeclared_one_found():
    rng = np.random.default_rng(5)
    y = rng.normal(0, 1.0, 40) * UM
    y[20:] += 12 * UM
    declared = track(y, np.full(40, UM), tool_changes=(20,))
    assert abs(declared.pred_mean[21] - 12 * UM) < 2.5 * UM
    assert 20 in declared.steps and declared.tool_changes == (20,)
    found = track(y, np.full(40, UM))
    assert found.steps == (20,) and found.p_step[20] > 0.9
    assert abs(found.pred_mean[22] - 12 * UM) < 2.5 * UM
    assert abs(found.smooth_level[10]) < 1 * UM and abs(found.smooth_level[30] - 12 * UM) < 1 * UM


def test_short_runs_give_finite_answers():
    for n in (1, 2, 3):
        y = np.array([4.0, 5.0, 3.5][:n]) * UM
        m = fit_track_model(y, UM)
        assert m in HYPER_GRID
        for tr in (track(y, UM), track(y, UM, model=m)):
            assert math.isfinite(tr.next_mean) and math.isfinite(tr.next_sd)
            assert np.all(np.isfinite(tr.level)) and np.all(np.isfinite(tr.smooth_level_sd))
            assert np.all(np.isfinite(tr.pred_mean[1:])) and np.isnan(tr.pred_mean[0])


def test_empirical_bayes_finds_the_scatter_and_the_drift():
    rng = np.random.default_rng(6)
    n = 200
    y = (0.4 * np.arange(n) + rng.normal(0, 4.0, n) + rng.normal(0, 1.0, n)) * UM
    m = fit_track_model(y, UM)
    assert m.scatter_sd == pytest.approx(4 * UM, rel=0.4)
    assert m.drift0_sd > 0
    tr = track(y, UM)
    assert tr.next_mean == pytest.approx(0.4 * n * UM, abs=2 * UM)


def test_transfer_moves_the_next_part_prediction():
    y = np.array([4.0, 5.0, 3.5, 4.5]) * UM
    m = _gaussian(level0_sd=None)
    plain = track(y, UM, model=m)
    half = track(y, UM, model=m, transfer=(0.5, 0.1))
    assert half.next_mean == pytest.approx(0.5 * plain.next_mean)
    assert half.next_sd == pytest.approx(
        math.sqrt(0.25 * plain.next_sd**2 + 0.01 * plain.next_mean**2)
    )


def test_fit_transfer_recovers_beta():
    s = np.array([10.0, -8.0, 15.0, 4.0, -12.0, 7.0]) * UM
    beta, u_beta = fit_transfer(s, 0.3 * s, UM, 0.5 * UM)
    assert beta == pytest.approx(0.3, abs=1e-9) and 0 < u_beta < 0.05
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(200):
        true = rng.normal(0, 10, 20) * UM
        semi = true + rng.normal(0, 1.0, 20) * UM
        fin = 0.3 * true + rng.normal(0, 0.5, 20) * UM
        b, ub = fit_transfer(semi, fin, UM, 0.5 * UM)
        hits += abs(b - 0.3) < 2 * ub
    assert 0.9 < hits / 200 <= 1.0


def test_bad_inputs_are_refused():
    with pytest.raises(InputError, match="u must be"):
        track([0.001, 0.002], [0.001, 0.0])
    with pytest.raises(InputError, match="tool change"):
        track([0.001, 0.002], UM, tool_changes=(2,))
    with pytest.raises(InputError, match="step_prob"):
        TrackModel(0, 0, 0, step_prob=0.6, outlier_prob=0.5)
    with pytest.raises(InputError, match="transfer"):
        track([0.001, 0.002], UM, transfer=(1.0, -1.0))
    with pytest.raises(InputError, match="semifinish"):
        fit_transfer([0.0, 0.0], [0.0, 0.0], UM, UM)

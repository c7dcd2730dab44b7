"""Part-to-part tracking: known answers for the Kalman filter, the smoother and the mixture."""

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.feedback._filter import STEP_MEMORY, mixture_filter
from piecs_bayes.feedback._tracking import (
    GRID_DYNAMICS,
    GRID_LOG_PRIOR,
    GRID_ODD_RATES,
    GRID_PRIOR_WEIGHTS,
    GRID_SCATTER,
    GRID_STEP_RATES,
    HYPER_GRID,
    U_REF,
    TrackModel,
    ewma_ratio,
    fit_track_model,
    fit_transfer,
    model_params,
    track,
)

UM = 1e-3


def _gaussian(**kw):
    base = dict(level_sd=0.3 * UM, drift_sd=0.1 * UM, scatter_sd=1.0 * UM, step_sd=8 * UM,
                step_prob=0.0, outlier_prob=0.0, drift0_sd=0.5 * UM, level0_sd=5 * UM)  # fmt: skip
    base.update(kw)
    return TrackModel(**base)


def _joint(model, u, declared, steps=(), odd=()):
    """A short run as one multivariate normal: the loadings of (levels 0..n, y 0..n-1)
    on independent standard normals and their prior means, written out from the model's
    equations (a declared change at part k: a step, and the wear of the k - last parts
    cut since the previous change goes with the old edge; `steps`, `odd`: the parts
    with an undeclared step or odd, the indicators given)."""
    n = len(u)
    last = 0
    # independent sources: level0, drift0, (w_k, v_k, step_k) for k=1..n, e_k for k<n,
    # a step at part 0
    n_src = 2 + 3 * n + n + 1
    lev = np.zeros((n + 1, n_src))
    dri = np.zeros((n + 1, n_src))
    mean = np.zeros(n + 1)
    lev[0, 0] = model.level0_sd
    lev[0, -1] = model.step_sd * (0 in steps)
    dri[0, 1] = model.drift0_sd
    for k in range(1, n + 1):
        j = 2 + 3 * (k - 1)
        change = k < n and declared[k]
        f = 1.0 - model.wear_reset * (k - last) * change
        lev[k] = lev[k - 1] + f * dri[k - 1]
        mean[k] = mean[k - 1] + f * model.drift0_mean
        lev[k, j] = model.level_sd
        if change or k in steps:
            lev[k, j + 2] = model.step_sd
        if change:
            last = k
        dri[k] = dri[k - 1]
        dri[k, j + 1] = model.drift_sd
    ys = lev[:n].copy()
    for k in range(n):
        ys[k, 2 + 3 * n + k] = math.sqrt(
            model.scatter_sd**2 + u[k] ** 2 + (k in odd) * model.outlier_scale**2
        )
    return lev, ys, mean


def _cond(row, y_rows, y, idx, m_row, mean):
    """Mean and variance of the quantity with loadings `row` (1, n_src) and prior mean
    `m_row` given y[idx] (`mean`: the levels' prior means, y's are the first n)."""
    if len(idx) == 0:
        return m_row, float(np.sum(row**2))
    yy = y_rows[idx]
    say = row @ yy.T
    gain = np.linalg.solve(yy @ yy.T, say.T).T
    est = m_row + gain @ (y[idx] - mean[idx])
    return float(est[0]), float(np.sum(row**2) - np.sum(gain * say))


@pytest.mark.parametrize(
    ("wear_reset", "drift0_mean"), [(1.0, 0.0), (0.0, 0.0), (1.0, 0.4 * UM), (0.5, -0.2 * UM)]
)
def test_gaussian_filter_and_smoother_equal_the_joint_normal(wear_reset, drift0_mean):
    u = np.array([1.0, 1.5, 0.8, 1.2]) * UM
    y = np.array([3.0, 4.5, 14.0, 15.5]) * UM
    declared = np.array([False, False, True, False])
    m = _gaussian(wear_reset=wear_reset, drift0_mean=drift0_mean)
    lev, ys, mean = _joint(m, u, declared)
    tr = track(y, u, model=m, tool_changes=(2,))
    loglik = 0.0
    for k in range(4):
        pm, pv = _cond(ys[k : k + 1], ys, y, list(range(k)), mean[k], mean)
        assert tr.pred_mean[k] == pytest.approx(pm, abs=1e-12)
        assert tr.pred_sd[k] == pytest.approx(math.sqrt(pv), rel=1e-9)
        loglik += -0.5 * (math.log(2 * math.pi * pv) + (y[k] - pm) ** 2 / pv)
        fm, fv = _cond(lev[k : k + 1], ys, y, list(range(k + 1)), mean[k], mean)
        assert tr.level[k] == pytest.approx(fm, abs=1e-12)
        assert tr.level_sd[k] == pytest.approx(math.sqrt(fv), rel=1e-9)
        sm, sv = _cond(lev[k : k + 1], ys, y, [0, 1, 2, 3], mean[k], mean)
        assert tr.smooth_level[k] == pytest.approx(sm, abs=1e-12)
        assert tr.smooth_level_sd[k] == pytest.approx(math.sqrt(sv), rel=1e-7)
    nm, nv = _cond(lev[4:5], ys, y, [0, 1, 2, 3], mean[4], mean)
    assert tr.next_mean == pytest.approx(nm, abs=1e-12)
    assert tr.next_sd == pytest.approx(math.sqrt(nv), rel=1e-9)
    assert tr.loglik == pytest.approx(loglik, rel=1e-9)
    assert tr.steps == (2,) and tr.tool_changes == (2,)
    # the 95 % predictive interval of a Gaussian model is mean ± 1.96 sd
    assert tr.pred_hi[1] == pytest.approx(tr.pred_mean[1] + 1.959964 * tr.pred_sd[1], rel=1e-5)


def _exact_mixture(m, u, y):
    """Log marginal likelihood, next level's mean and p(step at k | all parts) summed
    over all 3^n indicator sequences, each sequence's run a joint normal."""
    n = len(y)
    pri = np.array([1 - m.step_prob - m.outlier_prob, m.outlier_prob, m.step_prob])
    logw, means, steps = [], [], []
    for seq in itertools.product(range(3), repeat=n):
        lev, ys, mean = _joint(m, u, np.zeros(n, bool), steps=[k for k in range(n) if seq[k] == 2],
                               odd=[k for k in range(n) if seq[k] == 1])  # fmt: skip
        cov = ys @ ys.T
        r = y - mean[:n]
        ll = -0.5 * (n * math.log(2 * math.pi) + np.linalg.slogdet(cov)[1]
                     + r @ np.linalg.solve(cov, r))  # fmt: skip
        logw.append(np.sum(np.log(pri[list(seq)])) + ll)
        means.append(mean[n] + (lev[n] @ ys.T) @ np.linalg.solve(cov, r))
        steps.append([s == 2 for s in seq])
    logw = np.array(logw)
    top = logw.max()
    w = np.exp(logw - top)
    return top + math.log(w.sum()), float(w @ means) / w.sum(), w @ np.array(steps) / w.sum()


@pytest.mark.parametrize("y", [[0, 0.5, 4.0, 3.2, 4.5, 3.0, 4.1], [1, 0, 0.5, 5.0, 4.0, 1.0, 0.5]])
def test_the_collapsed_filter_is_close_to_the_exact_mixture(y):
    """Against all 3^7 indicator sequences: a step or two odd parts that one part of
    hindsight cannot tell apart. With `STEP_MEMORY` parts of hindsight the filter's
    evidence, next level and step probabilities are those of the exact mixture; merging
    after one part (GPB2, memory 1) is off by more."""
    m = TrackModel(level_sd=0.0, drift_sd=0.0, scatter_sd=1.0 * UM, step_sd=8 * UM,
                   step_prob=0.05, outlier_prob=0.05, outlier_scale=20 * UM, drift0_sd=0.0,
                   level0_sd=5 * UM)  # fmt: skip
    y = np.array(y) * UM
    u = np.full(y.size, UM)
    loglik, next_mean, p_step = _exact_mixture(m, u, y)
    err = {}
    for memory in (1, STEP_MEMORY):
        out = mixture_filter(y[None], (u**2)[None], model_params((m,)), np.zeros(y.size, bool),
                             memory=memory)  # fmt: skip
        err[memory] = (abs(out["loglik"][0].sum() - loglik),
                       abs(out["next_m"][0] - next_mean) / UM,
                       np.max(np.abs(out["p_lag"][0, :, 2] - p_step)))  # fmt: skip
    assert err[STEP_MEMORY][0] < 0.005 and err[STEP_MEMORY][1] < 0.005
    assert err[STEP_MEMORY][2] < 0.015
    assert err[1][0] > 0.1 and err[1][2] > 0.2


def test_a_declared_tool_change_restarts_the_wear():
    """Wear 0.5 µm/part, a new edge at part 20 set 3 µm lower: the level of part 20 is
    about 3 - 20 x 0.5 = -7 µm below the old trend's prediction (the wear of the old
    edge goes with it), which `wear_reset = 0` (a step only) would not expect."""
    rng = np.random.default_rng(9)
    k = np.arange(30)
    level = 0.5 * np.where(k < 20, k, k - 20) - 3.0 * (k >= 20)
    y = (level + rng.normal(0, 0.8, 30)) * UM
    m = TrackModel(level_sd=0.0, drift_sd=0.0, scatter_sd=0.5 * UM, step_sd=8 * UM,
                   step_prob=0.0, outlier_prob=0.0, drift0_sd=0.5 * UM)  # fmt: skip
    new = track(y[:20], UM, model=m)
    assert new.next_mean == pytest.approx(10 * UM, abs=1 * UM)
    full = track(y, UM, model=m, tool_changes=(20,))
    assert full.pred_mean[20] == pytest.approx(0.0, abs=1 * UM)  # 10 - 20 x 0.5
    kept = track(y, UM, model=replace(m, wear_reset=0.0), tool_changes=(20,))
    assert kept.pred_mean[20] == pytest.approx(10 * UM, abs=1 * UM)


def test_the_grid_prior():
    """The grid (issue 41): per factor the trained weights of `GRID_PRIOR_WEIGHTS`:
    the scatter, the dynamics (an EWMA weight of the level walk relative to
    the noise, a drift: none, wear of the edge, which only leaves material, a
    half-normal rate of scale 0.3 µm/part by its mean and sd, either sign, a new edge's
    fast wear that slows, a transient of either sign; a drift walk), the odd-part and
    the undeclared-step rates."""
    w = np.exp(GRID_LOG_PRIOR)
    assert w.sum() == pytest.approx(1.0) and len(w) == len(HYPER_GRID)

    def share(pick):
        return sum(wi for wi, g in zip(w, HYPER_GRID, strict=True) if pick(g))

    for f, values, attr in (("odd", GRID_ODD_RATES, "outlier_prob"), ("step", GRID_STEP_RATES,
                                                                   "step_prob")):  # fmt: skip
        wf = np.array(GRID_PRIOR_WEIGHTS[f]) / np.sum(GRID_PRIOR_WEIGHTS[f])
        for v, wv in zip(values, wf, strict=True):
            assert share(lambda g, a=attr, v=v: getattr(g, a) == v) == pytest.approx(wv)
    ws = np.array(GRID_PRIOR_WEIGHTS["scatter"]) / np.sum(GRID_PRIOR_WEIGHTS["scatter"])
    for sc, wv in zip(GRID_SCATTER, ws, strict=True):
        assert share(lambda g, sc=sc: g.scatter_sd == pytest.approx(sc * UM)) == pytest.approx(wv)
    wd = np.array(GRID_PRIOR_WEIGHTS["dynamics"]) / np.sum(GRID_PRIOR_WEIGHTS["dynamics"])
    assert len(wd) == len(GRID_DYNAMICS)
    fixed = share(lambda g: g.level_sd == 0 and g.drift0_sd == 0)
    assert fixed == pytest.approx(wd[GRID_DYNAMICS.index((0.0, "none", 0.0))])
    wear = next(g for g in HYPER_GRID if g.drift0_mean > 0)
    assert wear.drift0_mean == pytest.approx(0.3 * UM * math.sqrt(2 / math.pi))
    assert wear.drift0_sd == pytest.approx(0.3 * UM * math.sqrt(1 - 2 / math.pi))
    assert all(g.wear_reset == 1 for g in HYPER_GRID)
    walks = {(lam, walk) for lam, _, walk in GRID_DYNAMICS}
    assert {0.0, 0.95} <= {lam for lam, _ in walks} and max(w_ for _, w_ in walks) > 0
    for g in HYPER_GRID:  # the level walk is an EWMA weight of the grid times the noise
        noise = math.hypot(g.scatter_sd, U_REF)
        assert any(g.level_sd == pytest.approx(ewma_ratio(lam) * noise, abs=1e-15)
                   for lam, _ in walks)  # fmt: skip


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


def test_mixture_quantile_is_the_root_of_the_mixture_cdf():
    """Newton's method in a bisection bracket: a normal's quantile in closed form, and
    two-component mixtures (one far and wide, as an odd part's) against a root finder."""
    from scipy import optimize, special, stats

    from piecs_bayes.feedback._mixture import mixture_cdf, mixture_quantile

    m, s = np.array([[0.003]]), np.array([[0.0015]])
    for p in (0.001, 0.025, 0.5, 0.975):
        q = mixture_quantile(p, np.ones((1, 1)), m, s)
        assert q[0] == pytest.approx(0.003 + 0.0015 * special.ndtri(p), abs=1e-15)
    rng = np.random.default_rng(3)
    w = np.stack([np.full(50, 0.97), np.full(50, 0.03)], 1)
    mm = np.stack([rng.normal(0, 0.004, 50), rng.normal(0, 0.04, 50)], 1)
    ss = np.stack([rng.uniform(0.001, 0.003, 50), np.full(50, 0.04)], 1)
    mm[7] = np.nan  # a part without a predictive stays NaN
    for p in (0.025, 0.975):
        q = mixture_quantile(p, w, mm, ss)
        assert np.isnan(q[7]) and np.all(np.isfinite(np.delete(q, 7)))
        for i in (0, 13, 42):
            cdf = lambda x, i=i, p=p: float(np.sum(w[i] * stats.norm.cdf(x, mm[i], ss[i]))) - p  # noqa: E731
            assert q[i] == pytest.approx(optimize.brentq(cdf, -1, 1, xtol=1e-16), abs=1e-13)
            assert float(mixture_cdf(q[i], w[i], mm[i], ss[i])) == pytest.approx(p, abs=1e-12)
    # rows leave the iteration as they converge: each row alone gives its batch value,
    # and leading dimensions keep their shape (NaN rows included)
    q = mixture_quantile(0.975, w.reshape(5, 10, 2), mm.reshape(5, 10, 2), ss.reshape(5, 10, 2))
    assert q.shape == (5, 10) and np.isnan(q[0, 7])
    for i in (0, 13, 42, 49):
        alone = mixture_quantile(0.975, w[i : i + 1], mm[i : i + 1], ss[i : i + 1])[0]
        assert q.reshape(-1)[i] == pytest.approx(alone, abs=1e-15)


def test_a_mixture_of_thousands_of_components_starts_from_its_heaviest():
    """The grid's predictive mixes ~14,000 normals: the quantile starts from that of
    the heaviest 256 and ends at the whole mixture's root (a root finder's to 1e-13,
    its distribution function p to 1e-12), each row as alone."""
    from scipy import optimize, special

    from piecs_bayes.feedback._mixture import COARSE_COMPONENTS, mixture_cdf, mixture_quantile

    rng = np.random.default_rng(11)
    rows, c = 4, 6 * COARSE_COMPONENTS
    w = rng.dirichlet(np.full(c, 0.3), rows)  # a few heavy, many light components
    mm = rng.normal(0.0, 0.004, (rows, c)) + rng.normal(0.0, 0.002, (rows, 1))
    ss = rng.uniform(0.0008, 0.006, (rows, c))
    for p in (0.025, 0.975):
        q = mixture_quantile(p, w, mm, ss)
        for i in range(rows):

            def cdf(x, i=i, p=p):
                return float(np.sum(w[i] * special.ndtr((x - mm[i]) / ss[i]))) - p

            assert q[i] == pytest.approx(optimize.brentq(cdf, -1, 1, xtol=1e-16), abs=1e-13)
            assert float(mixture_cdf(q[i], w[i], mm[i], ss[i])) == pytest.approx(p, abs=1e-12)
            alone = mixture_quantile(p, w[i : i + 1], mm[i : i + 1], ss[i : i + 1])[0]
            assert q[i] == pytest.approx(alone, abs=1e-15)


@pytest.mark.parametrize(
    "shape, axis, keepdims",
    [((6, 9), 1, False), ((6, 9), 0, True), ((4, 3, 5), 1, True), ((9,), None, False)],
)
def test_logsumexp_is_scipys_to_the_bit(shape, axis, keepdims):
    """The filter's log-sum-exp gives scipy's numbers exactly (the same arithmetic),
    ties at the maximum, rows of -inf and a NaN included."""
    from scipy import special

    from piecs_bayes.feedback._mixture import logsumexp

    rng = np.random.default_rng(7)
    a = rng.normal(0.0, 40.0, shape)
    a.flat[1] = a.flat[2]  # a tie at the maximum of its row
    if a.ndim > 1:
        a[0] = -np.inf
        a[-1].flat[0] = np.nan
    ours, theirs = (
        logsumexp(a, axis=axis, keepdims=keepdims),
        special.logsumexp(a, axis=axis, keepdims=keepdims),
    )
    assert np.shape(ours) == np.shape(theirs)
    np.testing.assert_array_equal(ours, theirs)

"""Propagation of uncertainty against JCGM 101 (GUM Supplement 1) clause 9.

Oracles are only the lines marked PUB or REPRO in the shared reference file
(RECALL lines are unverified and not used), and closed forms derived here.

Monte Carlo error is explicit: each MC statistic is the mean of `R`
independent replicate runs, its standard error the replicates' sd over
$\\sqrt R$. A published value printed to `d` decimals is matched when
$|\\hat y - y_{pub}| \\le \\tfrac12 10^{-d} + 4\\,\\mathrm{se}$; a REPRO value
(itself a single run of $10^7$ trials) when
$|\\hat y - y_{repro}| \\le 4\\sqrt{\\mathrm{se}^2 + \\mathrm{se}_{repro}^2}$.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.uncertainty import (
    adaptive_monte_carlo,
    coverage_interval,
    propagate_linear,
    propagate_mc,
    uncertainty_budget,
)

K = 4.0
M_REPRO = 10_000_000
SQ3 = math.sqrt(3.0)


def _mc(fn, draw, *, m=250_000, r=8, seed=0):
    """R replicate runs -> (estimates, standard errors, replicate sd) of
    [mean, u, symmetric low, symmetric high, shortest low, shortest high]."""
    rows = []
    for child in np.random.SeedSequence(seed).spawn(r):
        _, _, ys = propagate_mc(fn, draw(np.random.default_rng(child), m))
        rows.append(
            [
                ys.mean(),
                ys.std(ddof=1),
                *coverage_interval(ys),
                *coverage_interval(ys, kind="shortest"),
            ]
        )
    rows = np.array(rows)
    sd = rows.std(axis=0, ddof=1)
    return rows.mean(axis=0), sd / math.sqrt(r), sd


def _check_pub(value, se, printed: str):
    half = 0.5 * 10.0 ** -len(printed.split(".")[1])
    assert abs(value - float(printed)) <= half + K * se, (value, printed, se)


def _check_repro(value, se, sd_rep, m_rep, printed: str, cube_root=False):
    # the REPRO run's own noise, scaled from our replicate spread to M = 1e7 trials
    # (the shortest interval's location converges at the cube-root rate), plus the
    # rounding of the printed value
    power = 1.0 / 3.0 if cube_root else 0.5
    se_repro = sd_rep * (m_rep / M_REPRO) ** power
    half = 0.5 * 10.0 ** -len(printed.split(".")[1])
    tol = half + K * math.hypot(se, se_repro)
    assert abs(value - float(printed)) <= tol, (value, printed, se, se_repro)


def _additive(x):
    return jnp.sum(x)


# --------------------------------------------------------------------------- 9.2 additive


def test_jcgm101_9_2_2_normal_inputs():
    # GUF: PUB y = 0.00, u = 2.00, 95 % [-3.92, 3.92]
    y, ycov, jac = propagate_linear(_additive, np.zeros(4), np.ones(4))
    u = math.sqrt(ycov[0, 0])
    assert np.allclose(jac, 1.0)
    assert f"{float(y):.2f}" in ("0.00", "-0.00") and f"{u:.2f}" == "2.00"
    k = stats.norm.ppf(0.975)
    assert f"{-k * u:.2f}" == "-3.92" and f"{k * u:.2f}" == "3.92"
    # MCM: PUB 0.00 2.00 [-3.92, 3.92]; REPRO mean -0.0008 u 2.0002 sym [-3.9226, 3.9176]
    est, se, sd = _mc(_additive, lambda rng, m: rng.standard_normal((m, 4)))
    for v, s, printed in zip(est[:4], se[:4], ["0.00", "2.00", "-3.92", "3.92"], strict=True):
        _check_pub(v, s, printed)
    for i, repro in enumerate(["-0.0008", "2.0002", "-3.9226", "3.9176"]):
        _check_repro(est[i], se[i], sd[i], 250_000, repro)


def test_jcgm101_9_2_3_rectangular_inputs():
    # GUF: PUB 0.00 2.00 [-3.92, 3.92] (linearisation cannot see the rectangular shape)
    y, ycov, _ = propagate_linear(_additive, np.zeros(4), np.ones(4))
    assert f"{math.sqrt(ycov[0, 0]):.2f}" == "2.00"
    # MCM: PUB 0.00 2.00 [-3.88, 3.88]; REPRO u 2.0003 sym [-3.8810, 3.8809]
    est, se, sd = _mc(_additive, lambda rng, m: rng.uniform(-SQ3, SQ3, (m, 4)), seed=1)
    for v, s, printed in zip(est[:4], se[:4], ["0.00", "2.00", "-3.88", "3.88"], strict=True):
        _check_pub(v, s, printed)
    for i, repro in [(1, "2.0003"), (2, "-3.8810"), (3, "3.8809")]:
        _check_repro(est[i], se[i], sd[i], 250_000, repro)


def test_jcgm101_9_2_4_one_dominant_rectangular_input():
    sds = np.array([1.0, 1.0, 1.0, 10.0])
    _, ycov, _ = propagate_linear(_additive, np.zeros(4), sds**2)
    assert math.sqrt(ycov[0, 0]) == pytest.approx(math.sqrt(103.0), rel=1e-14)
    # REPRO: u 10.151, sym [-17.021, 17.018]

    def draw(rng, m):
        return rng.uniform(-SQ3, SQ3, (m, 4)) * sds

    est, se, sd = _mc(_additive, draw, seed=2)
    for i, repro in [(1, "10.151"), (2, "-17.021"), (3, "17.018")]:
        _check_repro(est[i], se[i], sd[i], 250_000, repro)


# --------------------------------------------------------------------------- 9.3 mass


def _mass(x):
    m_rc, dm_rc, rho_a, rho_w, rho_r = x[0], x[1], x[2], x[3], x[4]
    return (m_rc + dm_rc) * (1.0 + (rho_a - 1.2) * (1.0 / rho_w - 1.0 / rho_r)) - 100_000.0


def _mass_draw(rng, m):
    return np.column_stack(
        [
            rng.normal(100_000.0, 0.050, m),
            rng.normal(1.234, 0.020, m),
            rng.uniform(1.10, 1.30, m),
            rng.uniform(7000.0, 9000.0, m),
            rng.uniform(7950.0, 8050.0, m),
        ]
    )


MASS_X = np.array([100_000.0, 1.234, 1.2, 8000.0, 8000.0])
MASS_U = np.array([0.050, 0.020, 0.2 / (2 * SQ3), 2000.0 / (2 * SQ3), 100.0 / (2 * SQ3)])


def test_jcgm101_9_3_mass_calibration_linear():
    # first-order GUF: at the estimates 1/rho_W - 1/rho_R = 0 and rho_a - rho_a0 = 0, so
    # only m_Rc and dm_Rc have non-zero sensitivity (1 each): u = sqrt(0.05^2 + 0.02^2)
    y, ycov, jac = propagate_linear(_mass, MASS_X, MASS_U**2)
    assert float(y) == pytest.approx(1.234, abs=1e-9)
    assert np.allclose(jac, [[1.0, 1.0, 0.0, 0.0, 0.0]], atol=1e-12)
    assert math.sqrt(ycov[0, 0]) == pytest.approx(math.hypot(0.05, 0.02), rel=1e-9)


def test_jcgm101_9_3_mass_calibration_monte_carlo():
    # REPRO: mean 1.23396 u 0.075488 sym [1.08437, 1.38350] shortest [1.08443, 1.38356]
    est, se, sd = _mc(_mass, _mass_draw, seed=3)
    repro = ["1.23396", "0.075488", "1.08437", "1.38350", "1.08443", "1.38356"]
    for i, value in enumerate(repro):
        _check_repro(est[i], se[i], sd[i], 250_000, value, cube_root=i >= 4)
    # the non-linearity matters: u(MCM) is 40 % above the first-order GUF value
    assert est[1] / math.hypot(0.05, 0.02) == pytest.approx(1.40, abs=0.01)


def test_jcgm101_adaptive_mass_calibration():
    res = adaptive_monte_carlo(_mass, _mass_draw, ndig=2, seed=4)
    # two significant digits of u = 0.075 -> tolerance 0.0005 mg (JCGM 101 7.9.2)
    assert float(res.tolerance) == pytest.approx(0.0005)
    assert res.block_size == 10_000 and res.n_blocks >= 2
    assert res.samples.shape == (res.n_trials,) and res.y.shape == ()
    assert f"{float(res.u):.3f}" in ("0.075", "0.076")
    # JCGM 101: results then hold to the tolerance (2 s <= delta); allow the REPRO noise
    for got, repro in [
        (res.y, 1.23396),
        (res.u, 0.075488),
        (res.low, 1.08437),
        (res.high, 1.38350),
    ]:
        assert abs(float(got) - repro) <= float(res.tolerance) + 0.0002
    assert "adaptive" not in repr(res) and "blocks" in repr(res)


def test_adaptive_additive_normal_two_digits_and_max_trials():
    res = adaptive_monte_carlo(_additive, lambda rng, m: rng.standard_normal((m, 4)), ndig=2)
    assert float(res.tolerance) == pytest.approx(0.05)
    assert f"{float(res.u):.1f}" == "2.0"
    with pytest.raises(AnalysisError, match="tolerance"):
        adaptive_monte_carlo(
            _additive, lambda rng, m: rng.standard_normal((m, 4)), ndig=4, max_trials=40_000
        )


# --------------------------------------------------------------------------- 9.4 comparison loss


def _comparison_draw(x1, r, u=0.005):
    cov = u**2 * np.array([[1.0, r], [r, 1.0]])

    def draw(rng, m):
        return rng.multivariate_normal([x1, 0.0], cov, size=m)

    return draw


def _loss(x):
    return x[0] ** 2 + x[1] ** 2


def test_jcgm101_9_4_comparison_loss_x1_zero_is_exponential():
    # closed form (r = 0, x1 = 0): Y = u^2 chi2_2 ~ exponential with mean 2u^2;
    # shortest 95 % interval [0, 2u^2 ln 20]. REPRO: 0.000050 0.000050 [0, 0.000150]
    u = 0.005
    est, se, sd = _mc(_loss, _comparison_draw(0.0, 0.0), seed=5)
    assert abs(est[0] - 2 * u**2) <= K * se[0]
    assert abs(est[1] - 2 * u**2) <= K * se[1]
    assert abs(est[4]) <= 1e-9
    assert abs(est[5] - 2 * u**2 * math.log(20.0)) <= K * se[5]
    for i, printed in [(0, "0.000050"), (1, "0.000050"), (5, "0.000150")]:
        _check_pub(est[i], se[i], printed)


@pytest.mark.parametrize(
    ("x1", "r", "repro"),
    [
        (0.050, 0.0, ["0.002550", "0.000502", "0.001591", "0.003545"]),
        (0.010, 0.0, ["0.000150", "0.000112", "0.000000", "0.000366"]),
        (0.050, 0.9, [None, "0.000504", "0.001626", "0.003557"]),
    ],
)
def test_jcgm101_9_4_comparison_loss_repro(x1, r, repro):
    u = 0.005
    # GUF first order: y = x1^2, u(y) = 2 x1 u (r plays no part: d/dX2 = 0 at X2 = 0)
    y, ycov, _ = propagate_linear(_loss, np.array([x1, 0.0]), u**2 * np.array([[1, r], [r, 1]]))
    assert float(y) == pytest.approx(x1**2) and math.sqrt(ycov[0, 0]) == pytest.approx(2 * x1 * u)
    est, se, sd = _mc(_loss, _comparison_draw(x1, r), seed=6)
    if r == 0.0:  # exact mean x1^2 + 2u^2 and variance 4 x1^2 u^2 + 4 u^4
        assert abs(est[0] - (x1**2 + 2 * u**2)) <= K * se[0]
        assert abs(est[1] - math.sqrt(4 * x1**2 * u**2 + 4 * u**4)) <= K * se[1]
    for i, value in zip([0, 1, 4, 5], repro, strict=True):
        if value is not None:
            _check_repro(est[i], se[i], sd[i], 250_000, value, cube_root=i >= 4)


# --------------------------------------------------------------------------- coverage intervals


def test_coverage_interval_order_statistics():
    y = np.arange(1.0, 21.0)[::-1]  # M = 20, p = 0.9: q = 18, r = 1
    assert coverage_interval(y, 0.9) == (1.0, 19.0)
    # M = 21, p = 0.9: q = int(18.9 + 0.5) = 19, (M - q) / 2 = 1 -> [y(1), y(20)]
    assert coverage_interval(np.arange(1.0, 22.0), 0.9) == (1.0, 20.0)
    # M = 10, p = 0.5: q = 5, (M - q) = 5 odd -> r = 3 -> [y(3), y(8)]
    assert coverage_interval(np.arange(1.0, 11.0), 0.5) == (3.0, 8.0)
    skew = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 2.0, 5.0, 9.0, 14.0, 20.0])
    # q = 5: [y(r), y(r+5)] spans six values; r = 1 gives the narrowest, [0, 2]
    assert coverage_interval(skew, 0.5, kind="shortest") == (0.0, 2.0)
    assert coverage_interval(skew[::-1], 0.5) == (0.2, 9.0)  # M - q = 5 odd: r = 3
    cols = np.column_stack([np.arange(1.0, 21.0), -np.arange(1.0, 21.0)])
    lo, hi = coverage_interval(cols, 0.9)
    assert np.array_equal(lo, [1.0, -20.0]) and np.array_equal(hi, [19.0, -2.0])
    with pytest.raises(InputError, match="kind"):
        coverage_interval(y, 0.9, kind="hdi")
    with pytest.raises(InputError, match="too few"):
        coverage_interval(np.arange(3.0), 0.95)


# --------------------------------------------------------------------------- linear vs MC, checks


def test_linear_and_monte_carlo_agree_for_a_linear_function():
    a = np.array([[1.0, -2.0, 0.5], [0.3, 0.0, 4.0]])
    mu = np.array([1.0, 2.0, -1.0])
    sig = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, -0.02], [0.0, -0.02, 0.25]])
    fn = lambda x: jnp.asarray(a) @ x  # noqa: E731
    y, ycov, jac = propagate_linear(fn, mu, sig)
    assert np.allclose(jac, a) and np.allclose(y, a @ mu)
    assert np.allclose(ycov, a @ sig @ a.T, rtol=1e-13)
    m = 400_000
    draws = np.random.default_rng(8).multivariate_normal(mu, sig, size=m)
    ymean, ymc, ys = propagate_mc(fn, draws)
    assert ys.shape == (m, 2)
    se_mean = np.sqrt(np.diag(ycov) / m)
    assert np.all(np.abs(ymean - y) <= K * se_mean)
    # se of a sample covariance entry: sqrt((S_ii S_jj + S_ij^2) / M)
    se_cov = np.sqrt((np.outer(np.diag(ycov), np.diag(ycov)) + ycov**2) / m)
    assert np.all(np.abs(ymc - ycov) <= K * se_cov)
    # the vectorised path (a NumPy function of the whole array) gives the same numbers
    _, ymc2, _ = propagate_mc(lambda s: s @ a.T, draws, vectorized=True)
    assert np.allclose(ymc2, ymc, rtol=1e-10)


def test_propagate_linear_checks_inputs_before_computing():
    calls = []

    def fn(x):
        calls.append(1)
        return x

    with pytest.raises(InputError, match=r"shape \(3,\), expected \(2,\)"):
        propagate_linear(fn, np.zeros(2), np.ones(3))
    with pytest.raises(InputError, match="diagonal element 1 is -0.5"):
        propagate_linear(fn, np.zeros(2), np.array([[1.0, 0.0], [0.0, -0.5]]))
    with pytest.raises(InputError, match="symmetric"):
        propagate_linear(fn, np.zeros(2), np.array([[1.0, 0.2], [0.1, 1.0]]))
    with pytest.raises(InputError, match="finite"):
        propagate_linear(fn, np.zeros(2), np.array([[1.0, np.nan], [np.nan, 1.0]]))
    with pytest.raises(InputError, match="vector"):
        propagate_linear(fn, np.zeros((2, 2)), np.eye(4))
    assert calls == []
    y, ycov, jac = propagate_linear(
        lambda x: jnp.stack([x[0] * x[1], x[0]]), 2.0 * np.ones(2), [0.1, 0.2]
    )
    assert ycov.shape == (2, 2) and jac.shape == (2, 2)
    assert ycov[0, 0] == pytest.approx(4 * 0.1 + 4 * 0.2)


# --------------------------------------------------------------------------- budgets


def test_budget_mass_calibration_shares_sum_to_total():
    _, ycov, jac = propagate_linear(_mass, MASS_X, MASS_U**2)
    names = ["m_Rc", "dm_Rc", "rho_a", "rho_W", "rho_R"]
    budget = uncertainty_budget(jac, {n: ([i], MASS_U[i] ** 2) for i, n in enumerate(names)})
    assert budget["m_Rc"][0] == pytest.approx(0.05**2)
    assert budget["dm_Rc"][0] == pytest.approx(0.02**2)
    assert budget["rho_a"][0] == 0.0 and budget["rho_W"][0] == 0.0
    assert budget["total"][0] == pytest.approx(ycov[0, 0], rel=1e-14)
    rel = uncertainty_budget(
        jac, {"mass": [0, 1], "air": [2, 3, 4]}, cov=np.diag(MASS_U**2), relative=True
    )
    assert rel["mass"][0] + rel["air"][0] == pytest.approx(1.0)


def test_budget_with_correlated_blocks_and_a_shared_source():
    rng = np.random.default_rng(9)
    jac = rng.normal(size=(4, 6))
    # source "probe": inputs 0-3 with correlated noise; "ball": input 4;
    # "scale": one common error acting on all inputs (rank-1 full covariance)
    blk = np.array([[1.0, 0.3, 0, 0], [0.3, 1.0, 0, 0], [0, 0, 2.0, -0.5], [0, 0, -0.5, 1.0]])
    gvec = np.linspace(1.0, 2.0, 6)
    scale = 0.2**2 * np.outer(gvec, gvec)
    ux = np.zeros((6, 6))
    ux[:4, :4] = blk
    ux[4, 4] = 0.7
    ux += scale
    sources = {"probe": ([0, 1, 2, 3], blk), "ball": ([4], 0.7), "scale": scale}
    budget = uncertainty_budget(jac, sources)
    total = np.diag(jac @ ux @ jac.T)
    assert np.allclose(budget["total"], total, rtol=1e-13)
    assert np.allclose(budget["probe"] + budget["ball"] + budget["scale"], total, rtol=1e-13)
    assert all(np.all(v >= 0) for v in budget.values())
    rel = uncertainty_budget(jac, sources, relative=True)
    assert np.allclose(rel["probe"] + rel["ball"] + rel["scale"], 1.0)


def test_budget_refuses_correlated_or_overlapping_sources():
    jac = np.eye(3)
    cov = np.array([[1.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(InputError, match="'a' and 'b' are correlated"):
        uncertainty_budget(jac, {"a": [0], "b": [1], "c": [2]}, cov=cov)
    assert uncertainty_budget(jac, {"ab": [0, 1], "c": [2]}, cov=cov)["ab"][0] == 1.0
    with pytest.raises(InputError, match="belongs to sources 'a' and 'b'"):
        uncertainty_budget(jac, {"a": [0, 1], "b": [1]}, cov=np.eye(3))
    with pytest.raises(InputError, match="no cov="):
        uncertainty_budget(jac, {"a": [0]})
    with pytest.raises(InputError, match="reserved"):
        uncertainty_budget(jac, {"total": [0]}, cov=np.eye(3))


def test_a_function_is_compiled_once_and_not_kept_alive():
    """`propagate_linear` and `propagate_mc` compile one program per function and
    input shape (a second call compiles nothing), and their caches do not keep a
    function alive once its caller lets it go."""
    import gc
    import weakref

    from jax import monitoring

    from piecs_bayes.uncertainty import _propagate

    built = []

    def count(event, *_, **__):
        if event == "/jax/core/compile/backend_compile_duration":
            built.append(event)

    monitoring.register_event_duration_secs_listener(count)

    def make(k):
        return lambda x: jnp.sin(k * x) * x[::-1]

    fn = make(1.7)
    x, var = np.array([0.3, 0.5]), np.array([1e-4, 4e-4])
    y, ycov, jac = propagate_linear(fn, x, var)
    want = np.array([[1.7 * math.cos(0.51) * 0.5, math.sin(0.51)],
                     [math.sin(0.85), 1.7 * math.cos(0.85) * 0.3]])  # fmt: skip
    np.testing.assert_allclose(jac, want, rtol=1e-13)
    np.testing.assert_allclose(ycov, want @ np.diag(var) @ want.T, rtol=1e-12)
    propagate_mc(fn, np.random.default_rng(0).normal(x, 0.01, (500, 2)))
    before = len(built)
    propagate_linear(fn, x + 0.1, var)
    propagate_mc(fn, np.random.default_rng(1).normal(x, 0.01, (500, 2)))
    monitoring.unregister_event_duration_listener(count)
    assert len(built) == before, built[before:]
    gone = weakref.ref(fn)
    del fn
    gc.collect()
    assert gone() is None
    assert not any(k is None for k in _propagate._LINEARISED.keys())

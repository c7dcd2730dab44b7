"""`piecs_bayes.fit.least_squares` / `solve_arrays`: known answers, robust losses
against SciPy, failure reporting, vmap and implicit differentiation, and robustness
to gross one-sided outliers (chips)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.fit.lsq import LsqResult, SolverOptions, Status, least_squares, solve_arrays

# --------------------------------------------------------------------------- #
# shared problems (module-level functions: one compile per shape)

X_POLY = np.linspace(-1.0, 2.0, 20)
DESIGN = np.stack([np.ones_like(X_POLY), X_POLY, X_POLY**2], axis=1)


def poly_residuals(p, y):
    return p["c0"] + p["c1"] * X_POLY + p["c2"] * X_POLY**2 - y


def poly_flat(p, y):
    return jnp.asarray(DESIGN) @ p - y


def exp_residuals(p, data):
    x, y = data
    return p[0] * jnp.exp(-p[1] * x) + p[2] - y


def line_flat(p, data):
    x, z = data
    return z - (p[0] + p[1] * x)


def _poly_data(seed=0, noise=0.05):
    rng = np.random.default_rng(seed)
    return DESIGN @ np.array([1.0, -0.5, 0.25]) + rng.normal(0, noise, X_POLY.size)


def _exp_data(seed=0, n=30, outliers=0):
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 4.0, n)
    y = 2.0 * np.exp(-1.3 * x) + 0.5 + rng.normal(0, 0.02, n)
    if outliers:
        idx = rng.choice(n, outliers, replace=False)
        y[idx] += rng.uniform(0.3, 1.0, outliers)
    return x, y


# --------------------------------------------------------------------------- #
# known answers (linear models)


def test_linear_model_matches_normal_equations():
    y = _poly_data()
    res = least_squares(poly_residuals, {"c0": 0.0, "c1": 0.0, "c2": 0.0}, jnp.asarray(y))
    assert isinstance(res, LsqResult)
    assert res.status is Status.SUCCESSFUL and res.converged
    beta, rss, *_ = np.linalg.lstsq(DESIGN, y, rcond=None)
    assert res.param_names == ("c0", "c1", "c2")
    assert np.allclose(res.params_flat, beta, rtol=1e-10, atol=1e-12)
    assert res.params["c1"] == pytest.approx(beta[1], rel=1e-10)
    assert res.rss == pytest.approx(rss[0], rel=1e-10)
    assert (res.n, res.dof) == (20, 17)
    assert res.residual_sd == pytest.approx(np.sqrt(rss[0] / 17), rel=1e-10)
    cov = rss[0] / 17 * np.linalg.inv(DESIGN.T @ DESIGN)
    assert np.allclose(res.covariance, cov, rtol=1e-9)
    assert res.std_errors["c2"] == pytest.approx(np.sqrt(cov[2, 2]), rel=1e-9)
    assert np.allclose(np.diag(res.correlation), 1.0)
    assert np.allclose(res.jacobian, DESIGN)
    assert res.covariance_accurate and res.covariance_reason is None
    assert res.outliers == () and res.loss == "linear"


def test_known_sigma_scales_covariance():
    y = _poly_data()
    res = least_squares(poly_flat, jnp.zeros(3), jnp.asarray(y), sigma=0.05)
    assert np.allclose(res.covariance, 0.05**2 * np.linalg.inv(DESIGN.T @ DESIGN), rtol=1e-9)


def test_weights_and_zero_weight_exclusion():
    y = _poly_data(1)
    w = np.linspace(0.5, 2.0, 20)
    w[[3, 11]] = 0.0
    res = least_squares(poly_flat, jnp.zeros(3), jnp.asarray(y), weights=w)
    keep = w > 0
    xw = DESIGN[keep] * np.sqrt(w[keep])[:, None]
    beta = np.linalg.lstsq(xw, y[keep] * np.sqrt(w[keep]), rcond=None)[0]
    rss = np.sum(w * (DESIGN @ beta - y) ** 2)
    assert np.allclose(res.params_flat, beta, rtol=1e-10)
    assert (res.n, res.dof) == (18, 15)
    assert res.rss == pytest.approx(rss, rel=1e-10)
    assert np.allclose(res.covariance, rss / 15 * np.linalg.inv(xw.T @ xw), rtol=1e-9)
    # a zero-weight point is as good as absent, even if its residual is garbage
    y_bad = y.copy()
    y_bad[3] = 1e6
    res_bad = least_squares(poly_flat, jnp.zeros(3), jnp.asarray(y_bad), weights=w)
    assert np.allclose(res_bad.params_flat, res.params_flat, rtol=1e-10)


@pytest.mark.parametrize("solver", ["gauss_newton", "dogleg"])
def test_solvers_agree_with_lm(solver):
    data = tuple(map(jnp.asarray, _exp_data(2)))
    ref = least_squares(exp_residuals, jnp.array([1.0, 1.0, 0.0]), data)
    res = least_squares(
        exp_residuals, jnp.array([1.0, 1.0, 0.0]), data, solver=SolverOptions(solver)
    )
    assert res.converged
    assert np.allclose(res.params_flat, ref.params_flat, rtol=1e-8)
    assert np.allclose(res.covariance, ref.covariance, rtol=1e-6)


class _Pars(NamedTuple):
    amp: jax.Array
    rate_offset: jax.Array  # shape (2,)


def test_pytree_names_and_structure():
    data = tuple(map(jnp.asarray, _exp_data(3)))

    def fn(p, d):
        return exp_residuals(jnp.array([p.amp, p.rate_offset[0], p.rate_offset[1]]), d)

    res = least_squares(fn, _Pars(jnp.array(1.0), jnp.array([1.0, 0.0])), data)
    assert res.param_names == ("amp", "rate_offset[0]", "rate_offset[1]")
    assert isinstance(res.params, _Pars) and res.params.rate_offset.shape == (2,)
    assert isinstance(res.std_errors, _Pars)
    assert res.std_errors.rate_offset[1] == pytest.approx(np.sqrt(res.covariance[2, 2]))
    text = repr(res)
    assert "SUCCESSFUL" in text and "rate_offset[1]" in text and "std error" in text
    assert "<table" in res._repr_html_()


# --------------------------------------------------------------------------- #
# bad input and failure reporting


def test_unknown_names_are_value_errors():
    y = jnp.asarray(_poly_data())
    with pytest.raises(ValueError, match=r"unknown loss 'l2'; expected one of"):
        least_squares(poly_flat, jnp.zeros(3), y, loss="l2")
    with pytest.raises(ValueError, match=r"unknown solver 'bfgs'.*'lm'"):
        least_squares(poly_flat, jnp.zeros(3), y, solver=SolverOptions("bfgs"))
    with pytest.raises(ValueError, match="unknown x_scale"):
        least_squares(poly_flat, jnp.zeros(3), y, x_scale="auto")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"weights": np.ones(5)}, r"weights must have shape \(20,\)"),
        ({"weights": -np.ones(20)}, "non-negative"),
        ({"scale": 0.0}, "scale must be a positive"),
        ({"sigma": -1.0}, "sigma must be a positive"),
        ({"solver": {"max_steps": 0}}, "max_steps"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(InputError, match=match):
        if "solver" in kwargs:  # refused when the SolverOptions is made
            kwargs = {"solver": SolverOptions(**kwargs["solver"])}
        least_squares(poly_flat, jnp.zeros(3), jnp.asarray(_poly_data()), **kwargs)


def test_residuals_must_be_1d():
    with pytest.raises(InputError, match="1-D"):
        least_squares(lambda p, a: jnp.outer(p, p), jnp.ones(2))


def test_failure_is_reported_never_silent():
    data = tuple(map(jnp.asarray, _exp_data(4)))
    y0 = jnp.array([10.0, 5.0, -3.0])
    with pytest.raises(AnalysisError, match="maximum number of steps"):
        least_squares(exp_residuals, y0, data, solver=SolverOptions(max_steps=3))
    res = least_squares(exp_residuals, y0, data, solver=SolverOptions(max_steps=3), throw=False)
    assert res.status is Status.MAX_STEPS_REACHED and not res.converged
    assert res.message == Status.MAX_STEPS_REACHED.message and "max_steps" in res.message
    assert not res.covariance_accurate
    assert "MAX_STEPS_REACHED" in repr(res)


def test_nonfinite_status():
    x, y = _exp_data(4)
    y[5] = np.nan  # a NaN in the data, with a non-zero weight
    data = (jnp.asarray(x), jnp.asarray(y))
    res = least_squares(exp_residuals, jnp.array([1.0, 1.0, 0.0]), data, throw=False)
    assert res.status is Status.NONFINITE and not res.converged
    with pytest.raises(AnalysisError, match="non-finite"):
        least_squares(exp_residuals, jnp.array([1.0, 1.0, 0.0]), data)


def offset_pair(p, y):
    return p[0] + p[1] - y  # two parameters, one combination identifiable


def test_covariance_unavailable_has_a_reason():
    # exactly determined (three points, three parameters): no dof for the variance ...
    y = jnp.asarray(_poly_data())
    w = np.zeros(20)
    w[[0, 9, 19]] = 1.0
    res = least_squares(poly_flat, jnp.zeros(3), y, weights=w)
    assert res.dof == 0 and res.covariance is None and "dof" in res.covariance_reason
    assert res.std_errors is None and res.correlation is None
    # ... unless sigma is known
    res = least_squares(poly_flat, jnp.zeros(3), y, weights=w, sigma=0.1)
    sub = DESIGN[[0, 9, 19]]
    assert np.allclose(res.covariance, 0.01 * np.linalg.inv(sub.T @ sub), rtol=1e-9)
    # redundant parameters: singular Jacobian
    res = least_squares(offset_pair, jnp.zeros(2), y)
    assert res.converged
    assert res.covariance is None and "singular" in res.covariance_reason


# --------------------------------------------------------------------------- #
# robust losses


@pytest.mark.parametrize("loss", ["huber", "soft_l1", "cauchy"])
def test_robust_loss_matches_scipy(loss):
    x, y = _exp_data(5, outliers=4)
    w = np.linspace(0.5, 1.5, x.size)
    scale = 0.05
    res = least_squares(
        exp_residuals,
        jnp.array([1.0, 1.0, 0.0]),
        (jnp.asarray(x), jnp.asarray(y)),
        weights=w,
        loss=loss,
        scale=scale,
    )

    def weighted(p):
        return np.sqrt(w) * (p[0] * np.exp(-p[1] * x) + p[2] - y)

    ref = scipy.optimize.least_squares(
        weighted,
        res.params_flat * 1.01,
        loss=loss,
        f_scale=scale,
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    assert ref.success
    assert np.allclose(res.params_flat, ref.x, rtol=1e-7, atol=1e-10)
    assert res.cost == pytest.approx(ref.cost, rel=1e-9)
    assert res.scale == scale
    # the effective weights are user * robust, the robust ones scipy's rho'(z)
    z = (weighted(res.params_flat) / scale) ** 2
    rho = {
        "huber": lambda z: np.where(z <= 1, 1.0, z**-0.5),
        "soft_l1": lambda z: (1 + z) ** -0.5,
        "cauchy": lambda z: 1 / (1 + z),
    }[loss]
    assert np.allclose(res.robust_weights, rho(z), rtol=1e-9)
    assert np.allclose(res.weights, w * rho(z), rtol=1e-9)


def test_tukey_known_answers():
    # location model: inliers symmetric about 10, one gross outlier; with scale 1 the
    # outlier gets weight exactly 0 and, by symmetry, the estimate is exactly 10
    y = np.array([9.8, 9.9, 10.0, 10.1, 10.2, 60.0])
    res = least_squares(
        lambda p, d: d - p[0], jnp.array([11.0]), jnp.asarray(y), loss="tukey", scale=1.0
    )
    assert res.params_flat[0] == pytest.approx(10.0, abs=1e-12)
    assert res.robust_weights[5] == 0.0 and res.outliers == (5,)
    u2 = ((y[:5] - 10.0) / 1.0) ** 2
    assert np.allclose(res.robust_weights[:5], (1 - u2) ** 2, rtol=1e-12)
    # IRLS fixed point on a nonlinear model: the solution is the weighted least-squares
    # solution with its own final Tukey weights
    x, yy = _exp_data(6, outliers=5)
    data = (jnp.asarray(x), jnp.asarray(yy))
    res = least_squares(exp_residuals, jnp.array([1.0, 1.0, 0.0]), data, loss="tukey", scale=0.1)
    assert res.converged
    wls = least_squares(exp_residuals, res.params_flat * 1.05, data, weights=res.robust_weights)
    assert np.allclose(wls.params_flat, res.params_flat, rtol=1e-9, atol=1e-12)


def test_callable_loss_equals_named():
    def my_huber(z):
        return jnp.where(z <= 1.0, z, 2.0 * jnp.sqrt(jnp.maximum(z, 1.0)) - 1.0)

    x, y = _exp_data(7, outliers=3)
    data = (jnp.asarray(x), jnp.asarray(y))
    a = least_squares(exp_residuals, jnp.array([1.0, 1.0, 0.0]), data, loss="huber", scale=0.05)
    b = least_squares(exp_residuals, jnp.array([1.0, 1.0, 0.0]), data, loss=my_huber, scale=0.05)
    assert np.allclose(a.params_flat, b.params_flat, rtol=1e-9)
    assert b.loss == "my_huber"


def test_estimated_scale_and_residual_sd():
    x, y = _exp_data(8, n=30)
    res = least_squares(
        exp_residuals, jnp.array([1.0, 1.0, 0.0]), (jnp.asarray(x), jnp.asarray(y)), loss="huber"
    )
    assert res.residual_sd == pytest.approx(0.02, rel=0.35)
    assert res.scale == pytest.approx(1.345 * res.residual_sd, rel=0.2)
    assert len(res.outliers) <= 1  # a 3-sigma flag on clean data happens by chance


# --------------------------------------------------------------------------- #
# batches and derivatives


def test_vmap_matches_loop():
    rng = np.random.default_rng(9)
    batch, n = 100, 30
    xs, ys, ws = [], [], []
    for i in range(batch):
        x, y = _exp_data(100 + i, n=n)
        w = np.ones(n)
        w[rng.integers(20, n) :] = 0.0  # padded tails of different length
        xs.append(x)
        ys.append(y)
        ws.append(w)
    xs, ys, ws = map(jnp.asarray, (np.array(xs), np.array(ys), np.array(ws)))
    y0 = jnp.array([1.0, 1.0, 0.0])

    def one(x, y, w):
        return solve_arrays(exp_residuals, y0, (x, y), w)

    batched = jax.jit(jax.vmap(one))(xs, ys, ws)  # one program, not one per operation
    for i in range(batch):  # the loop: one fit at a time, through the public API
        ref = least_squares(exp_residuals, y0, (xs[i], ys[i]), weights=ws[i])
        assert int(batched.status_code[i]) == ref.status == Status.SUCCESSFUL
        assert int(batched.dof[i]) == ref.dof == int(ws[i].sum()) - 3
        assert np.allclose(batched.params_flat[i], ref.params_flat, rtol=1e-9, atol=1e-12)
        assert np.allclose(batched.covariance[i], ref.covariance, rtol=1e-7, atol=1e-15)


def test_jacfwd_of_fit_is_the_analytic_sensitivity():
    """d(params)/d(data) through the implicit adjoint equals (X^T W X)^-1 X^T W for a
    linear model."""
    y = jnp.asarray(_poly_data(10))
    w = jnp.linspace(0.5, 2.0, 20)
    sens = jax.jit(jax.jacfwd(lambda d: solve_arrays(poly_flat, jnp.zeros(3), d, w).params_flat))(y)
    xtw = DESIGN.T * np.asarray(w)
    assert np.allclose(sens, np.linalg.solve(xtw @ DESIGN, xtw), rtol=1e-9, atol=1e-12)


def test_jacfwd_nonlinear_matches_finite_differences():
    """Also for a robust loss: a chip (gross outlier) has no influence on a Tukey fit."""
    x, y = _exp_data(11, outliers=2)
    y0 = jnp.array([1.0, 1.0, 0.0])
    chips = np.flatnonzero(y - (2.0 * np.exp(-1.3 * x) + 0.5) > 0.2)
    for loss in ("linear", "tukey"):

        def fit(d, loss=loss):
            data = (jnp.asarray(x), jnp.asarray(d))
            return least_squares(exp_residuals, y0, data, loss=loss).params_flat

        def fit_arrays(d, loss=loss):
            return solve_arrays(exp_residuals, y0, (jnp.asarray(x), d), loss=loss).params_flat

        sens = np.asarray(jax.jit(jax.jacfwd(fit_arrays))(y))
        h = 1e-6
        for j in (0, 7, 29):
            e = np.zeros_like(y)
            e[j] = h
            fd = (fit(y + e) - fit(y - e)) / (2 * h)
            assert np.allclose(sens[:, j], fd, rtol=1e-5, atol=1e-8), (loss, j)
        if loss == "tukey":
            assert np.all(np.abs(sens[:, chips]) < 1e-12)


# --------------------------------------------------------------------------- #
# robustness to chips: gross one-sided outliers on a probed line

PROBE_SIGMA = 0.002  # mm
TRUTH = np.array([0.010, 2e-4])  # normal offset (mm), rotation (rad ~ slope)
REPLICATES = 100


def _chipped_lines(fraction, seed):
    """REPLICATES lines of 40 probe points over 20 mm, noise 2 um, and `fraction` of
    the points lifted by chips of 50-500 um (one-sided)."""
    rng = np.random.default_rng(seed)
    n = 40
    x = np.linspace(-10.0, 10.0, n)
    z = TRUTH[0] + TRUTH[1] * x + rng.normal(0, PROBE_SIGMA, (REPLICATES, n))
    k = int(round(fraction * n))
    chipped = np.zeros((REPLICATES, n), dtype=bool)
    for i in range(REPLICATES):
        idx = rng.choice(n, k, replace=False)
        chipped[i, idx] = True
        z[i, idx] += rng.uniform(0.05, 0.5, k)
    return x, z, chipped


def _batch_fit(x, z, loss, sigma):
    fit = jax.vmap(
        lambda zz: solve_arrays(
            line_flat, jnp.zeros(2), (jnp.asarray(x), zz), loss=loss, sigma=sigma
        )
    )
    out = fit(jnp.asarray(z))
    assert np.all(np.asarray(out.status_code) == Status.SUCCESSFUL)
    se = np.sqrt(np.diagonal(np.asarray(out.covariance), axis1=1, axis2=2))
    zscore = (np.asarray(out.params_flat) - TRUTH) / se
    return out, zscore


@pytest.mark.parametrize("fraction", [0.10, 0.25])
def test_robust_fits_recover_truth_despite_chips(fraction):
    x, z, chipped = _chipped_lines(fraction, seed=int(fraction * 100))
    _, z_plain = _batch_fit(x, z, "linear", PROBE_SIGMA)
    # plain least squares: the truth is (far) outside 3 standard uncertainties
    assert np.mean(np.all(np.abs(z_plain) < 3, axis=1)) < 0.05
    losses = ["huber", "cauchy", "tukey"] if fraction <= 0.1 else ["cauchy", "tukey"]
    for loss in losses:
        out, zs = _batch_fit(x, z, loss, PROBE_SIGMA)
        inside = np.all(np.abs(zs) < 3, axis=1)
        assert inside.mean() >= 0.92, (loss, inside.mean())  # 3-sigma nominal: 0.995
        flagged = np.asarray(out.outlier)
        assert np.mean(np.all(flagged[chipped].reshape(REPLICATES, -1), axis=1)) >= 0.95
        assert np.mean(np.sum(flagged & ~chipped, axis=1)) <= 0.3  # few false alarms
        # the same with the residual scale estimated (no sigma): calibrated too
        _, zs_est = _batch_fit(x, z, loss, None)
        assert np.mean(np.all(np.abs(zs_est) < 3, axis=1)) >= 0.92, loss


def test_huber_keeps_a_bias_under_heavy_one_sided_chips():
    """A documented limitation, not a feature: Huber's bounded influence still lets
    25 % one-sided chips pull the offset by ~c eps/(1-eps) sigma/P(|u|<c), several
    standard uncertainties with 40 points; the redescending losses do not."""
    x, z, _ = _chipped_lines(0.25, seed=25)
    _, z_huber = _batch_fit(x, z, "huber", PROBE_SIGMA)
    _, z_plain = _batch_fit(x, z, "linear", PROBE_SIGMA)
    _, z_tukey = _batch_fit(x, z, "tukey", PROBE_SIGMA)
    assert np.mean(z_huber[:, 0]) > 2.0  # biased upwards, like the chips
    assert np.mean(np.abs(z_huber[:, 0])) < 0.1 * np.mean(np.abs(z_plain[:, 0]))
    assert abs(np.mean(z_tukey[:, 0])) < 0.5


# --------------------------------------------------------------------------- #
# a robust fit with a known sigma states the M-estimator's scatter (issue 41)

#: clean probed lines (no chips): enough replicates that the ratio of the parameters'
#: scatter to their stated variance has a sampling sd of sqrt(2 / R) = 0.01
CLEAN_REPLICATES = 20_000


@pytest.mark.parametrize(
    "loss",
    ["huber", *(pytest.param(k, marks=pytest.mark.slow) for k in ("soft_l1", "cauchy", "tukey"))],
)
def test_known_sigma_covariance_is_the_scatter_of_the_estimate(loss):
    """The fixed-weight sandwich alone was 2-5 % short in variance at the normal (Huber:
    scatter / stated 1.048 and 1.034 here, `losses.fixed_weight_factor`); scaled, the
    stated variance is the scatter within 3 sampling sds (+-0.03; a 4 % shortfall
    fails about 5 times in 6)."""
    from piecs_bayes.fit.lsq import TUNING

    rng = np.random.default_rng(5)
    n = 40
    x = np.linspace(-10.0, 10.0, n)
    z = TRUTH[0] + TRUTH[1] * x + rng.normal(0, PROBE_SIGMA, (CLEAN_REPLICATES, n))
    fit = jax.jit(jax.vmap(lambda zz: solve_arrays(
        line_flat, jnp.zeros(2), (jnp.asarray(x), zz), loss=loss, sigma=PROBE_SIGMA,
        scale=TUNING[loss] * PROBE_SIGMA,
    )))  # fmt: skip
    out = fit(jnp.asarray(z))
    assert np.all(np.asarray(out.status_code) == Status.SUCCESSFUL)
    scatter = np.var(np.asarray(out.params_flat), axis=0, ddof=1)
    stated = np.mean(np.diagonal(np.asarray(out.covariance), axis1=1, axis2=2), axis=0)
    assert np.all(np.abs(scatter / stated - 1.0) < 0.03), scatter / stated


def test_the_tabulated_fixed_weight_factors_are_the_integrals():
    """A fit reads `FIXED_WEIGHT_FACTORS` (no integration per process); each is the
    integral of `fixed_weight_factor` at the loss's tuning constant, to 1e-12."""
    from piecs_bayes.fit.lsq import losses

    computed = [losses.fixed_weight_factor(name) for name in losses.LOSS_NAMES]
    np.testing.assert_allclose(losses.FIXED_WEIGHT_FACTORS, computed, rtol=1e-12)
    assert losses.fixed_weight_factor_of(1) == losses.FIXED_WEIGHT_FACTORS[1]
    assert float(losses.fixed_weight_factor_of(jnp.asarray(7))) == 1.0  # a custom loss

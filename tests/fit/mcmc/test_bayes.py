"""Bayesian machinery against closed-form posteriors, within explicit Monte Carlo error.

Oracles: Newcomb's speed-of-light data (Gelman et al., BDA3 sect. 3.2, in the
shared reference folder) under the non-informative prior, whose marginal
posterior of the mean is Student-t; and a conjugate normal linear model.
Monte Carlo error bounds come from the sampler's own effective sample size:
the standard error of a mean is $\\mathrm{sd}/\\sqrt{\\mathrm{ESS}}$, of an sd
$\\mathrm{sd}\\sqrt{(\\kappa - 1)/(4\\,\\mathrm{ESS})}$, of a $q$ quantile
$\\sqrt{q(1-q)/\\mathrm{ESS}}/f(x_q)$; every check allows 4 of them.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import warnings
from dataclasses import replace
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from piecs_bayes.errors import InputError
from piecs_bayes.fit.mcmc import (
    ConvergenceError,
    ConvergenceWarning,
    HalfNormal,
    LogNormal,
    Normal,
    SamplerOptions,
    StudentT,
    Uniform,
    gaussian_loglik,
    prior_from_spec,
    sample_posterior,
    split_rhat,
    student_t_loglik,
)

K_SE = 4.0  # allowed multiples of the Monte Carlo standard error
QUIET = SamplerOptions(progress=False)


def _newcomb_header(text: str) -> dict[str, float]:
    """The exact closed-form numbers from the reference file's header."""
    head = next(line for line in text.splitlines() if "Exact closed form" in line)
    sig = next(line for line in text.splitlines() if "CrI for sigma" in line)
    num = r"([-+]?\d+\.\d+)"
    out = {
        "ybar": float(re.search(r"ybar=" + num, head).group(1)),
        "s": float(re.search(r"s=" + num, head).group(1)),
        "scale": float(re.search(r"s/sqrt\(n\)=" + num, head).group(1)),
        "sd_mu": float(re.search(r"sd\(mu\)=" + num, head).group(1)),
    }
    lo, hi = re.search(r"95% CrI \[" + num + ", " + num + r"\]", head).groups()
    slo, shi = re.search(r"sigma \[" + num + ", " + num + r"\]", sig).groups()
    out |= {"lo": float(lo), "hi": float(hi), "sig_lo": float(slo), "sig_hi": float(shi)}
    return out


def _newcomb_logpost(theta, y):
    # p(mu, sigma^2) ~ 1/sigma^2  <=>  flat in (mu, log sigma)
    return gaussian_loglik(y - theta[0], jnp.exp(theta[1]))


@functools.cache
def _run_newcomb(path: str):
    text = Path(path).read_text()
    y = np.loadtxt(path)
    x0 = np.array([y.mean(), math.log(y.std())])
    post = sample_posterior(
        _newcomb_logpost, x0, names=("mu", "log_sigma"), args=jnp.asarray(y),
        options=SamplerOptions(nwalkers=32, nsteps=3000, burn=500, seed=1, progress=False),
    )  # fmt: skip
    return y, _newcomb_header(text), post


@pytest.fixture
def newcomb(reference_dir):
    """Data, published closed form and one sampler run, shared by the tests below."""
    return _run_newcomb(str(reference_dir / "bayes" / "newcomb_speed_of_light.txt"))


def test_newcomb_header_is_the_closed_form(newcomb):
    y, ref, _ = newcomb
    n = y.size
    assert y.size == 66
    assert ref["ybar"] == pytest.approx(y.mean(), abs=1e-6)
    assert ref["s"] == pytest.approx(y.std(ddof=1), abs=1e-6)
    assert ref["scale"] == pytest.approx(y.std(ddof=1) / math.sqrt(n), abs=1e-6)
    t = stats.t(n - 1, loc=y.mean(), scale=ref["scale"])
    assert ref["sd_mu"] == pytest.approx(t.std(), abs=1e-6)
    assert (ref["lo"], ref["hi"]) == pytest.approx(t.interval(0.95), abs=1e-6)


def test_newcomb_posterior_of_mu_is_student_t(newcomb):
    y, ref, post = newcomb
    assert post.converged, post
    n = y.size
    nu = n - 1
    t = stats.t(nu, loc=ref["ybar"], scale=ref["scale"])
    mu = post["mu"]
    ess = post.ess[0]
    sd = mu.std(ddof=1)
    assert abs(mu.mean() - ref["ybar"]) <= K_SE * sd / math.sqrt(ess)
    kurt = 3.0 + 6.0 / (nu - 4.0)
    se_sd = ref["sd_mu"] * math.sqrt((kurt - 1.0) / (4.0 * ess))
    assert abs(sd - ref["sd_mu"]) <= K_SE * se_sd
    # the scale of the t: sd * sqrt((nu - 2) / nu)
    assert abs(sd * math.sqrt((nu - 2) / nu) - ref["scale"]) <= K_SE * se_sd
    lo, hi = post.interval(0.95)
    for q, got, want in [(0.025, lo[0], ref["lo"]), (0.975, hi[0], ref["hi"])]:
        se_q = math.sqrt(q * (1 - q) / ess) / t.pdf(want)
        assert abs(got - want) <= K_SE * se_q, (q, got, want, se_q)


def test_newcomb_posterior_of_sigma(newcomb):
    y, ref, post = newcomb
    n = y.size
    sigma = np.exp(post["log_sigma"])
    ess = post.ess[1]
    # sigma^2 | y ~ Inv-chi2(n-1, s^2): sigma = s sqrt((n-1)/X), X ~ chi2(n-1)
    s = ref["s"]
    for q, want in [(0.025, ref["sig_lo"]), (0.975, ref["sig_hi"])]:
        x = (n - 1) * s**2 / want**2
        dens = stats.chi2.pdf(x, n - 1) * 2.0 * (n - 1) * s**2 / want**3
        se_q = math.sqrt(q * (1 - q) / ess) / dens
        assert abs(np.quantile(sigma, q) - want) <= K_SE * se_q


def test_posterior_diagnostics_and_repr(newcomb):
    _, _, post = newcomb
    s = post.chains.shape[0]
    assert post.thin > 1 and s == len(range(post.thin - 1, 2500, post.thin))  # "auto" thinning
    assert post.chains.shape == (s, 4 * 32, 2)
    assert post.samples.shape == (s * 128, 2)
    assert post.log_prob.shape == (s, 128)
    assert np.all(post.tau_reliable) and np.all(post.rhat < 1.01) and np.all(post.ess > 400)
    assert 0.5 < post.acceptance_fraction.mean() < 0.9  # stretch move on a 2-d target
    assert post.wall_time > 0 and post.ess_per_second > 0
    assert post.problems == ()
    text = repr(post)
    assert "converged=True" in text and "mu" in text and "ESS/s" in text
    with pytest.raises(dataclasses.FrozenInstanceError):
        post.converged = False
    with pytest.raises(ValueError):
        post.chains[0, 0, 0] = 1.0
    with pytest.raises(KeyError, match="have"):
        post["nope"]


def test_posterior_to_arviz_and_netcdf(newcomb, tmp_path):
    _, _, post = newcomb
    idata = post.to_arviz()
    s = post.chains.shape[0]
    assert idata.posterior["mu"].shape == (4, 32 * s)  # chain = ensemble, walker-major draws
    assert idata.posterior.attrs["n_ensembles"] == 4
    assert np.allclose(idata.posterior.attrs["rhat"], post.rhat)
    path = post.to_netcdf(tmp_path / "newcomb.nc")
    from piecs_bayes.fit.mcmc._posterior import import_arviz as _import_arviz

    back = _import_arviz().from_netcdf(path)
    ens = post.ensemble_chains  # (K, S, W, d)
    assert np.array_equal(back.posterior["log_sigma"].values[1, :s], ens[1, :, 0, 1])
    assert np.array_equal(back.posterior["log_sigma"].values[1, s : 2 * s], ens[1, :, 1, 1])
    assert np.array_equal(
        np.sort(back.sample_stats["lp"].values.ravel()), np.sort(post.log_prob.ravel())
    )


@pytest.mark.parametrize("sampler", ["emcee", "lockstep"])
def test_arviz_computes_the_reported_rhat_and_ess_from_the_stored_chains(sampler, tmp_path):
    """Parity: what a user gets from `az.rhat` / `az.ess` on posterior.nc is what
    the package reports (and judges convergence by)."""
    from piecs_bayes.fit.mcmc import sample_posteriors
    from piecs_bayes.fit.mcmc._posterior import import_arviz as _import_arviz

    az = _import_arviz()
    kw = dict(names=("a", "b"), options=SamplerOptions(nwalkers=16, nsteps=1500, seed=4,
                                                        progress=False))  # fmt: skip
    x0 = np.array([0.3, -1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        if sampler == "emcee":
            post = sample_posterior(_toy2, x0, **kw)
        else:
            post = sample_posteriors(_toy2, x0[None], args=(np.zeros((1, 1)),), **kw)[0]
    assert post.thin > 1  # "auto": about tau / 2
    back = az.from_netcdf(post.to_netcdf(tmp_path / "p.nc"))
    ess = az.ess(back, method="bulk")
    rhat = az.rhat(back, method="rank")
    for j, name in enumerate(post.names):
        assert float(ess[name]) == pytest.approx(post.ess[j], rel=1e-9)
        assert float(rhat[name]) == pytest.approx(post.rhat[j], rel=1e-12)


def _toy2(theta, args):
    # a correlated 2-D Gaussian
    return -0.5 * (theta[0] ** 2 + (theta[1] - 0.8 * theta[0]) ** 2 / 0.36)


def test_tau_is_emcees_integrated_time():
    """`_taus` (batched FFTs) gives emcee's `integrated_time` per ensemble, to
    rounding, for long and short chains; a stuck walker gives NaN, as in emcee."""
    import emcee

    from piecs_bayes.fit.mcmc._core import _taus

    rng = np.random.default_rng(11)
    k, s, w, d = 2, 700, 40, 3
    x = np.empty((k, s, w, d))
    x[:, 0] = rng.standard_normal((k, w, d))
    phi = np.array([0.5, 0.9, 0.97])  # tau 3, 19, 66
    for t in range(1, s):
        x[:, t] = phi * x[:, t - 1] + np.sqrt(1 - phi**2) * rng.standard_normal((k, w, d))
    for kept in (x, x[:, :9], x[:, :100]):
        ref = [emcee.autocorr.integrated_time(e, c=5, tol=0, quiet=True) for e in kept]
        assert np.allclose(_taus(kept), np.maximum(ref, 1e-12), rtol=1e-12, atol=0)
    stuck = x[:, :50].copy()
    stuck[0, :, 3, 1] = 1.0
    with np.errstate(invalid="ignore"):
        tau = _taus(stuck)
    assert np.isnan(tau[0, 1]) and np.isfinite(np.delete(tau.ravel(), 1)).all()


def test_split_rhat_matches_arviz_across_ensembles(newcomb):
    _, _, post = newcomb
    from piecs_bayes.fit.mcmc._posterior import import_arviz as _import_arviz

    az = _import_arviz()
    for j in range(2):
        x = post.arviz_chains[..., j]  # one chain per ensemble
        ours = split_rhat(x)
        theirs = float(az.rhat(x, method="rank"))
        assert ours == pytest.approx(theirs, rel=1e-10)
    # and it detects ensembles that disagree
    rng = np.random.default_rng(0)
    shifted = rng.normal(size=(4, 2000)) + np.array([[0.0], [0.0], [0.0], [1.0]])
    assert split_rhat(shifted) > 1.05


def test_conjugate_normal_linear_model():
    rng = np.random.default_rng(7)
    z = np.linspace(-1.0, 1.0, 8)
    x = np.vander(z, 3, increasing=True)
    sigma = 0.5
    beta_true = np.array([1.0, -0.5, 0.3])
    y = x @ beta_true + rng.normal(0.0, sigma, z.size)
    m0 = np.array([0.5, 0.0, 0.0])
    s0 = np.array([0.4, 0.5, 0.6])
    priors = [Normal(m, s) for m, s in zip(m0, s0, strict=True)]
    # closed form: Sigma_n = (X'X/sigma^2 + S0^-1)^-1, m_n = Sigma_n (X'y/sigma^2 + S0^-1 m0)
    cov_n = np.linalg.inv(x.T @ x / sigma**2 + np.diag(1.0 / s0**2))
    mean_n = cov_n @ (x.T @ y / sigma**2 + m0 / s0**2)

    def log_post(theta, data):
        xx, yy = data
        lp = sum(p.log_pdf(theta[i]) for i, p in enumerate(priors))
        return lp + gaussian_loglik(yy - xx @ theta, sigma)

    post = sample_posterior(
        log_post, mean_n, names=("b0", "b1", "b2"), args=(jnp.asarray(x), jnp.asarray(y)),
        options=SamplerOptions(nwalkers=32, nsteps=4000, burn=500, seed=3, progress=False),
    )  # fmt: skip
    # 3,500 kept steps: 50 tau holds up to tau = 70 (42 seen on another instruction
    # set, where 2,500 steps did not converge: the verdict must not hang on the path)
    assert post.converged
    sd_n = np.sqrt(np.diag(cov_n))
    se_mean = sd_n / np.sqrt(post.ess)
    assert np.all(np.abs(post.mean - mean_n) <= K_SE * se_mean)
    se_sd = sd_n * np.sqrt(2.0 / (4.0 * post.ess))  # normal: kurtosis 3
    assert np.all(np.abs(post.sd - sd_n) <= K_SE * se_sd)
    corr_n = cov_n / np.outer(sd_n, sd_n)
    corr = post.cov / np.outer(post.sd, post.sd)
    # se of a correlation r: (1 - r^2) / sqrt(ESS)
    se_r = (1.0 - corr_n**2) / np.sqrt(post.ess.min())
    off = ~np.eye(3, dtype=bool)
    assert np.all(np.abs(corr - corr_n)[off] <= K_SE * se_r[off] + 1e-12)
    lo, hi = post.interval(0.95)
    zq = stats.norm.ppf(0.975)
    se_q = np.sqrt(0.025 * 0.975 / post.ess) / (stats.norm.pdf(zq) / sd_n)
    assert np.all(np.abs(lo - (mean_n - zq * sd_n)) <= K_SE * se_q)
    assert np.all(np.abs(hi - (mean_n + zq * sd_n)) <= K_SE * se_q)


def _toy(theta, args):
    return -0.5 * jnp.sum(theta**2)


SAMPLERS = ["emcee", "lockstep"]  # sample_posterior's two samplers


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_short_run_warns_with_advice(sampler):
    with pytest.warns(ConvergenceWarning) as rec:
        post = sample_posterior(
            _toy, np.zeros(2), names=("a", "b"), options=SamplerOptions(
                nsteps=40, seed=0, progress=False, min_ess=1e6, sampler=sampler),
        )  # fmt: skip
    msg = str(rec[0].message)
    assert "not converged" in msg
    assert re.search(r"increase nsteps to >= \d+", msg)  # tau advice, with the number
    assert re.search(r"effective sample size < 1e\+06: a \(\d+\)", msg)
    assert "nwalkers" in msg  # ESS advice
    assert "tau" in msg
    assert not post.converged and post.problems
    assert msg.startswith("MCMC run has not converged")  # one part: no "part 0"


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_short_run_can_raise(sampler):
    with pytest.raises(ConvergenceError, match="increase nsteps") as err:
        sample_posterior(
            _toy, np.zeros(2), names=("a", "b"), options=SamplerOptions(
                nsteps=40, seed=0, progress=False, on_fail="raise", sampler=sampler),
        )  # fmt: skip
    assert err.value.posterior.names == ("a", "b")  # the Posterior itself, not a list
    assert err.value.posterior.sampler.startswith(
        "emcee" if sampler == "emcee" else "piecs_bayes lockstep ensembles (jax)"
    )


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_same_seed_same_chains_and_start_ball_respects_support(sampler):
    # half-normal prior: walkers drawn below 0 are redrawn, never start at -inf
    prior = HalfNormal(1.0)

    def lp(theta, args):
        return prior.log_pdf(theta[0]) - 0.5 * theta[1] ** 2

    kw = dict(names=("s", "m"), cov0=[1.0, 1.0])
    opts = SamplerOptions(nsteps=60, progress=False, sampler=sampler)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # a 60-step run, on purpose
        a = sample_posterior(lp, np.array([0.5, 0.0]), options=replace(opts, seed=5), **kw)
        b = sample_posterior(lp, np.array([0.5, 0.0]), options=replace(opts, seed=5), **kw)
        c = sample_posterior(lp, np.array([0.5, 0.0]), options=replace(opts, seed=6), **kw)
    assert np.array_equal(a.chains, b.chains) and np.array_equal(a.log_prob, b.log_prob)
    assert not np.array_equal(a.chains, c.chains)
    assert np.all(a.samples[:, 0] >= 0.0)


def test_bad_arguments_are_named():
    with pytest.raises(InputError, match="names"):
        sample_posterior(_toy, np.zeros(2), names=("a",), options=QUIET)
    with pytest.raises(InputError, match="nwalkers"):
        sample_posterior(_toy, np.zeros(3), names="abc", options=replace(QUIET, nwalkers=4))
    with pytest.raises(InputError, match="cov0"):
        sample_posterior(_toy, np.zeros(2), names="ab", cov0=np.eye(3), options=QUIET)
    with pytest.raises(InputError, match="on_fail"):
        sample_posterior(_toy, np.zeros(2), names="ab", options=replace(QUIET, on_fail="maybe"))
    with pytest.raises(InputError, match="sampler: got 'nuts'"):
        sample_posterior(_toy, np.zeros(2), names="ab", options=replace(QUIET, sampler="nuts"))
    with pytest.raises(InputError, match="cov0"):
        sample_posterior(
            _toy,
            np.zeros(2),
            names="ab",
            cov0=np.eye(3),
            options=replace(QUIET, sampler="lockstep"),
        )


# --------------------------------------------------------------------------- likelihoods


def test_likelihoods_match_scipy():
    r = np.array([0.3, -1.2, 2.5, 0.0, -0.01])
    s = np.array([0.5, 1.0, 2.0, 0.1, 0.3])
    assert float(gaussian_loglik(r, s)) == pytest.approx(stats.norm.logpdf(r, 0, s).sum())
    assert float(gaussian_loglik(r, 0.7)) == pytest.approx(stats.norm.logpdf(r, 0, 0.7).sum())
    want = stats.t.logpdf(r, 4.5, 0, s).sum()
    assert float(student_t_loglik(r, s, 4.5)) == pytest.approx(want, rel=1e-12)


# --------------------------------------------------------------------------- priors

_PRIORS = [
    (Normal(0.1, 0.02), stats.norm(0.1, 0.02)),
    (Uniform(-1.0, 3.0), stats.uniform(-1.0, 4.0)),
    (HalfNormal(0.003), stats.halfnorm(0.0, 0.003)),
    (LogNormal(-1.0, 0.5), stats.lognorm(0.5, scale=math.exp(-1.0))),
    (StudentT(5.0, 0.2, 0.01), stats.t(5.0, 0.2, 0.01)),
]


@pytest.mark.parametrize(("prior", "ref"), _PRIORS, ids=lambda p: type(p).__name__)
def test_priors_match_scipy(prior, ref):
    lo, hi = ref.ppf([0.001, 0.999])
    x = np.linspace(lo, hi, 41)
    assert np.allclose(np.asarray(prior.log_pdf(x)), ref.logpdf(x), rtol=1e-10, atol=1e-10)
    assert prior.mean == pytest.approx(ref.mean(), rel=1e-12, abs=1e-15)
    assert prior.sd == pytest.approx(ref.std(), rel=1e-12)
    a, b = prior.support
    if math.isfinite(a):
        assert float(prior.log_pdf(a - 1e-9)) == -math.inf
    if math.isfinite(b):
        assert float(prior.log_pdf(b + 1e-9)) == -math.inf
    draws = prior.sample(np.random.default_rng(0), 40_000)
    # Kolmogorov-Smirnov at a fixed seed: the draws come from the distribution
    assert stats.kstest(draws, ref.cdf).pvalue > 0.001


def test_prior_from_spec_builds_each_distribution():
    assert prior_from_spec("p", {"dist": "normal", "mean": 0.0, "sd": 0.002}) == Normal(0.0, 0.002)
    assert prior_from_spec("p", {"dist": "uniform", "low": -1, "high": 1}) == Uniform(-1.0, 1.0)
    assert prior_from_spec("p", {"dist": "rectangular", "mean": 2.0, "half_width": 0.5}) == (
        Uniform(1.5, 2.5)
    )
    assert prior_from_spec("p", {"dist": "half_normal", "sd": 0.001}) == HalfNormal(0.001)
    assert prior_from_spec("p", {"dist": "lognormal", "mu": 0, "sigma": 1}) == LogNormal(0, 1)
    assert prior_from_spec("p", {"dist": "t", "nu": 4, "mean": 0, "scale": 2}) == (
        StudentT(4.0, 0.0, 2.0)
    )


@pytest.mark.parametrize(
    ("spec", "pattern"),
    [
        ({"mean": 0.0, "sd": 1.0}, r"'dist' missing"),
        ({"dist": "gamma", "a": 1.0}, r"'dist' = 'gamma': unknown distribution"),
        ({"dist": "normal", "mean": 0.0, "sigma": 1.0}, r"key 'sigma' = 1.0 is not a parameter"),
        ({"dist": "normal", "mean": 0.0}, r"missing \['sd'\]"),
        ({"dist": "normal", "mean": "zero", "sd": 1.0}, r"key 'mean' = 'zero': expected a number"),
        ({"dist": "normal", "mean": 0.0, "sd": -0.1}, r"key 'sd' = -0.1: expected a value > 0"),
        ({"dist": "normal", "mean": True, "sd": 1.0}, r"key 'mean' = True"),
        ({"dist": "uniform", "low": 1.0, "high": 1.0}, r"key 'high' = 1.0: expected high > low"),
        ({"dist": "normal", "mean": float("nan"), "sd": 1.0}, r"expected a finite number"),
    ],
)
def test_prior_from_spec_errors_name_source_key_and_value(spec, pattern):
    with pytest.raises(InputError, match=pattern) as err:
        prior_from_spec("machine.scale_x", spec, file="study.toml")
    assert "prior 'machine.scale_x'" in str(err.value)
    assert str(err.value).startswith("study.toml")


def test_progress_bar_per_ensemble(capsys):
    with pytest.warns(ConvergenceWarning):
        sample_posterior(
            _toy, np.zeros(2), names="ab", options=SamplerOptions(nsteps=20, n_ensembles=2)
        )
    err = capsys.readouterr().err
    assert "emcee ensemble 1/2" in err and "emcee ensemble 2/2" in err


def test_lockstep_progress_bar_and_diagnostics_line(capsys):
    lines = []
    with pytest.warns(ConvergenceWarning):
        sample_posterior(
            _toy,
            np.zeros(2),
            names="ab",
            options=SamplerOptions(nsteps=20, progress=lines.append, sampler="lockstep"),
        )  # one compilation with the short runs above: same model, ensembles and walkers
    assert "lockstep sampler (4 ensembles)" in capsys.readouterr().err
    assert lines == ["posterior diagnostics: autocorrelation times, ESS and R-hat per parameter"]

"""The main job's sampler: the lockstep JAX ensembles on one part's profile posterior.

`fit_profile_bayes` (and so `jobs.bayes_study` and the main job) samples with the
lockstep sampler by default; emcee stays available (`sampler="emcee"`). On the
demo part (7 features, four error sources and the probe sigma: 20 parameters)
the two samplers must agree within Monte Carlo error: per parameter, the means
within 4 combined standard errors $\\sqrt{\\mathrm{mcse}_a^2 + \\mathrm{mcse}_b^2}$
(each $\\mathrm{sd}/\\sqrt{\\mathrm{ESS}}$), the sds within 4 combined
$\\mathrm{sd}\\sqrt{(\\kappa - 1)/(4\\,\\mathrm{ESS})}$. The same seed must give the
same draws; progress, convergence verdicts and posterior.nc must be those of the
emcee path.
"""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from piecs_bayes.errors import InputError
from piecs_bayes.fit.mcmc import ConvergenceError, ConvergenceWarning, Posterior
from piecs_bayes.io import load_study
from piecs_bayes.jobs import bayes_study, fit_study, load_probe_data

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"
K_SE = 4.0  # allowed multiples of the combined Monte Carlo standard error
LOCKSTEP = "piecs_bayes lockstep ensembles (jax)"


@functools.cache
def _demo():
    study = load_study(DEMO)
    probe = load_probe_data(study)
    return study, probe, fit_study(study, probe, method="robust")


@functools.cache
def _run(sampler: str, nsteps: int, seed: int):
    """One part's posterior, 2 ensembles (one compilation shared by every lockstep
    run of this file: the run's length is not part of the compiled program)."""
    study, probe, fit = _demo()
    return bayes_study(
        study, fit, probe, nsteps=nsteps, n_ensembles=2, seed=seed, progress=False,
        on_fail="ignore", sampler=sampler,
    )  # fmt: skip


def _sd_se(post: Posterior) -> np.ndarray:
    """Standard error of each parameter's posterior sd: sd sqrt((kurtosis - 1) / (4 ESS))."""
    kappa = stats.kurtosis(post.samples, axis=0, fisher=False)
    return post.sd * np.sqrt((kappa - 1.0) / (4.0 * post.ess))


def test_lockstep_and_emcee_give_the_same_profile_posterior():
    lock = _run("lockstep", 4000, 1).posterior
    ref = _run("emcee", 4000, 1).posterior
    assert lock.sampler == LOCKSTEP and ref.sampler.startswith("emcee")
    assert lock.names == ref.names and len(lock.names) == 20
    # both long enough for their own diagnostics to be trusted
    assert np.all(lock.rhat < 1.01) and np.all(ref.rhat < 1.01)
    assert lock.ess.min() > 1000 and ref.ess.min() > 1000
    se_mean = np.hypot(lock.mcse, ref.mcse)
    assert np.all(np.abs(lock.mean - ref.mean) <= K_SE * se_mean), (lock.mean - ref.mean) / se_mean
    se_sd = np.hypot(_sd_se(lock), _sd_se(ref))
    assert np.all(np.abs(lock.sd - ref.sd) <= K_SE * se_sd), (lock.sd - ref.sd) / se_sd
    # the same moves (80 % DE, 20 % stretch): the same acceptance, the same mixing
    assert abs(lock.acceptance_fraction.mean() - ref.acceptance_fraction.mean()) < 0.03
    assert np.all(np.abs(np.log(lock.tau / ref.tau)) < np.log(1.5))


def test_same_seed_same_draws_other_seed_other_draws():
    a = _run("lockstep", 300, 7).posterior
    study, probe, fit = _demo()
    b = bayes_study(
        study, fit, probe, nsteps=300, n_ensembles=2, seed=7, progress=False, on_fail="ignore"
    )
    assert np.array_equal(a.chains, b.posterior.chains)
    assert np.array_equal(a.log_prob, b.posterior.log_prob)
    c = _run("lockstep", 300, 8).posterior
    assert not np.array_equal(a.chains, c.chains)


def test_bayes_study_shows_progress_and_writes_a_thinned_posterior_nc(capsys, tmp_path):
    study, probe, fit = _demo()
    lines = []
    bayes = bayes_study(
        study, fit, probe, nsteps=1000, n_ensembles=2, seed=2, progress=lines.append,
        on_fail="ignore",
    )  # fmt: skip
    err = capsys.readouterr().err
    assert "lockstep sampler (2 ensembles)" in err and "1000/1000" in err
    assert lines == ["posterior diagnostics: autocorrelation times, ESS and R-hat per parameter"]
    post = bayes.posterior
    assert post.thin > 1 and post.chains.shape[0] == 750 // post.thin  # every thin-th kept
    assert bayes.data.sampler == LOCKSTEP
    from piecs_bayes.fit.mcmc._posterior import import_arviz

    idata = import_arviz().from_netcdf(bayes.to_netcdf(tmp_path / "posterior.nc"))
    for attrs in (idata.attrs, idata.posterior.attrs):
        assert attrs["sampler"] == LOCKSTEP and attrs["moves"] == "de"
        assert (attrs["thin"], attrs["n_ensembles"]) == (post.thin, 2)
    # chain = ensemble, draw = its walkers' thinned trajectories
    assert idata.posterior.sizes["chain"] == 2
    assert idata.posterior.sizes["draw"] == post.nwalkers * post.chains.shape[0]


def test_a_short_run_warns_or_raises_with_the_single_part_message():
    study, probe, fit = _demo()
    kw = dict(nsteps=120, n_ensembles=2, seed=0, progress=False)
    with pytest.warns(ConvergenceWarning, match=r"^MCMC run has not converged"):
        bayes_study(study, fit, probe, **kw)
    with pytest.raises(ConvergenceError, match=r"MCMC run has not converged") as err:
        bayes_study(study, fit, probe, on_fail="raise", **kw)
    assert isinstance(err.value.posterior, Posterior) and not err.value.posterior.converged
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "ignore": not a word
        bayes_study(study, fit, probe, on_fail="ignore", **kw)


def test_an_unknown_sampler_is_named():
    study, probe, fit = _demo()
    with pytest.raises(InputError, match="sampler: got 'nuts'"):
        bayes_study(study, fit, probe, nsteps=100, progress=False, sampler="nuts")
